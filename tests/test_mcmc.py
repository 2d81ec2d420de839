"""MH–Green acceptance, prior recovery with the likelihood off, incremental vs full target."""

import math
from typing import NamedTuple

import numpy as np
import pytest
from scipy import stats

from semmap_pp import cells
from semmap_pp import world as wm
from semmap_pp.kernels import KernelSettings, Proposal, build_data, default_mix
from semmap_pp.mcmc import mh_green, run_chain
from standin import CachedTarget, PriorTarget


class FixedRng:
    """``random()`` returns a fixed uniform, so acceptance decisions are deterministic."""

    def __init__(self, u):
        self.u = u

    def random(self):
        return self.u


class P(NamedTuple):
    world: object
    logp: float


class FakeTracker:
    def __init__(self, logp, new_logp):
        self.world, self.logp, self.new_logp, self.accepted = "old", logp, new_logp, None

    def propose(self, world, changed):
        return P(world, self.new_logp)

    def accept(self, prop):
        self.accepted = prop
        self.world, self.logp = prop.world, prop.logp


@pytest.mark.parametrize("old,new,ratio,temp,u,expect", [
    (0.0, -1.0, 0.0, 1.0, math.exp(-1.0) * 0.999, True),    # u just below alpha = e^-1
    (0.0, -1.0, 0.0, 1.0, math.exp(-1.0) * 1.001, False),   # u just above
    (0.0, -1.0, 1.0, 1.0, 0.999, True),                      # the log ratio lifts alpha to 1
    (0.0, -2.0, 0.0, 2.0, math.exp(-1.0) * 0.999, True),    # T = 2 halves the log density step
    (0.0, -2.0, 0.0, 2.0, math.exp(-1.0) * 1.001, False),
    (0.0, -math.inf, 50.0, 1.0, 0.0, False),                # an impossible world is never accepted
    (-math.inf, -5.0, -50.0, 1.0, 0.999, True),             # leaving an impossible start always is
])
def test_mh_green_acceptance(old, new, ratio, temp, u, expect):
    tr = FakeTracker(old, new)
    ok = mh_green(FixedRng(u), tr, Proposal("new", ratio, (0,)), temperature=temp)
    assert ok is expect
    assert (tr.world == "new") is expect


def test_none_is_a_rejection():
    tr = FakeTracker(0.0, 0.0)
    assert mh_green(FixedRng(0.0), tr, None) is False and tr.accepted is None


def ess(x) -> float:
    """Effective sample size of a chain (Geyer's initial positive sequence of autocorrelations)."""
    x = np.asarray(x, float) - np.mean(x)
    n = len(x)
    f = np.fft.rfft(x, 2 * n)
    acf = np.fft.irfft(f * np.conj(f))[:n]
    acf /= acf[0]
    tau = 1.0
    for k in range(1, n - 1, 2):
        pair = acf[k] + acf[k + 1]
        if pair <= 0:
            break
        tau += 2 * pair
    return n / tau


def chisquare_ess(obs, probs, n_eff):
    """Chi-square p-value of counts ``obs`` against ``probs`` with the counts rescaled to ``n_eff``."""
    obs = np.asarray(obs, float)
    scale = n_eff / obs.sum()
    return stats.chisquare(obs * scale, np.asarray(probs) / np.sum(probs) * obs.sum() * scale).pvalue


def walled_map():
    c = np.full((9, 10), cells.FREE, np.uint8)
    c[0, :] = c[-1, :] = c[:, 0] = c[:, -1] = cells.OCCUPIED
    c[4, :6] = cells.OCCUPIED
    c[4, 2] = cells.FREE
    c[:, 6] = cells.OCCUPIED
    return c


def test_prior_is_recovered_with_the_likelihood_off():
    """Number of units and the r0 marginal of units match the prior (chi-square, thinned chain)."""
    data = build_data(walled_map(), min_side=3, wall_cells=1, wall_share=1, max_side=8, door_min=1,
                      door_max=2, settings=KernelSettings(wall_line_min=3))
    capacity, rate = 4, 1.5
    target = PriorTarget(data, capacity, rate)
    tr = target.start(wm.empty(capacity))
    n_seen, r0_seen = [], []

    def record(i, tracker, ok):
        if i % 15 == 0:
            w = tracker.world
            n_seen.append(wm.n_units(w))
            r0_seen.extend(w.rects[w.active, 0].tolist())

    rng = np.random.default_rng(2024)
    res = run_chain(rng, tr, default_mix(data.settings), 45_000, data, callback=record)
    assert res.accepted.sum() > 5000
    # number of units: the truncated Poisson p_n itself (slot term -log C(K, n), see standin)
    # (counts rescaled to the effective sample size: the chain's draws are autocorrelated)
    n_eff = ess(n_seen)
    assert n_eff > 150
    obs = np.bincount(n_seen, minlength=capacity + 1)
    assert chisquare_ess(obs, np.exp(target.log_pn), n_eff) > 1e-3
    # r0 of a unit: uniform over valid rectangles, so P(r0) is the share of valid (r0, r1) pairs
    h = data.shape[0]
    pairs = [(a, b) for a in range(h + 1) for b in range(h + 1) if 3 <= b - a <= 8]
    p_r0 = np.bincount([a for a, _ in pairs], minlength=h) / len(pairs)
    obs = np.bincount(r0_seen, minlength=h)[:h]
    keep = p_r0 > 0
    assert obs[~keep].sum() == 0
    assert chisquare_ess(obs[keep], p_r0[keep], n_eff * len(r0_seen) / len(n_seen)) > 1e-3


def test_placement_slot_term_shifts_the_number_of_units():
    """With ``-log(K!/(K-n)!)`` instead of ``-log C(K, n)`` the chain (correctly) follows p_n(n)/n!."""
    data = build_data(walled_map(), min_side=3, wall_cells=1, settings=KernelSettings(wall_line_min=3))
    target = PriorTarget(data, 4, 1.5, slots="placements")
    tr = target.start(wm.empty(4))
    seen = []
    run_chain(np.random.default_rng(8), tr, default_mix(data.settings), 36_000, data,
              callback=lambda i, t, ok: seen.append(wm.n_units(t.world)) if i % 15 == 0 else None)
    obs = np.bincount(seen, minlength=5)
    shifted = np.exp(target.log_pn - np.array([math.lgamma(k + 1) for k in range(5)]))
    assert chisquare_ess(obs, shifted, ess(seen)) > 1e-3
    assert chisquare_ess(obs, np.exp(target.log_pn), ess(seen)) < 1e-5


def test_prior_recovery_detects_a_biased_kernel(monkeypatch):
    """The same check fails when births forget the free-slot count (a wrong ratio)."""
    import importlib
    ar = importlib.import_module("semmap_pp.kernels.add_remove")
    orig = ar.add_log_ratio
    monkeypatch.setattr(ar, "add_log_ratio",
                        lambda n, k, rect, data: orig(n, k, rect, data) - math.log(k - n))
    data = build_data(walled_map(), min_side=3, wall_cells=1, settings=KernelSettings(wall_line_min=3))
    target = PriorTarget(data, 4, 1.5)
    tr = target.start(wm.empty(4))
    seen = []
    run_chain(np.random.default_rng(5), tr, default_mix(data.settings), 36_000, data,
              callback=lambda i, t, ok: seen.append(wm.n_units(t.world)) if i % 15 == 0 else None)
    obs = np.bincount(seen, minlength=5)
    assert chisquare_ess(obs, np.exp(target.log_pn), ess(seen)) < 1e-5


def test_incremental_target_matches_full_after_100k_kernels():
    """Every kernel reports every slot it changes: a per-slot cache stays exact over 150,000 kernels.

    (More than the 100,000 asked for, so that the rarest kind, SPLIT/MERGE at about one accepted move
    in 5,000, is reliably accepted more than 20 times whatever the random stream.)
    """
    data = build_data(walled_map(), min_side=3, wall_cells=1, wall_share=1, max_side=8, door_min=1,
                      door_max=2, settings=KernelSettings(wall_line_min=3))
    rng = np.random.default_rng(99)
    target = CachedTarget(rng, data, 5)
    tr = target.start(wm.empty(5))
    res = run_chain(rng, tr, default_mix(data.settings), 150_000, data)
    assert res.accepted.min() > 20   # every kind moved the chain
    assert tr.logp == pytest.approx(target.evaluate(tr.world), abs=1e-7)
    assert wm.is_valid(tr.world, data.shape, data.min_side)


def test_real_posterior_tracks_its_full_evaluation():
    """With the project's Posterior: incremental log posterior equals a full evaluation."""
    from semmap_pp.frame import build_frame_from_classes
    from semmap_pp.kernels import data_from_frame
    from semmap_pp.model import load_model
    from semmap_pp.posterior import Posterior

    model = load_model()
    c = np.full((60, 80), cells.UNKNOWN, np.uint8)
    c[4:56, 4:76] = cells.OCCUPIED
    c[6:54, 6:74] = cells.FREE
    c[28:31, 6:74] = cells.OCCUPIED      # a wall across, with a door
    c[28:31, 30:44] = cells.FREE
    c[6:28, 40:42] = cells.OCCUPIED
    frame = build_frame_from_classes(c, 0.05, model)
    post = Posterior(frame, model)
    data = data_from_frame(frame)
    tr = post.start(wm.empty(8))
    rng = np.random.default_rng(4)
    res = run_chain(rng, tr, default_mix(data.settings), 2500, data)
    assert res.accepted.sum() > 5
    full = post.evaluate(tr.world)
    assert tr.logp == pytest.approx(full.total, rel=1e-9, abs=1e-6)
