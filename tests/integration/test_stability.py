"""W*s of several seeds compared (semmap_pp.studies.stability, `semmap stability`)."""

import json
import math
import re
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from semmap_pp.cli import main
from semmap_pp.studies.stability import (SeedPlan, Stability, iou_matrix, match_units, pairwise_f1, unit_agreement,
                                 unit_f1)

ROOT = Path(__file__).resolve().parents[2]
MAP = ROOT / "tests" / "data" / "maps" / "intel_corner.yaml"
TINY = ["--chains", "2", "--cores", "1", "--tune", "2", "--draws", "4", "--n-inner", "5"]


def _iou(a, b):
    """IoU of two rectangles by counting cells."""
    m = np.zeros((2, 40, 40), bool)
    for k, (r0, c0, r1, c1) in enumerate((a, b)):
        m[k, r0:r1, c0:c1] = True
    union = (m[0] | m[1]).sum()
    return (m[0] & m[1]).sum() / union if union else 0.0


def test_iou_matrix_counts_cells():
    rng = np.random.default_rng(0)
    for _ in range(50):
        rects = []
        for _ in range(int(rng.integers(1, 6))):
            r0, c0 = rng.integers(0, 30, 2)
            rects.append((int(r0), int(c0), int(r0 + rng.integers(1, 10)), int(c0 + rng.integers(1, 10))))
        got = iou_matrix(rects, rects[::-1])
        want = [[_iou(a, b) for b in rects[::-1]] for a in rects]
        np.testing.assert_allclose(got, want)


def test_matches_are_one_to_one_greedy_by_iou_and_at_least_a_half():
    a = [(0, 0, 10, 10), (0, 0, 10, 12)]
    b = [(0, 0, 10, 11)]
    # both of a overlap b's unit by more than a half: the better pair is taken, once
    assert match_units(a, b) == [(1, 0, pytest.approx(110 / 120))]
    assert match_units([(0, 0, 10, 10)], [(0, 5, 10, 15)]) == []          # IoU 1/3
    assert match_units([], b) == [] and unit_f1([], []) == 1.0
    assert unit_f1(a, b) == pytest.approx(2 / 3)
    rng = np.random.default_rng(1)
    for _ in range(100):
        a = [tuple(int(v) for v in (r, c, r + h, c + w)) for r, c, h, w in rng.integers(1, 12, (5, 4))]
        b = [tuple(int(v) for v in (r, c, r + h, c + w)) for r, c, h, w in rng.integers(1, 12, (4, 4))]
        m = match_units(a, b)
        assert len({i for i, _, _ in m}) == len(m) == len({j for _, j, _ in m})
        assert all(v >= 0.5 and v == pytest.approx(_iou(a[i], b[j])) for i, j, v in m)
        assert unit_f1(a, b) == pytest.approx(unit_f1(b, a))


def _plan(seed, logp, units):
    return SeedPlan(seed, tuple(range(1, len(units) + 1)), tuple(r for r, _ in units),
                tuple(t for _, t in units), logp, 0.9, 1.0)


def test_agreement_counts_each_reference_unit_in_the_other_plans():
    room, hall, corridor = (0, 0, 10, 10), (0, 10, 20, 30), (10, 0, 14, 10)
    ref = _plan(0, -10.0, [(room, "room"), (hall, "hall"), (corridor, "corridor")])
    same = _plan(1, -12.0, [(room, "room"), (hall, "hall"), (corridor, "corridor")])
    moved = _plan(2, -11.0, [((0, 0, 10, 11), "room"), (hall, "other")])      # no corridor; hall retyped
    rows = unit_agreement(ref, [same, moved])
    assert [(u.found, u.same_type, u.others) for u in rows] == [(2, 2, 2), (2, 1, 2), (1, 1, 2)]
    assert rows[0].mean_iou == pytest.approx((1 + 100 / 110) / 2) and rows[2].mean_iou == 1.0
    st = Stability.of([same, moved, ref])          # the reference: the highest log posterior
    assert st.reference is ref and st.ref == 2 and st.stable_units() == 1
    f1 = pairwise_f1([same, moved, ref])
    assert np.allclose(f1, f1.T) and np.all(np.diag(f1) == 1) and f1[0, 2] == 1.0
    assert f1[0, 1] == pytest.approx(2 * 2 / 5)
    assert st.mean_f1() == pytest.approx((0.8 + 1.0 + 0.8) / 3)
    doc = json.loads(json.dumps(st.to_dict()))
    assert doc["reference_seed"] == 0 and doc["stable_units"] == 1
    assert [u["found"] for u in doc["units"]] == [2, 2, 1]
    table = st.table()
    assert "| 0 (reference) | 3 |" in table and "| 3 | corridor | 4 x 10 | 1/2 | 1/2 | 1.000 |" in table
    lonely = _plan(3, -20.0, [((30, 30, 35, 35), "room")])
    rows = unit_agreement(ref, [lonely])
    assert all(u.found == 0 and math.isnan(u.mean_iou) for u in rows)
    assert json.loads(json.dumps(Stability.of([ref, lonely]).to_dict()))["units"][0]["mean_iou"] is None
    with pytest.raises(ValueError):
        Stability.of([ref])


def test_stability_runs_each_seed_and_writes_table_json_and_figure(tmp_path, capsys):
    out = tmp_path / "stab"
    assert main(["stability", str(MAP), "--seeds", "3", "5", "--out", str(out), *TINY]) == 0
    printed = capsys.readouterr().out
    assert printed.splitlines()[0] == "| seed | units | CPR | log posterior | seconds |"
    doc = json.loads((out / "stability.json").read_text())
    assert [r["seed"] for r in doc["runs"]] == [3, 5]
    best = max(doc["runs"], key=lambda r: r["log_posterior"])
    assert doc["reference_seed"] == best["seed"] and len(doc["units"]) == best["units"]
    assert all(u["others"] == 1 and 0 <= u["same_type"] <= u["found"] <= 1 for u in doc["units"])
    assert doc["settings"]["draws"] == 4 and doc["rules"].endswith("table3.lp")
    f1 = np.array(doc["unit_f1"])
    assert f1.shape == (2, 2) and f1[0, 1] == f1[1, 0] == doc["mean_unit_f1"]
    assert doc["stable_units"] == sum(u["found"] == u["same_type"] == 1 for u in doc["units"])
    # each seed's W* is the one `semmap map --seed N` writes with the same run lengths (seed 5's
    # search took chain 1's start world from seed 3's), and the reference's units are its units
    for seed in (3, 5):
        one = tmp_path / f"one{seed}"
        assert main(["map", str(MAP), "--out", str(one), "--seed", str(seed), "--spread-draws", "0", *TINY,
                     "--progress", "none"]) == 0
        world = json.loads((one / "world.json").read_text())
        run = next(r for r in doc["runs"] if r["seed"] == seed)
        assert world["log_posterior"] == pytest.approx(run["log_posterior"], abs=1e-6)
        if seed == doc["reference_seed"]:
            assert [(u["id"], u["type"], u["vertices_m"]) for u in world["units"]] == \
                [(u["id"], u["type"], u["vertices_m"]) for u in doc["units"]]
    assert (out / "stability.md").read_text().startswith("# W* of ")
    assert Image.open(out / "stability.png").size[0] > 100


@pytest.mark.parametrize("args, needle", [
    (["--seeds", "3", "3"], "give at least two different --seeds"),
    (["--seeds", "1", "2", "--rules", "missing.lp"], "missing.lp"),
    (["--seeds", "1", "2", "--draws", "3"], "--draws must be at least 4"),
])
def test_stability_user_errors_write_nothing(tmp_path, capsys, args, needle):
    out = tmp_path / "o"
    assert main(["stability", str(MAP), "--out", str(out), *TINY, *args]) == 2
    err = capsys.readouterr().err
    assert needle in err and err.count("\n") == 1
    assert not out.exists()


def test_stability_of_an_all_unknown_map_is_two_empty_plans(tmp_path, capsys):
    """A legal but degenerate map: every W* is empty, the seeds agree (F1 1), CPR is null."""
    img = tmp_path / "unknown.png"
    Image.fromarray(np.full((60, 60), 205, np.uint8)).save(img)
    out = tmp_path / "stab"
    assert main(["stability", str(img), "--seeds", "0", "1", "--out", str(out), *TINY]) == 0
    doc = json.loads((out / "stability.json").read_text())
    assert [r["units"] for r in doc["runs"]] == [0, 0] and all(r["cpr"] is None for r in doc["runs"])
    assert doc["units"] == [] and doc["mean_unit_f1"] == 1.0 and doc["stable_units"] == 0
    assert "0 of 0 units" in capsys.readouterr().out
    # --json: the same object on stdout, one line, and nothing else
    assert main(["stability", str(img), "--seeds", "0", "1", "--json", *TINY]) == 0
    printed = capsys.readouterr().out.splitlines()
    again = json.loads(printed[0])
    assert len(printed) == 1 and again.keys() == doc.keys()

    def untimed(d):
        return dict(d, runs=[{k: v for k, v in r.items() if k != "seconds"} for r in d["runs"]])
    assert untimed(again) == untimed(doc)


def test_ctrl_c_stops_semmap_stability_and_writes_nothing(tmp_path):
    """SIGINT while the first seed samples: exit 130, the message, no traceback, no output folder."""
    from test_cli_faults import sigint_after

    floor = tmp_path / "f"
    assert main(["synth", "--seed", "3", "--units", "4", "--out", str(floor)]) == 0
    out, stdout = tmp_path / "stab", []
    code, err = sigint_after([floor / "map.yaml", "--seeds", "0", "1", "--out", out, "--chains", "2",
                              "--cores", "1", "--tune", "2", "--draws", "100000", "--n-inner", "5"],
                             "sampling:", wait=1.0, command="stability", out=stdout)
    assert code == 130, err
    assert "interrupted: stopping; nothing will be written" in err and "Traceback" not in err
    assert stdout == [""] and not out.exists()


def test_jobs_run_the_seeds_in_processes_of_their_own_with_the_same_results(tmp_path, capfd):
    """``--jobs 2``: the seeds' runs go two at a time in spawned processes, after the start world
    they share is built once; every number but the seconds is what the runs in a row give."""
    docs = []
    for jobs in ("1", "2"):
        out = tmp_path / f"j{jobs}"
        assert main(["stability", str(MAP), "--seeds", "3", "5", "--out", str(out), "--jobs", jobs, *TINY]) == 0
        doc = json.loads((out / "stability.json").read_text())
        for r in doc["runs"]:
            r.pop("seconds")
        docs.append(doc)
    assert docs[0] == docs[1]
    err = capfd.readouterr().err          # the workers write to the same file descriptor
    assert "2 runs, 2 at a time (--jobs)" in err
    assert re.search(r"^\[seed 5\] start world: \d+ units \(shared\)$", err, re.M), err


def test_ctrl_c_stops_parallel_runs_and_writes_nothing(tmp_path):
    """SIGINT while the workers sample (``--jobs 2``): the parent stops them, exit 130, the message,
    no traceback, no output folder."""
    from test_cli_faults import sigint_after

    floor = tmp_path / "f"
    assert main(["synth", "--seed", "3", "--units", "4", "--out", str(floor)]) == 0
    out, stdout = tmp_path / "stab", []
    code, err = sigint_after([floor / "map.yaml", "--seeds", "0", "1", "--out", out, "--jobs", "2", "--chains",
                              "2", "--cores", "1", "--tune", "2", "--draws", "100000", "--n-inner", "5"],
                             "] sampling:", wait=1.0, command="stability", out=stdout)
    assert code == 130, err
    assert "interrupted: stopping; nothing will be written" in err and "Traceback" not in err
    assert stdout == [""] and not out.exists()
