"""The greedy ascent's state and its wall moves (:mod:`semmap_pp.sampler.ascent`).

:class:`Climb` holds a tracker of the target and the kernels' data, and takes a candidate world
only when it raises log p; :class:`WallMoves` moves the walls of units, one edge at a time or every
edge on one wall together.
"""

from __future__ import annotations

import functools
import math
import os

import numba
import numpy as np

from semmap_pp import world as wm
from semmap_pp.forked import Forked
from semmap_pp.model import MAX_K
from semmap_pp.target.posterior import below_floor
from semmap_pp.target.prior import all_valid
from semmap_pp.sampler.kernels.shrink_dilate import wall_range

#: The ascent grows a full world's capacity up to this many slots (the model's bound on k_max).
MAX_CAPACITY = MAX_K


# The resolution at which ``[kernels] ascent_peaks`` is given (the maps the model was measured on).
PEAKS_RESOLUTION = 0.05

#: :meth:`Climb.each` hands half of a loop to a forked process only from this many items on.
FORK_MIN_ITEMS = 6


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


def _first_success(attempt, items, parent: int):
    """The index of the first of ``items`` for which ``attempt`` returns True, None when none
    does: :meth:`Climb.each`'s forked half. In the process ``parent`` itself (no process could be
    forked, or it failed) it tries nothing and returns ``False``."""
    if os.getpid() == parent:
        return False
    for k, x in enumerate(items):
        if attempt(x):
            return k
    return None


class FailedTries:
    """The tries of one move kind (each an item, such as a pair of units, with the
    :meth:`Climb.local_key` of what it meets) that failed in the kind's last call that changed
    nothing. W*'s polish does not try such an item again while its key is the same: its later
    rounds mostly move a few walls, far from most of the tries (not exact: a try could meet types
    changed by an edit farther away; docs/sampler.md, "crosses")."""

    def __init__(self):
        self._last: dict = {}
        self._now: dict = {}

    def skip(self, item, key: bytes) -> bool:
        """Whether ``item`` failed last time with the same ``key`` (it is then kept as failed)."""
        if self._last.get(item) == key:
            self._now[item] = key
            return True
        return False

    def failed(self, item, key: bytes) -> None:
        self._now[item] = key

    def end(self, changed: bool) -> None:
        """The end of a call: its failures are kept only when it changed nothing."""
        self._last, self._now = ({} if changed else self._now), {}


class Climb:
    """Greedy ascent state: a tracker of the target and the kernels' data."""

    #: Whether the loops of :meth:`each` try half of their items in a forked process meanwhile
    #: (two cores; set by :func:`~semmap_pp.sampler.ascent.refine_world`).
    fork = False
    #: Per move kind its :class:`FailedTries` (W*'s polish: the crosses, merges and bridges),
    #: None: every try made in every call.
    tries: dict | None = None

    def failed_tries(self, kind: str) -> FailedTries | None:
        """The :class:`FailedTries` of move ``kind``; None when they are not kept."""
        return None if self.tries is None else self.tries.setdefault(kind, FailedTries())

    @staticmethod
    def _tried(tries: FailedTries | None, item, key, kept: bool) -> bool:
        """``kept``, the outcome of a try of ``item``, noted in ``tries`` when it failed."""
        if tries is not None and not kept:
            tries.failed(item, key)
        return kept

    @staticmethod
    def _ended(tries: FailedTries | None, changed: bool) -> bool:
        """``changed``, the outcome of a call, after :meth:`FailedTries.end`."""
        if tries is not None:
            tries.end(changed)
        return changed

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

    def propose_above(self, new: wm.World, changed, floor: float, bound: float | None = None):
        """``new``'s proposal, for a caller that takes it only when its log p exceeds ``floor``.

        A tracker that :attr:`supports_floor` may skip the knowledge inference of a proposal whose
        type-free upper bound (``bound``, when the caller has it from :meth:`bound_order`) is
        already below ``floor`` (its ``logp`` is then ``-inf``): the same choices as with every
        proposal evaluated, fewer inferences.
        """
        if getattr(self.tr, "supports_floor", False):
            return self.tr.propose(new, changed, floor=floor, bound=bound)
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
        best = self.best_proposal([(w, changed) for w in worlds if self.valid(w)])
        if best is None:
            return False
        self.tr.accept(best)
        return True

    def best_proposal(self, candidates):
        """The proposal of highest log p among ``candidates`` (valid ``(world, changed)`` pairs),
        when it exceeds the current log p; the first in the list of those that tie; else None.

        With a tracker that takes floors and has an
        :meth:`~semmap_pp.target.posterior.Tracker.upper_bound`, the
        candidates are tried in the order of their bounds, highest first, each with the best log p
        so far as its floor, and the search stops at the first bound below it: the best comes
        early and raises the floor, so that most of the others are skipped before their types
        are inferred. The choice is the one made by trying them all in list order."""
        floor = self.tr.logp + 1e-9
        bounds, order = self.bound_order(candidates)
        best, best_lp, best_i = None, floor, len(candidates)
        for i in order:
            if bounds is not None and below_floor(bounds[i], best_lp):
                break                # this bound and every later one lie below the best so far
            w, changed = candidates[i]
            prop = self.propose_above(w, changed, best_lp, None if bounds is None else bounds[i])
            if prop.logp > best_lp or (best is not None and prop.logp == best_lp and i < best_i):
                best, best_lp, best_i = prop, prop.logp, i
        return best

    def bound_order(self, candidates):
        """``(bounds, order)``: the candidates' upper bounds and their indices highest bound
        first (a NaN bound, never below a floor, first with +inf), when the tracker takes floors
        and has :meth:`~semmap_pp.target.posterior.Tracker.upper_bound` and there are several;
        else ``(None, list order)``."""
        bound = (getattr(self.tr, "upper_bound", None)
                 if len(candidates) > 1 and getattr(self.tr, "supports_floor", False) else None)
        if bound is None:
            return None, range(len(candidates))
        bounds = [bound(w, changed) for w, changed in candidates]
        return bounds, sorted(range(len(candidates)),
                              key=lambda i: -bounds[i] if bounds[i] == bounds[i] else -math.inf)

    def best_few(self, candidates, k: int) -> list:
        """The worlds of the ``k`` candidates (valid ``(world, changed)`` pairs) of highest log p,
        highest first, the earlier in the list first on a tie: what scoring every candidate in
        full gives. In the order of their bounds (:meth:`bound_order`), each scored with the
        ``k``-th best log p so far as its floor, stopping at the first bound below it: the rest
        cannot be among the ``k``, and their types are never inferred."""
        bounds, order = self.bound_order(candidates)
        scored = []                                   # (log p, index), -inf when bounded
        for i in order:
            floor = sorted(lp for lp, _ in scored)[-k] if len(scored) >= k else -math.inf
            if bounds is not None and floor > -math.inf and below_floor(bounds[i], floor):
                break
            w, changed = candidates[i]
            prop = (self.propose_above(w, changed, floor, None if bounds is None else bounds[i])
                    if floor > -math.inf else self.tr.propose(w, changed))
            scored.append((prop.logp, i))
        return [candidates[i][0] for _, i in sorted(scored, key=lambda x: (-x[0], x[1]))[:k]]

    def each(self, items, attempt) -> bool:
        """``attempt(x)`` for each of ``items`` in turn, each on the world the ones before left;
        whether any of them returned True (changed the world).

        With :attr:`fork`, the second half of the items is tried meanwhile in a forked process,
        on the world as it is when the first half begins, up to its first success. When the first
        half changes nothing, that is what trying the second half here would do: only its first
        success is tried again here, and the items after it go on the same way; when the first
        half changes the world, the other process's answer is dropped. Either way the outcome is
        that of trying every item in turn here (the attempts are deterministic), in less time
        when most attempts fail, as a unit's crosses do; where many succeed (the wall moves) the
        forks cost more than they save. Without a process to fork (one core, a pool's worker,
        another thread running) the items are tried here."""
        items, changed = list(items), False
        while items:
            if not self.fork or len(items) < FORK_MIN_ITEMS:
                for x in items:
                    changed |= bool(attempt(x))
                return changed
            first, second = items[:len(items) // 2], items[len(items) // 2:]
            job = Forked(functools.partial(_first_success, attempt, second, os.getpid()), fork=True)
            try:
                hit = next((k for k, x in enumerate(first) if attempt(x)), None)
                if hit is not None:            # the world changed: the other answer is void
                    changed, items = True, first[hit + 1:] + second
                    continue
                found = job.result()
            finally:
                job.close()
            if found is False:                 # no process was forked: the second half here
                items, self.fork = second, False
                continue
            if found is None:                  # nothing in the second half changes the world
                return changed
            changed |= bool(attempt(second[found]))
            items = second[found + 1:]
        return changed

    def units(self, within=None) -> list:
        """The active slots, in slot order: all, or those in the set ``within``."""
        act = wm.active_slots(self.world).tolist()
        return act if within is None else [s for s in act if s in within]

    def near(self, slots) -> set:
        """``slots`` and the active units within two wall bands of any of them."""
        out = np.zeros(self.world.capacity, bool)
        for s in slots:
            if self.world.active[s]:
                out |= self._near_box(self.world.rects[s])
        return set(np.flatnonzero(out).tolist())

    def _near_box(self, r) -> np.ndarray:
        """(K,) bool: the active units within two wall bands of the box ``r``."""
        rects, t = self.world.rects, 2 * int(self.data.wall_cells)
        return self.world.active & ((rects[:, 0] <= r[2] + t) & (rects[:, 2] >= r[0] - t)
                                    & (rects[:, 1] <= r[3] + t) & (rects[:, 3] >= r[1] - t))

    def local_key(self, box) -> bytes:
        """``box`` with the slots and rectangles of the units within two wall bands of it: what a
        try over ``box`` meets, for :class:`FailedTries`."""
        near = np.flatnonzero(self._near_box(box))
        return (np.asarray(box, np.int64).tobytes() + near.astype(np.int64).tobytes()
                + np.asarray(self.world.rects[near], np.int64).tobytes())

    def untyped(self) -> wm.World:
        """The current world with its types left undecided (what the ascent returns)."""
        return wm.make(self.world.rects, self.world.active, np.full(self.world.capacity, wm.NO_TYPE))

    def removals(self) -> bool:
        changed = False
        for s in self.units():
            changed |= self.try_world(wm.remove(self.world, s), (s,))
        return changed


class WallMoves(Climb):
    """The wall moves of the ascent: each wall of a unit to its best position, or every edge on
    one wall together, and a candidate world kept only when its wall-moved units raise log p."""

    def tentative(self, new: wm.World, changed, polish, keep=None, alive=()) -> bool:
        """Take ``new``, wall-move the units ``polish``, keep it all only if log p rose (else undo);
        with ``keep`` (a test of the world then) also only if it passes, and with ``alive`` (slots)
        only if every one of them is still a unit: a wall move drops units and never adds one, so
        the wall moves stop as soon as one of them is gone (the same outcome, sooner)."""
        if not self.valid(new):
            return False
        old, before = self.world, self.tr.logp
        self.tr.accept(self.tr.propose(new, tuple(int(s) for s in changed)))

        def lost() -> bool:
            return not all(self.world.active[int(a)] for a in alive)

        for s in polish:
            if lost():
                break
            self.wall_moves(int(s))
        if not lost() and self.tr.logp > before + 1e-9 and (keep is None or keep(self.world)):
            return True
        diff = np.flatnonzero((old.active != self.world.active)
                              | np.any(old.rects != self.world.rects, axis=1))
        self.tr.accept(self.tr.propose(old, tuple(int(s) for s in diff)))
        return False

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
            candidates = []
            for c in self.positions(rect, side):
                r = list(rect)
                r[side] = c
                new, gone = self.absorb(wm.replace(self.world, slot, r), slot)
                if self.valid(new):
                    candidates.append((new, (slot, *gone)))
            best = self.best_proposal(candidates)
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
