"""Replica exchange (semmap_pp/sampler/replicas.py): detailed balance of the swaps on enumerated
tiny worlds under the project's own tempered Posterior, invariance of the joint chain (every
rung's kernels, then a round of swaps) built from the kernels' enumerations, and the cold rung of
the PyMC step sampling the cold target."""

import itertools
import math

import numpy as np
import pytest
from scipy import sparse
from scipy.sparse import csgraph

from semmap_pp import cells
from semmap_pp import world as wm
from semmap_pp.lattice.frame import build_frame_from_classes
from semmap_pp.model import load_model
from semmap_pp.sampler import replicas as rp
from semmap_pp.sampler.kernels import build_data, default_mix
from semmap_pp.sampler.kernels.common import world_key
from semmap_pp.target.posterior import Posterior
from semmap_pp.target.tempering import tempered
from test_kernels_balance import SETTINGS, all_states, tiny_classes, transition_matrix


def tiny_posterior():
    """The project's Posterior on a 7 x 8 lattice at 0.25 m (units of 5..7 x 5..8 cells)."""
    model = load_model()
    c = np.full((7, 8), cells.FREE, np.uint8)
    c[0, :] = c[:, 0] = cells.OCCUPIED
    c[:, 6] = cells.OCCUPIED
    c[3, 6] = cells.FREE
    c[5, 2] = cells.UNKNOWN
    frame = build_frame_from_classes(c, 0.25, model, theta=0.0)
    assert frame.shape == (7, 8)
    return Posterior(frame, model), frame


def lattice_states(frame, capacity):
    lo, (h, w) = frame.cells.min_side, frame.shape
    rects = [(r0, c0, r0 + a, c0 + b) for a in range(lo, h + 1) for b in range(lo, w + 1)
             for r0 in range(h - a + 1) for c0 in range(w - b + 1)]
    return [wm.make([r or (0, 0, 0, 0) for r in choice], [r is not None for r in choice], [-1] * capacity)
            for choice in itertools.product([None] + rects, repeat=capacity)]


def test_swaps_keep_the_product_of_the_rungs_targets_in_detailed_balance():
    post, frame = tiny_posterior()
    states = lattice_states(frame, 2)
    assert len(states) > 300
    ladder = rp.geometric_ladder(0.7, 3, 0.3)
    posts = [tempered(post, b) for b in ladder]
    trackers = [[p.start(s) for s in states] for p in posts]
    logpi = np.array([[p.evaluate(s).total for s in states] for p in posts])
    rng = np.random.default_rng(0)
    pairs = rng.integers(len(states), size=(4000, 2))
    checked = 0
    for i in range(len(ladder) - 1):
        for x, y in pairs:
            # rung i holds x, rung i+1 holds y; the swap gives rung i y and rung i+1 x
            fwd = rp.swap_log_ratio(trackers[i][x], trackers[i + 1][y])
            back = rp.swap_log_ratio(trackers[i][y], trackers[i + 1][x])
            before = logpi[i, x] + logpi[i + 1, y]
            after = logpi[i, y] + logpi[i + 1, x]
            if before == -math.inf or after == -math.inf:
                continue
            # pi(x, y) min(1, e^fwd) = pi(y, x) min(1, e^back), with fwd = after - before exactly
            assert fwd == pytest.approx(after - before, abs=1e-9 * max(1.0, abs(before)))
            assert back == pytest.approx(-fwd, abs=1e-9 * max(1.0, abs(before)))
            lhs = before + min(0.0, fwd)
            rhs = after + min(0.0, back)
            assert lhs == pytest.approx(rhs, abs=1e-9 * max(1.0, abs(lhs)))
            checked += 1
    assert checked > 4000


def test_an_accepted_swap_moves_the_worlds_and_retargets_the_trackers():
    post, frame = tiny_posterior()
    states = lattice_states(frame, 1)
    posts = [tempered(post, b) for b in (1.0, 0.2)]
    a, b = posts[0].start(states[5]), posts[1].start(states[40])
    reps = [a, b]
    rng = np.random.default_rng(1)
    for _ in range(200):
        before = [r.world for r in reps]
        if rp.try_swap(rng, reps, 0):
            break
    assert reps[0] is b and reps[1] is a and reps[0].post is posts[0] and reps[1].post is posts[1]
    assert [r.world for r in reps] == before[::-1]
    for r, p in zip(reps, posts):
        assert r.logp == pytest.approx(p.evaluate(r.world).total, rel=1e-12)


class _TableTracker:
    """A tracker of a tempered table target: ``log pi_b(s) = b ell[s] + prior[s]``."""

    def __init__(self, ell, prior, beta, state):
        self.ell, self.prior, self.state = ell, prior, state
        self.post = beta
        self.loglik, self.logprior = beta * ell[state], prior[state]
        self.logp = self.loglik + self.logprior

    def loglik_under(self, beta):
        return beta * self.ell[self.state]

    def retarget(self, beta):
        self.post, self.loglik = beta, beta * self.ell[self.state]
        self.logp = self.loglik + self.logprior


def swap_round_matrix(ell, prior, ladder, n, n_swaps, ratio=rp.swap_log_ratio, temps=None):
    """The exact transition matrix of :func:`replicas.swap_round` over joint states (one state
    index per rung), from the acceptance :func:`replicas.swap_log_ratio` gives."""
    k = len(ladder)
    joint = list(itertools.product(range(n), repeat=k))
    index = {s: i for i, s in enumerate(joint)}
    rows, cols, vals = [], [], []
    for s in joint:
        for i in range(k - 1):
            a = _TableTracker(ell, prior, ladder[i], s[i])
            b = _TableTracker(ell, prior, ladder[i + 1], s[i + 1])
            r = ratio(a, b) if temps is None else ratio(a, b, temps[i], temps[i + 1])
            acc = math.exp(min(0.0, r)) / (k - 1)
            t = list(s)
            t[i], t[i + 1] = t[i + 1], t[i]
            rows.append(index[s]), cols.append(index[tuple(t)]), vals.append(acc)
    one = sparse.coo_matrix((vals, (rows, cols)), shape=(len(joint),) * 2).tocsr()
    one = one + sparse.diags(1.0 - np.asarray(one.sum(axis=1)).ravel())
    out = sparse.identity(len(joint), format="csr")
    for _ in range(n_swaps):
        out = out @ one
    return out, joint


def joint_chain(ladder, n_inner=2, n_swaps=2, ratio=rp.swap_log_ratio, seed=5, temps=None):
    """Tiny kernel worlds (3 x 4 lattice, one slot): the exact matrices of a draw of the joint
    chain, every rung's ``n_inner`` kernels of the default mix then ``n_swaps`` swaps."""
    data = build_data(tiny_classes((3, 4)), min_side=2, wall_cells=1, max_side=3, door_min=1,
                      door_max=1, settings=SETTINGS)
    states = all_states(data, 1)
    rng = np.random.default_rng(seed)
    ell = rng.normal(0.0, 3.0, len(states))
    prior = rng.normal(0.0, 1.0, len(states))
    mix = default_mix(SETTINGS)
    kernels = []
    heat = temps if temps is not None else (1.0,) * len(ladder)
    for b, t in zip(ladder, heat):      # MH at temperature t: the rung's target to the power 1/t
        p, _ = transition_matrix(states, data, mix, (b * ell + prior) / t)
        pk = sparse.identity(len(states), format="csr")
        for _ in range(n_inner):
            pk = pk @ p
        kernels.append(pk)
    moves = kernels[0]
    for pk in kernels[1:]:
        moves = sparse.kron(moves, pk, format="csr")     # the rungs move independently
    swaps, joint = swap_round_matrix(ell, prior, ladder, len(states), n_swaps, ratio, temps)
    logpi = np.array([sum((b * ell[s[i]] + prior[s[i]]) / heat[i] for i, b in enumerate(ladder)) for s in joint])
    pi = np.exp(logpi - logpi.max())
    return moves, swaps, pi / pi.sum(), states, joint


@pytest.mark.parametrize("ladder", [(1.0, 0.3), (0.8, 0.4, 0.1)])
def test_the_joint_chain_leaves_the_product_target_invariant(ladder):
    moves, swaps, pi, states, joint = joint_chain(ladder)
    assert len(states) == 16 and len(joint) == 16 ** len(ladder)
    for p in (moves, swaps):   # each part is reversible with respect to the product target
        flow = sparse.diags(pi) @ p
        assert abs(flow - flow.T).max() <= 1e-12 * abs(flow).max()
    draw = moves @ swaps
    assert np.max(np.abs(pi @ draw - pi)) < 1e-12 * pi.max()
    assert csgraph.connected_components(draw, directed=True, connection="strong")[0] == 1
    # swaps do move worlds between rungs
    off = swaps - sparse.diags(swaps.diagonal())
    assert off.sum() > 0.05 * len(joint)


@pytest.mark.parametrize("ladder, temps", [((1.0, 1.0), (1.0, 3.0)), ((0.8, 0.4, 0.1), (1.0, 2.0, 4.0))])
def test_rungs_at_temperatures_keep_the_product_of_their_heated_targets_invariant(ladder, temps):
    """Rungs whose kernels run at temperature T (the prior flattened too, not only the
    likelihood): swaps with the full log ratio leave the product of ``π_k^(1/T_k)`` invariant."""
    moves, swaps, pi, states, joint = joint_chain(ladder, temps=temps)
    for p in (moves, swaps):
        flow = sparse.diags(pi) @ p
        assert abs(flow - flow.T).max() <= 1e-12 * abs(flow).max()
    draw = moves @ swaps
    assert np.max(np.abs(pi @ draw - pi)) < 1e-12 * pi.max()
    off = swaps - sparse.diags(swaps.diagonal())
    assert off.sum() > 0.05 * len(joint)


def test_a_heated_swap_that_leaves_out_the_prior_breaks_the_invariance():
    """The likelihood-only ratio is wrong once the prior is heated too: the check catches it."""
    moves, swaps, pi, _, _ = joint_chain((1.0, 0.5), temps=(1.0, 3.0), n_swaps=1,
                                         ratio=lambda a, b, ti=1.0, tj=1.0: rp.swap_log_ratio(a, b))
    assert np.max(np.abs(pi @ (moves @ swaps) - pi)) > 1e-4 * pi.max()


def test_a_wrong_swap_ratio_breaks_the_invariance():
    """The check above can fail: a swap ratio with the exponents' difference of the wrong sign."""
    moves, swaps, pi, _, _ = joint_chain((1.0, 0.3), ratio=lambda a, b: -rp.swap_log_ratio(a, b))
    draw = moves @ swaps
    assert np.max(np.abs(pi @ draw - pi)) > 1e-4 * pi.max()


@pytest.mark.parametrize("temps", [None, (1.0, 2.0, 4.0)])
def test_the_cold_rung_of_the_step_samples_the_cold_target(temps):
    """The PyMC step with three rungs (kernels on every rung, swaps, the cold rung recorded) on the
    project's tempered Posterior, the hot rungs also heated or not: the recorded worlds'
    frequencies match the cold target's enumerated probabilities (chi-square on the total unit
    area)."""
    from scipy import stats

    from semmap_pp.sampler.kernels import data_from_frame
    from semmap_pp.sampler.sampling import sample_worlds
    from test_mcmc import ess

    post, frame = tiny_posterior()
    states = lattice_states(frame, 2)
    ladder = (0.05, 0.02, 0.008)
    cold = tempered(post, ladder[0])
    logpi = np.array([cold.evaluate(s).total for s in states])
    pi = np.exp(logpi - logpi.max())
    pi /= pi.sum()
    area = lambda w: int(sum((r[2] - r[0]) * (r[3] - r[1]) for r, a in zip(w.rects, w.active) if a))
    keys = sorted({area(s) for s in states})
    expect = np.zeros(len(keys))
    for s, p in zip(states, pi):
        expect[keys.index(area(s))] += p
    res = sample_worlds(post, data_from_frame(frame), [wm.empty(2)], draws=3000, tune=50, chains=1,
                        cores=1, n_inner=4, seed=3, ladder=ladder, swaps=2, temperatures=temps)
    rec = res.records[0]
    assert np.all(rec.stats["beta"] == ladder[0])
    assert np.nanmean(rec.stats["swap_accept"]) > 0.05
    seen = [area(wm.make(r, a, [-1, -1])) for r, a in zip(rec.rects, rec.active)]
    obs = np.bincount([keys.index(v) for v in seen], minlength=len(keys)).astype(float)
    n_eff = ess(seen)
    assert n_eff > 150
    keep = expect * len(seen) >= 5
    obs_k = np.append(obs[keep], obs[~keep].sum())
    exp_k = np.append(expect[keep], expect[~keep].sum()) * len(seen)
    scale = n_eff / len(seen)
    assert stats.chisquare(obs_k * scale, exp_k * scale).pvalue > 1e-3
    # the recorded log posterior is the untempered one
    last = wm.make(rec.rects[-1], rec.active[-1], [-1, -1])
    assert rec.stats["logp"][-1] == pytest.approx(post.evaluate(last).total, rel=1e-9)
