"""ALLOCATE / DELETE: birth of a unit next to an existing one, sharing its wall; and its reverse.

Our reading of the paper's ALLOCATE (it does not define it): pick a unit ``A`` uniformly (``1/n``),
one of its four sides (``1/4``) and a free slot (``1/(K - n)``). The new unit ``B`` shares that wall:
its near edge is fixed (``B.lo = A.hi - g`` beyond a high side, ``B.hi = A.lo + g`` beyond a low
side); its span must overlap ``A``'s by at least ``m`` cells, so ``B.s0 in [0, A.s1 - m]`` and
``B.s1 in [A.s0 + m, L]``; its far edge keeps its side within ``[m, M]``. Sizes come from the free
space behind the wall: a seed ``p`` uniform over ``A``'s span picks the cell just inside ``B``'s wall
band, and the free runs from that cell give a box ``b(p) = (s0*, s1*, far*)``. Each coordinate is
drawn independently from

    q(x | b) = rho_box [x = b] + rho_jit [|x - b| <= j] / (2 j + 1) + rho_uni / |range|

over its range (a draw off the range, or a ``B`` too wide or too narrow, is an impossible move). So

    q_A,k(B) = mean_p prod_coords q(B.coord | b_coord(p)),
    q(W -> W + B) = 1/(K - n) * sum over (A, k) that B touches of q_A,k(B) / (4 n),

summing every unit and side that could have allocated ``B`` (not only the one drawn). DELETE picks
uniformly one of the ``N_del`` units that share a wall with another unit and removes it:

    log q(W'->W) / q(W->W')  [ALLOCATE]  =  -log N_del(W') - log q(W -> W').
"""

from __future__ import annotations

import itertools
import math

import numba
import numpy as np

from semmap_pp import world as wm
from semmap_pp.sampler.kernels.common import attached_to, pair_array, pairwise_sum
from semmap_pp.sampler.kernels.data import KernelData
from semmap_pp.sampler.kernels.proposal import Kernel, Proposal

_NONE = -(10 ** 9)  # box value of a seed whose cell lies off the lattice: matches no coordinate


def ranges(a_rect, side: int, data: KernelData):
    """``(axis, near, (far_lo, far_hi), (s0_lo, s0_hi), (s1_lo, s1_hi))`` or ``None`` if empty."""
    axis, sign = side // 2, (1 if side % 2 == 0 else -1)
    m, big, g = data.min_side, data.max_side, data.wall_share
    length, other = data.shape[axis], data.shape[1 - axis]
    if sign > 0:
        near = int(a_rect[axis + 2]) - g
        far = (near + m, min(length, near + big))
    else:
        near = int(a_rect[axis]) + g
        far = (max(0, near - big), near - m)
    s0 = (0, int(a_rect[3 - axis]) - m)
    s1 = (int(a_rect[1 - axis]) + m, other)
    if far[1] < far[0] or s0[1] < s0[0] or s1[1] < s1[0]:
        return None
    return axis, near, far, s0, s1


def boxes(a_rect, side: int, near: int, data: KernelData, p=None):
    """Box values ``(s0*, s1*, far*)`` for the seeds ``p`` (default: every cell of ``A``'s span)."""
    axis, sign = side // 2, (1 if side % 2 == 0 else -1)
    t = data.wall_cells
    length, other = data.shape[axis], data.shape[1 - axis]
    if p is None:
        p = np.arange(int(a_rect[1 - axis]), int(a_rect[3 - axis]))
    e = near + t if sign > 0 else near - t - 1
    if not 0 <= e < length:
        none = np.full(p.size, _NONE)
        return none, none, none
    if axis == 0:
        back, fwd = data.free_left[e, p], data.free_right[e, p]
        run = (data.free_down if sign > 0 else data.free_up)[e, p]
    else:
        back, fwd = data.free_up[p, e], data.free_down[p, e]
        run = (data.free_right if sign > 0 else data.free_left)[p, e]
    s0 = np.maximum(p - back + 1 - t, 0)
    s1 = np.minimum(p + fwd + t, other)
    far = np.minimum(e + run + t, length) if sign > 0 else np.maximum(e - run + 1 - t, 0)
    return s0, s1, far


def _box1(side: int, near: int, data: KernelData, p: int):
    """:func:`boxes` of the one seed ``p``, as Python ints (the same integer arithmetic)."""
    axis, sign = side // 2, (1 if side % 2 == 0 else -1)
    t = data.wall_cells
    length, other = data.shape[axis], data.shape[1 - axis]
    e = near + t if sign > 0 else near - t - 1
    if not 0 <= e < length:
        return _NONE, _NONE, _NONE
    if axis == 0:
        back, fwd = int(data.free_left[e, p]), int(data.free_right[e, p])
        run = int((data.free_down if sign > 0 else data.free_up)[e, p])
    else:
        back, fwd = int(data.free_up[p, e]), int(data.free_down[p, e])
        run = int((data.free_right if sign > 0 else data.free_left)[p, e])
    far = min(e + run + t, length) if sign > 0 else max(e - run + 1 - t, 0)
    return max(p - back + 1 - t, 0), min(p + fwd + t, other), far


def _coord_q(x: int, b: np.ndarray, lo: int, hi: int, data: KernelData) -> np.ndarray:
    if not lo <= x <= hi:
        return np.zeros(b.shape)
    s = data.settings
    j = s.box_jitter
    rho_uni = 1.0 - s.box_prob - s.box_jitter_prob
    return (s.box_prob * (b == x) + s.box_jitter_prob * (np.abs(b - x) <= j) / (2 * j + 1)
            + rho_uni / (hi - lo + 1))


def allocate_q_py(b_rect, a_rect, side: int, data: KernelData) -> float:
    """Plain-numpy reference of :func:`allocate_q` (for the tests)."""
    rg = ranges(a_rect, side, data)
    if rg is None:
        return 0.0
    axis, near, far, s0, s1 = rg
    sign = 1 if side % 2 == 0 else -1
    fidx = axis + 2 if sign > 0 else axis
    bs0, bs1, bfar = boxes(a_rect, side, near, data)
    q = (_coord_q(int(b_rect[1 - axis]), bs0, *s0, data) * _coord_q(int(b_rect[3 - axis]), bs1, *s1, data)
         * _coord_q(int(b_rect[fidx]), bfar, *far, data))
    return float(q.mean())


@numba.njit(cache=True, nogil=True)
def _coord_q1(x, b, lo, hi, box_prob, jit_prob, j, uni):  # pragma: no cover - compiled
    """One element of :func:`_coord_q`, the same floating-point operations in the same order."""
    if not lo <= x <= hi:
        return 0.0
    return (box_prob * (1.0 if b == x else 0.0) + jit_prob * (1.0 if abs(b - x) <= j else 0.0) / (2 * j + 1)
            + uni / (hi - lo + 1))


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _seed_q(back, fwd, run, e, sign, span0, span1, t, length, other, x0, lo0, hi0, x1, lo1, hi1, xf, lof,
            hif, box_prob, jit_prob, j, uni):  # pragma: no cover - compiled
    """Mean over the seeds of ``q0 * q1 * qf`` of :func:`allocate_q_py` (boxes and coordinates fused;
    the mean is numpy's: its pairwise sum divided by the count).

    ``back, fwd, run`` are the free-run arrays indexed ``[e, p]`` (transposed views for axis 1)."""
    n = span1 - span0
    out = np.empty(n)
    inside = 0 <= e < length
    for i in range(n):
        p = span0 + i
        if inside:
            b0 = max(p - back[e, p] + 1 - t, 0)
            b1 = min(p + fwd[e, p] + t, other)
            if sign > 0:
                bf = min(e + run[e, p] + t, length)
            else:
                bf = max(e - run[e, p] + 1 - t, 0)
        else:
            b0 = b1 = bf = _NONE
        out[i] = (_coord_q1(x0, b0, lo0, hi0, box_prob, jit_prob, j, uni)
                  * _coord_q1(x1, b1, lo1, hi1, box_prob, jit_prob, j, uni)
                  * _coord_q1(xf, bf, lof, hif, box_prob, jit_prob, j, uni))
    return pairwise_sum(out, 0, n) / n


def allocate_q(b_rect, a_rect, side: int, data: KernelData) -> float:
    """Probability that ALLOCATE from unit ``a_rect`` and ``side`` draws ``b_rect`` (seed averaged)."""
    rg = ranges(a_rect, side, data)
    if rg is None:
        return 0.0
    axis, near, far, s0, s1 = rg
    sign = 1 if side % 2 == 0 else -1
    fidx = axis + 2 if sign > 0 else axis
    t = data.wall_cells
    e = near + t if sign > 0 else near - t - 1
    if axis == 0:
        back, fwd = data.free_left, data.free_right
        run = data.free_down if sign > 0 else data.free_up
    else:
        back, fwd = data.free_up.T, data.free_down.T
        run = (data.free_right if sign > 0 else data.free_left).T
    s = data.settings
    q = _seed_q(back, fwd, run, e, sign, int(a_rect[1 - axis]), int(a_rect[3 - axis]), t,
                data.shape[axis], data.shape[1 - axis], int(b_rect[1 - axis]), s0[0], s0[1],
                int(b_rect[3 - axis]), s1[0], s1[1], int(b_rect[fidx]), far[0], far[1],
                float(s.box_prob), float(s.box_jitter_prob), int(s.box_jitter),
                1.0 - s.box_prob - s.box_jitter_prob)
    return float(q)


def _sources_q(b_rect, world, data: KernelData) -> float:
    """``sum over (A, side) that b_rect touches of q_A,side(b_rect) / (4 n)`` in ``world``."""
    n = int(world.active.sum())
    total = 0.0
    for a, side in attached_to(b_rect, world.rects, world.active, data.min_side, data.wall_share):
        total += allocate_q(b_rect, world.rects[a], side, data)
    return total / (4 * n)


def deletable(world, data: KernelData) -> np.ndarray:
    """Slots of the units that share a wall with at least one other unit."""
    pairs = pair_array(world.rects, world.active, data.min_side, data.wall_share)
    mark = np.zeros(world.capacity, bool)
    mark[pairs[:, 1]] = True
    mark[pairs[:, 2]] = True
    return np.flatnonzero(mark).astype(np.int64, copy=False)


def _log(x: float) -> float:
    return math.log(x) if x > 0 else -math.inf


def _allocate_proposal(world, slot, b_rect, data):
    new = wm.add(world, slot, b_rect)
    n_free = world.capacity - int(world.active.sum())
    lr = -math.log(deletable(new, data).size) - (_log(_sources_q(b_rect, world, data)) - math.log(n_free))
    return Proposal(new, lr, (slot,))


def _delete_proposal(world, slot, n_del, data):
    new = wm.remove(world, slot)
    n_free = new.capacity - int(new.active.sum())
    lr = _log(_sources_q(world.rects[slot], new, data)) - math.log(n_free) + math.log(n_del)
    return Proposal(new, lr, (slot,))


def _draw_coord(rng, b: int, lo: int, hi: int, data: KernelData):
    s = data.settings
    u = rng.random()
    if u < s.box_prob:
        x = b
    elif u < s.box_prob + s.box_jitter_prob:
        x = b + int(rng.random() * (2 * s.box_jitter + 1)) - s.box_jitter
    else:
        x = lo + int(rng.random() * (hi - lo + 1))
    return x if lo <= x <= hi else None


def propose_allocate(rng, world, data: KernelData):
    act = world.active.nonzero()[0]
    free = (~world.active).nonzero()[0]
    if act.size == 0 or free.size == 0:
        return None
    a = int(act[int(rng.random() * act.size)])
    side = int(rng.random() * 4)
    slot = int(free[int(rng.random() * free.size)])
    a_rect = world.rects[a]
    rg = ranges(a_rect, side, data)
    if rg is None:
        return None
    axis, near, far, s0, s1 = rg
    span0, span1 = int(a_rect[1 - axis]), int(a_rect[3 - axis])
    bs0, bs1, bfar = _box1(side, near, data, span0 + int(rng.random() * (span1 - span0)))
    x0 = _draw_coord(rng, bs0, *s0, data)
    x1 = _draw_coord(rng, bs1, *s1, data)
    xf = _draw_coord(rng, bfar, *far, data)
    if x0 is None or x1 is None or xf is None or not data.min_side <= x1 - x0 <= data.max_side:
        return None
    b = [0, 0, 0, 0]
    b[1 - axis], b[3 - axis] = x0, x1
    b[axis], b[axis + 2] = (near, xf) if side % 2 == 0 else (xf, near)
    return _allocate_proposal(world, slot, tuple(b), data)


def propose_delete(rng, world, data: KernelData):
    cand = deletable(world, data)
    if cand.size == 0:
        return None
    return _delete_proposal(world, int(cand[int(rng.random() * cand.size)]), cand.size, data)


def _coord_pmf(b: int, lo: int, hi: int, data: KernelData) -> dict:
    s = data.settings
    j = s.box_jitter
    out: dict[int, float] = {}
    for x, q in [(b, s.box_prob)] + [(b + o, s.box_jitter_prob / (2 * j + 1)) for o in range(-j, j + 1)]:
        if lo <= x <= hi:
            out[x] = out.get(x, 0.0) + q
    for x in range(lo, hi + 1):
        out[x] = out.get(x, 0.0) + (1.0 - s.box_prob - s.box_jitter_prob) / (hi - lo + 1)
    return out


def enumerate_allocate(world, data: KernelData):
    act = np.flatnonzero(world.active)
    free = np.flatnonzero(~world.active)
    if act.size == 0 or free.size == 0:
        return []
    pmf: dict[tuple, float] = {}
    for a in act.tolist():
        for side in range(4):
            rg = ranges(world.rects[a], side, data)
            if rg is None:
                continue
            axis, near, far, s0, s1 = rg
            bs0, bs1, bfar = boxes(world.rects[a], side, near, data)
            for k in range(bs0.size):
                p0, p1 = _coord_pmf(int(bs0[k]), *s0, data), _coord_pmf(int(bs1[k]), *s1, data)
                pf = _coord_pmf(int(bfar[k]), *far, data)
                for (x0, q0), (x1, q1), (xf, qf) in itertools.product(p0.items(), p1.items(), pf.items()):
                    if not data.min_side <= x1 - x0 <= data.max_side:
                        continue
                    b = [0, 0, 0, 0]
                    b[1 - axis], b[3 - axis] = x0, x1
                    b[axis], b[axis + 2] = (near, xf) if side % 2 == 0 else (xf, near)
                    key = tuple(b)
                    pmf[key] = pmf.get(key, 0.0) + q0 * q1 * qf / (bs0.size * 4 * act.size)
    return [(_allocate_proposal(world, slot, b, data), q / free.size)
            for b, q in pmf.items() for slot in free.tolist()]


def enumerate_delete(world, data: KernelData):
    cand = deletable(world, data)
    return [(_delete_proposal(world, int(s), cand.size, data), 1.0 / cand.size) for s in cand.tolist()]


allocate_delete = Kernel("allocate_delete", propose_allocate, enumerate_allocate,
                         propose_delete, enumerate_delete)
