"""The real-gt floors at coarser cells: each floor's map pooled ``k x k``, as a SLAM map saved at
``k`` times its resolution (0.1 m for ``k = 2``) would hold the same scans.

The five floors of ``bench/data/real-gt`` come at 0.05 m a cell; a user's map may come at 0.1 m.
A block of ``k x k`` cells is one cell: occupied when any of it is (a laser hit anywhere in the
cell), free when at least half of it is floor (the cells rooms.png labels: the free cells, and on a
map saved with graded values the cells seen free a few times), else unknown (:func:`pool_classes`,
the rule the synthetic floors' ``--pool`` uses too). The map is written as a trinary image with
map_server's default thresholds, its origin kept at the same corner of the building. Rooms found on
it are scored at the floor's own cells against its own truth: each coarse cell's room is given to
the floor cells among the ``k x k`` it pools (:func:`upsampled`, then cut to the floor), so the
ROSE2 protocol counts the same rooms and cells at every ``k``.

The same folder and ``k`` always give the same map.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import yaml
from PIL import Image


def pool_classes(classes: np.ndarray, k: int, floor: np.ndarray | None = None) -> np.ndarray:
    """``classes`` (FREE / OCCUPIED / UNKNOWN per cell) pooled ``k x k``: occupied when any cell of
    the block is, free when at least half of it is free (or ``floor``, when given), else unknown;
    the rows and columns past the last whole block are dropped.

    >>> from semmap_pp.cells import FREE as F, OCCUPIED as O, UNKNOWN as U
    >>> c = np.array([[F, F, U, O, F], [F, U, U, U, F], [U, U, F, F, F]], np.uint8)
    >>> pool_classes(c, 2).tolist() == [[F, O]]
    True
    """
    from semmap_pp.cells import FREE, OCCUPIED, UNKNOWN
    h, w = (n // k for n in classes.shape)

    def blocks(a):
        return a[:h * k, :w * k].reshape(h, k, w, k).transpose(0, 2, 1, 3).reshape(h, w, k * k)

    free = blocks(classes == FREE if floor is None else np.asarray(floor, bool))
    out = np.full((h, w), UNKNOWN, np.uint8)
    out[free.sum(axis=-1) * 2 >= k * k] = FREE
    out[blocks(classes == OCCUPIED).any(axis=-1)] = OCCUPIED
    return out


def write(folder: Path, out: Path, k: int) -> np.ndarray:
    """Write ``folder``'s floor pooled ``k x k`` (``out/map.yaml`` + ``map.pgm``); returns the
    floor's own floor cells (rooms.png's), the cells :func:`scored` labels."""
    from semmap_pp.cells import FREE, OCCUPIED
    from semmap_pp.grid import load_map
    from semmap_pp.semantic.rooms import floor_cells
    grid = load_map(folder / "map.yaml")
    rows = grid.classes.shape[0]
    floor = floor_cells(grid)
    pooled = pool_classes(grid.classes, k, floor)
    img = np.full(pooled.shape, 205, np.uint8)
    img[pooled == FREE] = 254
    img[pooled == OCCUPIED] = 0
    x, y, yaw = grid.origin
    dropped = rows - pooled.shape[0] * k        # rows cut off at the bottom, where the origin lies
    meta = {"image": "map.pgm", "resolution": grid.resolution * k,
            "origin": [x, y + dropped * grid.resolution, yaw],
            "negate": 0, "occupied_thresh": 0.65, "free_thresh": 0.196}
    out.mkdir(parents=True, exist_ok=True)
    Image.fromarray(img).save(out / "map.pgm")
    (out / "map.yaml").write_text(yaml.safe_dump(meta))
    return floor


def upsampled(labels: np.ndarray, k: int, shape: tuple[int, int]) -> np.ndarray:
    """``labels`` of the pooled map given back to the ``k x k`` cells each pools, in an array of the
    floor's own ``shape`` (0 in the rows and columns no block covered).

    >>> upsampled(np.array([[1, 2]]), 2, (3, 5)).tolist()
    [[1, 1, 2, 2, 0], [1, 1, 2, 2, 0], [0, 0, 0, 0, 0]]
    """
    out = np.zeros(shape, np.asarray(labels).dtype)
    big = np.repeat(np.repeat(np.asarray(labels), k, axis=0), k, axis=1)
    out[:big.shape[0], :big.shape[1]] = big[:shape[0], :shape[1]]
    return out


def scored(labels: np.ndarray, k: int, floor: np.ndarray) -> np.ndarray:
    """The labels of the pooled map on the floor's own cells: :func:`upsampled` to ``floor``'s
    shape, 0 off the ``floor`` (what rooms.png of the floor itself would label).

    >>> scored(np.array([[1, 2]]), 2, np.array([[1, 0, 1, 1], [1, 1, 0, 1]], bool)).tolist()
    [[1, 0, 2, 2], [1, 1, 0, 2]]
    """
    return np.where(floor, upsampled(labels, k, floor.shape), 0)
