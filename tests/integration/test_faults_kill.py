"""Faults: a `semmap map` killed with SIGKILL leaves every output file complete; rules are read once.

A run writes into a folder that already holds a complete earlier result (``--force``) and is killed
(SIGKILL: no handler, no clean-up) at several moments: while starting, while sampling, and twice
while writing its outputs (found by watching the folder for the temporary files of
:mod:`semmap_pp.atomic`). After each kill every file under its final name must parse completely:
world.json (valid JSON, schema-valid), the PNGs (decode), trace.nc (opens with ArviZ), resume.npz
(every array loads), the GeoJSON, GraphML, HTML and text files. Nothing may be lost either: each file
of the earlier result is still there (the old one or the new one). Temporary files of the killed
run may be left behind (names ``.NAME.*.tmp``); they are never a final name.

SIGINT (Ctrl-C) is tested in tests/integration/test_cli_faults.py: exit 130 with partial results on one and two
cores, ``--resume`` of an interrupted run. docs/robustness.md states the guarantees.
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time
import xml.etree.ElementTree as ET
from pathlib import Path

import jsonschema
import numpy as np
import pytest
from PIL import Image

from semmap_pp.cli import main
from semmap_pp.sampler.diagnostics import read_trace
from semmap_pp.run.inputs import load_inputs
from semmap_pp.run.pipeline import run_map
from semmap_pp.run.results import RunSettings

ROOT = Path(__file__).resolve().parents[2]
MAP = ROOT / "tests" / "data" / "maps" / "intel_corner.yaml"
SCHEMA = json.loads((ROOT / "docs" / "world.schema.json").read_text())
SHORT = ["--chains", "1", "--cores", "1", "--tune", "2", "--draws", "4", "--n-inner", "10"]


def check_complete(folder: Path) -> set[str]:
    """Parse every final-named file in ``folder`` completely; return their names."""
    names = {p.name for p in folder.iterdir() if not p.name.startswith(".")}
    for name in names:
        path = folder / name
        if name == "world.json":
            jsonschema.validate(json.loads(path.read_text()), SCHEMA)
        elif name.endswith((".json", ".geojson")):
            json.loads(path.read_text())
        elif name.endswith(".png"):
            with Image.open(path) as im:
                im.load()
        elif name.endswith(".nc"):
            tree = read_trace(path)
            assert np.isfinite(tree["posterior"]["log_posterior"].values).all()
        elif name.endswith(".npz"):
            with np.load(path) as z:
                for key in z.files:
                    z[key]
        elif name.endswith(".graphml"):
            ET.parse(path)
        elif name.endswith(".html"):
            assert path.read_text().rstrip().endswith("</html>"), name
        elif path.is_dir():                      # rosbag2/: every message of the bag decodes
            from rosbags.rosbag2 import Reader
            from rosbags.typesys import Stores, get_typestore

            store = get_typestore(Stores.ROS2_JAZZY)
            with Reader(path) as r:
                assert len([store.deserialize_cdr(raw, c.msgtype) for c, _, raw in r.messages()]) == 3
        else:
            assert path.read_text(encoding="utf-8").strip(), name
    return names


@pytest.fixture(scope="module")
def previous(tmp_path_factory) -> tuple[Path, set[str]]:
    """A complete earlier result of `semmap map` (in this process)."""
    out = tmp_path_factory.mktemp("previous") / "run"
    assert main(["map", str(MAP), "--out", str(out), "--seed", "1", "--progress", "none", *SHORT]) == 0
    names = check_complete(out)
    assert {"world.json", "labels.png", "trace.nc", "resume.npz", "diagnostics.txt"} <= names
    return out, names


def start(out: Path, *extra: str) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "semmap_pp", "map", str(MAP), "--out", str(out),
                             "--force", "--seed", "2", *extra],
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)


def kill(p: subprocess.Popen) -> None:
    p.send_signal(signal.SIGKILL)
    p.wait(timeout=60)
    assert p.returncode == -signal.SIGKILL, p.returncode


def wait_for_line(p: subprocess.Popen, needle: str, timeout: float = 120) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        line = p.stderr.readline()
        if not line:
            break
        if needle in line:
            return
    raise AssertionError(f"{needle!r} never appeared")


def wait_for_temp_files(p: subprocess.Popen, folder: Path, count: int, timeout: float = 180) -> int:
    """Poll ``folder`` until ``count`` distinct temporary output files have appeared."""
    seen: set[str] = set()
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline and p.poll() is None:
        seen.update(n for n in os.listdir(folder) if n.startswith(".") and n.endswith(".tmp"))
        if len(seen) >= count:
            return len(seen)
        time.sleep(0.0005)
    raise AssertionError(f"the run ended or timed out after {len(seen)} temporary files")


def copy_of(previous, tmp_path: Path) -> Path:
    out = tmp_path / "run"
    shutil.copytree(previous[0], out)
    return out


def test_killed_while_starting(previous, tmp_path):
    out = copy_of(previous, tmp_path)
    p = start(out, *SHORT)
    time.sleep(0.3)
    kill(p)
    assert check_complete(out) == previous[1]


def test_killed_while_sampling(previous, tmp_path):
    out = copy_of(previous, tmp_path)
    p = start(out, "--chains", "1", "--cores", "1", "--tune", "2", "--draws", "5000", "--n-inner", "5",
              "--progress", "plain", "--progress-every", "0.2")
    wait_for_line(p, "sampling started")
    time.sleep(0.3)
    kill(p)
    assert check_complete(out) == previous[1]


@pytest.mark.parametrize("moment", [1, 4], ids=["first-output-file", "fourth-output-file"])
def test_killed_while_writing_outputs(previous, tmp_path, moment):
    out = copy_of(previous, tmp_path)
    p = start(out, *SHORT, "--progress", "none")
    wait_for_temp_files(p, out, moment)
    kill(p)
    assert check_complete(out) == previous[1]   # every file there, each old or new, none partial


def test_rules_are_read_once_before_the_run(tmp_path):
    """Editing the rule file between load_inputs and run_map changes nothing in the run."""
    rules = tmp_path / "r.lp"
    shutil.copy(ROOT / "rules" / "table3.lp", rules)
    settings = dict(chains=1, cores=1, tune=2, draws=4, n_inner=10, seed=5)
    quiet = dict(log=lambda msg: None)

    inputs = load_inputs(MAP, rules_path=rules)
    rules.write_text(":- unit(U).\n")        # contradictory: re-reading it would fail the run
    edited = run_map(inputs, RunSettings.from_model(inputs.model, **settings), **quiet)

    shutil.copy(ROOT / "rules" / "table3.lp", rules)
    clean_inputs = load_inputs(MAP, rules_path=rules)
    clean = run_map(clean_inputs, RunSettings.from_model(clean_inputs.model, **settings), **quiet)
    assert inputs.rules.digest == clean_inputs.rules.digest
    np.testing.assert_array_equal(edited.world.rects, clean.world.rects)
    np.testing.assert_array_equal(edited.world.types, clean.world.types)
    assert edited.semantic.log_posterior == clean.semantic.log_posterior
