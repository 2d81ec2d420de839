"""Every benchmark runs: ``bench/run.py NAME --tiny --json`` for each ``bench/bench_*.py``, in this
process (imports and compiled code shared with the other tests), gives one JSON result.

``--tiny`` (each module's ``TINY`` or ``SIZES``) runs every part of a benchmark at a few kernels,
edits or cells: it measures nothing, it only keeps the benchmarks from rotting between the runs
that docs/benchmarks.md reports (``make bench``). A new benchmark without ``--tiny`` fails here.
"""

from __future__ import annotations

import importlib.util
import json
import math
import sys
from pathlib import Path

import pytest

BENCH = Path(__file__).resolve().parents[2] / "bench"
NAMES = sorted(p.stem[len("bench_"):] for p in BENCH.glob("bench_*.py"))


def bench(capsys, monkeypatch, *argv) -> dict:
    """The JSON result of ``bench/run.py *argv --json`` (the last line it prints)."""
    monkeypatch.setattr(sys, "path", list(sys.path))      # run.py puts bench/ first: undone after
    spec = importlib.util.spec_from_file_location("bench_runner", BENCH / "run.py")
    runner = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(runner)
    capsys.readouterr()
    assert runner.main([*argv, "--json"]) == 0
    out = capsys.readouterr().out.strip().splitlines()
    result = json.loads(out[-1])
    assert isinstance(result, dict) and result["benchmark"] == argv[0]
    assert math.isfinite(result["wall_s"]) and result["machine"]["cpus"] >= 1
    return result


def test_every_benchmark_is_tested():
    assert NAMES == ["batch", "knowledge", "large", "likelihood", "quality", "sampler"]


@pytest.mark.parametrize("name", NAMES)
def test_benchmark_runs_at_a_tiny_size(name, capsys, monkeypatch):
    result = bench(capsys, monkeypatch, name, "--tiny")
    assert result["command"] == f"python bench/run.py {name} --tiny --json"
    if name == "batch":
        assert result["one_worker_s"] > 0 and result["two_workers_s"] > 0
        assert set(result["task_wall_s_one_worker"]) == {"tiny"}
    elif name == "knowledge":
        assert result["auto_map_equals_exact_dense_12"] is True
        assert result["mcsat_max_abs_err_corridor_8"] < 0.05 and result["rc2_hard_units"] == 40
    elif name == "large":
        assert [m["cells"] for m in result["sizes"]] == [200 ** 2, 300 ** 2]
        assert result["canvas"]["crop"]["lattice"] != result["canvas"]["whole"]["lattice"]
    elif name == "likelihood":
        for k in ("1x", "4x"):
            assert result[k]["edits_timed"] >= 40 and result[k]["incremental_vs_full_rel_err"] < 1e-9
    elif name == "quality":
        (row,) = result["synthetic"]["rows"]
        assert row["seed"] == 1 and 0 < row["cpr"] <= 1
    elif name == "sampler":
        assert result["knowledge_pymc_kernels"] == 10 and result["knowledge_tracker_error"] < 1e-9


@pytest.mark.parametrize("seed,units", [(0, 20), (3, 30)])
def test_bench_likelihood_times_edits_on_the_cartesium_lattice(seed, units, capsys, monkeypatch):
    """``bench/run.py likelihood`` on its default map (cartesium, whose lattice the frame crops to
    the known cells): the world is placed on the cropped lattice, so the edits are evaluated (all
    of them were skipped, and the run ended in ``statistics.StatisticsError``), and the 4x map is
    that lattice tiled 2 x 2."""
    result = bench(capsys, monkeypatch, "likelihood", "--seed", str(seed), "--units", str(units),
                   "--edits", "40", "--full", "1")
    one, four = result["1x"], result["4x"]
    assert four["lattice"] == [2 * one["lattice"][0], 2 * one["lattice"][1]]
    assert one["lattice"] != result["lattice"]          # cropped: the case that failed
    assert one["edits_timed"] >= 35 and four["edits_timed"] == one["edits_timed"]
    assert one["edit_us_median"] > 0 and one["incremental_vs_full_rel_err"] < 1e-9
