"""Data-driven start worlds: a greedy cover of the free space by maximal rectangles.

The paper starts from "a random initial guess"; a chain started there spends most of its time
finding the obvious. Here the first chain starts from a deterministic decomposition of the free space
of the building lattice, and the other chains from dispersed variants of it (units dropped, split or
jittered at random), so that chains begin in different places and R-hat means something.

The decomposition works on a coarsened copy of the map (``factor`` lattice cells per coarse cell):
small holes in the free space (furniture, speckle) are filled, a coarse cell is free when most of its
cells are, and maximal all-free rectangles are taken greedily, largest first, until no rectangle of
the minimum side is left. Each rectangle is then mapped back to the lattice, grown by the wall band
so that its walls lie on the surrounding occupied cells, and each edge snapped to the strongest wall
line (row or column of occupied cells) nearby.

Examples
--------
>>> import numpy as np
>>> from semmap_pp.cells import FREE, OCCUPIED, UNKNOWN
>>> m = np.full((40, 60), UNKNOWN, np.uint8)
>>> m[5:35, 5:55] = OCCUPIED
>>> m[7:33, 7:30] = FREE; m[7:33, 32:53] = FREE   # two rooms, a wall between them
>>> rects = greedy_rectangles(m, min_side=6, wall_cells=2, factor=2, max_units=5)
>>> sorted(rects)
[(5, 5, 35, 32), (5, 30, 35, 55)]
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage as ndi

from semmap_pp import world as wm
from semmap_pp.cells import FREE, OCCUPIED


def largest_rectangle(mask: np.ndarray) -> tuple[int, int, int, int, int]:
    """Largest all-True axis-aligned rectangle of a boolean array.

    Returns ``(area, r0, c0, r1, c1)`` (half-open); area 0 when the mask is empty. Histogram-and-stack
    method, O(rows * cols).

    >>> largest_rectangle(np.array([[0, 1, 1], [1, 1, 1], [0, 1, 1]], bool))
    (6, 0, 1, 3, 3)
    """
    rows, cols = mask.shape
    heights = np.zeros(cols + 1, np.int64)  # sentinel column of height 0 flushes the stack
    best = (0, 0, 0, 0, 0)
    for r in range(rows):
        heights[:cols] = np.where(mask[r], heights[:cols] + 1, 0)
        h = heights.tolist()
        stack: list[int] = []
        for c in range(cols + 1):
            start = c
            while stack and h[stack[-1]] >= h[c]:
                top = stack.pop()
                left = stack[-1] + 1 if stack else 0
                area = h[top] * (c - left)
                if area > best[0]:
                    best = (area, r - h[top] + 1, left, r + 1, c)
                start = left
            del start
            stack.append(c)
    return best


def _fill_small_holes(free: np.ndarray, max_hole: int) -> np.ndarray:
    """Free mask with non-free components of at most ``max_hole`` cells enclosed by free space filled."""
    labels, n = ndi.label(~free)
    if n == 0:
        return free
    sizes = np.bincount(labels.ravel())
    small = sizes <= max_hole
    small[0] = False
    return free | small[labels]


def _snap_band(profile: np.ndarray, guess: int, radius: int, width: int) -> int:
    """Start of the ``width``-line band within ``guess ± radius`` holding the most occupied cells.

    ``profile`` counts occupied cells per line; ties go to the start nearest ``guess``.
    """
    band = np.convolve(profile, np.ones(width, profile.dtype), mode="valid")  # band[i] = sum profile[i:i+width]
    lo, hi = max(0, guess - radius), min(len(band), guess + radius + 1)
    if hi <= lo or band[lo:hi].max() == 0:
        return guess
    cand = np.arange(lo, hi)
    best = band[lo:hi] == band[lo:hi].max()
    return int(cand[best][np.argmin(np.abs(cand[best] - guess))])


def greedy_rectangles(classes: np.ndarray, *, min_side: int, wall_cells: int, factor: int,
                      max_units: int, max_hole: int | None = None, min_free: float = 0.9) -> list[tuple[int, int, int, int]]:
    """Greedy maximal-rectangle cover of the free space of a lattice class map.

    Parameters
    ----------
    classes : (H, W) uint8 lattice classes (``cells.FREE`` / ``UNKNOWN`` / ``OCCUPIED``)
    min_side : smallest unit side in lattice cells (walls included)
    wall_cells : thickness of a unit's wall band in cells
    factor : lattice cells per coarse cell (speed; the snapping restores full resolution)
    max_units : stop after this many rectangles
    max_hole : largest non-free blob (cells) filled as furniture; default ``4 * min_side ** 2``
    min_free : fraction of free cells that makes a coarse cell free

    Returns
    -------
    list of ``(r0, c0, r1, c1)`` lattice rectangles including their wall bands, largest first.
    """
    H, W = classes.shape
    free = classes == FREE
    occ = (classes == OCCUPIED).astype(np.int32)
    if max_hole is None:
        max_hole = min_side * min_side * 4
    free = _fill_small_holes(free, max_hole)
    h, w = H // factor, W // factor
    if h == 0 or w == 0:
        return []
    # a coarse cell is free only when nearly all of it is: a dashed wall line must still stop a rectangle
    coarse = free[:h * factor, :w * factor].reshape(h, factor, w, factor).mean(axis=(1, 3)) >= min_free
    min_coarse = max(1, (min_side - 2 * wall_cells) // factor)
    rects: list[tuple[int, int, int, int]] = []
    radius = factor + wall_cells
    for _ in range(8 * max_units):  # thin leftovers are consumed without becoming units
        if len(rects) >= max_units:
            break
        area, R0, C0, R1, C1 = largest_rectangle(coarse)
        if area < min_coarse * min_coarse:
            break
        coarse[R0:R1, C0:C1] = False
        if min(R1 - R0, C1 - C0) < min_coarse:
            continue
        r0, c0, r1, c1 = R0 * factor - wall_cells, C0 * factor - wall_cells, R1 * factor + wall_cells, \
            C1 * factor + wall_cells
        rows_band, cols_band = slice(max(r0, 0), min(r1, H)), slice(max(c0, 0), min(c1, W))
        row_profile = occ[:, cols_band].sum(axis=1)
        col_profile = occ[rows_band, :].sum(axis=0)
        r0 = _snap_band(row_profile, r0, radius, wall_cells)
        r1 = _snap_band(row_profile, r1 - wall_cells, radius, wall_cells) + wall_cells
        c0 = _snap_band(col_profile, c0, radius, wall_cells)
        c1 = _snap_band(col_profile, c1 - wall_cells, radius, wall_cells) + wall_cells
        r0, c0, r1, c1 = max(r0, 0), max(c0, 0), min(r1, H), min(c1, W)
        if r1 - r0 >= min_side and c1 - c0 >= min_side:
            rects.append((int(r0), int(c0), int(r1), int(c1)))
    return rects


def start_world(classes: np.ndarray, capacity: int, *, min_side: int, wall_cells: int,
                factor: int) -> wm.World:
    """The deterministic data-driven start world (types left undecided)."""
    rects = greedy_rectangles(classes, min_side=min_side, wall_cells=wall_cells, factor=factor,
                              max_units=capacity)
    world = wm.empty(capacity)
    for slot, rect in enumerate(rects):
        world = wm.add(world, slot, rect)
    return world


def dispersed_world(rng: np.random.Generator, base: wm.World, shape: tuple[int, int], *,
                    min_side: int, drop: float = 0.3, jitter: int = 4) -> wm.World:
    """A random variant of ``base``: each unit dropped with probability ``drop`` or its edges jittered.

    Used to start chains 2..C in different places. The result is a valid world (rectangles inside
    ``shape`` with sides of at least ``min_side``); units land in random free slots.
    """
    H, W = shape
    out = wm.empty(base.capacity)
    slots = rng.permutation(base.capacity)
    i = 0
    for s in wm.active_slots(base):
        if rng.random() < drop:
            continue
        r0, c0, r1, c1 = (int(v) for v in base.rects[s])
        d = rng.integers(-jitter, jitter + 1, size=4)
        r0, c0 = max(0, r0 + d[0]), max(0, c0 + d[1])
        r1, c1 = min(H, r1 + d[2]), min(W, c1 + d[3])
        if r1 - r0 < min_side or c1 - c0 < min_side:
            r0, c0, r1, c1 = (int(v) for v in base.rects[s])
        out = wm.add(out, int(slots[i]), (r0, c0, r1, c1))
        i += 1
    return out


# --------------------------------------------------------------------------------------------------
# Refinement: a deterministic greedy ascent of the knowledge-free target from the greedy cover.
#
# The greedy cover only sees free cells: a room whose walls are lined with furniture comes out short
# of its walls, the pieces of free space between the furniture become units of their own, and ray
# fans seen through windows become units outside the building. The sampler could repair all that,
# but with knowledge on every proposal costs a knowledge inference; the knowledge-free target
# (types from the geometry class, fixed P(SaLe)) costs a few hundred microseconds. So the start
# world is the local optimum of that target reached by the kernels' own moves, each taken only when
# it raises log p: remove a unit, move one wall to a nearby position or to a line of wall evidence
# (SHRINK/DILATE), merge two units that share a wall (MERGE), add a unit from the birth table where
# free space is left uncovered (ADD), split a unit at a wall line (SPLIT). The search is greedy, so
# it proves nothing; it only puts the chains where the likelihood is, and the sampler does the rest.

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


class _Ascent:
    """Greedy ascent state: a tracker of the knowledge-free target and the kernels' data."""

    def __init__(self, posterior, world: wm.World, data, *, peaks: int = 8, local: int = 3,
                 absorb_share: float = 0.8, merge_slack: float = 0.15, merge_line_max: float = 0.5):
        self.tr = posterior.start(world)
        self.data, self.peaks, self.local = data, peaks, local
        self.absorb_share, self.merge_slack, self.merge_line_max = absorb_share, merge_slack, merge_line_max

    @property
    def world(self) -> wm.World:
        return self.tr.world

    def valid(self, world: wm.World) -> bool:
        """Inside the lattice, every side within ``[min_side, max_side]``."""
        r = world.rects[world.active]
        return wm.is_valid(world, self.data.shape, self.data.min_side) and bool(
            np.all(r[:, 2:] - r[:, :2] <= self.data.max_side))

    def try_world(self, new: wm.World, changed) -> bool:
        """Accept ``new`` when it raises log p (strictly); returns whether it did."""
        if not self.valid(new):
            return False
        prop = self.tr.propose(new, tuple(int(s) for s in changed))
        if prop.logp > self.tr.logp + 1e-9:
            self.tr.accept(prop)
            return True
        return False

    def best_of(self, worlds, changed) -> bool:
        """Accept the best of ``worlds`` (all differing from the current one in ``changed``) if it helps."""
        best, best_lp = None, self.tr.logp + 1e-9
        for new in worlds:
            if not self.valid(new):
                continue
            prop = self.tr.propose(new, changed)
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
        r = world.rects[slot]
        act = wm.active_slots(world)
        o = world.rects[act]
        inter = (np.clip(np.minimum(o[:, 2], r[2]) - np.maximum(o[:, 0], r[0]), 0, None)
                 * np.clip(np.minimum(o[:, 3], r[3]) - np.maximum(o[:, 1], r[1]), 0, None))
        area = (o[:, 2] - o[:, 0]) * (o[:, 3] - o[:, 1])
        thin = np.minimum(o[:, 2] - o[:, 0], o[:, 3] - o[:, 1]) < 2 * self.data.min_side
        gone = [int(k) for k, i, a, f in zip(act, inter, area, thin)
                if k != slot and f and i >= self.absorb_share * a]
        for k in gone:
            world = wm.remove(world, k)
        return world, gone

    def wall_moves(self, slot: int) -> bool:
        """Move each wall of ``slot`` to its best candidate position (local steps, line-evidence peaks).

        A wall moved outwards may swallow units lying mostly inside the grown unit (the greedy cover
        leaves strips of free space between furniture and walls as units of their own): the
        candidate world drops them, so the move is judged against the world without them.
        """
        from semmap_pp.kernels.shrink_dilate import wall_range
        moved = False
        for side in range(4):
            if not self.world.active[slot]:
                break
            rect = [int(v) for v in self.world.rects[slot]]
            _, lo, hi, w = wall_range(rect, side, self.data)
            x = rect[side]
            cand = {x + d for d in range(-self.local, self.local + 1)} | set(_line_peaks(w, lo, self.peaks))
            cand = sorted(c for c in cand if lo <= c <= hi and c != x)
            best, best_lp = None, self.tr.logp + 1e-9
            for c in cand:
                r = list(rect)
                r[side] = c
                new, gone = self.absorb(wm.replace(self.world, slot, r), slot)
                if not self.valid(new):
                    continue
                prop = self.tr.propose(new, (slot, *gone))
                if prop.logp > best_lp:
                    best, best_lp = prop, prop.logp
            if best is not None:
                self.tr.accept(best)
                moved = True
        return moved

    def removals(self) -> bool:
        changed = False
        for s in wm.active_slots(self.world).tolist():
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
        frac = (cum[i0:i1, s1] - cum[i0:i1, s0]) / float(s1 - s0)
        return float(frac.max())

    def merges(self) -> bool:
        """Replace two nearby units by their bounding box when it adds little area and raises log p.

        Pairs whose boxes are at most a wall band apart, whose bounding box exceeds their union by at
        most ``merge_slack`` and whose boundary shows no wall line (:meth:`boundary_lines` below
        ``merge_line_max``): one space cut into two rectangles, e.g. a room cut at a row of furniture
        or a corridor in pieces. A wall between two rooms is a line along most of its length (door
        gaps included as door candidates), so rooms are not merged here even where the
        knowledge-free target would take it.
        """
        t = self.data.wall_cells
        changed = False
        act = wm.active_slots(self.world).tolist()
        for i, a in enumerate(act):
            for b in act[i + 1:]:
                if not (self.world.active[a] and self.world.active[b]):
                    continue
                ra = [int(v) for v in self.world.rects[a]]
                rb = [int(v) for v in self.world.rects[b]]
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
                changed |= self.tentative(wm.replace(wm.remove(self.world, b), a, box), (a, b), [a])
        return changed

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

    def splits(self) -> bool:
        """Split a unit at its strongest interior wall line when that helps (pieces share the wall)."""
        from semmap_pp.kernels.common import band_weights, line_cum
        d = self.data
        m, t, g = d.min_side, d.wall_cells, d.wall_share
        changed = False
        for s in wm.active_slots(self.world).tolist():
            free = wm.free_slots(self.world)
            if free.size == 0:
                break
            rect = [int(v) for v in self.world.rects[s]]
            worlds = []
            for axis in (0, 1):
                lo, hi = rect[axis] + m, rect[axis + 2] + g - m
                if hi < lo:
                    continue
                w = band_weights(line_cum(d, axis), lo, hi, -t, t - g, rect[1 - axis], rect[3 - axis],
                                 d.settings.line_floor)
                for cut in _line_peaks(w, lo, 3):
                    a, b = list(rect), list(rect)
                    a[axis + 2], b[axis] = cut, cut - g
                    worlds.append(wm.add(wm.replace(self.world, s, a), int(free[0]), b))
            if worlds and self.best_of(worlds, (s, int(free[0]))):
                changed = True
                self.wall_moves(s)
                self.wall_moves(int(free[0]))
        return changed

    def births(self, covered_frac: float = 0.5) -> bool:
        """Add birth-table boxes over free space that no unit covers, each polished, when that helps."""
        d = self.data
        changed = False
        for box in d.birth_rects.tolist():
            free = wm.free_slots(self.world)
            if free.size == 0:
                break
            r0, c0, r1, c1 = box
            rects = self.world.rects[self.world.active]
            ov = (np.clip(np.minimum(rects[:, 2], r1) - np.maximum(rects[:, 0], r0), 0, None)
                  * np.clip(np.minimum(rects[:, 3], c1) - np.maximum(rects[:, 1], c0), 0, None))
            if ov.sum() > covered_frac * (r1 - r0) * (c1 - c0):
                continue
            slot = int(free[0])
            before = self.tr.logp
            new = wm.add(self.world, slot, box)
            if not self.valid(new):
                continue
            prop = self.tr.propose(new, (slot,))
            self.tr.accept(prop)          # tentatively, then polish and keep only a net gain
            self.wall_moves(slot)
            if self.tr.logp > before + 1e-9:
                changed = True
            else:
                undo = self.tr.propose(wm.remove(self.world, slot), (slot,))
                self.tr.accept(undo)
        return changed


def refine_world(posterior, world: wm.World, data, *, rounds: int = 3, births: bool = True,
                 merges: bool = True) -> wm.World:
    """Greedy ascent of ``posterior`` from ``world`` with the kernels' moves (see the note above).

    Parameters
    ----------
    posterior : Posterior
        The target to climb (use the knowledge-free one: ``knowledge_on = False``).
    world : World
        The start (e.g. :func:`start_world`); must have a finite log posterior.
    data : KernelData
        The kernels' data of the same lattice (line evidence, birth table).
    rounds : int
        Passes of removals, wall moves, merges, splits and births (stops early when nothing changes).

    Returns
    -------
    World
        A world whose log posterior is at least that of ``world`` (types left undecided).
    """
    asc = _Ascent(posterior, world, data)
    if not np.isfinite(asc.tr.logp):
        return world
    for _ in range(rounds):
        changed = asc.removals()
        for s in wm.active_slots(asc.world).tolist():
            changed |= asc.wall_moves(s)
        changed |= asc.removals()
        if merges:
            changed |= asc.merges()
        changed |= asc.splits()
        if births:
            changed |= asc.births()
        if not changed:
            break
    out = asc.world
    return wm.make(out.rects, out.active, np.full(out.capacity, wm.NO_TYPE))
