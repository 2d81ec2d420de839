"""Stopping and continuing chains: the stop flag, the budget, resumed chains, the kept rectangle."""

import numpy as np
import pytest

from semmap_pp import cells
from semmap_pp import world as wm
from semmap_pp.errors import SemmapError
from semmap_pp.lattice.frame import build_frame_from_classes
from semmap_pp.sampler.kernels import data_from_frame
from semmap_pp.model import load_model
from semmap_pp.target.posterior import Posterior
from semmap_pp.sampler.resume import _rectangle, keep_common_draws, merge_records
from semmap_pp.sampler.sampling import ChainRecord, sample_worlds
from semmap_pp.sampler.step import StopFlag

CAP = 6


@pytest.fixture(scope="module")
def problem():
    c = np.full((40, 60), cells.UNKNOWN, np.uint8)
    c[3:37, 3:57] = cells.OCCUPIED
    c[5:35, 5:55] = cells.FREE
    c[5:35, 29:31] = cells.OCCUPIED
    c[15:25, 29:31] = cells.FREE
    model = load_model()
    frame = build_frame_from_classes(c, 0.05, model)
    return Posterior(frame, model), data_from_frame(frame)


def test_stop_flag_ends_sampling_after_min_draws(problem):
    post, data = problem
    stop, seen = StopFlag(), []

    def progress(info):
        seen.append(info)
        if len(seen) == 2:
            stop.set()          # as the SIGINT handler does, during the second draw of chain 0

    res = sample_worlds(post, data, [wm.empty(CAP)], draws=50, tune=2, chains=2, cores=1, n_inner=5,
                        seed=1, callback=progress, stop=stop)
    assert res.stopped == "interrupted"
    first, second = res.records
    assert len(first.stats["logp"]) == 4            # a begun chain makes its 4 draws
    assert second.stats == {} and second.last is None   # the next chain never began
    assert first.last.draw == 4 and first.stats["draw_index"].tolist() == [0, 1, 2, 3]
    assert res.best_world is not None and np.isfinite(res.best_logp)
    assert seen[0]["phase"] == "burn-in" and seen[2]["phase"] == "sampling"


def test_budget_keeps_min_draws_and_says_budget(problem):
    post, data = problem
    res = sample_worlds(post, data, [wm.empty(CAP)], draws=500, tune=100, chains=2, cores=1, n_inner=5,
                        seed=2, budget=1e-6)
    assert res.stopped == "budget"
    for rec in res.records:
        # the budget ran out in burn-in: burn-in ended at once, then 4 draws at temperature 1
        assert rec.stats["burn_in"].tolist() == [0, 0, 0, 0]
        assert np.all(rec.stats["temperature"] == 1.0)


def test_resumed_chains_continue_exactly(problem):
    post, data = problem
    kw = dict(tune=3, chains=2, cores=1, n_inner=8, seed=5, anneal=4.0)
    whole = sample_worlds(post, data, [wm.empty(CAP)], draws=7, **kw)
    part = sample_worlds(post, data, [wm.empty(CAP)], draws=3, **kw)
    starts = {c: r.last for c, r in enumerate(part.records)}
    lasts = [wm.make(r.rects[-1], r.active[-1], np.full(CAP, -1)) for r in part.records]
    more = sample_worlds(post, data, lasts, draws=4, tune=0, chains=2, cores=1, n_inner=8, seed=5,
                         anneal=4.0, resume=starts, schedule=(3, 10))
    merged = merge_records(part.records, more.records)
    for a, b in zip(whole.records, merged):
        np.testing.assert_array_equal(a.rects, b.rects)
        np.testing.assert_array_equal(a.stats["logp"], b.stats["logp"])
        np.testing.assert_array_equal(a.stats["burn_in"], b.stats["burn_in"])
    assert more.best_logp <= whole.best_logp + 1e-9


def record(n_tune, n_rec):
    n = n_tune + n_rec
    stats = {"logp": np.arange(n, dtype=float), "burn_in": np.r_[np.ones(n_tune, int), np.zeros(n_rec, int)]}
    return ChainRecord(stats, np.zeros((n, 1, 4), np.int32), np.zeros((n, 1), bool), None)


@pytest.mark.parametrize("lengths, expect", [
    ([200, 10, 0, 0], ([0], 200)),         # one long chain beats 2 x 10
    ([150, 148], ([0, 1], 148)),           # parallel chains stopped a draw apart: cut to 148
    ([10, 30, 30, 5], ([1, 2], 30)),       # 2 x 30 > 3 x 10
    ([6, 6, 6], ([0, 1, 2], 6)),
])
def test_rectangle_keeps_the_most_draws(lengths, expect):
    assert _rectangle(lengths) == expect


def test_keep_common_draws_falls_back_to_burn_in_and_refuses_nothing():
    chains, n, index, notes = keep_common_draws([record(2, 8), record(2, 5)])
    assert (chains, n) == ([0, 1], 5) and index[0].tolist() == [2, 3, 4, 5, 6]
    chains, n, index, notes = keep_common_draws([record(6, 1), record(5, 0)])
    assert (chains, n) == ([0, 1], 5) and any("burn-in" in t for t in notes)
    with pytest.raises(SemmapError):
        keep_common_draws([record(2, 1), record(1, 0)])
