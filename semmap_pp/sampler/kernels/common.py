"""Pieces shared by the kernels: line evidence, adjacency of units, wall-position moves.

Axis convention: a rectangle is ``(r0, c0, r1, c1)``; along axis ``a`` (0 = rows, 1 = columns) its
edges are ``rect[a]`` (low) and ``rect[a + 2]`` (high) and its span on the other axis is
``rect[1 - a], rect[3 - a]``. A *horizontal* line (a lattice row) bounds units along axis 0.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from semmap_pp.sampler.kernels.data import KernelData

LOG_HALF = math.log(0.5)


def line_cum(data: KernelData, axis: int) -> np.ndarray:
    """Prefix sums of line evidence for lines that bound units along ``axis``."""
    return data.hcum if axis == 0 else data.vcum


@numba.njit(cache=True, nogil=True)
def _band(cum, lo, hi, a, b, s0, s1, floor):  # pragma: no cover - compiled
    """:func:`band_weights_py` in one loop (integer prefix sums, the same final float operations)."""
    first, last = lo + a, hi + b
    i0, i1 = max(first, 0), min(last, cum.shape[0])
    cs = np.zeros(last - first + 1)
    if i1 > i0:
        acc = 0
        for i in range(i0, i1):
            acc += cum[i, s1] - cum[i, s0]
            cs[i - first + 1] = acc
        for k in range(i1 - first + 1, cs.shape[0]):
            cs[k] = cs[i1 - first]
    width = b - a
    n = hi - lo + 1
    out = np.empty(n)
    den = width * float(s1 - s0)
    for i in range(n):
        out[i] = floor + (cs[width + i] - cs[i]) / den
    return out


def band_weights(cum: np.ndarray, lo: int, hi: int, a: int, b: int, s0: int, s1: int,
                 floor: float) -> np.ndarray:
    """Weight of each position ``x = lo..hi``: ``floor`` + mean line fraction over lines ``x+a..x+b-1``.

    The line fraction of line ``i`` is the share of its cells in ``[s0, s1)`` that are wall (occupied)
    or door-candidate cells; lines outside the lattice count 0.
    """
    if hi >= lo and b > a and s1 > s0:
        return _band(cum, int(lo), int(hi), int(a), int(b), int(s0), int(s1), float(floor))
    return band_weights_py(cum, lo, hi, a, b, s0, s1, floor)


def band_weights_py(cum: np.ndarray, lo: int, hi: int, a: int, b: int, s0: int, s1: int,
                    floor: float) -> np.ndarray:
    """Plain-numpy reference of :func:`band_weights` (for the tests and degenerate ranges)."""
    first, last = lo + a, hi + b
    i0, i1 = max(first, 0), min(last, cum.shape[0])
    cs = np.zeros(last - first + 1)
    if i1 > i0:
        np.cumsum(cum[i0:i1, s1] - cum[i0:i1, s0], out=cs[i0 - first + 1:i1 - first + 1])
        cs[i1 - first + 1:] = cs[i1 - first]
    width = b - a
    n = hi - lo + 1
    return floor + (cs[width:width + n] - cs[:n]) / (width * float(s1 - s0))


@numba.njit(cache=True, nogil=True)
def _pairs(rects, active, m, g, merge_big):  # pragma: no cover - compiled
    """``(n, 3)`` rows ``(axis, a, b)`` of :func:`attach_pairs`, in its order (axis, then ``a``, then
    ``b``); with ``merge_big >= 0`` only the pairs of equal span whose union is at most that long."""
    k = rects.shape[0]
    out = np.empty((16, 3), np.int64)
    n = 0
    for axis in range(2):
        for i in range(k):
            if not active[i]:
                continue
            edge = rects[i, axis + 2] - g
            for j in range(k):
                if not active[j] or rects[j, axis] != edge:
                    continue
                if min(rects[i, 3 - axis], rects[j, 3 - axis]) - max(rects[i, 1 - axis],
                                                                     rects[j, 1 - axis]) < m:
                    continue
                if merge_big >= 0 and not (rects[i, 1 - axis] == rects[j, 1 - axis]
                                           and rects[i, 3 - axis] == rects[j, 3 - axis]
                                           and rects[j, axis + 2] - rects[i, axis] <= merge_big):
                    continue
                if n == out.shape[0]:
                    grown = np.empty((2 * n, 3), np.int64)
                    grown[:n] = out
                    out = grown
                out[n, 0], out[n, 1], out[n, 2] = axis, i, j
                n += 1
    return out[:n]


def pair_array(rects: np.ndarray, active: np.ndarray, m: int, g: int, merge_big: int = -1) -> np.ndarray:
    """:func:`attach_pairs` as an ``(n, 3)`` int64 array (compiled; see ``_pairs`` for ``merge_big``)."""
    return _pairs(rects, active, int(m), int(g), int(merge_big))


def attach_pairs(rects: np.ndarray, active: np.ndarray, m: int, g: int) -> list:
    """Slot pairs of units that share a wall: a list of ``(axis, a, b)``, ``a`` upper (0) or left (1).

    ``b`` lies below ``a`` (axis 0) when ``b.r0 == a.r1 - g`` and their column spans overlap by at
    least ``m`` cells; right of ``a`` (axis 1) in the same sense. Sorted by axis, then ``a``, then
    ``b`` (the order the kernels draw from).
    """
    return [tuple(p) for p in _pairs(rects, active, int(m), int(g), -1).tolist()]


def attach_pairs_py(rects: np.ndarray, active: np.ndarray, m: int, g: int) -> list:
    """Plain-Python reference of :func:`attach_pairs` (for the tests)."""
    rl = rects.tolist()
    slots = [i for i, a in enumerate(active.tolist()) if a]
    out = []
    for axis in (0, 1):
        by_lo: dict[int, list] = {}
        for i in slots:
            by_lo.setdefault(rl[i][axis], []).append(i)
        for i in slots:
            ri = rl[i]
            for j in by_lo.get(ri[axis + 2] - g, ()):
                rj = rl[j]
                if min(ri[3 - axis], rj[3 - axis]) - max(ri[1 - axis], rj[1 - axis]) >= m:
                    out.append((axis, i, j))
    return out


def attach_matrices(rects: np.ndarray, active: np.ndarray, m: int, g: int):
    """Which units share a wall, as (K, K) bool matrices ``(V, Hz)`` (see :func:`attach_pairs`)."""
    k = rects.shape[0]
    mats = np.zeros((2, k, k), bool)
    for axis, a, b in attach_pairs(rects, active, m, g):
        mats[axis, a, b] = True
    return mats[0], mats[1]


@numba.njit(cache=True, nogil=True)
def _attached(r0, c0, r1, c1, rects, active, m, g):  # pragma: no cover - compiled
    """Rows ``(k, side)`` of :func:`attached_to`, in its order."""
    k_max = rects.shape[0]
    out = np.empty((4 * k_max, 2), np.int64)
    n = 0
    for k in range(k_max):
        if not active[k]:
            continue
        a0, b0, a1, b1 = rects[k, 0], rects[k, 1], rects[k, 2], rects[k, 3]
        if min(b1, c1) - max(b0, c0) >= m:
            if r0 == a1 - g:
                out[n, 0], out[n, 1] = k, 0
                n += 1
            if r1 == a0 + g:
                out[n, 0], out[n, 1] = k, 1
                n += 1
        if min(a1, r1) - max(a0, r0) >= m:
            if c0 == b1 - g:
                out[n, 0], out[n, 1] = k, 2
                n += 1
            if c1 == b0 + g:
                out[n, 0], out[n, 1] = k, 3
                n += 1
    return out[:n]


def attached_to(rect, rects: np.ndarray, active: np.ndarray, m: int, g: int) -> list:
    """``(k, side)`` for every unit ``k`` that ``rect`` touches on ``k``'s side ``side``.

    Sides are indexed ``(axis, direction)`` as ``0: (0, +1)`` below, ``1: (0, -1)`` above,
    ``2: (1, +1)`` right, ``3: (1, -1)`` left of unit ``k``.
    """
    r0, c0, r1, c1 = (int(v) for v in rect)
    return [tuple(p) for p in _attached(r0, c0, r1, c1, rects, active, int(m), int(g)).tolist()]


def attached_to_py(rect, rects: np.ndarray, active: np.ndarray, m: int, g: int) -> list:
    """Plain-Python reference of :func:`attached_to` (for the tests)."""
    r0, c0, r1, c1 = (int(v) for v in rect)
    out = []
    rl = rects.tolist()
    for k, a in enumerate(active.tolist()):
        if not a:
            continue
        a0, b0, a1, b1 = rl[k]
        if min(b1, c1) - max(b0, c0) >= m:
            if r0 == a1 - g:
                out.append((k, 0))
            if r1 == a0 + g:
                out.append((k, 1))
        if min(a1, r1) - max(a0, r0) >= m:
            if c0 == b1 - g:
                out.append((k, 2))
            if c1 == b0 + g:
                out.append((k, 3))
    return out


# --- moving one wall position x within [lo, hi]: local step or jump towards line evidence ---------

def position_q(x_from: int, x_to: int, lo: int, w: np.ndarray, total: float, rho: float, d: int) -> float:
    """Probability that :func:`position_draw` moves ``x_from`` to ``x_to`` (``x_to != x_from``).

    ``q = rho * [1 <= |dx| <= d] / (2 d) + (1 - rho) * w[x_to] / (total - w[x_from])``.
    """
    q = rho / (2 * d) if 1 <= abs(x_to - x_from) <= d else 0.0
    rest = total - w[x_from - lo]
    if rest > 0:
        q += (1.0 - rho) * w[x_to - lo] / rest
    return q


@numba.njit(cache=True, nogil=True)
def _block_sum(a, lo, n):  # pragma: no cover - compiled
    """numpy's pairwise sum of a block of at most 128 values (eight running sums)."""
    if n < 8:
        res = 0.0
        for i in range(n):
            res += a[lo + i]
        return res
    r0, r1, r2, r3 = a[lo], a[lo + 1], a[lo + 2], a[lo + 3]
    r4, r5, r6, r7 = a[lo + 4], a[lo + 5], a[lo + 6], a[lo + 7]
    i = 8
    while i < n - (n % 8):
        r0 += a[lo + i]
        r1 += a[lo + i + 1]
        r2 += a[lo + i + 2]
        r3 += a[lo + i + 3]
        r4 += a[lo + i + 4]
        r5 += a[lo + i + 5]
        r6 += a[lo + i + 6]
        r7 += a[lo + i + 7]
        i += 8
    res = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
    while i < n:
        res += a[lo + i]
        i += 1
    return res


@numba.njit(cache=True, nogil=True)
def pairwise_sum(a, lo, n):  # pragma: no cover - compiled
    """``a[lo:lo + n].sum()`` exactly as numpy forms it (its pairwise summation: blocks of at most
    128 summed in eight running sums, longer ranges split in halves at a multiple of 8 and the two
    sums added), so a compiled total equals numpy's bit for bit (tests/unit/test_kernels_frozen.py
    checks it against ``np.sum``). The halving runs on an explicit stack (no recursion)."""
    if n <= 128:
        return _block_sum(a, lo, n)
    los = np.empty(64, np.int64)
    ns = np.empty(64, np.int64)
    stage = np.empty(64, np.int64)
    vals = np.empty(64)
    sp, vsp = 0, 0
    los[0], ns[0], stage[0] = lo, n, 0
    while sp >= 0:
        l, m = los[sp], ns[sp]
        if m <= 128:
            vals[vsp] = _block_sum(a, l, m)
            vsp += 1
            sp -= 1
            continue
        n2 = m // 2
        n2 -= n2 % 8
        if stage[sp] == 0:
            stage[sp] = 1
            sp += 1
            los[sp], ns[sp], stage[sp] = l, n2, 0
        elif stage[sp] == 1:
            stage[sp] = 2
            sp += 1
            los[sp], ns[sp], stage[sp] = l + n2, m - n2, 0
        else:
            vals[vsp - 2] = vals[vsp - 2] + vals[vsp - 1]
            vsp -= 1
            sp -= 1
    return vals[0]


@numba.njit(cache=True, nogil=True)
def _q1(x_from, x_to, lo, w, total, rho, d):  # pragma: no cover - compiled
    q = rho / (2 * d) if 1 <= abs(x_to - x_from) <= d else 0.0
    rest = total - w[x_from - lo]
    if rest > 0:
        q += (1.0 - rho) * w[x_to - lo] / rest
    return q


@numba.njit(cache=True, nogil=True)
def _pair_q(x, x2, lo, w, rho, d):  # pragma: no cover - compiled
    total = pairwise_sum(w, 0, w.shape[0])
    return _q1(x2, x, lo, w, total, rho, d), _q1(x, x2, lo, w, total, rho, d)


def position_log_ratio(x: int, x2: int, lo: int, w: np.ndarray, rho: float, d: int) -> float:
    """``log q(x|x2) - log q(x2|x)`` of :func:`position_q` with ``total = w.sum()`` (compiled)."""
    back, fwd = _pair_q(int(x), int(x2), int(lo), w, float(rho), int(d))
    return math.log(back) - math.log(fwd)


def position_draw(rng, x: int, lo: int, hi: int, w: np.ndarray, rho: float, d: int):
    """Draw a new position from ``x`` (``None``: the draw left ``[lo, hi]`` or no other position)."""
    if rng.random() < rho:
        step = 1 + int(rng.random() * d)
        x2 = x + step if rng.random() < 0.5 else x - step
        return x2 if lo <= x2 <= hi else None
    if hi <= lo:
        return None
    return lo + int(_jump(w, x - lo, rng.random()))


@numba.njit(cache=True, nogil=True)
def _jump(w, k, r):  # pragma: no cover - compiled
    """Index drawn by a jump: ``searchsorted(cdf, r * cdf[-1], "right")``, ``cdf`` the running sum
    of ``w`` with ``w[k]`` taken out (the same sums as ``np.cumsum``, and numpy's binary search step
    for step, so a rounding dip of ``cdf`` at ``k`` gives numpy's answer too)."""
    n = w.shape[0]
    cdf = np.empty(n)
    acc = 0.0
    for i in range(n):
        acc += w[i]
        cdf[i] = acc
    for i in range(k, n):
        cdf[i] -= w[k]
    u = r * cdf[n - 1]
    lo_i, hi_i = 0, n
    while lo_i < hi_i:
        mid = lo_i + ((hi_i - lo_i) >> 1)
        if not u < cdf[mid]:
            lo_i = mid + 1
        else:
            hi_i = mid
    return lo_i


def position_enumerate(x: int, lo: int, hi: int, w: np.ndarray, rho: float, d: int) -> dict:
    """Brute-force pmf of :func:`position_draw` over the new positions (for the exact tests)."""
    out: dict[int, float] = {}
    for step in range(1, d + 1):
        for x2 in (x + step, x - step):
            if lo <= x2 <= hi:
                out[x2] = out.get(x2, 0.0) + rho / d * 0.5
    if hi > lo:
        rest = float(w.sum() - w[x - lo])
        for x2 in range(lo, hi + 1):
            if x2 != x:
                out[x2] = out.get(x2, 0.0) + (1.0 - rho) * w[x2 - lo] / rest
    return out


def world_key(world) -> tuple:
    """Slot-level identity of a state (geometry and activity; types are a function of them)."""
    return (world.rects.tobytes(), world.active.tobytes())
