"""Move modules of semmap_pp with ``git mv`` and rewrite every reference to them.

    python tools/move_modules.py MAPPING_FILE [--dry-run]

MAPPING_FILE holds one move a line, ``old.dotted.module new.dotted.module`` (relative to
``semmap_pp``; a package moves with everything under it), ``#`` starts a comment. References
rewritten, in the Python, Markdown and TOML files git tracks (CHANGELOG.md is history and is left
as it is):

* dotted names ``semmap_pp.old.module[.attr]`` (imports, ``mock.patch`` targets, docstrings), but
  not a file format's name (``semmap_pp.resume/1``: followed by ``/``), which files on disk hold;
* ``from semmap_pp[.pkg] import module [as alias]`` of a moved module, made
  ``from semmap_pp.new.pkg import module [as alias]`` (the old name kept as alias when the module
  is renamed, so the code that uses it is unchanged);
* paths ``semmap_pp/old/module.py``.

Another branch's edits to a moved file follow it on merge (git's rename detection), since only
these lines change. Run it on such a branch to rewrite the imports of the files it added.
"""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PKG = "semmap_pp"
SKIP = {"CHANGELOG.md", "move_modules.py"}   # history, and this script's own examples
SUFFIXES = {".py", ".md", ".toml", ".cfg", ".in", ".txt"}


def read_mapping(path: Path) -> list[tuple[str, str]]:
    moves = []
    for line in path.read_text().splitlines():
        line = line.split("#", 1)[0].strip()
        if line:
            old, new = line.split()
            moves.append((old, new))
    return moves


def module_path(dotted: str) -> Path:
    """The file or package folder of ``semmap_pp.<dotted>``."""
    base = ROOT / PKG / Path(*dotted.split("."))
    return base if base.is_dir() else base.with_suffix(".py")


def git_mv(moves, dry: bool) -> None:
    for old, new in moves:
        src = module_path(old)
        if not src.exists():
            print(f"skip (gone): {old}")
            continue
        dst = ROOT / PKG / Path(*new.split("."))
        if src.suffix == ".py":
            dst = dst.with_suffix(".py")
        parent = dst.parent
        print(f"git mv {src.relative_to(ROOT)} {dst.relative_to(ROOT)}")
        if dry:
            continue
        parent.mkdir(parents=True, exist_ok=True)
        init = parent / "__init__.py"
        pkg_root = ROOT / PKG
        p = parent
        while p != pkg_root:                # every new folder a package
            if not (p / "__init__.py").exists():
                raise SystemExit(f"{p.relative_to(ROOT)} has no __init__.py: write it first")
            p = p.parent
        subprocess.run(["git", "mv", str(src), str(dst)], cwd=ROOT, check=True)
        del init


def rewriter(moves):
    # longest first, so that semmap_pp.outputs.semantic wins over a move of semmap_pp.outputs
    moves = sorted(moves, key=lambda m: -len(m[0]))
    dotted = [(re.compile(rf"\b{PKG}\.{re.escape(old)}(?![A-Za-z0-9_/])"), f"{PKG}.{new}")
              for old, new in moves]
    paths = [(re.compile(rf"\b{PKG}/{re.escape(old.replace('.', '/'))}(?=\.py\b|/)"),
              f"{PKG}/{new.replace('.', '/')}") for old, new in moves]
    by_old = dict(moves)
    from_import = re.compile(rf"^(\s*)from {PKG}((?:\.\w+)*) import (\w+)( as \w+)?(\s*(?:#.*)?)$",
                             re.M)

    def fix_from(m):
        indent, pkg, name, alias, tail = m.groups()
        full = (pkg[1:] + "." if pkg else "") + name
        if full not in by_old:
            return m.group(0)
        new = by_old[full]
        parent, _, new_name = new.rpartition(".")
        if alias is None and new_name != name:
            alias = f" as {name}"
        src = f"{PKG}.{parent}" if parent else PKG
        return f"{indent}from {src} import {new_name}{alias or ''}{tail}"

    def rewrite(text: str) -> str:
        text = from_import.sub(fix_from, text)
        for rx, new in dotted:
            text = rx.sub(new, text)
        for rx, new in paths:
            text = rx.sub(new, text)
        return text

    return rewrite


def tracked_files():
    out = subprocess.run(["git", "ls-files"], cwd=ROOT, check=True, capture_output=True, text=True)
    for name in out.stdout.splitlines():
        p = ROOT / name
        if p.name in SKIP or p.suffix not in SUFFIXES and p.name != "Makefile":
            continue
        if p.is_file():
            yield p


def main(argv):
    dry = "--dry-run" in argv
    args = [a for a in argv if a != "--dry-run"]
    moves = read_mapping(Path(args[0]))
    git_mv(moves, dry)
    rewrite = rewriter(moves)
    changed = 0
    for p in tracked_files():
        text = p.read_text()
        new = rewrite(text)
        if new != text:
            changed += 1
            print(f"rewrote {p.relative_to(ROOT)}")
            if not dry:
                p.write_text(new)
    print(f"{changed} files rewritten")


if __name__ == "__main__":
    main(sys.argv[1:])
