"""Exterior units: free space seen from inside the building through its windows and exits.

A laser sees through glass and open exits, so an occupancy map holds fans of free rays outside
the building. They are free space, and the sampler covers them with units (every covered free cell
is explained), but they are not rooms of the building. A unit is *exterior* when rays leave it
through at least three of its four sides: per side, the *enclosed share* of its wall band is

    (occupied cells + free cells inside another, *supported* unit) / (occupied + free cells)

(free cells that continue into a neighbouring unit are a shared boundary, not a ray leaving the
building; a side with fewer seen cells than ``seen_min`` of its band counts as enclosed), and the
unit is exterior when its second largest share is below ``max_share``. A unit is supported when
it passes that test on its own walls (no cover counted) and its own walls enclose at least
``max_share`` of its perimeter (the sides' shares weighted by their lengths): pieces of a corridor
cover each other, but two fans side by side do not, nor does a strip inside a fan that is closed
only at its two short ends.
Rays also leave a unit that covers the part of a room seen through its door (a room the robot
never entered); such a unit lies within the building's footprint, so a unit is flagged only when
more than half its area lies outside the convex hull of the *enclosed* units (supported ones
that pass the test with cover too). Fans are never enclosed, so they neither shield each other
nor widen the footprint; a world without an enclosed unit has no footprint and no exterior unit,
and at least two units are always left (a world is never left without units).

The flag changes nothing in the posterior: exterior units keep their cells' states (and so the
CPR); the outputs list them apart from the building's units (world.json ``exterior``), and
labels.png, doors, adjacency and objects hold the building's units only (docs/model.md,
"Exterior units").

Examples
--------
Two rooms, the upper one with a window in its right wall, and a fan of rays beyond the window:
free cells leave the fan's unit through its top, bottom and right sides; its left side is the
wall with the window.

>>> import numpy as np
>>> cls = np.ones((30, 30), np.uint8)
>>> cls[2:28, 2:14] = 2; cls[3:15, 3:13] = 0; cls[16:27, 3:13] = 0   # two rooms in walls
>>> cls[6:10, 13] = 0                         # a window in the upper room's right wall
>>> cls[1:20, 14:28] = 0                      # free space seen beyond the window
>>> rects = np.array([[2, 2, 16, 14], [2, 13, 18, 28], [15, 2, 28, 14]])
>>> find_exterior(cls, rects, wall=1, max_share=0.3, seen_min=0.1).tolist()
[False, True, False]
"""

from __future__ import annotations

import numpy as np

from semmap_pp.cells import FREE, OCCUPIED


def side_shares(classes: np.ndarray, rect, count: np.ndarray | None, wall: int, seen_min: float,
                own: int = 1) -> np.ndarray:
    """The enclosed share of each side band of ``rect`` (top, bottom, left, right).

    ``count`` is the number of units giving cover at each cell, ``own`` of them this unit itself
    (1 when it is counted in ``count``, else 0); None: no cover at all."""
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
        shared = 0 if count is None else int(np.count_nonzero(free & (count[ra:rb, ca:cb] > own)))
        seen = occ + n_free
        if seen > 0 and seen >= seen_min * cls.size:
            out[k] = (occ + shared) / seen
    return out


def perimeter_share(shares: np.ndarray, rect) -> float:
    """The enclosed share of ``rect``'s whole perimeter: its sides' ``shares`` (top, bottom, left,
    right, as :func:`side_shares`) weighted by the sides' lengths.

    >>> perimeter_share(np.array([1.0, 1.0, 0.0, 0.0]), (0, 0, 12, 3))   # closed at its short ends
    0.2
    """
    h, w = float(rect[2] - rect[0]), float(rect[3] - rect[1])
    lens = np.array([w, w, h, h])
    return float(np.dot(shares, lens) / lens.sum()) if lens.sum() > 0 else 0.0


def _outside_share(rect, hull) -> float:
    """The share of ``rect``'s area outside the convex polygon ``hull`` ((k, 2) lattice points in
    order), on a grid of 10 x 10 sample points; 1.0 without a hull (fewer than 3 points)."""
    r0, c0, r1, c1 = (float(v) for v in rect)
    if hull is None:
        return 1.0
    t = (np.arange(10) + 0.5) / 10.0
    rr, cc = np.meshgrid(r0 + t * (r1 - r0), c0 + t * (c1 - c0), indexing="ij")
    pts = np.stack([rr.ravel(), cc.ravel()], axis=1)
    a, b = hull, np.roll(hull, -1, axis=0)
    cross = ((b[:, 0] - a[:, 0])[None, :] * (pts[:, 1, None] - a[:, 1][None, :])
             - (b[:, 1] - a[:, 1])[None, :] * (pts[:, 0, None] - a[:, 0][None, :]))
    inside = np.all(cross >= -1e-9, axis=1) | np.all(cross <= 1e-9, axis=1)
    return float(1.0 - inside.mean())


def _hull(rects: np.ndarray):
    """Convex hull (counter-clockwise points) of the corners of ``rects``, or None if degenerate."""
    if len(rects) == 0:
        return None
    pts = np.unique(np.concatenate([rects[:, [0, 1]], rects[:, [0, 3]], rects[:, [2, 1]],
                                    rects[:, [2, 3]]]).astype(float), axis=0)
    if len(pts) < 3:
        return None
    pts = pts[np.lexsort((pts[:, 1], pts[:, 0]))]

    def half(points):
        out = []
        for p in points:
            while len(out) >= 2 and ((out[-1][0] - out[-2][0]) * (p[1] - out[-2][1])
                                     - (out[-1][1] - out[-2][1]) * (p[0] - out[-2][0])) <= 0:
                out.pop()
            out.append(p)
        return out

    lower, upper = half(pts), half(pts[::-1])
    hull = np.array(lower[:-1] + upper[:-1])
    return hull if len(hull) >= 3 else None


def find_exterior(classes: np.ndarray, rects: np.ndarray, wall: int, max_share: float,
                  seen_min: float, outside_min: float = 0.5) -> np.ndarray:
    """(n,) bool: which of the units ``rects`` (n, 4) are exterior (module docstring); all False
    when ``max_share`` is 0 (the test is off). A unit is flagged when its second largest enclosed
    share is below ``max_share`` and more than ``outside_min`` of its area lies outside the
    building's footprint: the convex hull of the units that are enclosed (supported, and with a
    second largest share of at least ``max_share``); a fan of rays through a door into a room
    the robot never entered lies within it. Fans are never supported, so they add nothing to the
    footprint and do not shield each other; without an enclosed unit nothing is flagged. At
    least two units are left: candidates are flagged the one most outside the footprint first
    (ties: the lower share, then the rectangle), so the result does not depend on the order of
    ``rects``."""
    classes = np.asarray(classes)
    rects = np.asarray(rects, dtype=np.int64).reshape(-1, 4)
    n = len(rects)
    exterior = np.zeros(n, dtype=bool)
    if max_share <= 0.0 or n < 3:
        return exterior
    own = [side_shares(classes, r, None, wall, seen_min, own=0) for r in rects]
    supported = np.array([np.sort(sh)[2] >= max_share and perimeter_share(sh, r) >= max_share
                          for sh, r in zip(own, rects)])
    count = np.zeros(classes.shape, dtype=np.int32)
    for r0, c0, r1, c1 in rects[supported]:
        count[max(r0, 0):max(r1, 0), max(c0, 0):max(c1, 0)] += 1
    share = np.array([np.sort(side_shares(classes, r, count, wall, seen_min, own=int(sup)))[2]
                      for r, sup in zip(rects, supported)])
    hull = _hull(rects[supported & (share >= max_share)])
    if hull is None:                # no unit enclosed: no footprint to be outside of
        return exterior
    order = []
    for i in np.flatnonzero(share < max_share):
        out = _outside_share(rects[i], hull)
        if out > outside_min:
            order.append(((-out, share[i], tuple(int(v) for v in rects[i])), i))
    for _key, i in sorted(order)[:max(n - 2, 0)]:
        exterior[i] = True
    return exterior


__all__ = ["find_exterior", "perimeter_share", "side_shares"]
