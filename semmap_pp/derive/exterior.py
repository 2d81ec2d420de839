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
that pass the test with cover too) whose own walls enclose at least three of their sides (a
corridor stub open at its end, held by its neighbour's cover, may reach out of the building and
does not widen the footprint). Fans are never enclosed, so they neither shield each other
nor widen the footprint; a world without such a unit has no footprint and no exterior unit,
and at least two units are always left (a world is never left without units; on a lattice of
several directions, where each tile's units are tested on their own, one unit per tile).

A fan in a concave corner of the building (beyond a window in one wing, against the outer wall
of the other) has two enclosed sides, the two outer walls, and lies within the convex hull. It
is exterior too when (a) rays leave it through its other two
sides (third largest share below ``max_share``), (b) each of its two enclosed sides is a wall
drawn in the map (seen, and its own occupied share at least ``max_share``, no cover counted) with an
enclosed unit right across it (at least ``max_share`` of a strip ``across`` cells deep beyond the
band), and (c) more than half of it lies outside the *orthogonal hull* of the units enclosed on
three sides (:func:`ortho_hull`; an L-shaped building is its own orthogonal hull). A room
glimpsed through its door, whose walls the laser did not draw, fails (b): its one enclosed side
with a unit across is the wall with the door. A fan in a notch between two enclosed wings (a U)
lies inside the orthogonal hull; in place of (c) it is told from a corridor piece between two
wings (open at its ends, both walls drawn, rooms across them) by how little of it the map shows:
rays spread out, so less than ``fan_seen_max`` of its interior cells are seen (free or
occupied), while a space the robot drove through is seen nearly whole.

Every rule above reads the building's extent off the units; a wing at another angle than the
lattice breaks them: its units fit its slanted walls poorly, so rays leave their sides, and the
wing lies outside the hulls of the units that fit. So a unit is flagged only when more than half
of it lies outside the building's own outline too (:func:`building_outline`): the walls the map
draws and all they enclose, gaps up to ``outline_gap`` cells (windows, exits) bridged, occupied
blobs no longer than ``object_extent`` (where rays outside end) not counted as walls. A unit the
building's walls enclose is never exterior. Where the outer wall has a wider gap (unseen, a glass
front) the outline lets the outside in, and the rules above decide alone.

A fan beyond a window between two wings can escape every rule above: the walls of both wings
enclose two of its sides, and the hull of a lattice's units spans the notch between them. Such a
unit is exterior by the outline alone when it has neither a door nor a passage to any other unit,
lies mostly outside the outline, shows less than ``fan_seen_max`` of its interior, and its own
walls line less than ``outline_walls_max`` of its perimeter. A room glimpsed through its door,
whose outer walls the laser never drew, lies outside the outline as well, but it opens onto the
corridor or the room it was seen from: W* gives it a door.

The hull of a lattice's enclosed units spans whatever lies between them (two wings of one
direction joined through a wing of another; a wing's corridor running past a hall), and a fan there
that rays leave through three sides escapes rule 2. Such a unit is exterior when more than half of
it lies outside the outline and the outline holds the building: at least ``outline_trust`` of
the cells of the enclosed units walled on three sides lie within it (:func:`outline_share`). A
map explored in part, whose rooms seen only through their doors were never walled in by the
laser, leaves them open to the outside; there the hull decides alone.

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

import functools

import numpy as np
from scipy import ndimage

from semmap_pp.cells import FREE, OCCUPIED, UNKNOWN, rects_mask


def _side_bands(rect, wall: int, beyond: int | None = None) -> tuple:
    """The (top, bottom, left, right) wall bands of ``rect`` as (r0, c0, r1, c1) boxes; with
    ``beyond``, the strips just outside each side instead, as deep as the band plus ``beyond``."""
    r0, c0, r1, c1 = (int(v) for v in rect)
    b = max(1, min(wall, r1 - r0, c1 - c0))
    if beyond is None:
        return ((r0, c0, r0 + b, c1), (r1 - b, c0, r1, c1),
                (r0, c0, r1, c0 + b), (r0, c1 - b, r1, c1))
    d = b + int(beyond)
    return ((r0 - d, c0, r0, c1), (r1, c0, r1 + d, c1), (r0, c0 - d, r1, c0), (r0, c1, r1, c1 + d))


def side_shares(classes: np.ndarray, rect, count: np.ndarray | None, wall: int, seen_min: float,
                own: int = 1) -> np.ndarray:
    """The enclosed share of each side band of ``rect`` (top, bottom, left, right).

    ``count`` is the number of units giving cover at each cell, ``own`` of them this unit itself
    (1 when it is counted in ``count``, else 0); None: no cover at all."""
    out = np.ones(4)
    for k, (ra, ca, rb, cb) in enumerate(_side_bands(rect, wall)):
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


def ortho_hull(rects: np.ndarray, shape) -> np.ndarray:
    """(H, W) bool: the orthogonal hull of the union of ``rects`` (clipped to ``shape``): the
    smallest set holding them whose every lattice row and column is one run, filled until stable.

    >>> L = np.array([[0, 0, 4, 2], [2, 0, 4, 6]])     # an L: its own orthogonal hull
    >>> int(ortho_hull(L, (6, 6)).sum()), int(ortho_hull(L, (6, 6))[0, 5])   # 8 + 12 - 4 cells
    (16, 0)
    >>> U = np.array([[0, 0, 4, 2], [2, 0, 4, 6], [0, 4, 4, 6]])   # a U: the notch is filled
    >>> int(ortho_hull(U, (6, 6))[0, 3])
    1
    """
    m = rects_mask(rects, shape)
    while True:
        new = m
        for axis in (0, 1):
            fwd = np.maximum.accumulate(new, axis=axis)
            back = np.flip(np.maximum.accumulate(np.flip(new, axis=axis), axis=axis), axis=axis)
            new = fwd & back
        if np.array_equal(new, m):
            return m
        m = new


def _seen_inside(classes: np.ndarray, rect, wall: int) -> float:
    """The share of ``rect``'s interior (its wall band excluded) seen in the map (free or
    occupied); 1.0 for a rectangle without interior."""
    r0, c0, r1, c1 = (int(v) for v in rect)
    inner = classes[max(r0 + wall, 0):max(r1 - wall, 0), max(c0 + wall, 0):max(c1 - wall, 0)]
    return float(np.count_nonzero(inner != UNKNOWN)) / inner.size if inner.size else 1.0


def _mask_outside_share(rect, mask: np.ndarray) -> float:
    """The share of ``rect``'s area outside ``mask`` (cells beyond the lattice count outside)."""
    r0, c0, r1, c1 = (int(v) for v in rect)
    area = max(r1 - r0, 0) * max(c1 - c0, 0)
    if area == 0:
        return 0.0
    inside = int(np.count_nonzero(mask[max(r0, 0):max(r1, 0), max(c0, 0):max(c1, 0)]))
    return 1.0 - inside / area


def _between_building_walls(classes, rect, shares, own, wall, seen_min, max_share, enclosed_mask,
                            across) -> bool:
    """Condition (b) of the module docstring for the two sides of ``rect`` with the largest
    ``shares`` (top, bottom, left, right); ``own``: the sides' shares without cover."""
    h, w = classes.shape
    bands = _side_bands(rect, wall)
    beyond = _side_bands(rect, wall, across)
    for side in np.argsort(shares, kind="stable")[2:]:
        ra, ca, rb, cb = bands[side]
        band = classes[max(ra, 0):max(rb, 0), max(ca, 0):max(cb, 0)]
        seen = np.count_nonzero(band != UNKNOWN)
        if seen < seen_min * max(band.size, 1) or own[side] < max_share:   # not a drawn wall
            return False
        ya, xa, yb, xb = beyond[side]
        strip = enclosed_mask[max(ya, 0):min(yb, h), max(xa, 0):min(xb, w)]
        if strip.size == 0 or strip.mean() < max_share:
            return False
    return True


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


def building_outline(classes: np.ndarray, gap: int, object_extent: int = 0) -> np.ndarray:
    """(H, W) bool: the cells within the building's outline, drawn by its own walls.

    The space outside is found as a disc of diameter ``gap`` cells rolling in from the lattice's
    border through free and unknown cells: its centres are the cells farther than ``gap / 2``
    from every occupied cell joined to the border (a wall's gaps no wider than ``gap``, windows
    and exits, keep it out), the space it sweeps is every cell within ``gap / 2`` of them; the
    outline holds the rest: the walls and everything they enclose. An outer wall with a wider
    gap (an unseen wall, a glass front) lets the disc in, and the rooms it reaches are outside.
    The walls are the occupied cells of 8-connected components longer than ``object_extent``
    cells along a lattice axis: the obstacles where rays through windows end (trees, cars,
    clutter outside) are objects, as inside a unit, and do not hold the disc back.

    >>> c = np.full((40, 40), UNKNOWN, np.uint8)
    >>> c[10, 10:30] = c[29, 10:30] = OCCUPIED; c[10:30, 10] = c[10:30, 29] = OCCUPIED
    >>> c[29, 18:22] = FREE                      # a 4-cell exit in the bottom wall
    >>> inside = building_outline(c, 6)
    >>> bool(inside[20, 20]), bool(inside[5, 5]), bool(inside[10, 20]), bool(building_outline(c, 3)[20, 20])
    (True, False, True, False)
    """
    c = np.asarray(classes)
    r = 0.5 * float(gap)
    pad = int(np.ceil(r)) + 1               # open space around the lattice: its border is outside
    occ = c == OCCUPIED
    if object_extent > 0 and occ.any():
        labels, _ = ndimage.label(occ, structure=np.ones((3, 3), bool))
        sizes = [0] + [max(sl[0].stop - sl[0].start, sl[1].stop - sl[1].start)
                       for sl in ndimage.find_objects(labels)]
        occ = (np.asarray(sizes) > object_extent)[labels] & occ
    occ = np.pad(occ, pad)
    if not occ.any():
        return np.zeros(c.shape, dtype=bool)
    # distance transforms rather than a closing with a disc: linear in the cells at any gap
    labels, _ = ndimage.label(ndimage.distance_transform_edt(~occ) > r)
    core = labels == labels[0, 0]
    swept = ndimage.distance_transform_edt(~core) <= r
    return ~swept[pad:pad + c.shape[0], pad:pad + c.shape[1]]


def _held_share(inside, rects: np.ndarray) -> float | None:
    """The share of the cells of ``rects`` (the units enclosed by walls of their own) that lie
    within the building's outline (``inside()``, made only when asked for); None without such
    cells. A map whose walls close the building (windows and exits bridged) holds nearly all of
    them; a map explored in part, whose rooms the robot saw only through their doors, leaves most
    of them open to the outside.

    >>> grid = np.zeros((6, 6), bool); grid[:3] = True
    >>> rects = np.array([[0, 0, 3, 6], [3, 0, 6, 2]])          # 18 cells inside, 6 outside
    >>> _held_share(lambda: grid, rects), _held_share(lambda: grid, rects[:0])
    (0.75, None)
    """
    if len(rects) == 0:
        return None
    mask = rects_mask(rects, inside().shape)
    return float(inside()[mask].mean()) if mask.any() else None


def _outside_the_outline(classes, rects, own, share, opened, taken, wall, outside_min,
                         fan_seen_max, walls_max, inside) -> list:
    """The ranking entries (as :func:`find_exterior` sorts them) of the units not in ``taken``
    that have no door and no passage (``opened``), show less than ``fan_seen_max`` of their
    interior, whose own walls (``own``: side shares without cover) line less than ``walls_max`` of
    their perimeter and that lie mostly outside the outline ``inside()`` (asked for only when a
    unit passes the rest): fans of rays beyond a window that the hulls keep in (module
    docstring)."""
    out = []
    for i in range(len(rects)):
        if (i in taken or opened[i] or _seen_inside(classes, rects[i], wall) >= fan_seen_max
                or perimeter_share(own[i], rects[i]) >= walls_max):
            continue
        o = _mask_outside_share(rects[i], inside())
        if o > outside_min:
            out.append(((-o, share[i], tuple(int(v) for v in rects[i])), i))
    return out


def enclosure(classes: np.ndarray, rects: np.ndarray, wall: int, max_share: float,
              seen_min: float) -> tuple:
    """How walls enclose each of ``rects`` (module docstring): ``(own, supported, shares,
    enclosed, walled)``, the sides' shares without cover (list of (4,) arrays), the supported
    units, the sides' shares with the supported units' cover ((n, 4)), the enclosed units, and the
    units whose own walls enclose three sides (the footprint is the hull of the enclosed ones
    among them; a corridor stub open at its end and held by its neighbour's cover may reach out of
    the building)."""
    own = [side_shares(classes, r, None, wall, seen_min, own=0) for r in rects]
    supported = np.array([np.sort(sh)[2] >= max_share and perimeter_share(sh, r) >= max_share
                          for sh, r in zip(own, rects)], dtype=bool).reshape(len(rects))
    count = np.zeros(classes.shape, dtype=np.int32)
    for r0, c0, r1, c1 in rects[supported]:
        count[max(r0, 0):max(r1, 0), max(c0, 0):max(c1, 0)] += 1
    shares = np.array([side_shares(classes, r, count, wall, seen_min, own=int(sup))
                       for r, sup in zip(rects, supported)]).reshape(len(rects), 4)
    enclosed = supported & (np.sort(shares, axis=1)[:, 2] >= max_share)
    walled = np.array([np.sort(sh)[1] >= max_share for sh in own], dtype=bool).reshape(len(rects))
    return own, supported, shares, enclosed, walled


def outline_share(classes: np.ndarray, rects: np.ndarray, wall: int, max_share: float,
                  seen_min: float, outline_gap: int, object_extent: int = 0) -> float | None:
    """The share of the cells of the enclosed units walled on three sides (:func:`enclosure`)
    that lie within :func:`building_outline`: how well the outline holds the building (the
    ``outline_trust`` test of :func:`find_exterior`); None without such units or outline."""
    rects = np.asarray(rects, dtype=np.int64).reshape(-1, 4)
    if outline_gap <= 0 or len(rects) == 0:
        return None
    _own, _sup, _shares, enclosed, walled = enclosure(np.asarray(classes), rects, wall, max_share,
                                                      seen_min)
    return _held_share(functools.cache(lambda: building_outline(classes, outline_gap, object_extent)),
                       rects[enclosed & walled])


def find_exterior(classes: np.ndarray, rects: np.ndarray, wall: int, max_share: float,
                  seen_min: float, outside_min: float = 0.5, across: int = 3,
                  fan_seen_max: float = 0.0, outline_gap: int = 0,
                  object_extent: int = 0, outline_walls_max: float = 0.0,
                  opened=None, keep: int = 2, outline_trust: float = 0.0) -> np.ndarray:
    """(n,) bool: which of the units ``rects`` (n, 4) are exterior (module docstring); all False
    when ``max_share`` is 0 (the test is off). A unit is flagged when its second largest enclosed
    share is below ``max_share`` and more than ``outside_min`` of its area lies outside the
    building's footprint: the convex hull of the units that are enclosed (supported, and with a
    second largest share of at least ``max_share``) with walls of their own on three sides (own
    third largest share at least ``max_share``); a fan of rays through a door into a room
    the robot never entered lies within it. Fans are never supported, so they add nothing to the
    footprint and do not shield each other; without an enclosed unit nothing is flagged. A unit
    with two open sides is flagged when it lies between two drawn building walls and outside the
    orthogonal hull of the units enclosed on three sides (module docstring; ``across``: cells
    beyond a side's band in which the enclosed unit across it is looked for; inside that hull, such
    a unit is flagged when less than ``fan_seen_max`` of its interior is seen, 0: never). At
    least two units are left: candidates are flagged the one most outside the footprint first
    (ties: the lower share, then the rectangle), so the result does not depend on the order of
    ``rects``. With ``outline_gap`` (cells, 0: off) a unit is flagged only when more than
    ``outside_min`` of its area lies outside :func:`building_outline` too (``object_extent``: the
    longest occupied component that is an object, not a wall): a unit the building's walls
    enclose is never exterior. With ``outline_walls_max`` (0: off) and ``opened`` ((n,) bool: the
    units with a door or a passage to another unit) a unit the rules above keep is exterior when it
    has no door and no passage, more than ``outside_min`` of it lies outside the outline, less than
    ``fan_seen_max`` of its interior is seen and its own walls line less than
    ``outline_walls_max`` of its perimeter (:func:`_outside_the_outline`). With ``outline_trust``
    (0: off) a unit that rays leave through three sides is flagged when more than ``outside_min``
    of it lies outside the outline, inside the hull or not, provided the outline holds the building:
    at least ``outline_trust`` of the cells of the enclosed units walled on three sides lie within
    it (:func:`_held_share`). At least ``keep`` of
    ``rects`` stay in the building (2: a world is never left without units; the units of one tile
    of a tiled lattice keep 1, the world's other tiles holding the rest)."""
    classes = np.asarray(classes)
    rects = np.asarray(rects, dtype=np.int64).reshape(-1, 4)
    n = len(rects)
    exterior = np.zeros(n, dtype=bool)
    if max_share <= 0.0 or n <= keep:
        return exterior
    own, supported, shares, enclosed, walled = enclosure(classes, rects, wall, max_share, seen_min)
    ranked = np.sort(shares, axis=1)
    share = ranked[:, 2]                                   # the second largest share
    hull = _hull(rects[enclosed & walled])
    if hull is None:                # no unit enclosed: no footprint to be outside of
        return exterior
    enclosed_mask = rects_mask(rects[enclosed], classes.shape)
    three_sides = rects[supported & (ranked[:, 1] >= max_share)]
    ortho = None                    # built when a unit first needs it
    # the building's own outline, made once and only when a unit needs it; so is the test of
    # whether it holds the building
    inside = functools.cache(lambda: building_outline(classes, outline_gap, object_extent))
    trusted = functools.cache(lambda: outline_gap > 0 and outline_trust > 0.0 and (
        _held_share(inside, rects[enclosed & walled]) or 0.0) >= outline_trust)
    order = []
    for i in range(n):
        out = _outside_share(rects[i], hull) if share[i] < max_share else 0.0
        if (out <= outside_min and ranked[i, 1] < max_share and len(three_sides)
                and _between_building_walls(classes, rects[i], shares[i], own[i], wall,
                                            seen_min, max_share, enclosed_mask, across)):
            if ortho is None:
                ortho = ortho_hull(three_sides, classes.shape)
            out = _mask_outside_share(rects[i], ortho)
            if out <= outside_min and _seen_inside(classes, rects[i], wall) < fan_seen_max:
                out = 1.0               # a fan in a notch: flagged first, as wholly outside
        if out <= outside_min and share[i] < max_share and trusted():   # a fan the hull spans
            out = _mask_outside_share(rects[i], inside())
        if out > outside_min:
            order.append(((-out, share[i], tuple(int(v) for v in rects[i])), i))
    if order and outline_gap > 0:   # what the building's walls enclose stays in
        order = [(key, i) for key, i in order if _mask_outside_share(rects[i], inside()) > outside_min]
    if outline_walls_max > 0.0 and outline_gap > 0 and opened is not None:
        order += _outside_the_outline(classes, rects, own, share, opened, {i for _k, i in order},
                                      wall, outside_min, fan_seen_max, outline_walls_max, inside)
    for _key, i in sorted(order)[:max(n - keep, 0)]:
        exterior[i] = True
    return exterior


__all__ = ["building_outline", "enclosure", "find_exterior", "ortho_hull", "outline_share",
           "perimeter_share", "side_shares"]
