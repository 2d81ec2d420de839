"""Scoring with the truth's L-shaped spaces cut either way (semmap_pp.evaluate.lshape)."""

import copy
import math

import numpy as np
import pytest

from semmap_pp.errors import MapError
from semmap_pp.evaluate import polygon_mask, recut_l, score_world, score_world_either_l
from semmap_pp.evaluate.lshape import other_cut

RES = 0.05
SHAPE = (75, 75)


def box(x0, y0, x1, y1):
    return [[x0, y0], [x1, y0], [x1, y1], [x0, y1]]


# An L of a (40 x 20 bar) and b (30 x 30 block under its left end), a corridor c below b, a room d
# right of a and a room e above a. Cut the other way the L is a' = the bar's 10 px right end and
# b' = the 30 x 50 column on the left.
A, B, C, D, E = box(10, 10, 50, 30), box(10, 30, 40, 60), box(10, 60, 50, 70), box(50, 10, 70, 30), \
    box(10, 0, 50, 10)
A2, B2 = box(40, 10, 50, 30), box(10, 10, 40, 60)


def truth():
    return {"units": [{"id": 1, "type": "room", "corners_px": A}, {"id": 2, "type": "other", "corners_px": B},
                      {"id": 3, "type": "corridor", "corners_px": C}, {"id": 4, "type": "room", "corners_px": D},
                      {"id": 5, "type": "room", "corners_px": E}],
            "doors": [{"units": [2, 3], "center_px": [25, 60], "width_m": 0.9},
                      {"units": [1, 4], "center_px": [50, 20], "width_m": 0.9},
                      {"units": [1, 5], "center_px": [20, 10], "width_m": 0.9}],
            "exits": [{"unit": 1, "center_px": [15, 10], "width_m": 1.0}],
            "adjacency": [[1, 2], [1, 4], [1, 5], [2, 3]], "open_boundaries": [[1, 2]],
            "l_shapes": [[1, 2]]}


def prediction(a, b):
    """The truth's other units plus ``a`` and ``b`` as the L's two pieces, with one door per true
    door at the same place, joined to whichever piece holds the door on its boundary."""
    units = [{"id": 11, "type": "room", "vertices_px": a}, {"id": 12, "type": "other", "vertices_px": b},
             {"id": 13, "type": "corridor", "vertices_px": C}, {"id": 14, "type": "room", "vertices_px": D},
             {"id": 15, "type": "room", "vertices_px": E}]
    other_cut_ = a == A2
    doors = [{"units": [12, 13], "center_px": [25, 60], "width_m": 0.9},
             {"units": [11, 14], "center_px": [50, 20], "width_m": 0.9},
             {"units": [12 if other_cut_ else 11, 15], "center_px": [20, 10], "width_m": 0.9}]
    return {"units": units, "doors": doors, "adjacency": []}


def same_corners(p, q, tol=1e-6):
    return np.allclose(sorted(map(tuple, np.round(p, 6))), sorted(map(tuple, np.round(q, 6))), atol=tol)


def test_other_cut_of_an_axis_aligned_l():
    pa, pb = other_cut(A, B)
    assert same_corners(pa, A2) and same_corners(pb, B2)
    # and back: cutting the other cut the other way gives the truth's cut
    qa, qb = other_cut(pa, pb)
    assert same_corners(qa, A) and same_corners(qb, B)


@pytest.mark.parametrize("deg", [0.0, 30.0, 90.0, 143.2])
def test_other_cut_turns_with_the_floor(deg):
    t = math.radians(deg)
    rot = np.array([[math.cos(t), -math.sin(t)], [math.sin(t), math.cos(t)]])
    turn = lambda c: ((np.asarray(c, float) - 37.0) @ rot.T + 37.0).tolist()  # noqa: E731
    pa, pb = other_cut(turn(A), turn(B))
    assert np.allclose(sorted(map(tuple, pa)), sorted(map(tuple, turn(A2))), atol=2e-3)
    assert np.allclose(sorted(map(tuple, pb)), sorted(map(tuple, turn(B2))), atol=2e-3)


@pytest.mark.parametrize("a, b", [
    (box(0, 0, 10, 10), box(10, 0, 20, 10)),       # side by side: one rectangle, no L
    (box(0, 0, 10, 10), box(30, 30, 40, 40)),      # apart
    (box(0, 0, 20, 10), box(5, 10, 15, 20)),       # a T: the block below the bar's middle
    ([[0, 0], [0, 0], [5, 5], [0, 5]], box(0, 5, 5, 10)),  # a degenerate first edge
])
def test_pairs_that_are_no_l_have_no_other_cut(a, b):
    assert other_cut(a, b) is None


def test_recut_moves_doors_exits_and_adjacency_with_the_geometry():
    t = truth()
    r = recut_l(t, [1, 2])
    units = {u["id"]: u for u in r["units"]}
    assert same_corners(units[1]["corners_px"], A2) and same_corners(units[2]["corners_px"], B2)
    assert units[1]["type"] == "room" and units[2]["type"] == "other"
    assert [d["units"] for d in r["doors"]] == [[2, 3], [1, 4], [2, 5]]   # a-e's door lies on b'
    assert r["exits"] == [{"unit": 2, "center_px": [15, 10], "width_m": 1.0}]
    assert {frozenset(p) for p in r["adjacency"]} == {frozenset(p) for p in
                                                       ([1, 2], [1, 4], [1, 5], [2, 5], [2, 3])}
    assert r["open_boundaries"] == [[1, 2]]
    assert t == truth()                                        # the input is left alone
    assert recut_l(t, [3, 4]) is None and recut_l(t, [1, 99]) is None


def test_a_prediction_cut_the_other_way_scores_full_either_way_but_not_strictly():
    t = truth()
    s, strict, recut = score_world_either_l(prediction(A2, B2), t, SHAPE, RES)
    assert recut == [[1, 2]]
    assert s.unit_f1 == 1.0 and s.door_recall == 1.0 and s.door_precision == 1.0
    plain = score_world(prediction(A2, B2), t, SHAPE, RES)
    assert (strict.unit_f1, strict.door_recall, strict.matches) == (plain.unit_f1, plain.door_recall, plain.matches)
    assert strict.unit_f1 == pytest.approx(2 * 4 / 10)      # a' overlaps a at IoU 0.25 only
    assert strict.door_recall == pytest.approx(1 / 3)


def test_a_prediction_with_the_truths_cut_keeps_the_strict_score():
    t = truth()
    s, strict, recut = score_world_either_l(prediction(A, B), t, SHAPE, RES)
    assert recut == [] and s is strict and s.unit_f1 == 1.0 and s.door_recall == 1.0


def test_malformed_l_shapes_name_the_truth():
    t = truth()
    t["l_shapes"] = [[1]]
    with pytest.raises(MapError, match="l_shapes"):
        score_world_either_l(prediction(A, B), t, SHAPE, RES, truth_source="floor/truth.json")


@pytest.mark.parametrize("seed", [4, 24])
def test_the_generators_ls_recut_cover_the_same_cells(seed):
    from semmap_pp.synth import generate_floor
    floor = generate_floor(seed)
    assert floor.truth["l_shapes"]
    units = {u["id"]: u for u in floor.truth["units"]}
    shape = floor.classes.shape
    for a, b in floor.truth["l_shapes"]:
        r = recut_l(floor.truth, [a, b])
        assert r is not None
        new = {u["id"]: u for u in r["units"]}
        old_a, old_b = (polygon_mask(units[k]["corners_px"], shape) for k in (a, b))
        new_a, new_b = (polygon_mask(new[k]["corners_px"], shape) for k in (a, b))
        assert ((old_a | old_b) == (new_a | new_b)).sum() >= shape[0] * shape[1] - 50
        assert (new_a & new_b).sum() <= 0.05 * (new_a | new_b).sum()
        assert not (same_corners(new[a]["corners_px"], units[a]["corners_px"], tol=1.0))
        back = recut_l(r, [a, b])
        for k in (a, b):
            assert np.allclose(sorted(map(tuple, {u["id"]: u for u in back["units"]}[k]["corners_px"])),
                               sorted(map(tuple, units[k]["corners_px"])), atol=0.01)
        assert copy.deepcopy(floor.truth) == floor.truth
