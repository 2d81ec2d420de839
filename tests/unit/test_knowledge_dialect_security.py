"""Rule files can bring in nothing from outside their folder: includes are found the way clingo
reads them (nested block comments), clingo is handed no comment, and no FIFO is ever opened."""

import os

import pytest

from semmap_pp.errors import RuleError
from semmap_pp.knowledge import load_rules
from semmap_pp.knowledge.dialect import strip_includes

BASE = "rolike(U) :- unit(U).\n"
HIDDEN = [  # each hides an include from a reader that does not nest block comments
    '%* %* *% " *% #include "{t}". %* " *%\n',
    '%*%* *%*% #include "{t}".\n',
    '%* a %* b %* c *% d *% " *% #include "{t}". %* " *%\n',
    '%* %* *%\n" *%\n#include "{t}".\n%* "\n*%\n',
]


@pytest.mark.parametrize("hide", HIDDEN)
def test_an_include_hidden_by_nested_comments_is_found_and_refused(tmp_path, hide):
    outside = tmp_path / "outside.lp"
    outside.write_text("secret(1).\n")
    rules = tmp_path / "rules"
    rules.mkdir()
    f = rules / "evil.lp"
    f.write_text(BASE + hide.format(t=outside))
    with pytest.raises(RuleError, match="absolute path is not allowed"):
        load_rules(f)
    f.write_text(BASE + hide.format(t="../outside.lp"))
    with pytest.raises(RuleError, match="outside the rules folder"):
        load_rules(f)


def test_what_clingo_is_handed_holds_no_comment():
    text = 'a. %* x %* y *% "z" *% b. % tail #include "q.lp".\nc.'
    out, inc = strip_includes(text, "r.lp")
    assert inc == [] and out.split() == ["a.", "b.", "c."] and len(out) == len(text)
    assert out.count("\n") == text.count("\n")              # positions kept for file:line:col


def test_an_unclosed_block_comment_is_an_error_with_its_place(tmp_path):
    f = tmp_path / "r.lp"
    f.write_text(BASE + "%* %* *%\n")
    with pytest.raises(RuleError, match=r"r\.lp:2:1: block comment %\* is never closed"):
        load_rules(f)


def test_a_fifo_is_never_opened_as_a_rule_file_or_include(tmp_path):
    fifo = tmp_path / "f.lp"
    os.mkfifo(fifo)
    with pytest.raises(RuleError, match="not a regular file"):
        load_rules(fifo)
    top = tmp_path / "top.lp"
    top.write_text(BASE + '#include "f.lp".\n')
    with pytest.raises(RuleError, match="no such file"):
        load_rules(top)
