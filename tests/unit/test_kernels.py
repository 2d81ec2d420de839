"""Properties of every kernel: reversibility by its partner, valid output, untouched input, and a
sampler that draws from exactly the distribution its ``enumerate`` lists."""

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings, strategies as st
from scipy import stats

from semmap_pp import cells
from semmap_pp import world as wm
from semmap_pp.sampler.kernels import KERNELS, KernelSettings, Mix, build_data
from semmap_pp.sampler.kernels.common import world_key

SET = KernelSettings(local_radius=2, birth_jitter=1, box_jitter=1, wall_line_min=3)


def small_map():
    """7 x 8 lattice: an outer wall, one inner wall with a one-cell door, a pillar."""
    c = np.full((7, 8), cells.FREE, np.uint8)
    c[0, :] = c[-1, :] = c[:, 0] = c[:, -1] = cells.OCCUPIED
    c[:, 4] = cells.OCCUPIED
    c[3, 4] = cells.FREE
    c[2, 2] = cells.UNKNOWN
    return c


DATA = {g: build_data(small_map(), min_side=2, wall_cells=1, wall_share=g, max_side=6, door_min=1,
                      door_max=2, settings=SET) for g in (0, 1)}


def walk(rng, data, capacity, steps, start=None):
    """A world reached by applying random proposals (all accepted) from ``start`` (default empty)."""
    w = wm.empty(capacity) if start is None else start
    # births next to units and splits make the adjacent pairs the other kernels need
    mix = Mix([(KERNELS[k], w) for k, w in [("add_remove", 1), ("split_merge", 3), ("allocate_delete", 3),
                                            ("shrink_dilate", 1), ("interchange", 1)]])
    for _ in range(steps):
        _, p = mix(rng, w, data)
        if p is not None:
            w = p.world
    return w


def valid(world, data):
    h, w = wm.heights_widths(world)
    return wm.is_valid(world, data.shape, data.min_side) and h.max() <= data.max_side and \
        w.max() <= data.max_side


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(seed=st.integers(0, 2 ** 32 - 1), steps=st.integers(0, 40), g=st.sampled_from([0, 1]),
       kind=st.sampled_from(sorted(KERNELS)), rich=st.booleans())
@pytest.mark.slow
def test_every_proposal_is_valid_exact_and_reversible(seed, steps, g, kind, rich):
    data, kernel = DATA[g], KERNELS[kind]
    rng = np.random.default_rng(seed)
    # from a world with adjacent units and few steps, or from the empty world with many
    world = walk(rng, data, 3, steps % 4, rich_world(g)) if rich else walk(rng, data, 3, steps)
    before = (world.rects.copy(), world.active.copy(), world.types.copy())
    for _ in range(10):
        p = kernel(rng, world, data)
        for a, b in zip(before, world):
            np.testing.assert_array_equal(a, b)   # the kernel never edits its input
        if p is not None:
            break
    if p is None:
        return
    assert valid(p.world, data)
    changed = np.flatnonzero(np.any(p.world.rects != world.rects, axis=1) | (p.world.active != world.active))
    assert set(changed.tolist()) == set(p.changed_slots)
    assert math.isfinite(p.log_ratio)
    forward = {world_key(q.world): q for q, _ in kernel.enumerate(world, data)}
    assert forward[world_key(p.world)].log_ratio == pytest.approx(p.log_ratio, abs=1e-9)
    # the partner proposes the exact reverse, with the opposite log ratio
    back = {world_key(q.world): q for q, _ in kernel.enumerate(p.world, data)}
    rev = back.get(world_key(world))
    assert rev is not None
    assert rev.log_ratio == pytest.approx(-p.log_ratio, abs=1e-9)


def rich_world(g):
    """Two units sharing a wall (mergeable, interchangeable) and one free slot."""
    s = g
    return wm.make([(1, 1, 6, 4), (1, 4 - s, 6, 7), (0, 0, 0, 0)], [True, True, False], [-1] * 3)


@pytest.mark.parametrize("kind", sorted(KERNELS))
@pytest.mark.parametrize("g", [0, 1])
def test_sampler_draws_what_enumerate_lists(kind, g):
    data, kernel = DATA[g], KERNELS[kind]
    world = rich_world(g)
    assert valid(world, data)
    probs = {}
    for q, pr in kernel.enumerate(world, data):
        probs[world_key(q.world)] = probs.get(world_key(q.world), 0.0) + pr
    none_p = 1.0 - sum(probs.values())
    assert none_p > -1e-12
    rng = np.random.default_rng(11)
    n = 4000
    counts = {}
    for _ in range(n):
        p = kernel(rng, world, data)
        key = None if p is None else world_key(p.world)
        assert key is None or key in probs
        counts[key] = counts.get(key, 0) + 1
    keys = sorted(probs, key=lambda k: -probs[k])
    expected = np.array([probs[k] for k in keys] + [max(none_p, 0.0)]) * n
    observed = np.array([counts.get(k, 0) for k in keys] + [counts.get(None, 0)])
    big = expected >= 5
    exp_b = np.append(expected[big], expected[~big].sum())
    obs_b = np.append(observed[big], observed[~big].sum())
    keep = exp_b > 0
    assert obs_b[~keep].sum() == 0
    pval = stats.chisquare(obs_b[keep], exp_b[keep]).pvalue if keep.sum() > 1 else 1.0
    assert pval > 1e-4, (kind, g, pval)


def test_impossible_moves_return_none():
    data = DATA[0]
    rng = np.random.default_rng(0)
    empty = wm.empty(2)
    full = wm.make([(1, 1, 6, 4), (1, 4, 6, 7)], [True, True], [-1, -1])
    sm = KERNELS["split_merge"]
    assert sm.enumerate(empty, data) == []               # nothing to split or merge
    assert all(p.world.active.sum() == 1 for p, _ in sm.enumerate(full, data))  # no free slot: merges only
    assert all(KERNELS[k](rng, empty, data) is None for k in ("shrink_dilate", "interchange"))


def test_split_prefers_the_wall_line():
    """The cut of a unit spanning the inner wall (column 4) falls on that wall most often."""
    data = DATA[0]
    w = wm.make([(1, 1, 6, 7), (0, 0, 0, 0)], [True, False], [-1, -1])
    cuts = {}
    for p, q in KERNELS["split_merge"].enumerate(w, data):
        if p.world.active.sum() == 2 and p.world.rects[0, 2] == 6:   # a vertical cut
            c = int(p.world.rects[0, 3])
            cuts[c] = cuts.get(c, 0.0) + q
    assert max(cuts, key=cuts.get) in (4, 5)
