"""The ascent's moves that cut and add units (:mod:`semmap_pp.sampler.ascent`): splits at wall
lines and births over uncovered free space."""

from __future__ import annotations

import numpy as np

from semmap_pp import world as wm
from semmap_pp.sampler.ascent_walls import WallMoves, _line_peaks
from semmap_pp.sampler.kernels.common import band_weights, line_cum


class CutMoves(WallMoves):
    """Splits of a unit at its strongest wall lines and births of units over free space."""

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
