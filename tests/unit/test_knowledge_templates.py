"""The engine's shortcuts against the full computation: unit templates from the grounded
template of their structure plus the soft weights, pair templates shared by every soft value of
the same structure, and the MAP types without the marginals (``KnowledgeEngine.map_types``)."""

import itertools

import numpy as np
import pytest

import semmap_pp.knowledge.engine_ground as engine_ground
from semmap_pp.knowledge import Evidence, KnowledgeEngine, load_rules
from semmap_pp.knowledge.local import LocalModel

RULES = "rules/table3.lp"
PROBS = (0.0, 1.0, 0.05, 0.35, 0.5, 0.7, 0.95)


def test_unit_template_equals_its_own_grounding():
    """For soft, hard and absent evidence atoms in every combination, the unit table built
    from the structure's template equals a clingo grounding of that very pattern."""
    model = LocalModel(load_rules(RULES))
    worst = 0.0
    for key in itertools.product((0.0, 1.0, 0.05, 0.62), (0.0, 0.35, 0.95), (0.0, 1.0, 0.2),
                                 (0.0, 1.0, 0.8)):
        table, k = model.unit(key)
        direct, k_direct = model.ground_unit(key)
        assert k == k_direct
        fin = np.isfinite(direct)
        assert np.array_equal(np.isfinite(table), fin)
        worst = max(worst, float(np.abs(table[fin] - direct[fin]).max()))
    assert worst < 1e-12


def test_soft_values_share_one_grounding_per_structure():
    """Many soft values of one structure: clingo grounds the structure's unit and pair
    templates once, and every result equals the general path (full grounding per evidence)."""
    rules = load_rules(RULES)
    fast, general = KnowledgeEngine(rules, method="exact"), KnowledgeEngine(rules, method="exact",
                                                                            fast=False)
    rng = np.random.default_rng(3)
    for _ in range(25):
        ro = {u: float(rng.choice(PROBS[2:])) for u in (1, 2, 3)}
        co = {u: float(rng.choice(PROBS[2:])) for u in (1, 2, 3)}
        ev = Evidence.build([1, 2, 3, 4], rolike=ro, colike=co, halike={4: 1.0},
                            muldoor={2: 1.0}, adj=[(1, 2), (2, 3), (3, 4), (1, 4)])
        a, b = fast.infer(ev), general.infer(ev)
        for u in ev.units:
            np.testing.assert_allclose(a.types[u], b.types[u], atol=1e-9)
        for pq in ev.adj:
            assert abs(a.sale[pq] - b.sale[pq]) < 1e-9
        assert a.map_types == b.map_types and abs(a.log_z - b.log_z) < 1e-9
    # structures: soft ro+co (with and without a hard muldoor) and the hard-halike unit
    assert fast.local.groundings <= 3 + 6


def _random_evidence(rng, max_units, p_adj):
    """Up to ``max_units`` units, each pair adjacent with probability ``p_adj``, every evidence
    atom drawn from :data:`PROBS` (absent, hard or soft)."""
    units = list(range(int(rng.integers(1, max_units + 1))))
    pairs = [(p, q) for p in units for q in units if p < q and rng.random() < p_adj]
    kw = {name: {u: float(rng.choice(PROBS)) for u in units}
          for name in ("rolike", "colike", "halike", "muldoor")}
    return Evidence.build(units, adj=pairs, **kw)


@pytest.mark.slow
def test_map_types_equal_the_full_inference():
    """``map_types`` on a fresh engine (no marginals computed) equals ``infer().map_types``
    of another fresh engine, and ``infer`` after ``map_types`` gives the same result as
    without it (the MAP decoding is reused, not changed)."""
    rules = load_rules(RULES)
    rng = np.random.default_rng(5)
    for _ in range(30):
        ev = _random_evidence(rng, 7, 0.4)
        units = ev.units
        first, second, third = (KnowledgeEngine(rules) for _ in range(3))
        assert first.has_map_only
        m = first.map_types(ev)
        r = second.infer(ev)
        assert m == r.map_types
        r1 = first.infer(ev)
        assert r1.map_types == r.map_types and r1.map_cost == r.map_cost
        assert r1.sale == r.sale and all(np.array_equal(r1.types[u], r.types[u]) for u in units)
        assert third.infer(ev).map_types == third.map_types(ev)   # from the result cache
    mcsat = KnowledgeEngine(rules, method="mcsat")
    assert not mcsat.has_map_only


def test_map_types_of_the_general_path_equal_the_full_inference(monkeypatch):
    """The same on the general path (rules that are not pairwise-local: every evidence grounded
    by clingo): ``map_types`` grounds and decodes the MAP without marginals, equal to a fresh
    engine's ``infer``; ``infer`` afterwards reuses that grounding (no second one) and gives the
    same result as without it, with exact and with loopy-BP marginals."""
    rules = load_rules("rules/halls_to_corridors.lp")
    rng = np.random.default_rng(8)
    grounds = []
    real_ground = engine_ground.ground
    monkeypatch.setattr(engine_ground, "ground",
                        lambda *a, **k: grounds.append(1) or real_ground(*a, **k))
    for method in ("auto", "lbp"):
        for _ in range(12):
            ev = _random_evidence(rng, 6, 0.5)
            units = ev.units
            first, second = (KnowledgeEngine(rules, method=method) for _ in range(2))
            assert first.local is None and first.has_map_only
            grounds.clear()
            m = first.map_types(ev)
            assert len(grounds) == 1
            r1 = first.infer(ev)
            assert len(grounds) == 1          # the MAP's grounding reused
            r = second.infer(ev)
            assert m == r.map_types == r1.map_types and r1.map_cost == r.map_cost
            assert r1.method == r.method and r1.sale == r.sale
            assert all(np.array_equal(r1.types[u], r.types[u]) for u in units)
            assert first.map_types(ev) == m   # from the result cache
            assert len(grounds) == 2


def _evidences(n, seed):
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(n):
        ro = {u: float(rng.choice(PROBS)) for u in (1, 2, 3)}
        ha = {u: float(rng.choice(PROBS)) for u in (2, 3, 4)}
        md = {u: 1.0 for u in (1, 2, 3, 4) if rng.random() < 0.4}
        out.append(Evidence.build([1, 2, 3, 4], rolike=ro, halike=ha, muldoor=md,
                                  adj=[(1, 2), (2, 3), (3, 4), (1, 3)]))
    return out


@pytest.mark.slow
def test_template_store_gives_bitwise_the_grounded_templates(tmp_path):
    """A second engine on the same store grounds nothing and gives bitwise the results of an
    engine without a store; a damaged store file is ignored; another program has its own key."""
    rules = load_rules(RULES)
    evs = _evidences(20, 7)
    plain = KnowledgeEngine(rules, method="exact", template_store=False)
    first = KnowledgeEngine(rules, method="exact", template_store=tmp_path)
    ref = [plain.infer(ev) for ev in evs]
    for ev in evs:
        first.infer(ev)
    assert first.local.groundings > 0 and plain.local.store is None
    (store,) = tmp_path.glob("templates-*.npz")
    second = KnowledgeEngine(rules, method="exact", template_store=tmp_path)
    for ev, r in zip(evs, ref):
        got = second.infer(ev)
        assert got.map_types == r.map_types and got.log_z == r.log_z and got.sale == r.sale
        assert all(np.array_equal(got.types[u], r.types[u]) for u in ev.units)
    assert second.local.groundings == 0
    good = store.read_bytes()
    store.write_bytes(b"not an npz")
    third = KnowledgeEngine(rules, method="exact", template_store=tmp_path)
    assert third.infer(evs[0]).map_types == ref[0].map_types and third.local.groundings > 0
    for foreign in _foreign_stores(good, tmp_path):   # readable files of the wrong kind: ignored too
        store.write_bytes(foreign)
        fourth = KnowledgeEngine(rules, method="exact", template_store=tmp_path)
        assert fourth.infer(evs[0]).map_types == ref[0].map_types
        assert fourth.local.groundings > 0                  # nothing of it was used
    other = KnowledgeEngine(load_rules("rules/none.lp"), method="exact", template_store=tmp_path)
    assert other.local is None or other.local.store != third.local.store


def _foreign_stores(good: bytes, tmp_path) -> list[bytes]:
    """Stores that load but must not be used: another key, a table cut short, a pickled object
    array, a pickle; each written as bytes."""
    import io
    import pickle
    with np.load(io.BytesIO(good), allow_pickle=False) as z:
        arrays = {k: z[k] for k in z.files}
    out = []
    for change in ({"key": np.array("another")}, {"unit_tables": arrays["unit_tables"][:-1]},
                   {"pair_shapes": arrays["pair_shapes"] + 1},
                   {"unit_keys": np.array([object()] * 3, dtype=object)}):
        buf = io.BytesIO()
        np.savez(buf, **(arrays | change))
        out.append(buf.getvalue())
    out.append(pickle.dumps(({1: 2}, {})))
    return out


def test_a_planted_pickle_in_the_template_store_never_runs(tmp_path, capsys):
    """A pickle whose loading would run code, planted where the store lives under the store's
    own name (and under the name stores had before), is never unpickled."""
    import pickle
    rules = load_rules(RULES)
    probe = tmp_path / "ran"

    class Payload:
        def __reduce__(self):
            return (open, (str(probe), "w"))

    first = KnowledgeEngine(rules, method="exact", template_store=tmp_path)
    first.infer(_evidences(1, 3)[0])
    (store,) = tmp_path.glob("templates-*.npz")
    for name in (store.name, store.with_suffix(".pkl").name):
        (tmp_path / name).write_bytes(pickle.dumps(Payload()))
        again = KnowledgeEngine(rules, method="exact", template_store=tmp_path)
        again.infer(_evidences(1, 3)[0])
        assert not probe.exists()
    assert "template cache ignored" in capsys.readouterr().err




def test_template_store_directory_from_the_environment(monkeypatch, tmp_path):
    from semmap_pp.knowledge.local import STORE_ENV, default_store

    monkeypatch.setenv(STORE_ENV, str(tmp_path))
    assert default_store() == tmp_path
    monkeypatch.setenv(STORE_ENV, "off")
    assert default_store() is None
    assert KnowledgeEngine(load_rules(RULES)).local.store is None


def _random_walk(rng, steps, n_start=6, hard=()):
    """Evidences along random edits of one world: a unit's evidence changed, a unit added (with
    a few neighbours) or removed, a pair added or removed; the predicates in ``hard`` hard
    (1.0) or absent, never soft."""
    units = list(range(n_start))
    pairs = {(p, q) for p in units for q in units if p < q and rng.random() < 0.35}
    values = {name: {} for name in ("rolike", "colike", "halike", "muldoor")}

    def draw(u):
        for name, d in values.items():
            d[u] = (float(rng.random() < 0.3) if name == "muldoor" or name in hard
                    else float(rng.choice(PROBS)))

    for u in units:
        draw(u)
    nxt = n_start
    for _ in range(steps):
        op = rng.integers(0, 5)
        if op == 0 and units:
            draw(int(rng.choice(units)))
        elif op == 1 and len(units) < 14:
            u, nxt = nxt, nxt + 1
            for v in units:
                if rng.random() < 0.3:
                    pairs.add((v, u))
            units.append(u)
            draw(u)
        elif op == 2 and len(units) > 1:
            u = int(rng.choice(units))
            units.remove(u)
            pairs = {pq for pq in pairs if u not in pq}
        elif op == 3 and len(units) > 1:
            p, q = sorted(int(v) for v in rng.choice(units, 2, replace=False))
            pairs ^= {(p, q)}
        else:
            for u in rng.choice(units, min(3, len(units)), replace=False):
                draw(int(u))
        yield Evidence.build(sorted(units), adj=sorted(pairs),
                             **{k: {u: d[u] for u in units} for k, d in values.items()})


@pytest.mark.slow
def test_the_map_side_updated_along_edits_equals_the_one_built_from_scratch(tmp_path):
    """Random walks of edits (units and pairs added and removed, evidence changed) under the two
    pairwise-local rule sets of rules/, one with pair terms that depend on a neighbour's
    evidence, and one whose pair rule couples room pairs: the MAP side updated from the previous
    evidence equals, table for table and bit for bit, the one built from scratch; both are None
    exactly when a pair couples its units (or reads a unit's soft atoms); the MAP types are those of the full inference; and
    ``map_types(ev, base=...)`` equals the full inference's."""
    from semmap_pp.knowledge.local import map_net, map_net_update
    coupled = tmp_path / "coupled.lp"
    coupled.write_text(open(RULES).read() + "\n:~ room(P), room(Q), adj(P,Q). [300@0, rr, P, Q]\n")
    # pair terms that depend on a neighbour's evidence, count neighbours, and keep a unit's
    # soft atom in its variable when a neighbour has MulDoor (so a neighbour's edit changes the
    # unit's cut); Table 3's pair rules all involve SaLe, which the MAP side maximises out, so
    # no pair term survives there
    neighbourly = tmp_path / "neighbourly.lp"
    neighbourly.write_text(open(RULES).read()
                           + "\n:~ room(P), adj(P,Q), halike(Q). [300@0, rh, P, Q]"
                           "\n:~ corr(P), adj(P,Q). [200@0, ca, P, Q]"
                           "\n:~ adj(P,Q), muldoor(P), colike(Q). [100@0, mq, P, Q]\n")
    for path in (RULES, "rules/none.lp", str(neighbourly), str(coupled)):
        rules = load_rules(path)
        engine, full_engine = KnowledgeEngine(rules), KnowledgeEngine(rules)
        model = engine.local
        assert engine.has_map_only
        rng = np.random.default_rng(11)
        prev_ev = prev = None
        nets = coupled_nets = 0
        for ev in _random_walk(rng, 80, hard=("halike",) if path == str(neighbourly) else ()):
            full = map_net(model, ev)
            coupled_nets += full is None
            if prev is not None:
                inc = map_net_update(model, prev, ev)
                assert (inc is None) == (full is None)
                if full is not None:
                    nets += 1
                    for name in ("keys", "nbrs", "cut", "shift", "x"):
                        assert getattr(inc, name) == getattr(full, name), name
                    assert inc.umax.keys() == full.umax.keys()
                    assert all(np.array_equal(inc.umax[u], full.umax[u]) for u in full.umax)
            truth = full_engine.infer(ev).map_types
            if full is not None:
                assert full.map_types() == truth
            if prev_ev is not None:
                assert engine.map_types(ev, base=prev_ev) == truth
            prev_ev, prev = ev, full
        if path == str(coupled):
            assert coupled_nets > 60    # the general path (junction tree) for most
        elif path == str(neighbourly):
            # a unit whose soft atom a pair reads keeps it: summing it out for the MAP couples
            # the pair, so those evidences take the general path; the others are updated
            assert nets > 15 and coupled_nets > 30
        else:
            assert nets > 60 and coupled_nets == 0
