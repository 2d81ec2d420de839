"""Rule-file validation: every rejection names file:line:col."""

import re

import pytest

from semmap_pp.errors import RuleError
from semmap_pp.knowledge import Evidence, KnowledgeEngine, load_rules
from semmap_pp.knowledge.ground import ground


def check(tmp_path, text, name="r.lp"):
    f = tmp_path / name
    f.write_text(text)
    return load_rules(f)


def rejects(tmp_path, text, pattern, where="r.lp:"):
    with pytest.raises(RuleError) as exc:
        check(tmp_path, text)
    msg = str(exc.value)
    assert re.search(pattern, msg), msg
    assert where in msg and re.search(r"\.lp:\d+:\d+: ", msg), msg
    return msg


def test_shipped_rule_files_load():
    for f in ("rules/table3.lp", "rules/none.lp", "rules/halls_to_corridors.lp"):
        load_rules(f)
    assert load_rules("rules/table3.lp").n_soft == 19


def test_script_is_rejected(tmp_path):
    msg = rejects(tmp_path, "#script (python)\nimport os\n#end.\n", "#script")
    assert ":1:1:" in msg


def test_external_function_call_is_rejected(tmp_path):
    msg = rejects(tmp_path, "p(X) :- unit(X), X = @f(X).\n", "@-terms")
    assert ":1:" in msg


def test_external_directive_is_rejected(tmp_path):
    rejects(tmp_path, "#external room(1).\n", "#external")


def test_program_other_than_base_is_rejected(tmp_path):
    rejects(tmp_path, "#program step(t).\n", "#program step")


def test_include_absolute_is_rejected(tmp_path):
    msg = rejects(tmp_path, '% ok\n#include "/etc/passwd".\n', "absolute")
    assert ":2:1:" in msg


def test_include_escaping_the_folder_is_rejected(tmp_path):
    sub = tmp_path / "rules"
    sub.mkdir()
    (tmp_path / "outside.lp").write_text(":- unit(U), room(U).\n")
    (sub / "r.lp").write_text('#include "../outside.lp".\n')
    with pytest.raises(RuleError, match=r"r\.lp:1:1: #include outside the rules folder"):
        load_rules(sub / "r.lp")


def test_include_inside_the_folder_is_read(tmp_path):
    (tmp_path / "part.lp").write_text(":~ rolike(U), not room(U). [1000@0, r, U]\n")
    rs = check(tmp_path, '#include "part.lp".\n:- unit(U), other(U).\n')
    assert rs.n_soft == 1 and rs.n_hard == 1 and len(rs.files) == 2


def test_error_in_included_file_names_that_file(tmp_path):
    (tmp_path / "part.lp").write_text("\n:~ rolike(U). [-5@0, r, U]\n")
    with pytest.raises(RuleError, match=r"part\.lp:2:\d+: negative weight"):
        check(tmp_path, '#include "part.lp".\n')


def test_include_in_a_comment_is_ignored(tmp_path):
    check(tmp_path, '% #include "/etc/passwd".\n%* #include "x". *%\n')


def test_unknown_predicate_is_rejected(tmp_path):
    msg = rejects(tmp_path, ":- unit(U),\n   wide(U).\n", "unknown predicate wide/1")
    assert ":2:4:" in msg


def test_helper_defined_in_the_file_is_allowed(tmp_path):
    rs = check(tmp_path, "big(U) :- halike(U).\n:~ big(U), room(U). [500@0, b, U]\n")
    assert rs.helpers == ("big/1",)


def test_query_atom_in_a_head_is_rejected(tmp_path):
    rejects(tmp_path, "room(U) :- rolike(U).\n", "cannot be derived")


def test_choice_rule_is_rejected(tmp_path):
    rejects(tmp_path, "{ room(U) } :- unit(U).\n", "choice rules")


def test_unsafe_variable_is_rejected(tmp_path):
    rejects(tmp_path, ":- room(U), not adj(U,V).\n", "unsafe")


def test_syntax_error_is_reported(tmp_path):
    msg = rejects(tmp_path, ":- room(U)\n:- hall(U).\n", "syntax error")
    assert ":2:" in msg


@pytest.mark.parametrize("weight, pattern", [
    ("-1500", "negative weight"), ("900000", "too large"), ('"1.5"', "not an integer"),
    ("nan", "not a #const"), ("W", "not the variable"), ("1.5", "syntax error")])
def test_bad_weights_are_rejected(tmp_path, weight, pattern):
    rejects(tmp_path, f":~ rolike(W), room(W). [{weight}@0, r, W]\n", pattern)


def test_const_weight_is_read(tmp_path):
    rs = check(tmp_path, "#const w = 1200.\n:~ rolike(U), not room(U). [w@0, r, U]\n")
    r = KnowledgeEngine(rs).infer(Evidence.build([1], rolike={1}))
    import math
    expected = 1 / (1 + 3 * math.exp(-1.2))
    assert abs(r.types[1][0] - expected) < 1e-12


def test_priority_other_than_zero_is_rejected(tmp_path):
    rejects(tmp_path, ":~ rolike(U), room(U). [100@1, r, U]\n", "priority must be 0")


@pytest.mark.parametrize("text", ["adj(q,P) :- adj(P,Q).\n",   # found by bench/fuzz.py
                                  "adj(P,7) :- unit(P).\n"])
def test_adj_derived_over_values_that_are_not_units_is_a_rule_error(tmp_path, text):
    """The frame opens sale(P,Q) for every adj(P,Q); a derived pair holding a constant crashed
    the network reader (clingo's symbol access: a RuntimeError), one holding an id the evidence
    does not have opened a SaLe atom between units that do not exist."""
    rs = check(tmp_path, text)
    with pytest.raises(RuleError, match=r"r\.lp: adj/2 must pair two units of the evidence, but "
                                        r"the rules derive adj\("):
        ground(rs, Evidence.build([1, 2], adj=[(1, 2)]))


def test_contradictory_hard_rules_name_the_file(tmp_path):
    rs = check(tmp_path, ":- unit(U), rolike(U).\n")
    with pytest.raises(RuleError, match=r"r\.lp: the hard rules admit no world"):
        ground(rs, Evidence.build([1], rolike={1}))


@pytest.mark.parametrize("text", [
    "adj(Q,P) :- adj(P,Q-5).\n",              # found by bench/fuzz.py: grounding never ended
    "adj(Q,P) :- adj(P,-Q).\n",
    "h(X) :- unit(X).\nh(Y) :- h(f(Y*2)).\n",
    "h(X) :- unit(X).\nh(Y) :- h(|Y|).\n",
])
def test_a_head_variable_solved_from_body_arithmetic_is_rejected(tmp_path, text):
    """clingo solves Q from an arithmetic body term (Q-5 = 2 gives Q = 7): a new value, so
    such a recursive rule grounds without end; the head variable must occur outside arithmetic."""
    rejects(tmp_path, text, r"head variable [QY] must occur in a positive body atom, outside "
            "arithmetic")


def test_body_arithmetic_is_fine_when_the_head_variable_also_occurs_plainly(tmp_path):
    rs = check(tmp_path, "near(P,Q) :- adj(P,Q), adj(Q,R), R != P+1.\n"
                         "fivish(Q) :- adj(P,Q), unit(P+0).\n"
                         ":~ near(P,Q), fivish(Q), room(P). [100@0, n, P, Q]\n")
    net = ground(rs, Evidence(units=(1, 2, 3), adj=((1, 2), (2, 3)))).network
    assert net.n_vars >= 3


# ---- intervals in facts (issue 55): clingo's idiom for many facts -----------------------------------

NAMED = ":~ unit(U), named(U), not hall(U). [1500@0, named_hall, U]\n"


@pytest.mark.parametrize("short, long", [
    ("named(1..3).\n", "named(1).\nnamed(2).\nnamed(3).\n"),
    ("named(2..3). far(1..2, 5..6).\nnamed(9..7).\n",
     "named(2). named(3). far(1,5). far(1,6). far(2,5). far(2,6).\n"),
])
def test_interval_facts_of_a_rule_file_are_the_facts_written_out(tmp_path, short, long):
    extra = ":~ far(P,Q), adj(P,Q). [100@0, far, P, Q]\n" if "far" in short else ""
    a = check(tmp_path, short + NAMED + extra, "short.lp")
    b = check(tmp_path, long + NAMED + extra, "long.lp")
    assert a.program == b.program and a.digest == b.digest       # the same knowledge, the same caches
    ev = Evidence.build(range(1, 7), rolike={1, 4}, colike={2}, muldoor={3: 0.6}, adj=[(1, 2), (2, 3), (1, 5)])
    ra, rb = KnowledgeEngine(a).infer(ev), KnowledgeEngine(b).infer(ev)
    for u in ev.units:
        assert ra.types[u].tolist() == rb.types[u].tolist()
    assert ra.log_z == rb.log_z and ra.map_cost == rb.map_cost
    named = {2, 3} | ({1} if short.startswith("named(1..3)") else set())
    for u in ev.units:        # the facts took effect: a named unit leans to hall (index 2), unit 6 not
        assert (ra.types[u][2] > ra.types[6][2] + 0.1) == (u in named), (u, ra.types[u])


@pytest.mark.parametrize("text, pattern", [
    ("named(1..1000000000).\n" + NAMED, r"r\.lp:1:1: the intervals of named\(\(1\.\.1000000000\)\) stand for "
                                        r"1,000,000,000 facts; a file's facts may stand for at most 100,000$"),
    ("named(1..70000).\nfar(1..40000).\n" + NAMED, r"r\.lp:2:1: the intervals of far.* stand for 40,000 facts, more "
                                                   r"than the 30,000 left"),
    ("named(1..N).\n" + NAMED, r"r\.lp:1:7: the bounds of the interval \(1\.\.N\) must be integers"),
    ("named(U) :- unit(U), U = 1..3.\n" + NAMED, r"r\.lp:1:26: intervals .* are not allowed here"),
    ("named(1..3) :- unit(1).\n" + NAMED, r"r\.lp:1:7: intervals .* are not allowed here"),
])
def test_interval_facts_that_stand_for_too_much_or_sit_in_a_rule_are_one_line(tmp_path, text, pattern):
    import time

    t0 = time.perf_counter()
    rejects(tmp_path, text, pattern)
    assert time.perf_counter() - t0 < 5


@pytest.mark.slow
def test_the_bound_counts_the_included_files_too(tmp_path):
    (tmp_path / "more.lp").write_text("far(1..60000).\n")
    msg = rejects(tmp_path, '#include "more.lp".\nnamed(1..60000).\n' + NAMED,
                  r"the intervals of far.* stand for 60,000 facts, more than the 40,000 left of the 100,000",
                  where="more.lp:1:1: ")
    assert "its includes too" in msg
