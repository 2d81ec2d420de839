"""Doors: runs of free cells on the wall two adjacent units share (paper Sec. III-B, docs/model.md).

For two units ``p`` and ``q`` the *connecting wall* is the strip between their facing wall bands:
when they sit side by side along the columns (their column gap exceeds their row gap) it is the
columns from the inner edge of the left unit's right band to the inner edge of the right unit's
left band, over the rows both interiors share; likewise with rows and columns swapped. Doors are
looked for on the map with its *specks* made free (:func:`semmap_pp.lattice.frame.doorway_classes`, kept by the frame as
``Frame.door_classes``): clusters of a few non-free cells, such as SLAM noise or a chair leg with
the unseen cell behind it, which would otherwise cut a door into two gaps too narrow to count (a
wall, a door jamb or a closed leaf is a long line of cells). A line of the strip across the wall
is *open* when every cell on it is free there. A door is a maximal run of open
lines whose width lies in ``[door_min, door_max]`` cells: a longer run is an open passage (the
two units are one space), a shorter one a gap in a noisy wall. A run that reaches within ``wall``
cells of both ends of the strip has no jamb on the shared wall — the whole boundary the two units
share is open, as where a corridor ends in a hall — and is an open passage too, whatever its width
(docs/model.md). A jamb is a wall the map shows: lines closed by unknown cells alone
(no occupied cell: the unseen margin along a wall, where a corridor narrows) count as reached, so
a corridor piece meeting the next through its whole seen width is joined by a passage
(CHANGELOG.md, quality change 40). A run that would be a passage is checked across the strip
widened by one wall band on each side (:func:`wide_lines`): a wall the shared band misses by a
cell or two walls the units apart, and only the stretches free there are openings
(:func:`_passage_or_doors`). Passages are not doors, but their cells are open: the
world's cell states make them FREE, as door cells (:mod:`semmap_pp.derive.states`).

Examples
--------
>>> import numpy as np
>>> from semmap_pp.model import load_model
>>> cells = load_model().cells(0.05)       # wall 2 cells, doors 10..50 cells
>>> free = np.zeros((60, 80), np.uint8)    # all free ...
>>> free[:, 38:42] = 2                     # ... but a wall at columns 38..41
>>> free[20:36, 38:42] = 0                 # with a 16-cell doorway
>>> [d.box for d in doors_between(free, (0, 0, 60, 40), (0, 40, 60, 80), cells)]
[(20, 38, 36, 42)]
"""

from __future__ import annotations

from typing import NamedTuple

import numba
import numpy as np

from semmap_pp.cells import FREE, OCCUPIED


class Door(NamedTuple):
    """A door between units (slots) ``p`` and ``q``.

    ``box`` is the lattice box ``(r0, c0, r1, c1)`` of its cells (half-open); ``vertical`` is True
    when the wall runs along the rows (the units sit side by side along the columns);
    ``width`` is the door's width in cells.
    """

    p: int
    q: int
    box: tuple
    vertical: bool
    width: int


def connecting_wall(rp, rq, wall: int):
    """The connecting-wall strip of two rectangles: ``(box, vertical)`` or ``None``.

    The strip spans the facing wall bands (and any gap between them) across the wall, and the
    rows (columns) that both interiors share along it.
    """
    rp = [int(v) for v in rp]
    rq = [int(v) for v in rq]
    col_gap = max(rp[1], rq[1]) - min(rp[3], rq[3])
    row_gap = max(rp[0], rq[0]) - min(rp[2], rq[2])
    vertical = col_gap >= row_gap
    a, b = (1, 0) if vertical else (0, 1)  # a: axis across the wall, b: axis along it
    left, right = (rp, rq) if rp[a] <= rq[a] else (rq, rp)
    lo = min(left[a + 2] - wall, right[a])
    hi = max(left[a + 2], right[a] + wall)
    s0 = max(rp[b], rq[b]) + wall
    s1 = min(rp[b + 2], rq[b + 2]) - wall
    if s1 <= s0 or hi <= lo:
        return None
    box = (s0, lo, s1, hi) if vertical else (lo, s0, hi, s1)
    return box, vertical


def open_runs(line_open: np.ndarray) -> list[tuple[int, int]]:
    """Maximal runs ``[start, stop)`` of True in a 1-D boolean array.

    >>> open_runs(np.array([0, 1, 1, 0, 1], bool))
    [(1, 3), (4, 5)]
    """
    x = np.concatenate([[False], np.asarray(line_open, bool), [False]]).astype(np.int8)
    d = np.diff(x)
    return list(zip(np.flatnonzero(d == 1).tolist(), np.flatnonzero(d == -1).tolist()))


def wall_strip(classes: np.ndarray, rp, rq, wall: int):
    """The map's cells on the connecting wall of ``rp`` and ``rq``: ``(strip, (a0, b0, a1, b1),
    vertical)``, the strip's lines across the wall along axis 1 when ``vertical`` (else axis 0);
    None without a connecting wall or when it leaves the map (nothing is seen through it)."""
    cw = connecting_wall(rp, rq, wall)
    if cw is None:
        return None
    (r0, c0, r1, c1), vertical = cw
    H, W = classes.shape
    a0, b0, a1, b1 = max(r0, 0), max(c0, 0), min(r1, H), min(c1, W)
    if a0 >= a1 or b0 >= b1:
        return None
    full_across = (b1 - b0) == (c1 - c0) if vertical else (a1 - a0) == (r1 - r0)
    if not full_across:
        return None
    return classes[a0:a1, b0:b1], (a0, b0, a1, b1), vertical


def openings_between(classes: np.ndarray, rp, rq, cells, p: int = 0,
                     q: int = 1) -> tuple[list[Door], list[Door]]:
    """``(doors, passages)`` on the connecting wall of units ``p`` (rectangle ``rp``) and ``q``
    (``rq``): maximal runs of open lines at least ``door_min`` wide; a run is a *passage* when it
    is wider than ``door_max`` or has no jamb on the shared wall (module docstring), else a door.

    Parameters
    ----------
    classes : (H', W') uint8
        Lattice input classes with their specks made free (``Frame.door_classes``,
        :func:`semmap_pp.lattice.frame.doorway_classes`).
    rp, rq : (r0, c0, r1, c1)
    cells : CellParams
        Wall thickness and door width limits in cells.
    """
    found = wall_strip(classes, rp, rq, cells.wall)
    if found is None:
        return [], []
    strip, (a0, b0, a1, b1), vertical = found
    line_open = (strip == FREE).all(axis=1 if vertical else 0)
    line_walled = (strip == OCCUPIED).any(axis=1 if vertical else 0)
    doors, passages = [], []
    n_lines = len(line_open)
    for s, e in open_runs(line_open):
        width = e - s
        if width < cells.door_min:
            continue
        box = (a0 + s, b0, a0 + e, b1) if vertical else (a0, b0 + s, a1, b0 + e)
        door = Door(int(p), int(q), tuple(int(v) for v in box), bool(vertical), width)
        while s > 0 and not line_walled[s - 1]:      # closed by unknown cells alone: no jamb
            s -= 1
        while e < n_lines and not line_walled[e]:
            e += 1
        no_jamb = s <= cells.wall and e >= n_lines - cells.wall
        if width > cells.door_max or no_jamb:
            d, p_ = _passage_or_doors(classes, rp, rq, cells, door, a0 if vertical else b0)
            doors += d
            passages += p_
        else:
            doors.append(door)
    return doors, passages


def wide_lines(classes: np.ndarray, rp, rq, wall: int):
    """Which lines of the connecting wall of ``rp`` and ``rq`` are free across the strip widened
    by one wall band on each side, within the two rectangles and the map (bool per line of
    :func:`wall_strip`'s strip), or None without a strip. A wall the shared band misses by a cell
    or two (a slanted wall, a band rounded to the lattice) closes these lines."""
    cw = connecting_wall(rp, rq, wall)
    if cw is None:
        return None
    (r0, c0, r1, c1), vertical = cw
    a = 1 if vertical else 0
    lo_unit = min(int(rp[a]), int(rq[a]))
    hi_unit = max(int(rp[a + 2]), int(rq[a + 2]))
    H, W = classes.shape
    if vertical:
        c0, c1 = max(c0 - wall, lo_unit, 0), min(c1 + wall, hi_unit, W)
        return (classes[max(r0, 0):min(r1, H), c0:c1] == FREE).all(axis=1)
    r0, r1 = max(r0 - wall, lo_unit, 0), min(r1 + wall, hi_unit, H)
    return (classes[r0:r1, max(c0, 0):min(c1, W)] == FREE).all(axis=0)


def _passage_or_doors(classes, rp, rq, cells, run: Door, first: int):
    """A run of open lines that would be a passage (too wide for a door, or without jambs),
    checked on the widened strip (:func:`wide_lines`): a passage when every one of its lines is
    free there too; else the two units are walled apart beside the band, and its stretches free
    there are the openings, each a door when at most ``door_max`` wide (their jambs are that
    wall), a passage when wider. A wall is a stretch of at least ``door_min`` closed lines:
    shorter ones (a jagged corner, a wall's end) are read as open. ``first``: the strip's first
    line index on the map."""
    wide = wide_lines(classes, rp, rq, cells.wall)
    lo = (run.box[0] if run.vertical else run.box[1]) - first
    part = wide[lo:lo + run.width].copy()
    for s, e in open_runs(~part):          # a wall is at least a door's width long; shorter
        if e - s < cells.door_min:         # closed stretches (a jagged corner) are ignored
            part[s:e] = True
    if part.all():
        return [], [run]
    doors, passages = [], []
    for s, e in open_runs(part):
        width = e - s
        if width < cells.door_min:
            continue
        k0 = (run.box[0] if run.vertical else run.box[1]) + s
        box = ((k0, run.box[1], k0 + width, run.box[3]) if run.vertical
               else (run.box[0], k0, run.box[2], k0 + width))
        (passages if width > cells.door_max else doors).append(run._replace(box=box, width=width))
    return doors, passages


def doors_between(classes: np.ndarray, rp, rq, cells, p: int = 0, q: int = 1) -> list[Door]:
    """The doors of :func:`openings_between` (passages left out)."""
    return openings_between(classes, rp, rq, cells, p, q)[0]


def find_openings(classes: np.ndarray, rects: np.ndarray, adj: np.ndarray, cells,
                  slots=None, cache: dict | None = None) -> tuple[list[Door], list[Door]]:
    """``(doors, passages)`` of a world: :func:`openings_between` for every adjacent pair.

    ``rects`` (n, 4) and ``adj`` (n, n) of the active units; ``slots`` their ids (default 0..n-1).
    ``cache`` (a dict kept across calls on one ``classes``): a pair's openings depend on its two
    rectangles alone, so they are kept by them and found once for all the worlds that hold the
    pair (labelled with each world's own slots).
    """
    rects = np.asarray(rects).reshape(-1, 4)
    slots = np.arange(len(rects)) if slots is None else np.asarray(slots)
    doors, passages = [], []
    for i, j in zip(*np.nonzero(np.triu(np.asarray(adj, bool), 1))):
        p, q = int(slots[i]), int(slots[j])
        if cache is None:
            d, g = openings_between(classes, rects[i], rects[j], cells, p, q)
        else:
            key = (*rects[i].tolist(), *rects[j].tolist())
            found = cache.get(key)
            if found is None:
                found = cache[key] = openings_between(classes, rects[i], rects[j], cells)
            d, g = ([o._replace(p=p, q=q) for o in kind] for kind in found)
        doors += d
        passages += g
    return doors, passages


def find_gap_passages(classes: np.ndarray, rects: np.ndarray, adj: np.ndarray, cells,
                      slots=None) -> list[Door]:
    """Passages between units that do not touch: two units that are not adjacent, face each
    other along a stretch both span and stand at most ``cells.passage_gap`` cells apart, joined
    where every line from one to the other is free and crosses no other unit (the opening rule of
    :func:`openings_between`, whatever its width or jambs). The search left that strip of floor
    to no unit, but a robot walks across it. Off when ``passage_gap`` is 0.

    >>> import numpy as np
    >>> from semmap_pp.model import load_model
    >>> cells = load_model().cells(0.05)       # wall 2 cells, gaps up to 20 cells
    >>> m = np.zeros((40, 60), np.uint8)       # all free
    >>> rects = np.array([(0, 0, 40, 20), (0, 26, 40, 60)])   # 6 free columns between them
    >>> [(d.p, d.q, d.width) for d in find_gap_passages(m, rects, np.zeros((2, 2), bool), cells)]
    [(0, 1, 36)]
    >>> rects = np.vstack([rects, [(10, 18, 20, 28)]])      # a third unit in the gap, rows 10..19:
    >>> [(d.box, d.width) for d in find_gap_passages(m, rects, np.zeros((3, 3), bool), cells)]
    [((20, 18, 38, 28), 18)]

    (the 8 free lines above it are narrower than a door.)
    """
    rects = np.asarray(rects).reshape(-1, 4)
    slots = np.arange(len(rects)) if slots is None else np.asarray(slots)
    gap_max = int(cells.passage_gap)
    out: list[Door] = []
    if gap_max <= 0:
        return out
    adj = np.asarray(adj, bool)
    for i in range(len(rects)):
        for j in range(i + 1, len(rects)):
            if adj[i, j]:
                continue
            a, b = rects[i], rects[j]
            col_gap = max(a[1], b[1]) - min(a[3], b[3])
            row_gap = max(a[0], b[0]) - min(a[2], b[2])
            if not min(col_gap, row_gap) < 0 < max(col_gap, row_gap) <= gap_max:
                continue
            cw = connecting_wall(a, b, cells.wall)
            if cw is None:
                continue
            r0, c0, r1, c1 = (max(v, 0) for v in cw[0])
            window = np.array(classes[r0:r1, c0:c1])    # the strip; other units' cells block it
            for k in range(len(rects)):
                if k != i and k != j:
                    o = rects[k]
                    window[max(o[0] - r0, 0):max(o[2] - r0, 0), max(o[1] - c0, 0):max(o[3] - c0, 0)] = OCCUPIED
            shift = np.array([r0, c0, r0, c0])
            d, p = openings_between(window, a - shift, b - shift, cells, int(slots[i]), int(slots[j]))
            out += [o._replace(box=tuple(int(v) for v in np.asarray(o.box) + shift)) for o in d + p]
    return out


@numba.njit(cache=True, nogil=True)
def _walled(classes, vertical, a0, b0, k, n_across):  # pragma: no cover - compiled
    """Whether line ``k`` of the strip at ``(a0, b0)`` holds an occupied cell."""
    for m in range(n_across):
        r, c = (a0 + k, b0 + m) if vertical else (a0 + m, b0 + k)
        if classes[r, c] == OCCUPIED:
            return True
    return False


@numba.njit(cache=True, nogil=True)
def _opening_counts(classes, rp, rq, wall, door_min, door_max):  # pragma: no cover - compiled
    """``(len(doors), len(passages))`` of ``openings_between(...)`` compiled: the same strip,
    lines and widths."""
    col_gap = max(rp[1], rq[1]) - min(rp[3], rq[3])
    row_gap = max(rp[0], rq[0]) - min(rp[2], rq[2])
    vertical = col_gap >= row_gap
    a, b = (1, 0) if vertical else (0, 1)
    if rp[a] <= rq[a]:
        left, right = rp, rq
    else:
        left, right = rq, rp
    lo = min(left[a + 2] - wall, right[a])
    hi = max(left[a + 2], right[a] + wall)
    s0 = max(rp[b], rq[b]) + wall
    s1 = min(rp[b + 2], rq[b + 2]) - wall
    if s1 <= s0 or hi <= lo:
        return 0, 0
    if vertical:
        r0, c0, r1, c1 = s0, lo, s1, hi
    else:
        r0, c0, r1, c1 = lo, s0, hi, s1
    H, W = classes.shape
    a0, b0, a1, b1 = max(r0, 0), max(c0, 0), min(r1, H), min(c1, W)
    if a0 >= a1 or b0 >= b1:
        return 0, 0
    if vertical:
        if (b1 - b0) != (c1 - c0):
            return 0, 0
        n_lines, n_across = a1 - a0, b1 - b0
    else:
        if (a1 - a0) != (r1 - r0):
            return 0, 0
        n_lines, n_across = b1 - b0, a1 - a0
    lo_unit = min(rp[a], rq[a])
    hi_unit = max(rp[a + 2], rq[a + 2])
    wlo = max(lo - wall, lo_unit, 0)             # the widened strip across the wall (wide_lines)
    whi = min(hi + wall, hi_unit, W if vertical else H)
    count = 0
    passages = 0
    run = 0
    for k in range(n_lines + 1):
        is_open = False
        if k < n_lines:
            is_open = True
            for m in range(n_across):
                r, c = (a0 + k, b0 + m) if vertical else (a0 + m, b0 + k)
                if classes[r, c] != FREE:
                    is_open = False
                    break
        if is_open:
            run += 1
        else:
            if run >= door_min:
                passage = run > door_max
                if not passage:          # a door unless no jamb closes it (unknown lines: none)
                    s = k - run
                    while s > 0 and not _walled(classes, vertical, a0, b0, s - 1, n_across):
                        s -= 1
                    e = k
                    while e < n_lines and not _walled(classes, vertical, a0, b0, e, n_across):
                        e += 1
                    passage = s <= wall and e >= n_lines - wall
                if passage:
                    d, q = _wide_split(classes, vertical, a0, b0, k - run, k, wlo, whi, door_min, door_max)
                    count += d
                    passages += q
                else:
                    count += 1
            run = 0
    return count, passages


@numba.njit(cache=True, nogil=True)
def _wide_split(classes, vertical, a0, b0, k0, k1, wlo, whi, door_min,
                door_max):  # pragma: no cover - compiled
    """``(doors, passages)`` of a would-be passage on lines ``k0..k1`` of the strip at ``(a0,
    b0)``, checked across ``wlo..whi`` (the widened strip): :func:`_passage_or_doors` compiled."""
    n = k1 - k0
    line_open = np.ones(n, np.bool_)
    for k in range(n):
        for m in range(wlo, whi):
            r, c = (a0 + k0 + k, m) if vertical else (m, b0 + k0 + k)
            if classes[r, c] != FREE:
                line_open[k] = False
                break
    closed = 0
    k = 0
    while k < n:                  # closed stretches shorter than a door: read as open
        if line_open[k]:
            k += 1
            continue
        e = k
        while e < n and not line_open[e]:
            e += 1
        if e - k < door_min:
            line_open[k:e] = True
        else:
            closed += e - k
        k = e
    doors = 0
    passages = 0
    run = 0
    for k in range(n + 1):
        is_open = k < n and line_open[k]
        if is_open:
            run += 1
        else:
            if run >= door_min:
                if run > door_max or (closed == 0 and k == n):
                    passages += 1
                else:
                    doors += 1
            run = 0
    return doors, passages


def opening_counts(classes: np.ndarray, rp, rq, cells) -> tuple[int, int]:
    """``(len(doors), len(passages))`` of :func:`openings_between`, compiled (the sampler's hot
    path)."""
    d, p = _opening_counts(classes, np.asarray(rp, np.int64), np.asarray(rq, np.int64),
                           int(cells.wall), int(cells.door_min), int(cells.door_max))
    return int(d), int(p)


def door_count(classes: np.ndarray, rp, rq, cells) -> int:
    """``len(doors_between(classes, rp, rq, cells))``, compiled."""
    return opening_counts(classes, rp, rq, cells)[0]
