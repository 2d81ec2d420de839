"""``semmap edit``: a run's W* changed by id and point, written as a world.json that ``score`` and
``map --start`` read; bad edits and bad input."""

import json
from pathlib import Path

import jsonschema
import numpy as np
import pytest

from semmap_pp.cli import main
from semmap_pp.lattice.frame import build_frame
from semmap_pp.grid import load_map
from semmap_pp.model import load_model
from semmap_pp.plans.world_file import read_world_units

ROOT = Path(__file__).resolve().parents[2]
MAP = ROOT / "tests" / "data" / "maps" / "intel_corner.yaml"
SCHEMA = json.loads((ROOT / "docs" / "world.schema.json").read_text())
PLAN = ["world.json", "labels.png", "regions.png", "rooms.png", "types.yaml", "types.pgm", "rosbag2", "world.geojson", "graph.graphml",
        "overlay.png", "graph.png"]


@pytest.fixture(scope="module")
def wstar(intel_corner_wstar):
    return intel_corner_wstar


@pytest.fixture(scope="module")
def frame():
    return build_frame(load_map(MAP), load_model())


def run(capsys, *args) -> tuple[int, str, str]:
    try:
        code = main(["edit", *map(str, args)])
    except SystemExit as exc:        # argparse's own errors (usage line + one error line)
        code = exc.code
    captured = capsys.readouterr()
    return code, captured.out, captured.err


def largest(doc) -> dict:
    return max(doc["units"], key=lambda u: u["size_m"][0] * u["size_m"][1])


def cut_line(unit) -> list[float]:
    """Two map points (metres) on the line through a unit's centre parallel to its shorter sides,
    both inside the unit."""
    v = np.array(unit["vertices_m"])                 # corners in order around the rectangle
    a, b = v[1] - v[0], v[2] - v[1]
    if np.hypot(*a) >= np.hypot(*b):                 # v0-v1 is a long side: cut from its middle
        p, q = (v[0] + v[1]) / 2, (v[2] + v[3]) / 2
    else:
        p, q = (v[1] + v[2]) / 2, (v[3] + v[0]) / 2
    inset = (q - p) * 0.3                             # inside the unit, on the cut line
    return [*(p + inset), *(q - inset)]


def test_a_cut_writes_a_valid_world_json_that_score_and_start_read(wstar, tmp_path, capsys, frame):
    doc = json.loads(wstar.read_text())
    unit = largest(doc)
    out = tmp_path / "cut" / "world.json"
    code, text, err = run(capsys, MAP, wstar, "--out", out.parent, "--cut", f"R{unit['id']}", *cut_line(unit),
                          "--json")
    assert code == 0, err
    assert sorted(p.name for p in out.parent.iterdir()) == sorted(PLAN)
    edited = json.loads(out.read_text())
    jsonschema.validate(edited, SCHEMA)
    assert edited["edited"]["from"] == str(wstar) and edited["edited"]["edits"][0].startswith(f"--cut R{unit['id']} ")
    before, after = json.loads(text)["worlds"]
    assert before["log_posterior"] == pytest.approx(doc["log_posterior"], abs=1e-6)
    assert after["log_posterior"] == pytest.approx(edited["log_posterior"], abs=1e-6)
    assert len(edited["units"]) + len(edited["exterior"]) == len(doc["units"]) + len(doc["exterior"]) + 1
    # the file is a world.json like any other: scored the same, and a start world
    assert main(["score", str(MAP), str(out), "--json"]) == 0
    row = json.loads(capsys.readouterr().out)["worlds"][0]
    assert row["log_posterior"] == pytest.approx(edited["log_posterior"], abs=1e-6)
    assert len(read_world_units(out, frame, load_map(MAP))) == len(edited["units"]) + len(edited["exterior"])


def test_the_written_file_says_what_each_unit_was(wstar, tmp_path, capsys, frame):
    """``edited.ids`` (and the printed lines): every unit of the written world.json with its id in
    the edited file, the two pieces of the cut with the edit that made them; the ids match the
    units' geometry, read back from both files."""
    doc = json.loads(wstar.read_text())
    unit = largest(doc)
    drop = next(u for u in doc["units"] if u["id"] != unit["id"])
    out = tmp_path / "ids" / "world.json"
    code, text, err = run(capsys, MAP, wstar, "--out", out.parent, "--drop", drop["id"],
                          "--cut", f"R{unit['id']}", *cut_line(unit), "--snap", "0")
    assert code == 0, err
    edited = json.loads(out.read_text())
    ids = edited["edited"]["ids"]
    assert len(ids) == len(edited["units"]) + len(edited["exterior"])
    assert [r["now"] for r in ids] == [f"{'RCHE'['room corridor hall other'.split().index(u['type'])]}{u['id']}"
                                       for u in edited["units"]] + [f"X{u['id']}" for u in edited["exterior"]]
    cut = edited["edited"]["edits"][1]
    assert [r["by"] for r in ids if r["was"] is None] == [cut, cut]
    assert all(r["by"] is None for r in ids if r["was"] is not None)
    was = {r["was"] for r in ids}
    assert str(unit["id"]) not in was and str(drop["id"]) not in was
    # a unit not edited is the same rectangle under its old and its new id (no snap: nothing moved)
    old = dict(read_world_units(wstar, frame, load_map(MAP)))
    new = dict(read_world_units(out, frame, load_map(MAP)))
    for r in ids:
        if r["was"] is not None:
            assert old[r["was"]] == new[r["now"].lstrip("RCHE")]
    lines = text.splitlines()
    head = lines.index(f"ids in {out} (each world.json numbers its units afresh, in reading order):")
    assert any(line.startswith("  new ") and line.endswith(f": {cut}") for line in lines[head:])
    assert f"  gone: {drop['id']}, {unit['id']}" in lines[head:] or f"  gone: {unit['id']}, {drop['id']}" in lines[head:]


def test_without_snapping_the_pieces_share_a_band_on_the_line(wstar, tmp_path, capsys, frame):
    doc = json.loads(wstar.read_text())
    unit = largest(doc)
    out = tmp_path / "exact" / "world.json"
    assert run(capsys, MAP, wstar, "--out", out.parent, "--snap", "0", "--cut", unit["id"], *cut_line(unit))[0] == 0
    grid = load_map(MAP)
    old = dict(read_world_units(wstar, frame, grid))
    new = [r for _, r in read_world_units(out, frame, grid)]
    rect = old[str(unit["id"])]
    assert rect not in new
    pieces = [r for r in new if r not in old.values()]
    assert len(pieces) == 2
    first, second = sorted(pieces)
    t = frame.cells.wall
    box = (min(first[0], second[0]), min(first[1], second[1]), max(first[2], second[2]), max(first[3], second[3]))
    assert box == rect                                    # the two pieces make up the unit
    assert first[2] - second[0] == t or first[3] - second[1] == t   # sharing one wall band


def test_moving_a_unit_s_wall_onto_its_own_centre_changes_nothing(wstar, tmp_path, capsys, frame):
    doc = json.loads(wstar.read_text())
    unit = largest(doc)
    grid = load_map(MAP)
    rect = dict(read_world_units(wstar, frame, grid))[str(unit["id"])]
    t = frame.cells.wall
    row, col = rect[0] + (t - 1) / 2, (rect[1] + rect[3]) / 2        # the top wall's centre line
    x, y = frame.lattice_to_image(row, col)
    out = tmp_path / "same" / "world.json"
    code, text, _ = run(capsys, MAP, wstar, "--out", out.parent, "--pixels", "--snap", "0", "--wall", unit["id"],
                        float(x) + 0.5, float(y) + 0.5)
    assert code == 0
    assert [r for _, r in read_world_units(out, frame, grid)] == [r for _, r in read_world_units(wstar, frame, grid)]
    lines = text.splitlines()
    assert lines[3].split()[-3] == "+0.0"                  # the same log posterior as the input


def test_bad_edits_and_inputs_get_one_line_and_write_nothing(wstar, tmp_path, capsys):
    out = tmp_path / "bad"
    cases = [
        (["--drop", "999"], f"{wstar}: --drop 999: no unit 999 in this world"),
        (["--drop", "1", "--drop", "1"], "unit 1 no longer exists after --drop 1"),
        (["--merge", "1"], "--merge needs two unit ids or more"),
        (["--drop", "Q1"], "is not a unit id"),
        (["--wall", "1", "x", "2"], "not a number"),
        ([], "no edit given"),
    ]
    for edit, message in cases:
        code, text, err = run(capsys, MAP, wstar, "--out", out, *edit)
        assert code == 2 and text == "" and len(err.strip().splitlines()) == 1, (edit, err)
        assert message in err, (edit, err)
        assert not out.exists()
    code, _, err = run(capsys, MAP, wstar, "--out", out, "--snap", "-1", "--drop", "1")
    assert code == 2 and "--snap" in err and not out.exists()
    broken = tmp_path / "broken.json"
    broken.write_text("{ not json")
    code, _, err = run(capsys, MAP, broken, "--out", out, "--drop", "1")
    assert code == 2 and str(broken) in err and not out.exists()
    code, _, err = run(capsys, MAP, wstar, "--out", wstar.parent, "--drop", "1", "--force")
    assert code == 2 and "is the directory of WORLD_JSON" in err
    out.mkdir()
    (out / "keep.txt").write_text("keep")
    code, _, err = run(capsys, MAP, wstar, "--out", out, "--drop", "1")
    assert code == 2 and "not empty (use --force" in err and sorted(p.name for p in out.iterdir()) == ["keep.txt"]
    assert run(capsys, MAP, wstar, "--out", out, "--drop", "1", "--force")[0] == 0
    count = [len(d["units"]) + len(d["exterior"]) for d in (json.loads(p.read_text()) for p in (wstar, out / "world.json"))]
    assert count[1] == count[0] - 1
