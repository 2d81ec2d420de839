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
from semmap_pp.run.pipeline import (KERNEL_TABLES, LIKELIHOOD_TABLES, data_start_world, shared_tables,
                                    timed_start_world)
from semmap_pp.run.shared import SharedArray, shared_folder
from semmap_pp.sampler.kernels import data_from_frame
from semmap_pp.target.likelihood import _prepare, prepare

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
        world, seconds, tables = job.result()
    finally:
        job.close()
    assert seconds > 0 and _same(world, data_start_world(inputs)) and tables is None


def test_one_core_makes_no_process_and_the_run_makes_its_start_world_itself(inputs):
    assert _start_job(inputs, NS(cores=1)) is None
    world, seconds, tables = timed_start_world(inputs)
    assert seconds > 0 and _same(world, data_start_world(inputs)) and tables is None


def test_the_forked_process_hands_over_the_runs_tables_made_into_its_shared_folder(inputs, monkeypatch):
    """Given the run's shared folder, the start world's process makes the run's kernel and
    likelihood tables there and hands them back as mapped files (their paths travel, not their
    values): the values the run would make itself, and the same start world."""
    monkeypatch.setattr(forked, "_one_thread", lambda: True)
    with shared_folder() as folder:
        job = _start_job(inputs, NS(cores=2), folder)
        try:
            child = job._proc.pid
            world, seconds, (data, likelihood) = job.result()
        finally:
            job.close()
        assert seconds > 0 and _same(world, data_start_world(inputs))
        own = data_from_frame(inputs.frame, inputs.model.kernels)
        for name in KERNEL_TABLES:
            mapped = getattr(data, name)
            assert isinstance(mapped, SharedArray) and Path(mapped._path).parent == Path(folder)
            assert Path(mapped._path).name.startswith(f"{child}-")      # made by the child
            assert np.array_equal(mapped, getattr(own, name))
        fresh = _prepare(inputs.frame, inputs.model)
        for name in LIKELIHOOD_TABLES:
            assert isinstance(getattr(likelihood, name), SharedArray)
            assert np.array_equal(getattr(likelihood, name), getattr(fresh, name))
        data2, factory = shared_tables(inputs, folder, (data, likelihood))
        assert data2 is data and factory.likelihood is likelihood
        assert prepare(inputs.frame, inputs.model) is likelihood     # what the run's targets read
    assert not Path(folder).exists()


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
