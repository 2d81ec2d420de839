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
line (row or column of occupied cells) nearby. :func:`semmap_pp.sampler.ascent.refine_world` then climbs the
knowledge-free target from this cover (``pipeline.start_worlds``).

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

import numba
import numpy as np
from scipy import ndimage as ndi

from semmap_pp import world as wm
from semmap_pp.cells import FREE, OCCUPIED


def largest_rectangle(mask: np.ndarray) -> tuple[int, int, int, int, int]:
    """Largest all-True axis-aligned rectangle of a boolean array.

    Returns ``(area, r0, c0, r1, c1)`` (half-open); area 0 when the mask is empty. Histogram-and-stack
    method, O(rows * cols), compiled (:func:`_largest_rectangle`); of equal areas, the one with the
    topmost bottom edge, then the leftmost right edge, then the tallest.

    >>> largest_rectangle(np.array([[0, 1, 1], [1, 1, 1], [0, 1, 1]], bool))
    (6, 0, 1, 3, 3)
    """
    m = np.ascontiguousarray(mask, dtype=np.bool_)
    if m.ndim != 2:
        raise ValueError(f"mask must be 2-D, got shape {m.shape}")
    return tuple(int(v) for v in _largest_rectangle(m))


@numba.njit(cache=True, nogil=True)
def _largest_rectangle(mask):  # pragma: no cover - compiled
    """:func:`largest_rectangle` compiled: per row the column heights of True runs ending there,
    and the largest rectangle under that histogram by a stack of increasing heights."""
    rows, cols = mask.shape
    heights = np.zeros(cols + 1, np.int64)  # sentinel column of height 0 flushes the stack
    stack = np.empty(cols + 1, np.int64)
    best_area, b_r0, b_c0, b_r1, b_c1 = 0, 0, 0, 0, 0
    for r in range(rows):
        for c in range(cols):
            heights[c] = heights[c] + 1 if mask[r, c] else 0
        top_n = 0
        for c in range(cols + 1):
            hc = heights[c]
            while top_n > 0 and heights[stack[top_n - 1]] >= hc:
                top_n -= 1
                top = stack[top_n]
                left = stack[top_n - 1] + 1 if top_n > 0 else 0
                area = heights[top] * (c - left)
                if area > best_area:
                    best_area, b_r0, b_c0, b_r1, b_c1 = area, r - heights[top] + 1, left, r + 1, c
            stack[top_n] = c
            top_n += 1
    return best_area, b_r0, b_c0, b_r1, b_c1


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
                    min_side: int, drop: float = 0.3, jitter: int = 4, spans=()) -> wm.World:
    """A random variant of ``base``: each unit dropped with probability ``drop`` or its edges jittered.

    Used to start chains 2..C in different places. The result is a valid world (rectangles inside
    ``shape`` with sides of at least ``min_side``, and inside the tile of ``spans`` the unit was
    in, on a tiled lattice); units land in random free slots.
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
        home = [(a, b) for a, b in spans if a <= base.rects[s][1] < b]
        if r1 - r0 < min_side or c1 - c0 < min_side or (home and not home[0][0] <= c0 < c1 <= home[0][1]):
            r0, c0, r1, c1 = (int(v) for v in base.rects[s])
        out = wm.add(out, int(slots[i]), (r0, c0, r1, c1))
        i += 1
    return out
