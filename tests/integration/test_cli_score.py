"""``semmap score``: a run's W* scores as the run scored it; edited worlds, rule files, bad input."""

import json
from pathlib import Path

import pytest

from semmap_pp.cli import main

ROOT = Path(__file__).resolve().parents[2]
MAP = ROOT / "tests" / "data" / "maps" / "intel_corner.yaml"


@pytest.fixture(scope="module")
def wstar(intel_corner_wstar):
    return intel_corner_wstar


def score(capsys, *args) -> tuple[int, str, str]:
    code = main(["score", *map(str, args)])
    captured = capsys.readouterr()
    return code, captured.out, captured.err


def test_a_runs_w_star_scores_as_the_run_scored_it(wstar, capsys):
    code, out, _ = score(capsys, MAP, wstar, "--json")
    assert code == 0
    doc = json.loads(wstar.read_text())
    row = json.loads(out)["worlds"][0]
    assert row["log_posterior"] == pytest.approx(doc["log_posterior"], abs=1e-6)
    assert row["log_likelihood"] + row["log_prior"] == pytest.approx(row["log_posterior"], abs=1e-2)
    assert row["cpr"] == pytest.approx(doc["cpr"], abs=1e-6)
    assert row["units"] == len(doc["units"]) and row["exterior"] == len(doc["exterior"])
    types = [u["type"] for u in doc["units"]]
    assert row["types"] == {t: types.count(t) for t in ("room", "corridor", "hall", "other")}


def test_an_edited_world_is_compared_with_the_first_and_polished_on_request(wstar, tmp_path, capsys):
    doc = json.loads(wstar.read_text())
    biggest = max(doc["units"], key=lambda u: u["size_m"][0] * u["size_m"][1])
    doc["units"] = [u for u in doc["units"] if u is not biggest]
    edited = tmp_path / "edited.json"
    edited.write_text(json.dumps(doc))
    code, out, _ = score(capsys, MAP, wstar, edited, "--json", "--polish")
    assert code == 0
    first, second = json.loads(out)["worlds"]
    assert second["units"] == first["units"] - 1
    assert second["log_posterior"] < first["log_posterior"]     # a room's worth of cells unexplained
    for row in (first, second):                                 # the polish never lowers log p
        assert row["polished"]["log_posterior"] >= row["log_posterior"] - 1e-6
    assert second["polished"]["log_posterior"] > second["log_posterior"]
    code, text, _ = score(capsys, MAP, wstar, edited)
    assert code == 0
    lines = text.splitlines()
    assert lines[0].startswith(f"map {MAP}, rules table3.lp, model default.toml, ROI default")
    delta = second["log_posterior"] - first["log_posterior"]
    assert f"{delta:+,.1f}" in lines[3] and lines[2].split()[-3] == "-"


def test_no_knowledge_types_every_unit_room(wstar, capsys):
    code, out, _ = score(capsys, MAP, wstar, "--rules", ROOT / "rules" / "none.lp", "--json")
    assert code == 0
    row = json.loads(out)["worlds"][0]
    assert row["types"]["room"] == row["units"]


def test_bad_worlds_get_one_line_naming_the_file(wstar, tmp_path, capsys):
    broken = tmp_path / "broken.json"
    broken.write_text("{ not json")
    code, out, err = score(capsys, MAP, wstar, broken)
    assert code == 2 and out == ""                   # every file is read before anything is scored
    assert len(err.strip().splitlines()) == 1 and str(broken) in err
    doc = json.loads(wstar.read_text())
    doc["map"]["width"] += 10
    other = tmp_path / "other_map.json"
    other.write_text(json.dumps(doc))
    code, out, err = score(capsys, MAP, other)
    assert code == 2 and out == ""
    assert str(other) in err and "written for a 250x207 map" in err
