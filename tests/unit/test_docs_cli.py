"""docs/cli.md lists every subcommand of `semmap` in its opening block and gives each a section."""

import re
from pathlib import Path

from semmap_pp.cli import build_parser

DOC = Path(__file__).resolve().parents[2] / "docs" / "cli.md"


def test_every_subcommand_is_listed_and_has_a_section():
    parser = build_parser()
    sub = next(a for a in parser._actions if a.dest == "command")
    names = sorted(sub.choices)
    text = DOC.read_text(encoding="utf-8")
    block = text.split("```")[1]
    listed = set(re.findall(r"^semmap (\w+)", block, re.MULTILINE))
    assert listed == set(names), sorted(set(names) ^ listed)
    headings = " ".join(re.findall(r"^##+ .*$", text, re.MULTILINE))
    missing = [n for n in names if f"`semmap {n}`" not in headings]
    assert not missing, missing
