"""`semmap map` with two cores makes its start world in a forked process while it imports the rest
of the program (cli/cmd_map.py `_start_job`, run/pipeline.py `timed_start_world`): the same world
as the run makes itself, and with one core no process at all."""

import os
from pathlib import Path
from types import SimpleNamespace as NS

import numpy as np
import pytest

from semmap_pp import forked
from semmap_pp.cli.cmd_map import _import_the_rest, _start_job
from semmap_pp.run.inputs import load_inputs
from semmap_pp.run.pipeline import data_start_world, timed_start_world

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def inputs():
    return load_inputs(ROOT / "tests/data/maps/intel_corner.yaml")


def _same(a, b):
    return np.array_equal(a.rects[a.active], b.rects[b.active]) and a.capacity == b.capacity


def test_two_cores_fork_a_process_that_makes_the_runs_own_start_world(inputs, monkeypatch):
    monkeypatch.setattr(forked, "_one_thread", lambda: True)     # the test runner may hold threads
    job = _start_job(inputs, NS(cores=2))
    try:
        assert job._proc is not None and job._proc.pid != os.getpid()
        _import_the_rest()          # what the parent does meanwhile
        world, seconds = job.result()
    finally:
        job.close()
    assert seconds > 0 and _same(world, data_start_world(inputs))


def test_one_core_makes_no_process_and_the_run_makes_its_start_world_itself(inputs):
    assert _start_job(inputs, NS(cores=1)) is None
    world, seconds = timed_start_world(inputs)
    assert seconds > 0 and _same(world, data_start_world(inputs))


def test_the_first_line_is_said_before_the_rest_is_imported_and_once(monkeypatch, capsys, tmp_path):
    """With two cores `semmap map` says the map's head line ("...; building the start worlds")
    as soon as the start world's process is forked, before the second or two of imports, and
    the run's own log does not say it again."""
    from semmap_pp.cli import cmd_map
    from semmap_pp.cli import main

    monkeypatch.setattr(forked, "_one_thread", lambda: True)
    seen = []
    real = cmd_map._import_the_rest

    def importing():
        seen.append(capsys.readouterr().err)
        real()

    monkeypatch.setattr(cmd_map, "_import_the_rest", importing)
    rc = main(["map", str(ROOT / "tests/data/maps/intel_corner.yaml"), "--out", str(tmp_path / "out"),
               "--cores", "2", "--chains", "2", "--draws", "4", "--tune", "0", "--n-inner", "2",
               "--spread-draws", "0", "--progress", "none"])
    err = seen[0] + capsys.readouterr().err
    assert rc == 0 and "building the start worlds" in seen[0]
    assert err.count("building the start worlds") == 1
