"""World cell states WALL / FREE / OBJECT / UNKNOWN on the lattice, and the objects of each unit.

Output definition (the paper; docs/outputs.md): a cell outside every unit is UNKNOWN; a cell in some
unit's wall band is WALL, unless it is a door or passage cell (FREE: where the wall two units
share is open); an interior cell is OBJECT when the
input is unknown (the paper: "unknown cells of the input map that are located within a unit are
considered as object cells") or when it is occupied and its 8-connected component of non-free
cells *within that unit's interior* spans at most ``object_max_extent`` cells along both axes;
otherwise FREE. A cell inside several interiors is OBJECT if any of them makes it one.

The likelihood (:mod:`semmap_pp.target.likelihood`) uses a per-map approximation of the occupied-cell
rule (wall-like = on a straight run longer than ``object_max_extent``); :func:`cell_states` with
``objects="lines"`` reproduces it, and docs/model.md compares the two.

Examples
--------
>>> import numpy as np
>>> cls = np.zeros((8, 8), np.uint8); cls[3, 3] = 2; cls[4, 5] = 1
>>> s = cell_states(cls, np.array([[1, 1, 7, 7]]), wall=1, object_max_extent=2)
>>> [int(s[0, 0]), int(s[1, 1]), int(s[3, 3]), int(s[4, 5]), int(s[2, 2])]  # unknown wall object object free
[3, 0, 2, 2, 1]
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from scipy import ndimage

from semmap_pp.cells import FREE, OCCUPIED, UNKNOWN, W_FREE, W_OBJECT, W_UNKNOWN, W_WALL

EIGHT = np.ones((3, 3), dtype=bool)


class Object(NamedTuple):
    """A connected component of non-free input cells inside one unit's interior.

    ``box`` is its lattice bounding box ``(r0, c0, r1, c1)`` (half-open), ``cells`` its size.
    """

    unit: int
    box: tuple
    cells: int


def interior(rect, wall: int) -> tuple[int, int, int, int]:
    r0, c0, r1, c1 = (int(v) for v in rect)
    return r0 + wall, c0 + wall, r1 - wall, c1 - wall


def _clip(box, shape):
    r0, c0, r1, c1 = box
    return max(r0, 0), max(c0, 0), min(r1, shape[0]), min(c1, shape[1])


def unit_objects(classes: np.ndarray, rect, wall: int, object_max_extent: int,
                 unit: int = 0) -> tuple[list[Object], np.ndarray]:
    """Objects of one unit and the interior mask of its occupied-object cells.

    Components are 8-connected components of non-free input cells (occupied or unknown) within
    the unit's interior; an object spans at most ``object_max_extent`` cells along both axes.

    Returns
    -------
    objects : list of Object
    occupied_object : (h, w) bool
        Over the clipped interior box: occupied cells that belong to an object.
    """
    r0, c0, r1, c1 = _clip(interior(rect, wall), classes.shape)
    if r0 >= r1 or c0 >= c1:
        return [], np.zeros((0, 0), bool)
    sub = classes[r0:r1, c0:c1]
    labels, n = ndimage.label(sub != FREE, structure=EIGHT)
    objects = []
    small = np.zeros(n + 1, dtype=bool)
    for k, sl in enumerate(ndimage.find_objects(labels), start=1):
        if sl is None:
            continue
        h, w = sl[0].stop - sl[0].start, sl[1].stop - sl[1].start
        if max(h, w) <= object_max_extent:
            small[k] = True
            size = int(np.count_nonzero(labels[sl] == k))
            objects.append(Object(int(unit), (r0 + sl[0].start, c0 + sl[1].start,
                                              r0 + sl[0].stop, c0 + sl[1].stop), size))
    return objects, small[labels] & (sub == OCCUPIED)


def seen_shares(classes: np.ndarray, rect, wall: int) -> tuple[float, float]:
    """``(interior, wall band)``: the share of each part of the unit ``rect`` that the map shows
    (free or occupied input cells; unknown cells and cells beyond the lattice are not shown).

    Near 1 for a room the robot drove through. A room glimpsed through its door has its outline
    partly unseen: the part of its wall band the map does not show is inferred, not observed (W*
    puts a wall there because the target does, not because the map shows one).

    >>> cls = np.full((10, 10), UNKNOWN, np.uint8); cls[0:10, 0:5] = OCCUPIED; cls[1:9, 1:5] = FREE
    >>> seen_shares(cls, (0, 0, 10, 10), wall=1)   # the left half seen: 32 of 64 inside, 18 of 36 band
    (0.5, 0.5)
    """
    r0, c0, r1, c1 = (int(v) for v in rect)
    seen = classes != UNKNOWN

    def count(box):
        a0, b0, a1, b1 = _clip(box, classes.shape)
        return int(np.count_nonzero(seen[a0:a1, b0:b1])) if a0 < a1 and b0 < b1 else 0

    i0, j0, i1, j1 = interior(rect, wall)
    n_all = max(r1 - r0, 0) * max(c1 - c0, 0)
    n_in = max(i1 - i0, 0) * max(j1 - j0, 0)
    s_all = count((r0, c0, r1, c1))
    s_in = count((i0, j0, i1, j1)) if n_in else 0
    band = n_all - n_in
    return (s_in / n_in if n_in else 0.0, (s_all - s_in) / band if band else 0.0)


def find_objects(classes: np.ndarray, rects: np.ndarray, wall: int, object_max_extent: int,
                 slots=None) -> list[Object]:
    """Objects of every unit (``rects`` (n, 4); ``slots`` their ids, default 0..n-1)."""
    rects = np.asarray(rects).reshape(-1, 4)
    slots = np.arange(len(rects)) if slots is None else np.asarray(slots)
    out = []
    for rect, s in zip(rects, slots):
        out += unit_objects(classes, rect, wall, object_max_extent, int(s))[0]
    return out


def cell_states(classes: np.ndarray, rects: np.ndarray, wall: int, object_max_extent: int,
                doors=(), objects: str = "components", wall_like: np.ndarray | None = None):
    """(H', W') uint8 world cell states (``cells.W_*``) of the units ``rects`` (n, 4).

    Parameters
    ----------
    classes : (H', W') uint8
        Lattice input classes.
    rects : (n, 4)
    wall, object_max_extent : int
        In cells.
    doors : iterable of Door
        Door (and passage) boxes become FREE.
    objects : {"components", "lines"}
        "components": the per-unit connected-component rule (the output definition);
        "lines": the likelihood's rule, occupied cells are objects unless ``wall_like``.
    wall_like : (H', W') bool
        Required for ``objects="lines"`` (:func:`semmap_pp.target.likelihood.wall_like`).
    """
    shape = classes.shape
    band = np.zeros(shape, np.int32)     # number of units with the cell in their wall band
    inside = np.zeros(shape, bool)       # in some interior
    is_obj = np.zeros(shape, bool)       # an object cell of some interior
    for rect in np.asarray(rects).reshape(-1, 4):
        r0, c0, r1, c1 = _clip(rect, shape)
        if r0 >= r1 or c0 >= c1:
            continue
        band[r0:r1, c0:c1] += 1
        i0, j0, i1, j1 = _clip(interior(rect, wall), shape)
        if i0 >= i1 or j0 >= j1:
            continue
        band[i0:i1, j0:j1] -= 1
        inside[i0:i1, j0:j1] = True
        sub = classes[i0:i1, j0:j1]
        if objects == "components":
            occ_obj = unit_objects(classes, rect, wall, object_max_extent)[1]
        elif objects == "lines":
            occ_obj = (sub == OCCUPIED) & ~wall_like[i0:i1, j0:j1]
        else:
            raise ValueError(f"objects must be 'components' or 'lines', got {objects!r}")
        is_obj[i0:i1, j0:j1] |= (sub == UNKNOWN) | occ_obj
    states = np.full(shape, W_UNKNOWN, dtype=np.uint8)
    states[inside] = np.where(is_obj[inside], W_OBJECT, W_FREE)
    states[band > 0] = W_WALL
    for d in doors:
        r0, c0, r1, c1 = _clip(d.box, shape)
        states[r0:r1, c0:c1] = W_FREE
    return states
