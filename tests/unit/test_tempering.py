"""The tempered likelihood: exact scaling of the target, trackers moved between rungs, and the
correlation area that sets the likelihood's exponent (semmap_pp/target/tempering.py)."""

import dataclasses

import numpy as np
import pytest

from semmap_pp import cells
from semmap_pp import world as wm
from semmap_pp.lattice.frame import build_frame_from_classes
from semmap_pp.model import load_model
from semmap_pp.sampler.kernels import data_from_frame, default_mix
from semmap_pp.sampler.mcmc import run_chain
from semmap_pp.target.posterior import Posterior
from semmap_pp.target.tempering import correlation_area, likelihood_exponent, tempered


def two_rooms(model):
    c = np.full((60, 80), cells.UNKNOWN, np.uint8)
    c[4:56, 4:76] = cells.OCCUPIED
    c[6:54, 6:74] = cells.FREE
    c[28:31, 6:74] = cells.OCCUPIED      # a wall across, with a door
    c[28:31, 30:44] = cells.FREE
    c[40:44, 50:53] = cells.OCCUPIED     # an object
    return build_frame_from_classes(c, 0.05, model)


@pytest.mark.parametrize("enclosure_cost", [0.0, 1.0])
def test_a_tempered_target_is_the_likelihood_times_beta_and_the_same_prior(enclosure_cost):
    m = load_model()
    model = dataclasses.replace(m, sensor=dataclasses.replace(m.sensor, enclosure_cost=enclosure_cost))
    frame = two_rooms(model)
    post = Posterior(frame, model)
    data = data_from_frame(frame)
    tr = post.start(wm.empty(6))
    run_chain(np.random.default_rng(1), tr, default_mix(data.settings), 600, data)
    worlds = [wm.empty(6), tr.world, wm.add(wm.empty(6), 0, (4, 4, 31, 76)),
              wm.add(wm.empty(6), 0, (10, 10, 25, 30))]
    assert tempered(tempered(post, 0.5), 2.0) is post and tempered(post, 1.0) is post
    for beta in (0.5, 0.013):
        hot = tempered(post, beta)
        assert tempered(hot, 0.5).beta == pytest.approx(0.5 * beta)
        for w in worlds:
            full, part = post.evaluate(w), hot.evaluate(w)
            assert part.loglik == pytest.approx(beta * full.loglik, rel=1e-12)
            assert part.logprior == full.logprior
        if enclosure_cost:
            assert post.enclosure(worlds[3]) != 0.0
            assert hot.enclosure(worlds[3]) == pytest.approx(beta * post.enclosure(worlds[3]))
    # a chain on the tempered target tracks its full evaluation, and retargeting a tracker gives
    # what a tracker started on the other target gives
    hot = tempered(post, 0.1)
    tr = hot.start(wm.empty(6))
    res = run_chain(np.random.default_rng(2), tr, default_mix(data.settings), 800, data)
    assert res.accepted.sum() > 5
    assert tr.logp == pytest.approx(hot.evaluate(tr.world).total, rel=1e-9)
    assert tr.loglik_under(post) == pytest.approx(post.evaluate(tr.world).loglik, rel=1e-12)
    tr.retarget(post)
    assert tr.post is post
    assert tr.logp == pytest.approx(post.start(tr.world).logp, rel=1e-12)


def test_the_knowledge_phase_of_a_tempered_copy_is_its_base():
    model = load_model()
    post = Posterior(two_rooms(model), model)
    hot = tempered(post, 0.5)
    assert hot.knowledge_on is False
    post.knowledge_on = True
    assert hot.knowledge_on is True
    hot.knowledge_on = False
    assert post.knowledge_on is False


def test_tempering_refuses_a_nonpositive_exponent():
    model = load_model()
    post = Posterior(two_rooms(model), model)
    for beta in (0.0, -1.0, float("nan")):
        with pytest.raises(ValueError):
            tempered(post, beta)


def test_the_correlation_area_of_white_noise_is_one_and_of_blocks_their_area():
    rng = np.random.default_rng(0)
    mask = np.ones((600, 600), bool)
    white = rng.normal(size=mask.shape)
    assert correlation_area(white, mask, 8) == pytest.approx(1.0, abs=0.5)
    # noise constant over 4 x 4 blocks: every cell is correlated with its block, A = 16 up to edges
    blocks = np.kron(rng.normal(size=(150, 150)), np.ones((4, 4)))
    assert correlation_area(blocks, mask, 8) == pytest.approx(16.0, rel=0.1)
    # lags beyond the block add nothing; a shorter window sees part of it: the correlation at lag
    # h is (4 - |h_r|)(4 - |h_c|) / 16, which sums to 16 over |h| <= 3 and to 3.5^2 over |h| <= 2
    assert correlation_area(blocks, mask, 3) == pytest.approx(correlation_area(blocks, mask, 8), rel=0.1)
    assert correlation_area(blocks, mask, 2) == pytest.approx(3.5 ** 2, rel=0.1)
    # cells outside the mask do not count: blocks beside white noise, the blocks alone
    half = mask.copy()
    half[:, 300:] = False
    both = np.where(half, blocks, white)
    assert correlation_area(both, half, 8) == pytest.approx(16.0, rel=0.15)
    assert correlation_area(blocks, mask, 0) == 1.0


def test_the_exponent_is_one_over_the_correlation_area_of_wstar_residuals():
    model = load_model()
    frame = two_rooms(model)
    post = Posterior(frame, model)
    w = wm.add(wm.add(wm.empty(4), 0, (4, 4, 31, 76)), 1, (28, 4, 56, 76))
    lam, area = likelihood_exponent(post, w, 0.5)
    assert area > 1.0 and lam == pytest.approx(1.0 / area)
    assert likelihood_exponent(post, w, 0.0) == (1.0, 1.0)
    # the same from a tempered copy (the rule reads the untempered residuals)
    assert likelihood_exponent(tempered(post, 0.2), w, 0.5)[1] == pytest.approx(area)
