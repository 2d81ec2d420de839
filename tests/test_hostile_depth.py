"""Inputs nested or sized to break a parser (issue 55's F9, F10, F11, F12 and --n-inner): each is
one line naming the file (or the option), exit 2, no traceback."""

import json
from pathlib import Path

import pytest

from semmap_pp.cli import main

ROOT = Path(__file__).resolve().parents[1]
INTEL = ROOT / "tests" / "data" / "maps" / "intel_corner.yaml"
RULES = ROOT / "rules" / "table3.lp"


def _err(capsys) -> str:
    err = capsys.readouterr().err.strip()
    assert "Traceback" not in err and "\n" not in err and len(err) < 400, err[:500]
    return err


@pytest.mark.parametrize("depth", [3_000, 100_000])
def test_json_nested_too_deep_is_one_line(tmp_path, capsys, depth):
    f = tmp_path / "w.json"
    f.write_text("[" * depth + "]" * depth)
    for argv in (["where", str(f), "1", "1"], ["diff", str(f), str(f)], ["score", str(INTEL), str(f)]):
        assert main(argv) == 2
        err = _err(capsys)
        assert "w.json" in err and ("nested too deeply" in err or "not a world.json" in err)


@pytest.mark.parametrize("digits", [4_400, 20_000])
def test_json_with_an_integer_of_thousands_of_digits_is_one_line(tmp_path, capsys, digits):
    f = tmp_path / "w.json"
    f.write_text('{"format": "semmap_pp.world/1", "units": [{"id": ' + "7" * digits + "}]}")
    assert main(["where", str(f), "1", "1"]) == 2
    assert "digits" in _err(capsys)


@pytest.mark.parametrize("rule", [
    "p(X) :- unit(X), q({}).",                          # a term nested 5,000 deep
    ":~ unit(U). [{}@0, U]",                            # a weight that is a sum of 20,000 terms
])
def test_rules_nested_too_deep_are_one_line(tmp_path, capsys, rule):
    inner = ("f(" * 5000 + "X" + ")" * 5000) if rule.startswith("p(") else "+".join(["1"] * 20000)
    f = tmp_path / "deep.lp"
    f.write_text(rule.format(inner) + "\n")
    assert main(["rules", "check", str(f)]) in (1, 2)
    out = _err(capsys)
    # how deep Python's stack goes differs between processes: past it, "nested too deeply";
    # short of it, the file's own error (q/1 is no predicate; a sum is no weight). Either way one
    # line naming the file.
    assert "deep.lp" in out and ("nested too deeply" in out or "unknown predicate" in out
                                 or "weight" in out)


@pytest.mark.parametrize("where", ["rule", "evidence"])
def test_a_nul_byte_is_refused_with_its_place(tmp_path, capsys, where):
    f = tmp_path / "x.lp"
    if where == "rule":
        f.write_bytes(b"rolike(U) :- unit(U).\n:~ unit(U).\x00 [1@0, U]\n")
        assert main(["rules", "check", str(f)]) in (1, 2)
    else:
        f.write_bytes(b"unit(1).\nunit(2).\x00 adj(1,2).\n")
        assert main(["rules", "query", str(RULES), "--evidence", str(f)]) == 2
    err = _err(capsys)
    assert "x.lp:2:" in err and "NUL byte" in err


@pytest.mark.parametrize("argv, what", [
    (["--seed", str(2 ** 64)], "--seed: must be at most 4294967295"),
    (["--n-inner", "999999999999"], "--n-inner: must be at most 1,000,000"),
])
def test_seed_and_kernels_per_draw_are_bounded(tmp_path, capsys, argv, what):
    with pytest.raises(SystemExit) as exc:
        main(["map", str(INTEL), "--out", str(tmp_path / "o"), *argv])
    assert exc.value.code == 2
    assert what in capsys.readouterr().err
    assert not (tmp_path / "o").exists()
