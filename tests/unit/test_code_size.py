"""The code stays in pieces a reader can hold: no function over :data:`MAX_FUNCTION_LINES` lines, no
class over :data:`MAX_CLASS_LINES` lines, no constructor with more than :data:`MAX_INIT_PARAMS`
parameters (``self`` not counted; group settings into a dataclass). Read with :mod:`ast`, over every
module of the package; docs/architecture.md."""

from __future__ import annotations

import ast
import functools
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[2] / "semmap_pp"

MAX_FUNCTION_LINES = 80
MAX_CLASS_LINES = 300
MAX_INIT_PARAMS = 10

#: functions allowed over the limit, ``"path/module.py:name"`` -> why
EXEMPT_FUNCTIONS: dict[str, str] = {}


@functools.cache
def definitions() -> tuple:
    """``(kind, "path:name", lines, params)`` of every function and class of the package."""
    out = []
    for path in sorted(PACKAGE.rglob("*.py")):
        if "_share" in path.parts:
            continue
        rel = path.relative_to(PACKAGE).as_posix()
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
                lines = node.end_lineno - node.lineno + 1
                params = 0
                if not isinstance(node, ast.ClassDef):
                    a = node.args
                    params = len(a.posonlyargs) + len(a.args) + len(a.kwonlyargs)
                    params += (a.vararg is not None) + (a.kwarg is not None)
                kind = "class" if isinstance(node, ast.ClassDef) else "function"
                out.append((kind, f"{rel}:{node.name}", lines, params))
    return tuple(out)


def test_no_long_function():
    long = [f"{where}: {n} lines" for kind, where, n, _ in definitions()
            if kind == "function" and n > MAX_FUNCTION_LINES and where not in EXEMPT_FUNCTIONS]
    assert not long, (f"functions over {MAX_FUNCTION_LINES} lines (split them):\n" + "\n".join(long))


def test_the_exemptions_are_still_needed():
    lines = {where: n for kind, where, n, _ in definitions() if kind == "function"}
    stale = [w for w in EXEMPT_FUNCTIONS if lines.get(w, 0) <= MAX_FUNCTION_LINES]
    assert not stale, f"exempt but short now (or gone): drop them from EXEMPT_FUNCTIONS: {stale}"


def test_no_large_class():
    large = [f"{where}: {n} lines" for kind, where, n, _ in definitions()
             if kind == "class" and n > MAX_CLASS_LINES]
    assert not large, f"classes over {MAX_CLASS_LINES} lines (split them):\n" + "\n".join(large)


def test_no_constructor_with_many_parameters():
    many = [f"{where}: {p - 1} parameters" for kind, where, _, p in definitions()
            if kind == "function" and where.endswith(":__init__") and p - 1 > MAX_INIT_PARAMS]
    assert not many, (f"constructors with more than {MAX_INIT_PARAMS} parameters (group them in a "
                      "settings dataclass):\n" + "\n".join(many))
