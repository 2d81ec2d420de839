import dataclasses
import math

import numpy as np
import pytest

from semmap_pp.sampler import diagnostics as dg
from semmap_pp.errors import SemmapError


def mixing_chains(rng, chains=4, draws=400):
    return rng.normal(size=(chains, draws))


def test_well_mixed_chains_pass():
    rng = np.random.default_rng(1)
    rep = dg.convergence({"log_posterior": mixing_chains(rng), "n_units": rng.integers(3, 9, (4, 400))},
                         rhat_max=1.01, ess_min=200)
    assert rep.ok, rep.to_text()
    assert [q.name for q in rep.quantities] == ["log_posterior", "n_units"]


def test_one_chain_stuck_elsewhere_fails_on_rhat():
    rng = np.random.default_rng(2)
    a = mixing_chains(rng)
    a[2] += 4.0
    rep = dg.convergence({"log_posterior": a}, rhat_max=1.01, ess_min=10)
    assert not rep.ok
    assert "R-hat" in rep.quantities[0].reason


def test_sticky_chain_fails_on_ess():
    rng = np.random.default_rng(3)
    # a random walk with tiny steps: chains overlap little and autocorrelation is huge
    a = np.cumsum(rng.normal(scale=0.01, size=(4, 400)), axis=1)
    rep = dg.convergence({"x": a}, rhat_max=10.0, ess_min=100)
    assert not rep.ok
    assert "ESS" in rep.quantities[0].reason


def test_nan_counts_as_failure():
    const = np.full((4, 100), 7.0)
    rep = dg.convergence({"n_units": const}, rhat_max=1.01, ess_min=10)
    assert not rep.ok and "never moved" in rep.quantities[0].reason
    nan = np.full((4, 100), np.nan)
    rep = dg.convergence({"cpr": nan}, rhat_max=1.01, ess_min=10)
    assert not rep.ok and "NaN" in rep.quantities[0].reason
    assert rep.to_dict()["quantities"]["cpr"]["rhat"] is None  # JSON-safe


def test_chains_stuck_at_different_values_fail_as_infinite():
    stuck = np.repeat(np.array([[1.0], [2.0]]), 25, axis=1)   # as n_hall on cartesium, 2 chains
    rep = dg.convergence({"n_hall": stuck}, rhat_max=1.01, ess_min=10)
    assert not rep.ok and "infinite" in rep.quantities[0].reason


def test_shape_mismatch_is_refused():
    with pytest.raises(ValueError):
        dg.convergence({"a": np.zeros((4, 10)), "b": np.zeros((3, 10))}, rhat_max=1.01, ess_min=1)


def test_trace_round_trip(tmp_path):
    rng = np.random.default_rng(4)
    tree = dg.to_datatree({"log_posterior": mixing_chains(rng, 2, 50)},
                          sample_stats={"accept_add": rng.random((2, 50))}, attrs={"map": "x.yaml"})
    path = dg.write_trace(tree, tmp_path / "trace.nc")
    back = dg.read_trace(path)
    np.testing.assert_allclose(back["posterior"]["log_posterior"].values,
                               tree["posterior"]["log_posterior"].values)
    rep = dg.convergence(back, rhat_max=1.1, ess_min=10)
    assert rep.n_chains == 2 and rep.n_draws == 50
    assert [p.name for p in tmp_path.iterdir()] == ["trace.nc"]  # no temporary file left


def test_read_trace_errors_are_one_line(tmp_path):
    with pytest.raises(SemmapError, match="no trace file"):
        dg.read_trace(tmp_path / "missing.nc")
    bad = tmp_path / "bad.nc"
    bad.write_bytes(b"not hdf5 at all")
    with pytest.raises(SemmapError) as exc:
        dg.read_trace(bad)
    assert "\n" not in str(exc.value) and "bad.nc" in str(exc.value)


def test_spread_accumulator_counts_types():
    acc = dg.SpreadAccumulator((2, 2))
    acc.add(np.array([[1, 0], [0, 0]], bool), np.array([[0, 0], [1, -1]]))
    acc.add(np.array([[1, 0], [0, 1]], bool), np.array([[0, 2], [1, -1]]))
    assert acc.p_wall().tolist() == [[1.0, 0.0], [0.0, 0.5]]
    assert acc.p_type()[2].tolist() == [[0.0, 0.5], [0.0, 0.0]]
    # cells ever wall: (0,0) with p=1 (variance 0) and (1,1) with p=0.5 (variance 0.25)
    assert acc.wall_spread() == pytest.approx(0.125)


def test_the_report_gives_each_chains_mean():
    """Two chains settled in different modes: the per-chain means say which is where (the text
    table and the JSON), while the pooled mean hides it."""
    rng = np.random.default_rng(5)
    a = mixing_chains(rng, chains=2, draws=50)
    a[1] -= 100.0
    units = np.repeat(np.array([[20.0], [15.0]]), 50, axis=1)
    rep = dg.convergence({"log_posterior": a, "n_units": units}, rhat_max=1.05, ess_min=10)
    lp, n = rep.quantities
    assert lp.chain_means == pytest.approx((a[0].mean(), a[1].mean()))
    assert n.chain_means == (20.0, 15.0) and n.mean == 17.5
    assert rep.to_dict()["quantities"]["n_units"]["chain_means"] == [20.0, 15.0]
    text = rep.to_text()
    assert "mean per chain" in text
    assert text.splitlines()[-1].split() == ["n_units", "20", "15"]
    single = dg.convergence({"n_units": units[:1]}, rhat_max=1.05, ess_min=10)
    assert "mean per chain" not in single.to_text()      # one chain: nothing to compare


def test_chains_in_separate_modes_are_named():
    """A chain whose mean log posterior lies far below the best chain's, measured in the chains' own
    standard deviations, is named (text line and JSON); chains that mix, or differ by less than
    SEPARATION_SDS of their spread, are not."""
    rng = np.random.default_rng(7)
    a = mixing_chains(rng, chains=3, draws=200)          # unit-scale chains that mix
    rep = dg.convergence({"log_posterior": a}, rhat_max=1.05, ess_min=10)
    assert rep.separated_chains() == [] and rep.separation_note() == ""
    assert rep.to_dict()["separated_chains"] == []
    far = a.copy()
    far[0] -= 50.0                                        # chain 1 far below chains 2 and 3
    far[2] -= 2.0 * far[2].std()                          # chain 3 a little below: not separated
    rep = dg.convergence({"log_posterior": far}, rhat_max=1.05, ess_min=10)
    best = 1 + int(np.argmax(far.mean(axis=1)))
    assert best == 2
    (c, gap), = rep.separated_chains()
    assert c == 1 and gap == pytest.approx(far[1].mean() - far[0].mean(), abs=0.05)
    note = rep.separation_note()
    assert note.startswith("chains in separate modes: chain 1's mean log posterior lies") and "chain 2's" in note
    assert note in rep.to_text().splitlines()
    assert rep.to_dict()["separated_chains"] == [{"chain": 1, "log_posterior_below_best": round(gap, 1)}]
    # the threshold scales with the chains' own spread: a gap of 30 separates chains of sd 1, not
    # chains of sd 10
    for scale, separated in ((1.0, [1]), (10.0, [])):
        b = a * scale
        b[0] -= 30.0
        rep = dg.convergence({"log_posterior": b}, rhat_max=1.05, ess_min=10)
        assert [c for c, _ in rep.separated_chains()] == separated
    # chains stuck at constant values: separated when the means differ by more than 4 nats
    stuck = np.repeat(np.array([[-100.0], [-103.0], [-110.0]]), 20, axis=1)
    rep = dg.convergence({"log_posterior": stuck}, rhat_max=1.05, ess_min=10)
    assert rep.separated_chains() == [(3, 10.0)]
    # without a log posterior summary, or with one chain, nothing to say
    assert dg.convergence({"n_units": stuck}, rhat_max=1.05, ess_min=10).separated_chains() == []
    assert dg.convergence({"log_posterior": stuck[:1]}, rhat_max=1.05, ess_min=10).separated_chains() == []


def mser_brute_force(x, gain=dg.WARMUP_GAIN):
    """The MSER cut written out: every d <= n // 2, the rest's squared standard error of the mean."""
    n = len(x)
    se = [np.sum((x[d:] - np.mean(x[d:])) ** 2) / (n - d) ** 2 for d in range(n // 2 + 1)]
    return next(d for d, v in enumerate(se) if v <= min(se) * gain + 1e-300)


def test_warmup_draws_is_the_mser_cut():
    rng = np.random.default_rng(7)
    for n in (4, 5, 25, 60):
        for k in range(40):
            climb = np.r_[np.linspace(-rng.uniform(0, 50), 0, rng.integers(1, n)), np.zeros(n)][:n]
            x = -777_000.0 + climb + rng.normal(scale=rng.uniform(0.1, 5.0), size=n)
            assert dg.warmup_draws(x) == mser_brute_force(x), (n, k)
    assert dg.warmup_draws([1.0, 2.0, np.nan, 3.0, 4.0]) == 0 and dg.warmup_draws([5.0, 0.0, 0.0]) == 0


def test_warmup_draws_cuts_a_climb_and_leaves_a_stationary_chain():
    rng = np.random.default_rng(8)
    climb = np.r_[np.linspace(-400.0, -20.0, 10), np.zeros(40)] + rng.normal(size=50)
    assert 9 <= dg.warmup_draws(climb) <= 11
    # stationary traces keep their draws: 12 of 2,000 white-noise traces of 25 draws lose some
    cut = [dg.warmup_draws(rng.normal(size=25)) for _ in range(2000)]
    assert sum(c > 0 for c in cut) < 40


def test_within_mode_leaves_out_other_modes_climbing_draws_and_constant_summaries():
    rng = np.random.default_rng(9)
    lp = rng.normal(size=(3, 60))
    lp[0, :12] += np.linspace(-300.0, -30.0, 12)     # chain 1 still climbing in its first 12 draws
    lp[1] -= 5_000.0                                  # chain 2 in another mode
    n_units = np.full((3, 60), 20.0)
    n_units[1] = 15.0                                 # constant in chains 1 and 3, not in all
    rep = dg.convergence({"log_posterior": lp, "n_units": n_units}, rhat_max=1.1, ess_min=50)
    m = rep.within_mode
    assert m.chains == (1, 3) and 11 <= m.first_draw <= 13
    assert [q.name for q in m.quantities] == ["log_posterior"] and m.constant == (("n_units", 20.0),)
    q = m.quantities[0]
    rest = lp[[0, 2], m.first_draw:]
    assert q.mean == pytest.approx(rest.mean()) and q.sd == pytest.approx(rest.std())
    assert m.ok and m.ess >= 50 and not rep.ok       # mixed within the mode, not converged overall
    assert rep.shows_mode()
    text = rep.to_text()
    assert "within the best chain's mode (chains 1, 3, draws" in text and "constant there: n_units 20" in text
    assert any(line.startswith("mixed within the mode (smallest ESS") for line in text.splitlines())
    d = rep.to_dict()["within_mode"]
    assert d["chains"] == [1, 3] and d["first_draw"] == m.first_draw and d["constant"] == {"n_units": 20.0}


def test_a_mode_over_every_chain_from_the_first_draw_reuses_the_whole_diagnostics(monkeypatch):
    """Well-mixed chains: the mode is every chain, nothing cut, so the within-mode quantities are
    the report's own (ArviZ runs once per summary) and equal what a second run would give."""
    rng = np.random.default_rng(4)
    s = {"log_posterior": mixing_chains(rng), "n_units": rng.integers(3, 9, (4, 400)).astype(float)}
    calls = []
    real = dg._diagnose_one
    monkeypatch.setattr(dg, "_diagnose_one", lambda *a: calls.append(a[0]) or real(*a))
    rep = dg.convergence(s, rhat_max=1.01, ess_min=200)
    m = rep.within_mode
    assert m.chains == (1, 2, 3, 4) and m.first_draw == 0
    assert calls == ["log_posterior", "n_units"]
    assert m.quantities == rep.quantities
    again = [real(q.name, s[q.name], 1.01, 200) for q in rep.quantities]
    assert [(q.rhat, q.ess_bulk, q.ess_tail) for q in again] == [(q.rhat, q.ess_bulk, q.ess_tail)
                                                                  for q in m.quantities]


def test_within_mode_with_nothing_moving_is_not_mixed_and_one_chain_uses_its_halves():
    frozen = dg.convergence({"log_posterior": np.full((2, 30), -10.0)}, rhat_max=1.05, ess_min=10)
    assert not frozen.within_mode.ok and frozen.within_mode.quantities == ()
    assert "no summary moved" in frozen.within_mode.verdict()
    rng = np.random.default_rng(10)
    one = dg.convergence({"log_posterior": rng.normal(size=(1, 400))}, rhat_max=1.05, ess_min=100)
    assert one.ok and np.isfinite(one.quantities[0].rhat)       # ArviZ alone gives NaN for one chain
    trend = dg.convergence({"log_posterior": np.linspace(0.0, 50.0, 400)[None] + rng.normal(size=(1, 400))},
                           rhat_max=1.05, ess_min=100)
    assert not trend.ok and trend.quantities[0].rhat > 1.05
    plain = dg.convergence({"log_posterior": rng.normal(size=(2, 100))}, rhat_max=1.05, ess_min=10)
    assert not plain.shows_mode() and "within the best chain's mode" not in plain.to_text()


def test_chains_each_constant_at_their_own_value_give_an_infinite_rhat():
    """ArviZ returns a huge finite number here (rank normalisation); the report says infinite."""
    a = np.r_[np.full(20, -777_734.6), np.full(20, -777_735.1)].reshape(2, 20)
    q = dg.convergence({"log_posterior": a}, rhat_max=1.05, ess_min=10).quantities[0]
    assert q.rhat == np.inf and "each chain stuck at its own value" in q.reason


def test_a_chain_that_jumped_once_has_an_infinite_rhat_not_twenty_digits():
    # chain 1 at 0 throughout, chain 2 at 1 then at 0 from its middle: every half-chain is
    # constant, so split R-hat has no variance within; ArviZ returns a huge finite number
    # (3.0e15), which the tables printed in twenty digits
    a = np.zeros((2, 200))
    a[1, :100] = 1.0
    q = dg.convergence({"n_other": a}, rhat_max=1.05, ess_min=100).quantities[0]
    assert q.rhat == np.inf and "a chain jumped once" in q.reason and not q.ok
    assert dg.format_rhat(3017531479833410.5) == "3.02e+15" and dg.format_rhat(1.01234) == "1.012"


def ar1(rng, phi, n, burn=2000):
    x = np.zeros(n + burn)
    e = rng.normal(size=n + burn)
    for i in range(1, n + burn):
        x[i] = phi * x[i - 1] + e[i]
    return x[burn:]


def staircase(rng, n, steps=12, height=40.0):
    """A chain that takes nearly every step up and few down: plateaus of jitter, jumps up at random
    draws (what cartesium's chains do at T = 1, docs/sampler.md "Chains that climb")."""
    jumps = np.zeros(n)
    jumps[rng.choice(np.arange(1, n), steps, replace=False)] = rng.exponential(height, steps)
    return np.cumsum(jumps) + 0.5 * rng.normal(size=n)


def test_a_climbing_chain_is_named_and_more_draws_are_not_promised_to_steady_it():
    rng = np.random.default_rng(12)
    lp = np.stack([staircase(rng, 600), staircase(rng, 600)]) - 7.8e5
    rep = dg.convergence({"log_posterior": lp}, rhat_max=1.05, ess_min=100, draws_option="--spread-draws")
    m = rep.within_mode
    assert not m.ok and [c for c, _ in m.climbing] == [1, 2]
    for c, rise in m.climbing:
        x = lp[c - 1, m.first_draw:]
        q = np.array_split(x, 4)
        assert rise == pytest.approx(q[-1].mean() - q[0].mean(), abs=0.06) and rise > 0
    verdict = m.verdict()
    assert "chains 1, 2 still climbing" in verdict and "climb further rather than steady them" in verdict
    assert "may steady" not in verdict and "(--spread-draws)" in verdict
    assert rep.to_dict()["within_mode"]["climbing"] == [{"chain": c, "rise": r} for c, r in m.climbing]
    assert verdict in rep.to_text()


def test_stationary_chains_are_not_called_climbing():
    """White noise of 25 draws or more never (of 8, 2.6 % of 4000 traces); a sticky stationary chain
    (AR(1), phi up to 0.999) of 400 draws at most once in 200 (of 25 draws, the search's default,
    it can look like a climb: measured 4-11 %)."""
    rng = np.random.default_rng(13)
    assert all(dg.climb(5.0 * rng.normal(size=n)) == 0.0 for n in (25, 400) for _ in range(500))
    for phi in (0.9, 0.99, 0.999):
        flagged = 0
        for _ in range(200):
            x = ar1(rng, phi, 400)
            flagged += dg.climb(x[dg.warmup_draws(x):]) > 0
        assert flagged <= 1, (phi, flagged)
    rep = dg.convergence({"log_posterior": np.stack([ar1(rng, 0.99, 400), ar1(rng, 0.99, 400)])},
                         rhat_max=1.05, ess_min=1000)
    assert rep.within_mode.climbing == () and rep.within_mode.verdict().endswith(
        '(--draws) may steady them (docs/sampler.md, "Chains that climb")')


def test_climb_needs_the_whole_trace_to_rise():
    up = np.repeat([0.0, 5.0, 9.0, 20.0], 10)
    assert dg.climb(up) == 20.0
    assert dg.climb(up[::-1]) == 0.0                              # falling
    assert dg.climb(np.concatenate([up, up])) == 0.0              # up, back down, up again
    assert dg.climb(np.repeat([0.0, 0.3, 0.6, 0.9], 10)) == 0.0   # less than CLIMB_MIN_NATS
    assert dg.climb(up[:7]) == 0.0 and dg.climb(np.r_[up, np.nan]) == 0.0


def test_the_default_thresholds_are_vehtari_et_al_2021s():
    from semmap_pp.model import load_model

    d = load_model().diagnostics
    assert (d.rhat_max, d.ess_min) == (1.01, 400)


def test_a_failing_verdict_names_the_quantity_the_summaries_and_a_remedy():
    """Chains apart on the log posterior only: R-hat fails there, not on n_units; every summary's
    ESS is short of 400, split into bulk and tail; for chains apart it names replica exchange as
    measured not to join them, and the seeds' comparison (with --tempered already on: a longer
    ladder)."""
    rng = np.random.default_rng(5)
    lp = rng.normal(size=(2, 200))
    lp[1] += 6.0
    rep = dg.convergence({"log_posterior": lp, "n_units": rng.normal(size=(2, 200))}, rhat_max=1.01, ess_min=400)
    failed = rep.failed()
    parts = dict(p.split(" on ", 1) for p in failed.split("; "))
    assert "log_posterior" in parts["R-hat > 1.01"] and "n_units" not in parts["R-hat > 1.01"]
    assert "log_posterior" in parts["bulk ESS < 400"]
    lp_q = rep.quantities[0]
    assert f"log_posterior ({dg.format_rhat(lp_q.rhat)})" in parts["R-hat > 1.01"]
    assert f"log_posterior ({lp_q.ess_bulk:.0f})" in parts["bulk ESS < 400"]
    assert "--tempered" in rep.remedy() and "--rungs" not in rep.remedy()
    assert "none measured does yet" in rep.remedy() and "semmap stability" in rep.remedy()
    tempered = dataclasses.replace(rep, tempered=True)
    assert "--rungs" in tempered.remedy() and "`semmap map --tempered`" not in tempered.remedy()
    text = rep.to_text().splitlines()
    i = text.index("NOT converged")
    assert text[i + 1] == f"failed: {failed}" and text[i + 2] == f"to fix: {rep.remedy()}"
    assert "bulk ESS" in lp_q.reason and "R-hat" in lp_q.reason


def test_an_ess_short_verdict_asks_for_the_draws_that_ess_needs():
    """Chains that agree (R-hat passes at 1.1) but with too few draws for ESS 400: the remedy is
    more draws, about 400 / ESS times as many, with the option that lengthens these chains."""
    rng = np.random.default_rng(6)
    rep = dg.convergence({"log_posterior": rng.normal(size=(2, 60))}, rhat_max=1.1, ess_min=400,
                         draws_option="--spread-draws")
    assert not rep.ok and "R-hat" not in rep.failed()
    q = rep.quantities[0]
    low = min(q.ess_bulk, q.ess_tail)
    n = math.ceil(60 * 400 / low)
    assert rep.remedy() == f"about {400 / low:,.0f} times as many draws (--spread-draws {n}) for ESS 400"


def test_a_passing_verdict_has_no_failure_or_remedy():
    rng = np.random.default_rng(7)
    rep = dg.convergence({"log_posterior": rng.normal(size=(4, 400))}, rhat_max=1.05, ess_min=100)
    assert rep.ok and rep.failed() == "" and rep.remedy() == ""
    assert "\nconverged" in rep.to_text() and "failed:" not in rep.to_text()


def test_chains_that_never_moved_are_not_told_to_draw_more():
    frozen = dg.convergence({"log_posterior": np.full((2, 8), -10.0), "n_units": np.full((2, 8), 3.0)},
                            rhat_max=1.01, ess_min=400)
    assert not frozen.ok and "no summary moved" in frozen.remedy() and "times as many draws" not in frozen.remedy()
