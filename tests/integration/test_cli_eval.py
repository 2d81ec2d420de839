"""`semmap eval DIR --truth T`: synthetic truth, ipa segmentation and ipa place types, detected."""

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from semmap_pp.cli import main
from semmap_pp.cli.cmd_eval import detect_kind
from semmap_pp.evaluate import read_ipa_gt, read_ipa_types, read_label_image
from semmap_pp.evaluate.types import TRUTH_CORRIDOR, TRUTH_ROOM
from semmap_pp.semantic.world_json import write_labels_png

ROOT = Path(__file__).resolve().parents[2]
IPA = ROOT / "tests" / "data" / "ipa"
TINY = ["--chains", "2", "--cores", "1", "--tune", "2", "--draws", "4", "--n-inner", "5", "--progress", "none"]


@pytest.fixture(scope="module")
def floor(tmp_path_factory):
    out = tmp_path_factory.mktemp("floor") / "f"
    assert main(["synth", "--seed", "3", "--units", "4", "--out", str(out)]) == 0
    return out


def fake_run(path, units, labels, cpr=0.5, **extra):
    """A run folder holding only what `semmap eval` reads: world.json and labels.png."""
    path.mkdir(parents=True, exist_ok=True)
    (path / "world.json").write_text(json.dumps(dict({"format": "semmap_pp.world/1", "units": units, "cpr": cpr},
                                                     **extra)))
    write_labels_png(path / "labels.png", np.asarray(labels))
    return path


def scores(capsys, *args):
    assert main(["eval", *map(str, args), "--json"]) == 0
    return json.loads(capsys.readouterr().out)


def test_sampled_run_against_its_synthetic_floor(floor, tmp_path, capsys):
    run = tmp_path / "run"
    assert main(["map", str(floor / "map.yaml"), "--out", str(run), *TINY]) == 0
    capsys.readouterr()
    doc = scores(capsys, run, "--truth", floor)
    s = doc["scores"]
    assert doc["kind"] == "synthetic" and s["units_true"] == 4
    assert s["units_predicted"] == len(json.loads((run / "world.json").read_text())["units"])
    assert s["units_exterior"] == len(json.loads((run / "world.json").read_text())["exterior"])
    for k in ("unit_f1", "unit_precision", "unit_recall", "segmentation_precision", "segmentation_iou", "cpr"):
        assert 0.0 <= s[k] <= 1.0, k
    assert main(["eval", str(run), "--truth", str(floor / "truth.json")]) == 0
    table = capsys.readouterr().out
    assert "unit_f1" in table and "door_recall" in table and "segmentation_recall" in table


def test_the_truth_itself_scores_perfectly(floor, tmp_path, capsys):
    t = json.loads((floor / "truth.json").read_text())
    units = [{"id": u["id"], "type": u["type"], "vertices_px": u["corners_px"]} for u in t["units"]]
    doors = [{"units": d["units"], "center_px": d["center_px"], "width_m": d["width_m"]} for d in t["doors"]]
    run = fake_run(tmp_path / "perfect", units, read_label_image(floor / "truth_labels.png"),
                   adjacency=t["adjacency"], doors=doors)
    s = scores(capsys, run, "--truth", floor)["scores"]
    assert s["unit_f1"] == 1.0 and s["type_accuracy"] == 1.0
    assert s["adjacency_recall"] == 1.0 and s["door_recall"] == 1.0
    assert s["segmentation_precision"] == 1.0 and s["segmentation_recall"] == 1.0


def test_the_posterior_marginals_reliability_against_the_truth(floor, tmp_path, capsys):
    """The truth as a run whose posterior marginals are certain: every claim right, ECE 0. Give
    one unit existence 0.6 and a wrong type 0.7 and one door 0.2: the bins and ECEs follow."""
    t = json.loads((floor / "truth.json").read_text())
    certain = {"room": 0.0, "corridor": 0.0, "hall": 0.0, "other": 0.0}
    units = [{"id": u["id"], "type": u["type"], "vertices_px": u["corners_px"], "posterior_exists": 1.0,
              "posterior_type": dict(certain, **{u["type"]: 1.0})} for u in t["units"]]
    doors = [{"units": d["units"], "center_px": d["center_px"], "width_m": d["width_m"], "posterior_exists": 1.0}
             for d in t["doors"]]
    extra = dict(adjacency=t["adjacency"], doors=doors, posterior_marginals={"worlds": 10})
    run = fake_run(tmp_path / "certain", units, read_label_image(floor / "truth_labels.png"), **extra)
    doc = scores(capsys, run, "--truth", floor)
    assert doc["scores"]["ece_units"] == 0.0 and doc["scores"]["ece_doors"] == 0.0
    assert doc["calibration"]["units"]["claims"] == len(units)
    wrong = "corridor" if units[0]["type"] != "corridor" else "room"
    units[0]["posterior_exists"] = 0.6
    units[0]["posterior_type"] = dict(certain, **{wrong: 0.7, units[0]["type"]: 0.3})
    doors[0]["posterior_exists"] = 0.2
    run = fake_run(tmp_path / "unsure", units, read_label_image(floor / "truth_labels.png"), **extra)
    doc = scores(capsys, run, "--truth", floor)
    n, k = len(units), len(doors)
    assert doc["scores"]["ece_units"] == pytest.approx(round(0.4 / n, 4))        # right at p 0.6
    assert doc["scores"]["ece_types"] == pytest.approx(round(0.7 / n, 4))        # wrong at p 0.7
    assert doc["scores"]["ece_doors"] == pytest.approx(round(0.8 / k, 4))        # right at p 0.2
    assert [0.6, 0.7, 1, 0.6, 1.0] in doc["calibration"]["units"]["bins"]
    assert main(["eval", str(run), "--truth", str(floor)]) == 0
    assert "reliability of the posterior marginals, doors" in capsys.readouterr().out


def unsure_run(floor, path):
    """The truth as a run with posterior marginals, one unit's existence 0.6 and wrong type 0.7 and
    one door's 0.2 (as above), and a report.html with its convergence section."""
    t = json.loads((floor / "truth.json").read_text())
    certain = {"room": 0.0, "corridor": 0.0, "hall": 0.0, "other": 0.0}
    units = [{"id": u["id"], "type": u["type"], "vertices_px": u["corners_px"], "posterior_exists": 1.0,
              "posterior_type": dict(certain, **{u["type"]: 1.0})} for u in t["units"]]
    units[0]["posterior_exists"] = 0.6
    units[0]["posterior_type"] = dict(certain, **{"corridor" if units[0]["type"] != "corridor" else "room": 0.7,
                                                  units[0]["type"]: 0.3})
    doors = [{"units": d["units"], "center_px": d["center_px"], "width_m": d["width_m"], "posterior_exists": 1.0}
             for d in t["doors"]]
    doors[0]["posterior_exists"] = 0.2
    run = fake_run(path, units, read_label_image(floor / "truth_labels.png"), adjacency=t["adjacency"],
                   doors=doors, posterior_marginals={"worlds": 10})
    (run / "report.html").write_text(REPORT)
    return run


REPORT = ('<!DOCTYPE html><html><body><nav><a href="#spread">Posterior spread</a><a href="#convergence">'
          'Convergence</a></nav><h2 id="spread">Posterior spread</h2>\n<!-- calibration --><!-- /calibration -->'
          '\n<h2 id="convergence">Convergence</h2></body></html>')


def test_the_reliability_diagram_is_the_table_as_a_png(floor, tmp_path, capsys):
    """--figure writes the reliability diagram of exactly the table --json gives, after the table's
    text the path; with --json nothing but the JSON."""
    from semmap_pp.outputs.figures import reliability_png

    run = unsure_run(floor, tmp_path / "unsure")
    fig = tmp_path / "figs" / "reliability.png"              # a folder that does not exist yet
    doc = scores(capsys, run, "--truth", floor, "--figure", fig)
    title = f"Reliability of the posterior marginals of {run} against {floor}"
    assert fig.read_bytes() == reliability_png(doc["calibration"], title)
    assert doc["calibration"]["units"]["bins"][0] == [0.6, 0.7, 1, 0.6, 1.0]
    assert main(["eval", str(run), "--truth", str(floor), "--figure", str(fig)]) == 0
    out = capsys.readouterr().out.rstrip().splitlines()
    assert out[-1] == str(fig) and out[-2].startswith("  p in [0.9, 1.0]")
    assert sorted(p.name for p in fig.parent.iterdir()) == ["reliability.png"]      # no temporary left


def test_the_report_gains_the_calibration_section_once(floor, tmp_path, capsys):
    run = unsure_run(floor, tmp_path / "unsure")
    for _ in range(2):
        assert main(["eval", str(run), "--truth", str(floor), "--report"]) == 0
        assert capsys.readouterr().out.rstrip().endswith(str(run / "report.html"))
    page = (run / "report.html").read_text()
    assert page.count('id="calibration"') == 1 and page.count('href="#calibration"') == 1
    assert page.index('id="spread"') < page.index('id="calibration"') < page.index('id="convergence"')
    assert page.count("data:image/png;base64,") == 1
    assert '<td>units</td><td>[0.6, 0.7)</td><td class="num">1</td><td class="num">0.600</td>' in page
    assert sorted(p.name for p in run.iterdir()) == ["labels.png", "report.html", "world.json"]  # lock gone


def one_line_error(capsys, *args):
    assert main(["eval", *map(str, args)]) == 2
    out, err = capsys.readouterr()
    assert out == "" and err.startswith("semmap: error: ") and err.count("\n") == 1, err
    return err


def test_the_diagram_refuses_bad_paths_and_truths_in_one_line(floor, tmp_path, capsys):
    run = unsure_run(floor, tmp_path / "unsure")
    before = sorted(p.name for p in tmp_path.iterdir())
    assert "is a directory" in one_line_error(capsys, run, "--truth", floor, "--figure", tmp_path)
    assert "is a file, not a folder" in one_line_error(capsys, run, "--truth", floor, "--figure",
                                                       run / "world.json" / "d.png")
    assert "go with --truth" in one_line_error(capsys, run, "--segmentation", floor / "truth_labels.png",
                                               "--figure", tmp_path / "a.png")
    t = read_ipa_types(IPA / "training_Fr52.png")
    ipa = fake_run(tmp_path / "ipa", [{"id": 1, "type": "room"}], np.where(t == TRUTH_ROOM, 1, 0))
    assert "needs a synthetic truth" in one_line_error(capsys, ipa, "--truth", IPA / "training_Fr52.png",
                                                       "--figure", tmp_path / "b.png")
    drew_none = shutil.copytree(run, tmp_path / "none")
    doc = json.loads((drew_none / "world.json").read_text())
    del doc["posterior_marginals"]
    (drew_none / "world.json").write_text(json.dumps(doc))
    assert "holds no posterior marginals" in one_line_error(capsys, drew_none, "--truth", floor,
                                                            "--figure", tmp_path / "c.png", "--report")
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(before + ["ipa", "none"])   # nothing written


def test_a_report_that_cannot_take_the_section_is_left_as_it_was(floor, tmp_path, capsys):
    from semmap_pp.run.outdir import lock_out_dir

    run = unsure_run(floor, tmp_path / "unsure")
    fig = tmp_path / "r.png"
    (run / "report.html").write_text("<html>not ours</html>")
    err = one_line_error(capsys, run, "--truth", floor, "--report", "--figure", fig)
    assert "not a report.html of `semmap map`" in err
    assert (run / "report.html").read_text() == "<html>not ours</html>" and not fig.exists()
    (run / "report.html").unlink()
    assert "report.html: missing" in one_line_error(capsys, run, "--truth", floor, "--report")
    (run / "report.html").write_text(REPORT)
    with lock_out_dir(run):                                    # a `semmap map` writing into the folder
        assert "in use by another semmap run" in one_line_error(capsys, run, "--truth", floor, "--report")
    assert (run / "report.html").read_text() == REPORT and not fig.exists()


def test_ipa_segmentation_of_labels_and_regions(tmp_path, capsys):
    gt = read_ipa_gt(IPA / "office_a_gt_segmentation.png")
    merged = np.where(gt > 0, 1, 0)                 # one segment for every room
    run = fake_run(tmp_path / "seg", [{"id": 1, "type": "room"}], gt)
    write_labels_png(run / "regions.png", merged)
    doc = scores(capsys, run, "--truth", IPA / "office_a_gt_segmentation.png")
    s = doc["scores"]
    assert doc["kind"] == "ipa-segmentation"
    assert s["precision"] == 1.0 and s["recall"] == 1.0 and s["rooms"] == 27
    assert s["regions_segments"] == 1 and s["regions_precision"] < 0.5 and s["regions_recall"] == 1.0


def test_ipa_place_types(tmp_path, capsys):
    truth = read_ipa_types(IPA / "training_Fr52.png")
    labels = np.where(truth == TRUTH_ROOM, 1, np.where(truth == TRUTH_CORRIDOR, 2, 0))
    right = fake_run(tmp_path / "right", [{"id": 1, "type": "room"}, {"id": 2, "type": "corridor"}], labels)
    wrong = fake_run(tmp_path / "wrong", [{"id": 1, "type": "corridor"}, {"id": 2, "type": "room"}], labels)
    s = scores(capsys, right, "--truth", IPA / "training_Fr52.png")["scores"]
    assert s["type_accuracy"] == 1.0 and s["coverage"] == 1.0
    assert scores(capsys, wrong, "--truth", IPA / "training_Fr52.png")["scores"]["type_accuracy"] == 0.0


def test_kind_by_content_when_the_name_says_nothing(tmp_path):
    shutil.copy(IPA / "office_a_gt_segmentation.png", tmp_path / "a.png")
    shutil.copy(IPA / "training_Fr52.png", tmp_path / "b.png")
    assert detect_kind(tmp_path / "a.png") == "ipa-segmentation"
    assert detect_kind(tmp_path / "b.png") == "ipa-types"


@pytest.mark.parametrize("world", [
    '{"format": "semmap_pp.world/1", "units": [' + ",".join(['{"id": 1}'] * 20_001) + "]}",
    '{"format": "semmap_pp.world/1", "objects": [' + ",".join(["[]"] * 2_000_001) + "]}",
])
def test_a_runs_world_json_is_bounded_as_every_world_json_is(tmp_path, capsys, world):
    # issue 55 F3: a world.json is bounded before anything is built from it, here too
    run = fake_run(tmp_path / "big", [], np.ones((5, 5)))
    (run / "world.json").write_text(world)
    assert main(["eval", str(run), "--truth", str(IPA / "training_Fr52.png")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith(f"semmap: error: {run / 'world.json'}: ")
    assert "a world.json holds at most 20000" in err or "too many for a world.json" in err


def test_truth_of_another_map_is_a_user_error(floor, tmp_path, capsys):
    run = fake_run(tmp_path / "small", [{"id": 1, "type": "room"}], np.ones((5, 5)))
    assert main(["eval", str(run), "--truth", str(IPA / "training_Fr52.png")]) == 2
    err = capsys.readouterr().err
    assert "not the same map" in err and err.count("\n") == 1


def test_an_l_cut_the_other_way_is_scored_both_ways(tmp_path, capsys):
    from test_evaluate_lshape import A2, B2, prediction, truth
    t = dict(truth(), height=75, width=75, resolution=0.05)
    (tmp_path / "t").mkdir()
    (tmp_path / "t" / "truth.json").write_text(json.dumps(t))
    pred = prediction(A2, B2)
    run = fake_run(tmp_path / "run", pred["units"], np.zeros((75, 75)), doors=pred["doors"])
    s = scores(capsys, run, "--truth", tmp_path / "t")["scores"]
    assert s["l_shapes"] == 1 and s["l_shapes_recut"] == 1
    assert s["unit_f1"] == pytest.approx(0.8) and s["unit_f1_either_l"] == 1.0
    assert s["door_recall"] == pytest.approx(1 / 3) and s["door_recall_either_l"] == 1.0
