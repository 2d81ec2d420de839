"""Exact marginals, MC-SAT and MAP against an enumeration oracle.

The oracle is independent of the factor network: clingo enumerates every stable model (world)
of frame + rules + evidence with its cost, and marginals are sums of exp(-cost) over worlds.
"""

from collections import OrderedDict

import clingo
import numpy as np
import pytest

from semmap_pp.errors import RuleError
from semmap_pp.knowledge import Evidence, KnowledgeEngine, load_rules, mcsat
from semmap_pp.knowledge.evidence import ground_facts
from semmap_pp.knowledge.ground import FRAME, ground
from semmap_pp.knowledge.exact import JunctionTree
from semmap_pp.knowledge.map import map_clingo, map_rc2
from semmap_pp.knowledge.mcsat import ClauseStack, ClauseTemplate, MCSATSettings
from semmap_pp.knowledge.mcsat_tree import BatchTree, pick

RULE_FILES = ["rules/table3.lp", "rules/halls_to_corridors.lp", "rules/none.lp"]
TYPES = ("room", "corr", "hall", "other")


def worlds_of(rules, ev):
    """Every world (stable model) of frame + rules + evidence with its cost, by clingo."""
    ctl = clingo.Control(["--warn=none", "--models=0", "--opt-mode=enum,1000000000"])
    ctl.add("base", [], FRAME + rules.program + ground_facts(ev))
    ctl.ground([("base", [])])
    worlds = []
    ctl.solve(on_model=lambda m: worlds.append(
        (m.symbols(atoms=True), m.cost[0] if m.cost else 0)))
    return worlds


def _query(syms, ev):
    """The query atoms of a world: each unit's type and the open SaLe atoms that hold."""
    types, sale = {}, set()
    for s in syms:
        if s.name in TYPES and len(s.arguments) == 1:
            types[s.arguments[0].number] = TYPES.index(s.name)
        elif s.name == "sale":
            sale.add((s.arguments[0].number, s.arguments[1].number))
    return tuple(types[u] for u in ev.units), frozenset(sale)


def oracle(rules, ev):
    """Brute force: every world with its weight, by clingo's model enumeration. Returns the type
    and SaLe marginals, the lowest cost of a world (thousandths), log Z and the world count."""
    worlds = worlds_of(rules, ev)
    costs = np.array([c for _, c in worlds], dtype=float)
    w = np.exp(-(costs - costs.min()) / 1000.0)
    z = w.sum()
    types = {u: np.zeros(4) for u in ev.units}
    sale = {pq: 0.0 for pq in ev.adj}
    for (syms, _), wi in zip(worlds, w):
        for s in syms:
            if s.name in TYPES and len(s.arguments) == 1:
                types[s.arguments[0].number][TYPES.index(s.name)] += wi / z
            elif s.name == "sale" and (s.arguments[0].number, s.arguments[1].number) in sale:
                sale[(s.arguments[0].number, s.arguments[1].number)] += wi / z
    log_z = np.log(z) - costs.min() / 1000.0
    return types, sale, costs.min(), log_z, len(worlds)


def oracle_map(rules, ev):
    """Brute-force MAP of the query atoms: the worlds grouped by their types and SaLe atoms,
    each group's weight the sum over its soft evidence atoms. Returns the best group's cost
    (``-1000 log`` of its summed weight, thousandths) and the type tuples (``ev.units`` order,
    ``TYPES`` indices) of the groups within 1e-6 of it."""
    groups: dict = {}
    for syms, cost in worlds_of(rules, ev):
        key = _query(syms, ev)
        groups[key] = groups.get(key, 0.0) + np.exp(-cost / 1000.0)
    costs = {k: -1000.0 * np.log(v) for k, v in groups.items()}
    best = min(costs.values())
    return best, {k[0] for k, c in costs.items() if c <= best + 1e-6}


def _map_tuple(r, ev):
    return tuple(TYPES.index({"corridor": "corr"}.get(r.map_types[u], r.map_types[u]))
                 for u in ev.units)


def assert_matches_brute_force(r, rules, ev):
    """``r`` (an exact InferenceResult of ``ev``) against enumeration: type and SaLe marginals,
    log Z, and the MAP (its cost and types among the optimal ones)."""
    types, sale, _, log_z, _ = oracle(rules, ev)
    for u in ev.units:
        np.testing.assert_allclose(r.types[u], types[u], atol=1e-9)
    for pq in ev.adj:
        assert abs(r.sale[pq] - sale[pq]) < 1e-9
    assert abs(r.log_z - log_z) < 1e-9
    map_best, map_types = oracle_map(rules, ev)
    assert abs(r.map_cost * 1000 - map_best) < 1e-6 and _map_tuple(r, ev) in map_types


def random_evidence(rng, max_worlds=2 ** 13):
    while True:
        n = int(rng.integers(1, 7))
        units = list(range(1, n + 1))
        pairs = [(p, q) for p in units for q in units if p < q and rng.random() < 0.5]
        kw = {}
        n_soft = 0
        for name in ("rolike", "colike", "halike", "muldoor"):
            d = {}
            for u in units:
                r = rng.random()
                if r < 0.25:
                    d[u] = 1.0
                elif r < 0.3:
                    d[u] = round(float(rng.uniform(0.05, 0.95)), 2)
                    n_soft += 1
            kw[name] = d
        # directed SaLe atoms are tied by symmetry in table3/halls; none.lp has one per pair
        if 4 ** n * 2 ** (len(pairs) + n_soft) <= max_worlds:
            return Evidence.build(units, adj=pairs, **kw)


def cases(seed, k):
    rng = np.random.default_rng(seed)
    return [random_evidence(rng) for _ in range(k)]


@pytest.mark.slow
@pytest.mark.parametrize("rule_file", RULE_FILES)
def test_exact_matches_enumeration(rule_file):
    rules = load_rules(rule_file)
    engine = KnowledgeEngine(rules, method="exact")
    for ev in cases(1, 8):
        types, sale, _, log_z, _ = oracle(rules, ev)
        r = engine.infer(ev)
        for u in ev.units:
            np.testing.assert_allclose(r.types[u], types[u], atol=1e-9)
        for pq in ev.adj:
            assert abs(r.sale[pq] - sale[pq]) < 1e-9
        assert abs(r.log_z - log_z) < 1e-9


@pytest.mark.slow
@pytest.mark.parametrize("rule_file", RULE_FILES[:2])
def test_map_engines_reach_the_minimum_cost(rule_file):
    # clingo and RC2 on the ground network minimise the cost of a whole world (soft evidence
    # atoms included); the engine's MAP maximises the types and SaLe with the soft evidence
    # atoms summed out, by every path: the junction tree on templates (pairwise rules) or on
    # the ground network, RC2 on the ground network's tables
    rules = load_rules(rule_file)
    n_soft = 0
    for ev in cases(2, 8):
        _, _, best, _, _ = oracle(rules, ev)
        g = ground(rules, ev, keep_control=True)
        xc, cc = map_clingo(g)
        xr, cr = map_rc2(g.network)
        assert cc == best and cr == best
        assert g.network.cost(xc) == best and g.network.cost(xr) == best
        map_best, map_types = oracle_map(rules, ev)
        soft = any(0 < p < 1 for name in ("rolike", "colike", "halike", "muldoor")
                   for _, p in ev.unary(name))
        n_soft += soft
        if not soft:
            assert abs(map_best - best) < 1e-6
        for engine in (KnowledgeEngine(rules), KnowledgeEngine(rules, fast=False),
                       KnowledgeEngine(rules, map_method="rc2")):
            r = engine.infer(ev)
            assert abs(r.map_cost * 1000 - map_best) < 1e-3, (engine.map_method, engine.local)
            assert _map_tuple(r, ev) in map_types
    assert n_soft >= 3


def test_rc2_map_keeps_hard_rules_that_the_soft_ones_would_break(tmp_path):
    """Soft rules that pay for corridors next to corridors and for a hall with no corridor
    beside it, hard rules that forbid a corridor with many doors and two adjacent halls: RC2 on
    the ground network (hard factors' forbidden states as boxes of hard clauses) reaches
    clingo's minimum cost and breaks no hard rule, on random hard evidence (without the hard
    clauses it breaks them: checked by deleting them)."""
    path = tmp_path / "clash.lp"
    path.write_text(
        "nextcorr(U) :- adj(U,V), corr(V).\n"
        ":~ colike(U), not corr(U). [2000@0, c, U]\n"
        ":~ hall(U), not nextcorr(U). [700@0, h, U]\n"
        ":~ corr(P), corr(Q), adj(P,Q). [300@0, cc, P, Q]\n"
        ":- corr(U), muldoor(U).\n"
        ":- hall(P), hall(Q), adj(P,Q).\n"
        ":- halike(U), room(U).\n")
    rules = load_rules(path)
    rng = np.random.default_rng(3)
    for _ in range(12):
        n = int(rng.integers(3, 7))
        units = range(1, n + 1)
        adj = [(p, q) for p in units for q in units if p < q and rng.random() < 0.5]
        ev = Evidence.build(units, colike=[u for u in units if rng.random() < 0.6],
                            muldoor=[u for u in units if rng.random() < 0.4],
                            halike=[u for u in units if rng.random() < 0.4], adj=adj)
        g = ground(rules, ev, keep_control=True)
        _xc, cc = map_clingo(g)
        xr, cr = map_rc2(g.network)
        assert cr == cc and g.network.cost(xr) == cc


def test_clingo_map_refuses_soft_evidence_it_would_maximise():
    rules = load_rules("rules/table3.lp")
    engine = KnowledgeEngine(rules, map_method="clingo")
    assert engine.infer(Evidence.build([1], rolike={1})).map_types == {1: "room"}
    with pytest.raises(RuleError, match="sum.*soft evidence|soft evidence.*'jt' or 'rc2'"):
        engine.infer(Evidence.build([1], rolike={1: 0.6}))


def test_a_unit_on_the_corridor_ratio_boundary_gets_its_most_probable_type():
    # Table 4 near a ratio of 3: room-like and corridor-like each 0.475, hall-like 0.05, with
    # multiple doors. Maximising the three soft atoms too would pick "no class" (0.525^2 0.95,
    # the likeliest atom state), which no rule reads, and type the unit by tie-breaking (room,
    # the first). Summed out, the MAP is the marginals' argmax, corridor (aces' corridor pieces).
    from semmap_pp.target.geometry_evidence import soft_probabilities
    from semmap_pp.model import load_model
    # a 1.15 x 3.45 m unit at 0.05 m (23 x 69 cells: aces' piece east of its roundabout)
    p = soft_probabilities(np.array([[0, 0, 23, 69]]), 0.05, load_model().evidence)[0]
    np.testing.assert_allclose(p, [0.475, 0.475, 0.05])
    rules = load_rules("rules/table3.lp")
    ev = Evidence.build([1], rolike={1: float(p[0])}, colike={1: float(p[1])},
                        halike={1: float(p[2])}, muldoor={1})
    for engine in (KnowledgeEngine(rules), KnowledgeEngine(rules, fast=False),
                   KnowledgeEngine(rules, map_method="rc2"), KnowledgeEngine(rules, method="mcsat")):
        r = engine.infer(ev)
        assert r.map_types == {1: "corridor"}
        if engine.method != "mcsat":
            assert int(np.argmax(r.types[1])) == 1
    best, types = oracle_map(rules, ev)
    assert types == {(1,)}


@pytest.mark.slow
@pytest.mark.parametrize("rule_file", RULE_FILES[:2])
def test_mcsat_default_settings_close_to_enumeration(rule_file):
    rules = load_rules(rule_file)
    engine = KnowledgeEngine(rules, method="mcsat")
    worst = 0.0
    for ev in cases(3, 5):
        types, sale, _, _, _ = oracle(rules, ev)
        r = engine.infer(ev)
        for u in ev.units:
            worst = max(worst, np.abs(r.types[u] - types[u]).max())
        for pq in ev.adj:
            worst = max(worst, abs(r.sale[pq] - sale[pq]))
    assert worst < 0.03


def test_mcsat_is_a_deterministic_function_of_the_evidence():
    rules = load_rules("rules/table3.lp")
    ev = Evidence.build([1, 2, 3], rolike={1}, colike={2}, muldoor={2}, adj=[(1, 2), (2, 3)])
    a = KnowledgeEngine(rules, method="mcsat").infer(ev)
    b = KnowledgeEngine(rules, method="mcsat").infer(ev)
    for u in ev.units:
        assert np.array_equal(a.types[u], b.types[u])
    other = KnowledgeEngine(rules, method="mcsat", seed=1).infer(ev)
    assert any(not np.array_equal(a.types[u], other.types[u]) for u in ev.units)


def test_none_is_uniform_and_table3_points_to_the_rules():
    ev = Evidence.build([1, 2], halike={1}, rolike={2}, adj=[(1, 2)])
    flat = KnowledgeEngine.from_file("rules/none.lp").infer(ev)
    np.testing.assert_allclose(flat.types[1], 0.25, atol=1e-12)
    assert abs(flat.sale[(1, 2)] - 0.5) < 1e-12
    t3 = KnowledgeEngine.from_file("rules/table3.lp").infer(ev)
    assert t3.map_types == {1: "hall", 2: "room"}
    assert t3.types[1][2] > 0.8 and t3.sale[(1, 2)] < 0.5


def test_soft_evidence_probability_is_the_marginal_without_rules():
    # no rule touches muldoor in none.lp, so the soft atom keeps its probability; in table3 a
    # soft MulDoor on a room-like unit moves mass from room to other.
    hard = KnowledgeEngine.from_file("rules/table3.lp").infer(Evidence.build([1], rolike={1}))
    soft = KnowledgeEngine.from_file("rules/table3.lp").infer(
        Evidence.build([1], rolike={1}, muldoor={1: 0.9}))
    assert soft.types[1][3] > hard.types[1][3] and soft.types[1][0] < hard.types[1][0]


def test_cache_returns_the_same_result_and_is_bounded():
    engine = KnowledgeEngine.from_file("rules/table3.lp", cache_size=2)
    evs = [Evidence.build(range(1, k + 1)) for k in (1, 2, 3)]
    first = engine.infer(evs[0])
    assert engine.infer(Evidence.build([1])) is first and engine.hits == 1
    engine.infer(evs[1])
    engine.infer(evs[2])
    assert len(engine._cache) == 2 and engine.infer(evs[0]) is not first


def test_contradictory_hard_rules_name_the_file(tmp_path):
    f = tmp_path / "contra.lp"
    f.write_text(":- rolike(U), not room(U).\n:- rolike(U), room(U).\n")
    engine = KnowledgeEngine.from_file(f)
    with pytest.raises(Exception) as exc:
        engine.infer(Evidence.build([1], rolike={1}))
    assert str(f) in str(exc.value) and "no world" in str(exc.value)


@pytest.mark.slow
def test_mcsat_general_path_close_to_enumeration_on_table3():
    # the same rules through the ground network (no fast path): SaLe atoms are tree variables
    rules = load_rules("rules/table3.lp")
    engine = KnowledgeEngine(rules, method="mcsat", fast=False)
    assert engine.local is None
    worst = 0.0
    for ev in cases(4, 3):
        types, sale, _, _, _ = oracle(rules, ev)
        r = engine.infer(ev)
        worst = max([worst] + [np.abs(r.types[u] - types[u]).max() for u in ev.units]
                    + [abs(r.sale[pq] - sale[pq]) for pq in ev.adj])
    assert worst < 0.03


def test_mcsat_contradictory_hard_rules_name_the_file(tmp_path):
    f = tmp_path / "contra.lp"
    f.write_text(":- rolike(U), not room(U).\n:- rolike(U), room(U).\n")
    engine = KnowledgeEngine.from_file(f, method="mcsat")
    with pytest.raises(RuleError) as exc:
        engine.infer(Evidence.build([1], rolike={1}))
    assert str(f) in str(exc.value) and "no world" in str(exc.value)


def test_mcsat_rejects_a_burn_in_as_long_as_the_run():
    engine = KnowledgeEngine.from_file("rules/table3.lp", method="mcsat",
                                       mcsat=MCSATSettings(n_iter=5, burn_in=5))
    with pytest.raises(RuleError, match="burn_in"):
        engine.infer(Evidence.build([1], rolike={1}))


def test_pick_never_draws_a_state_of_zero_weight():
    # zero weights first, in the middle and last; u close to 1 must not run past the last
    # positive state, u = 0 must skip the leading zeros
    probs = np.array([[0, 0, 1], [2, 0, 0], [0, 3, 0], [1, 0, 0]], dtype=np.float32)
    u = np.array([1 - 2.0 ** -53, 0.0, 0.5])
    marg = np.zeros((4, 3))
    idx = pick(probs, u, marg)
    assert idx.tolist() == [3, 2, 0]
    np.testing.assert_allclose(marg, probs / probs.sum(axis=0))


def test_equal_clauses_merge_and_inert_clauses_drop():
    # one binary scope variable; clause a and b both forbid state 1, c forbids nothing, d
    # forbids both states (never satisfied, so never kept)
    viol = np.array([[0, 1], [0, 1], [0, 0], [1, 1]], dtype=bool)
    t = ClauseTemplate((2,), 1, np.ones(2, dtype=bool), viol, [1000, 500, 700, 900])
    assert t.k == 1
    # kept together with probability 1 - e^-(w_a + w_b): outcome 1 of the alias table (slot i
    # keeps i with probability q[i], else gives alias[i])
    (_c0, n, cut, alias), = ClauseStack([t]).chunks[0]
    q = cut - np.arange(n)
    outcome = (q + np.bincount(alias, weights=1 - q, minlength=n)) / n
    assert abs(outcome[1] - (1 - np.exp(-1.5))) < 1e-12
    # weights of the states by the block alone: state 1 violates the merged clause
    np.testing.assert_allclose(t.prior / t.prior.sum(), [1 / (1 + np.exp(-1.5)),
                                                         np.exp(-1.5) / (1 + np.exp(-1.5))])


def test_count_table_matches_the_direct_count(monkeypatch):
    rng = np.random.default_rng(5)
    # scope (3 states) x private atoms (2 states); hard forbids (2, 1); two templates stacked
    hard = np.ones(6, dtype=bool)
    hard[5] = False
    viols = [rng.random((5, 6)) < 0.4, rng.random((3, 6)) < 0.5]
    weights = [[800, 1200, 300, 2000, 50], [400, 900, 1500]]
    tpls = [ClauseTemplate((3,), 2, hard, v, w) for v, w in zip(viols, weights)]
    with_lut = ClauseStack(tpls)
    monkeypatch.setattr(mcsat, "LUT_BITS", 0)
    direct = ClauseStack(tpls)
    assert with_lut.lut is not None and direct.lut is None
    tids = np.array([0, 1, 1, 0])
    off = with_lut.offsets(tids)
    words = [rng.integers(0, 1 << with_lut.k, size=(4, 7))]
    np.testing.assert_array_equal(with_lut.counts(words, 4, 7, off),
                                  direct.counts(words, 4, 7, off))
    assert with_lut.counts(words, 4, 7, off).shape == (4, 3, 7)
    # the count by hand for instance 1 (template 1) in chain 2: bit c of the word keeps the
    # template's (merged) clause c
    w, t = int(words[0][1, 2]), tpls[1]
    hand = [sum(bool(hard.reshape(3, 2)[s, a]) and not any(
        t.viol[c, a, s] and (w >> c) & 1 for c in range(t.k)) for a in range(2))
        for s in range(3)]
    assert direct.counts(words, 4, 7, off)[1, :, 2].tolist() == hand


def test_slice_draw_is_uniform_over_the_solutions():
    # two 3-state variables, the table allows 5 of the 9 pairs; with a private atom of two
    # states on (0, 0) the solution (0, 0) counts twice
    counts = np.array([[2, 1, 0], [0, 1, 0], [1, 0, 1]], dtype=np.float32)
    scopes = [np.array([[0, 1]])]
    B = 20000
    jt = JunctionTree([3, 3], [(0, 1)])
    tree = BatchTree([3, 3], scopes, jt, B)
    table = np.broadcast_to(counts.reshape(1, 9, 1), (1, 9, B))
    assert tree.upward([table], check=True)
    marg = [np.zeros((3, B)), np.zeros((3, B))]
    x = tree.sample(np.random.default_rng(0), marg)
    freq = np.bincount(x[0] * 3 + x[1], minlength=9) / B
    np.testing.assert_allclose(freq, counts.reshape(-1) / counts.sum(), atol=0.015)
    # the Rao-Blackwell terms average to the exact marginals of the uniform solution
    np.testing.assert_allclose(marg[0].mean(axis=1), counts.sum(axis=1) / counts.sum(),
                               atol=0.015)
    np.testing.assert_allclose(marg[1].mean(axis=1), counts.sum(axis=0) / counts.sum(),
                               atol=0.015)


def test_mcsat_with_more_clauses_than_one_word_matches_the_exact_distribution():
    # one 8-state variable under 70 distinct soft clauses: two words of clause bits, no count
    # table; P(s) is proportional to exp(-sum of the weights of the clauses s violates)
    rng = np.random.default_rng(11)
    sets = set()
    while len(sets) < 70:
        bits = tuple(bool(b) for b in rng.random(8) < 0.3)
        if 0 < sum(bits) < 8:
            sets.add(bits)
    viol = np.array(sorted(sets))
    weights = rng.integers(100, 1500, size=len(viol))
    tpl = ClauseTemplate((8,), 1, np.ones(8, dtype=bool), viol, weights)
    assert tpl.k == 70
    blocks, _ = mcsat.stack_blocks([(tpl, [0])])
    assert len(blocks[0].stack.masks) == 2 and blocks[0].stack.lut is None
    marg, _ = mcsat.run_mcsat([8], blocks, np.random.default_rng(0), 2000, 30, 10)
    p = np.exp(-(viol * weights[:, None]).sum(axis=0) / 1000.0)
    np.testing.assert_allclose(marg[0], p / p.sum(), atol=0.02)


def test_pairs_reading_soft_atoms_keep_them_in_the_unit_variable(tmp_path):
    # a pair rule on a soft evidence atom: that unit's variable keeps the atom (type x MulDoor),
    # units whose soft atoms no pair reads are collapsed to their type; both exact vs enumeration
    f = tmp_path / "soft_pair.lp"
    f.write_text(":~ muldoor(P), room(Q), adj(P,Q). [800@0, md_room, P, Q]\n"
                 ":~ room(P), room(Q), adj(P,Q), not sale(P,Q). [1100@0, rr, P, Q]\n"
                 ":~ rolike(U), not room(U). [1500@0, r, U]\n")
    rules = load_rules(f)
    ev = Evidence.build([1, 2, 3], rolike={2: 0.6, 3: 1.0}, muldoor={1: 0.7},
                        adj=[(1, 2), (2, 3), (1, 3)])
    engine = KnowledgeEngine(rules, method="exact")
    tn = engine.local.type_network(ev)
    assert tn.shift == [1, 0, 0] and tn.card == [8, 4, 4]
    types = oracle(rules, ev)[0]
    r = engine.infer(ev)
    # the MAP sums unit 1's MulDoor atom out, which couples it to its neighbours: the ground
    # network's junction tree gives it
    assert_matches_brute_force(r, rules, ev)
    lbp = KnowledgeEngine(rules, method="lbp").infer(ev)
    assert max(np.abs(lbp.types[u] - types[u]).max() for u in ev.units) < 0.02
    assert lbp.map_types == r.map_types


def test_auto_is_exact_below_its_clique_bound_and_bitwise_equal_to_exact():
    rules = load_rules("rules/table3.lp")
    auto, exact = KnowledgeEngine(rules), KnowledgeEngine(rules, method="exact")
    for ev in cases(7, 6):
        a, e = auto.infer(ev), exact.infer(ev)
        assert a.method == "exact"
        assert all(np.array_equal(a.types[u], e.types[u]) for u in ev.units)
        assert a.sale == e.sale and a.map_types == e.map_types and a.log_z == e.log_z


@pytest.mark.slow
def test_a_soft_atom_tied_to_many_units_is_summed_out_exactly_or_kept_and_maximised(tmp_path):
    # a pair rule reads the hub's soft corridor-likeness against each neighbour's type: summing
    # the atom out joins the hub's factors into one over every neighbour's type
    f = tmp_path / "hub.lp"
    f.write_text(":~ colike(U), adj(U,V), room(V). [700@0, cr, U, V]\n"
                 ":~ rolike(U), not room(U). [1500@0, r, U]\n")
    rules = load_rules(f)

    def star(n):
        return Evidence.build(list(range(1, n + 2)), colike={1: 0.6},
                              rolike={u: 0.7 for u in range(2, n + 2)},
                              adj=[(1, u) for u in range(2, n + 2)])

    small = star(3)                       # 2 x 4^3 states: summed out exactly
    r = KnowledgeEngine(rules).infer(small)
    best, types = oracle_map(rules, small)
    assert r.map_method == "jt" and abs(r.map_cost * 1000 - best) < 1e-6
    assert _map_tuple(r, small) in types
    big = star(11)                        # 2 x 4^11 = 8.4M > 4M states: kept, maximised
    r = KnowledgeEngine(rules).infer(big)
    assert r.map_method == "jt+max"
    assert set(r.map_types) == set(big.units) and all(np.isfinite(r.types[u]).all() for u in big.units)


@pytest.mark.slow
def test_a_derived_atom_over_many_units_is_a_chain_with_the_same_distribution(monkeypatch):
    # halls_to_corridors.lp's nextcorr(U) :- adj(U,V), corr(V). is the OR over U's neighbours'
    # types; read inline, hall(U), not nextcorr(U) at a corridor with eight neighbours is one
    # table of 4 x 4^8 states, above the limit: cartesium under this file failed. As a chain of
    # auxiliary variables it is exact: with the chain forced on every derived atom of two or
    # more bodies, marginals, log Z and the MAP equal brute force
    import semmap_pp.knowledge.ground as ground_module

    rules = load_rules("rules/halls_to_corridors.lp")
    star = Evidence.build(list(range(1, 11)), halike={1}, rolike=set(range(2, 11)),
                          adj=[(1, u) for u in range(2, 11)])
    g = ground(rules, star)
    assert len(g.network.aux) == 9 and KnowledgeEngine(rules).infer(star).map_types[1] == "hall"
    monkeypatch.setattr(ground_module, "CHAIN_STATES", 4)
    engine = KnowledgeEngine(rules, method="exact")
    chained = 0
    for ev in cases(5, 8):
        chained += len(ground(rules, ev).network.aux) > 0
        assert_matches_brute_force(engine.infer(ev), rules, ev)
    assert chained >= 4


@pytest.mark.slow
def test_one_grounding_per_structure_with_any_soft_values(monkeypatch):
    """The ground program depends on the evidence's structure alone (soft atoms only open and
    weigh): a cache grounds each structure once, and every evidence of that structure, whatever
    its soft probabilities, gets the network of a grounding with its own weights (each
    assignment's cost equal) and, through the engine, the brute-force marginals, log Z and MAP."""
    import semmap_pp.knowledge.ground as ground_module
    rules = load_rules("rules/halls_to_corridors.lp")
    calls = []
    real = ground_module._clingo_ground
    monkeypatch.setattr(ground_module, "_clingo_ground", lambda *a: calls.append(1) or real(*a))
    cache = OrderedDict()
    engine = KnowledgeEngine(rules, method="exact")
    rng = np.random.default_rng(17)
    for probs in ((0.3, 0.8), (0.05, 0.95), (0.62, 0.5), (0.3, 0.8)):
        ev = Evidence.build([1, 2, 3], rolike={1: probs[0], 2: 1.0}, colike={3: probs[1]},
                            muldoor={2: 0.7}, adj=[(1, 2), (2, 3)])
        net = ground(rules, ev, cache=cache).network
        with_weights = ground(rules, ev, keep_control=True).network
        assert list(net.names) == list(with_weights.names)
        for _ in range(200):
            x = [int(rng.integers(c)) for c in net.card]
            assert net.cost(x) == with_weights.cost(x)
        assert_matches_brute_force(engine.infer(ev), rules, ev)
    # one structure: the cache grounded once, the keep_control groundings 4 times, the engine
    # (its own cache) once
    assert len(calls) == 1 + 4 + 1
