"""Where the mapping robot took its scans, in building-frame continuous cell coordinates.

The robot drives along every reached corridor and through every reached hall, into some of the
rooms behind open doors (the others it only glimpses through the door while passing), and never
behind a closed door. Scan positions keep a clearance from walls and furniture.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from semmap_pp.synth.params import SynthParams
from semmap_pp.synth.raster import BuildingRasters
from semmap_pp.synth.topology import FloorPlan


def _polyline(points, step: float) -> list:
    out = []
    for (x0, y0), (x1, y1) in zip(points[:-1], points[1:]):
        n = max(1, int(np.hypot(x1 - x0, y1 - y0) / step))
        for k in range(n):
            t = k / n
            out.append((x0 + t * (x1 - x0), y0 + t * (y1 - y0)))
    out.append(tuple(points[-1]))
    return out


def _door_point(plan: FloorPlan, d, unit: int, depth: float):
    """A point ``depth`` cells from door ``d``'s centre, on the side of ``unit``."""
    x0, y0, x1, y1 = plan.rects[unit].tolist()
    if d.orient == "v":
        side = 1.0 if x0 >= d.coord else -1.0
        return (d.coord + side * depth, d.centre)
    side = 1.0 if y0 >= d.coord else -1.0
    return (d.centre, d.coord + side * depth)


def scan_poses(rng: np.random.Generator, plan: FloorPlan, br: BuildingRasters, solid: np.ndarray,
               p: SynthParams, res: float) -> np.ndarray:
    """Scan positions ``(N, 2)`` as building-frame ``(x, y)`` in cells (continuous)."""
    step = p.pose_spacing / res
    m = 1.0 / res
    pts: list = []
    for i in range(len(plan.types)):
        if not plan.entered[i]:
            continue
        x0, y0, x1, y1 = (float(v) for v in plan.rects[i].tolist())
        w, h = x1 - x0, y1 - y0
        cx, cy = (x0 + x1) / 2, (y0 + y1) / 2
        kind = plan.types[i]
        if kind == "corridor":
            inset = min(0.5 * m, 0.3 * max(w, h))
            jit = 0.12 * min(w, h)
            if w >= h:
                line = [(x0 + inset, cy + rng.uniform(-jit, jit)), (x1 - inset, cy + rng.uniform(-jit, jit))]
            else:
                line = [(cx + rng.uniform(-jit, jit), y0 + inset), (cx + rng.uniform(-jit, jit), y1 - inset)]
            pts += _polyline(line, step)
        elif kind == "hall":
            gap = rng.uniform(p.hall_lane_min, p.hall_lane_max) * m
            inset = min(1.0 * m, 0.3 * min(w, h))
            if w >= h:
                for k, y in enumerate(np.arange(y0 + inset, y1 - inset + 1, gap)):
                    ends = [(x0 + inset, y), (x1 - inset, y)]
                    pts += _polyline(ends if k % 2 == 0 else ends[::-1], step)
            else:
                for k, x in enumerate(np.arange(x0 + inset, x1 - inset + 1, gap)):
                    ends = [(x, y0 + inset), (x, y1 - inset)]
                    pts += _polyline(ends if k % 2 == 0 else ends[::-1], step)
        else:
            inner = [(cx, cy)]
            for _ in range(int(rng.integers(0, 3))):
                inner.append((rng.uniform(x0 + 0.25 * w, x1 - 0.25 * w),
                              rng.uniform(y0 + 0.25 * h, y1 - 0.25 * h)))
            for d in plan.doors:
                if d.is_open and i in (d.a, d.b):
                    other = d.b if d.a == i else d.a
                    if plan.entered[other]:
                        path = [_door_point(plan, d, other, 0.6 * m), _door_point(plan, d, i, 0.6 * m)]
                        pts += _polyline(path + inner, step)
            for a, b in plan.open_pairs:
                if i in (a, b):
                    o, c, s0, s1 = plan.shared[(a, b)]
                    mid = (c, (s0 + s1) / 2) if o == "v" else ((s0 + s1) / 2, c)
                    pts += _polyline([mid] + inner, step)
    for d in plan.doors:  # glimpses into rooms the robot passes but does not enter
        if d.is_open and plan.entered[d.a] != plan.entered[d.b]:
            here = d.a if plan.entered[d.a] else d.b
            pts.append(_door_point(plan, d, here, rng.uniform(0.5, 1.0) * m))
    if not pts:
        return np.zeros((0, 2))
    pts_a = np.asarray(pts, dtype=float)
    # keep a clearance from walls and furniture; a blocked scan position is dropped
    clearance = ndimage.distance_transform_edt(~solid)
    ox, oy = br.offset
    col = np.clip(np.floor(pts_a[:, 0]).astype(int) - ox, 0, solid.shape[1] - 1)
    row = np.clip(np.floor(pts_a[:, 1]).astype(int) - oy, 0, solid.shape[0] - 1)
    ok = (clearance[row, col] >= 0.25 * m) & (br.labels[row, col] > 0)
    return pts_a[ok]
