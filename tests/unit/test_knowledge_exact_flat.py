"""The compiled junction-tree calibration (exact.calibrate_flat) equals the numpy one
(exact.calibrate + scope_marginal) and brute-force enumeration."""

import itertools

import numpy as np
import pytest

from semmap_pp.knowledge.exact import JunctionTree, calibrate, calibrate_flat, scope_marginal


def _random_network(rng, n, p_edge, cards=(2, 3, 4), p_inf=0.0):
    card = [int(rng.choice(cards)) for _ in range(n)]
    pots = [((i,), rng.normal(size=card[i])) for i in range(n)]
    for i, j in itertools.combinations(range(n), 2):
        if rng.random() < p_edge:
            t = rng.normal(size=(card[i], card[j])) * 2
            t[rng.random(t.shape) < p_inf] = -np.inf
            pots.append(((i, j), t))
    if n >= 3 and rng.random() < 0.5:   # a three-variable factor now and then
        s = tuple(sorted(rng.choice(n, 3, replace=False).tolist()))
        pots.append((s, rng.normal(size=tuple(card[v] for v in s))))
    return card, pots


def _log_enumerate(card, pots):
    """The log potential of every joint state (axes in variable order)."""
    logp = np.zeros(card)
    for s, t in pots:
        shape = [1] * len(card)
        for v, k in zip(s, t.shape):
            shape[v] = k
        logp = logp + t.reshape(shape)
    return logp


def _enumerate(card, pots):
    logp = _log_enumerate(card, pots)
    m = logp.max()
    p = np.exp(logp - m)
    return float(np.log(p.sum()) + m), p / p.sum()


@pytest.mark.parametrize("seed", range(40))
def test_flat_calibration_equals_numpy_and_enumeration(seed):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(1, 8))
    card, pots = _random_network(rng, n, p_edge=float(rng.uniform(0.1, 0.7)),
                                 p_inf=0.15 if seed % 3 == 0 else 0.0)
    scopes = [s for s, _ in pots]
    jt = JunctionTree(card, scopes)
    want = [f for f, s in enumerate(scopes) if len(s) >= 2]
    log_z, marg, joint = calibrate_flat(jt.plan(scopes), [t for _, t in pots], want)
    ref_z, ref_marg, full = calibrate(jt, pots, return_beliefs=True)
    brute_z, p = _enumerate(card, pots)
    if not np.isfinite(brute_z):
        assert marg is None and not np.isfinite(log_z)
        return
    assert abs(log_z - ref_z) <= 1e-9 and abs(log_z - brute_z) <= 1e-9
    for v in range(n):
        axes = tuple(a for a in range(n) if a != v)
        assert np.abs(marg[v] - ref_marg[v]).max() <= 1e-12
        assert np.abs(marg[v] - p.sum(axis=axes)).max() <= 1e-9
    for f, pm in zip(want, joint):
        s = scopes[f]
        assert pm.shape == tuple(card[v] for v in s)
        assert np.abs(pm - scope_marginal(jt, full, s)).max() <= 1e-12
        axes = tuple(a for a in range(n) if a not in s)
        assert np.abs(pm - p.sum(axis=axes)).max() <= 1e-9


def test_flat_calibration_reports_an_impossible_network():
    card = [2, 2]
    pots = [((0,), np.zeros(2)), ((1,), np.zeros(2)), ((0, 1), np.full((2, 2), -np.inf))]
    jt = JunctionTree(card, [s for s, _ in pots])
    log_z, marg, joint = calibrate_flat(jt.plan([s for s, _ in pots]), [t for _, t in pots], [2])
    assert log_z == -np.inf and marg is None and joint == []


def test_plan_is_cached_per_scope_list():
    scopes = [(0,), (1,), (0, 1)]
    jt = JunctionTree([3, 2], scopes)
    assert jt.plan(scopes) is jt.plan(list(scopes))
    assert jt.plan(scopes[:2] + [(0, 1), (0,)]) is not jt.plan(scopes)


def test_flat_calibration_of_an_empty_network():
    jt = JunctionTree([], [])
    log_z, marg, joint = calibrate_flat(jt.plan([]), [], [])
    assert log_z == 0.0 and marg == [] and joint == []


def _wide_network(rng, n):
    """A chain-and-triangle network whose log tables span thousands of nats, so some clique's
    finite entries lie more than exact._EXP_RANGE below its maximum."""
    card = [int(rng.choice((2, 3, 4))) for _ in range(n)]
    pots = [((i,), rng.normal(size=card[i]) * 400.0) for i in range(n)]
    for i in range(n - 1):
        pots.append(((i, i + 1), rng.normal(size=(card[i], card[i + 1])) * 400.0))
    for i in range(0, n - 2, 2):
        s = (i, i + 1, i + 2)
        pots.append((s, rng.normal(size=tuple(card[v] for v in s)) * 400.0))
    return card, pots


@pytest.mark.parametrize("seed", range(12))
def test_calibration_of_cliques_spanning_thousands_of_nats(seed, monkeypatch):
    """calibrate exponentiates a clique once for all its children when its finite entries lie
    within _EXP_RANGE of their maximum, and takes log-sum-exp per child otherwise: both give
    log Z, the marginals and every finite calibrated belief (the log joint mass of a clique
    state, here enumerated), where one shared exp(x - max) would underflow to -inf."""
    from semmap_pp.knowledge import exact
    rng = np.random.default_rng(100 + seed)
    n = int(rng.integers(4, 8))
    card, pots = _wide_network(rng, n)
    jt = JunctionTree(card, [s for s, _ in pots])
    logp = _log_enumerate(card, pots)
    top = logp.max()
    brute_z = float(np.log(np.exp(logp - top).sum()) + top)
    log_z, marg, full = calibrate(jt, pots, return_beliefs=True)
    assert abs(log_z - brute_z) <= 1e-9 * abs(brute_z)
    p = np.exp(logp - top)
    p /= p.sum()
    for v in range(n):
        assert np.abs(marg[v] - p.sum(axis=tuple(a for a in range(n) if a != v))).max() <= 1e-9
    spans = []
    for i, ax in enumerate(jt.axes):
        others = tuple(a for a in range(n) if a not in ax)
        mx = logp.max(axis=others, keepdims=True)
        ref = np.log(np.exp(logp - mx).sum(axis=others, keepdims=True)) + mx
        ref = ref.reshape(tuple(card[a] for a in sorted(ax)))
        ref = np.transpose(ref, np.argsort(np.argsort(ax)))   # axes in clique order
        assert np.isfinite(full[i]).all()
        assert np.allclose(full[i], ref, rtol=1e-9, atol=1e-6)
        spans.append(float(full[i].max() - full[i].min()))
    assert max(spans) > exact._EXP_RANGE     # the per-child path was taken somewhere
    monkeypatch.setattr(exact, "_EXP_RANGE", 0.0)   # every clique by log-sum-exp per child
    z2, marg2, full2 = calibrate(jt, pots, return_beliefs=True)
    assert abs(z2 - log_z) <= 1e-12 * abs(log_z)
    for v in range(n):
        assert np.abs(marg2[v] - marg[v]).max() <= 1e-12
    for a, b in zip(full, full2):
        assert np.allclose(a, b, rtol=1e-12, atol=1e-9)
