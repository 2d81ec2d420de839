"""Tempering and replica exchange in the sample around W* are opt-in: the model's defaults leave
them off, `semmap map --tempered` / `--rungs N` switch them on, and the statistics of a tempered
sample (beta, swap_accept) reach spread.nc only when it was tempered."""

import argparse
import dataclasses
from types import SimpleNamespace as NS

import numpy as np

from semmap_pp.cli.cmd_map import _tempering
from semmap_pp.model import load_model
from semmap_pp.run.results import SpreadSample, Tempering, collect_draws
from semmap_pp.sampler.diagnostics import SUMMARIES, convergence


def test_the_default_model_leaves_the_sample_untempered_with_one_rung():
    s = load_model().sampler
    assert s.spread_tempered is False
    # what sample_spread builds from them: exponent 1, one rung
    assert (s.spread_correlation_lag_m if s.spread_tempered else 0.0) == 0.0
    assert (s.spread_rungs if s.spread_tempered else 1) == 1


@dataclasses.dataclass(frozen=True)
class _Inputs:
    model: object


def test_tempered_and_rungs_switch_it_on():
    inputs = _Inputs(load_model())
    off = _tempering(inputs, argparse.Namespace(tempered=False, rungs=None))
    assert off is inputs
    on = _tempering(inputs, argparse.Namespace(tempered=True, rungs=None))
    assert on.model.sampler.spread_tempered and on.model.sampler.spread_rungs == inputs.model.sampler.spread_rungs
    six = _tempering(inputs, argparse.Namespace(tempered=False, rungs=6))
    assert six.model.sampler.spread_tempered and six.model.sampler.spread_rungs == 6
    assert inputs.model.sampler.spread_tempered is False          # the model itself untouched


def _records(beta, swap):
    n = 6
    stats = {"logp": np.linspace(-10, -5, n), "burn_in": np.zeros(n, int), "beta": np.full(n, beta),
             "swap_accept": np.full(n, swap), "accept": np.full(n, 0.2), "temperature": np.ones(n),
             "knowledge": np.ones(n, int), "best_logp": np.full(n, -5.0)}
    stats |= {k: np.arange(n, dtype=float) for k in SUMMARIES[1:]}
    return [NS(stats=dict(stats), rects=np.zeros((n, 2, 4), int), active=np.zeros((n, 2), bool))
            for _ in range(2)]


def test_beta_and_swap_accept_are_kept_only_for_a_tempered_sample():
    model = load_model()
    plain = collect_draws(_records(1.0, np.nan), model)[3]
    assert "beta" not in plain and "swap_accept" not in plain and "accept" in plain
    hot = collect_draws(_records(0.0115, 0.25), model)[3]
    assert np.all(hot["beta"] == 0.0115) and np.all(hot["swap_accept"] == 0.25)


def test_the_spread_line_says_where_the_chains_started_and_how_they_were_tempered():
    rep = convergence({"log_posterior": np.random.default_rng(0).normal(size=(2, 20))}, rhat_max=1.01,
                      ess_min=400)
    common = dict(draws=20, n_inner=20, summaries={}, report=rep, samples={}, seconds=2.0,
                  kernels_per_second=100.0, start_logp=0.0, best_logp=0.0, kept=((0, 1), 20))
    plain = SpreadSample(sample_stats={}, **common).text()
    assert "x 20 kernels from W*" in plain and "power" not in plain and "swap" not in plain
    t = Tempering(ladder=(0.02, 0.01, 0.005), area=50.0, swaps=3, dispersed=True)
    hot = SpreadSample(sample_stats={"swap_accept": np.array([[0.0, 0.5], [0.5, 1.0]])}, tempering=t,
                       **common).text()
    assert "(chain 1 from W*, the others from the search's dispersed starts)" in hot
    assert "over 3 rungs" in hot and "power 1/50.0" in hot and "3 replicas per chain" in hot
    assert "swaps accepted 0.500 of the time" in hot
