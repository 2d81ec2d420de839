"""Greedy ascent of a target with the kernels' own moves: the start world's refinement and W*'s
final polish.

The greedy cover of :mod:`semmap_pp.sampler.start_worlds` only sees free cells: a room whose walls are lined with
furniture comes out short of its walls, the pieces of free space between the furniture become units
of their own, and ray fans seen through windows become units outside the building. The sampler could
repair all that, but with knowledge on every proposal costs a knowledge inference; the
knowledge-free target (types from the geometry class, fixed P(SaLe)) costs a few hundred
microseconds. So the start world is the local optimum of that target reached by the kernels' own
moves, each taken only when it raises log p: remove a unit, move one wall to a nearby position or to
a line of wall evidence (SHRINK/DILATE), merge two units that share a wall (MERGE), add a unit from
the birth table where free space is left uncovered (ADD), split a unit at a wall line (SPLIT); and
one compound move no single kernel makes, *bridging* two collinear pieces of a corridor across the
unit between them (:meth:`_Ascent.bridges`); in W*'s polish also two more, recutting an L-shaped
pair the other way (:meth:`_Ascent.recuts`) and moving every edge on one wall together
(:meth:`_Ascent.shared_wall_moves`), and two fewer: the start ascent cuts a unit twice at once when
no single cut helps (a room inside an L of walls) and adds units over uncovered free space (births),
W*'s polish cuts once and adds none (:func:`polish`).

After sampling, the same ascent under the full target (knowledge on) polishes W*, the best sampled
world: a short chain at T = 1 leaves it a few wall moves or one merge short of the nearest local
maximum (on the 30 synthetic floors the polish raised log p on most floors, by up to 700 nats;
docs/quality.md). The search is greedy, so it proves nothing and never lowers log p; it changes
neither the chains nor their diagnostics, only the world reported as W*.

A split or a birth needs an empty slot: when every slot holds a unit, the ascent doubles the
world's capacity (:func:`semmap_pp.world.grow`, up to :data:`MAX_CAPACITY`), so a building with more
units than ``[prior] k_max`` is not cut off at that number (docs/model.md, "Prior"). A result that
fits the capacity it started with is returned in it (:func:`semmap_pp.world.fit`): the slot term of
the log posterior, ``-log C(K, n)``, depends on the capacity K.
"""

from __future__ import annotations

import numba
import numpy as np

from semmap_pp import world as wm
from semmap_pp.model import MAX_K
from semmap_pp.target.prior import all_valid
from semmap_pp.sampler.kernels.shrink_dilate import wall_range
from semmap_pp.sampler.kernels.common import band_weights, line_cum

#: The ascent grows a full world's capacity up to this many slots (the model's bound on k_max).
MAX_CAPACITY = MAX_K


# The resolution at which ``[kernels] ascent_peaks`` is given (the maps the model was measured on).
PEAKS_RESOLUTION = 0.05


def ascent_peaks(n: int, resolution: float) -> int:
    """How many line-evidence peaks a wall move tries at ``resolution`` metres per cell: ``n`` at
    0.05 m and coarser, ``n`` times 0.05 m / ``resolution`` on finer maps. A finer map draws a
    wall in more lines of cells, each a peak of its own (at 0.025 m a 0.15 m wall is two lines
    with an unknown core), so ``n`` peaks reach fewer walls there (CHANGELOG.md, quality
    change 30). Coarser maps keep ``n``: fewer peaks at 0.1 m helped the floors scanned at 0.1 m and hurt
    the floors pooled to 0.1 m.

    >>> [ascent_peaks(8, r) for r in (0.0125, 0.025, 0.04, 0.05, 0.1)], ascent_peaks(0, 0.025)
    ([32, 16, 10, 8, 8], 0)
    """
    return max(n, round(n * PEAKS_RESOLUTION / resolution))


def _line_peaks(w: np.ndarray, lo: int, k: int) -> list[int]:
    """Positions (``lo`` + index) of the ``k`` largest local maxima of ``w`` above its floor."""
    if w.size == 0:
        return []
    left = np.concatenate([[-np.inf], w[:-1]])
    right = np.concatenate([w[1:], [-np.inf]])
    peak = (w >= left) & (w >= right) & (w > w.min())
    idx = np.flatnonzero(peak)
    idx = idx[np.argsort(-w[idx], kind="stable")][:k]
    return (idx + lo).tolist()


def _strongest_line(cum: np.ndarray, i0: int, i1: int, s0: int, s1: int) -> float:
    """The largest share of wall or door cells on lines ``i0..i1`` over the span ``s0..s1``
    (``cum``: the lines' cumulative counts along the span)."""
    return float(((cum[i0:i1, s1] - cum[i0:i1, s0]) / float(s1 - s0)).max())


@numba.njit(cache=True, nogil=True)
def _swallowed(rects, active, slot, thin_below, share):  # pragma: no cover - compiled
    """(K,) bool: the active units other than ``slot`` whose shorter side is below
    ``thin_below`` and of whose area at least ``share`` lies inside unit ``slot``."""
    out = np.zeros(rects.shape[0], np.bool_)
    a0, b0, a1, b1 = rects[slot, 0], rects[slot, 1], rects[slot, 2], rects[slot, 3]
    for k in range(rects.shape[0]):
        if not active[k] or k == slot:
            continue
        r0, c0, r1, c1 = rects[k, 0], rects[k, 1], rects[k, 2], rects[k, 3]
        if min(r1 - r0, c1 - c0) >= thin_below:
            continue
        inter = max(min(r1, a1) - max(r0, a0), 0) * max(min(c1, b1) - max(c0, b0), 0)
        out[k] = inter >= share * ((r1 - r0) * (c1 - c0))
    return out


class _Ascent:
    """Greedy ascent state: a tracker of the target and the kernels' data."""

    def __init__(self, posterior, world: wm.World, data, *, peaks: int | None = None, local: int = 3,
                 absorb_share: float = 0.8, merge_slack: float = 0.15, merge_line_max: float = 0.5,
                 merge_keep: float = 0.5, trim_line_min: float = 0.5):
        self.posterior = posterior
        self.tr = posterior.start(world)
        self.data, self.local = data, local
        self.absorb_share, self.merge_slack, self.merge_line_max = absorb_share, merge_slack, merge_line_max
        self.merge_keep, self.trim_line_min = merge_keep, trim_line_min
        self.resolution, self.evidence = posterior.cells.resolution, posterior.model.evidence
        self.peaks = ascent_peaks(data.settings.ascent_peaks, self.resolution) if peaks is None else peaks

    @property
    def world(self) -> wm.World:
        return self.tr.world

    def free(self, n: int = 1) -> np.ndarray:
        """The empty slots; when fewer than ``n`` are left, the capacity is doubled first (the
        tracker rebuilt on the grown world: its log p changes by the slot term only)."""
        free = wm.free_slots(self.world)
        if free.size < n and self.world.capacity < MAX_CAPACITY:
            grown = wm.grow(self.world, min(2 * self.world.capacity, MAX_CAPACITY))
            self.tr = self.posterior.start(grown)
            free = wm.free_slots(self.world)
        return free

    def valid(self, world: wm.World) -> bool:
        """Inside the lattice, every side within ``[min_side, max_side]`` (the prior's compiled
        test: the ascent asks it of every candidate)."""
        return all_valid(world.rects, world.active, self.data.shape, self.data.min_side,
                         self.data.max_side)

    def propose_above(self, new: wm.World, changed, floor: float):
        """``new``'s proposal, for a caller that takes it only when its log p exceeds ``floor``.

        A tracker that :attr:`supports_floor` may skip the knowledge inference of a proposal whose
        type-free upper bound is already below ``floor`` (its ``logp`` is then ``-inf``): the same
        choices as with every proposal evaluated, fewer inferences.
        """
        if getattr(self.tr, "supports_floor", False):
            return self.tr.propose(new, changed, floor=floor)
        return self.tr.propose(new, changed)

    def try_world(self, new: wm.World, changed) -> bool:
        """Accept ``new`` when it raises log p (strictly); returns whether it did."""
        if not self.valid(new):
            return False
        floor = self.tr.logp + 1e-9
        prop = self.propose_above(new, tuple(int(s) for s in changed), floor)
        if prop.logp > floor:
            self.tr.accept(prop)
            return True
        return False

    def best_of(self, worlds, changed) -> bool:
        """Accept the best of ``worlds`` (all differing from the current one in ``changed``) if it helps."""
        best, best_lp = None, self.tr.logp + 1e-9
        for new in worlds:
            if not self.valid(new):
                continue
            prop = self.propose_above(new, changed, best_lp)
            if prop.logp > best_lp:
                best, best_lp = prop, prop.logp
        if best is None:
            return False
        self.tr.accept(best)
        return True

    def absorb(self, world: wm.World, slot: int):
        """``world`` without the *fragments* lying mostly (``absorb_share``) inside unit ``slot``.

        A fragment is a unit whose shorter side is below ``2 * min_side``: a strip of free space
        between furniture and a wall, not a room (two rooms are never swallowed by one move).
        """
        gone = np.flatnonzero(_swallowed(world.rects, world.active, int(slot),
                                         2 * int(self.data.min_side),
                                         float(self.absorb_share))).tolist()
        for k in gone:
            world = wm.remove(world, k)
        return world, gone

    def wall_moves(self, slot: int) -> bool:
        """Move each wall of ``slot`` to its best candidate position (local steps, line-evidence peaks).

        A wall moved outwards may swallow units lying mostly inside the grown unit (the greedy cover
        leaves strips of free space between furniture and walls as units of their own): the
        candidate world drops them, so the move is judged against the world without them.
        """
        moved = False
        for side in range(4):
            if not self.world.active[slot]:
                break
            rect = [int(v) for v in self.world.rects[slot]]
            best, best_lp = None, self.tr.logp + 1e-9
            for c in self.positions(rect, side):
                r = list(rect)
                r[side] = c
                new, gone = self.absorb(wm.replace(self.world, slot, r), slot)
                if not self.valid(new):
                    continue
                prop = self.propose_above(new, (slot, *gone), best_lp)
                if prop.logp > best_lp:
                    best, best_lp = prop, prop.logp
            if best is not None:
                self.tr.accept(best)
                moved = True
        return moved

    def positions(self, rect, side: int) -> list:
        """The candidate positions of wall ``side`` of ``rect``, ascending, its own left out:
        local steps and line-evidence peaks within the range that keeps the unit valid."""
        _, lo, hi, w = wall_range(rect, side, self.data)
        x = int(rect[side])
        cand = {x + d for d in range(-self.local, self.local + 1)} | set(_line_peaks(w, lo, self.peaks))
        return sorted(c for c in cand if lo <= c <= hi and c != x)

    def all_wall_moves(self, within=None) -> bool:
        """:meth:`wall_moves` for every unit active now (of ``within``, when given), in slot order."""
        changed = False
        for s in self.units(within):
            changed |= self.wall_moves(s)
        return changed

    def wall_group(self, slot: int, side: int) -> list[tuple[int, int]]:
        """The edges ``(slot, side)`` that lie on the same wall as ``side`` of ``slot``.

        Edges across the same axis within two wall bands of it whose spans overlap or touch the
        group's (closed under that relation): the facing edges of the units on the other side of a
        wall and the collinear edges of the units beside it. One wall moved edge by edge cannot
        move: each edge alone opens a gap or an overlap at the others.
        """
        rects, act = self.world.rects, self.world.active
        axis, tol = side % 2, 2 * int(self.data.wall_cells)
        x = int(rects[slot][side])
        edges = [(int(s), k) for s in np.flatnonzero(act) for k in (axis, axis + 2)
                 if abs(int(rects[s][k]) - x) <= tol]
        group, span = [(slot, side)], [int(rects[slot][1 - axis]), int(rects[slot][3 - axis])]
        grew = True
        while grew:
            grew = False
            for s, k in edges:
                if (s, k) in group:
                    continue
                a, b = int(rects[s][1 - axis]), int(rects[s][3 - axis])
                if a <= span[1] + tol and b >= span[0] - tol:
                    group.append((s, k))
                    span = [min(span[0], a), max(span[1], b)]
                    grew = True
        return group

    def shared_wall_moves(self) -> set:
        """Move every edge of a wall together (:meth:`wall_group` of two or more edges).

        Candidates as :meth:`wall_moves` (:meth:`positions` of the first edge), each shifting
        all the group's edges by the same amount; the best is taken when it raises log p
        (INTERCHANGE's move, for every unit on the wall rather than one pair). Each group is
        tried once per call. Returns the slots of the units moved (empty: nothing moved).
        """
        moved, seen = set(), set()
        for slot in self.units():
            for side in range(4):
                if not self.world.active[slot] or (slot, side) in seen:
                    continue
                group = self.wall_group(slot, side)
                seen.update(group)
                if len(group) < 2:
                    continue
                rect = [int(v) for v in self.world.rects[slot]]
                slots = tuple(sorted({s for s, _ in group}))
                worlds = []
                for c in self.positions(rect, side):
                    d, rects = c - rect[side], np.array(self.world.rects)
                    for s, k in group:
                        rects[s, k] += d
                    worlds.append(wm.make(rects, self.world.active, self.world.types))
                if self.best_of(worlds, slots):
                    moved.update(slots)
        return moved

    def near(self, slots) -> set:
        """``slots`` and the active units within two wall bands of any of them."""
        rects, act, t = self.world.rects, self.world.active, 2 * int(self.data.wall_cells)
        out = np.zeros(len(act), bool)
        for s in slots:
            if act[s]:
                r = rects[s]
                out |= ((rects[:, 0] <= r[2] + t) & (rects[:, 2] >= r[0] - t)
                        & (rects[:, 1] <= r[3] + t) & (rects[:, 3] >= r[1] - t))
        return set(np.flatnonzero(act & out).tolist())

    def units(self, within=None) -> list:
        """The active slots, in slot order: all, or those in the set ``within``."""
        act = wm.active_slots(self.world).tolist()
        return act if within is None else [s for s in act if s in within]

    def untyped(self) -> wm.World:
        """The current world with its types left undecided (what the ascent returns)."""
        return wm.make(self.world.rects, self.world.active, np.full(self.world.capacity, wm.NO_TYPE))

    def removals(self) -> bool:
        changed = False
        for s in self.units():
            changed |= self.try_world(wm.remove(self.world, s), (s,))
        return changed

    def boundary_lines(self, ra, rb) -> float:
        """Strongest wall-line fraction on the boundary between two side-by-side units (0..1).

        The lines (lattice rows or columns, with door candidates) within a wall band of the two
        facing edges, each as the share of its cells over the shared span that are wall or door.
        """
        d, t = self.data, self.data.wall_cells
        gap_r = max(ra[0], rb[0]) - min(ra[2], rb[2])
        gap_c = max(ra[1], rb[1]) - min(ra[3], rb[3])
        axis = 0 if gap_r >= gap_c else 1            # stacked along rows: the boundary is a row band
        cum = d.hcum if axis == 0 else d.vcum
        s0, s1 = max(ra[1 - axis], rb[1 - axis]), min(ra[3 - axis], rb[3 - axis])
        if s1 <= s0:
            return 1.0
        lo_r, hi_r = (ra, rb) if ra[axis] <= rb[axis] else (rb, ra)
        i0 = max(min(lo_r[axis + 2], hi_r[axis]) - t, 0)
        i1 = min(max(lo_r[axis + 2], hi_r[axis]) + t, cum.shape[0])
        if i1 <= i0:
            return 1.0
        return _strongest_line(cum, i0, i1, s0, s1)

    def crossing_line(self, axis: int, lo_r, hi_r) -> float:
        """Strongest wall line across the gap between two collinear units (0..1).

        ``lo_r`` ends before ``hi_r`` begins along ``axis``; the lines across that axis strictly
        inside the gap (a wall band off each unit's end), each as the share of its cells over the
        two units' common span, wall band excluded, that are wall or door (as
        :meth:`boundary_lines`). 0 when the gap holds no such line.
        """
        d, t = self.data, self.data.wall_cells
        cum = d.hcum if axis == 0 else d.vcum
        x = 1 - axis
        s0, s1 = max(lo_r[x], hi_r[x]) + t, min(lo_r[x + 2], hi_r[x + 2]) - t
        i0, i1 = lo_r[axis + 2] + t, min(hi_r[axis] - t, cum.shape[0])
        if s1 <= s0 or i1 <= i0:
            return 0.0
        return _strongest_line(cum, i0, i1, s0, s1)

    def merges(self) -> bool:
        """Replace two nearby units by their bounding box when it adds little area and raises log p.

        Pairs whose boxes are at most a wall band apart, whose bounding box exceeds their union by at
        most ``merge_slack`` and whose boundary shows no wall line (:meth:`boundary_lines` below
        ``merge_line_max``): one space cut into two rectangles, e.g. a room cut at a row of furniture
        or a corridor in pieces. A wall between two rooms is a line along most of its length (door
        gaps included as door candidates), so rooms are not merged here even where the
        knowledge-free target would take it. A unit overlapping the box is trimmed to its largest
        part beside it (:meth:`cut_back`). A trim deeper than a wall band is kept only when that
        part keeps at least ``merge_keep`` of its area and a wall line (:meth:`boundary_lines` at
        least ``trim_line_min``) stands along the new boundary, otherwise the pair is skipped; a
        trim of at most a wall band only sets two bands on one line (a corridor piece a cell lower
        than the other reaches that far into the rooms beside it) and is not tested. A unit with
        no part of a unit side left beside the box is dropped (a third piece of the same space: a
        strip along a hall's wall in three pieces joins the hall two at a time only so; the slack
        bounds what the box can swallow).
        The box and the trimmed units are then wall-moved, and the whole kept only if log p rose.
        """
        t = self.data.wall_cells
        changed = False
        for a, b, ra, rb in self._pairs():
            gap_r = max(ra[0], rb[0]) - min(ra[2], rb[2])
            gap_c = max(ra[1], rb[1]) - min(ra[3], rb[3])
            if gap_r > t or gap_c > t:
                continue
            box = (min(ra[0], rb[0]), min(ra[1], rb[1]), max(ra[2], rb[2]), max(ra[3], rb[3]))
            area = lambda r: (r[2] - r[0]) * (r[3] - r[1])  # noqa: E731
            union = area(ra) + area(rb) - max(0, -gap_r) * max(0, -gap_c)
            if area(box) > (1 + self.merge_slack) * union:
                continue
            if self.boundary_lines(ra, rb) >= self.merge_line_max:
                continue
            new, cut = self.cut_back(wm.replace(wm.remove(self.world, b), a, box), a, box)
            if any(new.active[u] and self.trimmed_by(new, u) > t
                   and (area(new.rects[u]) < self.merge_keep * area(self.world.rects[u])
                        or self.boundary_lines(box, [int(v) for v in new.rects[u]]) < self.trim_line_min)
                   for u in cut):
                continue      # the box would trim a unit to a sliver, or where no wall stands
            changed |= self.tentative(new, (a, b, *cut), [a, *cut])
        return changed

    def _pairs(self):
        """``(a, b, rect a, rect b)`` for each pair of the units active now, skipping a pair once
        an accepted move has removed either (the rectangles are read when the pair comes up)."""
        act = wm.active_slots(self.world).tolist()
        for i, a in enumerate(act):
            for b in act[i + 1:]:
                if self.world.active[a] and self.world.active[b]:
                    yield (a, b, [int(v) for v in self.world.rects[a]],
                           [int(v) for v in self.world.rects[b]])

    def bridges(self, align: int = 3) -> bool:
        """Join two collinear units across the units between them (a corridor in pieces).

        Pairs whose spans across their axis agree within ``align`` cells at both ends, with a gap
        along it of at least a unit side and no wall line across the gap (:meth:`crossing_line`
        below ``merge_line_max``), whose bounding box is corridor-like (Table 4's thresholds: long
        side at least ``corridor_min_ratio`` times the short one, short side under
        ``hall_min_size``): the first unit becomes the box, the second
        is dropped, and every other unit overlapping the box is cut back to its largest part beside
        it (sharing the box's wall band) or dropped when nothing is left; the box and the units
        near it are then wall-moved twice, and the whole kept only if log p rose. A unit that spans
        a corridor and the room beside it (their wall has doors, and the pieces between them are
        too short to be wall-like) is a local optimum for every single move, not for this one.
        """
        d = self.data
        changed = False
        for a, b, ra, rb in self._pairs():
            for axis in (0, 1):
                x = 1 - axis
                if abs(ra[x] - rb[x]) > align or abs(ra[x + 2] - rb[x + 2]) > align:
                    continue
                lo_r, hi_r = (ra, rb) if ra[axis] <= rb[axis] else (rb, ra)
                gap = hi_r[axis] - lo_r[axis + 2]
                if gap < d.min_side:    # something unit-sized lies between
                    continue
                if self.crossing_line(axis, lo_r, hi_r) >= self.merge_line_max:
                    continue          # a wall crosses the gap: two spaces, not one in pieces
                box = [min(ra[0], rb[0]), min(ra[1], rb[1]), max(ra[2], rb[2]), max(ra[3], rb[3])]
                sides = sorted((box[2] - box[0], box[3] - box[1]))
                if (sides[1] < self.evidence.corridor_min_ratio * sides[0]
                        or sides[0] * self.resolution >= self.evidence.hall_min_size):
                    continue          # only corridor-like boxes: a corridor in pieces
                new, cut = self.cut_back(wm.remove(wm.replace(self.world, a, box), b), a, box)
                m = 2 * d.wall_cells   # the units along the box move with it
                near = [u for u in wm.active_slots(new).tolist() if u != a and not (
                    new.rects[u][0] >= box[2] + m or new.rects[u][2] <= box[0] - m
                    or new.rects[u][1] >= box[3] + m or new.rects[u][3] <= box[1] - m)]
                changed |= self.tentative(new, (a, b, *cut), [a, *near] * 2)
                break
        return changed

    def recuts(self, align: int = 3) -> bool:
        """Cut an L-shaped pair of units the other way.

        Two units stacked along one axis (sharing their wall band), one end aligned (within
        ``align`` cells) and one narrower than the other, cover an L. The L has a second cut, along
        the narrower unit's free side: the narrower unit then runs the L's full length and the
        wider one keeps the part beside it (sharing the wall band). Tried for every such pair where
        a wall line (:meth:`boundary_lines` at least ``trim_line_min``) stands along the new cut,
        both units then wall-moved, kept only if log p rose. Two rooms side by side, the second
        shorter, cut across both at the shorter one's end wall (synthetic floor 5) are a local
        optimum for every other move.
        """
        g, t = self.data.wall_share, self.data.wall_cells
        changed = False
        for a, b, ra, rb in self._pairs():
            for axis in (0, 1):                    # stacked along rows (0) or along columns (1)
                x = 1 - axis
                lo_r, hi_r = (ra, rb) if ra[axis] <= rb[axis] else (rb, ra)
                if not 0 <= lo_r[axis + 2] - hi_r[axis] <= max(g, t):
                    continue                       # not stacked with a shared wall band
                wa, wb = ra[x + 2] - ra[x], rb[x + 2] - rb[x]
                if abs(wa - wb) <= align:
                    continue                       # a rectangle, not an L
                (n, rn), (w, rw) = ((a, ra), (b, rb)) if wa < wb else ((b, rb), (a, ra))
                long, short = list(rn), list(rw)
                long[axis], long[axis + 2] = min(ra[axis], rb[axis]), max(ra[axis + 2], rb[axis + 2])
                if abs(rn[x + 2] - rw[x + 2]) <= align:      # aligned at the far end
                    long[x + 2] = max(rn[x + 2], rw[x + 2])
                    short[x + 2] = rn[x] + g
                elif abs(rn[x] - rw[x]) <= align:            # aligned at the near end
                    long[x] = min(rn[x], rw[x])
                    short[x] = rn[x + 2] - g
                else:
                    continue                       # a T, not an L
                if self.boundary_lines(long, short) >= self.trim_line_min:
                    new = wm.replace(wm.replace(self.world, n, long), w, short)
                    changed |= self.tentative(new, (n, w), [n, w])
                break
        return changed

    def trimmed_by(self, new: wm.World, u: int) -> int:
        """How many cells :meth:`cut_back` took off unit ``u`` (the largest move of a side of its
        rectangle from the current world to ``new``)."""
        return int(np.abs(new.rects[u].astype(np.int64) - self.world.rects[u].astype(np.int64)).max())

    def cut_back(self, world: wm.World, a: int, box) -> tuple[wm.World, list]:
        """``world`` with every unit but ``a`` that overlaps ``box`` (by more than the wall band)
        cut back to its largest part beside the box, sharing the box's wall band, or dropped when
        no part of at least a unit side is left; and the slots so changed."""
        g, min_side = self.data.wall_share, self.data.min_side
        cut = []
        for u in wm.active_slots(world).tolist():
            if u == a:
                continue
            ru = [int(v) for v in world.rects[u]]
            if not (ru[0] < box[2] - g and ru[2] > box[0] + g and ru[1] < box[3] - g
                    and ru[3] > box[1] + g):
                continue
            options = []
            for side, value in ((2, box[0] + g), (0, box[2] - g), (3, box[1] + g), (1, box[3] - g)):
                r = list(ru)
                r[side] = value
                if r[2] - r[0] >= min_side and r[3] - r[1] >= min_side:
                    options.append(((r[2] - r[0]) * (r[3] - r[1]), r))
            world = wm.replace(world, u, max(options)[1]) if options else wm.remove(world, u)
            cut.append(u)
        return world, cut

    def tentative(self, new: wm.World, changed, polish) -> bool:
        """Take ``new``, wall-move the units ``polish``, keep it all only if log p rose (else undo)."""
        if not self.valid(new):
            return False
        old, before = self.world, self.tr.logp
        self.tr.accept(self.tr.propose(new, tuple(int(s) for s in changed)))
        for s in polish:
            self.wall_moves(int(s))
        if self.tr.logp > before + 1e-9:
            return True
        diff = np.flatnonzero((old.active != self.world.active)
                              | np.any(old.rects != self.world.rects, axis=1))
        self.tr.accept(self.tr.propose(old, tuple(int(s) for s in diff)))
        return False

    def cuts(self, rect) -> list[tuple[list, list]]:
        """The two pieces of ``rect`` cut at each of its three strongest interior wall lines per
        axis (the pieces share the wall band)."""
        d = self.data
        m, t, g = d.min_side, d.wall_cells, d.wall_share
        rect = [int(v) for v in rect]
        out = []
        for axis in (0, 1):
            lo, hi = rect[axis] + m, rect[axis + 2] + g - m
            if hi < lo:
                continue
            w = band_weights(line_cum(d, axis), lo, hi, -t, t - g, rect[1 - axis], rect[3 - axis],
                             d.settings.line_floor)
            for cut in _line_peaks(w, lo, 3):
                a, b = list(rect), list(rect)
                a[axis + 2], b[axis] = cut, cut - g
                out.append((a, b))
        return out

    def splits(self, double: bool = True) -> bool:
        """Split a unit at its strongest interior wall line when that helps (pieces share the
        wall); when no single cut helps and ``double``, cut one of the two pieces again (a room
        inside an L of walls needs both cuts: each alone leaves a wall-less band across open
        floor)."""
        changed = False
        for s in self.units():
            free = self.free(2)
            if free.size == 0:
                break
            f = int(free[0])
            singles = [wm.add(wm.replace(self.world, s, a), f, b)
                       for a, b in self.cuts(self.world.rects[s])]
            if singles and self.best_of(singles, (s, f)):
                changed = True
                self.wall_moves(s)
                self.wall_moves(f)
                continue
            if not double or free.size < 2 or not singles:
                continue
            f2 = int(free[1])
            doubles = [wm.add(wm.replace(w1, piece, a), f2, b)
                       for w1 in singles for piece in (s, f)
                       for a, b in self.cuts(w1.rects[piece])]
            if doubles and self.best_of(doubles, (s, f, f2)):
                changed = True
                for slot in (s, f, f2):
                    self.wall_moves(slot)
        return changed

    def births(self, covered_frac: float = 0.5) -> bool:
        """Add birth-table boxes over free space that no unit covers, each polished, when that helps."""
        d = self.data
        changed = False
        for box in d.birth_rects.tolist():
            free = self.free(1)
            if free.size == 0:
                break
            r0, c0, r1, c1 = box
            rects = self.world.rects[self.world.active]
            ov = (np.clip(np.minimum(rects[:, 2], r1) - np.maximum(rects[:, 0], r0), 0, None)
                  * np.clip(np.minimum(rects[:, 3], c1) - np.maximum(rects[:, 1], c0), 0, None))
            if ov.sum() > covered_frac * (r1 - r0) * (c1 - c0):
                continue
            slot = int(free[0])   # polished by wall moves, kept only for a net gain
            changed |= self.tentative(wm.add(self.world, slot, box), (slot,), [slot])
        return changed


def refine_world(posterior, world: wm.World, data, *, rounds: int = 3, births: bool = True,
                 merges: bool = True, recuts: bool = False, shared_walls: bool = False,
                 double_cuts: bool = True) -> wm.World:
    """Greedy ascent of ``posterior`` from ``world`` with the kernels' moves (module docstring);
    ``merges=False`` leaves out the merges and the bridges, ``recuts=True`` adds the recuts of
    L-shaped pairs (:meth:`_Ascent.recuts`), ``shared_walls=True`` the moves of whole walls
    (:meth:`_Ascent.shared_wall_moves`), ``double_cuts=False`` the second cut of a piece when no
    single cut helps (:meth:`_Ascent.splits`); W*'s polish is :func:`polish`.

    Parameters
    ----------
    posterior : Posterior
        The target to climb: the knowledge-free one (``knowledge_on = False``) for a start world,
        the full one for W*'s polish.
    world : World
        The start (e.g. :func:`semmap_pp.sampler.start_worlds.start_world`, or W*); must have a finite log
        posterior.
    data : KernelData
        The kernels' data of the same lattice (line evidence, birth table).
    rounds : int
        Passes of removals, wall moves, merges, bridges, splits and births (stops early when nothing
        changes); with ``shared_walls`` also the bound on the passes of whole-wall moves, and on
        how often the phases alternate: after whole walls moved, the moves that join or drop
        units (removals, wall moves, merges, bridges) run again, since a moved wall may open a
        merge (synthetic floor 27's corridor in two pieces, joined for +287.6 nats); splits,
        recuts and births do not (with them aces' south corridor came out in three pieces;
        CHANGELOG.md, quality change 33).

    Returns
    -------
    World
        A world whose log posterior is at least that of ``world`` (types left undecided).
    """
    asc = _Ascent(posterior, world, data)
    if not np.isfinite(asc.tr.logp):
        return world

    def one_round() -> bool:
        changed = asc.removals()
        changed |= asc.all_wall_moves()
        changed |= asc.removals()
        if merges:
            changed |= asc.merges()
            changed |= asc.bridges()
        if recuts:
            changed |= asc.recuts()
        changed |= asc.splits(double_cuts)
        if births:
            changed |= asc.births()
        return changed

    def join_round() -> bool:     # after whole walls moved: nothing cut, nothing born
        changed = asc.removals()
        changed |= asc.all_wall_moves()
        if merges:
            changed |= asc.merges()
            changed |= asc.bridges()
        return changed

    for phase in range(rounds if shared_walls else 1):
        for _ in range(rounds):
            if not (one_round() if phase == 0 else join_round()):
                break
        if not shared_walls:
            break
        walls_moved = False   # from where the other moves stop: the same world or a better one
        for _ in range(rounds):
            moved = asc.shared_wall_moves()
            if not moved:
                break
            walls_moved = True
            asc.all_wall_moves(asc.near(moved))   # the walls the moved ones may have unblocked
        if not walls_moved:   # else the joining moves again: a moved wall may open a merge
            break
    out = asc.untyped()
    if out.capacity > world.capacity and wm.n_units(out) <= world.capacity:
        out = wm.fit(out, world.capacity)   # grown on the way but fits again: the caller's slots
    return out


def polish(posterior, world: wm.World, data, rounds: int) -> wm.World:
    """W*'s polish: :func:`refine_world` of the full target with the recuts and the whole-wall
    moves, without double cuts and births. The knowledge-free start ascent cuts rooms out of
    L-shaped walls with two cuts and covers free space by births already; in the polish, under a
    rule file off the fast path, the second cuts took two thirds of its time on cartesium and the
    births a third on aces. Without the double cuts no W* of the 30 synthetic floors, the ipa
    types plans, cartesium, aces or freiburg-079 changed (CHANGELOG.md, quality change 35);
    without the births too, no W* measured changed at all (quality change 36)."""
    return refine_world(posterior, world, data, rounds=rounds, recuts=True, shared_walls=True,
                        double_cuts=False, births=False)


def snap_walls(posterior, world: wm.World, data, slots, *, reach: int, rounds: int = 2) -> wm.World:
    """Each wall of the units in ``slots`` to its best position within ``reach`` cells of where it
    is (local steps only, no line peak farther away, no unit swallowed), for up to ``rounds``
    passes: the walls of a hand-edited world (``semmap edit``) set on the map's own lines near
    the points given. Returns a world whose log posterior is at least that of ``world``, or
    ``world`` itself when its log posterior is not finite or ``reach`` is 0."""
    if reach <= 0:
        return world
    asc = _Ascent(posterior, world, data, peaks=0, local=int(reach), absorb_share=2.0)
    return _wall_rounds(asc, world, rounds, {int(s) for s in slots})


def align_walls(posterior, world: wm.World, data, *, rounds: int = 3) -> wm.World:
    """Wall moves only: each wall of each unit to its best position, for up to ``rounds`` passes.

    Sets given rectangles (a ground truth drawn in another frame, a hand-made world) on the
    lattice's best walls without adding, removing, merging or cutting units — except that a wall
    moved outwards may swallow a unit lying mostly inside the grown one (:meth:`_Ascent.wall_moves`).
    Returns a world whose log posterior is at least that of ``world`` (types left undecided), or
    ``world`` itself when its log posterior is not finite.
    """
    return _wall_rounds(_Ascent(posterior, world, data), world, rounds)


def _wall_rounds(asc: _Ascent, world: wm.World, rounds: int, within=None) -> wm.World:
    """Up to ``rounds`` passes of ``asc``'s wall moves (of the units in ``within``, when given)
    from ``world``, stopping when a pass moves nothing; ``world`` when its log p is not finite."""
    if not np.isfinite(asc.tr.logp):
        return world
    for _ in range(rounds):
        if not asc.all_wall_moves(within):
            break
    return asc.untyped()
