"""The package's layers: folders by stage, imports in one direction (docs/architecture.md).

Every module's imports are read with :mod:`ast`, those inside functions included, so a loop hidden
in a function body counts as much as one at the top of a file. A module imports only from its own
folder, from the foundations at the root, and from the folders before its own in :data:`STAGES`.
"""

from __future__ import annotations

import ast
import functools
import io
import tokenize
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[2] / "semmap_pp"

#: the foundations, loose at the root of the package: every folder may import them, they import
#: no folder
ROOT = ("errors", "cells", "atomic", "resources", "model", "world", "jitcache", "userdirs", "forked")
#: the folders in the order of the stages; each imports only the root and the folders before it
STAGES = ("grid", "synth", "lattice", "derive", "knowledge", "target", "sampler", "evaluate",
          "semantic", "run", "plans", "studies", "outputs", "cli")
MAX_LOOSE = 11
#: arrows the stage order allows but the layers do not: outputs are handed typed worlds by the run
#: (semmap_pp.run.spread.posterior_worlds) and never call back into it
FORBIDDEN = {("outputs", "run"): "outputs write what the run hands them; they never call back into it"}
#: the folder whose commands import their work when they run: building the parser imports every
#: cmd_*.py, and ``semmap --help`` (or ``semmap info``) would otherwise import PyMC, ArviZ,
#: clingo and matplotlib (cli/__init__.py)
LAZY_FOLDERS = ("cli",)


def modules():
    for path in sorted(PACKAGE.rglob("*.py")):
        if "_share" in path.parts:
            continue
        parts = path.relative_to(PACKAGE).with_suffix("").parts
        yield path, parts


def stage_of(parts: tuple[str, ...]) -> str:
    """The folder of a module (``""`` for the root's own modules)."""
    return parts[0] if len(parts) > 1 else ""


def _comments(source: str) -> dict[int, str]:
    return {tok.start[0]: tok.string for tok in tokenize.generate_tokens(io.StringIO(source).readline)
            if tok.type == tokenize.COMMENT}


def imports(path: Path, parts: tuple[str, ...]):
    """``(target, lineno, in_function, comment)`` for every import of a ``semmap_pp`` module or
    of another package; relative imports resolved."""
    source = path.read_text()
    tree = ast.parse(source)
    comments = _comments(source)
    is_pkg = parts[-1] == "__init__"
    here = ["semmap_pp", *parts[:-1]] if not is_pkg else ["semmap_pp", *parts[:-1]]

    def visit(node, in_function):
        for child in ast.iter_child_nodes(node):
            fn = in_function or isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda))
            if isinstance(child, (ast.Import, ast.ImportFrom)):
                note = comments.get(child.lineno) or comments.get(child.lineno - 1) or ""
                if isinstance(child, ast.Import):
                    for a in child.names:
                        yield a.name, child.lineno, in_function, note
                else:
                    base = child.module or ""
                    if child.level:
                        up = here[: len(here) - (child.level - 1)]
                        base = ".".join(up + ([base] if base else []))
                    for a in child.names:
                        yield f"{base}.{a.name}", child.lineno, in_function, note
            yield from visit(child, fn)

    yield from visit(tree, False)


def target_stage(dotted: str) -> str | None:
    """The folder a ``semmap_pp...`` import lands in (``""`` for the root), else None."""
    parts = dotted.split(".")
    if parts[0] != "semmap_pp":
        return None
    if len(parts) == 1:
        return ""
    first = parts[1]
    return first if (PACKAGE / first).is_dir() else ""


@functools.cache
def package_imports() -> tuple:
    """``(path, parts, imports)`` of every module of the package, read once per test process."""
    return tuple((path, parts, tuple(imports(path, parts))) for path, parts in modules())


def folder_edges():
    for path, parts, found in package_imports():
        src = stage_of(parts)
        if parts == ("__main__",):
            src = "cli"
        for target, line, in_function, note in found:
            dst = target_stage(target)
            if dst is not None and dst != src:
                yield src, dst, f"{path.relative_to(PACKAGE.parent)}:{line}", in_function, note


def rank(stage: str) -> int:
    return -1 if stage == "" else STAGES.index(stage)


def test_every_folder_has_its_stage():
    folders = {p.name for p in PACKAGE.iterdir() if p.is_dir() and (p / "__init__.py").exists()}
    assert folders == set(STAGES), f"folders not in STAGES (or gone): {sorted(folders ^ set(STAGES))}"


def test_few_loose_modules():
    loose = sorted(p.stem for p in PACKAGE.glob("*.py") if not p.name.startswith("__"))
    assert set(loose) == set(ROOT), f"loose modules beside the foundations: {sorted(set(loose) - set(ROOT))}"
    assert len(loose) <= MAX_LOOSE


def test_imports_follow_the_stages():
    wrong = [f"{where}: {src or 'root'} imports {dst or 'root'}"
             for src, dst, where, _, _ in folder_edges() if rank(dst) > rank(src)]
    assert not wrong, "imports against the stage order:\n" + "\n".join(wrong)


def test_no_forbidden_arrow():
    wrong = [f"{where}: {src} imports {dst}: {FORBIDDEN[src, dst]}"
             for src, dst, where, _, _ in folder_edges() if (src, dst) in FORBIDDEN]
    assert not wrong, "\n".join(wrong)


def test_no_cycle_between_folders():
    graph: dict[str, set[str]] = {}
    for src, dst, *_ in folder_edges():
        graph.setdefault(src, set()).add(dst)
    state: dict[str, int] = {}
    cycle: list[str] = []

    def dfs(node, trail):
        state[node] = 1
        for nxt in sorted(graph.get(node, ())):
            if state.get(nxt) == 1:
                cycle.extend(trail[trail.index(nxt):] + [nxt] if nxt in trail else [node, nxt])
                return True
            if state.get(nxt) is None and dfs(nxt, trail + [nxt]):
                return True
        state[node] = 2
        return False

    for node in sorted(graph):
        if state.get(node) is None and dfs(node, [node]):
            break
    assert not cycle, "a cycle between folders: " + " -> ".join(s or "root" for s in cycle)


def test_in_function_imports_say_why():
    bare = []
    for path, parts, found in package_imports():
        if stage_of(parts) in LAZY_FOLDERS:
            continue
        for target, line, in_function, note in found:
            if in_function and not note:
                bare.append(f"{path.relative_to(PACKAGE.parent)}:{line}: {target}")
    assert not bare, ("imports inside functions without a comment saying why (hoist them to the top "
                      "of the module, or say which heavy or optional dependency they defer):\n"
                      + "\n".join(bare))


def test_the_checker_sees_a_function_import(tmp_path):
    src = tmp_path / "m.py"
    src.write_text("import os\n\ndef f():\n    from semmap_pp.run import pipeline\n"
                   "    import numba  # heavy: compiles\n")
    got = list(imports(src, ("outputs", "m")))
    assert got[0][:3] == ("os", 1, False)
    assert got[1][:3] == ("semmap_pp.run.pipeline", 4, True) and got[1][3] == ""
    assert got[2][3] == "# heavy: compiles"
    assert rank(target_stage(got[1][0])) > rank("lattice")


def module_of(dotted: str) -> tuple[str, ...] | None:
    """The ``semmap_pp`` module a dotted import lands in, as parts below the package (a package's
    ``__init__`` when no submodule of that name exists), else None."""
    parts = dotted.split(".")
    if parts[0] != "semmap_pp":
        return None
    parts = parts[1:]
    while parts:
        base = PACKAGE.joinpath(*parts)
        if base.with_suffix(".py").is_file():
            return tuple(parts)
        if (base / "__init__.py").is_file():
            return (*parts, "__init__")
        parts = parts[:-1]
    return ("__init__",)


def module_edges():
    """``(module, imported module, where)`` for every import between two modules of one folder
    (the root's modules form a folder too), those inside functions included."""
    for path, parts, found in package_imports():
        for target, line, _in_function, _note in found:
            dst = module_of(target)
            if dst is None or dst == parts or dst[:-1] != parts[:-1]:
                continue
            yield parts, dst, f"{path.relative_to(PACKAGE.parent)}:{line}"


def find_cycle(graph: dict) -> list:
    """One cycle of ``graph`` (node -> set of nodes) as a list of nodes, first node repeated at
    the end; empty when there is none."""
    state: dict = {}

    def dfs(node, trail):
        state[node] = 1
        for nxt in sorted(graph.get(node, ())):
            if state.get(nxt) == 1:
                return trail[trail.index(nxt):] + [nxt]
            if state.get(nxt) is None:
                found = dfs(nxt, trail + [nxt])
                if found:
                    return found
        state[node] = 2
        return []

    for node in sorted(graph):
        if state.get(node) is None:
            found = dfs(node, [node])
            if found:
                return found
    return []


def test_no_cycle_between_modules_of_a_folder():
    graph: dict = {}
    where: dict = {}
    for src, dst, at in module_edges():
        graph.setdefault(src, set()).add(dst)
        where.setdefault((src, dst), at)
    cycle = find_cycle(graph)
    steps = [f"{where[a, b]}: {'.'.join(a)} imports {'.'.join(b)}" for a, b in zip(cycle, cycle[1:])]
    assert not cycle, "a cycle between modules of one folder:\n" + "\n".join(steps)


def test_the_checker_sees_a_cycle():
    assert find_cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert find_cycle({"a": {"b"}, "b": {"c"}}) == []
    assert module_of("semmap_pp.knowledge.dialect.walk") == ("knowledge", "dialect")
    assert module_of("semmap_pp.knowledge.RuleSet") == ("knowledge", "__init__")
    assert module_of("numpy") is None


def test_each_stage_has_its_settings():
    """Every table of the model file is one stage's settings class (model.STAGE_SETTINGS), the
    stage a folder of the package, and every field of Model but its path belongs to one stage."""
    import dataclasses

    from semmap_pp.model import STAGE_SETTINGS, Model

    assert set(STAGE_SETTINGS) <= set(STAGES)
    tables = [t for group in STAGE_SETTINGS.values() for t in group]
    fields = [f.name for f in dataclasses.fields(Model) if f.name != "path"]
    assert sorted(tables) == sorted(fields), "model tables without a stage, or claimed twice"
