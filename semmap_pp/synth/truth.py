"""Ground truth of a synthetic floor: ``truth.json`` and ``truth_labels.png``.

Pixel coordinates are continuous image coordinates ``[x, y]`` (x = column, y = row, the convention
of :mod:`semmap_pp.cells`): the cell ``[row, col]`` covers ``col <= x < col + 1`` and
``row <= y < row + 1``, so its centre is ``[col + 0.5, row + 0.5]``. A unit's corners lie on the
centre lines of its walls. ``docs/synthetic.md`` describes every field.
"""

from __future__ import annotations

import io
import json
import os
import re
from pathlib import Path

import numpy as np
from PIL import Image

from semmap_pp import atomic
from semmap_pp.errors import OutputError
from semmap_pp.synth.render import Placement
from semmap_pp.synth.topology import FloorPlan

DIGITS = 3
_NUMBER_LIST = re.compile(r"\[\s*(-?[\d.]+(?:,\s*-?[\d.]+)*)\s*\]")  # rounding of every float in truth.json, so the file's bytes are stable


def _r(v) -> float:
    return round(float(v), DIGITS) + 0.0  # "+ 0.0" turns -0.0 into 0.0


def _pt(xy) -> list:
    return [_r(xy[0]), _r(xy[1])]


def build_truth(plan: FloorPlan, pl: Placement, *, seed: int, resolution: float, width: int, height: int,
                laser_range_m: float) -> dict:
    """The ``truth.json`` document of a plan placed into the image by ``pl``."""
    units = []
    for i, (x0, y0, x1, y1) in enumerate(plan.rects.tolist()):
        corners = pl.apply([[x0, y0], [x1, y0], [x1, y1], [x0, y1]])
        centre = pl.apply([[(x0 + x1) / 2, (y0 + y1) / 2]])[0]
        a, b = (x1 - x0) * resolution, (y1 - y0) * resolution
        units.append({
            "id": i + 1,
            "type": plan.types[i],
            "corners_px": [_pt(c) for c in corners],
            "center_px": _pt(centre),
            "size_m": [_r(max(a, b)), _r(min(a, b))],
            "explored": bool(plan.explored[i]),
            "entered": bool(plan.entered[i]),
        })
    doors = []
    for d in plan.doors:
        xy = (d.coord, d.centre) if d.orient == "v" else (d.centre, d.coord)
        doors.append({"units": [d.a + 1, d.b + 1], "center_px": _pt(pl.apply([xy])[0]),
                      "width_m": _r(d.width * resolution), "open": bool(d.is_open)})
    exits = []
    for unit, o, c, s0, s1 in plan.exits:
        mid = (s0 + s1) / 2
        xy = (c, mid) if o == "v" else (mid, c)
        exits.append({"unit": unit + 1, "center_px": _pt(pl.apply([xy])[0]),
                      "width_m": _r((s1 - s0) * resolution)})
    pairs = lambda ps: [[a + 1, b + 1] for a, b in sorted(ps)]
    return {
        "seed": int(seed),
        "resolution": _r(resolution),
        "rotation_deg": _r(pl.rotation_deg),
        "width": int(width),
        "height": int(height),
        "origin": [0.0, 0.0, 0.0],
        "layout": plan.layout,
        "laser_range_m": _r(laser_range_m),
        "units": units,
        "doors": doors,
        "exits": exits,
        "adjacency": pairs(plan.shared.keys()),
        "open_boundaries": pairs(plan.open_pairs),
        "l_shapes": pairs(plan.l_pairs),
    }


def encode_truth(truth: dict) -> str:
    """The JSON text of ``truth`` (fixed key order, fixed float rounding, trailing newline)."""
    text = json.dumps(truth, indent=1)
    # lists of plain numbers on one line: [x, y] points stay readable
    text = _NUMBER_LIST.sub(lambda m: "[" + ", ".join(m.group(1).split()).replace(",,", ",") + "]",
                            text)
    return text + "\n"


def encode_labels(labels: np.ndarray) -> bytes:
    """16-bit greyscale PNG bytes of a uint16 label image."""
    labels = np.ascontiguousarray(labels, dtype=np.uint16)
    buf = io.BytesIO()
    Image.fromarray(labels).save(buf, format="PNG")
    return buf.getvalue()


def read_labels(path: str | os.PathLike) -> np.ndarray:
    """A ``truth_labels.png`` back as uint16 ``[H, W]``."""
    with Image.open(path) as im:
        return np.array(im, dtype=np.uint16)


def write_truth(out_dir: str | os.PathLike, truth: dict, labels: np.ndarray) -> dict:
    """Write ``truth.json`` and ``truth_labels.png`` into ``out_dir`` atomically; return the paths."""
    out = Path(out_dir)
    paths = {"truth": out / "truth.json", "truth_labels": out / "truth_labels.png"}
    try:
        atomic.write_bytes(paths["truth_labels"], encode_labels(labels))
        atomic.write_text(paths["truth"], encode_truth(truth))
    except OSError as exc:
        raise OutputError(out, f"cannot write truth: {exc.strerror or exc}") from exc
    return paths
