"""bench_quality.target_report: every target under every reading the run measured, met or not,
with the truth's own score beside the synthetic readings (docs/quality.md, "Issue 5's targets")."""

import pytest

from benchmod import bench_quality as bq


def result():
    """A run of the synthetic, truth and real subsets with numbers on both sides of each bound."""
    synthetic = {"cpr": 0.9288, "cpr_building": 0.9511, "unit_f1": 0.8624, "unit_f1_either_l": 0.8822,
                 "unit_f1_observed": 0.9116, "unit_f1_visible": 0.9292, "type_accuracy": 0.9883,
                 "door_f1": 0.8251, "door_f1_either_l": 0.8575, "door_f1_observed": 0.8708,
                 "door_f1_visible": 0.9123}
    truth = {"cpr": 0.8911, "unit_f1": 0.9095, "door_f1": 0.8879}
    real = [{"map": "intel-lab", "cpr": 0.9467, "time_to_wstar_s": 4.2},
            {"map": "ubremen-cartesium", "cpr": 0.8999, "time_to_wstar_s": 61.0},
            {"map": "aces", "cpr": 0.5}]
    return {"synthetic": {"means": synthetic}, "truth": {"means": truth}, "real": {"rows": real}}


def test_each_reading_is_a_row_with_its_own_verdict():
    rows = bq.target_report(result())
    assert [(r["target"], r["value"], r["met"]) for r in rows] == [
        ("synthetic_cpr", 0.9288, False), ("synthetic_cpr", 0.9511, True),
        ("unit_f1", 0.8624, False), ("unit_f1", 0.8822, False), ("unit_f1", 0.9116, True),
        ("unit_f1", 0.9292, True), ("type_accuracy", 0.9883, True),
        ("door_f1", 0.8251, False), ("door_f1", 0.8575, True), ("door_f1", 0.8708, True),
        ("door_f1", 0.9123, True),
        ("cartesium_cpr", 0.8999, False), ("intel_cpr", 0.9467, True),
        ("time_to_wstar_s", 61.0, False)]      # an upper bound: 61 s is over 60 s
    # the literal reading of each target comes first
    assert rows[0]["reading"].startswith("default ROI") and rows[2]["reading"] == "every true unit"


def test_the_ceiling_is_the_truths_score_of_the_same_reading_and_only_for_synthetic():
    rows = {(r["target"], r["reading"]): r for r in bq.target_report(result())}
    assert rows[("synthetic_cpr", "default ROI (the known map, closed)")]["ceiling"] == 0.8911
    assert rows[("unit_f1", "every true unit")]["ceiling"] == 0.9095
    assert rows[("unit_f1", "the seen true units")]["ceiling"] is None     # not in this truth run
    assert rows[("intel_cpr", "default ROI")]["ceiling"] is None


def test_a_bound_met_exactly_is_met_and_unmeasured_readings_are_left_out():
    rows = bq.target_report({"synthetic": {"means": {"door_f1": 0.85, "cpr": None}},
                             "real": {"rows": [{"map": "ubremen-cartesium", "time_to_wstar_s": 60.0}]}})
    assert [(r["target"], r["met"]) for r in rows] == [("door_f1", True), ("time_to_wstar_s", True)]
    assert bq.target_report({"ipa": {"means": {"precision": 0.8}}}) == []


def test_the_table_has_a_line_per_reading():
    rows = bq.target_report(result())
    lines = bq.report_lines(rows)
    assert len(lines) == len(rows) + 1
    assert lines[1].split()[-1] == "no" and "0.8911" in lines[1]
    assert "<= 60" in lines[-1] and lines[-1].endswith("no")


@pytest.mark.parametrize("target", sorted(bq.TARGETS))
def test_every_target_has_a_reading(target):
    assert any(t == target for t, *_ in bq.READINGS)
