"""Partial explorations of the real-gt floors: maps of a robot that drove through some rooms only.

The robot starts in the room with the most neighbours (a corridor), and goes on, breadth first,
into each neighbouring room that is long and thin (``elongation`` at least 3: a corridor, always
driven) or, otherwise, with probability ``explored``. From a scan position every metre in the rooms
it drove through (at least 0.3 m from a wall) it casts 720 rays of 8 m over the full floor's map;
a ray stops at the first occupied cell or at a cell the full map never saw (its unknown grey: the
commonest grey value its YAML's thresholds call unknown, 153 on the freiburg floors, 205 on the
others). The partial map keeps the cells a ray reached, with their grey values, and is that grey
elsewhere: rooms the robot passed
are seen only through their doors, as fans of rays. The truth is the floor's hand-drawn truth on
the cells the partial map saw (the truth is drawn on the floor: on a map saved with graded values
it holds cells lighter than the unknown grey that the YAML's thresholds call unknown); the ROSE2
protocol then drops rooms of 200 cells or fewer.

The same folder, ``explored`` and ``seed`` always give the same map.
"""

from __future__ import annotations

from pathlib import Path

import numba
import numpy as np
import yaml
from PIL import Image
from scipy import ndimage as ndi

from turned_maps import unknown_grey

#: (share of the rooms entered, seed) of the two explorations of each floor
EXPLORATIONS = ((0.3, 1), (0.6, 2))


@numba.njit
def _cast(block, poses, n_angles, max_cells):  # pragma: no cover - compiled
    H, W = block.shape
    seen = np.zeros((H, W), np.bool_)
    for k in range(poses.shape[0]):
        y0, x0 = poses[k, 0] + 0.5, poses[k, 1] + 0.5
        for a in range(n_angles):
            th = 2.0 * np.pi * a / n_angles
            dy, dx = np.sin(th) * 0.5, np.cos(th) * 0.5
            y, x = y0, x0
            for _ in range(int(max_cells * 2)):
                iy, ix = int(y), int(x)
                if iy < 0 or ix < 0 or iy >= H or ix >= W:
                    break
                seen[iy, ix] = True
                if block[iy, ix]:
                    break
                y += dy
                x += dx
    return seen


def _elongation(mask: np.ndarray) -> float:
    ys, xs = np.nonzero(mask)
    h, w = np.ptp(ys) + 1, np.ptp(xs) + 1
    return max(h, w) / min(h, w)


def explore(folder: Path, explored: float, seed: int, truth: np.ndarray):
    """``(image, meta, truth)``: the partial map's grey image and YAML fields, and its truth labels.

    ``truth`` is the floor's room labels (0 none)."""
    meta = yaml.safe_load((folder / "map.yaml").read_text())
    img = np.asarray(Image.open(folder / meta["image"]).convert("L"))
    res = float(meta["resolution"])
    p = (255.0 - img) / 255.0
    free = p < float(meta["free_thresh"])
    occupied = p > float(meta["occupied_thresh"])
    canvas = unknown_grey(folder, img)                    # the grey of the cells the map never saw
    unseen = np.abs(img.astype(int) - canvas) <= 3
    rng = np.random.default_rng(seed)
    ids = [int(t) for t in np.unique(truth) if t > 0 and (truth == t).sum() > 200]
    neighbours = {t: set() for t in ids}
    for t in ids:
        grown = ndi.binary_dilation(truth == t, iterations=12)
        neighbours[t] = {int(u) for u in np.unique(truth[grown]) if u in neighbours and u != t}
    area = {t: int((truth == t).sum()) for t in ids}
    start = max(ids, key=lambda t: (len(neighbours[t]), area[t]))
    entered, queue = {start}, [start]
    while queue:
        t = queue.pop(0)
        for u in sorted(neighbours[t]):
            if u not in entered and (_elongation(truth == u) >= 3.0 or rng.random() < explored):
                entered.add(u)
                queue.append(u)
    clear = ndi.distance_transform_edt(free) * res
    step = max(1, int(round(1.0 / res)))
    yy, xx = (a.ravel() for a in np.mgrid[0:img.shape[0]:step, 0:img.shape[1]:step])
    keep = (clear[yy, xx] >= 0.3) & np.isin(truth[yy, xx], sorted(entered))
    poses = np.stack([yy[keep], xx[keep]], 1).astype(np.float64)
    seen = _cast(occupied | unseen, poses, 720, 8.0 / res)
    part = np.full(img.shape, canvas, np.uint8)
    part[seen] = img[seen]
    return part, dict(meta, image="map.png"), np.where(seen, truth, 0)


def write(folder: Path, out: Path, explored: float, seed: int, truth: np.ndarray) -> np.ndarray:
    """Write the partial map (``out/map.yaml`` + ``map.png``); returns its truth labels."""
    part, meta, labels = explore(folder, explored, seed, truth)
    out.mkdir(parents=True, exist_ok=True)
    Image.fromarray(part).save(out / "map.png")
    (out / "map.yaml").write_text(yaml.safe_dump(meta))
    return labels
