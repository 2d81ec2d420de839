"""MH–Green acceptance, prior recovery with the likelihood off, incremental vs full target."""

import math
from typing import NamedTuple

import numpy as np
import pytest
from scipy import stats

from semmap_pp import cells
from semmap_pp import world as wm
from semmap_pp.sampler.kernels import KernelSettings, Proposal, build_data, default_mix
from semmap_pp.sampler.mcmc import mh_green, run_chain
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


class FloorTracker(FakeTracker):
    """:class:`FakeTracker` that takes a floor (as the project's Tracker does) and records it."""

    supports_floor = True

    def propose(self, world, changed, floor=None):
        self.floor = floor
        return P(world, self.new_logp)


@pytest.mark.parametrize("old,new,ratio,temp", [
    (0.0, -2.0, 0.5, 2.0),          # log alpha = -1 + 0.5
    (-10.0, -13.0, -0.4, 3.0),      # -1 - 0.4
    (5.0, 4.0, 0.3, 0.5),           # T < 1 sharpens: -2 + 0.3
    (0.0, 1.5, -1.0, 2.5),          # a better world, a ratio against it: 0.6 - 1
    (0.0, -1.0, 2.5, 4.0),          # -0.25 + 2.5 > 0: always accepted
    (3.0, -7.0, 4.0, 10.0),         # -1 + 4 > 0
])
def test_mh_green_at_a_temperature(old, new, ratio, temp):
    """Mutant class "MH at T != 1" (docs/robustness.md, "Mutants"): with T != 1 and a nonzero log
    ratio the acceptance probability is min(1, exp((log pi(W') - log pi(W)) / T + log_ratio))
    (semmap_pp/sampler/mcmc.py): a uniform just below it accepts, just above it rejects; a target that
    takes a floor gets ``log pi(W) + T (log u - log_ratio)`` and decides the same; and over 20,000
    seeded uniforms the share accepted is that probability (binomial test)."""
    alpha = min(1.0, math.exp((new - old) / temp + ratio))
    below = [alpha * (1 - 1e-9)] + ([] if alpha == 1.0 else [alpha * (1 + 1e-9)])
    for u, expect in zip(below, (True, False)):
        for cls in (FakeTracker, FloorTracker):
            tr = cls(old, new)
            assert mh_green(FixedRng(u), tr, Proposal("new", ratio, (0,)), temperature=temp) is expect
            assert (tr.world == "new") is expect
            if cls is FloorTracker:
                assert tr.floor == pytest.approx(old + temp * (math.log(u) - ratio), rel=1e-12, abs=1e-12)
    rng = np.random.default_rng(17)
    n = 20_000
    accepted = sum(mh_green(rng, FakeTracker(old, new), Proposal("new", ratio, (0,)), temperature=temp)
                   for _ in range(n))
    if alpha == 1.0:
        assert accepted == n
    else:
        assert stats.binomtest(accepted, n, alpha).pvalue > 1e-3


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


@pytest.mark.slow
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
    ar = importlib.import_module("semmap_pp.sampler.kernels.add_remove")
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


@pytest.mark.slow
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
    from semmap_pp.lattice.frame import build_frame_from_classes
    from semmap_pp.sampler.kernels import data_from_frame
    from semmap_pp.model import load_model
    from semmap_pp.target.posterior import Posterior

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


def likelihood_off_model(n_mean=1.5):
    """The default model with the likelihood switched off and the SaLe factor too, so that the
    project's own Posterior is the prior of units and rectangles alone: every sensor row is the
    unknown row (every category's gain 0), ψ = 1 (no overlap penalty), no enclosure cost, and no
    P(SaLe) above the threshold 1; p_n a Poisson of mean ``n_mean``."""
    import dataclasses

    from semmap_pp.model import load_model

    m = load_model()
    flat = np.tile(m.sensor.other[cells.WORLD_STATES.index("unknown")], (len(cells.WORLD_STATES), 1))
    return dataclasses.replace(
        m, sensor=dataclasses.replace(m.sensor, psi=1.0, corridor=flat, other=flat, enclosure_cost=0.0),
        prior=dataclasses.replace(m.prior, n_mean=n_mean, sale_threshold=1.0))


@pytest.mark.slow
def test_the_real_posterior_with_the_likelihood_off_samples_the_prior():
    """Mutant class "the one-unit prior" (docs/robustness.md, "Mutants"): the project's sampler
    (the five kernels, :func:`mh_green`) on the project's Posterior with the likelihood off
    (:func:`likelihood_off_model`) recovers the prior exactly: the number of units follows the
    truncated Poisson ``p_n`` over 0..K, the joint law of (units, corridors) is ``p_n(n)``
    times a binomial of each unit's corridor share among the valid rectangles (types from the
    geometry, knowledge off), and a unit's width the share of valid rectangles of that width
    (chi-square, counts rescaled to the effective sample size)."""
    from math import comb

    from semmap_pp.cells import UNIT_TYPES
    from semmap_pp.target.geometry_evidence import GEOMETRY_TYPE, geometry_class
    from semmap_pp.lattice.frame import build_frame_from_classes
    from semmap_pp.sampler.kernels import data_from_frame
    from semmap_pp.target.posterior import Posterior
    from semmap_pp.target.prior import log_p_n_table

    model = likelihood_off_model()
    h, w = 10, 30                                   # 2.5 m x 7.5 m at 0.25 m: units of 5..10 x 5..30 cells
    c = np.full((h, w), cells.FREE, np.uint8)
    c[0, :] = c[-1, :] = c[:, 0] = c[:, -1] = cells.OCCUPIED
    c[:, w // 2] = cells.OCCUPIED
    c[h // 2, w // 2] = cells.FREE
    frame = build_frame_from_classes(c, 0.25, model, theta=0.0)
    assert frame.shape == (h, w)
    post = Posterior(frame, model)
    data = data_from_frame(frame)
    K = 4
    tr = post.start(wm.empty(K))
    corridor = UNIT_TYPES.index("corridor")
    n_seen, corr_seen, widths = [], [], []

    def record(i, tracker, ok):
        if i % 15 == 0:
            wd = tracker.world
            n_seen.append(wm.n_units(wd))
            corr_seen.append(int(np.sum(wd.types[wd.active] == corridor)))
            widths.extend((wd.rects[wd.active, 3] - wd.rects[wd.active, 1]).tolist())

    res = run_chain(np.random.default_rng(2), tr, default_mix(data.settings), 150_000, data,
                    callback=record)
    assert tr.loglik == post.evaluate(wm.empty(K)).loglik     # the likelihood is a constant
    # number of units: p_n itself
    p_n = np.exp(log_p_n_table(K, model.prior))
    obs = np.bincount(n_seen, minlength=K + 1)
    n_eff = ess(n_seen)
    assert chisquare_ess(obs, p_n, n_eff) > 1e-3
    assert n_eff > 500
    # (units, corridors): p_n(n) C(n, k) q^k (1 - q)^(n - k), q the corridor share of the support
    lo = frame.cells.min_side
    sizes = [(a, b) for a in range(lo, h + 1) for b in range(lo, w + 1)]
    count = np.array([(h - a + 1) * (w - b + 1) for a, b in sizes])
    types = GEOMETRY_TYPE[geometry_class(np.array([(0, 0, a, b) for a, b in sizes]), 0.25, model.evidence)]
    q = count[types == corridor].sum() / count.sum()
    assert 0.1 < q < 0.5
    cats = [(n, k) for n in range(K + 1) for k in range(n + 1)]
    p_joint = [p_n[n] * comb(n, k) * q ** k * (1 - q) ** (n - k) for n, k in cats]
    obs = np.bincount([cats.index(nk) for nk in zip(n_seen, corr_seen)], minlength=len(cats))
    assert chisquare_ess(obs, p_joint, n_eff) > 1e-3
    # a unit's width b: (w - b + 1) of the positions of every valid height
    p_w = np.array([(w - b + 1) for b in range(lo, w + 1)], float)
    obs = np.bincount(widths, minlength=w + 1)[lo:]
    assert chisquare_ess(obs, p_w, n_eff * len(widths) / len(n_seen)) > 1e-3
    assert res.accepted.min() > 20       # every kernel pair moved the chain
