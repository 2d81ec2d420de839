"""world.json (schema: docs/world.schema.json) and labels.png.

Pixel coordinates are ``[x, y]`` in the continuous pixel frame of :mod:`semmap_pp.cells`
(x = column, y = row, pixel (r, c) spans ``[c, c+1) x [r, r+1)``); metres are the ROS map frame.
Numbers are rounded (pixels to 1e-3, metres to 1e-4, probabilities to 1e-6) so that the same world
always gives the same bytes.
"""

from __future__ import annotations

import io
import json
import math
import os
import re
from pathlib import Path

import numpy as np
from PIL import Image

from semmap_pp import __version__
from semmap_pp import atomic
from semmap_pp.cells import UNIT_TYPES
from semmap_pp.derive.states import seen_shares
from semmap_pp.lattice.tiles import rect_spans, unit_theta
from semmap_pp.sampler.marginals import MATCH_IOU

FORMAT = "semmap_pp.world/1"


def _px(frame, rows, cols) -> np.ndarray:
    """Lattice cell-index coordinates -> [x, y] in the continuous pixel frame."""
    x, y = frame.lattice_to_image(np.asarray(rows, float), np.asarray(cols, float))
    return np.stack([np.atleast_1d(x) + 0.5, np.atleast_1d(y) + 0.5], axis=1)


def _m(frame, px: np.ndarray) -> np.ndarray:
    x, y = frame.image_to_metres(px[:, 0], px[:, 1])
    return np.stack([np.atleast_1d(x), np.atleast_1d(y)], axis=1)


def _r(values, nd):
    return [round(float(v), nd) for v in values]


def _box_centre(box) -> tuple[float, float]:
    r0, c0, r1, c1 = box
    return (r0 + r1 - 1) / 2.0, (c0 + c1 - 1) / 2.0


def rect_corners_m(frame, rect) -> np.ndarray:
    """(4, 2) corners of a lattice rectangle in map-frame metres, unrounded (``vertices_m``'s)."""
    return _m(frame, frame.rect_vertices_px(rect))


def _rect_geometry(frame, rect, res: float) -> dict:
    """``vertices_px``, ``orientation_deg``, ``vertices_m``, ``center_m`` and ``size_m`` of a
    unit's lattice rectangle."""
    r0, c0, r1, c1 = (int(v) for v in rect)
    vpx = frame.rect_vertices_px(rect)
    vm = rect_corners_m(frame, rect)
    return {"vertices_px": [_r(v, 3) for v in vpx],
            "orientation_deg": round(math.degrees(unit_theta(frame, rect)), 4),
            "vertices_m": [_r(v, 4) for v in vm],
            "center_m": _r(vm.mean(axis=0), 4),
            "size_m": sorted([round((r1 - r0) * res, 4), round((c1 - c0) * res, 4)], reverse=True)}


def _orientations(frame) -> dict:
    """world.json's ``orientation_deg`` of the map, and ``orientations_deg`` for a building of
    several directions."""
    out = {"orientation_deg": round(math.degrees(frame.theta), 4)}
    if rect_spans(frame):
        out["orientations_deg"] = [round(math.degrees(t.theta), 4) for t in frame.tiles]
    return out


def _seen(frame, rect) -> dict:
    """``seen_share`` and ``walls_seen_share``: how much of a unit's interior and of its wall band
    the map shows (:func:`semmap_pp.derive.states.seen_shares`)."""
    inside, band = seen_shares(frame.classes, rect, frame.cells.wall)
    return {"seen_share": round(inside, 4), "walls_seen_share": round(band, 4)}


def ordered_openings(openings, ids) -> list:
    """Doors or passages in world.json's order (by their units' ids, then lattice box): the
    ``i``-th has id ``i + 1``."""
    return sorted(openings, key=lambda o: (sorted((ids[o.p], ids[o.q])), o.box))


def _openings(frame, openings, ids, res: float) -> list[dict]:
    """Doors or passages (:class:`semmap_pp.derive.doors.Door`) as world.json lists them: ``units``,
    ``center_px``, ``center_m``, ``width_m``, ``endpoints_px`` and ``id`` (1..n in order of their
    unit pair and lattice box)."""
    out = []
    for door in ordered_openings(openings, ids):
        r0, c0, r1, c1 = door.box
        rc, cc = _box_centre(door.box)
        if door.vertical:   # the opening runs along the rows
            ends = _px(frame, [r0 - 0.5, r1 - 0.5], [cc, cc])
        else:
            ends = _px(frame, [rc, rc], [c0 - 0.5, c1 - 0.5])
        centre = _px(frame, [rc], [cc])
        out.append({"units": sorted([ids[door.p], ids[door.q]]), "center_px": _r(centre[0], 3),
                    "center_m": _r(_m(frame, centre)[0], 4), "width_m": round(door.width * res, 4),
                    "endpoints_px": [_r(e, 3) for e in ends]})
    for i, door in enumerate(out, 1):
        door["id"] = i
    return out


def world_dict(sm, *, rules: str | None = None, model: str | None = None, seed: int | None = None,
               roi_name: str = "default") -> dict:
    """The world.json content of a :class:`~semmap_pp.semantic.semantic_map.SemanticMap`."""
    grid, frame, world, d = sm.grid, sm.frame, sm.world, sm.derived
    res = float(grid.resolution)
    ids = sm.slot_ids

    doors = _openings(frame, d.doors, ids, res)
    passages = _openings(frame, d.passages + d.gap_passages, ids, res)

    objects = []
    for ob in sorted(d.objects, key=lambda o: (ids[o.unit], o.box)):
        r0, c0, r1, c1 = ob.box
        centre = _px(frame, [_box_centre(ob.box)[0]], [_box_centre(ob.box)[1]])
        objects.append({"unit": ids[ob.unit], "center_px": _r(centre[0], 3),
                        "center_m": _r(_m(frame, centre)[0], 4),
                        "extent_m": round(max(r1 - r0, c1 - c0) * res, 4), "cells": int(ob.cells)})
    for i, ob in enumerate(objects, 1):
        ob["id"] = i

    unexplored = []
    for un in sorted(d.unexplored, key=lambda o: o.box):
        centre = _px(frame, [un.centroid[0]], [un.centroid[1]])
        unexplored.append({"center_px": _r(centre[0], 3), "center_m": _r(_m(frame, centre)[0], 4),
                           "area_m2": round(un.cells * res * res, 4)})
    for i, un in enumerate(unexplored, 1):
        un["id"] = i

    exterior = [{"id": sm.exterior_ids[e.slot], **_rect_geometry(frame, world.rects[e.slot], res),
                 **_seen(frame, world.rects[e.slot]), "units": sorted(ids[s] for s in e.neighbours)}
                for e in sorted(d.exterior, key=lambda o: sm.exterior_ids[o.slot])]

    adjacency = sorted({tuple(sorted((ids[int(d.slots[i])], ids[int(d.slots[j])])))
                        for i, j in zip(*np.nonzero(np.triu(d.adjacency, 1)))})
    units = []
    for uid in sm.unit_ids:
        s = sm.slot_of(uid)
        marg = sm.marginals[uid]
        units.append({
            "id": uid,
            "type": UNIT_TYPES[int(world.types[s])],
            "type_marginals": {t: round(float(marg[k]), 6) for k, t in enumerate(UNIT_TYPES)},
            **_rect_geometry(frame, world.rects[s], res),
            **_seen(frame, world.rects[s]),
            "seen_through_door": s in sm.through_door,
            "doors": [o["id"] for o in doors if uid in o["units"]],
            "passages": [o["id"] for o in passages if uid in o["units"]],
            "objects": [o["id"] for o in objects if o["unit"] == uid],
        })

    src = grid.source
    image = grid.image_path.name if grid.image_path is not None else (src.name if src else None)
    yaml_name = src.name if src is not None and src.suffix.lower() in (".yaml", ".yml") else None
    lp = float(sm.log_posterior)
    return {
        "format": FORMAT,
        "map": {"image": image, "yaml": yaml_name, "width": int(grid.width), "height": int(grid.height),
                "resolution": res, "origin": [float(v) for v in grid.origin],
                **_orientations(frame),
                "frame_id": grid.frame_id, "stamp_ns": int(grid.stamp_ns),
                **({"topic": grid.topic} if grid.topic is not None else {}),
                "notes": list(grid.notes)},
        "units": units,
        "adjacency": [list(p) for p in adjacency],
        "doors": doors,
        "passages": passages,
        "objects": objects,
        "unexplored": unexplored,
        "exterior": exterior,
        "rooms": rooms_list(sm),
        "log_posterior": round(lp, 6) if math.isfinite(lp) else -1e308,
        "cpr": None if not math.isfinite(sm.cpr) else round(sm.cpr, 6),
        "roi": roi_name,
        "rules": rules,
        "model": model,
        "seed": seed,
        **({"ids": sm.id_record} if sm.id_record is not None else {}),
        "generator": f"semmap_pp {__version__}",
    }


def with_posterior(doc: dict, sm, units: dict, doors: dict, *, worlds: int, source: str) -> dict:
    """``doc`` (world.json's content of ``sm``) with the posterior marginals over sampled worlds
    (:mod:`semmap_pp.sampler.marginals`): each unit's ``posterior_exists`` and ``posterior_type``
    (``units``: W* slot -> :class:`~semmap_pp.sampler.marginals.UnitMarginal`), each door's
    ``posterior_exists`` (``doors``: :class:`~semmap_pp.derive.doors.Door` -> share of worlds), and
    ``posterior_marginals`` saying how many worlds they count and where the worlds come from."""
    out = dict(doc)
    out_units = []
    for u in doc["units"]:
        m = units[sm.slot_of(u["id"])]
        out_units.append(dict(u, posterior_exists=round(float(m.exists), 6),
                              posterior_type=None if m.types is None else
                              {t: round(float(p), 6) for t, p in zip(UNIT_TYPES, m.types)}))
    out["units"] = out_units
    order = ordered_openings(sm.derived.doors, sm.slot_ids)
    out["doors"] = [dict(d, posterior_exists=round(float(doors[door]), 6)) for d, door in zip(doc["doors"], order)]
    out["posterior_marginals"] = {
        "worlds": int(worlds), "source": source,
        "unit_exists": f"a sampled unit's lattice rectangle overlaps the unit's with IoU >= {MATCH_IOU:g}",
        "unit_type": "the types of those matching units, over the worlds with one",
        "door_exists": "a sampled door's lattice box meets the door's, grown by the wall band's thickness"}
    return out


def rooms_list(sm) -> list[dict]:
    """world.json's ``rooms``: each room of rooms.png (:mod:`semmap_pp.semantic.rooms`) with its
    units, free cells, area, seen share, and whether it was seen through its door alone."""
    cell_m2 = float(sm.grid.resolution) ** 2
    return [{"id": r.id, "units": list(r.units), "cells": r.cells, "area_m2": round(r.cells * cell_m2, 4),
             "seen_share": round(r.seen_share, 4), "seen_through_door": r.seen_through_door}
            for r in sm.rooms.rooms]


_NUMBER_LIST = re.compile(r"\[\s*(-?[\d.eE+-]+(?:,\s*-?[\d.eE+-]+)*)\s*\]")


def dumps(doc: dict) -> str:
    """Canonical JSON text: stable key order as built, 1-space indent, lists of numbers on one line.

    >>> print(dumps({"a": [1, 2.5], "b": [[0, 1], [2, 3]]}), end="")
    {
     "a": [1, 2.5],
     "b": [
      [0, 1],
      [2, 3]
     ]
    }
    """
    text = json.dumps(doc, indent=1, ensure_ascii=False, allow_nan=False)
    text = _NUMBER_LIST.sub(lambda m: "[" + ", ".join(v.strip() for v in m.group(1).split(",")) + "]", text)
    return text + "\n"


def write_world_json(path: str | os.PathLike, doc: dict) -> Path:
    atomic.write_text(path, dumps(doc))
    return Path(path)


def png_bytes(array: np.ndarray) -> bytes:
    """PNG bytes of a 2-D uint8 or uint16 array (16-bit greyscale for uint16), deterministic."""
    a = np.ascontiguousarray(array)
    if a.dtype == np.uint16:
        img = Image.frombytes("I;16", (a.shape[1], a.shape[0]), a.astype("<u2").tobytes())
    elif a.dtype == np.uint8:
        img = Image.fromarray(a)
    else:
        raise ValueError(f"png_bytes takes uint8 or uint16 arrays, got {a.dtype}")
    buf = io.BytesIO()
    img.save(buf, format="PNG", optimize=False)
    return buf.getvalue()


def write_labels_png(path: str | os.PathLike, labels_image: np.ndarray) -> Path:
    """A 16-bit label image in the input image's size and frame, 0 none: labels.png (unit id per
    cell, walls included) and rooms.png (room id per free cell)."""
    atomic.write_bytes(path, png_bytes(labels_image.astype(np.uint16)))
    return Path(path)
