"""method="auto": exact when the junction tree is small, loopy BP otherwise; MAP stays exact.

Oracles: enumeration of every joint state of a small pairwise network (for the BP code itself),
clingo's enumeration of every world (``test_knowledge_inference.oracle``) for the engine on
small loopy floors, and the exact engine (itself checked against that enumeration to 1e-9) on
many random floors of up to 6 units.
"""

import itertools
import time

import numpy as np
import pytest
from test_knowledge_inference import _map_tuple, assert_matches_brute_force, oracle, oracle_map

from semmap_pp.knowledge import Evidence, KnowledgeEngine, load_rules
from semmap_pp.knowledge.exact import MAX_CLIQUE_STATES, JunctionTree, TooDense
from semmap_pp.knowledge.layouts import dense_floor
from semmap_pp.knowledge.lbp import (BPSettings, _exp_tables, _one_factor, _sparse_factor,
                                     _sparse_plan, cluster, factor_bp, pairwise_bp)
from semmap_pp.knowledge.local import separate
from semmap_pp.knowledge.map import map_pairwise_rc2
from semmap_pp.knowledge.trees import AutoLimits

# Largest LBP error against exact marginals on random floors of 3..6 units with 70 % of the
# pairs adjacent (types and SaLe, rules/table3.lp): measured 0.0072 over 300 floors.
TABLE3_TOL = 0.02


def enumerated_marginals(card, pots):
    """Marginals of a factor network (log tables over scopes), by enumeration."""
    states = np.array(list(itertools.product(*[range(c) for c in card])))
    logp = sum(t[tuple(states[:, v] for v in s)] for s, t in pots)
    w = np.exp(logp - logp.max())
    w /= w.sum()
    return [np.bincount(states[:, v], w, c) for v, c in enumerate(card)]


def brute_force(unary, pairs):
    """Marginals and pair joints of a pairwise log-potential network, by enumeration."""
    cards = [len(u) for u in unary]
    states = np.array(list(itertools.product(*[range(c) for c in cards])))
    logp = sum(u[states[:, i]] for i, u in enumerate(unary))
    logp = logp + sum(t[states[:, i], states[:, j]] for i, j, t in pairs)
    w = np.exp(logp - logp.max())
    w /= w.sum()
    marg = [np.bincount(states[:, i], weights=w, minlength=c) for i, c in enumerate(cards)]
    joint = []
    for i, j, t in pairs:
        jt = np.zeros(t.shape)
        np.add.at(jt, (states[:, i], states[:, j]), w)
        joint.append(jt)
    return marg, joint


def random_network(rng, n, edges, strength):
    unary = [rng.normal(0, 1, 4) for _ in range(n)]
    pairs = [(i, j, rng.normal(0, strength, (4, 4))) for i, j in edges]
    return unary, pairs


def test_bp_is_exact_on_a_tree():
    # a star plus a path (no loop): the BP fixed point is the exact marginal
    rng = np.random.default_rng(0)
    unary, pairs = random_network(rng, 6, [(0, 1), (0, 2), (0, 3), (3, 4), (4, 5)], 1.0)
    res = pairwise_bp(unary, pairs, range(len(pairs)), BPSettings(tol=1e-13, max_iter=500))
    marg, joint = brute_force(unary, pairs)
    assert res.converged
    for a, b in zip(res.marginals, marg):
        np.testing.assert_allclose(a, b, atol=1e-9)
    for k, jt in enumerate(joint):
        np.testing.assert_allclose(res.pair_beliefs[k], jt, atol=1e-9)


def test_bp_on_loops_is_close_for_weak_couplings_and_not_exact():
    # K5 and a 2x3 grid with couplings of table3's size (|log ratio| <= ~0.6)
    rng = np.random.default_rng(1)
    k5 = [(i, j) for i in range(5) for j in range(i + 1, 5)]
    grid = [(0, 1), (1, 2), (3, 4), (4, 5), (0, 3), (1, 4), (2, 5)]
    worst = 0.0
    for edges, n in ((k5, 5), (grid, 6)):
        for _ in range(5):
            unary, pairs = random_network(rng, n, edges, 0.3)
            res = pairwise_bp(unary, pairs)
            marg, _ = brute_force(unary, pairs)
            worst = max(worst, max(np.abs(a - b).max() for a, b in zip(res.marginals, marg)))
    assert 1e-6 < worst < TABLE3_TOL   # an approximation, but a close one


def test_bp_never_gives_mass_to_a_forbidden_state():
    unary = [np.array([0.0, -np.inf, 0.0, 0.0]), np.zeros(4), np.zeros(4)]
    forbid = np.zeros((4, 4))
    forbid[2, 3] = -np.inf   # x0 = 2 and x1 = 3 never together
    pairs = [(0, 1, forbid), (1, 2, np.eye(4)), (0, 2, -np.eye(4))]
    res = pairwise_bp(unary, pairs, [0])
    assert res.marginals[0][1] == 0.0 and res.pair_beliefs[0][2, 3] == 0.0
    for m in res.marginals:
        assert abs(m.sum() - 1) < 1e-12


def test_bp_is_a_deterministic_function_of_the_network():
    rng = np.random.default_rng(2)
    unary, pairs = random_network(rng, 6, [(i, j) for i in range(6) for j in range(i + 1, 6)], 1)
    a = pairwise_bp(unary, pairs, range(15))
    b = pairwise_bp([u.copy() for u in unary], [(i, j, t.copy()) for i, j, t in pairs],
                    range(15))
    assert all(np.array_equal(x, y) for x, y in zip(a.marginals, b.marginals))
    assert all(np.array_equal(a.pair_beliefs[k], b.pair_beliefs[k]) for k in range(15))


def test_factor_bp_is_exact_on_a_tree_of_factors():
    # a ternary factor and a pair hanging off it: a tree of factors
    rng = np.random.default_rng(3)
    card = [2, 3, 4, 2]
    pots = [((0, 1, 2), rng.normal(0, 1, (2, 3, 4))), ((2, 3), rng.normal(0, 1, (4, 2))),
            ((1,), rng.normal(0, 1, 3))]
    res = factor_bp(card, pots, BPSettings(tol=1e-13, max_iter=500))
    for v, c in enumerate(card):
        np.testing.assert_allclose(res.marginals[v], enumerated_marginals(card, pots)[v],
                                   atol=1e-9)


def _factor_messages(etab, ins, dims):
    """``lbp._one_factor`` (the compiled pass over one factor) on each of ``n`` factors of one
    shape: ``etab`` (n, S), ``ins`` (n, Σ dims); returns (n, Σ dims)."""
    dims = np.asarray(dims, dtype=np.int64)
    r = len(dims)
    out = np.zeros(ins.shape)
    pre, suf = np.empty(r + 1), np.empty(r + 1)
    digit, col = np.empty(r, dtype=np.int64), np.empty(r, dtype=np.int64)
    for i in range(len(etab)):
        _one_factor(np.ascontiguousarray(etab[i]), np.ascontiguousarray(ins[i]), out[i], dims,
                    pre, suf, digit, col)
    return out


def _messages_in_log_space(tables, ins_log, shape):
    """Reference for :func:`_factor_messages`: message to position p = log Σ over the other
    positions of (table + their incoming log messages), normalised (uniform when nothing is
    possible), one factor at a time by broadcasting."""
    out = []
    for t, vin in zip(tables, ins_log):
        row = []
        for p, c in enumerate(shape):
            s = np.asarray(t, dtype=float)
            for q, m in enumerate(vin):
                if q != p:
                    sh = [1] * len(shape)
                    sh[q] = shape[q]
                    s = s + m.reshape(sh)
            other = tuple(q for q in range(len(shape)) if q != p)
            top = np.max(s)
            with np.errstate(divide="ignore"):
                lse = (np.log(np.exp(s - top).sum(axis=other)) + top if np.isfinite(top)
                       else np.full(c, -np.inf))
            w = np.exp(lse - np.max(lse)) if np.isfinite(np.max(lse)) else np.zeros(c)
            row.append(w / w.sum() if w.sum() > 0 else np.full(c, 1.0 / c))
        out.append(np.concatenate(row))
    return np.array(out)


@pytest.mark.parametrize("shape", [(2, 2), (4, 2, 2), (4, 4, 4), (2, 3, 4, 2), (4, 4, 4, 4, 4)])
def test_compiled_factor_messages_equal_the_log_space_sums(shape):
    # random log tables with forbidden (-inf) entries, one factor forbidding everything, and
    # incoming messages with zero entries (a variable that rules a value out)
    rng = np.random.default_rng(sum(shape))
    n = 7
    tables = rng.normal(0, 3, (n,) + shape)
    tables[rng.random(tables.shape) < 0.2] = -np.inf
    tables[3] = -np.inf
    ins_log = [[rng.normal(0, 2, c) for c in shape] for _ in range(n)]
    for k in range(n):
        ins_log[k][0][rng.random(shape[0]) < 0.3] = -np.inf
    dims = np.array(shape, dtype=np.int64)
    ins = np.array([np.concatenate([np.exp(m - np.max(m)) if np.isfinite(np.max(m))
                                    else np.zeros(len(m)) for m in vin]) for vin in ins_log])
    got = _factor_messages(_exp_tables(list(tables)), ins, dims)
    want = _messages_in_log_space(tables, ins_log, shape)
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-15)
    assert np.allclose(got[3], np.concatenate([np.full(c, 1.0 / c) for c in shape]))


def _sparse_messages(table, ins, shape):
    """:func:`_sparse_factor` on one probability-space table through :func:`_sparse_plan`;
    None when the plan keeps the table dense."""
    flat = np.ascontiguousarray(table, dtype=float).ravel()
    mode, soff, sidx, sval = _sparse_plan(flat, np.array([0, flat.size], dtype=np.int64))
    if mode[0] < 0:
        return None
    r = len(shape)
    out = np.empty(len(ins))
    _sparse_factor(mode[0], sidx[soff[0]:soff[1]], sval[soff[0]:soff[1]], ins, out,
                   np.array(shape, dtype=np.int64), np.empty(r + 1), np.empty(r + 1),
                   np.empty(r, dtype=np.int64), np.empty(r, dtype=np.int64))
    return out


@pytest.mark.slow
@pytest.mark.parametrize("shape", [(4, 4, 4), (4, 2, 2, 4), (4, 4, 4, 4, 4)])
@pytest.mark.parametrize("common", [1.0, 0.0, 0.37])
def test_sparse_factor_messages_equal_the_dense_pass(shape, common):
    # a table that is one value but at a few states (as a soft rule's factor over a unit and
    # its neighbours is), with zero incoming entries: the constant-plus-correction pass gives
    # the dense pass's messages; common 0 (mostly forbidden) keeps its zeros exact
    rng = np.random.default_rng(len(shape) + int(10 * common))
    dims = np.array(shape, dtype=np.int64)
    S = int(np.prod(shape))
    for _ in range(5):
        table = np.full(S, common)
        few = rng.choice(S, size=S // 8, replace=False)
        table[few] = rng.uniform(0.05, 2.0, len(few))
        ins = rng.random(int(dims.sum()))
        ins[rng.random(len(ins)) < 0.2] = 0.0
        got = _sparse_messages(table, ins, shape)
        assert got is not None
        want = _factor_messages(table[None, :], ins[None, :], dims)[0]
        np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-15)
        if common == 0.0:
            assert np.array_equal(got == 0, want == 0)


def test_sparse_plan_keeps_dense_what_the_correction_could_wipe_out():
    shape = (4, 4, 4)
    table = np.ones(64)
    table[:8] = 0.5
    assert _sparse_messages(table, np.ones(12), shape) is not None
    table[9] = 1e-9        # far below the common value: subtracting could lose it
    assert _sparse_messages(table, np.ones(12), shape) is None
    table = np.ones(64)
    table[:20] = 0.5       # more than a quarter differ
    assert _sparse_messages(table, np.ones(12), shape) is None
    assert _sparse_messages(np.ones(32), np.ones(10), (4, 4, 2)) is None   # too small


def _cluster_plain(card, potentials, max_states):
    """Reference for :func:`cluster`: the same passes without skipping a factor whose
    neighbourhood did not change."""
    facs = {k: (tuple(s), np.asarray(t, dtype=np.float64)) for k, (s, t) in
            enumerate(potentials) if len(s) >= 2}
    rest = [(tuple(s), t) for s, t in potentials if len(s) < 2]
    changed = True
    while changed:
        changed = False
        for f in sorted(facs):
            if f not in facs:
                continue
            sf, tf = facs[f]
            for g in sorted(k for k in facs if k != f and set(facs[k][0]) & set(sf)):
                sg, tg = facs[g]
                union = tuple(sorted(set(sf) | set(sg)))
                if len(sf) + len(sg) - len(union) < 2 or np.prod([card[v] for v in union]) > max_states:
                    continue
                shape = [card[v] for v in union]
                ea = np.broadcast_to(tf.reshape([card[v] if v in sf else 1 for v in union]), shape)
                eb = np.broadcast_to(tg.reshape([card[v] if v in sg else 1 for v in union]), shape)
                del facs[g]
                facs[f] = sf, tf = union, ea + eb
                changed = True
    return rest + [facs[k] for k in sorted(facs)]


def test_cluster_equals_the_plain_passes():
    # random networks of many overlapping factors, where merges in one pass open new ones in the
    # next: skipping factors whose neighbourhood did not change must not change the result
    rng = np.random.default_rng(12)
    passes = 0
    for trial in range(40):
        n = int(rng.integers(6, 14))
        card = [int(c) for c in rng.choice([2, 3, 4], n)]
        pots = []
        for _ in range(int(rng.integers(n, 3 * n))):
            scope = tuple(sorted(int(v) for v in rng.choice(n, int(rng.integers(1, 4)), replace=False)))
            pots.append((scope, rng.normal(0, 1, [card[v] for v in scope])))
        limit = int(rng.choice([16, 64, 256]))
        got, want = cluster(card, pots, limit), _cluster_plain(card, pots, limit)
        assert [s for s, _ in got] == [s for s, _ in want]
        assert all(np.array_equal(np.asarray(a), np.asarray(b)) for (_, a), (_, b) in zip(got, want))
        passes += sum(len(s) > 3 for s, _ in got)
    assert passes > 20     # merges did chain across passes
    # (0, 1) is tried first and refused by both (0, 2, 3) and (1, 2, 3); once those two merge,
    # the next pass must try (0, 1) again, which now absorbs them (it comes first)
    card = [2] * 7
    pots = [((0, 1), rng.normal(0, 1, (2, 2))), ((5, 6), rng.normal(0, 1, (2, 2))),
            ((0, 2, 3), rng.normal(0, 1, (2, 2, 2))), ((1, 2, 3), rng.normal(0, 1, (2, 2, 2)))]
    assert [s for s, _ in cluster(card, pots, 64)] == [s for s, _ in _cluster_plain(card, pots, 64)] \
        == [(0, 1, 2, 3), (5, 6)]


@pytest.mark.slow
def test_factor_bp_is_exact_on_a_tree_with_a_sparse_factor():
    # a 4^4 factor that is constant but at a few states takes the sparse pass
    rng = np.random.default_rng(13)
    card = [4, 4, 4, 4, 3]
    big = np.zeros((4, 4, 4, 4))
    big[0, :, 1, :] = -0.8
    big[2, 3, 3, 3] = 1.5
    pots = [((0, 1, 2, 3), big), ((3, 4), rng.normal(0, 1, (4, 3))), ((0,), rng.normal(0, 1, 4)),
            ((2,), rng.normal(0, 1, 4))]
    res = factor_bp(card, pots, BPSettings(tol=1e-13, max_iter=500))
    for v, c in enumerate(card):
        np.testing.assert_allclose(res.marginals[v], enumerated_marginals(card, pots)[v],
                                   atol=1e-9)


def test_cluster_keeps_the_joint_and_merges_tight_overlaps():
    # two factors on (0, 1, 2) and (1, 2, 3) share two variables: merged; (3, 4) shares one
    rng = np.random.default_rng(4)
    card = [2, 2, 2, 2, 3]
    pots = [((0, 1, 2), rng.normal(0, 1, (2, 2, 2))), ((1, 2, 3), rng.normal(0, 1, (2, 2, 2))),
            ((3, 4), rng.normal(0, 1, (2, 3))), ((1, 2), rng.normal(0, 1, (2, 2))),
            ((4,), rng.normal(0, 1, 3))]
    merged = cluster(card, pots, 1 << 8)
    assert sorted(s for s, _ in merged) == [(0, 1, 2, 3), (3, 4), (4,)]
    states = np.array(list(itertools.product(*[range(c) for c in card])))

    def joint(ps):
        return sum(np.broadcast_to(t, t.shape)[tuple(states[:, v] for v in s)] for s, t in ps)
    np.testing.assert_allclose(joint(merged), joint(pots), atol=1e-12)
    # within 8 states only the subset (1, 2) is absorbed
    assert sorted(s for s, _ in cluster(card, pots, 8)) == [(0, 1, 2), (1, 2, 3), (3, 4), (4,)]


@pytest.mark.slow
def test_general_path_lbp_on_table3_is_as_close_as_the_type_network():
    # the same rules through the ground network: a SaLe atom, its mirror and the symmetry rule
    # are merged into one factor per pair, so BP sees the same loops as on the type network
    rules = load_rules("rules/table3.lp")
    exact = KnowledgeEngine(rules, method="exact")
    lbp = KnowledgeEngine(rules, method="lbp", fast=False)
    rng = np.random.default_rng(8)
    worst = 0.0
    for _ in range(15):
        ev = random_dense_floor(rng)
        a, b = exact.infer(ev), lbp.infer(ev)
        assert b.method == "lbp"
        worst = max([worst] + [np.abs(a.types[u] - b.types[u]).max() for u in ev.units]
                    + [abs(a.sale[pq] - b.sale[pq]) for pq in ev.adj])
    assert worst < TABLE3_TOL


def test_separate_splits_only_sums_of_unit_terms():
    a, b = np.array([0.0, -1.0]), np.array([0.5, 0.0, -2.0])
    split = separate(a[:, None] + b[None, :])
    assert split is not None
    np.testing.assert_allclose(split[0][:, None] + split[1][None, :], a[:, None] + b[None, :])
    assert separate(np.array([[0.0, 0.0], [0.0, -1.0]])) is None      # a coupling
    assert separate(np.array([[0.0, -np.inf], [0.0, 0.0]])) is None   # a hard pair rule


def test_none_folds_every_pair_and_table3_folds_every_map_pair():
    ev = Evidence.build([1, 2, 3], rolike={1: 0.7}, adj=[(1, 2), (2, 3), (1, 3)])
    none = KnowledgeEngine.from_file("rules/none.lp").local.type_network(ev)
    assert none.sum_pairs == [] and none.max_pairs == [] and none.card == [4, 4, 4]
    assert none.sale == {(1, 2): 0.5, (1, 3): 0.5, (2, 3): 0.5}
    t3 = KnowledgeEngine.from_file("rules/table3.lp").local.type_network(ev)
    # SaLe can always be chosen to satisfy the pair rules: the MAP never couples units, but
    # the sum over SaLe does (two rooms: 1 + e^-2.2, a room and a hall: 1 + e^-1, ...)
    assert len(t3.sum_pairs) == 3 and t3.max_pairs == []
    assert t3.card == [4, 4, 4]   # unit 1's soft RoLi summed out: no pair reads it


def loopy_floors():
    """Small floors whose adjacency has cycles (a triangle, a 4-cycle with a chord)."""
    yield Evidence.build([1, 2, 3], rolike={1, 2}, colike={3}, muldoor={3},
                         adj=[(1, 2), (2, 3), (1, 3)])
    yield Evidence.build([1, 2, 3, 4], rolike={1, 3}, halike={2}, colike={4: 0.7},
                         adj=[(1, 2), (2, 3), (3, 4), (1, 4)])


@pytest.mark.slow
def test_lbp_close_to_enumeration_on_loopy_floors():
    rules = load_rules("rules/table3.lp")
    engine = KnowledgeEngine(rules, method="lbp")
    for ev in loopy_floors():
        types, sale, best, _, _ = oracle(rules, ev)
        r = engine.infer(ev)
        assert r.method == "lbp" and r.log_z is None
        err = max([np.abs(r.types[u] - types[u]).max() for u in ev.units]
                  + [abs(r.sale[pq] - sale[pq]) for pq in ev.adj])
        assert 0 < err < TABLE3_TOL
        map_best, map_types = oracle_map(rules, ev)     # the MAP stays exact
        assert abs(r.map_cost * 1000 - map_best) < 1e-6 and _map_tuple(r, ev) in map_types


def random_dense_floor(rng):
    n = int(rng.integers(3, 7))
    units = list(range(1, n + 1))
    pairs = [(p, q) for p in units for q in units if p < q and rng.random() < 0.7]
    kw = {}
    for name in ("rolike", "colike", "halike", "muldoor"):
        d = {}
        for u in units:
            r = rng.random()
            if r < 0.3:
                d[u] = 1.0
            elif r < 0.4:
                d[u] = round(float(rng.uniform(0.05, 0.95)), 2)
        kw[name] = d
    return Evidence.build(units, adj=pairs, **kw)


@pytest.mark.slow
def test_lbp_within_tolerance_of_exact_on_random_floors():
    rules = load_rules("rules/table3.lp")
    exact = KnowledgeEngine(rules, method="exact")
    lbp = KnowledgeEngine(rules, method="lbp")
    rng = np.random.default_rng(5)
    worst = 0.0
    for _ in range(60):
        ev = random_dense_floor(rng)
        a, b = exact.infer(ev), lbp.infer(ev)
        worst = max([worst] + [np.abs(a.types[u] - b.types[u]).max() for u in ev.units]
                    + [abs(a.sale[pq] - b.sale[pq]) for pq in ev.adj])
        assert a.map_types == b.map_types and abs(a.map_cost - b.map_cost) < 1e-9
    assert worst < TABLE3_TOL


@pytest.mark.slow
@pytest.mark.parametrize("rule_file", ["rules/table3.lp", "rules/halls_to_corridors.lp"])
def test_auto_picks_exact_on_small_floors_and_agrees_with_enumeration(rule_file):
    rules = load_rules(rule_file)
    engine = KnowledgeEngine(rules)   # the default is auto
    assert engine.method == "auto"
    for ev in loopy_floors():
        r = engine.infer(ev)
        assert r.method == "exact"
        assert_matches_brute_force(r, rules, ev)


def test_general_path_falls_back_to_factor_bp():
    # halls_to_corridors.lp is not pairwise-local: BP runs on the ground network (SaLe atoms
    # and soft atoms as variables); a ground-network clique bound of 1 forces the fallback on a
    # small floor
    rules = load_rules("rules/halls_to_corridors.lp")
    ev = next(loopy_floors())
    types, sale, best, _, _ = oracle(rules, ev)
    assert KnowledgeEngine(rules).infer(ev).method == "exact"      # a small tree: exact
    r = KnowledgeEngine(rules, auto=AutoLimits(states_ground=1)).infer(ev)
    assert r.method == "lbp" and r.map_method == "rc2"
    assert abs(r.map_cost * 1000 - best) < 1e-6
    err = max([np.abs(r.types[u] - types[u]).max() for u in ev.units]
              + [abs(r.sale[pq] - sale[pq]) for pq in ev.adj])
    assert err < 0.1   # the ground network's loops are tight (see docs/rules.md)


@pytest.mark.slow
def test_map_by_rc2_when_the_map_tree_is_too_large(tmp_path):
    # a pair rule that no SaLe choice satisfies couples the MAP: two adjacent rooms cost 1.5
    f = tmp_path / "rr.lp"
    f.write_text(":~ rolike(U), not room(U). [1000@0, r, U]\n"
                 ":~ room(P), room(Q), adj(P,Q). [1500@0, rr, P, Q]\n")
    rules = load_rules(f)
    ev = Evidence.build([1, 2, 3, 4], rolike={1, 2, 3, 4},
                        adj=[(1, 2), (2, 3), (3, 4), (1, 4), (1, 3)])
    _, _, best, _, _ = oracle(rules, ev)
    r = KnowledgeEngine(rules, auto=AutoLimits(states=4)).infer(ev)
    assert r.method == "lbp" and r.map_method == "rc2"
    assert abs(r.map_cost * 1000 - best) < 1e-6
    assert sum(t == "room" for t in r.map_types.values()) == 2   # 1 and 3 adjacent: 2, 4 rooms


@pytest.mark.slow
def test_pairwise_rc2_reaches_the_brute_force_optimum():
    rng = np.random.default_rng(6)
    for _ in range(5):
        unary = [-rng.integers(0, 3000, 4) / 1000.0 for _ in range(4)]
        pairs = [(i, j, -rng.integers(0, 3000, (4, 4)) / 1000.0)
                 for i, j in [(0, 1), (1, 2), (2, 3), (0, 3), (0, 2)]]
        pairs[0][2][0, :] = -np.inf
        x, best = map_pairwise_rc2(unary, pairs, "test")
        states = np.array(list(itertools.product(range(4), repeat=4)))
        logp = sum(u[states[:, i]] for i, u in enumerate(unary))
        logp = logp + sum(t[states[:, i], states[:, j]] for i, j, t in pairs)
        assert abs(best - logp.max()) < 1e-9
        assert abs(sum(u[x[i]] for i, u in enumerate(unary))
                   + sum(t[x[i], x[j]] for i, j, t in pairs) - best) < 1e-9


def _violated_cost(hard, soft, wght, first, x):
    """(any hard clause false, summed weight of the false soft clauses) when axis ``a`` of the
    table takes state ``x[a]``: a clause is false when none of its literals is a true state."""
    true = {f + k for f, k in zip(first, x)}

    def false(clause):
        return not any(lit in true for lit in clause)
    return any(false(c) for c in hard), sum(w for c, w in zip(soft, wght) if false(c))


def test_rc2_clauses_charge_every_assignment_its_entrys_cost():
    """``map._add_costs`` covers a table by boxes: for every joint state, the soft clauses it
    falsifies weigh its cost above the table's minimum and a hard clause is falsified exactly
    when the entry is ``-inf``. Random tables over 1-5 variables of 2-4 states, with values
    from a few levels (so that boxes of several entries form) and, in some, entries that
    depend on one axis only."""
    from semmap_pp.knowledge.map import COST_SCALE, _add_costs
    rng = np.random.default_rng(12)
    for case in range(60):
        shape = tuple(int(c) for c in rng.integers(2, 5, int(rng.integers(1, 6))))
        table = -rng.integers(0, 3, shape) / 2.0
        if case % 3 == 0:    # a term in the last axis alone, added everywhere
            table = table + (-rng.integers(0, 3, shape[-1]) / 4.0)
        table[rng.random(shape) < 0.1] = -np.inf
        if not np.isfinite(table).any():
            continue
        first = [int(f) for f in np.cumsum([1] + list(shape[:-1]))]
        hard, soft, wght = [], [], []
        low = _add_costs(hard, soft, wght, table, first)
        assert low == min(round(-COST_SCALE * v) for v in table.reshape(-1) if np.isfinite(v))
        assert all(w > 0 for w in wght)
        for x in itertools.product(*(range(c) for c in shape)):
            forbidden, cost = _violated_cost(hard, soft, wght, first, x)
            v = table[x]
            assert forbidden == (not np.isfinite(v)), (case, x)
            if np.isfinite(v):
                assert cost == round(-COST_SCALE * v) - low, (case, x)
        assert len(hard) + len(soft) <= int((table < table.max()).sum())


def test_rc2_a_rule_over_all_neighbours_is_one_clause():
    """"A hall none of whose four neighbours is a corridor costs 0.8" is 3⁴ entries of one
    cost: one clause of 7 literals (the unit is not a hall, or some neighbour is a corridor),
    where one clause per entry made 81."""
    from semmap_pp.knowledge.map import _add_costs
    hall, corridor = 2, 1
    table = np.zeros((4,) * 5)
    none_corridor = [k for k in range(4) if k != corridor]
    table[np.ix_([hall], none_corridor, none_corridor, none_corridor, none_corridor)] = -0.8
    first = [1, 5, 9, 13, 17]
    hard, soft, wght = [], [], []
    assert _add_costs(hard, soft, wght, table, first) == 0
    assert hard == [] and wght == [800_000]
    assert sorted(soft[0]) == [1, 2, 4] + [f + corridor for f in first[1:]]


def test_rc2_map_of_random_table_networks_equals_enumeration():
    """``map_tables_rc2`` on networks of 2-4-ary tables over 5 variables: the optimum equals
    the enumerated one, and the returned assignment attains it."""
    from semmap_pp.knowledge.map import map_tables_rc2
    rng = np.random.default_rng(5)
    card = [4, 2, 4, 3, 2]
    states = np.array(list(itertools.product(*(range(c) for c in card))))
    for _ in range(25):
        pots = []
        for scope in [(0,), (0, 1), (1, 2, 3), (0, 2, 3, 4), (3, 4)]:
            t = -rng.integers(0, 3, [card[v] for v in scope]) / 4.0
            t[rng.random(t.shape) < 0.08] = -np.inf
            pots.append((scope, t))
        logp = sum(t[tuple(states[:, v] for v in scope)] for scope, t in pots)
        if not np.isfinite(logp).any():
            continue
        x, best = map_tables_rc2(card, pots, "test")
        assert abs(best - logp.max()) < 1e-9
        assert abs(sum(t[tuple(x[list(scope)])] for scope, t in pots) - best) < 1e-9


corridor_rows_floor = dense_floor  # the benchmark's dense layout (semmap_pp/knowledge/layouts.py)


def check_valid(r, ev):
    for u in ev.units:
        p = r.types[u]
        assert p.shape == (4,) and np.all(p >= 0) and np.all(p <= 1) and abs(p.sum() - 1) < 1e-9
    assert set(r.sale) == set(ev.adj) and all(0 <= v <= 1 for v in r.sale.values())
    assert set(r.map_types) == set(ev.units)


@pytest.mark.parametrize("n", [40, 80])
def test_dense_floors_that_used_to_raise_get_marginals_in_time(n):
    rules = load_rules("rules/table3.lp")
    ev = corridor_rows_floor(n)
    engine = KnowledgeEngine(rules)
    card, sum_pots = engine.local.reduced(ev)     # the network inference used to run on
    with pytest.raises(TooDense, match="too densely connected"):
        JunctionTree(card, [s for s, _ in sum_pots], rules.path, max_states=MAX_CLIQUE_STATES)
    r = engine.infer(ev)            # templates built here
    assert r.method == "lbp"
    check_valid(r, ev)
    # the MAP is exact: RC2's optimum of the ground network, soft evidence summed out
    rc2 = KnowledgeEngine(rules, map_method="rc2", method="lbp").infer(ev)
    assert rc2.map_method == "rc2" and abs(r.map_cost - rc2.map_cost) < 1e-5
    best = np.inf
    for _ in range(3):
        engine._cache.clear()
        t = time.perf_counter()
        again = engine.infer(ev)
        best = min(best, time.perf_counter() - t)
    assert all(np.array_equal(again.types[u], r.types[u]) for u in ev.units)
    assert again.sale == r.sale and again.map_types == r.map_types
    assert best < 0.1   # measured 2-7 ms on a loaded 2-core machine (docs/benchmarks.md)


def alone(ev, u):
    """The evidence of unit ``u`` without its neighbours."""
    kw = {name: {v: p for v, p in ev.unary(name) if v == u}
          for name in ("rolike", "colike", "halike", "muldoor")}
    return Evidence.build([u], **kw)


@pytest.mark.parametrize("rule_file", ["rules/none.lp", "unit_rules"])
def test_rules_without_pair_terms_give_independent_units_on_80_units(rule_file, tmp_path):
    # no pair rule: every unit's marginal is what its own evidence gives it alone, exactly;
    # "unit_rules" is table3's reasoning on type (unit rules only), so the marginals differ
    # from unit to unit
    if rule_file == "unit_rules":
        text = open("rules/table3.lp").read()
        rule_file = tmp_path / "unit_rules.lp"
        rule_file.write_text(text[:text.index("% ---- reasoning on SaLe")])
    ev = corridor_rows_floor(80)
    engine = KnowledgeEngine.from_file(rule_file)
    r = engine.infer(ev)
    check_valid(r, ev)
    assert r.method == "exact" and r.map_method == "jt"
    tn = engine.local.type_network(ev)
    assert tn.sum_pairs == [] and tn.max_pairs == []
    for u in ev.units:
        one = engine.infer(alone(ev, u))
        np.testing.assert_allclose(r.types[u], one.types[u], atol=1e-12)
        assert r.map_types[u] == one.map_types[u]
    assert all(abs(v - 0.5) < 1e-12 for v in r.sale.values())
