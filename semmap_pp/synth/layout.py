"""Floor plans as tilings of axis-aligned rectangles in whole cells (the building frame).

A plan is drawn in the *building frame*: integer cell coordinates, ``x`` to the right, ``y``
downwards, before the floor is rotated into the image. A unit is the half-open rectangle
``[x0, x1) x [y0, y1)`` whose edges run along the *centre lines* of its walls, so neighbouring units
share an edge coordinate exactly and a plan is a set of non-overlapping tiles.

Three layout kinds, as real floors are built: a corridor spine with rooms on both sides, a grid of
corridors with blocks of rooms between them, and a hall with rooms around it (optionally with a
corridor leaving it). Wide room slots sometimes become an L: two units sharing an open boundary.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from semmap_pp.synth.params import SynthParams

LAYOUTS = ("spine", "grid", "hall")


@dataclass
class Draft:
    """A plan under construction: rectangles, their types and open (wall-less) boundaries.

    Attributes
    ----------
    rects : list of [x0, y0, x1, y1]
        Integer cells of the building frame (wall centre lines).
    types : list of str
        ``room`` / ``corridor`` / ``hall`` / ``other`` per rectangle.
    open_pairs : list of (i, j)
        Pairs of rectangle indices whose shared boundary has no wall.
    l_pairs : list of (i, j)
        The subset of ``open_pairs`` that form L-shaped spaces.
    layout : str
        Which generator made it.
    """

    rects: list = field(default_factory=list)
    types: list = field(default_factory=list)
    open_pairs: list = field(default_factory=list)
    l_pairs: list = field(default_factory=list)
    layout: str = ""

    def add(self, rect, kind: str) -> int:
        """Append a rectangle and return its index."""
        x0, y0, x1, y1 = (int(v) for v in rect)
        if not (x1 > x0 and y1 > y0):
            raise ValueError(f"empty rectangle {rect}")
        self.rects.append([x0, y0, x1, y1])
        self.types.append(kind)
        return len(self.rects) - 1


def cells(metres: float, resolution: float) -> int:
    """Whole cells of a length in metres (at least one)."""
    return max(1, int(round(metres / resolution)))


def partition(rng: np.random.Generator, length: int, lo: int, hi: int) -> list[int]:
    """Split ``length`` cells into random widths in ``[lo, hi]`` that sum to ``length``.

    Returns a single width ``[length]`` when no split fits (a slot shorter than ``lo`` stays one
    piece, a caller decides whether to keep it).

    Examples
    --------
    >>> w = partition(np.random.default_rng(0), 100, 20, 40)
    >>> sum(w), all(20 <= x <= 40 for x in w)
    (100, True)
    """
    n_min = -(-length // hi)
    n_max = length // lo
    if n_max < 1 or n_min > n_max:
        return [length]
    n = int(rng.integers(n_min, n_max + 1))
    for _ in range(20):
        raw = rng.uniform(lo, hi, n)
        edges = np.round(np.cumsum(raw) / raw.sum() * length).astype(int)
        widths = np.diff(np.concatenate([[0], edges]))
        if widths.min() >= lo and widths.max() <= hi:
            return [int(w) for w in widths]
    edges = np.round(np.arange(1, n + 1) * length / n).astype(int)
    return [int(w) for w in np.diff(np.concatenate([[0], edges]))]


def _place(origin, axis: str, sign: int, u0: int, u1: int, v0: int, v1: int) -> list[int]:
    """Rectangle of row-local coordinates (u along the row, v away from its front) in cells."""
    ox, oy = origin
    a, b = sorted((sign * v0, sign * v1))
    if axis == "x":
        return [ox + u0, oy + a, ox + u1, oy + b]
    return [ox + a, oy + u0, ox + b, oy + u1]


def add_row(rng: np.random.Generator, draft: Draft, p: SynthParams, res: float, origin,
            axis: str, sign: int, length: int, depth: int, jitter: bool) -> None:
    """Fill a row of rooms facing a corridor or hall.

    The row's front lies on the line through ``origin`` along ``axis``; rooms extend ``depth``
    cells away from it in direction ``sign``. With ``jitter`` single rooms are deeper or
    shallower than the row (the outline of real floors is ragged); inside blocks it is off, as
    the row behind must stay flush. Wide slots sometimes become an L-shaped space.
    """
    lo, hi = cells(p.room_min, res), cells(p.room_max, res)
    u = 0
    for w in partition(rng, length, lo, hi):
        d = depth
        if jitter and rng.random() < p.p_room_depth_jitter:
            delta = int(round(rng.uniform(-1.0, 1.0) * p.room_depth_jitter / res))
            d = int(np.clip(depth + delta, lo, hi))
        leftover_min = cells(p.l_min_leftover, res)
        can_l = w >= 2 * lo and d >= lo + leftover_min
        if can_l and rng.random() < p.p_l_shape:
            wa = int(np.clip(round(w * rng.uniform(0.4, 0.6)), lo, w - lo))
            back = int(rng.integers(leftover_min, d - lo + 1))
            a_first = rng.random() < 0.5
            ua, ub = (u, u + wa) if a_first else (u + w - wa, u + w)
            vb0, vb1 = (u + wa, u + w) if a_first else (u, u + w - wa)
            ia = draft.add(_place(origin, axis, sign, ua, ub, 0, d), "room")
            ib = draft.add(_place(origin, axis, sign, vb0, vb1, 0, d - back), "room")
            small = (vb1 - vb0) * back * res * res < p.room_min * p.room_min * 1.5
            draft.add(_place(origin, axis, sign, vb0, vb1, d - back, d), "other" if small else "room")
            draft.open_pairs.append((ia, ib))
            draft.l_pairs.append((ia, ib))
        else:
            draft.add(_place(origin, axis, sign, u, u + w, 0, d), "room")
        u += w


def _mean_width(rng: np.random.Generator, p: SynthParams) -> float:
    return float(rng.uniform(p.room_width_mean_min, p.room_width_mean_max))


def spine(rng: np.random.Generator, p: SynthParams, res: float, n_units: int) -> Draft:
    """A corridor with rooms on one or both sides, sometimes ending in a hall."""
    d = Draft(layout="spine")
    wc = cells(rng.uniform(p.corridor_width_min, p.corridor_width_max), res)
    with_hall = n_units >= 5 and rng.random() < p.p_spine_hall
    both = n_units > 8 or (n_units >= 4 and rng.random() < p.p_spine_two_sided)
    n_rooms = max(1, n_units - 1 - int(with_hall))
    per_side = -(-n_rooms // 2) if both else n_rooms
    length = cells(max(p.room_min, per_side * _mean_width(rng, p)), res)
    corridor = d.add([0, 0, length, wc], "corridor")
    depth_top = cells(rng.uniform(p.room_depth_min, p.room_depth_max), res)
    add_row(rng, d, p, res, (0, 0), "x", -1, length, depth_top, jitter=True)
    depth_bot = cells(rng.uniform(p.room_depth_min, p.room_depth_max), res)
    if both:
        add_row(rng, d, p, res, (0, wc), "x", 1, length, depth_bot, jitter=True)
    if with_hall:
        span = depth_top + wc + (depth_bot if both else 0)
        hh = max(span, cells(rng.uniform(p.hall_min, p.hall_max), res))
        wh = cells(rng.uniform(p.hall_min, p.hall_max), res)
        y0 = -depth_top - (hh - span) // 2
        hall = d.add([length, y0, length + wh, y0 + hh], "hall")
        if rng.random() < p.p_open_junction:
            d.open_pairs.append((corridor, hall))
    return d


def grid(rng: np.random.Generator, p: SynthParams, res: float, n_units: int) -> Draft:
    """Parallel corridors joined by cross corridors; blocks of two rows of rooms between them."""
    d = Draft(layout="grid")
    wc = cells(rng.uniform(p.corridor_width_min, p.corridor_width_max), res)
    nx = int(rng.integers(2, 4))
    ny = 2 if n_units < 30 else int(rng.integers(2, 4))
    n_corr = ny + nx * (ny - 1)
    outer_rows = int(rng.integers(0, 3))
    blocks = (nx - 1) * (ny - 1)
    rows = 2 * blocks + outer_rows * (nx - 1)
    per_row = max(1.0, (n_units - n_corr) / max(rows, 1))
    bw = [cells(max(2 * p.room_min, per_row * _mean_width(rng, p)), res) for _ in range(nx - 1)]
    bh = [cells(rng.uniform(p.block_depth_min, p.block_depth_max), res) for _ in range(ny - 1)]
    xs = np.concatenate([[0], np.cumsum([w + wc for w in bw])]).astype(int)
    ys = np.concatenate([[0], np.cumsum([h + wc for h in bh])]).astype(int)
    horiz = [d.add([0, int(y), int(xs[-1]) + wc, int(y) + wc], "corridor") for y in ys]
    for i, x in enumerate(xs):
        for j in range(ny - 1):
            v = d.add([int(x), int(ys[j]) + wc, int(x) + wc, int(ys[j + 1])], "corridor")
            d.open_pairs += [(horiz[j], v), (horiz[j + 1], v)]
    for i in range(nx - 1):
        for j in range(ny - 1):
            top = int(round(bh[j] * rng.uniform(0.4, 0.6)))
            x0 = int(xs[i]) + wc
            add_row(rng, d, p, res, (x0, int(ys[j]) + wc), "x", 1, bw[i], top, jitter=False)
            add_row(rng, d, p, res, (x0, int(ys[j + 1])), "x", -1, bw[i], bh[j] - top, jitter=False)
    for k in range(outer_rows):
        depth = cells(rng.uniform(p.room_depth_min, p.room_depth_max), res)
        for i in range(nx - 1):
            x0 = int(xs[i]) + wc
            if k == 0:
                add_row(rng, d, p, res, (x0, 0), "x", -1, bw[i], depth, jitter=True)
            else:
                add_row(rng, d, p, res, (x0, int(ys[-1]) + wc), "x", 1, bw[i], depth, jitter=True)
    return d


def hall(rng: np.random.Generator, p: SynthParams, res: float, n_units: int) -> Draft:
    """A large hall with rows of rooms on two to four sides, maybe a corridor leaving it."""
    d = Draft(layout="hall")
    w = cells(rng.uniform(p.hall_min, p.hall_max), res)
    h = cells(rng.uniform(p.hall_min, min(p.hall_max, w * res + 2.0)), res)
    hall_id = d.add([0, 0, w, h], "hall")
    sides = [s for s in ("top", "bottom", "left", "right") if rng.random() < 0.75]
    if len(sides) < 2:
        sides = ["top", "bottom"]
    mean_room = (p.room_width_mean_min + p.room_width_mean_max) / 2
    capacity = sum((w if s in ("top", "bottom") else h) * res / mean_room for s in sides)
    corridor = n_units - 1 > capacity + 2
    if corridor and "right" in sides:
        sides.remove("right")
    for s in sides:
        depth = cells(rng.uniform(p.room_depth_min, p.room_depth_max), res)
        if s == "top":
            add_row(rng, d, p, res, (0, 0), "x", -1, w, depth, jitter=True)
        elif s == "bottom":
            add_row(rng, d, p, res, (0, h), "x", 1, w, depth, jitter=True)
        elif s == "left":
            add_row(rng, d, p, res, (0, 0), "y", -1, h, depth, jitter=True)
        else:
            add_row(rng, d, p, res, (w, 0), "y", 1, h, depth, jitter=True)
    if corridor:
        wc = cells(rng.uniform(p.corridor_width_min, p.corridor_width_max), res)
        yc = int(rng.integers(max(1, h // 4), max(2, h - wc - h // 4)))
        rest = n_units - 1 - capacity
        length = cells(max(p.room_min, rest / 2 * _mean_width(rng, p)), res)
        c = d.add([w, yc, w + length, yc + wc], "corridor")
        d.open_pairs.append((hall_id, c))
        for origin, sign in (((w, yc), -1), ((w, yc + wc), 1)):
            depth = cells(rng.uniform(p.room_depth_min, p.room_depth_max), res)
            add_row(rng, d, p, res, origin, "x", sign, length, depth, jitter=True)
    return d


GENERATORS = {"spine": spine, "grid": grid, "hall": hall}


def choose_layout(rng: np.random.Generator, p: SynthParams, n_units: int) -> str:
    """Draw a layout kind that suits ``n_units``."""
    weights = np.array(p.layout_weights, dtype=float)
    if n_units < p.grid_min_units:
        weights[1] = 0.0
    if n_units < 4:
        weights[2] = 0.0
    return LAYOUTS[int(rng.choice(len(LAYOUTS), p=weights / weights.sum()))]
