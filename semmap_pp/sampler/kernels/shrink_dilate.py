"""SHRINK / DILATE: move one wall of one unit (inwards: SHRINK, outwards: DILATE).

Pick a unit uniformly (``1/n``) and one of its four walls (``1/4``). The wall's position ``x`` moves to
``x'`` within the range that keeps the unit on the lattice and within the side range (the range
depends only on the opposite wall, so it is the same for the move and its reverse), drawn from

    q(x'|x) = rho * [1 <= |x' - x| <= d] / (2 d) + (1 - rho) * w(x') / (sum w - w(x)),

a local step or a jump towards line evidence: ``w(x) = floor +`` mean wall evidence over the unit's
wall band at ``x`` across its span. A step off the range is an impossible move (``None``). The unit
and wall choices are the same in both directions, so

    log q(W'->W) / q(W->W') = log q(x|x') - log q(x'|x).

A SHRINK is undone by a DILATE of the same wall: the pair is one self-reverse kernel.
"""

from __future__ import annotations


import numpy as np

from semmap_pp import world as wm
from semmap_pp.sampler.kernels.common import (band_weights, line_cum, position_draw, position_enumerate,
                                      position_log_ratio)
from semmap_pp.sampler.kernels.data import KernelData
from semmap_pp.sampler.kernels.proposal import Kernel, Proposal


def wall_range(rect, side: int, data: KernelData):
    """``(index, lo, hi, w)`` for wall ``side`` (0: r0, 1: c0, 2: r1, 3: c1) of ``rect``."""
    axis = side % 2
    m, big, t = data.min_side, data.max_side, data.wall_cells
    low_edge, high_edge = int(rect[axis]), int(rect[axis + 2])
    if side < 2:
        lo, hi, a, b = max(0, high_edge - big), high_edge - m, 0, t
    else:
        lo, hi, a, b = low_edge + m, min(data.shape[axis], low_edge + big), -t, 0
    w = band_weights(line_cum(data, axis), lo, hi, a, b, int(rect[1 - axis]), int(rect[3 - axis]),
                     data.settings.line_floor)
    return side, lo, hi, w


def _proposal(world, slot, side, x2, lo, w, data):
    s = data.settings
    x = int(world.rects[slot][side])
    rect = world.rects[slot].tolist()
    rect[side] = x2
    lr = position_log_ratio(x, x2, lo, w, s.local_prob, s.local_radius)
    return Proposal(wm.replace(world, slot, rect), lr, (slot,))


def propose_shrink_dilate(rng, world, data: KernelData):
    act = world.active.nonzero()[0]
    if act.size == 0:
        return None
    slot = int(act[int(rng.random() * act.size)])
    side = int(rng.random() * 4)
    _, lo, hi, w = wall_range(world.rects[slot], side, data)
    s = data.settings
    x2 = position_draw(rng, int(world.rects[slot][side]), lo, hi, w, s.local_prob, s.local_radius)
    if x2 is None:
        return None
    return _proposal(world, slot, side, x2, lo, w, data)


def enumerate_shrink_dilate(world, data: KernelData):
    act = np.flatnonzero(world.active)
    s = data.settings
    out = []
    for slot in act.tolist():
        for side in range(4):
            _, lo, hi, w = wall_range(world.rects[slot], side, data)
            pmf = position_enumerate(int(world.rects[slot][side]), lo, hi, w, s.local_prob, s.local_radius)
            for x2, q in pmf.items():
                out.append((_proposal(world, slot, side, x2, lo, w, data), q / (4 * act.size)))
    return out


shrink_dilate = Kernel("shrink_dilate", propose_shrink_dilate, enumerate_shrink_dilate)
