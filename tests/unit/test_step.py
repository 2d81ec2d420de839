"""The PyMC step: points, chains on one and two cores, re-sync, the -inf guard, annealing, W*."""

import pickle

import cloudpickle
import numpy as np
import pytest

from semmap_pp import cells
from semmap_pp import world as wm
from semmap_pp.lattice.frame import build_frame_from_classes
from semmap_pp.sampler.kernels import data_from_frame
from semmap_pp.model import load_model
from semmap_pp.target.posterior import Posterior
from semmap_pp.sampler.sampling import sample_worlds
from semmap_pp.sampler.chain_settings import ChainSettings
from semmap_pp.sampler.step import (WorldStep, point_to_world, world_model,
                                    world_to_point)

CAP = 6


def two_rooms():
    """A 40 x 60 lattice: two rooms joined by a door (real model, 5 cm cells)."""
    c = np.full((40, 60), cells.UNKNOWN, np.uint8)
    c[3:37, 3:57] = cells.OCCUPIED
    c[5:35, 5:55] = cells.FREE
    c[5:35, 29:31] = cells.OCCUPIED
    c[15:25, 29:31] = cells.FREE
    return c


@pytest.fixture(scope="module")
def problem():
    model = load_model()
    frame = build_frame_from_classes(two_rooms(), 0.05, model)
    return Posterior(frame, model), data_from_frame(frame)


def test_point_round_trip():
    w = wm.add(wm.add(wm.empty(4), 1, (2, 3, 20, 30), 1), 3, (0, 0, 25, 25), 0)
    back = point_to_world(world_to_point(w))
    for a, b in zip(w, back):
        np.testing.assert_array_equal(a, b)


def check_trace(trace, post, chains, draws):
    assert trace.nchains == chains
    for c in range(chains):
        rects = trace.get_values("rects", chains=c)
        active = trace.get_values("active", chains=c)
        logp = trace.get_sampler_stats("logp", chains=c)
        n = trace.get_sampler_stats("n_units", chains=c)
        assert rects.shape == (draws, CAP, 4) and len(logp) == draws
        for i in (0, draws // 2, draws - 1):   # the stats describe the recorded world exactly
            w = wm.make(rects[i], active[i] > 0, np.full(CAP, -1))
            assert logp[i] == pytest.approx(post.evaluate(w).total, abs=1e-6)
            assert n[i] == wm.n_units(w)
        acc = trace.get_sampler_stats("accept", chains=c)
        assert np.all((acc >= 0) & (acc <= 1))
        assert np.all(np.isnan(trace.get_sampler_stats("cpr", chains=c)))


def test_four_chains_sequential_resync_guard_and_best(problem):
    post, data = problem
    bad = wm.make([(0, 0, 5, 500)] + [(0, 0, 0, 0)] * (CAP - 1), [True] + [False] * (CAP - 1), [-1] * CAP)
    starts = [wm.empty(CAP), wm.add(wm.empty(CAP), 2, (3, 3, 37, 31)), bad, wm.empty(CAP)]
    res = sample_worlds(post, data, starts, draws=6, tune=4, chains=4, cores=1, n_inner=20, seed=3,
                        anneal=4.0)
    draws = 10
    check_trace(res.trace, post, 4, draws)
    # the impossible start (a unit off the lattice) fell back to the empty world
    assert np.isfinite(res.trace.get_sampler_stats("logp", chains=2)).all()
    # annealing during tuning only: T falls from 4 towards 1, then stays 1
    temp = res.trace.get_sampler_stats("temperature", chains=0)
    assert temp[0] == pytest.approx(4.0) and np.all(np.diff(temp[:4]) < 0) and np.all(temp[4:] == 1.0)
    # W*: the best world over all chains, its log posterior what the stats say, never below a draw
    all_logp = np.concatenate([res.trace.get_sampler_stats("logp", chains=c) for c in range(4)])
    assert res.best_logp >= all_logp.max() - 1e-9
    assert post.evaluate(res.best_world).total == pytest.approx(res.best_logp, abs=1e-6)
    # chains are different random streams
    lp = [tuple(res.trace.get_sampler_stats("logp", chains=c)) for c in (0, 3)]
    assert lp[0] != lp[1]


def test_two_cores_match_one_core(problem):
    post, data = problem
    kw = dict(draws=3, tune=2, chains=2, n_inner=15, seed=11)
    one = sample_worlds(post, data, [wm.empty(CAP)], cores=1, **kw)
    two = sample_worlds(post, data, [wm.empty(CAP)], cores=2, **kw)
    check_trace(two.trace, post, 2, 5)
    for c in range(2):   # the same seed gives the same chains whether sequential or parallel
        np.testing.assert_array_equal(one.trace.get_values("rects", chains=c),
                                      two.trace.get_values("rects", chains=c))
    assert one.best_logp == pytest.approx(two.best_logp)


def test_parallel_chains_are_forked_on_linux_unless_told_otherwise(problem, monkeypatch):
    """``pm.sample`` gets ``mp_ctx="fork"`` on Linux whatever Python's default start method (3.14
    made it forkserver: every chain would import and load the compiled code anew), and the
    caller's ``mp_ctx`` when given."""
    import sys

    import pymc as pm

    import semmap_pp.sampler.sampling as sampling

    seen = []

    class Called(Exception):
        pass

    def fake_sample(*args, **kwargs):
        seen.append(kwargs["mp_ctx"])
        raise Called

    monkeypatch.setattr(pm, "sample", fake_sample)
    post, data = problem
    for given in (None, "spawn"):
        with pytest.raises(Called):
            sample_worlds(post, data, [wm.empty(CAP)], draws=3, tune=0, chains=2, cores=2, n_inner=5,
                          seed=1, mp_ctx=given)
    assert seen == [sampling.DEFAULT_MP_CONTEXT, "spawn"]
    assert sampling.DEFAULT_MP_CONTEXT == ("fork" if sys.platform.startswith("linux") else None)


def test_step_pickles_without_its_caches(problem):
    post, data = problem
    with world_model(CAP) as m:
        step = WorldStep(m.value_vars, target=post, data=data, chain=ChainSettings(n_inner=5))
    step.setup_chain(np.random.default_rng(0), 0, 1)
    step.step(world_to_point(wm.empty(CAP)))
    assert step._tracker is not None
    clone = cloudpickle.loads(cloudpickle.dumps(step))
    assert clone._tracker is None and clone.n_inner == 5
    assert clone.stats_dtypes_shapes.keys() == step.stats_dtypes_shapes.keys()
    pickle.dumps(step.data)


def test_step_rejects_foreign_variables(problem):
    import pymc as pm
    post, data = problem
    with pm.Model():
        x = pm.Normal("x")
        with pytest.raises(ValueError):
            WorldStep([x], target=post, data=data)
