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

import numpy as np
import pytest

BENCH = Path(__file__).resolve().parents[2] / "bench"
NAMES = sorted(p.stem[len("bench_"):] for p in BENCH.glob("bench_*.py"))


def bench_runner(monkeypatch):
    """``bench/run.py`` as a module (its ``main(argv)``)."""
    monkeypatch.setattr(sys, "path", list(sys.path))      # run.py puts bench/ first: undone after
    spec = importlib.util.spec_from_file_location("bench_runner", BENCH / "run.py")
    runner = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(runner)
    return runner


def bench(capsys, monkeypatch, *argv) -> dict:
    """The JSON result of ``bench/run.py *argv --json`` (the last line it prints)."""
    runner = bench_runner(monkeypatch)
    capsys.readouterr()
    assert runner.main([*argv, "--json"]) == 0
    out = capsys.readouterr().out.strip().splitlines()
    result = json.loads(out[-1])
    assert isinstance(result, dict) and result["benchmark"] == argv[0]
    assert math.isfinite(result["wall_s"]) and result["machine"]["cpus"] >= 1
    return result


def test_every_benchmark_is_tested():
    assert NAMES == ["against", "batch", "knowledge", "large", "learn", "likelihood", "quality", "sampler",
                     "zones"]


@pytest.mark.parametrize("name", NAMES)
def test_benchmark_runs_at_a_tiny_size(name, capsys, monkeypatch):
    if name == "against" and not (BENCH.parent / ".git").exists():
        pytest.skip("bench against checks out another version: a git checkout only")
    result = bench(capsys, monkeypatch, name, "--tiny")
    assert result["command"] == f"python bench/run.py {name} --tiny --json"
    if name == "against":
        (row,) = result["rows"]
        assert row["map"] == "tests/data/maps/tiny.yaml"
        # HEAD against this checkout: the same plan, unless uncommitted changes change it
        assert row["same_plan"] is True or result["this"].endswith("+uncommitted changes")
        assert len(row["other_s"]) == len(row["this_s"]) == 1 and row["ratio_of_means"] > 0
        assert len(result["rev"]) == 40 and result["max_ratio"] == row["ratio_of_means"]
    elif name == "batch":
        assert result["one_worker_s"] > 0 and result["two_workers_s"] > 0
        assert set(result["task_wall_s_one_worker"]) == {"tiny"}
    elif name == "knowledge":
        assert result["auto_map_equals_exact_dense_12"] is True
        assert result["mcsat_max_abs_err_corridor_8"] < 0.05 and result["rc2_hard_units"] == 40
    elif name == "large":
        assert [m["cells"] for m in result["sizes"]] == [200 ** 2, 300 ** 2]
        assert result["canvas"]["crop"]["lattice"] != result["canvas"]["whole"]["lattice"]
        intel, campus = result["whole"]["floors"]        # whole `semmap map` runs, in subprocesses
        assert (intel["floor"], campus["floor"]) == ("intel", "campus")
        for f in (intel, campus):
            assert 0 < f["known_cells"] < f["canvas_cells"] and f["wall_s"] > 0 and f["peak_mib"] > 0
            assert f["units"] >= 1 and f["log"][-1].startswith("W*: ")
        ratios = campus["vs_intel"]
        assert ratios["known_ratio"] > 1 and ratios["canvas_ratio"] > 1
        assert ratios["time_over_known"] > 0
    elif name == "learn":
        assert [r["map"] for r in result["rows"]] == ["synth-0", "synth-1", "synth-2"]
        assert all(0 <= r["accuracy_learned"] <= 1 for r in result["rows"])
        assert len(result["weights_all"]) == 19
    elif name == "likelihood":
        for k in ("1x", "4x"):
            assert result[k]["edits_timed"] >= 40 and result[k]["incremental_vs_full_rel_err"] < 1e-9
    elif name == "quality":
        (row,) = result["synthetic"]["rows"]
        assert row["seed"] == 1 and 0 < row["cpr"] <= 1
        assert 0 < row["rooms_precision"] <= 1 and 0 < row["rooms_recall"] <= 1 and row["rooms_outside"] >= 0
    elif name == "sampler":
        assert result["knowledge_pymc_kernels"] == 10 and result["knowledge_tracker_error"] < 1e-9
    elif name == "zones":
        (wings,) = result["wings"]
        assert wings["kind"] == "30" and wings["directions_found"] == wings["directions"] == 2
        assert wings["correct"] > 0.95 and result["one_direction"] == {"maps": 1, "one_zone": 1}
        (pentagon,) = result["drawn"]
        assert len(pentagon["zones_deg"]) == 5 and result["composite"]["side"] == 600


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


def test_the_partial_subset_runs_on_one_exploration(capsys, monkeypatch):
    result = bench(capsys, monkeypatch, "quality", "--tiny", "--subset", "partial",
                   "--maps", "freiburg_building52@0.3")
    (row,) = result["partial"]["rows"]
    assert row["map"] == "freiburg_building52@0.3" and 0 < row["precision"] <= 1 and 0 < row["recall"] <= 1


def test_partial_explorations_see_part_of_the_floor_and_are_reproducible(monkeypatch):
    """bench/partial_maps.py: the partial map keeps the full map's grey values on the cells its
    rays reached and is the floor's unknown grey elsewhere (153 on freiburg_building52); its truth
    is the floor's on the cells it saw;
    rooms the robot did not enter are seen in part (through their doors); the same
    arguments give the same map, and entering more rooms sees more."""
    monkeypatch.setattr(sys, "path", [str(BENCH), *sys.path])
    import partial_maps
    from semmap_pp.evaluate import read_segmentation_truth
    folder = BENCH / "data" / "real-gt" / "freiburg_building52"
    truth = read_segmentation_truth(folder / "gt.png", "rose2")
    part, meta, gt = partial_maps.explore(folder, 0.3, 1, truth)
    again, _, gt2 = partial_maps.explore(folder, 0.3, 1, truth)
    assert (part == again).all() and (gt == gt2).all()
    from PIL import Image
    full = np.asarray(Image.open(folder / "map.png").convert("L"))
    canvas = partial_maps.unknown_grey(folder, full)
    seen = part != canvas
    assert canvas == 153 and (part[seen] == full[seen]).all()
    assert 0.2 < seen.mean() / (full != canvas).mean() < 1.0
    assert (gt[~seen] == 0).all() and (gt[seen] == truth[seen]).all()
    shares = [(gt == t).sum() / (truth == t).sum() for t in np.unique(truth) if t and (truth == t).sum() > 200]
    assert min(shares) < 0.8 and max(shares) > 0.95           # some rooms seen in part, some whole
    more, _, _ = partial_maps.explore(folder, 0.6, 1, truth)
    assert (more != 205).sum() > seen.sum()


def test_quality_over_seeds_gives_each_seed_its_rows_and_the_mean_of_their_means(capsys, monkeypatch):
    result = bench(capsys, monkeypatch, "quality", "--tiny", "--over-seeds", "0,1")
    part = result["synthetic"]
    assert [r["sampler_seed"] for r in part["rows"]] == [0, 1]
    assert all(r["seed"] == 1 for r in part["rows"])          # the floor's seed is kept
    by_seed = part["means_by_seed"]
    for key in ("cpr", "rooms_precision"):
        values = [by_seed[s][key] for s in ("0", "1")]
        assert part["means"][key] == pytest.approx(np.mean(values), abs=1e-4)
        assert part["seed_sd"][key] == pytest.approx(np.std(values), abs=1e-4)


@pytest.mark.parametrize("text", ["0,x", "1,1", "-1", ","])
def test_quality_over_seeds_refuses_a_bad_list(text, capsys, monkeypatch):
    with pytest.raises(SystemExit, match="--over-seeds"):
        bench_runner(monkeypatch).main(["quality", "--tiny", "--over-seeds", text, "--json"])



def test_quality_wings_scores_rooms_png_against_the_drawn_truth_of_each_plan(capsys, monkeypatch):
    result = bench(capsys, monkeypatch, "quality", "--tiny", "--subset", "wings", "--maps", "wing30")
    (row,) = result["wings"]["rows"]
    assert row["map"] == "wing30" and row["true_rooms"] == 17
    assert 0 < row["precision"] <= 1 and 0 < row["recall"] <= 1
    assert 0 <= row["exterior_inside"] <= row["exterior_units"]


def test_quality_save_writes_each_wstar_with_its_labels_and_rooms(capsys, monkeypatch, tmp_path):
    """``--save DIR``: DIR/MAP/ holds world.json, labels.png and rooms.png, whose room ids are
    world.json's rooms and whose free cells are those the bench scored."""
    from PIL import Image
    bench(capsys, monkeypatch, "quality", "--tiny", "--subset", "wings", "--maps", "wing30",
          "--save", str(tmp_path))
    out = tmp_path / "wing30"
    world = json.loads((out / "world.json").read_text())
    rooms = np.asarray(Image.open(out / "rooms.png"))
    labels = np.asarray(Image.open(out / "labels.png"))
    assert rooms.dtype == np.uint16 and rooms.shape == labels.shape
    assert set(np.unique(rooms[rooms > 0]).tolist()) == {r["id"] for r in world["rooms"]}
    assert all(int((rooms == r["id"]).sum()) == r["cells"] for r in world["rooms"])


def test_quality_synthetic_wings_scores_a_floor_of_wings_beside_its_control(capsys, monkeypatch):
    result = bench(capsys, monkeypatch, "quality", "--tiny", "--subset", "synthetic-wings",
                   "--maps", "wings2-30,wings2-0")
    part = result["synthetic-wings"]
    row, control = sorted(part["rows"], key=lambda r: r["group"] != "wings2-30")
    assert control["group"] == "wings2-0" and control["seed"] == 1
    assert control["true_units"] == row["true_units"]          # the same plans, joined at 0 degrees
    assert part["groups"]["wings2-30"]["minus_control"]["unit_f1"] == \
        round(row["unit_f1"] - control["unit_f1"], 4)
    assert "minus_control" not in part["groups"]["wings2-0"]
    assert row["group"] == "wings2-30" and row["seed"] == 1 and row["true_units"] >= 7
    assert 0 < row["cpr"] <= 1 and 0 <= row["unit_f1"] <= 1
    assert 0 < row["rooms_precision"] <= 1 and 0 < row["rooms_recall"] <= 1
    assert part["groups"]["wings2-30"]["floors"] == 1 and part["seeds"] == [1, 1]
    assert part["groups"]["wings2-30"]["unit_f1"] == row["unit_f1"]
    assert set(row["unit_recall_by_wing"]) == {"0", "1", "2"}
    assert all(0 <= v <= 1 for v in row["unit_recall_by_wing"].values())


def test_the_fuzzer_runs_from_the_checkout():
    """``python bench/fuzz.py`` (docs/robustness.md) finds the fuzz targets of tests/unit and
    ends with its JSON summary: a short run of one target."""
    import subprocess

    proc = subprocess.run([sys.executable, str(BENCH / "fuzz.py"), "--seconds", "0.1", "--examples", "5",
                           "--targets", "mutated-yaml"], capture_output=True, text=True, timeout=300,
                          cwd=BENCH.parent)
    assert proc.returncode == 0, proc.stderr[-2000:]
    result = json.loads(proc.stdout.strip().splitlines()[-1])
    assert result["benchmark"] == "fuzz" and result["cases"]["mutated-yaml"] >= 1
    assert result["failures"] == 0


def test_quality_synthetic_wings_leaves_out_a_floor_the_generator_cannot_lay_out(monkeypatch):
    """Seed 6's three plans collide when every joint is at 0 degrees: the control skips that floor
    (no row, the reason kept) and a turned group is compared with it on the seeds both hold."""
    bench_runner(monkeypatch)                      # puts bench/ on the path
    import argparse

    import bench_quality as bq
    args = argparse.Namespace(pool=1, resolution=0.05, quiet=True)
    out = bq.bench_synthetic(args, None, None, [("wings3-0", 6, bq.WING_GROUPS["wings3-0"])])
    assert out["rows"] == [] and out["skipped"] == [
        {"group": "wings3-0", "seed": 6, "reason": "could not join wing 3 to wing 2"}]
    rows = [{"group": "wings3-drawn", "seed": s, "unit_f1": f} for s, f in ((5, 0.5), (6, 0.9), (7, 0.7))] + \
        [{"group": "wings3-0", "seed": s, "unit_f1": f} for s, f in ((5, 0.6), (7, 0.9))]
    assert bq._group_difference(rows, "wings3-drawn", "wings3-0")["unit_f1"] == -0.15
    assert bq._group_difference(rows, "wings3-drawn", None) is None
