"""Cell classes, stated once for the whole project.

Arrays are indexed ``[row, col]`` with row 0 the *top* row of the input image, exactly as the image
is stored. ``x`` means column and ``y`` means row wherever pixel coordinates are written as pairs
(``[x, y]``). Metric coordinates follow ROS map_server: the map origin is the *bottom-left* pixel, so
``x_m = origin_x + (col + 0.5) * resolution`` and ``y_m = origin_y + (height - row - 0.5) * resolution``
(see :mod:`semmap_pp.grid`).
"""

from __future__ import annotations

import numpy as np

# Classes of the input map C_M (uint8 codes).
FREE = np.uint8(0)
UNKNOWN = np.uint8(1)
OCCUPIED = np.uint8(2)
INPUT_CLASSES = ("free", "unknown", "occupied")

# States of a cell in a semantic world W (uint8 codes). Order matches the sensor-model columns.
W_WALL = np.uint8(0)
W_FREE = np.uint8(1)
W_OBJECT = np.uint8(2)
W_UNKNOWN = np.uint8(3)
WORLD_STATES = ("wall", "free", "object", "unknown")

# Unit types, in the order used by every marginal vector.
UNIT_TYPES = ("room", "corridor", "hall", "other")
#: The letter of each type, as overlay.png, graph.png and graph.graphml label units (the paper's Fig. 5c).
TYPE_LETTER = {"room": "R", "corridor": "C", "hall": "H", "other": "E"}


def known_box(classes) -> tuple[int, int, int, int] | None:
    """``(r0, c0, r1, c1)`` (ends excluded): the bounding box of the known (free or occupied) cells
    of an array of input classes; None when every cell is unknown.

    >>> c = np.full((4, 6), UNKNOWN); c[1, 2] = FREE; c[2, 4] = OCCUPIED
    >>> known_box(c), known_box(np.full((2, 2), UNKNOWN))
    ((1, 2, 3, 5), None)
    """
    return mask_box(np.asarray(classes) != UNKNOWN)


def mask_box(mask) -> tuple[int, int, int, int] | None:
    """``(r0, c0, r1, c1)`` (ends excluded): the bounding box of the True cells of a 2-D mask;
    None when there are none (:func:`known_box` for a mask already made).

    >>> mask_box(np.eye(3, dtype=bool)[::-1]), mask_box(np.zeros((2, 2), bool))
    ((0, 0, 3, 3), None)
    """
    mask = np.asarray(mask, dtype=bool)
    rows, cols = np.flatnonzero(mask.any(axis=1)), np.flatnonzero(mask.any(axis=0))
    if rows.size == 0:
        return None
    return int(rows[0]), int(cols[0]), int(rows[-1]) + 1, int(cols[-1]) + 1


def rects_mask(rects, shape) -> np.ndarray:
    """(H, W) bool: the cells of the rectangles ``rects`` (n, 4; ``(r0, c0, r1, c1)``, ends
    excluded, negative sides clipped at 0) on a lattice of ``shape``.

    >>> rects_mask([(0, 1, 2, 3), (-1, -1, 1, 1)], (3, 3)).astype(int).tolist()
    [[1, 1, 1], [0, 1, 1], [0, 0, 0]]
    """
    m = np.zeros(shape, dtype=bool)
    for r0, c0, r1, c1 in np.asarray(rects, dtype=np.int64).reshape(-1, 4):
        m[max(r0, 0):max(r1, 0), max(c0, 0):max(c1, 0)] = True
    return m


def border_cells(a: np.ndarray) -> np.ndarray:
    """The first and last row and column of the 2-D array ``a``, each cell once.

    >>> border_cells(np.arange(12).reshape(3, 4)).tolist()
    [0, 1, 2, 3, 8, 9, 10, 11, 4, 7]
    """
    if a.shape[0] < 3 or a.shape[1] < 3:
        return a.ravel()
    return np.concatenate([a[0], a[-1], a[1:-1, 0], a[1:-1, -1]])
