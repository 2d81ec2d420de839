"""`semmap map --start WORLD_JSON`: a world.json read back onto the map's lattice, and its refusals."""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from semmap_pp import world as wm
from semmap_pp.errors import SemmapError
from semmap_pp.run.inputs import load_inputs
from semmap_pp.plans.world_file import read_start_world

ROOT = Path(__file__).resolve().parents[2]
MAP = ROOT / "tests" / "data" / "maps" / "intel_corner.yaml"
FAST = ["--chains", "2", "--cores", "1", "--tune", "2", "--draws", "4", "--n-inner", "20", "--seed", "3"]


def semmap(*args):
    return subprocess.run([sys.executable, "-m", "semmap_pp", *map(str, args)], capture_output=True,
                          text=True, timeout=600)


@pytest.fixture(scope="module")
def run_dir(intel_corner_run):
    return intel_corner_run


@pytest.fixture(scope="module")
def inputs():
    return load_inputs(MAP, rules_path=None)


def test_a_world_json_comes_back_as_the_worlds_lattice_rectangles(run_dir, inputs, tmp_path):
    doc = json.loads((run_dir / "world.json").read_text())
    world = read_start_world(run_dir / "world.json", inputs.frame, inputs.grid, 64)
    assert world.capacity == 64 and wm.n_units(world) == len(doc["units"]) + len(doc["exterior"])
    # each rectangle gives back the corners world.json holds (3 decimals)
    got = sorted(np.round(inputs.frame.rect_vertices_px(world.rects[s]), 3).tolist()
                 for s in wm.active_slots(world))
    want = sorted(u["vertices_px"] for u in doc["units"] + doc["exterior"])
    np.testing.assert_allclose(np.asarray(got), np.asarray(want), atol=1e-3)
    # a corner moved by hand by less than a pixel off the lattice is snapped back
    doc["units"][0]["vertices_px"][0][0] += 0.4
    moved = tmp_path / "moved.json"
    moved.write_text(json.dumps(doc))
    again = read_start_world(moved, inputs.frame, inputs.grid, 64)
    assert np.array_equal(again.rects, world.rects) and np.array_equal(again.active, world.active)
    # more units than slots: the capacity doubles until they fit
    assert read_start_world(run_dir / "world.json", inputs.frame, inputs.grid, 1).capacity >= wm.n_units(world)


def test_the_capacity_stops_at_max_k(run_dir, inputs, monkeypatch):
    import semmap_pp.plans.world_file as wf

    n = wm.n_units(read_start_world(run_dir / "world.json", inputs.frame, inputs.grid, 64))
    monkeypatch.setattr(wf, "MAX_K", n)
    assert read_start_world(run_dir / "world.json", inputs.frame, inputs.grid, 1).capacity == n
    monkeypatch.setattr(wf, "MAX_K", n - 1)
    with pytest.raises(SemmapError, match=f"{n} units; a world holds at most {n - 1}"):
        read_start_world(run_dir / "world.json", inputs.frame, inputs.grid, 1)


def test_every_chain_starts_from_the_given_world(run_dir, tmp_path, inputs):
    out = tmp_path / "b"
    r = semmap("map", MAP, "--out", out, "--start", run_dir / "world.json",
               "--chains", "2", "--cores", "1", "--tune", "0", "--draws", "4", "--n-inner", "1")
    assert r.returncode == 0, r.stderr
    assert "start world:" in r.stderr and "(given)" in r.stderr
    assert f"note: every chain started from {run_dir / 'world.json'}" in r.stderr
    given = read_start_world(run_dir / "world.json", inputs.frame, inputs.grid, 64)
    z = np.load(out / "resume.npz", allow_pickle=True)
    for c in range(2):   # resume.npz keeps each chain's start world
        assert np.array_equal(z[f"start_active_{c}"], given.active)
        assert np.array_equal(z[f"start_rects_{c}"][given.active], given.rects[given.active])
    # one kernel per draw: the first recorded world is the start or one edit away from it
    n0 = [int(z[f"active_{c}"][0].sum()) for c in range(2)]
    assert all(abs(n - wm.n_units(given)) <= 1 for n in n0)


def _edited(run_dir, tmp_path, edit, frame) -> Path:
    doc = json.loads((run_dir / "world.json").read_text())
    edit(doc, frame)
    path = tmp_path / "edited.json"
    path.write_text(json.dumps(doc))
    return path


def _lattice_unit(doc, frame, rect):
    doc["units"][0]["vertices_px"] = frame.rect_vertices_px(rect).round(3).tolist()


@pytest.mark.parametrize("edit, needle", [
    (lambda d, f: d.update(format="other/1"), "not a world.json of semmap_pp"),
    (lambda d, f: d["map"].update(width=999), "written for a 999x207 map at 0.05 m/cell; this map is 240x207"),
    (lambda d, f: d["map"].update(resolution=10**400), "written for a 240x207 map at 10000000000000000000... m/cell"),
    (lambda d, f: d["map"].update(resolution=float("nan")), "written for a 240x207 map at nan m/cell"),
    (lambda d, f: d["units"][0].update(vertices_px=[[10**400, 0], [3, 0], [3, 3], [0, 3]]),
     "'vertices_px' must be four"),
    (lambda d, f: d["units"][0].update(vertices_px=[[0, 0], [3, 0]]), "'vertices_px' must be four"),
    (lambda d, f: d["units"][0].update(vertices_px=[[0, 0], [30, 5], [25, 35], [-5, 30]]),
     "is not a rectangle of this map's lattice"),
    (lambda d, f: _lattice_unit(d, f, (-40, 10, 30, 60)), "reaches beyond the map's lattice"),
    (lambda d, f: _lattice_unit(d, f, (10, 10, 12, 60)), "the model allows sides of"),
    (lambda d, f: d.update(units={}), "'units' must be a list"),
])
def test_what_cannot_start_a_chain_is_refused_naming_the_file(run_dir, tmp_path, inputs, edit, needle):
    path = _edited(run_dir, tmp_path, edit, inputs.frame)
    with pytest.raises(SemmapError) as exc:
        read_start_world(path, inputs.frame, inputs.grid, 64)
    assert needle in exc.value.message and exc.value.path == str(path)


def test_a_fifo_or_a_folder_is_refused_without_reading_it(tmp_path, inputs):
    import os

    fifo = tmp_path / "world.json"
    os.mkfifo(fifo)
    for path in (fifo, tmp_path):
        with pytest.raises(SemmapError, match="not a regular file"):
            read_start_world(path, inputs.frame, inputs.grid, 64)
    with pytest.raises(SemmapError, match="no such file"):
        read_start_world(tmp_path / "missing.json", inputs.frame, inputs.grid, 64)


def test_the_cli_refuses_a_bad_start_in_one_line_and_writes_nothing(tmp_path):
    bad = tmp_path / "world.json"
    bad.write_text("{not json")
    out = tmp_path / "o"
    r = semmap("map", MAP, "--out", out, *FAST, "--start", bad)
    assert r.returncode == 2 and str(bad) in r.stderr
    assert r.stderr.strip().count("\n") == 0 and "Traceback" not in r.stderr
    assert not out.exists()
    r = semmap("map", "--resume", tmp_path, "--start", bad)
    assert r.returncode == 2 and "--start cannot be given with --resume" in r.stderr


def test_tools_outline_trust_reads_a_run_s_world_back_and_gives_each_tile_s_share(run_dir, inputs,
                                                                               capsys):
    """tools/outline_trust.py: the share of the enclosed units' cells within the outline, per tile,
    for a world.json read back as `semmap score` reads it; the same as derive.exterior's."""
    import importlib.util
    from semmap_pp.derive.exterior import outline_share
    spec = importlib.util.spec_from_file_location("outline_trust", ROOT / "tools" / "outline_trust.py")
    tool = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(tool)
    assert tool.main([str(MAP), str(run_dir / "world.json"), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    (shares,) = out["tiles"].values()
    world = read_start_world(run_dir / "world.json", inputs.frame, inputs.grid, 64)
    c = inputs.frame.cells
    direct = outline_share(inputs.frame.classes, world.rects[wm.active_slots(world)], c.wall,
                           c.exterior_max_share, c.exterior_seen_min, c.exterior_outline_gap,
                           c.object_max_extent)
    assert len(shares) == 1 and shares[0] == (None if direct is None else round(direct, 3))
    assert direct is None or 0.0 <= direct <= 1.0
