"""INTERCHANGE: move the shared wall of two adjacent units together.

Pick uniformly one of the ``N_adj`` pairs of units sharing a wall (``b.lo == a.hi - g`` along an axis,
spans overlapping by at least ``m``). Their shared wall moves from ``s`` to ``s'``: ``a.hi = s'``,
``b.lo = s' - g``; the pair's outer walls stay, so the union of their extents along the axis is kept
(and their total size exactly when their spans agree). ``s'`` keeps both units within the side range
(the range depends only on the outer walls: the same both ways) and is drawn as in SHRINK/DILATE,
local step or jump towards line evidence across the overlap of the spans:

    log q(W'->W) / q(W->W') = log N_adj(W) - log N_adj(W') + log q(s|s') - log q(s'|s).
"""

from __future__ import annotations

import math


from semmap_pp import world as wm
from semmap_pp.sampler.kernels.common import (attach_pairs, band_weights, pair_array, line_cum, position_draw,
                                      position_enumerate, _pair_q)
from semmap_pp.sampler.kernels.data import KernelData
from semmap_pp.sampler.kernels.proposal import Kernel, Proposal


def adjacent_pairs(world, data: KernelData) -> list:
    """``(axis, a, b)`` of every pair sharing a wall, ``a`` the upper or left unit."""
    return attach_pairs(world.rects, world.active, data.min_side, data.wall_share)


def n_adjacent(world, data: KernelData) -> int:
    return pair_array(world.rects, world.active, data.min_side, data.wall_share).shape[0]


def shared_wall_range(ra, rb, axis: int, data: KernelData):
    """``(s, lo, hi, w)``: the shared wall's position, its admissible range and weights."""
    m, big, t, g = data.min_side, data.max_side, data.wall_cells, data.wall_share
    a_lo, s, b_hi = int(ra[axis]), int(ra[axis + 2]), int(rb[axis + 2])
    lo, hi = max(a_lo + m, b_hi + g - big), min(a_lo + big, b_hi + g - m)
    s0 = max(int(ra[1 - axis]), int(rb[1 - axis]))
    s1 = min(int(ra[3 - axis]), int(rb[3 - axis]))
    w = band_weights(line_cum(data, axis), lo, hi, -t, t - g, s0, s1, data.settings.line_floor)
    return s, lo, hi, w


def _proposal(world, pair, s2, n_pairs, wall, data):
    axis, a, b = pair
    set_ = data.settings
    s, lo, hi, w = wall
    ra, rb = world.rects[a].tolist(), world.rects[b].tolist()
    ra[axis + 2], rb[axis] = s2, s2 - data.wall_share
    new = wm.replace(wm.replace(world, a, ra), b, rb)
    back, fwd = _pair_q(s, s2, lo, w, float(set_.local_prob), int(set_.local_radius))
    lr = (math.log(n_pairs) - math.log(n_adjacent(new, data))
          + math.log(back)
          - math.log(fwd))
    return Proposal(new, lr, (a, b))


def propose_interchange(rng, world, data: KernelData):
    pairs = adjacent_pairs(world, data)
    if not pairs:
        return None
    pair = pairs[int(rng.random() * len(pairs))]
    axis, a, b = pair
    wall = shared_wall_range(world.rects[a], world.rects[b], axis, data)
    s, lo, hi, w = wall
    set_ = data.settings
    s2 = position_draw(rng, s, lo, hi, w, set_.local_prob, set_.local_radius)
    if s2 is None:
        return None
    return _proposal(world, pair, s2, len(pairs), wall, data)


def enumerate_interchange(world, data: KernelData):
    pairs = adjacent_pairs(world, data)
    set_ = data.settings
    out = []
    for pair in pairs:
        axis, a, b = pair
        wall = shared_wall_range(world.rects[a], world.rects[b], axis, data)
        s, lo, hi, w = wall
        for s2, q in position_enumerate(s, lo, hi, w, set_.local_prob, set_.local_radius).items():
            out.append((_proposal(world, pair, s2, len(pairs), wall, data), q / len(pairs)))
    return out


interchange = Kernel("interchange", propose_interchange, enumerate_interchange)
