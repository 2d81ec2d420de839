"""`semmap map` on a drawn plan with a wing at 30 degrees (tests/data/wings/wing30): a lattice per
direction, each unit at its own wing's angle in world.json, the units of the turned wing not
exterior, rooms.png close to the drawn truth, and the run's world.json read back exactly."""

import json
from pathlib import Path

import numpy as np
import pytest

from semmap_pp.cli import main

WINGS = Path(__file__).resolve().parents[1] / "data" / "wings"
TINY = ["--chains", "2", "--cores", "1", "--tune", "2", "--draws", "4", "--n-inner", "5",
        "--spread-draws", "0", "--progress", "none"]


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
    out = tmp_path_factory.mktemp("wing30") / "run"
    assert main(["map", str(WINGS / "wing30.yaml"), "--out", str(out), *TINY]) == 0
    return out


def test_each_unit_lies_at_its_own_wings_angle(run_dir):
    doc = json.loads((run_dir / "world.json").read_text())
    assert doc["map"]["orientations_deg"] == pytest.approx([0.0, 30.0], abs=0.5)
    angles = {round(u["orientation_deg"]) for u in doc["units"]}
    assert angles == {0, 30}
    for u in doc["units"]:
        v = np.asarray(u["vertices_px"])
        side = v[1] - v[0]
        assert np.degrees(np.arctan2(side[1], side[0])) == pytest.approx(u["orientation_deg"], abs=1e-3)
    turned = [u for u in doc["units"] if round(u["orientation_deg"]) == 30]
    assert len(turned) >= 7                      # the turned wing's six rooms and its corridor
    linked = {p["units"][0] for p in doc["passages"]} | {p["units"][1] for p in doc["passages"]}
    assert linked & {u["id"] for u in turned}    # its corridor joins the link across the zones


def test_rooms_png_matches_the_drawn_truth(run_dir, capsys):
    assert main(["eval", str(run_dir), "--segmentation", str(WINGS / "wing30_gt.png"), "--json"]) == 0
    s = json.loads(capsys.readouterr().out)
    s = s["scores"]
    assert s["precision_macro"] > 0.9 and s["recall_macro"] > 0.9, s


def test_the_world_file_is_read_back_on_the_same_lattices(run_dir, capsys):
    assert main(["score", str(WINGS / "wing30.yaml"), str(run_dir / "world.json"), "--json"]) == 0
    got = json.loads(capsys.readouterr().out)
    doc = json.loads((run_dir / "world.json").read_text())
    first = got["worlds"][0]
    assert first["log_posterior"] == pytest.approx(doc["log_posterior"], abs=1e-3)
