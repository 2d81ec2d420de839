"""Adjacency R: dilate every unit's walls and test the overlap (paper Fig. 4).

Two units are adjacent when their wall bands, each dilated by ``d`` cells (a square structuring
element, i.e. Chebyshev distance), overlap. :func:`adjacency_raster` does exactly that on the
lattice; :func:`adjacency_matrix` computes the
same relation from the rectangles alone in closed form (a dilated wall band is a box minus a box),
which is what the sampler uses. Tests check that the two agree.

Examples
--------
>>> import numpy as np
>>> rects = np.array([[0, 0, 10, 10], [0, 9, 10, 20], [0, 30, 10, 40]])
>>> adjacency_matrix(rects, wall=2, dilation=1).astype(int)
array([[0, 1, 0],
       [1, 0, 0],
       [0, 0, 0]])
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage


def _area(r0, c0, r1, c1):
    return np.maximum(r1 - r0, 0) * np.maximum(c1 - c0, 0)


def _boxes(rects: np.ndarray, wall: int, dilation: int):
    r = np.asarray(rects, dtype=np.int64).reshape(-1, 4)
    outer = r + np.array([-dilation, -dilation, dilation, dilation])
    inner = r + np.array([wall + dilation, wall + dilation, -wall - dilation, -wall - dilation])
    empty = (inner[:, 2] <= inner[:, 0]) | (inner[:, 3] <= inner[:, 1])
    inner[empty] = 0  # an empty hole: the dilated band is the whole outer box
    return outer, inner


def _meet(a, b):
    """Intersection boxes of box arrays ``a`` (n,1,4) and ``b`` (1,m,4) -> 4 arrays (n, m)."""
    return (np.maximum(a[..., 0], b[..., 0]), np.maximum(a[..., 1], b[..., 1]),
            np.minimum(a[..., 2], b[..., 2]), np.minimum(a[..., 3], b[..., 3]))


def adjacency_rows(rects: np.ndarray, rows, wall: int, dilation: int) -> np.ndarray:
    """Adjacency of the units ``rows`` (indices into ``rects``) to every unit: (len(rows), n) bool."""
    outer, inner = _boxes(rects, wall, dilation)
    rows = np.asarray(rows, dtype=np.intp).reshape(-1)
    oa, ia = outer[rows][:, None, :], inner[rows][:, None, :]
    ob, ib = outer[None, :, :], inner[None, :, :]
    x = _meet(oa, ob)                       # X = outer_a ∩ outer_b
    xb = np.stack(x, axis=-1)
    xa_ = _meet(xb, ia)                     # X ∩ inner_a
    xb_ = _meet(xb, ib)                     # X ∩ inner_b
    xab = _meet(np.stack(xa_, axis=-1), ib)  # X ∩ inner_a ∩ inner_b
    left = _area(*x) - _area(*xa_) - _area(*xb_) + _area(*xab)  # |X \ (inner_a ∪ inner_b)|
    adj = left > 0
    adj[np.arange(len(rows)), rows] = False
    return adj


def adjacency_matrix(rects: np.ndarray, wall: int, dilation: int) -> np.ndarray:
    """(n, n) bool adjacency of all units, from the rectangles (closed form)."""
    n = len(np.asarray(rects).reshape(-1, 4))
    return adjacency_rows(rects, np.arange(n), wall, dilation)


def dilated_wall_mask(shape, rect, wall: int, dilation: int) -> np.ndarray:
    """Raster of one unit's wall band dilated by ``dilation`` cells, clipped to ``shape``."""
    band = np.zeros(shape, dtype=bool)
    r0, c0, r1, c1 = (int(v) for v in rect)
    band[max(r0, 0):max(r1, 0), max(c0, 0):max(c1, 0)] = True
    if r1 - r0 > 2 * wall and c1 - c0 > 2 * wall:
        band[max(r0 + wall, 0):max(r1 - wall, 0), max(c0 + wall, 0):max(c1 - wall, 0)] = False
    size = 2 * dilation + 1
    return ndimage.binary_dilation(band, structure=np.ones((size, size), bool))


def adjacency_raster(shape, rects: np.ndarray, wall: int, dilation: int) -> np.ndarray:
    """(n, n) bool adjacency on the raster: the paper's procedure, pair by pair.

    Each unit's wall band is dilated; two units are adjacent when their dilated bands share a
    cell. (Labelling the union of all overlaps into connected components and reading adjacency
    from shared labels, literally as the paper's figure suggests, would make two units adjacent
    when only their overlaps with a third unit touch; the pairwise test avoids that.)
    The raster must hold every unit with its dilation (pad it).
    """
    rects = np.asarray(rects).reshape(-1, 4)
    n = len(rects)
    masks = [dilated_wall_mask(shape, r, wall, dilation) for r in rects]
    adj = np.zeros((n, n), dtype=bool)
    for p in range(n):
        for q in range(p + 1, n):
            adj[p, q] = adj[q, p] = bool(np.any(masks[p] & masks[q]))
    return adj
