"""Scores against the synthetic truth (semmap_pp.evaluate.truth)."""

import copy
import math

import pytest

from semmap_pp.errors import MapError
from semmap_pp.evaluate.truth import match_units, polygon_mask, score_world

RES = 0.05          # metres per cell; 1 m = 20 cells
SHAPE = (20, 30)


def rect(x0, y0, x1, y1):
    """Corners of the axis-aligned box covering the cells of columns x0..x1 and rows y0..y1.

    In the continuous pixel frame cell [r, c] spans [c, c + 1) x [r, r + 1), so the box's corners
    are (x0, y0) and (x1 + 1, y1 + 1).
    """
    return [[x0, y0], [x1 + 1, y0], [x1 + 1, y1 + 1], [x0, y1 + 1]]


# ---------------------------------------------------------------------------- polygon_mask
def test_rectangle_covers_the_cells_inside_either_orientation():
    m = polygon_mask([[1, 1], [5, 1], [5, 4], [1, 4]], (6, 7))
    assert m.sum() == 4 * 3 and m[1:4, 1:5].all()          # columns 1..4, rows 1..3
    assert (polygon_mask(rect(1, 1, 4, 3)[::-1], (6, 7)) == m).all()


def test_rotated_square_counts_lattice_points():
    # A square rotated by 45 deg with corners on cell centres, centred on cell (10, 10):
    # cells with |c - 10| + |r - 10| <= 5, i.e. 2n^2 + 2n + 1 = 61 for n = 5 (the 20 cells whose
    # centres lie on the edges count).
    diamond = [[10.5, 5.5], [15.5, 10.5], [10.5, 15.5], [5.5, 10.5]]
    assert polygon_mask(diamond, (21, 21)).sum() == 61
    # In a frame whose integer coordinates are cell centres the same cells need integer corners.
    shifted = [[x - 0.5, y - 0.5] for x, y in diamond]
    assert (polygon_mask(shifted, (21, 21), centre_offset=0.0)
            == polygon_mask(diamond, (21, 21))).all()


def test_non_convex_polygon():
    # L shape: rows 0..2 x columns 0..4 (15 cells) plus rows 3..4 x columns 0..2 (6 cells)
    ell = [[0, 0], [5, 0], [5, 3], [3, 3], [3, 5], [0, 5]]
    m = polygon_mask(ell, (6, 6))
    assert m.sum() == 21
    assert m[2, 4] and m[4, 2] and not m[3, 3]


def test_polygon_is_clipped_to_the_grid():
    assert polygon_mask(rect(-5, -5, 1, 1), (4, 4)).sum() == 4   # cells (0..1, 0..1)
    assert polygon_mask(rect(10, 10, 12, 12), (4, 4)).sum() == 0


# ---------------------------------------------------------------------------- matching
def test_match_units_pairs_and_iou_values():
    a = polygon_mask(rect(0, 0, 9, 0), (1, 20))      # 10 cells
    b = polygon_mask(rect(0, 0, 7, 0), (1, 20))      # 8 cells inside a: IoU 0.8
    c = polygon_mask(rect(10, 0, 19, 0), (1, 20))
    pairs, iou = match_units([b, c], [a, c])
    assert pairs == [(0, 0), (1, 1)]
    assert iou[0, 0] == pytest.approx(0.8) and iou[0, 1] == 0.0


def test_matching_is_one_to_one_when_true_units_overlap():
    # Two overlapping true units a (10 cells) and a2 (9 cells, inside a), one prediction p = a.
    # IoU(p, a) = 1, IoU(p, a2) = 0.9: p matches a only, a2 stays unmatched.
    a = polygon_mask(rect(0, 0, 9, 0), (1, 12))
    a2 = polygon_mask(rect(1, 0, 9, 0), (1, 12))
    pairs, iou = match_units([a], [a2, a])
    assert pairs == [(0, 1)] and iou[0, 0] == pytest.approx(0.9)


def test_iou_threshold_is_inclusive():
    a = polygon_mask(rect(0, 0, 3, 0), (1, 8))       # 4 cells
    b = polygon_mask(rect(0, 0, 1, 0), (1, 8))       # 2 cells inside a: IoU 2/4 = 0.5
    assert match_units([b], [a])[0] == [(0, 0)]
    assert match_units([b], [a], iou_min=0.51)[0] == []


# ---------------------------------------------------------------------------- score_world
def truth_world():
    return {
        "units": [
            {"id": 1, "type": "room", "corners_px": rect(0, 0, 9, 4)},        # 50 cells
            {"id": 2, "type": "corridor", "corners_px": rect(0, 6, 9, 10)},   # 50 cells
            {"id": 3, "type": "room", "corners_px": rect(12, 0, 21, 4)},      # 50 cells
        ],
        "adjacency": [[1, 2], [1, 3]],
        "doors": [
            {"units": [1, 2], "center_px": [5, 5], "width_m": 0.9},
            {"units": [1, 3], "center_px": [11, 2], "width_m": 1.5},
        ],
    }


def as_prediction(truth, offset=100):
    """The truth re-written as a prediction, with ids shifted by ``offset``."""
    return {
        "units": [{"id": u["id"] + offset, "type": u["type"], "vertices_px": u["corners_px"]}
                  for u in truth["units"]],
        "adjacency": [[a + offset, b + offset] for a, b in truth["adjacency"]],
        "doors": [{"units": [a + offset for a in d["units"]], "center_px": d["center_px"],
                   "width_m": d["width_m"]} for d in truth["doors"]],
    }


def test_hand_computed_world():
    pred = {
        "units": [
            {"id": 10, "type": "room", "vertices_px": rect(0, 0, 9, 4)},    # = unit 1, IoU 1
            # columns 3..12 rows 6..10 (50 cells); overlap with unit 2 = columns 3..9 = 35
            # cells, union 65 -> IoU 35/65 = 0.54: matched, but typed room (truth: corridor)
            {"id": 11, "type": "room", "vertices_px": rect(3, 6, 12, 10)},
            # columns 16..25: overlap with unit 3 = 30, union 70 -> 0.43 < 0.5: unmatched
            {"id": 12, "type": "hall", "vertices_px": rect(16, 0, 25, 4)},
            {"id": 13, "type": "other", "vertices_px": rect(0, 14, 5, 18)},   # overlaps nothing
        ],
        "adjacency": [[10, 11], [10, 12], [11, 13]],
        "doors": [
            {"units": [11, 10], "center_px": [5, 24], "width_m": 0.8},   # 19 px = 0.95 m: ok
            {"units": [10, 11], "center_px": [5, 26], "width_m": 0.8},   # 21 px = 1.05 m: no
            {"units": [10, 12], "center_px": [11, 2], "width_m": 1.5},   # 12 is unmatched: no
        ],
    }
    s = score_world(pred, truth_world(), SHAPE, RES)
    assert s.matches == {10: 1, 11: 2}
    assert s.match_iou[11] == pytest.approx(35 / 65)
    assert s.unit_precision == pytest.approx(2 / 4)
    assert s.unit_recall == pytest.approx(2 / 3)
    assert s.unit_f1 == pytest.approx(2 * 2 / (4 + 3))          # 2PR/(P+R) = 2TP/(nP+nT)
    assert s.type_accuracy == pytest.approx(1 / 2)
    # adjacency: (10,11) -> (1,2) true; (10,12) and (11,13) have an unmatched end -> 1/3, 1/2
    assert s.adjacency_precision == pytest.approx(1 / 3)
    assert s.adjacency_recall == pytest.approx(1 / 2)
    # doors: only the first predicted door matches (the 1-2 door) -> 1/3, 1/2
    assert s.door_precision == pytest.approx(1 / 3)
    assert s.door_recall == pytest.approx(1 / 2)


def test_truth_as_prediction_scores_one():
    truth = truth_world()
    s = score_world(as_prediction(truth), truth, SHAPE, RES)
    assert s[:8] == (1.0,) * 8


def test_grid_and_resolution_default_to_the_truth_header():
    truth = dict(truth_world(), height=SHAPE[0], width=SHAPE[1], resolution=RES)
    pred = as_prediction(truth)
    pred["doors"][0]["center_px"] = [5 + 21, 5]     # 1.05 m at 0.05 m/cell: too far
    assert score_world(pred, truth).door_recall == pytest.approx(1 / 2)
    assert score_world(pred, truth, resolution=0.04).door_recall == 1.0   # 0.84 m: close enough
    with pytest.raises(MapError, match="missing 'height'"):
        score_world(pred, truth_world())


def test_door_tolerance_is_the_larger_of_width_and_one_metre():
    truth = truth_world()
    pred = as_prediction(truth)
    # The 1-3 door is 1.5 m wide: 1.4 m (28 px) away still matches, 1.6 m (32 px) does not.
    pred["doors"][1]["center_px"] = [11, 2 + 28]
    assert score_world(pred, truth, SHAPE, RES).door_recall == 1.0
    pred["doors"][1]["center_px"] = [11, 2 + 32]
    assert score_world(pred, truth, SHAPE, RES).door_recall == pytest.approx(1 / 2)
    # The 1-2 door is 0.9 m wide: the 1 m floor applies; 0.95 m matches, 1.05 m does not.
    pred = as_prediction(truth)
    pred["doors"][0]["center_px"] = [5 + 19, 5]
    assert score_world(pred, truth, SHAPE, RES).door_recall == 1.0
    pred["doors"][0]["center_px"] = [5 + 21, 5]
    assert score_world(pred, truth, SHAPE, RES).door_recall == pytest.approx(1 / 2)


def test_doors_match_one_to_one():
    truth = truth_world()
    pred = as_prediction(truth)
    pred["doors"].append(copy.deepcopy(pred["doors"][0]))   # the same door predicted twice
    s = score_world(pred, truth, SHAPE, RES)
    assert s.door_recall == 1.0 and s.door_precision == pytest.approx(2 / 3)
    assert s.door_matches.count(True) == 2 and s.door_matches[-1] in (True, False)
    pred = as_prediction(truth)
    pred["doors"][1]["center_px"] = [11, 2 + 32]                # the 1-3 door 1.6 m off: no match
    assert score_world(pred, truth, SHAPE, RES).door_matches == (True, False)


def test_door_matches_agree_with_door_precision_in_the_prediction_order():
    truth = truth_world()
    pred = as_prediction(truth)
    pred["doors"] = pred["doors"][::-1]
    pred["doors"][0]["center_px"] = [11, 2 + 32]                # now first: too far to match
    s = score_world(pred, truth, SHAPE, RES)
    assert s.door_matches == (False, True)
    assert s.door_precision == pytest.approx(sum(s.door_matches) / len(s.door_matches))


def test_empty_prediction():
    s = score_world({"units": []}, truth_world(), SHAPE, RES)
    assert math.isnan(s.unit_precision) and s.unit_recall == 0.0 and s.unit_f1 == 0.0
    assert math.isnan(s.type_accuracy) and math.isnan(s.adjacency_precision)
    assert s.adjacency_recall == 0.0 and s.door_recall == 0.0


@pytest.mark.parametrize("pred, message", [
    ({}, "pred.json: top level: missing 'units'"),
    ({"units": [{"id": 1}]}, "pred.json: unit 1: missing 'vertices_px'"),
    ({"units": [{"id": 1, "vertices_px": [[0, 0], [1, 1]]}]}, "must be >= 3"),
    ({"units": [], "adjacency": [[1, 2, 3]]}, "adjacency entries"),
    ({"units": [], "doors": [{"units": [1, 2]}]}, "door #0: missing 'center_px'"),
])
def test_malformed_prediction_is_a_map_error_naming_the_source(pred, message):
    with pytest.raises(MapError, match=message.replace("[", r"\[")):
        score_world(pred, truth_world(), SHAPE, RES, pred_source="pred.json")


def test_duplicate_unit_ids_are_rejected():
    pred = {"units": [{"id": 1, "vertices_px": rect(0, 0, 1, 1)},
                      {"id": 1, "vertices_px": rect(2, 2, 3, 3)}]}
    with pytest.raises(MapError, match="not unique"):
        score_world(pred, truth_world(), SHAPE, RES)
