"""The bound on a rule set's grounding (semmap_pp.knowledge.size) and the refusals it drives.

A rule file is Datalog: grounding ends, but a rule with many free unit variables grounds n^k
statements and a run would never end. The bound must hold for clingo's real grounding (else a
file that hangs slips through), and what exceeds the limit must stop with one line naming the
statement: when the file is loaded (a floor of 64 units), before clingo grounds an evidence, and
in `semmap rules check` and `semmap map`.
"""

from __future__ import annotations

import random
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

from semmap_pp.cli import main
from semmap_pp.errors import RuleError
from semmap_pp.knowledge import ground as ground_mod
from semmap_pp.knowledge import load_rules, size
from semmap_pp.knowledge.evidence import Evidence, ground_facts
from semmap_pp.knowledge.size import MAX_GROUND_STATEMENTS, Sizes

ROOT = Path(__file__).resolve().parents[2]
SMALL_MAP = ROOT / "tests" / "data" / "maps" / "intel_corner.yaml"

# Rule files covering what the bound counts: products of unit variables, pairs linked by adj,
# helpers (one of them two hops, one recursive), aggregates (a guard, an assignment, a
# conditional literal), constants in helper atoms, anonymous variables, negated literals.
FILES = {
    "product": ":~ unit(A), unit(B), unit(C), room(A). [1@0, m, A, B, C]\n",
    "helpers": """adj(Q,P) :- adj(P,Q).
nextcorr(U) :- adj(U,V), corr(V).
twohop(U,W) :- adj(U,V), adj(V,W), U != W.
:~ hall(U), not nextcorr(U). [800@0, h, U]
:~ room(U), room(W), twohop(U,W). [300@0, t, U, W]
""",
    "aggregates": """adj(Q,P) :- adj(P,Q).
:~ room(U), #count { V : adj(U,V), corr(V) } >= 2. [700@0, a, U]
:~ corr(U), N = #count { V : adj(U,V), room(V) }, N > 3. [500@0, b, U, N]
:- hall(U), hall(V) : adj(U,V).
""",
    "recursive": """adj(Q,P) :- adj(P,Q).
reach(X,Y) :- adj(X,Y).
reach(X,Z) :- reach(X,Y), adj(Y,Z).
:~ hall(A), hall(B), reach(A,B), A < B. [900@0, r, A, B]
""",
    "constants": """adj(Q,P) :- adj(P,Q).
kind(U, big) :- halike(U).
kind(U, small) :- rolike(U).
kind(U, long) :- colike(U).
:~ kind(U, K), kind(V, K), adj(U,V), room(U). [400@0, k, U, V, K]
:~ muldoor(U), not corr(U), not other(U). [600@0, md, U]
""",
    "anonymous": """adj(Q,P) :- adj(P,Q).
:~ room(A), adj(A,_), adj(_,A). [100@0, an, A]
:~ hall(A), hall(B), A != B, not adj(A,B). [200@0, far, A, B]
""",
}
BOMB = ":~ unit(A), unit(B), unit(C), unit(D), unit(E), unit(F), room(A). [1@0, many, A, B, C, D, E, F]\n"


def _write(tmp_path, name, text) -> Path:
    path = tmp_path / f"{name}.lp"
    path.write_text(text)
    return path


def _statements(rules, ev) -> int:
    """The ground statements clingo emits for ``ev`` (rules, weight rules, cost entries)."""
    obs, _ctl = ground_mod._clingo_ground(rules, ground_facts(ev, weights=False))
    return len(obs.rules) + len(obs.wrules) + sum(len(lits) for _p, lits in obs.mins)


def _random_evidence(rng, n) -> Evidence:
    pairs = {(a, b) for a in range(n) for b in range(a + 1, n) if rng.random() < 3 / n}

    def pick():
        return {u: rng.choice([1.0, 0.6]) for u in range(n) if rng.random() < 0.4}

    return Evidence.build(range(n), rolike=pick(), colike=pick(), halike=pick(), muldoor=pick(),
                          adj=pairs)


@pytest.mark.parametrize("name", [*FILES, "table3", "halls_to_corridors"])
def test_the_bound_holds_for_clingos_grounding(tmp_path, name):
    path = (ROOT / "rules" / f"{name}.lp") if name not in FILES else _write(tmp_path, name, FILES[name])
    rules, frame_only = load_rules(path), load_rules(ROOT / "rules" / "none.lp")
    rng = random.Random(name)
    for _ in range(25):
        ev = _random_evidence(rng, rng.randint(1, 22))
        made = _statements(rules, ev) - _statements(frame_only, ev)   # the frame's own left out
        assert made <= rules.bound.total(Sizes.of(ev)), (name, ev)


def test_the_bound_of_a_product_of_units_is_its_size(tmp_path):
    """Not a loose bound: n^3 tuples of a weak constraint on one open atom are n^3 cost entries,
    and the bound is the statements-per-instance factor times that."""
    product = load_rules(_write(tmp_path, "product", FILES["product"]))
    none = load_rules(ROOT / "rules" / "none.lp")
    for n in (3, 7, 12):
        ev = Evidence.build(range(n), adj=[(i, i + 1) for i in range(n - 1)])
        assert _statements(product, ev) - _statements(none, ev) == n ** 3
        assert product.bound.total(Sizes.of(ev)) == size.STATEMENTS_PER_INSTANCE * n ** 3


def test_a_file_that_cannot_ground_a_floor_is_refused_when_loaded(tmp_path):
    path = _write(tmp_path, "bomb", "adj(Q,P) :- adj(P,Q).\n" + BOMB)
    with pytest.raises(RuleError) as info:
        load_rules(path)
    text = str(info.value)
    assert text.startswith(f"{path}:2:1: grounding a floor of 64 units"), text
    assert f"over the limit of {MAX_GROUND_STATEMENTS:,}" in text and "unit(F)" in text
    assert "\n" not in text


def test_an_evidence_over_the_limit_is_refused_before_clingo_runs(tmp_path, monkeypatch):
    rules = load_rules(_write(tmp_path, "product", FILES["product"]))   # 2 n^3 + ... statements
    at = rules.bound.limit_units()
    assert rules.bound.total(Sizes.floor(at - 1)) <= MAX_GROUND_STATEMENTS \
        < rules.bound.total(Sizes.floor(at))

    def no_clingo(*args, **kwargs):
        raise AssertionError("clingo was asked to ground an evidence over the limit")

    monkeypatch.setattr(ground_mod, "_clingo_ground", no_clingo)
    n = round((MAX_GROUND_STATEMENTS / 2) ** (1 / 3)) + 1     # n^3 tuples, two statements each
    ev = Evidence.build(range(n), adj=[(i, i + 1) for i in range(n - 1)])
    with pytest.raises(RuleError, match=rf"product\.lp:1:1: grounding a world of {n} units could "
                                        r"take up to .* over the limit"):
        ground_mod.ground(rules, ev)
    # just below the limit the check passes (clingo is not run here: the bound alone)
    rules.bound.check(Sizes.of(Evidence.build(range(n - 2))))


def test_rules_check_says_where_the_limit_is_reached(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    path = _write(tmp_path, "product", FILES["product"])
    assert main(["rules", "check", str(path)]) == 0
    out = capsys.readouterr().out
    at = load_rules(path).bound.limit_units()
    assert f"the limit of {MAX_GROUND_STATEMENTS:,} is reached at {at:,} units" in out
    assert "most of it from product.lp:1:1" in out
    # the templates ground one unit or pair at a time: no grounding line for table3
    assert main(["rules", "check", str(ROOT / "rules" / "table3.lp")]) == 0
    assert "grounding:" not in capsys.readouterr().out
    bomb = _write(tmp_path, "bomb", BOMB)
    assert main(["rules", "check", str(bomb)]) == 1
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and err.startswith(f"{bomb}:1:1: grounding a floor of 64 units")


def test_a_run_whose_world_grows_over_the_limit_stops_with_one_line_and_no_output(
        tmp_path, capsys, monkeypatch):
    """The file loads (its floor check passes) but the run's worlds ground more than the limit:
    the knowledge engine refuses the evidence, the run stops with exit 2 and writes nothing."""
    monkeypatch.setattr(size, "FLOOR_UNITS", 2)
    monkeypatch.setattr(size, "MAX_GROUND_STATEMENTS", 40)
    path = _write(tmp_path, "product", FILES["product"])
    out = tmp_path / "out"
    code = main(["map", str(SMALL_MAP), "--out", str(out), "--rules", str(path), "--chains", "1",
                 "--cores", "1", "--tune", "4", "--draws", "4", "--n-inner", "10",
                 "--spread-draws", "0"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2, err
    assert err[-1].startswith(f"semmap: error: {path}:1:1: grounding a world of "), err
    assert "over the limit of 40," in err[-1] and not out.exists()


# --- random programs ------------------------------------------------------------------------

_UNARY = ("unit", "rolike", "colike", "halike", "muldoor", "room", "corr", "hall", "other", "h1")
_BINARY = ("adj", "sale", "h2")


@st.composite
def _body(draw, want=()):
    """A safe random body: positive atoms binding some of A..D (and the variables ``want``),
    then negated atoms, a comparison and an aggregate over variables already bound."""
    names = ["A", "B", "C", "D"]
    lits, bound = [], set()
    for v in want:                                   # the head's variables occur positively
        lits.append(f"{draw(st.sampled_from(_UNARY))}({v})")
        bound.add(v)
    for _ in range(draw(st.integers(1, 4))):
        if draw(st.booleans()):
            x, y = draw(st.sampled_from(names)), draw(st.sampled_from(names))
            if x == y:
                continue
            lits.append(f"{draw(st.sampled_from(_BINARY))}({x},{y})")
            bound |= {x, y}
        else:
            x = draw(st.sampled_from(names))
            lits.append(f"{draw(st.sampled_from(_UNARY))}({x})")
            bound.add(x)
    if not bound:
        lits.append("unit(A)")
        bound.add("A")
    b = sorted(bound)
    for _ in range(draw(st.integers(0, 2))):
        x = draw(st.sampled_from(b))
        lits.append(f"not {draw(st.sampled_from(_UNARY))}({x})")
    if len(b) > 1 and draw(st.booleans()):
        lits.append(f"{b[0]} {draw(st.sampled_from(['<', '!=', '=']))} {b[1]}")
    if draw(st.booleans()):
        x = draw(st.sampled_from(b))
        kind = draw(st.sampled_from(["guard", "assign", "cond"]))
        inner = f"adj({x},Y), {draw(st.sampled_from(_UNARY))}(Y)"
        lits.append({"guard": f"#count {{ Y : {inner} }} >= 2",
                     "assign": f"N = #count {{ Y : {inner} }}, N > 1",
                     "cond": f"corr(Y) : {inner}"}[kind])
    return ", ".join(lits), b


@st.composite
def _program(draw):
    lines = ["adj(Q,P) :- adj(P,Q)."]
    body, _ = draw(_body(want=("A",)))
    lines.append(f"h1(A) :- {body}.")
    body, _ = draw(_body(want=("A", "B")))
    lines.append(f"h2(A,B) :- {body}.")
    if draw(st.booleans()):                          # recursion through evidence
        lines.append("h2(A,C) :- h2(A,B), adj(B,C).")
    for k in range(draw(st.integers(1, 3))):
        body, b = draw(_body())
        if "N = #count" in body:
            b = b + ["N"]
        lines.append(f":~ {body}. [1@0, w{k}, {', '.join(b)}]" if draw(st.booleans())
                     else f":- {body}.")
    return "\n".join(lines) + "\n"


@settings(max_examples=150, deadline=None, suppress_health_check=list(HealthCheck))
@given(_program(), st.integers(0, 2**32 - 1))
def test_the_bound_holds_for_random_programs(text, seed):
    """Random safe programs over evidence, query and helper atoms (adj and sale links, negation,
    comparisons, count aggregates, conditional literals, recursion through adj): clingo never
    grounds more statements than the bound says."""
    import tempfile
    with tempfile.TemporaryDirectory() as d:
        try:
            rules = load_rules(_write(Path(d), "random", text))
        except RuleError as exc:                     # over the limit at a floor of 64 units
            assert "over the limit" in str(exc), (text, exc)
            return
        none = load_rules(ROOT / "rules" / "none.lp")
        rng = random.Random(seed)
        for _ in range(3):
            ev = _random_evidence(rng, rng.randint(1, 12))
            made = _statements(rules, ev) - _statements(none, ev)
            assert made <= rules.bound.total(Sizes.of(ev)), (text, ev)
