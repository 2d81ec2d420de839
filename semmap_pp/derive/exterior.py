"""Exterior units: free space seen from inside the building through its windows and exits.

A laser sees through glass and open exits, so an occupancy map holds fans of free rays outside
the building. They are free space, and the sampler covers them with units (every covered free cell
is explained), but they are not rooms of the building. A unit is *exterior* when rays leave it
through at least three of its four sides: per side, the *enclosed share* of its wall band is

    (occupied cells + free cells inside another, non-exterior unit) / (occupied + free cells)

(free cells that continue into a neighbouring unit are a shared boundary, not a ray leaving the
building; a side with fewer seen cells than ``seen_min`` of its band counts as enclosed), and the
unit is exterior when its second largest share is below ``max_share``. A unit next to an exterior
unit loses that neighbour's cover, so the test is repeated until no further unit is flagged.

The flag changes nothing in the posterior: exterior units keep their cells' states (and so the
CPR); the outputs list them apart from the building's units (world.json ``exterior``), and
labels.png, doors, adjacency and objects hold the building's units only (docs/model.md,
"Exterior units").

Examples
--------
A room closed by walls on three sides and open to its right neighbour, which is a fan: free cells
leaving through its top, bottom and right sides.

>>> import numpy as np
>>> cls = np.ones((20, 30), np.uint8)
>>> cls[2:18, 2:14] = 0                       # room interior
>>> cls[2:18, 2] = 2; cls[2, 2:14] = 2; cls[17, 2:14] = 2; cls[2:18, 13] = 2   # its walls
>>> cls[8:12, 13] = 0                         # a window in the right wall
>>> cls[2:18, 14:28] = 0                      # rays beyond the window
>>> rects = np.array([[2, 2, 18, 14], [2, 13, 18, 28]])
>>> find_exterior(cls, rects, wall=1, max_share=0.3, seen_min=0.1).tolist()
[False, True]
"""

from __future__ import annotations

import numpy as np

from semmap_pp.cells import FREE, OCCUPIED


def side_shares(classes: np.ndarray, rect, count: np.ndarray, wall: int, seen_min: float) -> np.ndarray:
    """The enclosed share of each side band of ``rect`` (top, bottom, left, right).

    ``count`` is the number of non-exterior units covering each cell, this unit included."""
    r0, c0, r1, c1 = (int(v) for v in rect)
    b = max(1, min(wall, r1 - r0, c1 - c0))
    bands = ((r0, c0, r0 + b, c1), (r1 - b, c0, r1, c1), (r0, c0, r1, c0 + b), (r0, c1 - b, r1, c1))
    out = np.ones(4)
    for k, (ra, ca, rb, cb) in enumerate(bands):
        ra, ca = max(ra, 0), max(ca, 0)
        cls = classes[ra:rb, ca:cb]
        if cls.size == 0:
            continue
        occ = int(np.count_nonzero(cls == OCCUPIED))
        free = cls == FREE
        n_free = int(np.count_nonzero(free))
        shared = int(np.count_nonzero(free & (count[ra:rb, ca:cb] > 1)))
        seen = occ + n_free
        if seen > 0 and seen >= seen_min * cls.size:
            out[k] = (occ + shared) / seen
    return out


def find_exterior(classes: np.ndarray, rects: np.ndarray, wall: int, max_share: float,
                  seen_min: float) -> np.ndarray:
    """(n,) bool: which of the units ``rects`` (n, 4) are exterior (module docstring); all False
    when ``max_share`` is 0 (the test is off). Each round tests every unit not yet flagged against
    the same cover, so the result does not depend on the order of ``rects``."""
    classes = np.asarray(classes)
    rects = np.asarray(rects, dtype=np.int64).reshape(-1, 4)
    n = len(rects)
    exterior = np.zeros(n, dtype=bool)
    if max_share <= 0.0 or n == 0:
        return exterior
    count = np.zeros(classes.shape, dtype=np.int32)
    for r0, c0, r1, c1 in rects:
        count[max(r0, 0):max(r1, 0), max(c0, 0):max(c1, 0)] += 1
    while True:
        new = [i for i in np.flatnonzero(~exterior)
               if np.sort(side_shares(classes, rects[i], count, wall, seen_min))[2] < max_share]
        if not new:
            return exterior
        for i in new:
            r0, c0, r1, c1 = rects[i]
            exterior[i] = True
            count[max(r0, 0):max(r1, 0), max(c0, 0):max(c1, 0)] -= 1


__all__ = ["find_exterior", "side_shares"]
