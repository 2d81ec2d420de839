"""Tests of semmap_pp.target.prior: proper unit-parameter and count priors, the SaLe factor."""

import itertools
import math

import numpy as np
import pytest

from semmap_pp.model import load_model
from semmap_pp.target.prior import (connecting_length_difference, log_p_n, log_p_n_table, log_p_rect,
                             log_prior, log_slots, n_rects, rect_faults, rects_valid,
                             sale_log_factor)

PRIOR = load_model().prior


def test_n_rects_matches_enumeration():
    for length in range(0, 12):
        for lo in range(1, 6):
            for hi in range(lo, 14):
                brute = sum(1 for a in range(length) for s in range(lo, hi + 1) if a + s <= length)
                assert n_rects(length, lo, hi) == brute


def test_p_rect_sums_to_one_over_the_support():
    shape, lo, hi = (7, 9), 3, 5
    total = sum(math.exp(log_p_rect((r0, c0, r1, c1), shape, lo, hi))
                for r0, r1 in itertools.combinations(range(shape[0] + 1), 2)
                for c0, c1 in itertools.combinations(range(shape[1] + 1), 2)
                if math.isfinite(log_p_rect((r0, c0, r1, c1), shape, lo, hi)))
    assert total == pytest.approx(1.0)
    assert log_p_rect((0, 0, 2, 4), shape, lo, hi) == -math.inf      # side too short
    assert log_p_rect((-1, 0, 3, 4), shape, lo, hi) == -math.inf     # outside the lattice


@pytest.mark.parametrize("kind", ["poisson", "geometric"])
def test_p_n_is_normalised_with_the_given_mean(kind):
    params = PRIOR.__class__(**{**PRIOR.__dict__, "n_prior": kind, "n_mean": 4.0})
    table = np.exp(log_p_n_table(200, params))
    assert table.sum() == pytest.approx(1.0)
    assert np.dot(np.arange(201), table) == pytest.approx(4.0, rel=1e-6)
    assert log_p_n(201, 200, params) == -math.inf


def test_slots_term_counts_ordered_placements():
    assert math.exp(log_slots(2, 5)) == pytest.approx(10.0)   # C(5, 2)
    assert math.exp(log_slots(5, 5)) == pytest.approx(1.0)
    assert log_slots(0, 5) == 0.0


def test_connecting_walls_side_by_side_and_stacked():
    # side by side along the columns: heights 40 and 30 cells differ by 10 cells = 0.5 m
    assert connecting_length_difference((0, 0, 40, 20), (5, 20, 35, 50), 0.05) == pytest.approx(0.5)
    # one above the other: widths 20 and 24 cells
    assert connecting_length_difference((0, 0, 40, 20), (40, 0, 60, 24), 0.05) == pytest.approx(0.2)


def test_sale_factor_only_for_adjacent_pairs_above_threshold():
    rects = np.array([(0, 0, 40, 20), (0, 20, 30, 50), (0, 100, 40, 120)])
    adj = np.array([[0, 1, 0], [1, 0, 0], [0, 0, 0]], bool)
    high = np.full((3, 3), 0.9)
    d = 0.5
    assert sale_log_factor(rects, adj, high, 0.05, PRIOR) == pytest.approx(-d * d / (2 * PRIOR.sale_sigma_m ** 2))
    assert sale_log_factor(rects, adj, np.full((3, 3), 0.1), 0.05, PRIOR) == 0.0
    assert sale_log_factor(rects, np.zeros((3, 3), bool), high, 0.05, PRIOR) == 0.0


def test_log_prior_adds_its_parts():
    rects = np.array([(0, 0, 40, 30), (0, 30, 40, 60)])
    adj = np.array([[0, 1], [1, 0]], bool)
    sale = np.zeros((2, 2))
    shape, lo, hi = (100, 100), 21, 1600
    lp = log_prior(rects, 8, shape, lo, hi, adj, sale, 0.05, PRIOR)
    expected = log_p_n(2, 8, PRIOR) - log_slots(2, 8) + 2 * log_p_rect(rects[0], shape, lo, hi)
    assert lp == pytest.approx(expected)
    assert log_prior(rects, 1, shape, lo, hi, adj, sale, 0.05, PRIOR) == -math.inf


def test_compiled_slot_sale_sum_equals_the_reference():
    from semmap_pp.target.prior import sale_log_factor_slots
    rng = np.random.default_rng(4)
    table = load_model().knowledge.fixed_sale
    for _ in range(50):
        K = 6
        r0, c0 = rng.integers(0, 50, K), rng.integers(0, 50, K)
        rects = np.stack([r0, c0, r0 + rng.integers(21, 60, K), c0 + rng.integers(21, 60, K)], 1)
        active = rng.random(K) < 0.8
        adj = rng.random((K, K)) < 0.5
        adj = np.triu(adj, 1)
        adj = adj | adj.T
        types = rng.integers(0, 4, K)
        sale = table[np.ix_(types, types)]
        live = np.flatnonzero(active)
        ref = sale_log_factor(rects[live], adj[np.ix_(live, live)], sale[np.ix_(live, live)], 0.05, PRIOR)
        assert sale_log_factor_slots(rects, active, adj, PRIOR, 0.05, sale=sale) == pytest.approx(ref)
        assert sale_log_factor_slots(rects, active, adj, PRIOR, 0.05, types=types, table=table) == pytest.approx(ref)


def test_rect_faults_are_empty_exactly_when_the_rectangle_is_in_the_support():
    """The reasons world_file and world_edit give for a refused rectangle come from one rule,
    the prior's own (:func:`rects_valid`)."""
    rng = np.random.default_rng(5)
    for _ in range(3000):
        r0, c0 = rng.integers(-5, 40, 2)
        h, w = rng.integers(-2, 40, 2)
        rect = (int(r0), int(c0), int(r0 + h), int(c0 + w))
        faults = rect_faults(rect, (50, 60), 4, 30)
        assert (not faults) == bool(rects_valid(np.array([rect]), (50, 60), 4, 30)[0])
        assert ("small" in faults) == (min(h, w) < 4) and ("large" in faults) == (max(h, w) > 30)
