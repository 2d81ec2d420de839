"""`semmap map` on the drawn plans with a wing at 30 and at 45 degrees (tests/data/wings): a
lattice per direction, each unit at its own wing's angle in world.json, the fans beyond the two
windows (one per wing) exterior and no unit of the building, rooms.png close to the drawn truth,
and the run's world.json read back exactly."""

import json
from pathlib import Path

import numpy as np
import pytest

from semmap_pp.cli import main

WINGS = Path(__file__).resolve().parents[1] / "data" / "wings"
TINY = ["--chains", "2", "--cores", "1", "--tune", "2", "--draws", "4", "--n-inner", "5",
        "--spread-draws", "0", "--progress", "none"]


@pytest.fixture(scope="module", params=["wing30", "wing45"])
def run_dir(request, tmp_path_factory):
    out = tmp_path_factory.mktemp(request.param) / "run"
    assert main(["map", str(WINGS / f"{request.param}.yaml"), "--out", str(out), *TINY]) == 0
    return out


def test_each_unit_lies_at_its_own_wings_angle(run_dir):
    doc = json.loads((run_dir / "world.json").read_text())
    turn = 30 if run_dir.parent.name.startswith("wing30") else -45
    assert doc["map"]["orientations_deg"] == pytest.approx([0.0, turn], abs=0.5)
    angles = {round(u["orientation_deg"]) for u in doc["units"]}
    assert angles == {0, turn}
    for u in doc["units"]:
        v = np.asarray(u["vertices_px"])
        side = v[1] - v[0]
        assert np.degrees(np.arctan2(side[1], side[0])) == pytest.approx(u["orientation_deg"], abs=1e-3)
    turned = [u for u in doc["units"] if round(u["orientation_deg"]) == turn]
    assert len(turned) >= 7                      # the turned wing's six rooms and its corridor
    assert len(doc["exterior"]) == 2             # the fans beyond the windows, one per wing
    assert {round(x["orientation_deg"]) for x in doc["exterior"]} == {0, turn}
    linked = {p["units"][0] for p in doc["passages"]} | {p["units"][1] for p in doc["passages"]}
    assert linked & {u["id"] for u in turned}    # its corridor joins the link across the zones


def test_rooms_png_matches_the_drawn_truth(run_dir, capsys):
    plan = run_dir.parent.name[:6]
    assert main(["eval", str(run_dir), "--segmentation", str(WINGS / f"{plan}_gt.png"), "--json"]) == 0
    s = json.loads(capsys.readouterr().out)
    s = s["scores"]
    assert s["precision_macro"] > 0.9 and s["recall_macro"] > 0.9, s


def test_the_world_file_is_read_back_on_the_same_lattices(run_dir, capsys):
    plan = run_dir.parent.name[:6]
    assert main(["score", str(WINGS / f"{plan}.yaml"), str(run_dir / "world.json"), "--json"]) == 0
    got = json.loads(capsys.readouterr().out)
    doc = json.loads((run_dir / "world.json").read_text())
    first = got["worlds"][0]
    assert first["log_posterior"] == pytest.approx(doc["log_posterior"], abs=1e-3)
