"""End to end through the command line (subprocesses) on a small real map."""

import json
import re
import subprocess
import sys
from pathlib import Path

import jsonschema
import numpy as np
import pytest
from PIL import Image

ROOT = Path(__file__).resolve().parents[2]
MAP = ROOT / "tests" / "data" / "maps" / "intel_corner.yaml"
SCHEMA = json.loads((ROOT / "docs" / "world.schema.json").read_text())
FAST = ["--chains", "2", "--cores", "1", "--tune", "4", "--draws", "4", "--n-inner", "20", "--spread-draws", "8"]


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
    assert {"diagnostics.txt", "labels.png", "trace.nc", "spread.nc", "world.json", "resume.npz"} <= names
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
    hint = "" if verdict == "converged" else f"; whether other seeds find the same plan: `semmap stability {MAP}`"
    assert f"chains: {verdict} (2 x 4 draws; R-hat and ESS: `semmap diagnose {out}`{hint})" in r.stderr
    # the search's note on separate modes, as diagnostics.txt gives it above the sample around W*
    # (whose own section may hold a note of its chains: the log names that sample's verdict only)
    search = text[:text.index("\nsample around W* (")]
    note = [x for x in search.splitlines() if x.startswith("chains in separate modes")]
    assert note == [x for x in r.stderr.splitlines() if x.startswith("chains in separate modes")]
    # the sample around W* (the spread figures' draws): its line in the log, its report in the file
    sample = next(x for x in text.splitlines() if x.startswith("sample around W* ("))
    assert sample in r.stderr and "2 chain(s) x 8 draws x 20 kernels from W*" in sample
    spread_verdict = next(x for x in text.splitlines()[text.splitlines().index(sample):]
                          if x in ("converged", "NOT converged"))
    assert f"sample around W*: {spread_verdict} (2 x 8 draws; `semmap diagnose {out / 'spread.nc'}`)" in r.stderr
    # the diagnostics within the best chain's mode: heading and verdict in the file (for the search
    # and for the sample around W*), one line in the log: the sample's, whose draws the figures hold
    lines = text.splitlines()
    heads = [i for i, x in enumerate(lines) if x.startswith("within the best chain's mode (")]
    logged = [x for x in r.stderr.splitlines() if x.startswith("within the best chain's mode (")]
    assert len(heads) == 2 and len(logged) == 1      # n_hall is 0 in every draw: constant there
    assert lines.index(sample) < heads[1]
    verdict = next(x for x in lines[heads[1]:] if "mixed within the mode" in x)
    assert logged == [f"{lines[heads[1]]}: {verdict}"]
    search = next(x for x in lines[heads[0]:] if "mixed within the mode" in x)
    assert "spread figures" not in search           # the search's draws are not the figures' here
    assert "(--spread-draws)" in verdict or verdict.startswith("mixed") or "no summary moved" in verdict
    report_html = (out / "report.html").read_text()
    assert "ithin the best chain&#x27;s mode (" in report_html and "mixed within the mode" in report_html
    # chains are numbered from 1 on the page, as in diagnostics.txt
    chain = re.search(r"<th>W\* from chain</th><td[^>]*>(\d+)</td>", report_html)
    assert chain and 1 <= int(chain.group(1)) <= 2
    # its "Posterior spread" section is the sample around W*, with its own verdict
    spread = report_html[report_html.index('id="spread"'):report_html.index('id="convergence"')]
    assert "Sample around W* (posterior.png, posterior_cells.png): 2 chain(s) x 8 draws" in spread
    assert f"Its chains: {spread_verdict} (2 chains × 8 draws, spread.nc)" in spread
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


def wstar_part(doc: dict) -> dict:
    """world.json's content without the posterior marginals over the sampled worlds."""
    doc = dict(doc, units=[{k: v for k, v in u.items() if not k.startswith("posterior_")} for u in doc["units"]],
               doors=[{k: v for k, v in d.items() if k != "posterior_exists"} for d in doc["doors"]])
    doc.pop("posterior_marginals", None)
    return doc


def test_same_seed_same_world_json_with_or_without_the_sample_around_wstar(first_run, tmp_path):
    """The sample around W* follows the search and never changes W*; without it (--spread-draws 0)
    there is no spread.nc, and a stale one in a folder written again with --force is removed."""
    out, _ = first_run
    b = tmp_path / "b"
    b.mkdir()
    (b / "spread.nc").write_bytes((out / "spread.nc").read_bytes())
    r = semmap("map", MAP, "--out", b, "--seed", 7, *FAST, "--spread-draws", "0", "--force")
    assert r.returncode == 0, r.stderr
    # W* the same; only the posterior marginals differ: counted over the search's draws instead
    with_sample, without = (json.loads((d / "world.json").read_text()) for d in (out, b))
    assert with_sample["posterior_marginals"]["source"] == "the sample around W*"
    assert without["posterior_marginals"]["source"] == "the search's draws"
    assert wstar_part(with_sample) == wstar_part(without)
    assert not (b / "spread.nc").exists() and "sample around W*" not in r.stderr
    assert "sample around W*" not in (b / "diagnostics.txt").read_text()


def test_diagnose_reports_the_sample_around_wstar(first_run):
    out, _ = first_run
    r = semmap("diagnose", out)
    assert r.returncode in (0, 1), r.stderr
    head, sep, around = r.stdout.partition("--- the sample around W* (")
    assert sep and "spread.nc): the draws posterior.png and posterior_cells.png are made of ---" in around
    assert "draws 4, n_inner 20" in head and "start W*" in around and "draws 8, n_inner 20" in around
    d = json.loads(semmap("diagnose", out, "--json").stdout)
    assert d["spread_sample"]["trace"] == str(out / "spread.nc")
    assert d["spread_sample"]["convergence"]["draws"] == 8 and d["convergence"]["draws"] == 4
    # the verdicts say which draws the figures hold
    text = (out / "diagnostics.txt").read_text()
    assert "(the spread figures from the sample around W*)" in text or "chains in separate modes" not in text


@pytest.mark.parametrize("value", ["1", "3"])
def test_too_few_spread_draws_is_a_usage_error(tmp_path, value):
    r = semmap("map", MAP, "--out", tmp_path / "o", *FAST, "--spread-draws", value)
    assert r.returncode == 2 and "--spread-draws must be 0" in r.stderr and not (tmp_path / "o").exists()


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


@pytest.mark.parametrize("cores", [1, 2])
def test_a_rule_file_failing_inside_the_chains_is_one_line_on_any_number_of_cores(tmp_path, cores):
    # hard rules that admit no world: the knowledge engine raises in the chains, which run in
    # other processes on 2 cores (pymc wraps the error); the command says it in one line
    bad = tmp_path / "no_world.lp"
    bad.write_text(":- unit(U).\n")
    out = tmp_path / "o"
    fast = list(FAST)
    fast[fast.index("--cores") + 1] = str(cores)
    r = semmap("map", MAP, "--out", out, *fast, "--rules", bad)
    assert r.returncode == 2, r.stderr
    last = r.stderr.strip().splitlines()[-1]
    assert last.startswith("semmap: error:") and "no_world.lp" in last and "admit no world" in last
    assert "Traceback" not in r.stderr and not out.exists()


def test_a_rule_file_off_the_fast_path_is_named_at_the_start(first_run, tmp_path):
    """A rule file that is not pairwise-local runs (the general path) and the run says so
    before it starts, naming the command that finds the statement; table3.lp gets no such note."""
    out = tmp_path / "halls"
    r = semmap("map", MAP, "--out", out, "--seed", 7, *FAST, "--spread-draws", "0",
               "--rules", ROOT / "rules" / "halls_to_corridors.lp")
    assert r.returncode == 0, r.stderr
    notes = [line for line in r.stderr.splitlines() if "is not pairwise-local" in line]
    assert len(notes) == 1 and notes[0].startswith("note: ") and "semmap rules check" in notes[0]
    assert r.stderr.index(notes[0]) < r.stderr.index("sampling")
    assert json.loads((out / "world.json").read_text())["rules"].endswith("halls_to_corridors.lp")
    assert "pairwise-local" not in first_run[1].stderr


def test_two_cores_give_the_same_world_json_as_one(first_run, tmp_path):
    """With two cores the start world is made in a forked process while the rest of the program
    is imported, and the chains run side by side: the same world.json as with one core."""
    out, _ = first_run
    r = semmap("map", MAP, "--out", tmp_path / "c", "--seed", 7, *FAST, "--cores", "2")
    assert r.returncode == 0, r.stderr
    assert re.search(r"start world: \d+ units \(\d+\.\d s\)", r.stderr)
    assert (tmp_path / "c" / "world.json").read_bytes() == (out / "world.json").read_bytes()
