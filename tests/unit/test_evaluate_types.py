"""Per-cell room / corridor accuracy (semmap_pp.evaluate.types)."""

import math
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from semmap_pp.cells import UNIT_TYPES
from semmap_pp.errors import MapError
from semmap_pp.evaluate.io import read_ipa_types
from semmap_pp.evaluate.types import (TRUTH_CORRIDOR as C, TRUTH_DOORWAY as D,
                                      TRUTH_OUTSIDE as X, TRUTH_ROOM as R, TYPE_NONE,
                                      type_accuracy, type_map_from_labels)

DATA = Path(__file__).parents[1] / "data" / "ipa"
room, corr, hall, other = (UNIT_TYPES.index(t) for t in ("room", "corridor", "hall", "other"))
none = TYPE_NONE


def test_hand_computed_case():
    truth = np.array([[R, R, R, R, C, C, C, D, X]])
    pred = np.array([[room, hall, other, none, corr, corr, room, corr, room]])
    s = type_accuracy(pred, truth)
    # scored cells: the 7 room/corridor cells (doorway and outside left out)
    # room truth:     room ok, hall->room ok, other->room ok, none wrong  -> 3/4
    # corridor truth: corr ok, corr ok, room wrong                        -> 2/3
    assert s.n_cells == 7
    assert s.accuracy == pytest.approx(5 / 7)
    assert s.recall_room == pytest.approx(3 / 4)
    assert s.recall_corridor == pytest.approx(2 / 3)
    assert s.balanced_accuracy == pytest.approx((3 / 4 + 2 / 3) / 2)
    assert s.coverage == pytest.approx(6 / 7)             # one unassigned cell
    assert s.accuracy_covered == pytest.approx(5 / 6)
    assert s.confusion.tolist() == [[3, 0, 1], [1, 2, 0]]


def test_unassigned_prediction_scores_zero_with_zero_coverage():
    truth = np.array([[R, C, D]])
    s = type_accuracy(np.full((1, 3), none), truth)
    assert s.accuracy == 0.0 and s.coverage == 0.0
    assert math.isnan(s.accuracy_covered)
    assert s.confusion.tolist() == [[0, 0, 1], [0, 0, 1]]


def test_truth_without_corridors_gives_nan_corridor_recall():
    s = type_accuracy(np.array([[room, corr]]), np.array([[R, R]]))
    assert s.accuracy == 0.5 and math.isnan(s.recall_corridor)
    assert s.balanced_accuracy == 0.5          # NaN recall skipped, not averaged in


def test_nothing_scored_gives_nan():
    s = type_accuracy(np.array([[room]]), np.array([[D]]))
    assert s.n_cells == 0 and math.isnan(s.accuracy) and math.isnan(s.coverage)


@pytest.mark.parametrize("pred, truth", [
    (np.zeros((1, 2), int), np.zeros((1, 3), int)),   # shapes differ
    (np.array([[4]]), np.array([[R]])),               # no such unit type
    (np.array([[room]]), np.array([[7]])),            # no such truth code
])
def test_inconsistent_inputs_are_map_errors(pred, truth):
    with pytest.raises(MapError):
        type_accuracy(pred, truth)


def test_type_map_from_labels():
    labels = np.array([[0, 3, 3], [5, 9, 0]])
    out = type_map_from_labels(labels, {3: "corridor", 5: "other"})
    # 0 -> none, 3 -> corridor, 5 -> other, 9 has no type -> none
    assert out.tolist() == [[none, corr, corr], [other, none, none]]
    with pytest.raises(MapError, match="kitchen"):
        type_map_from_labels(labels, {3: "kitchen"})


def test_read_ipa_types_on_bundled_fr52_agrees_with_raw_pixels():
    path = DATA / "training_Fr52.png"
    raw = np.asarray(Image.open(path))
    truth = read_ipa_types(path)
    assert ((raw == 77) == (truth == R)).all()
    assert ((raw == 115) == (truth == C)).all()
    assert ((raw == 179) == (truth == D)).all()
    # An all-room prediction scores the room share of the room + corridor cells.
    n_room, n_corr = int((raw == 77).sum()), int((raw == 115).sum())
    s = type_accuracy(np.full(raw.shape, room), truth)
    assert s.accuracy == pytest.approx(n_room / (n_room + n_corr))
    assert s.recall_room == 1.0 and s.recall_corridor == 0.0


def test_read_ipa_types_rejects_other_grey_values(tmp_path):
    Image.fromarray(np.array([[77, 100]], dtype=np.uint8)).save(tmp_path / "t.png")
    with pytest.raises(MapError, match=r"t.png: unexpected grey values \[100\]"):
        read_ipa_types(tmp_path / "t.png")
