"""Topological defects: adjacent rooms whose connecting walls differ in length.

Two rooms that share a wall in a real building usually line up along it: the knowledge rules make
such pairs SaLe ("same length") and the prior rewards a small difference ``d`` of their connecting
walls with ``exp(-d^2 / 2 sigma^2)`` (:func:`semmap_pp.target.prior.connecting_length_difference`). A
*topological defect* is a pair of adjacent units, both typed room, whose ``d`` exceeds a tolerance
(``[diagnostics] defect_tolerance_m`` of the model file). ``semmap compare`` counts them in W* and
averages them over sampled worlds, to show what a knowledge set buys.

Examples
--------
Two rooms side by side (columns), 1 cell = 0.1 m, walls 1 cell thick, adjacency dilation 1 cell:
the left one is 20 cells high, the right one 12, so their connecting walls differ by 0.8 m.

>>> import numpy as np
>>> from semmap_pp import world as wm
>>> w = wm.add(wm.add(wm.empty(3), 0, (0, 0, 20, 10), 0), 1, (0, 9, 12, 20), 0)
>>> [(d.p, d.q, round(d.difference_m, 3)) for d in topological_defects(w, 0.1, 1, 1, 0.5)]
[(0, 1, 0.8)]
>>> topological_defects(w, 0.1, 1, 1, 1.0)     # within a 1 m tolerance
[]
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from semmap_pp import world as wm
from semmap_pp.cells import UNIT_TYPES
from semmap_pp.derive.adjacency import adjacency_matrix
from semmap_pp.target.prior import connecting_length_difference

ROOM = UNIT_TYPES.index("room")
# Rounding slack (a fraction of a cell): 6 cells * 0.1 m is 0.6000000000000001, not more than 0.6 m.
_SLACK = 1e-6


class Defect(NamedTuple):
    """One defect: the slots of the two rooms and the length difference of their connecting walls."""

    p: int
    q: int
    difference_m: float


def topological_defects(world: wm.World, resolution: float, wall: int, dilation: int,
                        tolerance_m: float) -> list[Defect]:
    """Adjacent room pairs of ``world`` whose connecting walls differ by more than ``tolerance_m``.

    Parameters
    ----------
    world : World
        Types assigned (``world.types``; untyped units are never rooms).
    resolution : float
        Metres per lattice cell.
    wall, dilation : int
        Wall band and adjacency dilation in cells (``frame.cells.wall``, ``.adjacency_dilation``).
    tolerance_m : float

    Returns
    -------
    list of Defect
        Ordered by slot pair, ``p < q``.
    """
    slots = wm.active_slots(world)
    rooms = slots[np.asarray(world.types)[slots] == ROOM]
    if len(rooms) < 2:
        return []
    rects = np.asarray(world.rects)[rooms].astype(np.int64)
    adj = adjacency_matrix(rects, wall, dilation)
    i, j = np.nonzero(np.triu(adj, 1))
    if i.size == 0:
        return []
    d = connecting_length_difference(rects[i], rects[j], resolution)
    limit = tolerance_m + _SLACK * resolution
    return [Defect(int(rooms[a]), int(rooms[b]), float(x)) for a, b, x in zip(i, j, d) if x > limit]


def count_defects(worlds, resolution: float, wall: int, dilation: int, tolerance_m: float) -> np.ndarray:
    """Number of defects of each world in ``worlds`` (an int array, one entry per world)."""
    return np.array([len(topological_defects(w, resolution, wall, dilation, tolerance_m)) for w in worlds],
                    dtype=np.int64)


__all__ = ["Defect", "topological_defects", "count_defects", "ROOM"]
