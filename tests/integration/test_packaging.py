"""The wheel carries the knowledge and the numbers: a package installed with ``pip install .`` finds
its rule files and model file without the checkout (semmap_pp.resources, setup.py)."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

from semmap_pp.cli.cmd_rules import shipped_listing
from semmap_pp.resources import DEFAULT_MODEL, DEFAULT_RULES, SHIPPED, evidence_files, rule_files, shipped

ROOT = Path(__file__).resolve().parents[2]
BUILD_FILES = ("pyproject.toml", "setup.py", "MANIFEST.in", "README.md")


def _tracked(folder: Path) -> list[str]:
    """The files of ``folder`` as the build copies them (caches and hidden files left out)."""
    return sorted(p.relative_to(folder).as_posix() for p in folder.rglob("*")
                  if p.is_file() and "__pycache__" not in p.parts and not p.name.startswith(".")
                  and p.suffix != ".pyc")


@pytest.fixture(scope="module")
def wheel(tmp_path_factory) -> Path:
    """A wheel built offline from a copy of the checkout's sources (the checkout is not written)."""
    pytest.importorskip("setuptools", minversion="77")
    src = tmp_path_factory.mktemp("src")
    for name in BUILD_FILES:
        shutil.copy2(ROOT / name, src / name)
    ignore = shutil.ignore_patterns("__pycache__", "*.pyc", "_share")
    for name in ("semmap_pp", *SHIPPED):
        shutil.copytree(ROOT / name, src / name, ignore=ignore)
    out = tmp_path_factory.mktemp("wheel")
    run = subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation",
                          "--no-index", "-q", "-w", str(out), str(src)],
                         capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr
    (whl,) = out.glob("semmap_pp-*.whl")
    return whl


def test_the_checkout_serves_its_own_folders():
    assert shipped("rules") == ROOT / "rules" and shipped("models") == ROOT / "models"
    assert DEFAULT_RULES == ROOT / "rules" / "table3.lp" and DEFAULT_MODEL == ROOT / "models" / "default.toml"
    assert [f.name for f in rule_files()] == ["halls_to_corridors.lp", "none.lp", "table3.lp",
                                              "table3_learned.lp"]
    assert [f.name for f in evidence_files()] == ["small_floor.lp"]
    with pytest.raises(ValueError, match="not a shipped folder"):
        shipped("data")


def test_the_wheel_holds_every_module_rule_file_and_the_model(wheel):
    names = set(zipfile.ZipFile(wheel).namelist())
    modules = {"semmap_pp/" + m for m in _tracked(ROOT / "semmap_pp") if m.endswith(".py")}
    assert modules and modules <= names, sorted(modules - names)[:5]
    for folder in SHIPPED:
        want = {f"semmap_pp/_share/{folder}/{f}" for f in _tracked(ROOT / folder)}
        assert want and want <= names, sorted(want - names)
    assert "semmap_pp/_share/rules/table3.lp" in names and "semmap_pp/_share/models/default.toml" in names
    assert not any(n.startswith(("rules/", "models/")) for n in names)   # nothing at site-packages' top


def test_an_installed_package_reads_its_own_copies(wheel, tmp_path):
    site = tmp_path / "site"
    zipfile.ZipFile(wheel).extractall(site)
    (tmp_path / "models").mkdir()            # an unrelated folder beside the package is not read
    (site / "models").mkdir()
    (site / "models" / "default.toml").write_text("not toml [")
    code = ("import semmap_pp, semmap_pp.resources as r;"
            "from semmap_pp.model import load_model; from semmap_pp.knowledge import load_rules;"
            "print(semmap_pp.__file__); print(r.DEFAULT_MODEL); print(r.DEFAULT_RULES);"
            "m = load_model(); rs = load_rules(r.DEFAULT_RULES); print(m.path, rs.n_soft)")
    env = {**os.environ, "PYTHONPATH": str(site)}
    run = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, env=env, capture_output=True,
                         text=True, timeout=120)
    assert run.returncode == 0, run.stderr
    package, model, rules, loaded = run.stdout.splitlines()
    share = site / "semmap_pp" / "_share"
    assert Path(package).parent == site / "semmap_pp"
    assert Path(model) == share / "models" / "default.toml"
    assert Path(rules) == share / "rules" / "table3.lp"
    assert loaded.split()[0] == str(share / "models" / "default.toml") and int(loaded.split()[1]) > 0
    listing = subprocess.run([sys.executable, "-m", "semmap_pp", "rules", "list"], cwd=tmp_path,
                             env=env, capture_output=True, text=True, timeout=120)
    assert listing.returncode == 0, listing.stderr
    assert f"rule files in {share / 'rules'}:" in listing.stdout
    assert f"model file: {share / 'models' / 'default.toml'}" in listing.stdout


def test_rules_list_names_every_shipped_file_and_the_defaults():
    lines = shipped_listing()
    assert lines[0] == f"rule files in {ROOT / 'rules'}:"
    for f in rule_files() + evidence_files():
        assert any(ln.lstrip().startswith(f.relative_to(ROOT / "rules").as_posix()) for ln in lines), f
    (default,) = [ln for ln in lines if "(the default of --rules)" in ln]
    assert default.lstrip().startswith("table3.lp") and "Table 3 of Liu & von Wichert" in default
    assert f"model file: {DEFAULT_MODEL} (the default of --model)" in lines
