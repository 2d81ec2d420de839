"""Unexplored areas: free space outside every unit that is too small to be a unit (paper Fig. 5).

A component (8-connected) of input-free lattice cells outside every unit rectangle (walls
included) is an unexplored area when it has at least ``min_area`` cells (smaller ones are noise)
and is too small to be a unit: its bounding box has a side shorter than ``min_side`` cells or it
has fewer than ``min_side**2`` cells.

Examples
--------
>>> import numpy as np
>>> cls = np.ones((10, 12), np.uint8); cls[1:9, 1:5] = 0; cls[2:4, 8:10] = 0
>>> [a.box for a in find_unexplored(cls, np.array([[0, 0, 10, 6]]), min_side=3, min_area=2)]
[(2, 8, 4, 10)]
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from scipy import ndimage

from semmap_pp.cells import FREE

EIGHT = np.ones((3, 3), dtype=bool)


class Unexplored(NamedTuple):
    """An unexplored area: lattice bounding box, cell count, and centroid ``(row, col)``."""

    box: tuple
    cells: int
    centroid: tuple


def find_unexplored(classes: np.ndarray, rects: np.ndarray, min_side: int,
                    min_area: int) -> list[Unexplored]:
    """Unexplored areas of the world with units ``rects`` (n, 4) on lattice classes ``classes``."""
    free = np.asarray(classes) == FREE
    for r0, c0, r1, c1 in np.asarray(rects).reshape(-1, 4):
        free[max(r0, 0):max(r1, 0), max(c0, 0):max(c1, 0)] = False
    labels, n = ndimage.label(free, structure=EIGHT)
    if n == 0:
        return []
    sizes = np.bincount(labels.ravel(), minlength=n + 1)
    out = []
    for k, sl in enumerate(ndimage.find_objects(labels), start=1):
        size = int(sizes[k])
        h, w = sl[0].stop - sl[0].start, sl[1].stop - sl[1].start
        if size < min_area or (min(h, w) >= min_side and size >= min_side ** 2):
            continue
        rr, cc = np.nonzero(labels[sl] == k)
        out.append(Unexplored((sl[0].start, sl[1].start, sl[0].stop, sl[1].stop), size,
                              (float(rr.mean() + sl[0].start), float(cc.mean() + sl[1].start))))
    return out
