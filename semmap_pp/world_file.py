"""A world.json read back onto a map's lattice: the start world of ``semmap map --start FILE``.

world.json (docs/outputs.md) gives each unit and exterior unit as four corners in the input image's
pixel frame. On the lattice of the map that run used, each is one lattice rectangle
(:meth:`semmap_pp.frame.Frame.rect_from_vertices_px`). The file may come from another run on the same
map (the paper's Fig. 7 samples from W*) or be edited by hand (a wall moved, a unit added: any
rectangle of the lattice will do; corners within :data:`MAX_OFF_PX` of one are snapped to it).
What cannot start a chain is refused with a one-line :class:`~semmap_pp.errors.SemmapError`
naming the file: not a world.json, written for a map of
another size or resolution, a unit that is not a rectangle of this map's lattice (the building's
orientation differs: another map, or a model whose lattice settings changed), or a unit outside
the lattice or outside the prior's side range.

:func:`read_previous_ids` reads a world.json's units in map-frame metres instead, for a new run on
a map that has grown since (``semmap map --ids-from FILE``: the units' ids carried over).
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from semmap_pp import world as wm
from semmap_pp.errors import SemmapError
from semmap_pp.model import MAX_K
from semmap_pp.prior import rect_faults
from semmap_pp.outputs.ids import MAX_ID
from semmap_pp.outputs.world_json import FORMAT

#: Corners farther than this (pixels) from their lattice rectangle's are not of this lattice.
#: world.json rounds pixel coordinates to 3 decimals, so a unit of this lattice lies within 0.001;
#: a corner moved by hand is snapped to the nearest lattice rectangle when it lies within a pixel.
MAX_OFF_PX = 1.0

#: A larger file is refused before it is read (cartesium's world.json: 0.3 MB).
MAX_BYTES = 256 * 2 ** 20


def finite(x) -> float | None:
    """``x`` as a finite float, or None (not a number, a bool, infinite, or an int beyond floats)."""
    if isinstance(x, bool) or not isinstance(x, (int, float)):
        return None
    try:
        v = float(x)
    except OverflowError:
        return None
    return v if math.isfinite(v) else None


def _brief(x) -> str:
    """``x`` for a message: a file's value shown whole unless it is long (a 400-digit width)."""
    text = str(x)
    return text if len(text) <= 24 else text[:20] + "..."


def corners(path, item, name: str, key: str = "vertices_px") -> np.ndarray:
    """``item[key]`` as four finite ``[x, y]`` corners, else one error naming ``path`` and ``name``."""
    v = item.get(key) if isinstance(item, dict) else None
    try:
        arr = np.asarray(v, dtype=np.float64)
    except (TypeError, ValueError, OverflowError):   # an int beyond floats too
        arr = None
    if arr is None or arr.shape != (4, 2) or not np.all(np.isfinite(arr)):
        raise SemmapError(path, f"{name}: '{key}' must be four [x, y] numbers")
    return arr


def read_world_doc(path, not_file: str = "not a regular file") -> dict:
    """The top-level object of the world.json at ``path``, refused when it is not a regular
    file (``not_file`` says so), is larger than :data:`MAX_BYTES`, or is not of :data:`FORMAT`."""
    from semmap_pp.evaluate.io import read_json

    p = Path(path)
    if p.exists() and not p.is_file():   # a directory, FIFO or device would fail or block
        raise SemmapError(path, not_file)
    if p.exists() and p.stat().st_size > MAX_BYTES:
        raise SemmapError(path, f"{p.stat().st_size} bytes is too large for a world.json "
                                f"(at most {MAX_BYTES})")
    doc = read_json(path)
    if not isinstance(doc, dict) or doc.get("format") != FORMAT:
        raise SemmapError(path, f"not a world.json of semmap_pp (expected \"format\": \"{FORMAT}\")")
    return doc


def read_start_world(path: str | os.PathLike, frame, grid, capacity: int) -> wm.World:
    """The units and exterior units of the world.json at ``path`` as a world on ``frame``'s lattice
    (types unassigned), in ``capacity`` slots or, for more units, the smallest doubling of it
    (at most :data:`semmap_pp.model.MAX_K`).

    ``grid`` is the map the run reads (:class:`semmap_pp.grid.OccupancyGrid`): the file must have
    been written for a map of the same width, height and resolution.
    """
    return pack_world([rect for _, rect in read_world_units(path, frame, grid)], capacity, path)


def pack_world(rects, capacity: int, path=None) -> wm.World:
    """Lattice rectangles as a world (types unassigned) in ``capacity`` slots or the smallest
    doubling of it that holds them; more than :data:`semmap_pp.model.MAX_K` is an error naming
    ``path``."""
    if len(rects) > MAX_K:
        raise SemmapError(path, f"{len(rects)} units; a world holds at most {MAX_K}")
    size_k = max(1, int(capacity))
    while size_k < len(rects):   # doubled as the ascent grows a full world (ascent._Ascent.free)
        size_k = min(2 * size_k, MAX_K)
    world = wm.empty(size_k)
    for slot, rect in enumerate(rects):
        world = wm.add(world, slot, rect)
    return world


def read_world_units(path: str | os.PathLike, frame, grid) -> list[tuple[str, tuple[int, int, int, int]]]:
    """The units and exterior units of the world.json at ``path`` on ``frame``'s lattice, in the
    file's order, each as ``(key, rect)``: the key is the unit's id as text (``"7"``; ``"X2"`` for
    exterior unit 2), the position in its list when it has none. Checked as
    :func:`read_start_world` says."""
    doc = read_world_doc(path)
    m = doc.get("map")
    size = (m.get("width"), m.get("height"), m.get("resolution")) if isinstance(m, dict) else None
    here = (grid.width, grid.height, grid.resolution)
    res = finite(size[2]) if size is not None else None
    if size is None or size[:2] != here[:2] or res is None \
            or not math.isclose(res, here[2], rel_tol=1e-9):
        was = ("no 'map' size" if size is None
               else f"a {_brief(size[0])}x{_brief(size[1])} map at {_brief(size[2])} m/cell")
        raise SemmapError(path, f"written for {was}; this map is {here[0]}x{here[1]} at {here[2]} "
                                f"m/cell")
    items = []
    for key, prefix, noun in (("units", "", "unit "), ("exterior", "X", "exterior unit ")):
        listed = doc.get(key, [])
        if not isinstance(listed, list):
            raise SemmapError(path, f"'{key}' must be a list")
        for i, u in enumerate(listed):
            uid = f"{prefix}{u.get('id', i + 1) if isinstance(u, dict) else i + 1}"
            items.append((noun + uid, uid, u))
    c = frame.cells
    rects = []
    for name, key, item in items:
        rect, off = frame.rect_from_vertices_px(corners(path, item, name))
        if off > MAX_OFF_PX:
            raise SemmapError(path, f"{name} is not a rectangle of this map's lattice (its corners lie "
                                    f"{off:.2f} px from the nearest one; the building's orientation here "
                                    f"is {math.degrees(frame.theta):.1f} deg, the file's "
                                    f"{m.get('orientation_deg', '?')}): was it written for this map "
                                    f"and model?")
        r0, c0, r1, c1 = rect
        faults = rect_faults(rect, frame.shape, c.min_side, c.max_side)
        if "outside" in faults:
            raise SemmapError(path, f"{name} reaches beyond the map's lattice ({frame.shape[0]} x "
                                    f"{frame.shape[1]} cells; the unit spans rows {r0}..{r1}, columns "
                                    f"{c0}..{c1})")
        if faults:
            raise SemmapError(path, f"{name} is {r1 - r0} x {c1 - c0} cells; the model allows sides of "
                                    f"{c.min_side} to {c.max_side} cells ([world] min_unit_side_m, "
                                    f"max_unit_side_m)")
        rects.append((key, rect))
    return rects


@dataclass(frozen=True)
class PreviousIds:
    """The units of an earlier world.json in map-frame metres, whose ids a new run carries over
    (``semmap map --ids-from FILE``, :func:`semmap_pp.outputs.ids.carry_ids`)."""

    path: Path
    ids: tuple[int, ...]
    corners_m: np.ndarray      # (n, 4, 2) each unit's ``vertices_m``
    next_id: int               # the first id the file's numbering never used


def read_run_world(path: str | os.PathLike) -> tuple:
    """``(path, doc)``: the world.json at ``path``, or in the folder ``path`` (a run's), read as
    :func:`read_world_doc` reads it; ``path`` is then the file's, for messages."""
    p = Path(path)
    if p.is_dir() and (p / "world.json").is_file():   # a run's folder
        path = p / "world.json"
    return path, read_world_doc(path, "not a regular file (a world.json, or a run's folder that holds one)")


def read_previous_ids(path: str | os.PathLike) -> PreviousIds:
    """The units of the world.json at ``path`` (or in the folder ``path``, an earlier run's) with
    their ids and corners in metres.

    Unlike :func:`read_world_units` it does not ask for the same map: a SLAM map grows between
    updates (size and origin change, the ``map`` frame stays), so units are read in metres. Each
    unit needs an integer ``id`` of at least 1, unique in the file, and four finite ``vertices_m``;
    the next id is the file's own ``ids.next`` when it carries one (ids that went away are not
    given again), else its largest id + 1. Anything else is one :class:`SemmapError` naming the
    file. Exterior units are not read: their ids are numbered afresh in every file.
    """
    path, doc = read_run_world(path)
    return previous_ids_from_doc(doc, path)


def previous_ids_from_doc(doc: dict, path) -> PreviousIds:
    """:func:`read_previous_ids` of a world.json's content, already read from ``path``."""
    units = doc.get("units", [])
    if not isinstance(units, list):
        raise SemmapError(path, "'units' must be a list")
    ids, quads = [], []
    for i, u in enumerate(units):
        uid = u.get("id") if isinstance(u, dict) else None
        if isinstance(uid, bool) or not isinstance(uid, int) or not 1 <= uid <= MAX_ID:
            raise SemmapError(path, f"unit {i + 1} of the list: 'id' must be an integer from 1 to "
                                    f"{MAX_ID}, got {_brief(uid)}")
        if uid in ids:
            raise SemmapError(path, f"unit id {uid} is used twice")
        quads.append(corners(path, u, f"unit {uid}", "vertices_m"))
        ids.append(uid)
    nxt = max(ids, default=0) + 1
    listed = doc.get("ids")
    if isinstance(listed, dict) and "next" in listed:
        given = listed["next"]
        if isinstance(given, bool) or not isinstance(given, int) or not 1 <= given <= MAX_ID:
            raise SemmapError(path, f"ids.next must be an integer from 1 to {MAX_ID}, got {_brief(given)}")
        nxt = max(nxt, given)
    if nxt > MAX_ID:
        raise SemmapError(path, f"no unit id is left after {MAX_ID} (labels.png holds 16-bit ids)")
    return PreviousIds(Path(path), tuple(ids), np.asarray(quads, np.float64).reshape(-1, 4, 2), nxt)
