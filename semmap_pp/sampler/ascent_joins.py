"""The ascent's moves that join units (:mod:`semmap_pp.sampler.ascent`): merges of two units
into their bounding box, bridges of a corridor in pieces, and recuts of an L-shaped pair."""

from __future__ import annotations

import numpy as np

from semmap_pp import world as wm
from semmap_pp.sampler.ascent_walls import WallMoves


def _strongest_line(cum: np.ndarray, i0: int, i1: int, s0: int, s1: int) -> float:
    """The largest share of wall or door cells on lines ``i0..i1`` over the span ``s0..s1``
    (``cum``: the lines' cumulative counts along the span)."""
    return float(((cum[i0:i1, s1] - cum[i0:i1, s0]) / float(s1 - s0)).max())


class JoinMoves(WallMoves):
    """Merges, bridges and recuts: moves that replace two units by one or cut a pair anew, each
    wall-moved and kept only when log p rose (:meth:`WallMoves.tentative`)."""

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
        changed, tries = False, self.failed_tries("merges")
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
            key = None if tries is None else self.local_key(box)
            if key is not None and tries.skip((a, b), key):
                continue
            new, cut = self.cut_back(wm.replace(wm.remove(self.world, b), a, box), a, box)
            if any(new.active[u] and self.trimmed_by(new, u) > t
                   and (area(new.rects[u]) < self.merge_keep * area(self.world.rects[u])
                        or self.boundary_lines(box, [int(v) for v in new.rects[u]]) < self.trim_line_min)
                   for u in cut):
                continue      # the box would trim a unit to a sliver, or where no wall stands
            changed |= self._tried(tries, (a, b), key, self.tentative(new, (a, b, *cut), [a, *cut]))
        return self._ended(tries, changed)

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
        changed, tries = False, self.failed_tries("bridges")
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
                key = None if tries is None else self.local_key(box)
                if key is not None and tries.skip((a, b, axis), key):
                    break
                new, cut = self.cut_back(wm.remove(wm.replace(self.world, a, box), b), a, box)
                m = 2 * d.wall_cells   # the units along the box move with it
                near = [u for u in wm.active_slots(new).tolist() if u != a and not (
                    new.rects[u][0] >= box[2] + m or new.rects[u][2] <= box[0] - m
                    or new.rects[u][1] >= box[3] + m or new.rects[u][3] <= box[1] - m)]
                changed |= self._tried(tries, (a, b, axis), key,
                                       self.tentative(new, (a, b, *cut), [a, *near] * 2))
                break
        return self._ended(tries, changed)

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
