"""Evidence values, the facts syntax and the `semmap rules` command."""

import json
from pathlib import Path

import numpy as np
import pytest

from semmap_pp.cli import main
from semmap_pp.errors import EvidenceError
from semmap_pp.knowledge import Evidence, KnowledgeEngine, evidence_from_facts, evidence_to_facts


def test_build_canonicalises_pairs_and_drops_zero_probabilities():
    ev = Evidence.build([3, 1, 2], rolike={1: 0.0, 2: 1.0}, adj=[(3, 1), (1, 3), (2, 1)])
    assert ev.units == (1, 2, 3) and ev.rolike == ((2, 1.0),) and ev.adj == ((1, 2), (1, 3))
    assert ev == Evidence.build([1, 2, 3], rolike=[2], adj=[(1, 2), (1, 3)])


@pytest.mark.parametrize("kwargs, pattern", [
    (dict(units=[1], adj=[(1, 1)]), "not adjacent to itself"),
    (dict(units=[1], adj=[(1, 2)]), "unit 2 is not declared"),
    (dict(units=[1], rolike={2}), "unit 2 is not declared"),
    (dict(units=[1], muldoor={1: 1.5}), r"not in \[0, 1\]"),
    (dict(units=[1], muldoor={1: float("nan")}), r"not in \[0, 1\]"),
])
def test_build_rejects_bad_evidence(kwargs, pattern):
    with pytest.raises(EvidenceError, match=pattern):
        Evidence.build(**kwargs)


def test_facts_round_trip():
    ev = Evidence.build([1, 2, 5], colike={1}, muldoor={1: 0.35}, halike=[5], adj=[(5, 2)])
    assert evidence_from_facts(evidence_to_facts(ev)) == ev


@pytest.mark.parametrize("text, pattern", [
    ("unit(1). room(1).", r"ev\.lp:1:10: unknown evidence predicate room/1"),
    ("unit(1).\nrolike(X) :- unit(X).", r"ev\.lp:2:1: only ground evidence facts"),
    ('unit(1). soft(rolike(1), "high").', "probability must be"),
    ('unit(1). soft(rolike(1), 0).', "probability must be"),
    ("unit(1). rolike(1). rolike(1).", "given twice"),
    ('#include "x.lp".', r"ev\.lp:1:1: #include is not allowed"),
    ("unit(1). adj(1,2).", "unit 2 is not declared"),
    ("unit(1)", "syntax error"),
])
def test_bad_facts_are_rejected(text, pattern):
    with pytest.raises(EvidenceError, match=pattern):
        evidence_from_facts(text, "ev.lp")


def test_soft_evidence_without_rules_keeps_its_probability(tmp_path):
    ev = evidence_from_facts('unit(1). soft(muldoor(1), "0.3").')
    eng = KnowledgeEngine.from_file("rules/none.lp", fast=False)
    net_types = eng.infer(ev).types[1]
    np.testing.assert_allclose(net_types, 0.25, atol=1e-12)


def test_fast_and_general_paths_agree():
    rng = np.random.default_rng(7)
    fast = KnowledgeEngine.from_file("rules/table3.lp")
    slow = KnowledgeEngine.from_file("rules/table3.lp", fast=False)
    assert fast.local is not None and slow.local is None
    for _ in range(5):
        units = list(range(1, 9))
        adj = [(p, q) for p in units for q in units if p < q and rng.random() < 0.3]
        kw = {n: {u: float(rng.choice([1.0, 0.4])) for u in units if rng.random() < 0.3}
              for n in ("rolike", "colike", "halike", "muldoor")}
        ev = Evidence.build(units, adj=adj, **kw)
        a, b = fast.infer(ev), slow.infer(ev)
        for u in units:
            np.testing.assert_allclose(a.types[u], b.types[u], atol=1e-9)
        for pq in adj:
            assert abs(a.sale[pq] - b.sale[pq]) < 1e-9
        assert abs(a.log_z - b.log_z) < 1e-9 and abs(a.map_cost - b.map_cost) < 1e-9


def test_cli_check_and_query(tmp_path, capsys):
    assert main(["rules", "check", "rules/table3.lp", "rules/none.lp"]) == 0
    bad = tmp_path / "bad.lp"
    bad.write_text(":- room(U), @f(U).\n")
    assert main(["rules", "check", str(bad)]) == 1
    assert f"{bad}:1:" in capsys.readouterr().err
    ev = tmp_path / "ev.lp"
    ev.write_text("unit(1). unit(2). halike(1). rolike(2). adj(1,2).\n")
    assert main(["rules", "query", "rules/table3.lp", "--evidence", str(ev), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["map_types"] == {"1": "hall", "2": "room"} and "1,2" in out["sale"]
    assert main(["rules", "query", "rules/table3.lp", "--evidence", str(ev), "--map", "rc2"]) == 0
    assert "P(SaLe(1,2))" in capsys.readouterr().out
    ev.write_text("unit(1). wall(1).\n")
    assert main(["rules", "query", "rules/table3.lp", "--evidence", str(ev)]) == 2
    assert "unknown evidence predicate" in capsys.readouterr().err


def test_cli_check_says_how_the_engine_runs_the_rules(tmp_path, capsys):
    """``rules check`` says whether a file runs on unit and pair templates or on the general
    path, and for the latter quotes the first statement that puts it there, with the reason;
    what it says agrees with the engine's own choice."""
    from semmap_pp.knowledge.local import pairwise_obstacle
    table3 = (Path("rules/table3.lp")).read_text()
    cases = {
        "table3.lp": (table3, None),
        "helper.lp": (table3 + "nextcorr(U) :- adj(U,V), corr(V).\n"
                      ":~ hall(U), not nextcorr(U). [800@0, hall_next_corr, U]\n",
                      "defines a helper atom"),
        "three.lp": (table3 + ":~ corr(P), corr(Q), corr(R), adj(P,Q), adj(Q,R). "
                     "[300@0, three, P, Q, R]\n", "reads more than two units"),
        "ids.lp": (":~ room(U), rolike(U). [100@0, same, U]\n"
                   ":~ corr(U), colike(U). [100@0, same, U]\n", "an id of its own"),
    }
    for name, (text, reason) in cases.items():
        path = tmp_path / name
        path.write_text(text)
        assert main(["rules", "check", str(path)]) == 0
        out = capsys.readouterr().out.splitlines()
        assert out[0].startswith(f"{path}: ok (")
        engine = KnowledgeEngine.from_file(path)
        if reason is None:
            assert out[1] == "  inference: unit and pair templates (the rules are pairwise-local)"
            assert engine.local is not None and pairwise_obstacle(engine.rules) is None
        else:
            assert out[1].startswith("  inference: the general path") and reason in out[1]
            assert engine.local is None


def test_cli_evidence_of_a_world_gives_its_types_back(intel_corner_wstar, tmp_path, capsys):
    """``rules evidence MAP WORLD_JSON`` writes what the engine saw for that world: queried with
    the rules of the run, the MAP types and the marginals are world.json's own (units keep their
    ids; exterior unit Xk becomes n + k); a bad world.json is one line, nothing written."""
    doc = json.loads(intel_corner_wstar.read_text())
    ev = tmp_path / "ev.lp"
    map_path = "tests/data/maps/intel_corner.yaml"
    assert main(["rules", "evidence", map_path, str(intel_corner_wstar), "--out", str(ev)]) == 0
    assert capsys.readouterr().out.strip() == str(ev)
    text = ev.read_text()
    assert text.startswith(f"% the evidence of {intel_corner_wstar} on ")
    parsed = evidence_from_facts(text, str(ev))
    n = max(u["id"] for u in doc["units"])
    assert list(parsed.units) == sorted([u["id"] for u in doc["units"]] + [n + x["id"] for x in doc["exterior"]])
    assert doc["rules"] == "table3.lp"
    assert main(["rules", "query", "rules/table3.lp", "--evidence", str(ev), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    for u in doc["units"]:
        assert out["map_types"][str(u["id"])] == u["type"]
        got = out["types"][str(u["id"])]
        assert all(got[t] == pytest.approx(p, abs=2e-6) for t, p in u["type_marginals"].items())
    # the same facts on stdout
    assert main(["rules", "evidence", map_path, str(intel_corner_wstar)]) == 0
    assert capsys.readouterr().out == text
    # an exterior unit X1 is numbered after the largest unit id
    moved = dict(doc, units=doc["units"][:-1], exterior=[dict(doc["units"][-1], id=1)] + [
        dict(x, id=x["id"] + 1) for x in doc["exterior"]])
    (tmp_path / "ext.json").write_text(json.dumps(moved))
    assert main(["rules", "evidence", map_path, str(tmp_path / "ext.json")]) == 0
    facts = capsys.readouterr().out
    top = max(u["id"] for u in moved["units"])
    assert f"% {top + 1}: exterior unit X1 of the file" in facts
    assert top + 1 in evidence_from_facts(facts).units
    bad = tmp_path / "bad.json"
    bad.write_text("{}")
    assert main(["rules", "evidence", map_path, str(bad), "--out", str(tmp_path / "x.lp")]) == 2
    err = capsys.readouterr().err
    assert str(bad) in err and err.count("\n") == 1 and not (tmp_path / "x.lp").exists()
    assert main(["rules", "evidence", map_path, str(intel_corner_wstar), "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "is a directory" in err


# ---- intervals in facts (issue 55): clingo's idiom for many facts -----------------------------------

@pytest.mark.parametrize("short, long", [
    ("unit(1..6).", " ".join(f"unit({u})." for u in range(1, 7))),
    ("unit(1..4). rolike(2..3). adj(1,2..4). muldoor(4..4). halike(3..1).",
     "unit(1). unit(2). unit(3). unit(4). rolike(2). rolike(3). adj(1,2). adj(1,3). adj(1,4). muldoor(4)."),
    ('unit(0..3). soft(colike(1..2), "0.6"). adj(0..1, 2..3). muldoor(-1..-2).',
     'unit(0). unit(1). unit(2). unit(3). soft(colike(1), "0.6"). soft(colike(2), "0.6"). '
     "adj(0,2). adj(0,3). adj(1,2). adj(1,3)."),
])
def test_interval_facts_are_the_facts_they_stand_for(short, long):
    a, b = evidence_from_facts(short, "ev.lp"), evidence_from_facts(long, "ev.lp")
    assert a == b
    eng = KnowledgeEngine.from_file("rules/table3.lp")
    ra, rb = eng.infer(a), eng.infer(b)
    for u in b.units:
        np.testing.assert_array_equal(ra.types[u], rb.types[u])
    assert ra.log_z == rb.log_z and ra.map_cost == rb.map_cost


@pytest.mark.parametrize("text, pattern", [
    ("unit(1..1000000000).", r"ev\.lp:1:1: the intervals of unit\(\(1\.\.1000000000\)\) stand for "
                             r"1,000,000,000 facts; a file's facts may stand for at most 100,000"),
    ("unit(1..60000). rolike(1..60000).", r"ev\.lp:1:17: the intervals of rolike.* stand for 60,000 facts, more "
                                          r"than the 40,000 left of the 100,000"),
    ("adj(1..1000, 1..1000).", "stand for 1,000,000 facts"),
    ("unit(1..n).", r"ev\.lp:1:6: the bounds of the interval \(1\.\.n\) must be integers"),
    ("unit(X..3).", "must be integers"),
    ("unit(1). rolike(U) :- unit(U), U = 1..3.", "only ground evidence facts"),
])
def test_interval_facts_that_stand_for_too_much_or_nothing_ground_are_one_line(text, pattern):
    import time

    t0 = time.perf_counter()
    with pytest.raises(EvidenceError, match=pattern):
        evidence_from_facts(text, "ev.lp")
    assert time.perf_counter() - t0 < 5


def test_cli_query_with_interval_evidence(tmp_path, capsys):
    (tmp_path / "six.lp").write_text("".join(f"unit({u}).\n" for u in range(1, 7)) + "rolike(1).\nadj(1,2).\n")
    (tmp_path / "int.lp").write_text("unit(1..6).\nrolike(1).\nadj(1,2).\n")
    outs = []
    for name in ("six.lp", "int.lp"):
        assert main(["rules", "query", "rules/table3.lp", "--evidence", str(tmp_path / name), "--json"]) == 0
        doc = json.loads(capsys.readouterr().out)
        outs.append({k: v for k, v in doc.items() if k != "evidence"})
    assert outs[0] == outs[1]
    (tmp_path / "big.lp").write_text("unit(1..1000000000).\n")
    assert main(["rules", "query", "rules/table3.lp", "--evidence", str(tmp_path / "big.lp")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"{tmp_path / 'big.lp'}:1:1: the intervals" in err
