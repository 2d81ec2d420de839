"""ADD / REMOVE: birth and death of a unit.

ADD puts a new unit into a free slot chosen uniformly (``1 / (K - n)``) with a rectangle drawn from the
birth density

    q_b(r) = rho * U(r) + (1 - rho) * sum_i w_i * prod_k [|r_k - C_ik| <= j] / (2 j + 1)^4,

``U`` uniform over all valid rectangles, ``C`` the data-driven candidate table (free-space boxes around
distance-transform maxima and regions) with weights ``w``, each coordinate jittered uniformly by up to
``j`` cells. Draws that leave the lattice or the side range are impossible moves (``None``).
REMOVE picks one of the ``n`` units uniformly. For ``W (n units) -> W' (n + 1)``:

    log q(W'->W) / q(W->W') = -log(n + 1) + log(K - n) - log q_b(r).
"""

from __future__ import annotations

import itertools
import math

import numba
import numpy as np

from semmap_pp import world as wm
from semmap_pp.sampler.kernels.data import KernelData
from semmap_pp.sampler.kernels.proposal import Kernel, Proposal


def _valid(rect, data: KernelData) -> bool:
    r0, c0, r1, c1 = rect
    h, w = r1 - r0, c1 - c0
    return (r0 >= 0 and c0 >= 0 and r1 <= data.shape[0] and c1 <= data.shape[1]
            and data.min_side <= h <= data.max_side and data.min_side <= w <= data.max_side)


def _rho(data: KernelData) -> float:
    return data.settings.birth_uniform if len(data.birth_rects) else 1.0


def birth_q(rect, data: KernelData) -> float:
    """Probability that :func:`birth_draw` returns ``rect`` (0 for an invalid rectangle)."""
    rect = tuple(int(v) for v in rect)
    if not _valid(rect, data):
        return 0.0
    rho = _rho(data)
    q = rho / (data.side_counts[0] * data.side_counts[1])
    if rho < 1.0:
        j = data.settings.birth_jitter
        near = _near(data.birth_rects, rect[0], rect[1], rect[2], rect[3], int(j))
        q += (1.0 - rho) * float(data.birth_weights[near].sum()) / (2 * j + 1) ** 4
    return q


@numba.njit(cache=True, nogil=True)
def _near(cands, r0, c0, r1, c1, j):  # pragma: no cover - compiled
    """Indices (ascending) of the candidates with every coordinate within ``j`` of the rectangle."""
    out = np.empty(cands.shape[0], np.int64)
    n = 0
    for i in range(cands.shape[0]):
        if (abs(cands[i, 0] - r0) <= j and abs(cands[i, 1] - c0) <= j and abs(cands[i, 2] - r1) <= j
                and abs(cands[i, 3] - c1) <= j):
            out[n] = i
            n += 1
    return out[:n]


def _draw_side(rng, data: KernelData, axis: int):
    lengths, cdf = data.side_cdfs[axis]
    i = min(int(np.searchsorted(cdf, rng.random(), side="right")), len(lengths) - 1)
    h = int(lengths[i])
    lo = int(rng.random() * (data.shape[axis] - h + 1))
    return lo, lo + h


def birth_draw(rng, data: KernelData):
    """A rectangle from the birth density, or ``None`` when the draw is not a valid rectangle."""
    if rng.random() < _rho(data):
        if data.side_counts[0] == 0 or data.side_counts[1] == 0:
            return None
        r0, r1 = _draw_side(rng, data, 0)
        c0, c1 = _draw_side(rng, data, 1)
        return (r0, c0, r1, c1)
    cdf = np.cumsum(data.birth_weights)
    i = min(int(np.searchsorted(cdf, rng.random() * cdf[-1], side="right")), len(cdf) - 1)
    j = data.settings.birth_jitter
    off = [int(rng.random() * (2 * j + 1)) - j for _ in range(4)]
    rect = tuple(v + o for v, o in zip(data.birth_rects[i].tolist(), off))
    return rect if _valid(rect, data) else None


def add_log_ratio(n: int, capacity: int, rect, data: KernelData) -> float:
    """Log proposal ratio of ADD from a world of ``n`` units (REMOVE's is its negative)."""
    return -math.log(n + 1) + math.log(capacity - n) - math.log(birth_q(rect, data))


def propose_add(rng, world, data: KernelData):
    free = (~world.active).nonzero()[0]
    if free.size == 0:
        return None
    slot = int(free[int(rng.random() * free.size)])
    rect = birth_draw(rng, data)
    if rect is None:
        return None
    n = world.capacity - free.size
    return Proposal(wm.add(world, slot, rect), add_log_ratio(n, world.capacity, rect, data), (slot,))


def propose_remove(rng, world, data: KernelData):
    act = world.active.nonzero()[0]
    if act.size == 0:
        return None
    slot = int(act[int(rng.random() * act.size)])
    rect = world.rects[slot]
    return Proposal(wm.remove(world, slot),
                    -add_log_ratio(act.size - 1, world.capacity, rect, data), (slot,))


def birth_pmf(data: KernelData) -> dict:
    """Brute-force pmf of :func:`birth_draw` over valid rectangles (tests only: enumerates all)."""
    pmf: dict[tuple, float] = {}
    rho = _rho(data)
    h, w = data.shape
    if data.side_counts[0] and data.side_counts[1]:
        for r0, r1, c0, c1 in itertools.product(range(h + 1), range(h + 1), range(w + 1), range(w + 1)):
            rect = (r0, c0, r1, c1)
            if _valid(rect, data):
                pmf[rect] = pmf.get(rect, 0.0) + rho / (data.side_counts[0] * data.side_counts[1])
    if rho < 1.0:
        j = data.settings.birth_jitter
        share = (1.0 - rho) / (2 * j + 1) ** 4
        for cand, wt in zip(data.birth_rects.tolist(), data.birth_weights.tolist()):
            for off in itertools.product(range(-j, j + 1), repeat=4):
                rect = tuple(v + o for v, o in zip(cand, off))
                if _valid(rect, data):
                    pmf[rect] = pmf.get(rect, 0.0) + wt * share
    return pmf


def enumerate_add(world, data: KernelData):
    free = np.flatnonzero(~world.active)
    if free.size == 0:
        return []
    n = world.capacity - free.size
    out = []
    for rect, q in birth_pmf(data).items():
        lr = add_log_ratio(n, world.capacity, rect, data)
        for slot in free.tolist():
            out.append((Proposal(wm.add(world, slot, rect), lr, (slot,)), q / free.size))
    return out


def enumerate_remove(world, data: KernelData):
    act = np.flatnonzero(world.active)
    return [(Proposal(wm.remove(world, s), -add_log_ratio(act.size - 1, world.capacity, world.rects[s], data),
                      (int(s),)), 1.0 / act.size) for s in act.tolist()]


add_remove = Kernel("add_remove", propose_add, enumerate_add, propose_remove, enumerate_remove)
