"""bench_quality.error_breakdown and door_breakdown: each unmatched unit and each missed or extra
door lands in exactly one class (docs/quality.md, "Synthetic floors": where unit F1 is lost)."""

from semmap_pp.evaluate import score_world

from benchmod import bench_quality as bq

SHAPE = (100, 100)


def box(x0, y0, x1, y1):
    return [[x0, y0], [x1, y0], [x1, y1], [x0, y1]]


def worlds():
    """A truth of seven units and a prediction with a unit of each error class (IoU 0.4 or less
    where a unit is not to match: 0.5 matches)."""
    truth = {"resolution": 0.05, "units": [
        {"id": 0, "type": "room", "corners_px": box(0, 0, 20, 20)},     # matched by P0
        {"id": 1, "type": "room", "corners_px": box(20, 0, 40, 20)},    # merged with T2 in P1
        {"id": 2, "type": "room", "corners_px": box(40, 0, 60, 20)},
        {"id": 3, "type": "room", "corners_px": box(0, 20, 40, 40)},    # cut: P2, P3 (+ uncovered)
        {"id": 4, "type": "room", "corners_px": box(0, 40, 40, 60)},    # seen in part: P4
        {"id": 5, "type": "room", "corners_px": box(40, 20, 80, 60)},   # matched by P5, piece P6
        {"id": 6, "type": "room", "corners_px": box(60, 0, 80, 20), "explored": False},
    ], "doors": [
        {"units": [0, 5], "center_px": [40, 10], "width_m": 0.8, "open": True},   # found
        {"units": [0, 3], "center_px": [10, 20], "width_m": 0.8, "open": True},   # T3 missed
        {"units": [5, 6], "center_px": [70, 20], "width_m": 0.8, "open": False},  # T6 unseen
        {"units": [0, 5], "center_px": [40, 18], "width_m": 0.8, "open": False},  # drawn as wall
    ]}
    pred = {"units": [
        {"id": 10, "type": "room", "vertices_px": box(0, 0, 20, 20)},
        {"id": 11, "type": "room", "vertices_px": box(20, 0, 70, 20)},
        {"id": 12, "type": "room", "vertices_px": box(0, 20, 16, 40)},
        {"id": 13, "type": "room", "vertices_px": box(16, 20, 32, 40)},
        {"id": 14, "type": "room", "vertices_px": box(0, 40, 12, 60)},
        {"id": 15, "type": "room", "vertices_px": box(40, 20, 70, 60)},
        {"id": 16, "type": "room", "vertices_px": box(70, 20, 80, 60)},
        {"id": 17, "type": "room", "vertices_px": box(85, 85, 99, 99)},   # outside the building
    ], "doors": [
        {"units": [10, 15], "center_px": [40, 10]},   # true positive
        {"units": [10, 11], "center_px": [20, 10]},   # touches the unmatched P1
        {"units": [10, 15], "center_px": [5, 5]},     # matched pair, no true door near
    ]}
    return pred, truth


def test_every_unmatched_unit_is_in_exactly_one_class():
    pred, truth = worlds()
    e = bq.error_breakdown(pred, truth, SHAPE)
    assert e == {"pred_unmatched": 6, "pred_outside_building": 1, "pred_spans": 1,
                 "pred_piece_of_matched": 1, "pred_piece_of_missed": 3, "pred_other": 0,
                 "true_missed": 5, "true_missed_unseen": 1, "true_missed_cut": 1,
                 "true_missed_merged": 2, "true_missed_partial": 1, "true_missed_other": 0}
    assert sum(v for k, v in e.items() if k.startswith("pred_") and k != "pred_unmatched") == 6
    assert sum(v for k, v in e.items() if k.startswith("true_missed_")) == 5


def test_every_extra_and_missed_door_is_in_exactly_one_class():
    pred, truth = worlds()
    sc = score_world(pred, truth, shape=SHAPE, resolution=0.05)
    d = bq.door_breakdown(pred, truth, sc)
    assert d == {"door_tp": 1, "door_fp": 2, "door_fp_unmatched_unit": 1, "door_fp_matched_pair": 1,
                 "door_fn": 3, "door_fn_unmatched_unit": 2, "door_fn_unmatched_unit_closed": 1,
                 "door_fn_matched_pair": 1, "door_closed_between_matched": 1}
    assert d["door_tp"] == round(sc.door_precision * 3) == round(sc.door_recall * 4)


def test_a_perfect_prediction_loses_nothing():
    _, truth = worlds()
    seen = [u for u in truth["units"] if u.get("explored", True)]
    pred = {"units": [{"id": u["id"], "type": u["type"], "vertices_px": u["corners_px"]} for u in seen],
            "doors": [d for d in truth["doors"] if d["open"] and 6 not in d["units"]]}
    e = bq.error_breakdown(pred, truth, SHAPE)
    assert e["pred_unmatched"] == 0 and e["true_missed"] == e["true_missed_unseen"] == 1
    d = bq.door_breakdown(pred, truth, score_world(pred, truth, shape=SHAPE, resolution=0.05))
    assert d["door_fp"] == 0 and d["door_fn"] == 2
    assert d["door_fn_unmatched_unit_closed"] == 1 and d["door_closed_between_matched"] == 1


def test_surgery_replaces_the_units_over_each_missed_or_pieced_true_unit():
    """bench_surgery's repairs: the predicted units over a missed true unit (or one holding an
    unmatched piece) out, that true unit and the seen neighbours they hold > 30 % of in; never an
    unseen one (T6, which P1 holds half of)."""
    pred, truth = worlds()
    assert bq.surgery_clusters(pred, truth, SHAPE) == [
        (1, "merged", [1], [1, 2]), (2, "merged", [1], [1, 2]), (3, "cut", [2, 3], [3]),
        (4, "partial", [4], [4]), (5, "holds_piece", [5, 6], [5])]


def test_the_real_subset_scores_the_bundled_maps_then_the_shared_ones_not_bundled(tmp_path):
    bundled, shared = tmp_path / "maps", tmp_path / "real"
    bundled.mkdir()
    for name in ("intel-lab", "ubremen-cartesium"):
        (bundled / f"{name}.yaml").write_text("image: x.png\n")
    assert bq.real_maps(bundled, shared) == [(bundled / "intel-lab.yaml", True),
                                             (bundled / "ubremen-cartesium.yaml", True)]
    shared.mkdir()
    for name in ("aces", "intel-lab", "freiburg-079"):
        (shared / f"{name}.yaml").write_text("image: x.pgm\n")
    (shared / "aces.pgm").write_text("")
    assert bq.real_maps(bundled, shared) == [(bundled / "intel-lab.yaml", True),
                                             (bundled / "ubremen-cartesium.yaml", True),
                                             (shared / "aces.yaml", False),
                                             (shared / "freiburg-079.yaml", False)]


def test_rows_that_fell_back_to_knowledge_off_are_listed():
    # a row whose knowledge engine failed was run with the geometry's fixed types: the subset's
    # result lists it (knowledge_off), so its numbers are not read as the rules'
    rows = [{"seed": 0, "knowledge": "knowledge: on"},
            {"seed": 4, "knowledge": "knowledge: off (engine failed: RuleError: x.lp: ...)"},
            {"map": "NLB", "knowledge": "knowledge: off (engine failed: ...)"}, {"seed": 5, "error": "e"}]
    assert bq.knowledge_off({"rows": rows}) == ["4", "NLB"]
    assert bq.knowledge_off({"skipped": "no data"}) == []


def test_route_agreement_counts_pairs_and_detours():
    """Three rooms in a row, A | B a door, B : C an open wall, and D below A behind a closed door;
    W* holds the same rooms (ids 10..13)."""
    truth = {"units": [{"id": i, "type": "room", "corners_px": c} for i, c in
                       enumerate([box(0, 0, 20, 20), box(20, 0, 40, 20), box(40, 0, 60, 20), box(0, 20, 20, 40)], 1)],
             "doors": [{"units": [1, 2], "center_px": [20, 10], "width_m": 0.8, "open": True},
                       {"units": [1, 4], "center_px": [10, 20], "width_m": 0.8, "open": False}],
             "open_boundaries": [[2, 3]]}
    units = [{"id": 9 + u["id"], "type": "room", "vertices_px": u["corners_px"]} for u in truth["units"]]
    matches = {10: 1, 11: 2, 12: 3, 13: 4}
    same = {"units": units, "doors": [{"id": 1, "units": [10, 11], "center_px": [20, 10]}],
            "passages": [{"id": 1, "units": [11, 12], "center_px": [40, 10]}]}
    r = bq.route_agreement(same, truth, matches, 0.05)
    assert (r["route_pairs"], r["route_found"], r["route_extra"]) == (3, 3, 0)   # A-B, A-C, B-C
    assert r["route_ratios"] == [1.0, 1.0, 1.0]
    no_passage = dict(same, passages=[])                                       # C cut off
    r = bq.route_agreement(no_passage, truth, matches, 0.05)
    assert (r["route_pairs"], r["route_found"], r["route_extra"]) == (3, 1, 0)
    into_d = dict(same, doors=same["doors"] + [{"id": 2, "units": [10, 13], "center_px": [10, 20]}])
    r = bq.route_agreement(into_d, truth, matches, 0.05)
    assert (r["route_pairs"], r["route_found"], r["route_extra"]) == (3, 3, 3)   # D reached: 3 extra pairs
    detour = dict(same, doors=[{"id": 1, "units": [10, 11], "center_px": [20, 19]}])   # the door at a corner
    r = bq.route_agreement(detour, truth, matches, 0.05)
    assert r["route_ratios"][0] > 1.0 and r["route_found"] == 3


def test_an_l_shaped_room_is_one_room_of_the_synthetic_truth():
    """rooms.png is scored against rooms: the generator's L-shaped room, two units with no wall
    between them, is one room; a prediction of the whole L is right, and one that cuts it in
    two finds only the larger part of it."""
    import numpy as np
    from semmap_pp.evaluate import protocol_scores
    units = np.zeros((50, 50), np.int64)   # rooms of more than 200 cells (the protocol's)
    units[0:50, 0:20] = 1                # the L's long arm ...
    units[30:50, 20:50] = 2              # ... and its foot
    units[0:25, 25:50] = 3               # another room
    rooms = bq.room_truth(units, [[1, 2]])
    assert set(np.unique(rooms).tolist()) == {0, 1, 3}
    assert (rooms[units == 2] == 1).all() and (rooms[units == 3] == 3).all()
    whole = np.where(units == 2, 1, units)
    assert protocol_scores(rooms, whole).precision == 1.0
    assert protocol_scores(units, whole).precision < 1.0     # scored against the units it is not
    cut = protocol_scores(rooms, units)
    assert cut.precision == 1.0 and cut.recall < 1.0
