"""From a draft tiling to a floor plan: shared walls, adjacency, doors, windows, exits, and what
the robot explored.

Boundaries are written ``(orient, coord, s0, s1)`` in building-frame cells: ``"v"`` is the vertical
line ``x = coord`` for ``s0 <= y < s1``, ``"h"`` the horizontal line ``y = coord`` for
``s0 <= x < s1``. Every choice is drawn from the caller's generator in a fixed order (lists sorted by
unit index), so one seed gives one plan.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, replace

import numpy as np

from semmap_pp.synth.layout import Draft, cells
from semmap_pp.synth.params import SynthParams

OPEN_TYPES = ("corridor", "hall")  # units the robot always drives through when it reaches them


@dataclass(frozen=True)
class Door:
    """An opening of ``width`` cells centred at ``centre`` on the boundary between units a < b."""

    a: int
    b: int
    orient: str
    coord: int
    centre: float
    width: int
    is_open: bool


@dataclass
class FloorPlan:
    """A complete floor plan in the building frame (see the module docstring for boundaries)."""

    rects: np.ndarray                 # (n, 4) int: x0, y0, x1, y1
    types: list
    layout: str
    open_pairs: list                  # sorted (a, b): shared boundary without a wall
    l_pairs: list
    shared: dict                      # (a, b) -> boundary, a < b, for every adjacent pair
    doors: list                       # Door
    walls: list                       # (orient, coord, s0, s1, thickness)
    windows: list                     # (orient, coord, s0, s1)
    exits: list                       # (unit, orient, coord, s0, s1)
    explored: np.ndarray              # (n,) bool: reachable through open doors
    entered: np.ndarray               # (n,) bool: the robot drove inside


def shared_boundary(r, q):
    """The boundary two rectangles share, or ``None`` when they only touch at a corner or not at all.

    Examples
    --------
    >>> shared_boundary([0, 0, 10, 10], [10, 4, 20, 30])
    ('v', 10, 4, 10)
    >>> shared_boundary([0, 0, 10, 10], [10, 10, 20, 30]) is None
    True
    """
    if r[2] == q[0] or q[2] == r[0]:
        s0, s1 = max(r[1], q[1]), min(r[3], q[3])
        if s1 > s0:
            return ("v", int(r[2] if r[2] == q[0] else r[0]), int(s0), int(s1))
    if r[3] == q[1] or q[3] == r[1]:
        s0, s1 = max(r[0], q[0]), min(r[2], q[2])
        if s1 > s0:
            return ("h", int(r[3] if r[3] == q[1] else r[1]), int(s0), int(s1))
    return None


def all_shared(rects) -> dict:
    """``{(a, b): boundary}`` for every pair a < b of rectangles sharing a boundary."""
    out = {}
    for a in range(len(rects)):
        for b in range(a + 1, len(rects)):
            s = shared_boundary(rects[a], rects[b])
            if s is not None:
                out[(a, b)] = s
    return out


def exterior_intervals(rects, shared: dict, i: int) -> list:
    """Parts of unit ``i``'s four edges that no other unit lies behind."""
    x0, y0, x1, y1 = (int(v) for v in rects[i])
    edges = [("h", y0, x0, x1), ("h", y1, x0, x1), ("v", x0, y0, y1), ("v", x1, y0, y1)]
    covered = {k: [] for k in range(4)}
    for (a, b), (o, c, s0, s1) in sorted(shared.items()):
        if i not in (a, b):
            continue
        for k, (eo, ec, _, _) in enumerate(edges):
            if eo == o and ec == c:
                covered[k].append((s0, s1))
    out = []
    for k, (o, c, s0, s1) in enumerate(edges):
        pos = s0
        for a, b in sorted(covered[k]):
            if a > pos:
                out.append((o, c, pos, a))
            pos = max(pos, b)
        if pos < s1:
            out.append((o, c, pos, s1))
    return out


def _door_fits(boundary, p: SynthParams, res: float) -> bool:
    _, _, s0, s1 = boundary
    return s1 - s0 >= cells(p.door_min + 2 * p.door_margin, res)


def _graph(n: int, shared: dict, open_pairs: list, p: SynthParams, res: float, alive) -> list:
    nbrs = [[] for _ in range(n)]
    opened = set(open_pairs)
    for (a, b), s in sorted(shared.items()):
        if alive[a] and alive[b] and ((a, b) in opened or _door_fits(s, p, res)):
            nbrs[a].append(b)
            nbrs[b].append(a)
    return nbrs


def _connected(nbrs, alive) -> bool:
    idx = [i for i in range(len(alive)) if alive[i]]
    if not idx:
        return True
    seen = {idx[0]}
    todo = [idx[0]]
    while todo:
        u = todo.pop()
        for v in nbrs[u]:
            if v not in seen:
                seen.add(v)
                todo.append(v)
    return len(seen) == len(idx)


def prune(rng: np.random.Generator, draft: Draft, n_units: int, p: SynthParams, res: float) -> np.ndarray:
    """Which rectangles to keep: drop rooms from the draft until ``n_units`` remain, never one that
    is part of an open boundary or whose removal disconnects the floor; drop unreachable ones."""
    n = len(draft.rects)
    shared = all_shared(draft.rects)
    alive = np.ones(n, dtype=bool)
    in_open = {i for pair in draft.open_pairs for i in pair}
    nbrs = _graph(n, shared, draft.open_pairs, p, res, alive)
    # a rectangle no door can reach is not part of the floor
    root = _root(draft.rects, draft.types, alive)
    reach = _reach(nbrs, root)
    alive &= reach
    while alive.sum() > n_units:
        cand = [i for i in range(n) if alive[i] and draft.types[i] in ("room", "other")
                and i not in in_open]
        rng.shuffle(cand)
        for i in cand:
            trial = alive.copy()
            trial[i] = False
            if _connected(_graph(n, shared, draft.open_pairs, p, res, trial), trial):
                alive = trial
                break
        else:
            break
    return alive


def _root(rects, types, alive) -> int:
    area = [(r[2] - r[0]) * (r[3] - r[1]) if alive[i] else -1 for i, r in enumerate(rects)]
    big = [i for i in range(len(rects)) if alive[i] and types[i] in OPEN_TYPES]
    pool = big or [i for i in range(len(rects)) if alive[i]]
    return max(pool, key=lambda i: (area[i], -i))


def _reach(nbrs, root: int) -> np.ndarray:
    seen = np.zeros(len(nbrs), dtype=bool)
    seen[root] = True
    todo = [root]
    while todo:
        u = todo.pop()
        for v in nbrs[u]:
            if not seen[v]:
                seen[v] = True
                todo.append(v)
    return seen


def _draw_door(rng, a: int, b: int, boundary, p: SynthParams, res: float, is_open: bool) -> Door:
    o, c, s0, s1 = boundary
    margin = cells(p.door_margin, res)
    width = cells(rng.uniform(p.door_min, p.door_max), res)
    width = max(cells(p.door_min, res), min(width, s1 - s0 - 2 * margin))
    lo, hi = s0 + margin + width / 2, s1 - margin - width / 2
    centre = float(np.floor(rng.uniform(lo, hi))) + (width % 2) * 0.5 if hi > lo else (s0 + s1) / 2
    return Door(a, b, o, c, centre, int(width), is_open)


def _windows(rng, o: str, c: int, s0: int, s1: int, p: SynthParams, res: float) -> list:
    """Windows spread along an exterior wall, one per slot of random length."""
    slot = rng.uniform(p.window_spacing_min, p.window_spacing_max) / res
    margin = p.door_margin / res
    out = []
    for k in range(int((s1 - s0) // slot)):
        w = rng.uniform(p.window_min, p.window_max) / res
        w = min(w, slot - 2 * margin)
        mid = s0 + (k + 0.5) * slot
        if w > 0:
            out.append((o, c, int(mid - w / 2), int(mid + w / 2)))
    return out


def _doors(rng, rects, types, shared, open_pairs, p: SynthParams, res: float) -> list:
    """A spanning tree of doors (rooms preferably onto corridors and halls), then extra doors."""
    n = len(rects)
    opened = set(open_pairs)
    root = _root(rects, types, np.ones(n, dtype=bool))
    reached = np.zeros(n, dtype=bool)
    reached[root] = True
    # open boundaries join spaces without doors
    changed = True
    while changed:
        changed = False
        for a, b in sorted(opened):
            if reached[a] != reached[b]:
                reached[a] = reached[b] = True
                changed = True
    pairs = []
    while not reached.all():
        frontier = []
        for (a, b), s in sorted(shared.items()):
            if reached[a] == reached[b] or (a, b) in opened or not _door_fits(s, p, res):
                continue
            inner, outer = (a, b) if reached[a] else (b, a)
            prio = 0 if types[inner] in OPEN_TYPES else 1
            frontier.append((prio, a, b))
        if not frontier:
            break
        best = min(f[0] for f in frontier)
        options = [f for f in frontier if f[0] == best]
        _, a, b = options[int(rng.integers(len(options)))]
        pairs.append((a, b))
        for u in (a, b):
            reached[u] = True
        changed = True
        while changed:
            changed = False
            for x, y in sorted(opened):
                if reached[x] != reached[y]:
                    reached[x] = reached[y] = True
                    changed = True
    tree = set(pairs)
    for (a, b), s in sorted(shared.items()):
        if (a, b) in tree or (a, b) in opened or not _door_fits(s, p, res):
            continue
        corridorish = types[a] in OPEN_TYPES or types[b] in OPEN_TYPES
        both_open = types[a] in OPEN_TYPES and types[b] in OPEN_TYPES
        prob = 1.0 if both_open else (p.p_extra_door if corridorish else p.p_extra_room_door)
        if rng.random() < prob:
            pairs.append((a, b))
    doors = []
    for a, b in sorted(pairs):
        closable = types[a] not in OPEN_TYPES or types[b] not in OPEN_TYPES
        is_open = not (closable and rng.random() < p.p_door_closed)
        doors.append(_draw_door(rng, a, b, shared[(a, b)], p, res, is_open))
    return doors


def _explore(rng, n: int, types, doors: list, open_pairs: list, root: int, p: SynthParams):
    nbrs = [[] for _ in range(n)]
    for d in doors:
        if d.is_open:
            nbrs[d.a].append(d.b)
            nbrs[d.b].append(d.a)
    for a, b in open_pairs:
        nbrs[a].append(b)
        nbrs[b].append(a)
    explored = np.zeros(n, dtype=bool)
    entered = np.zeros(n, dtype=bool)
    explored[root] = entered[root] = True
    queue = deque([root])
    open_set = set(open_pairs)
    while queue:
        u = queue.popleft()
        for v in sorted(set(nbrs[u])):
            if explored[v]:
                continue
            explored[v] = True
            joined = (min(u, v), max(u, v)) in open_set
            if types[v] in OPEN_TYPES or joined or rng.random() < p.p_enter_room:
                entered[v] = True
                queue.append(v)
    return explored, entered


def build_plan(rng: np.random.Generator, draft: Draft, keep: np.ndarray, p: SynthParams,
               res: float) -> FloorPlan:
    """Walls, doors, windows, exits and exploration of the kept rectangles of ``draft``."""
    old = [i for i in range(len(draft.rects)) if keep[i]]
    new_of = {o: k for k, o in enumerate(old)}
    rects = np.array([draft.rects[i] for i in old], dtype=np.int64).reshape(-1, 4)
    types = [draft.types[i] for i in old]
    remap = lambda pairs: sorted((min(new_of[a], new_of[b]), max(new_of[a], new_of[b]))
                                 for a, b in pairs if a in new_of and b in new_of)
    open_pairs, l_pairs = remap(draft.open_pairs), remap(draft.l_pairs)
    shared = all_shared(rects.tolist())
    open_pairs = [pr for pr in open_pairs if pr in shared]
    l_pairs = [pr for pr in l_pairs if pr in shared]
    doors = _doors(rng, rects.tolist(), types, shared, open_pairs, p, res)

    t_in = [cells(rng.uniform(p.wall_inner_min, p.wall_inner_max), res) for _ in range(2)]
    t_out = cells(rng.uniform(p.wall_outer_min, p.wall_outer_max), res)
    walls = []
    for pair, (o, c, s0, s1) in sorted(shared.items()):
        if pair not in open_pairs:
            walls.append((o, c, s0, s1, t_in[int(rng.integers(2))]))
    windows, exits = [], []
    for i in range(len(rects)):
        x0, y0, x1, y1 = rects[i].tolist()
        # corridors open to the outside only at their ends; halls on any side
        end_orient = "v" if x1 - x0 >= y1 - y0 else "h"
        for o, c, s0, s1 in exterior_intervals(rects.tolist(), shared, i):
            walls.append((o, c, s0, s1, t_out))
            if types[i] != "corridor" and rng.random() < p.p_window:
                windows += _windows(rng, o, c, s0, s1, p, res)
            exit_here = types[i] == "hall" or (types[i] == "corridor" and o == end_orient)
            if exit_here and _door_fits((o, c, s0, s1), p, res) and rng.random() < p.p_exit:
                d = _draw_door(rng, i, i, (o, c, s0, s1), p, res, True)
                lo = int(d.centre - d.width / 2)
                exits.append((i, o, c, lo, lo + d.width))
    root = _root(rects.tolist(), types, np.ones(len(rects), dtype=bool))
    explored, entered = _explore(rng, len(rects), types, doors, open_pairs, root, p)
    return FloorPlan(rects, types, draft.layout, open_pairs, l_pairs, shared, doors, walls, windows,
                exits, explored, entered)


def rescale_plan(plan: FloorPlan, factor: float) -> FloorPlan:
    """``plan`` with every length multiplied by ``factor`` and rounded to whole cells.

    The generator draws every plan in cells of :data:`semmap_pp.synth.floor.PLAN_RESOLUTION` and
    scales it to the map's resolution, so one seed gives one building at every resolution (rounding
    each length on its own would flip the draft's fit tests and draw another building). Edges that
    coincide before coincide after (each coordinate is rounded by itself); thicknesses and widths
    keep at least one cell.

    Examples
    --------
    >>> d = Door(0, 1, "v", 10, 5.0, 3, False)
    >>> p = FloorPlan(np.array([[0, 0, 10, 8], [10, 0, 21, 8]]), ["room", "room"], "row", [], [],
    ...          {(0, 1): ("v", 10, 0, 8)}, [d], [("v", 10, 0, 8, 1)], [], [],
    ...          np.ones(2, bool), np.ones(2, bool))
    >>> q = rescale_plan(p, 2.0)
    >>> q.rects.tolist(), q.shared[(0, 1)], q.doors[0].width, q.walls[0]
    ([[0, 0, 20, 16], [20, 0, 42, 16]], ('v', 20, 0, 16), 6, ('v', 20, 0, 16, 2))
    """
    if factor == 1.0:
        return plan

    def c(v) -> int:
        return int(round(v * factor))

    def t(v) -> int:
        return max(1, int(round(v * factor)))

    return replace(plan,
                   rects=np.array([[c(v) for v in r] for r in plan.rects.tolist()],
                                  dtype=np.int64).reshape(-1, 4),
                   shared={k: (o, c(v), c(s0), c(s1)) for k, (o, v, s0, s1) in plan.shared.items()},
                   doors=[replace(d, coord=c(d.coord), centre=d.centre * factor, width=t(d.width))
                          for d in plan.doors],
                   walls=[(o, c(v), c(s0), c(s1), t(th)) for o, v, s0, s1, th in plan.walls],
                   windows=[(o, c(v), c(s0), c(s1)) for o, v, s0, s1 in plan.windows],
                   exits=[(i, o, c(v), c(s0), c(s1)) for i, o, v, s0, s1 in plan.exits])
