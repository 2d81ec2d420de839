"""The user docs describe the program as it is: its history is CHANGELOG.md's.

docs/ and README.md are checked for the marks of a lab notebook (a session named, a "What changed"
entry, a figure dated by a changelog entry or a commit) and every file a doc, a code comment, the model file or a rule file cites under docs/ must
exist (no DESIGN.md the project does not ship).
"""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
USER_DOCS = sorted((ROOT / "docs").glob("*.md")) + [ROOT / "README.md"]
#: a session named (the notebook's unit of time), or a "What changed" entry ("what changed between two
#: files", a description of `semmap diff`, is not one)
HISTORY = re.compile(r"(?i:\bsessions?\b)|\bWhat changed\b")
#: a doc cited by path (docs/NAME.md), or the design notes the project does not ship (DESIGN.md)
CITED = re.compile(r"\bdocs/([\w-]+\.md)\b|\b(DESIGN\.md)\b")
#: the code, and the files a user edits beside it: the model file and the rule files
SOURCES = ([p for p in (ROOT / "semmap_pp").rglob("*.py")] + list((ROOT / "bench").glob("*.py"))
           + list((ROOT / "models").glob("*.toml")) + list((ROOT / "rules").rglob("*.lp")))


#: a figure dated by an entry of the changelog ("0.946 before CHANGELOG.md, quality change 34"), the
#: words possibly broken over two lines, or by a commit ("at 39c63c7 just before it")
DATED = re.compile(r"(?i:\b(?:before|since|after|until)\s+CHANGELOG\.md)|\bat [0-9a-f]{7,40}\s+just before\b")


def history_lines(path: Path, base: Path = ROOT) -> list[str]:
    text = path.read_text()
    lines = text.splitlines()
    hits = {i: line for i, line in enumerate(lines, 1) if HISTORY.search(line)}
    for m in DATED.finditer(text):
        i = text.count("\n", 0, m.start()) + 1
        hits[i] = lines[i - 1]
    return [f"{path.relative_to(base)}:{i}: {hits[i].strip()[:100]}" for i in sorted(hits)]


def test_user_docs_hold_no_history():
    found = [hit for p in USER_DOCS for hit in history_lines(p)]
    assert not found, ("history in the user docs (move it to CHANGELOG.md, keep what is true now):\n"
                       + "\n".join(found[:40]) + (f"\n... and {len(found) - 40} more" if len(found) > 40 else ""))


def test_code_comments_hold_no_history():
    found = [hit for p in SOURCES for hit in history_lines(p)]
    assert not found, "history in code comments (CHANGELOG.md holds it):\n" + "\n".join(found)


def test_cited_docs_exist():
    known = {p.name for p in (ROOT / "docs").glob("*.md")} | {p.name for p in ROOT.glob("*.md")}
    missing = []
    for p in SOURCES + USER_DOCS:
        for i, line in enumerate(p.read_text().splitlines(), 1):
            for name in (a or b for a, b in CITED.findall(line)):
                if name not in known:
                    missing.append(f"{p.relative_to(ROOT)}:{i}: {name}")
    assert not missing, "docs cited that the project does not hold:\n" + "\n".join(missing)


def test_the_check_sees_history(tmp_path):
    page = tmp_path / "page.md"
    page.write_text("# Page\n\nSince session 12 the map is read twice.\n\n## What changed\n\nNothing.\n")
    assert history_lines(page, tmp_path) == ["page.md:3: Since session 12 the map is read twice.",
                                             "page.md:5: ## What changed"]
    page.write_text("semmap diff: what changed between two files.\n")
    assert history_lines(page, tmp_path) == []
    page.write_text("CPR 0.947 (0.946 before\nCHANGELOG.md, quality change 34).\nSee CHANGELOG.md for the history.\n")
    assert history_lines(page, tmp_path) == ["page.md:1: CPR 0.947 (0.946 before"]
    page.write_text("types 0.985 (0.983 at 39c63c7 just before it)\n")
    assert history_lines(page, tmp_path) == ["page.md:1: types 0.985 (0.983 at 39c63c7 just before it)"]
