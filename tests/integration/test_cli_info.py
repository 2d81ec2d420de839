"""Tests of `semmap info MAP [--json]`."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from semmap_pp.cli import main
from semmap_pp.grid import write_map

DATA = Path(__file__).parents[1] / "data" / "maps"
REAL = Path(__file__).parents[2] / "data" / "maps"


def run_cli(*args: str) -> subprocess.CompletedProcess:
    env = dict(os.environ, PYTHONWARNINGS="error")
    return subprocess.run([sys.executable, "-m", "semmap_pp", *args], capture_output=True,
                          text=True, timeout=60, env=env)


def test_text_output_of_the_tiny_map(capsys):
    assert main(["info", str(DATA / "tiny.yaml")]) == 0
    out = capsys.readouterr().out
    assert "5 x 4 cells, 2.50 x 2.00 m" in out
    assert "resolution  0.5 m/cell" in out
    assert "origin      x -1 m, y 2 m, yaw 0 rad" in out
    assert "trinary (negate 0)" in out
    assert "occupied > 0.65, free < 0.196" in out
    # 4 free, 9 unknown, 7 occupied of 20 cells.
    assert "free                 4 cells   20.00 %" in out
    assert "unknown              9 cells   45.00 %" in out
    assert "occupied             7 cells   35.00 %" in out
    assert "known part  " in out
    assert "note" not in out


def test_json_output_is_one_object(capsys):
    assert main(["info", str(DATA / "tiny.yaml"), "--json"]) == 0
    out = capsys.readouterr().out
    assert out.count("\n") == 1
    facts = json.loads(out)
    assert (facts["width"], facts["height"]) == (5, 4)
    assert (facts["width_m"], facts["height_m"]) == (2.5, 2.0)
    assert facts["origin"] == [-1.0, 2.0, 0.0] and facts["resolution"] == 0.5
    assert facts["counts"] == {"free": 4, "unknown": 9, "occupied": 7}
    assert facts["fractions"]["unknown"] == pytest.approx(0.45)
    assert sum(facts["fractions"].values()) == pytest.approx(1.0)
    assert facts["image"].endswith("tiny.pgm") and facts["notes"] == []
    r0, c0, r1, c1 = facts["known_box"]          # the free and occupied cells' bounding box
    assert 0 <= r0 < r1 <= 4 and 0 <= c0 < c1 <= 5


def test_the_known_part_of_a_map_in_a_large_unknown_canvas(capsys, tmp_path):
    from semmap_pp.cells import FREE, OCCUPIED, UNKNOWN
    from semmap_pp.grid import classes_to_image

    c = np.full((300, 400), UNKNOWN, np.uint8)
    c[100:120, 50:90] = FREE
    c[100, 50:90] = OCCUPIED
    write_map(tmp_path / "m.yaml", classes_to_image(c), 0.05)
    assert main(["info", str(tmp_path / "m.yaml"), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["known_box"] == [100, 50, 120, 90]
    assert main(["info", str(tmp_path / "m.yaml")]) == 0
    assert "known part  40 x 20 cells from column 50, row 100 (0.7 % of the image)" in capsys.readouterr().out


def test_bare_image_reports_the_assumed_resolution_and_options_apply(capsys, tmp_path):
    np.save(tmp_path / "m.npy", np.array([[254, 128]], np.uint8))   # 128: p = 0.498
    assert main(["info", str(tmp_path / "m.npy"), "--json"]) == 0
    facts = json.loads(capsys.readouterr().out)
    assert facts["counts"] == {"free": 1, "unknown": 1, "occupied": 0}
    assert facts["resolution"] == 0.05 and "assumed 0.05" in facts["notes"][0]
    assert main(["info", str(tmp_path / "m.npy"), "--json", "--occupied-thresh", "0.4",
                 "--resolution", "0.1", "--negate", "1"]) == 0
    facts = json.loads(capsys.readouterr().out)
    # negated: 254 -> p = 0.996 occupied; 128 -> p = 0.502 occupied at 0.4.
    assert facts["counts"] == {"free": 0, "unknown": 0, "occupied": 2}
    assert facts["resolution"] == 0.1 and facts["notes"] == []


def test_real_map_through_a_subprocess():
    result = run_cli("info", str(REAL / "intel-lab.yaml"), "--json")
    assert result.returncode == 0, result.stderr
    facts = json.loads(result.stdout)
    assert (facts["width"], facts["height"]) == (586, 587)
    assert sum(facts["counts"].values()) == 586 * 587


@pytest.mark.parametrize("name, content, phrase", [
    ("broken.yaml", "image: [unclosed\n", "YAML syntax error"),
    ("bad.png", "not a png", "not an image file"),
    ("norez.yaml", "image: norez.yaml\n", "YAML file itself"),
])
def test_errors_through_a_subprocess_are_one_line_without_traceback(tmp_path, name, content,
                                                                    phrase):
    (tmp_path / name).write_text(content)
    result = run_cli("info", str(tmp_path / name))
    assert result.returncode == 2
    assert result.stdout == ""
    assert "Traceback" not in result.stderr
    lines = result.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"semmap: error: {tmp_path / name}")
    assert phrase in lines[0]


def test_missing_map_through_a_subprocess(tmp_path):
    result = run_cli("info", str(tmp_path / "absent.yaml"))
    assert result.returncode == 2 and "Traceback" not in result.stderr
    assert result.stderr.strip() == f"semmap: error: {tmp_path / 'absent.yaml'}: map file does not exist"


def test_info_on_a_map_written_by_write_map(capsys, tmp_path):
    write_map(tmp_path / "w.yaml", np.array([[254, 254], [205, 0]], np.uint8), 0.25,
              origin=(1.0, 2.0, 0.0))
    assert main(["info", str(tmp_path / "w.yaml"), "--json"]) == 0
    facts = json.loads(capsys.readouterr().out)
    assert facts["counts"] == {"free": 2, "unknown": 1, "occupied": 1}
    assert facts["origin"] == [1.0, 2.0, 0.0] and facts["width_m"] == 0.5


def test_a_map_whose_border_is_open_space_is_pointed_at_the_outside_setting(capsys, tmp_path):
    from semmap_pp.grid import OccupancyGrid
    from semmap_pp.grid.write import save_grid

    c = np.zeros((40, 40), np.uint8)                 # free everywhere ...
    c[:, 0] = 1                                      # ... but the left column unknown
    c[38, 20] = 2                                    # and an occupied cell near the bottom edge
    path = save_grid(OccupancyGrid(c, np.zeros(c.shape), 0.05), tmp_path / "m.yaml")
    assert main(["info", str(path)]) == 0
    out = capsys.readouterr().out
    # 156 border cells: 40 unknown, 29 within 0.75 m (15 cells) of the occupied one
    assert "border       55.77 % of the border cells open free space (the outside is shown as free" in out
    assert main(["info", str(path), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["border_open"] == pytest.approx(87 / 156)
    assert main(["info", str(DATA / "tiny.yaml")]) == 0
    assert "border" in (out := capsys.readouterr().out) and "shown as free" not in out


def test_a_reader_that_goes_away_ends_the_command_quietly():
    """``semmap info MAP --json | head -c 10``-like: stdout's reader closes early; exit 141, no
    traceback on stderr."""
    code = ("import sys\n"
            "from semmap_pp.cli import main\n"
            "class Gone:\n"
            "    def write(self, s): raise BrokenPipeError(32, 'Broken pipe')\n"
            "    def flush(self): pass\n"
            "sys.stdout = Gone()\n"
            f"sys.exit(main(['info', {str(DATA / 'tiny.yaml')!r}]))\n")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert r.returncode == 141 and "Traceback" not in r.stderr, r.stderr


def test_orientation_gives_the_lattices_theta_and_the_walls_at_another_angle(tmp_path, capsys):
    """`--orientation`: θ0 as `semmap map` finds it (cartesium −24.0°, nothing off axis), and for
    a wing at another angle the building's two directions (a lattice each, no note), with the
    off-axis walls' share, angle and pixels in the JSON."""
    from semmap_pp.cells import FREE, OCCUPIED, UNKNOWN
    from semmap_pp.synth import generate_floor

    assert main(["info", str(REAL / "ubremen-cartesium.yaml"), "--orientation"]) == 0
    out = capsys.readouterr().out
    assert "orientation -24.0 deg (the lattice's" in out and "off axis    no part of the map" in out
    a = generate_floor(3, units=8, rotation_deg=0.0).classes
    b = generate_floor(5, units=8, rotation_deg=30.0).classes
    both = np.full((max(a.shape[0], b.shape[0]), a.shape[1] + b.shape[1]), UNKNOWN, np.uint8)
    both[:a.shape[0], :a.shape[1]] = a
    both[:b.shape[0], a.shape[1]:] = b
    image = np.where(both == FREE, 254, np.where(both == OCCUPIED, 0, 205)).astype(np.uint8)
    path = write_map(tmp_path / "wings.yaml", image, 0.05)
    assert main(["info", str(path), "--orientation", "--json"]) == 0
    facts = json.loads(capsys.readouterr().out)
    off = facts["off_axis"]
    assert abs(facts["orientation_deg"]) < 0.5 and off["share"] > 0.25
    assert abs(off["angle_deg"] + 30.0) < 1.0 and off["box_px"][0] >= a.shape[1] - 160
    # two directions, a lattice each: the run makes no note of the wing
    assert facts["orientations_deg"] == pytest.approx([facts["orientation_deg"], -30.0], abs=1.0)
    assert not off["note"] and len(facts["direction_shares"]) == 2
    assert main(["info", str(path), "--orientation"]) == 0
    lines = capsys.readouterr().out.splitlines()
    line = next(ln for ln in lines if ln.startswith("directions"))
    a0, a1 = facts["orientations_deg"]
    w0, w1 = facts["direction_shares"]
    assert line == (f"directions  {a0:.1f} deg ({100 * w0:.0f} %), {a1:.1f} deg ({100 * w1:.0f} %) of the "
                    f"walls: a lattice each, every unit's walls run along or across its own")
    assert not [ln for ln in lines if ln.startswith("off axis")]
    assert "orientation_deg" not in json.loads(_info_json(path, capsys))      # only when asked


def _info_json(path, capsys) -> str:
    assert main(["info", str(path), "--json"]) == 0
    return capsys.readouterr().out


def test_orientation_with_a_bad_model_file_is_one_line(tmp_path, capsys):
    bad = tmp_path / "bad.toml"
    bad.write_text("[lattice\n")
    assert main(["info", str(DATA / "tiny.yaml"), "--orientation", "--model", str(bad)]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"semmap: error: {bad}: not valid TOML") and err.count("\n") == 1
