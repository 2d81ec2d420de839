"""SPLIT / MERGE: one unit into two that share a new wall, and back.

SPLIT picks a unit uniformly (``1/n``), an axis (``1/2``), a cut position ``s`` and a free slot for
the second piece (``1/(K - n)``). Along axis ``a`` the unit ``[lo, hi)`` becomes ``[lo, s)`` (kept in
its slot) and ``[s - g, hi)`` (the new slot), ``g`` the wall share; ``s`` ranges over
``[lo + m, hi + g - m]`` with probability ``w(s) / sum w``, ``w(s) = floor + `` mean line evidence
over the new wall's lines ``s - t .. s - g + t - 1`` across the unit's span: cuts go where the map
shows a wall or a door line.

MERGE picks uniformly one of the ``N_merge`` pairs of units that share a whole wall (same span,
``b.lo == a.hi - g``) and whose union is a valid unit; the union goes into the first unit's slot.

    log q(W'->W) / q(W->W')  [SPLIT, W has n units]
        = -log N_merge(W') - [ -log n - log 2 + log w(s)/sum w - log(K - n) ].
"""

from __future__ import annotations

import math

import numpy as np

from semmap_pp import world as wm
from semmap_pp.sampler.kernels.common import LOG_HALF, band_weights, line_cum, pair_array
from semmap_pp.sampler.kernels.data import KernelData
from semmap_pp.sampler.kernels.proposal import Kernel, Proposal


def cut_weights(rect, axis: int, data: KernelData):
    """``(lo, hi, w)``: admissible cut positions ``lo..hi`` along ``axis`` and their weights."""
    m, t, g = data.min_side, data.wall_cells, data.wall_share
    lo, hi = int(rect[axis]) + m, int(rect[axis + 2]) + g - m
    if hi < lo:
        return lo, hi, None
    w = band_weights(line_cum(data, axis), lo, hi, -t, t - g, int(rect[1 - axis]), int(rect[3 - axis]),
                     data.settings.line_floor)
    return lo, hi, w


def pieces(rect, axis: int, s: int, g: int):
    first = rect.tolist() if isinstance(rect, np.ndarray) else [int(v) for v in rect]
    second = list(first)
    first[axis + 2] = s
    second[axis] = s - g
    return tuple(first), tuple(second)


def split_log_q(rect, axis: int, s: int, n: int, capacity: int, data: KernelData, cut=None) -> float:
    """Log probability that SPLIT (given its direction) cuts ``rect`` at ``s`` into a given free slot."""
    lo, hi, w = cut if cut is not None else cut_weights(rect, axis, data)
    return (-math.log(n) + LOG_HALF + math.log(w[s - lo] / w.sum()) - math.log(capacity - n))


def mergeable(world, data: KernelData) -> list:
    """``(axis, a, b)`` of every pair MERGE may join, ``a`` the first (upper or left) unit."""
    arr = pair_array(world.rects, world.active, data.min_side, data.wall_share, data.max_side)
    return [tuple(p) for p in arr.tolist()]


def _split_world(world, slot, new_slot, axis, s, data):
    first, second = pieces(world.rects[slot], axis, s, data.wall_share)
    return wm.add(wm.replace(world, slot, first), new_slot, second)


def _split_proposal(world, slot, new_slot, axis, s, n, data, cut=None):
    new = _split_world(world, slot, new_slot, axis, s, data)
    lq = split_log_q(world.rects[slot], axis, s, n, world.capacity, data, cut)
    return Proposal(new, -math.log(len(mergeable(new, data))) - lq, (slot, new_slot))


def propose_split(rng, world, data: KernelData):
    act = world.active.nonzero()[0]
    free = (~world.active).nonzero()[0]
    if act.size == 0 or free.size == 0:
        return None
    slot = int(act[int(rng.random() * act.size)])
    axis = 0 if rng.random() < 0.5 else 1
    lo, hi, w = cut_weights(world.rects[slot], axis, data)
    if w is None:
        return None
    cdf = np.cumsum(w)
    s = lo + min(int(np.searchsorted(cdf, rng.random() * cdf[-1], side="right")), hi - lo)
    new_slot = int(free[int(rng.random() * free.size)])
    return _split_proposal(world, slot, new_slot, axis, s, act.size, data, (lo, hi, w))


def _merge_proposal(world, pair, n_pairs, data):
    axis, a, b = pair
    union = world.rects[a].tolist()
    union[axis + 2] = int(world.rects[b][axis + 2])
    new = wm.remove(wm.replace(world, a, union), b)
    s = int(world.rects[a][axis + 2])
    lq = split_log_q(union, axis, s, int(world.active.sum()) - 1, world.capacity, data)
    return Proposal(new, lq + math.log(n_pairs), (a, b))


def propose_merge(rng, world, data: KernelData):
    pairs = mergeable(world, data)
    if not pairs:
        return None
    return _merge_proposal(world, pairs[int(rng.random() * len(pairs))], len(pairs), data)


def enumerate_split(world, data: KernelData):
    act = np.flatnonzero(world.active)
    free = np.flatnonzero(~world.active)
    out = []
    if act.size == 0 or free.size == 0:
        return out
    for slot in act.tolist():
        for axis in (0, 1):
            lo, hi, w = cut_weights(world.rects[slot], axis, data)
            if w is None:
                continue
            for s in range(lo, hi + 1):
                q = 0.5 / act.size * w[s - lo] / w.sum() / free.size
                for new_slot in free.tolist():
                    out.append((_split_proposal(world, slot, new_slot, axis, s, act.size, data), q))
    return out


def enumerate_merge(world, data: KernelData):
    pairs = mergeable(world, data)
    return [(_merge_proposal(world, p, len(pairs), data), 1.0 / len(pairs)) for p in pairs]


split_merge = Kernel("split_merge", propose_split, enumerate_split, propose_merge, enumerate_merge)
