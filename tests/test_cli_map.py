"""End to end through the command line (subprocesses) on a small real map."""

import json
import subprocess
import sys
from pathlib import Path

import jsonschema
import numpy as np
import pytest
from PIL import Image

ROOT = Path(__file__).resolve().parents[1]
MAP = ROOT / "tests" / "data" / "maps" / "intel_corner.yaml"
SCHEMA = json.loads((ROOT / "docs" / "world.schema.json").read_text())
FAST = ["--chains", "2", "--cores", "1", "--tune", "4", "--draws", "4", "--n-inner", "20"]


def semmap(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "semmap_pp", *map(str, args)], capture_output=True,
                          text=True, cwd=cwd, timeout=600)


@pytest.fixture(scope="module")
def first_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("run") / "a"
    r = semmap("map", MAP, "--out", out, "--seed", 7, *FAST)
    assert r.returncode == 0, r.stderr
    return out, r


def test_map_writes_every_file(first_run):
    out, r = first_run
    names = {p.name for p in out.iterdir()}
    assert {"diagnostics.txt", "labels.png", "trace.nc", "world.json", "resume.npz"} <= names
    doc = json.loads((out / "world.json").read_text())
    jsonschema.validate(doc, SCHEMA)
    assert doc["map"]["width"] == 240 and doc["map"]["height"] == 207
    assert len(doc["units"]) >= 3 and doc["cpr"] > 0.6
    labels = np.asarray(Image.open(out / "labels.png"))
    assert labels.shape == (207, 240)
    assert set(np.unique(labels)) - {0} == {u["id"] for u in doc["units"]}
    text = (out / "diagnostics.txt").read_text()
    assert "R-hat" in text and "log_posterior" in text
    # the W* line names the units by type, as world.json types them; diagnostics.txt repeats it
    line = next(x for x in r.stderr.splitlines() if "W*:" in x)
    types = [u["type"] for u in doc["units"]]
    assert f"W*: {len(types)} units (" in line
    assert all(f"{types.count(t)} {t}" in line for t in set(types))
    assert line[line.index("W*:"):line.index(", log posterior")] in text
    # the verdict of the chains, as diagnostics.txt gives it, and where to read more
    verdict = "converged" if "\nconverged\n" in text else "NOT converged"
    assert f"chains: {verdict} (2 x 4 draws; R-hat and ESS: `semmap diagnose {out}`)" in r.stderr
    note = [x for x in text.splitlines() if x.startswith("chains in separate modes")]
    assert note == [x for x in r.stderr.splitlines() if x.startswith("chains in separate modes")]
    # the diagnostics within the best chain's mode: heading and verdict in the file, one line in the log
    lines = text.splitlines()
    heads = [i for i, x in enumerate(lines) if x.startswith("within the best chain's mode (")]
    logged = [x for x in r.stderr.splitlines() if x.startswith("within the best chain's mode (")]
    assert len(heads) == len(logged) == 1              # n_hall is 0 in every draw: constant there
    verdict = next(x for x in lines[heads[0]:] if "mixed within the mode" in x)
    assert logged == [f"{lines[heads[0]]}: {verdict}"]
    report_html = (out / "report.html").read_text()
    assert "ithin the best chain&#x27;s mode (" in report_html and "mixed within the mode" in report_html
    # the report links every file of the folder, resume.npz (written after it) included
    report = (out / "report.html").read_text()
    for name in names:
        assert f'href="{name}"' in report, name


def test_same_seed_same_world_json(first_run, tmp_path):
    out, _ = first_run
    r = semmap("map", MAP, "--out", tmp_path / "b", "--seed", 7, *FAST)
    assert r.returncode == 0, r.stderr
    assert (tmp_path / "b" / "world.json").read_bytes() == (out / "world.json").read_bytes()


def test_non_empty_out_dir_is_refused(first_run):
    out, _ = first_run
    r = semmap("map", MAP, "--out", out, *FAST)
    assert r.returncode == 2
    assert r.stderr.strip().count("\n") == 0 and "not empty" in r.stderr and "Traceback" not in r.stderr


@pytest.mark.parametrize("bad, needle", [
    (["--rules", "missing.lp"], "missing.lp"),
    (["--model", "missing.toml"], "missing.toml"),
])
def test_bad_inputs_one_line_no_output(tmp_path, bad, needle):
    out = tmp_path / "o"
    r = semmap("map", MAP, "--out", out, *FAST, *bad)
    assert r.returncode == 2, r.stderr
    assert needle in r.stderr and r.stderr.strip().count("\n") == 0 and "Traceback" not in r.stderr
    assert not out.exists()
