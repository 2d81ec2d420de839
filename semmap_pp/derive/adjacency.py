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

import numba
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


@numba.njit(cache=True, nogil=True)
def _box_area(r0, c0, r1, c1):  # pragma: no cover - compiled
    return max(r1 - r0, 0) * max(c1 - c0, 0)


@numba.njit(cache=True, nogil=True)
def adjacency_row(rects, active, s, wall, dilation, out):  # pragma: no cover - compiled
    """Adjacency of slot ``s`` to every active slot, written into ``out`` (compiled twin of
    :func:`adjacency_rows` for the sampler's hot path; tests check they agree)."""
    a = rects[s]
    oa0, oa1, oa2, oa3 = a[0] - dilation, a[1] - dilation, a[2] + dilation, a[3] + dilation
    ia0, ia1 = a[0] + wall + dilation, a[1] + wall + dilation
    ia2, ia3 = a[2] - wall - dilation, a[3] - wall - dilation
    if ia2 <= ia0 or ia3 <= ia1:
        ia0 = ia1 = ia2 = ia3 = 0
    for t in range(rects.shape[0]):
        if t == s or not active[t]:
            out[t] = False
            continue
        b = rects[t]
        ob0, ob1, ob2, ob3 = b[0] - dilation, b[1] - dilation, b[2] + dilation, b[3] + dilation
        ib0, ib1 = b[0] + wall + dilation, b[1] + wall + dilation
        ib2, ib3 = b[2] - wall - dilation, b[3] - wall - dilation
        if ib2 <= ib0 or ib3 <= ib1:
            ib0 = ib1 = ib2 = ib3 = 0
        x0, x1, x2, x3 = max(oa0, ob0), max(oa1, ob1), min(oa2, ob2), min(oa3, ob3)
        left = _box_area(x0, x1, x2, x3)
        if left == 0:
            out[t] = False
            continue
        left -= _box_area(max(x0, ia0), max(x1, ia1), min(x2, ia2), min(x3, ia3))
        left -= _box_area(max(x0, ib0), max(x1, ib1), min(x2, ib2), min(x3, ib3))
        left += _box_area(max(x0, ia0, ib0), max(x1, ia1, ib1), min(x2, ia2, ib2),
                          min(x3, ia3, ib3))
        out[t] = left > 0
