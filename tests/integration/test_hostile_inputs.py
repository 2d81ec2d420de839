"""Hostile and malformed inputs through the whole ``semmap map`` path (and ``info``, ``rules check``).

Each bad input must give one line on stderr naming the file and the problem, exit status 2 (1 for
``rules check``), no traceback and no output folder; each legal but degenerate input (all unknown,
all free, all occupied, 1 x 1) must give a schema-valid world.json and exit 0. docs/robustness.md
lists every case and what happens.

Unit-level cases that already exist are reused, not repeated:

* tests/unit/test_grid_errors.py -- 41 malformed maps (``CASES``) through ``load_map`` and ``semmap info``;
  here every one of them also goes through ``semmap map`` (:func:`test_grid_error_cases_through_map`);
* tests/unit/test_knowledge_dialect.py -- ``#script``, ``@``-terms, ``#include``, unsafe variables, syntax
  errors, weights and contradictory hard rules through ``load_rules`` / ``ground``;
* tests/unit/test_model.py -- model values out of range through ``load_model``;
* tests/integration/test_cli_map.py -- a missing rule or model file, a non-empty output folder.

The cases below are the ones those files do not cover, or cover only below the command line.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import jsonschema
import numpy as np
import pytest
from PIL import Image

import test_grid_errors
from semmap_pp.cli import main
from semmap_pp.grid import write_map
from semmap_pp.model import DEFAULT_MODEL

ROOT = Path(__file__).resolve().parents[2]
SCHEMA = json.loads((ROOT / "docs" / "world.schema.json").read_text())
FAST = ["--chains", "1", "--cores", "1", "--tune", "2", "--draws", "4", "--n-inner", "10",
        "--progress", "none"]
GOOD_YAML = test_grid_errors.GOOD_YAML   # names m.pgm, 0.05 m/cell


# --- builders: each returns (arguments after `semmap map`, the file the message must name) --------

def good_map(d: Path) -> Path:
    return test_grid_errors.yaml_with(d, GOOD_YAML)


def yaml_text(d: Path, text: str, name: str = "m.yaml") -> Path:
    test_grid_errors.good_pgm(d)
    (d / name).write_text(text)
    return d / name


def with_resolution(d: Path, value: str) -> tuple[list, Path]:
    p = yaml_text(d, test_grid_errors.replace_key("resolution", value))
    return [p], p


def with_image(d: Path, image: str, *extra: str) -> tuple[list, Path]:
    p = yaml_text(d, test_grid_errors.replace_key("image", image))
    return [p, *extra], p


def alias_bomb(d: Path) -> tuple[list, Path]:
    """A YAML whose image value is 9^8 strings by nested aliases (tiny file, huge repr)."""
    lines = ["l0: &l0 [x, x, x, x, x, x, x, x, x]"]
    for i in range(1, 8):
        lines.append(f"l{i}: &l{i} [" + ", ".join([f"*l{i - 1}"] * 9) + "]")
    p = yaml_text(d, "\n".join(lines) + "\nimage: *l7\nresolution: 0.05\n")
    return [p], p


def fifo_yaml(d: Path) -> tuple[list, Path]:
    p = d / "pipe.yaml"
    os.mkfifo(p)          # reading it would block for ever
    return [p], p


def device_yaml(d: Path) -> tuple[list, Path]:
    p = d / "zero.yaml"
    p.symlink_to("/dev/zero")   # reading it would never end
    return [p], p


def big_yaml(d: Path) -> tuple[list, Path]:
    p = yaml_text(d, GOOD_YAML + "# " + "x" * (2 << 20) + "\n")
    return [p], p


def model_edit(d: Path, old: str, new: str) -> tuple[list, Path]:
    text = DEFAULT_MODEL.read_text()
    assert old in text, old
    p = d / "model.toml"
    p.write_text(text.replace(old, new, 1))
    return [good_map(d), "--model", p], p


def fifo_model(d: Path) -> tuple[list, Path]:
    p = d / "model.toml"
    os.mkfifo(p)
    return [good_map(d), "--model", p], p


def rules(d: Path, text: str, name: str = "r.lp") -> tuple[list, Path]:
    p = d / name
    p.write_text(text)
    return [good_map(d), "--rules", p], p


def rules_bytes(d: Path, data: bytes) -> tuple[list, Path]:
    p = d / "r.lp"
    p.write_bytes(data)
    return [good_map(d), "--rules", p], p


def rules_device(d: Path) -> tuple[list, Path]:
    p = d / "r.lp"
    p.symlink_to("/dev/zero")
    return [good_map(d), "--rules", p], p


# (id, builder(tmp) -> (argv after "map", file named), phrase in the message)
CASES = [
    # maps: files that are not what their name says, or lie about their size
    ("text-named-pgm", lambda d: ((d / "t.pgm").write_text("hello") and [d / "t.pgm"], d / "t.pgm"),
     "not an image file"),
    ("zero-by-zero-png", lambda d: ([test_grid_errors.huge_png_header(d / "z.png", 0, 0)], d / "z.png"),
     "no cells (0x0)"),
    ("pgm-header-claims-20000x20000",
     lambda d: ((d / "h.pgm").write_bytes(b"P5\n20000 20000\n255\n" + b"\0" * 16)
                and [d / "h.pgm"], d / "h.pgm"), "20000x20000 = 400000000 cells"),
    ("pgm-header-claims-more-than-the-file-holds",
     lambda d: ((d / "h.pgm").write_bytes(b"P5\n3000 3000\n255\n" + b"\0" * 16)
                and [d / "h.pgm"], d / "h.pgm"), "only 16 bytes follow"),
    ("pgm-header-width-beyond-int64",
     lambda d: ((d / "h.pgm").write_bytes(b"P5\n" + b"9" * 30 + b" 1\n255\n\0")
                and [d / "h.pgm"], d / "h.pgm"), "more than the limit"),
    ("png-20000x20000-over-pillow-limit",
     lambda d: ([test_grid_errors.huge_png_header(d / "h.png", 20000, 20000), "--max-cells",
                 "500000000"], d / "h.png"), "larger than Pillow decodes safely"),
    ("float-tiff-named-png",
     lambda d: (Image.new("F", (3, 3)).save(d / "f.png", "TIFF") or [d / "f.png"], d / "f.png"),
     "mode F is not supported"),
    # YAML files that attack the reader
    ("yaml-is-a-fifo", fifo_yaml, "not a regular file"),
    ("yaml-is-dev-zero", device_yaml, "not a regular file"),
    ("yaml-over-1-mib", big_yaml, "too large for a map_server map"),
    ("yaml-alias-bomb", alias_bomb, "'image' must be a file name"),
    ("yaml-python-tag", lambda d: (lambda p: ([p], p))(yaml_text(
        d, "image: !!python/object/apply:os.system ['true']\nresolution: 0.05\n")),
     "could not determine a constructor"),
    ("yaml-resolution-huge-integer", lambda d: with_resolution(d, "1" + "0" * 400),
     "resolution must be a positive finite number"),
    ("yaml-origin-huge-integer",
     lambda d: (lambda p: ([p], p))(yaml_text(d, test_grid_errors.replace_key(
         "origin", "[1" + "0" * 400 + ", 0, 0]"))), "origin must be a list of 3 finite numbers"),
    ("yaml-mode-not-a-string", lambda d: (lambda p: ([p], p))(yaml_text(d, GOOD_YAML + "mode: [raw]\n")),
     "mode must be one of"),
    ("yaml-image-empty", lambda d: with_image(d, "''"), "'image' must be a file name"),
    # issue 55 F7: a YAML's escape names a file of bytes that are not UTF-8 (it exists: it was read)
    ("yaml-image-escape-not-utf8",
     lambda d: ((d / os.fsdecode(b"\xff.pgm")).write_bytes(b"P5 2 2 255 ....") and with_image(d, '"\\udcff.pgm"')),
     "'image' is not UTF-8 text"),
    ("yaml-image-names-a-yaml",
     lambda d: ((d / "other.yaml").write_text(GOOD_YAML) and with_image(d, "other.yaml")[0],
                d / "other.yaml"), "not an image file"),
    # YAML whose image is outside its folder (policy: refused unless --allow-outside)
    ("yaml-image-absolute-system-file", lambda d: with_image(d, "/etc/passwd"),
     "outside the YAML file's folder"),
    ("yaml-image-dot-dot", lambda d: with_image(d, "../../../../etc/passwd"),
     "outside the YAML file's folder"),
    ("yaml-image-home", lambda d: with_image(d, "~/m.pgm"), "outside the YAML file's folder"),
    ("yaml-image-outside-allowed-must-decode",
     lambda d: (with_image(d, "/etc/passwd", "--allow-outside")[0], Path("/etc/passwd")),
     "not an image file"),
    # resolution and origin that would overflow or explode the work arrays
    ("resolution-1e-9", lambda d: with_resolution(d, "1.0e-9"), "do not fit in lattice cells"),
    ("resolution-2e-4-pads-beyond-limit", lambda d: with_resolution(d, "2.0e-4"),
     "exceeds the limit of 100000000 cells"),
    ("resolution-1e300", lambda d: with_resolution(d, "1.0e+300"), "at most 1e+09 m is accepted"),
    ("origin-1e308",
     lambda d: (lambda p: ([p], p))(yaml_text(d, test_grid_errors.replace_key(
         "origin", "[1.0e+308, 0.0, 0.0]"))), "at most 1e+09 m is accepted"),
    # model files
    ("model-probability-above-one",
     lambda d: model_edit(d, "free = [0.90, 0.05, 0.05]", "free = [1.90, -0.95, 0.05]"),
     "probabilities must lie in [0, 1]"),
    ("model-probability-nan", lambda d: model_edit(d, "free = [0.90, 0.05, 0.05]", "free = [nan, 0.05, 0.05]"),
     "probabilities must lie in [0, 1]"),
    ("model-psi-nan", lambda d: model_edit(d, "psi = 0.5", "psi = nan"), "sensor.psi: must be finite"),
    ("model-k-max-huge", lambda d: model_edit(d, "k_max = 64", "k_max = 100000000000"),
     "prior.k_max: must be <= 100000"),
    ("model-kernel-weight-not-a-number",
     lambda d: model_edit(d, "add_remove = 1.0", 'add_remove = "lots"'), "[kernels]"),
    ("model-kernel-weight-infinite",
     lambda d: model_edit(d, "add_remove = 1.0", "add_remove = inf"), "weights must be finite"),
    ("model-is-a-fifo", fifo_model, "not a regular file"),
    # rule files
    ("rules-script", lambda d: rules(d, "#script (python)\nimport os\nos.system('true')\n#end.\n"),
     "#script is not allowed"),
    ("rules-at-term", lambda d: rules(d, "p(X) :- unit(X), X = @f(X).\n"), "@-terms"),
    ("rules-include-system-file", lambda d: rules(d, '#include "/etc/passwd".\n'), "absolute path"),
    ("rules-include-dot-dot", lambda d: rules(d, '#include "../../../../../etc/passwd".\n'),
     "outside the rules folder"),
    ("rules-unsafe-variable", lambda d: rules(d, ":- room(U), not adj(U,V).\n"), "unsafe"),
    ("rules-syntax-error", lambda d: rules(d, ":- room(U)\n:- hall(U).\n"), "syntax error"),
    ("rules-weight-negative", lambda d: rules(d, ":~ rolike(U), room(U). [-1500@0, r, U]\n"),
     "negative weight"),
    ("rules-weight-huge", lambda d: rules(d, ":~ rolike(U), room(U). [900000@0, r, U]\n"), "too large"),
    ("rules-weight-wraps-32-bit", lambda d: rules(d, ":~ rolike(U), room(U). [4294968296@0, r, U]\n"),
     "integer 4294968296 is too large"),
    ("rules-weight-nan", lambda d: rules(d, ":~ rolike(U), room(U). [nan@0, r, U]\n"), "not a #const"),
    ("rules-weight-string", lambda d: rules(d, ':~ rolike(U), room(U). ["1.5"@0, r, U]\n'),
     "not an integer"),
    ("rules-interval-explodes-grounding", lambda d: rules(d, "big(Y) :- unit(X), Y = 1..30000000.\n"),
     "intervals"),
    ("rules-recursion-without-end", lambda d: rules(d, "c(X) :- unit(X).\nc(X+1) :- c(X).\n"),
     "must be a variable or a constant"),
    # clingo solves Q from Q-5: adj(1,2) gives adj(7,1), then adj(6,7), ... without end (it
    # passed `semmap rules check` and hung `semmap map`; found by bench/fuzz.py)
    ("rules-recursion-through-body-arithmetic", lambda d: rules(d, "adj(Q,P) :- adj(P,Q-5).\n"),
     "head variable Q must occur in a positive body atom, outside arithmetic"),
    ("rules-six-free-unit-variables", lambda d: rules(
        d, ":~ unit(A), unit(B), unit(C), unit(D), unit(E), unit(F), room(A). [1@0, m, A, B, C, D, E, F]\n"),
     "over the limit of 2,000,000"),     # ran without end without the grounding bound
    ("rules-binary-file", lambda d: rules_bytes(d, bytes(range(256))), "cannot read rule file"),
    ("rules-non-ascii-character", lambda d: rules(d, ":- room(U) \u00e9.\n"),
     "not allowed outside comments and strings"),
    ("rules-dev-zero", rules_device, "not a regular file"),
]


def run_map(argv, out: Path, capsys) -> tuple[int, str, str]:
    code = main(["map", *map(str, argv), "--out", str(out), *FAST])
    captured = capsys.readouterr()
    return code, captured.out, captured.err


@pytest.mark.parametrize("build, phrase", [c[1:] for c in CASES], ids=[c[0] for c in CASES])
def test_hostile_input_through_map_is_one_line_and_exit_2(tmp_path, capsys, build, phrase):
    d = tmp_path / "in"
    d.mkdir()
    argv, named = build(d)
    out = tmp_path / "out"
    code, stdout, stderr = run_map(argv, out, capsys)
    assert code == 2, stderr
    lines = stderr.splitlines()
    assert len(lines) == 1, stderr
    assert lines[0].startswith(f"semmap: error: {named}"), lines[0]
    assert phrase in lines[0], lines[0]
    assert len(lines[0]) < 400 and stdout == ""
    assert not out.exists()


@pytest.mark.parametrize("build, phrase", [c[1:] for c in test_grid_errors.CASES],
                         ids=[c[0] for c in test_grid_errors.CASES])
def test_grid_error_cases_through_map(tmp_path, capsys, build, phrase):
    d = tmp_path / "in"
    d.mkdir()
    path, kwargs = build(d)
    argv = [path]
    for key, value in kwargs.items():
        argv += [f"--{key.replace('_', '-')}", str(value)]
    code, stdout, stderr = run_map(argv, tmp_path / "out", capsys)
    assert code == 2 and stdout == ""
    lines = stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("semmap: error: ") and phrase in lines[0], stderr
    assert not (tmp_path / "out").exists()


# --- legal inputs: sound results ------------------------------------------------------------------

def test_image_outside_the_folder_loads_with_allow_outside(tmp_path, capsys):
    (tmp_path / "images").mkdir()
    (tmp_path / "maps").mkdir()
    write_map(tmp_path / "images" / "m.yaml", np.array([[254, 0], [205, 254]], np.uint8), 0.1)
    (tmp_path / "maps" / "m.yaml").write_text(test_grid_errors.replace_key("image", "../images/m.pgm"))
    assert main(["info", str(tmp_path / "maps" / "m.yaml")]) == 2
    assert "outside the YAML file's folder" in capsys.readouterr().err
    assert main(["info", str(tmp_path / "maps" / "m.yaml"), "--allow-outside", "--json"]) == 0
    facts = json.loads(capsys.readouterr().out)
    assert facts["counts"] == {"free": 2, "unknown": 1, "occupied": 1}
    assert any("outside the YAML file's folder (allowed)" in n for n in facts["notes"])


@pytest.mark.parametrize("image", ["sub/../m.pgm", "./m.pgm"])
def test_dot_dot_that_stays_inside_the_folder_is_legal(tmp_path, capsys, image):
    (tmp_path / "sub").mkdir()
    with_image(tmp_path, image)
    assert main(["info", str(tmp_path / "m.yaml")]) == 0, capsys.readouterr().err


@pytest.mark.parametrize("fmt, suffix, described", [
    ("PNG", ".pgm", "PNG L"), ("JPEG", ".png", "JPEG L"), ("GIF", ".pgm", "GIF P"), ("BMP", ".png", "BMP L")])
def test_mislabelled_images_are_read_by_their_content(tmp_path, capsys, fmt, suffix, described):
    a = np.full((6, 5), 254, np.uint8)
    a[2:4, 1:3] = 0
    Image.fromarray(a).save(tmp_path / f"m{suffix}", fmt)
    assert main(["info", str(tmp_path / f"m{suffix}"), "--json"]) == 0
    facts = json.loads(capsys.readouterr().out)
    assert described in facts["image_format"]
    assert facts["width"] == 5 and facts["height"] == 6
    assert facts["counts"]["occupied"] == 4 and facts["counts"]["free"] == 26


def test_pgm_with_more_bytes_than_its_header_reads_the_header_size(tmp_path, capsys):
    (tmp_path / "m.pgm").write_bytes(b"P5\n2 1\n255\n\xfe\x00" + b"\x00" * 50)
    assert main(["info", str(tmp_path / "m.pgm"), "--json"]) == 0
    facts = json.loads(capsys.readouterr().out)
    assert (facts["width"], facts["height"]) == (2, 1)
    assert facts["counts"] == {"free": 1, "unknown": 0, "occupied": 1}


def degenerate(d: Path, value: int, shape) -> Path:
    return write_map(d / "m.yaml", np.full(shape, value, np.uint8), 0.05)


def check_world(out: Path, shape) -> dict:
    doc = json.loads((out / "world.json").read_text())
    jsonschema.validate(doc, SCHEMA)
    assert (doc["map"]["height"], doc["map"]["width"]) == shape
    labels = np.asarray(Image.open(out / "labels.png"))
    assert labels.shape == shape
    assert set(np.unique(labels)) - {0} == {u["id"] for u in doc["units"]}
    return doc


def test_all_unknown_map_gives_an_empty_world(tmp_path, capsys):
    code, stdout, stderr = run_map([degenerate(tmp_path, 205, (30, 40))], tmp_path / "out", capsys)
    assert code == 0, stderr
    doc = check_world(tmp_path / "out", (30, 40))
    assert doc["units"] == [] and doc["adjacency"] == [] and doc["cpr"] is None  # empty ROI


@pytest.mark.parametrize("value", [0, 254], ids=["all-occupied", "all-free"])
def test_all_occupied_or_all_free_map_gives_a_valid_world(tmp_path, capsys, value):
    code, stdout, stderr = run_map([degenerate(tmp_path, value, (30, 40))], tmp_path / "out", capsys)
    assert code == 0, stderr
    doc = check_world(tmp_path / "out", (30, 40))
    assert len(doc["units"]) <= 1   # 1.5 x 2 m: room for one unit at most


# When no rectangle of the minimum side fits the map, log p_rect = -inf; the empty world's prior
# must not become 0 * -inf = NaN (it did, and the run crashed; posterior.prior_n and prior.log_prior).
@pytest.mark.parametrize("shape", [(1, 1), (1, 200)])
def test_map_smaller_than_a_unit_gives_an_empty_world(tmp_path, capsys, shape):
    code, stdout, stderr = run_map([degenerate(tmp_path, 254, shape)], tmp_path / "out", capsys)
    assert code == 0, stderr
    assert check_world(tmp_path / "out", shape)["units"] == []


def test_contradictory_hard_rules_stop_the_run_with_one_line_and_no_output(tmp_path, capsys):
    (tmp_path / "r.lp").write_text("% no unit may exist\n:- unit(U).\n")
    argv = [ROOT / "tests" / "data" / "maps" / "intel_corner.yaml", "--rules", tmp_path / "r.lp"]
    code, stdout, stderr = run_map(argv, tmp_path / "out", capsys)
    assert code == 2
    last = stderr.splitlines()[-1]
    assert last.startswith(f"semmap: error: {tmp_path / 'r.lp'}: the hard rules admit no world"), stderr
    assert "Traceback" not in stderr and not (tmp_path / "out").exists()


def test_out_of_memory_is_one_line_and_exit_2(tmp_path, capsys, monkeypatch):
    import semmap_pp.run.inputs

    def no_memory(*args, **kwargs):
        raise MemoryError()

    monkeypatch.setattr(semmap_pp.run.inputs, "building_frame", no_memory)
    code, stdout, stderr = run_map([good_map(tmp_path)], tmp_path / "out", capsys)
    assert code == 2 and stdout == ""
    assert stderr.splitlines() == [stderr.strip()] and stderr.startswith("semmap: error: out of memory")
    assert not (tmp_path / "out").exists()


def test_rule_file_that_includes_itself_is_read_once(tmp_path, capsys):
    (tmp_path / "r.lp").write_text('#include "r.lp".\n:- unit(U), room(U), hall(U).\n')
    assert main(["rules", "check", str(tmp_path / "r.lp")]) == 0
    assert "1 hard, 0 soft" in capsys.readouterr().out


# --- a representative part as real subprocesses ----------------------------------------------------

def semmap(*args) -> subprocess.CompletedProcess:
    env = dict(os.environ, PYTHONWARNINGS="error::RuntimeWarning")
    return subprocess.run([sys.executable, "-m", "semmap_pp", *map(str, args)], capture_output=True,
                          text=True, timeout=120, env=env)


def assert_one_line(result, code: int, named: Path, phrase: str, prefix: str = "semmap: error: "):
    assert result.returncode == code, result.stderr
    assert "Traceback" not in result.stderr and result.stdout == ""
    lines = result.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"{prefix}{named}") and phrase in lines[0], lines


def test_subprocess_map_refuses_a_20000_square_pgm_before_reading_it(tmp_path):
    path = tmp_path / "h.pgm"
    path.write_bytes(b"P5\n20000 20000\n255\n" + b"\0" * 16)
    result = semmap("map", path, "--out", tmp_path / "out", *FAST)
    assert_one_line(result, 2, path, "more than the limit of 100000000 cells")
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("case", ["yaml-alias-bomb", "yaml-image-absolute-system-file"])
def test_subprocess_info(tmp_path, case):
    build = dict((c[0], c[1]) for c in CASES)[case]
    phrase = dict((c[0], c[2]) for c in CASES)[case]
    argv, named = build(tmp_path)
    assert_one_line(semmap("info", *argv), 2, named, phrase)


@pytest.mark.parametrize("case", ["rules-script", "rules-weight-wraps-32-bit", "rules-non-ascii-character"])
def test_subprocess_rules_check(tmp_path, case):
    build = dict((c[0], c[1]) for c in CASES)[case]
    phrase = dict((c[0], c[2]) for c in CASES)[case]
    argv, named = build(tmp_path)
    assert_one_line(semmap("rules", "check", named), 1, named, phrase, prefix="")


# knowledge/evidence.py parses evidence facts with clingo, whose lexer error on a non-ASCII character
# quotes one byte of it; clingo's Python logger cannot decode that message and clingo aborts the
# process ("PANIC: exception in nothrow scope", SIGABRT). Rule files are guarded by
# dialect.check_lexemes, and so are evidence files (knowledge.evidence.evidence_from_facts).
def test_subprocess_rules_query_with_non_ascii_evidence(tmp_path):
    (tmp_path / "ev.lp").write_text("unit(1). \u00e9\n")
    result = semmap("rules", "query", ROOT / "rules" / "table3.lp", "--evidence", tmp_path / "ev.lp")
    assert_one_line(result, 2, tmp_path / "ev.lp", "")


# ---- names that are not UTF-8 (issue 55's F7) -----------------------------------------------------
# Linux file names are bytes; Python keeps a byte that is not UTF-8 as a lone surrogate, which no
# UTF-8 output can hold (the run ended in a UnicodeEncodeError after sampling, an empty folder left).
# Every argument is checked before anything is read; names that come from elsewhere (a resumed run's
# absolute paths, made in a folder of such a name) are written as escapes.

NOT_UTF8 = os.fsdecode(b"\xff")       # "\udcff"


@pytest.mark.parametrize("where", ["yaml", "image", "out", "out-parent", "start"])
def test_a_name_that_is_not_utf8_is_refused_before_anything(tmp_path, capsys, where):
    good = good_map(tmp_path)
    argv = [str(good), "--out", str(tmp_path / "out"), *FAST]
    bad = {"yaml": tmp_path / f"m{NOT_UTF8}.yaml", "image": tmp_path / f"{NOT_UTF8}.pgm",
           "out": tmp_path / f"o{NOT_UTF8}", "out-parent": tmp_path / f"d{NOT_UTF8}" / "out",
           "start": tmp_path / f"w{NOT_UTF8}.json"}[where]
    if where == "yaml":
        bad.write_text(good.read_text())
        argv[0] = str(bad)
    elif where == "image":
        bad.write_bytes((tmp_path / "m.pgm").read_bytes())
        argv[0] = str(bad)
    elif where.startswith("out"):
        argv[2] = str(bad)
    else:
        bad.write_text("{}")
        argv += ["--start", str(bad)]
    code = main(["map", *argv])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "Traceback" not in err
    shown = str(bad).replace(NOT_UTF8, "\\xff")
    assert err.startswith(f"semmap: error: {shown}: not UTF-8 text"), err
    err.encode("utf-8")                                  # the message itself prints anywhere
    assert [p for p in tmp_path.iterdir() if p.is_dir()] == []     # no output folder, nor its parent


@pytest.mark.parametrize("command", ["info", "score", "rules-check", "where"])
def test_every_command_refuses_such_a_name_in_a_real_process(tmp_path, command):
    d = os.fsencode(tmp_path)
    name = d + b"/\xfe\xe9.yaml"
    argv = {"info": [b"info", name], "score": [b"score", name, name],
            "rules-check": [b"rules", b"check", d + b"/r\xe9.lp"], "where": [b"where", name, b"0", b"0"]}[command]
    result = subprocess.run([os.fsencode(sys.executable), b"-m", b"semmap_pp", *argv], capture_output=True,
                            timeout=120, cwd=ROOT)
    err = result.stderr.decode("utf-8")                 # valid UTF-8: nothing was printed raw
    assert result.returncode == 2 and result.stdout == b"" and "Traceback" not in err
    shown = "r\\xe9.lp" if command == "rules-check" else "\\xfe\\xe9.yaml"
    assert err.count("\n") == 1 and f"{shown}: not UTF-8 text" in err, err


def test_a_run_made_in_a_folder_of_such_a_name_resumes(tmp_path):
    """``semmap map m.yaml --out out`` run inside a folder named b'd\\xfc' works (its arguments are
    UTF-8) and stores the map's absolute path, which is not; ``--resume out`` writes every output,
    the name escaped."""
    folder = os.fsencode(tmp_path) + b"/d\xfc"
    os.mkdir(folder)
    write_map(Path(os.fsdecode(folder)) / "m.yaml", np.pad(np.full((36, 46), 254, np.uint8), 2), 0.05)
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    run = [sys.executable, "-m", "semmap_pp", "map"]
    first = subprocess.run([*run, "m.yaml", "--out", "out", *FAST], cwd=folder, env=env, capture_output=True,
                           text=True, timeout=300)
    assert first.returncode == 0, first.stderr
    out = Path(os.fsdecode(folder)) / "out"
    meta = json.loads(str(np.load(out / "resume.npz")["meta"]))
    assert NOT_UTF8 not in meta["inputs"]["map"] and os.fsdecode(b"\xfc") in meta["inputs"]["map"]
    again = subprocess.run([*run, "--resume", "out", "--draws", "4", "--progress", "none"], cwd=folder,
                           env=env, capture_output=True, timeout=300)
    assert again.returncode == 0, again.stderr.decode("utf-8", "replace")[-2000:]
    assert "Traceback" not in again.stderr.decode("utf-8", "replace")
    doc = json.loads((out / "world.json").read_text(encoding="utf-8"))
    jsonschema.validate(doc, SCHEMA)
    assert (out / "report.html").read_text(encoding="utf-8") and (out / "diagnostics.txt").read_text(encoding="utf-8")
    import h5py

    with h5py.File(out / "trace.nc", "r") as f:
        assert f.attrs["map"].endswith("d\\xfc/m.yaml")


def test_printable_shows_the_bytes_of_a_name():
    from semmap_pp.errors import SemmapError, printable

    assert printable(os.fsdecode(b"/m/\xff\xc3\xa9.png")) == "/m/\\xffé.png"
    assert printable("caf\u00e9") == "caf\u00e9" and printable(None) == "None"
    assert printable("a\ud800") == "a\\ud800"       # a surrogate no file name gives
    e = SemmapError(os.fsdecode(b"/x/\xfe.yaml"), "cannot read " + os.fsdecode(b"\xfe"), 3, 4)
    assert str(e) == "/x/\\xfe.yaml:3:4: cannot read \\xfe"


# ---- tall and thin maps (issue 55's F8) -----------------------------------------------------------
# A figure's sides follow the map's: 1 x 2000 cells drew 0.7 pixels wide, and matplotlib's PNG writer
# refused the empty image after world.json was written (no report, no resume.npz).

@pytest.mark.parametrize("shape, walls", [((2000, 1), False), ((4000, 3), True)])
def test_a_tall_thin_map_runs_to_the_end_with_figures_of_a_minimum_width(tmp_path, capsys, shape, walls):
    from semmap_pp.outputs.figures import MIN_SIDE_PX
    from semmap_pp.outputs.report import FILES

    a = np.full(shape, 254, np.uint8)
    if walls:
        a[:, 0] = a[:, -1] = 0
    code, stdout, stderr = run_map([write_map(tmp_path / "m.yaml", a, 0.05)], tmp_path / "out", capsys)
    assert code == 0, stderr
    check_world(tmp_path / "out", shape)
    assert {p.name for p in (tmp_path / "out").iterdir()} >= set(FILES) | {"resume.npz"}
    for name in ("overlay", "graph", "posterior", "posterior_cells"):
        w, h = Image.open(tmp_path / "out" / f"{name}.png").size
        assert w >= MIN_SIDE_PX and h >= 1000, (name, w, h)


def test_a_figure_box_of_one_cell_by_thousands_has_both_sides(capsys):
    from semmap_pp.outputs import figures

    for box in ((0, 5000, 0, 1), (0, 1, 0, 5000), (0, 100_000, 0, 2)):
        fig, (ax,) = figures._axes(box, extra_h=0.1, long_side=900)
        w, h = fig.get_size_inches() * figures.DPI
        assert min(w, h) >= figures.MIN_SIDE_PX - 1e-9
        assert Image.open(__import__("io").BytesIO(figures.png(fig))).size[0] >= figures.MIN_SIDE_PX
