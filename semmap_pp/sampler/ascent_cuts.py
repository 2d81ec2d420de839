"""The ascent's moves that cut and add units (:mod:`semmap_pp.sampler.ascent`): splits at wall
lines, crosses (a unit cut along both axes at once into four spaces), jogs (a unit cut where a
neighbour's wall lies inside it, the wall moved with the neighbour's) and births over uncovered
free space."""

from __future__ import annotations

import functools

import numpy as np

from semmap_pp import world as wm
from semmap_pp.sampler.ascent_walls import WallMoves, _line_peaks
from semmap_pp.sampler.kernels.common import band_weights, line_cum
from semmap_pp.sampler.kernels.shrink_dilate import wall_range


def _wall_runs(w: np.ndarray, lo: int, k: int, local: int) -> list[int]:
    """Positions (``lo`` + index) at the ``k`` strongest peaks of ``w``, a run of equal values
    counting as one peak: a peak of one position as it is, a longer run (a plateau) with every
    position on it and ``local`` steps past either end.

    The band weights of :func:`~semmap_pp.sampler.kernels.common.band_weights` saturate where
    several lines in a row are wall or door cells over the whole span (a cupboard against a wall,
    its gaps to the side walls of door width): each position of such a plateau is a peak of
    :func:`~semmap_pp.sampler.ascent_walls._line_peaks`, so its three strongest peaks were three
    neighbouring lines of one wall, and the line evidence cannot tell where on the plateau the
    wall is. The target does, as a wall move's local steps let it do for one wall.

    >>> _wall_runs(np.array([0.1, 1.0, 1.0, 1.0, 0.1, 0.1, 0.6, 0.1, 0.4, 0.1]), 100, 2, 1)
    [100, 101, 102, 103, 104, 106]
    """
    if w.size == 0:
        return []
    n = w.size
    starts = np.flatnonzero(np.concatenate([[True], w[1:] != w[:-1]]))
    ends = np.concatenate([starts[1:], [n]]) - 1
    vals = w[starts]
    left = np.concatenate([[-np.inf], vals[:-1]])
    right = np.concatenate([vals[1:], [-np.inf]])
    idx = np.flatnonzero((vals >= left) & (vals >= right) & (vals > w.min()))
    out = set()
    for i in idx[np.argsort(-vals[idx], kind="stable")][:k].tolist():
        a, b = int(starts[i]), int(ends[i])
        if b > a:
            a, b = max(a - local, 0), min(b + local, n - 1)
        out.update(range(a, b + 1))
    return sorted(v + lo for v in out)


class CutMoves(WallMoves):
    """Splits and crosses of a unit at its strongest wall lines, jogs, and births of units over
    free space."""

    def cut_lines(self, rect, axis: int, wide: bool = False) -> list[int]:
        """Where ``rect`` may be cut across ``axis``: its three strongest interior wall lines
        (pieces of at least ``min_side``); ``wide``: the three strongest runs of lines, a
        plateau of equal line evidence tried all along and ``local`` steps past its ends
        (:func:`_wall_runs`)."""
        d = self.data
        m, t, g = d.min_side, d.wall_cells, d.wall_share
        lo, hi = rect[axis] + m, rect[axis + 2] + g - m
        if hi < lo:
            return []
        w = band_weights(line_cum(d, axis), lo, hi, -t, t - g, rect[1 - axis], rect[3 - axis],
                         d.settings.line_floor)
        return _wall_runs(w, lo, 3, self.local) if wide else _line_peaks(w, lo, 3)

    def cuts(self, rect, wide: bool = False) -> list[tuple[list, list]]:
        """The two pieces of ``rect`` cut at each of its :meth:`cut_lines` per axis (the pieces
        share the wall band)."""
        g = self.data.wall_share
        rect = [int(v) for v in rect]
        out = []
        for axis in (0, 1):
            for cut in self.cut_lines(rect, axis, wide):
                a, b = list(rect), list(rect)
                a[axis + 2], b[axis] = cut, cut - g
                out.append((a, b))
        return out

    def crosses(self) -> bool:
        """Cut a unit along both axes at once into four pieces when that helps: a unit over four
        spaces that meet at a junction of walls (a corridor, the clutter beside it and two rooms
        behind a broken wall), out of which no single or double cut climbs. Each piece of a cut
        there is a long strip typed as a corridor, whose clutter and unknown cells the corridor's
        sensor row makes dear, so every cut alone lowers log p, while the four pieces, their
        walls moved, are a room, a room, the clutter and the corridor.

        The crosses are the pairs of :meth:`cut_lines` (three per axis; the four pieces share
        the wall bands, as a split's); the ``[kernels] cross_tries`` best by log p as cut are
        tried in turn, each with its four pieces wall-moved (:meth:`tentative`), and the first
        that raises log p with four spaces is kept: every piece still there (a cross one of
        whose pieces a wall move absorbs carves the unit, and cut freiburg_building101's rooms
        into pieces) and at least ``2 min_side`` long (the ascent's fragments are narrower than
        that; a piece shorter both ways is a corner of furniture, not a space: docs/sampler.md).
        In W*'s polish (:class:`~semmap_pp.sampler.ascent_walls.FailedTries`), after a call that
        kept none the next one tries only the units whose rectangle or a near unit's
        (:meth:`local_key`) changed since: the polish's later rounds mostly move a few walls (not
        exact; docs/sampler.md, "crosses")."""
        tries = int(self.data.settings.cross_tries)
        if tries <= 0:
            return False
        failed = self.failed_tries("crosses")
        keys = None if failed is None else {s: self.local_key(self.world.rects[s]) for s in self.units()}
        todo = [s for s in self.units() if keys is None or not failed.skip(s, keys[s])]
        changed = self.each(todo, functools.partial(self._cross, tries=tries))
        if failed is not None:    # (half of them may be tried in a forked process: noted here)
            for s in todo:        # dropped by ``end`` when a cross was kept
                failed.failed(s, keys[s])
        return self._ended(failed, changed)

    def _cross(self, s: int, tries: int) -> bool:
        """:meth:`crosses` of unit ``s``: whether one of its crosses was kept."""
        g, least = self.data.wall_share, 2 * int(self.data.min_side)
        if not self.world.active[s]:
            return False
        r0, c0, r1, c1 = rect = [int(v) for v in self.world.rects[s]]
        rows, cols = self.cut_lines(rect, 0), self.cut_lines(rect, 1)
        if not rows or not cols:
            return False
        slots = (s, *(int(f) for f in self.free(3)[:3]))
        if len(slots) < 4:            # a full world at its largest capacity
            return False
        crosses = []
        for r in rows:
            for c in cols:
                pieces = ([r0, c0, r, c], [r0, c - g, r, c1], [r - g, c0, r1, c], [r - g, c - g, r1, c1])
                new = wm.replace(self.world, s, pieces[0])
                for slot, piece in zip(slots[1:], pieces[1:]):
                    new = wm.add(new, slot, piece)
                if self.valid(new):
                    crosses.append((new, slots))

        def spaces(world) -> bool:      # (every piece still there: ``alive``)
            sides = np.diff(world.rects[list(slots)].reshape(-1, 2, 2), axis=1)[:, 0]
            return bool((sides.max(axis=1) >= least).all())

        return any(self.tentative(new, slots, slots, keep=spaces, alive=slots)
                   for new in self.best_few(crosses, tries))     # the best by log p as cut

    def splits(self, double: bool = True, wide: bool = False) -> bool:
        """Split a unit at its strongest interior wall line when that helps (pieces share the
        wall); when no single cut helps and ``double``, cut one of the two pieces again (a room
        inside an L of walls needs both cuts: each alone leaves a wall-less band across open
        floor). ``wide``: the single cuts at the strongest runs of lines (:meth:`cuts`)."""
        changed = False
        for s in self.units():
            free = self.free(2)
            if free.size == 0:
                break
            f = int(free[0])
            singles = [wm.add(wm.replace(self.world, s, a), f, b)
                       for a, b in self.cuts(self.world.rects[s], wide)]
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

    def jogs(self) -> bool:
        """Where a wall jogs: the piece of a unit facing one neighbour cut off, and its wall moved
        into the unit together with the neighbour's facing wall, when that helps.

        A corridor along a row of offices whose walls to it do not all lie on one line (two
        offices deeper than the others) is one rectangle only if it reaches into the deeper
        offices; their walls then lie inside it, and its border with them, on open floor, reads
        as a passage. No single move mends it: a cut alone adds a unit, a wall of the corridor
        moved alone opens a gap, the office's moved alone overlaps the corridor. Each unit ``s``
        and each neighbour ``v`` whose facing edge lies on a side of ``s`` (within two wall
        bands) over part of its span: ``s`` is cut where ``v``'s span begins and ends (the pieces
        share their wall bands, as a split's), unless a wall line stands on their border
        (:meth:`~semmap_pp.sampler.ascent_joins.JoinMoves.boundary_lines` at least
        ``trim_line_min``), and the middle piece's side and ``v``'s facing edge move together
        into ``s``, to the line-evidence peaks inside it (:meth:`inward_peaks`); the best is
        kept when it raises log p, and its pieces' walls then move to their best positions."""
        changed = False
        for s in self.units():
            for side in range(4):
                if self.world.active[s]:
                    changed |= self._jog(s, side)
        return changed

    def _jog(self, s: int, side: int) -> bool:
        """:meth:`jogs` for the side ``side`` of unit ``s``: the best jog over its neighbours."""
        d = self.data
        m, g, tol = int(d.min_side), int(d.wall_share), 2 * int(d.wall_cells)
        along, opp = 1 - side % 2, (side + 2) % 4
        worlds, changed, free = [], set(), self.free(2)
        rects, act = self.world.rects, self.world.active
        rect = [int(v) for v in rects[s]]
        lo, hi = rect[along], rect[along + 2]
        for v in np.flatnonzero(act).tolist():
            if v == s or abs(int(rects[v][opp]) - rect[side]) > tol:
                continue
            a, b = max(int(rects[v][along]), lo), min(int(rects[v][along + 2]), hi)
            cut_a, cut_b = a - lo >= m, hi - b >= m      # a piece of s before / after v's span
            if b - a < m or not (cut_a or cut_b) or \
                    self.boundary_lines(rect, [int(x) for x in rects[v]]) >= self.trim_line_min:
                continue                                 # (a wall line stands on their border)
            pieces = ([(lo, a + g)] if cut_a else []) + [(a if cut_a else lo, b if cut_b else hi)] \
                + ([(b - g, hi)] if cut_b else [])
            mid = 1 if cut_a else 0
            slots = [s] + [int(f) for f in free[:len(pieces) - 1]]
            base = self.world
            for slot, (p0, p1) in zip(slots, pieces):
                r = list(rect)
                r[along], r[along + 2] = p0, p1
                base = wm.replace(base, slot, r) if slot == s else wm.add(base, slot, r)
            middle = [int(x) for x in base.rects[slots[mid]]]
            for c in self.inward_peaks(middle, side):
                shift = c - middle[side]
                new = np.array(base.rects)
                new[slots[mid], side] += shift
                new[v, opp] += shift
                worlds.append(wm.make(new, base.active, base.types))
            changed.update((*slots, v))
        if not worlds or not self.best_of(worlds, tuple(sorted(changed))):
            return False
        for slot in sorted(changed):
            if self.world.active[slot]:
                self.wall_moves(slot)
        return True

    def inward_peaks(self, rect, side: int) -> list:
        """The strongest line-evidence peaks for wall ``side`` of ``rect`` inside it, beyond a
        wall move's local steps (:attr:`local`): where a wall of ``rect`` could jog to. The
        peaks over the whole range of the wall (:meth:`positions`) are often the lines of the
        walls beyond the unit, stronger than a wall with a door inside it."""
        _, lo, hi, w = wall_range(rect, side, self.data)
        x = int(rect[side])
        a, b = (max(lo, x + self.local + 1), hi) if side < 2 else (lo, min(hi, x - self.local - 1))
        if b < a:
            return []
        return _line_peaks(w[a - lo:b - lo + 1], a, self.peaks)

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
