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
