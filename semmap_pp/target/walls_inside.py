"""Walls inside a unit: a check of W* against maps that show the outside of the building as free.

Where the input map marks the space around the building as free (a rendering that counts every
cell a long-range ray crossed, or unseen space saved as free), one unit over the whole map explains
the free cells best, and the building's walls end up *inside* it, read as clutter: W* is then
one or two units, whatever the model (the Radish map freiburg-079, whose outside is free, gives
2 units). A unit whose interior holds a large share of the map's wall-like cells (occupied runs
longer than ``object_max_extent``, :mod:`semmap_pp.target.likelihood`) shows it; the pipeline then adds a
note saying so (``[diagnostics] walls_inside_max``, docs/model.md). No unit of W* holds more than
5 % on cartesium, intel and aces, 12 % on the 30 synthetic floors (a hall with wall-like
furniture), 2 % on the ipa plans; on freiburg-079 one holds 100 %.

Examples
--------
A map of two rooms whose walls are wall-like (114 cells), one unit over all of it (the middle
wall's 18 cells lie inside it), one over the left room (none inside):

>>> import numpy as np
>>> from semmap_pp.target.likelihood import X_FREE, X_WALLLIKE
>>> x = np.full((20, 30), X_FREE, np.uint8)
>>> x[[0, 19], :] = X_WALLLIKE; x[:, [0, 15, 29]] = X_WALLLIKE
>>> walls_inside(x, np.array([[0, 0, 20, 30], [0, 0, 20, 16]]), wall=1).round(3).tolist()
[0.158, 0.0]
"""

from __future__ import annotations

import numpy as np

from semmap_pp.derive.states import _clip, interior
from semmap_pp.target.likelihood import X_WALLLIKE


def walls_inside(xcode: np.ndarray, rects: np.ndarray, wall: int) -> np.ndarray:
    """(n,) share of the map's wall-like cells lying in the interior (wall band excluded) of each
    of the units ``rects`` (n, 4); zeros when the map has no wall-like cell."""
    wall_like = np.asarray(xcode) == X_WALLLIKE
    total = int(np.count_nonzero(wall_like))
    rects = np.asarray(rects, dtype=np.int64).reshape(-1, 4)
    out = np.zeros(len(rects))
    if total == 0:
        return out
    for k, rect in enumerate(rects):
        r0, c0, r1, c1 = _clip(interior(rect, wall), wall_like.shape)
        if r1 > r0 and c1 > c0:
            out[k] = np.count_nonzero(wall_like[r0:r1, c0:c1]) / total
    return out


__all__ = ["walls_inside"]
