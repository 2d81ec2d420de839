"""Where the knowledge and the numbers that ship with semmap_pp are: ``rules/`` and ``models/``.

They are top-level folders of the repository, so that a user edits knowledge and numbers without
touching code. Run from a checkout (or an editable install, ``make install``), they are read from
there. A wheel (``pip install .``, ``pip install git+URL``) cannot hold top-level folders, so the
build copies them into the package as ``semmap_pp/_share/rules`` and ``semmap_pp/_share/models``
(``setup.py``); an installed package reads those. The copies win when both exist, so that an
installed package never reads an unrelated ``models/`` folder that happens to lie beside it in
``site-packages``.

>>> shipped("rules").joinpath("table3.lp").is_file() and DEFAULT_MODEL.is_file()
True
"""

from __future__ import annotations

from pathlib import Path

PACKAGE_DIR = Path(__file__).resolve().parent
#: the copies a wheel carries (absent in a checkout)
SHARE_DIR = PACKAGE_DIR / "_share"
#: the folders that ship with the package, as setup.py copies them
SHIPPED = ("rules", "models")


def shipped(name: str) -> Path:
    """The folder ``name`` (one of :data:`SHIPPED`): the package's copy when installed from a
    wheel, else the checkout's top-level folder (which may be missing if a checkout was pruned;
    reading a file from it then fails with the path named)."""
    if name not in SHIPPED:
        raise ValueError(f"not a shipped folder: {name!r} (one of {', '.join(SHIPPED)})")
    copy = SHARE_DIR / name
    return copy if copy.is_dir() else PACKAGE_DIR.parent / name


#: the rule file `semmap map` and the rest use unless told otherwise (the paper's Table 3)
DEFAULT_RULES = shipped("rules") / "table3.lp"
#: the model file every command reads unless given ``--model``
DEFAULT_MODEL = shipped("models") / "default.toml"


def rule_files() -> list[Path]:
    """The shipped rule files (``rules/*.lp``), sorted by name."""
    return sorted(shipped("rules").glob("*.lp"))


def evidence_files() -> list[Path]:
    """The shipped evidence examples for ``semmap rules query`` (``rules/evidence/*.lp``)."""
    return sorted((shipped("rules") / "evidence").glob("*.lp"))
