"""Per-cell room / corridor typing scored against the ipa place-type images.

Codes used here
---------------
Predicted type map (``pred_type_map``, integer array): the index of the type in
:data:`semmap_pp.cells.UNIT_TYPES` (0 room, 1 corridor, 2 hall, 3 other), or ``TYPE_NONE`` (-1)
for a cell that no unit covers.

Truth (``truth``, integer array, see :func:`semmap_pp.evaluate.io.read_ipa_types`):
``TRUTH_ROOM`` (0), ``TRUTH_CORRIDOR`` (1), ``TRUTH_DOORWAY`` (2), ``TRUTH_OUTSIDE`` (-1).
Room and corridor share their code with ``UNIT_TYPES`` so that a prediction and a truth agree
when their codes are equal.

The score is two-class (room vs corridor): hall and other are scored as room, because the ipa
truth knows only rooms, corridors and doorways, and a hall or an "other" space is a room-like
place in that taxonomy. Doorway and outside cells are left out. A truth cell that the prediction
leaves unassigned (``TYPE_NONE``) counts as wrong; ``coverage`` says how many were assigned.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import NamedTuple

import numpy as np

from semmap_pp.cells import UNIT_TYPES
from semmap_pp.errors import MapError

TYPE_NONE = -1
TYPE_ROOM = UNIT_TYPES.index("room")
TYPE_CORRIDOR = UNIT_TYPES.index("corridor")

TRUTH_OUTSIDE = -1
TRUTH_ROOM = TYPE_ROOM
TRUTH_CORRIDOR = TYPE_CORRIDOR
TRUTH_DOORWAY = 2

# Order of the confusion matrix axes.
TRUTH_CLASSES = ("room", "corridor")
PRED_CLASSES = ("room", "corridor", "none")


class TypeScore(NamedTuple):
    """Result of :func:`type_accuracy`.

    Attributes
    ----------
    accuracy : float
        Correct cells / truth room-or-corridor cells (unassigned cells are wrong).
    recall_room, recall_corridor : float
        Correct cells of that truth class / cells of that truth class.
    balanced_accuracy : float
        Mean of the two recalls (NaN recalls are skipped).
    coverage : float
        Assigned cells / truth room-or-corridor cells.
    accuracy_covered : float
        Correct cells / assigned truth room-or-corridor cells.
    confusion : np.ndarray of int64, shape (2, 3)
        Rows: truth room, corridor. Columns: predicted room (incl. hall, other), corridor, none.
    n_cells : int
        Truth room-or-corridor cells scored.
    """

    accuracy: float
    recall_room: float
    recall_corridor: float
    balanced_accuracy: float
    coverage: float
    accuracy_covered: float
    confusion: np.ndarray
    n_cells: int


def _ratio(num: float, den: float) -> float:
    return float(num) / float(den) if den else float("nan")


def type_accuracy(pred_type_map: np.ndarray, truth: np.ndarray) -> TypeScore:
    """Two-class (room / corridor) per-cell accuracy of a predicted type map.

    Parameters
    ----------
    pred_type_map : np.ndarray of int, shape (H, W)
        ``UNIT_TYPES`` index per cell, ``TYPE_NONE`` (-1) where no unit is.
    truth : np.ndarray of int, shape (H, W)
        ``TRUTH_*`` codes (see the module docstring).

    Returns
    -------
    TypeScore

    Raises
    ------
    MapError
        When the shapes differ or a code is out of range.

    Examples
    --------
    Truth: 3 room cells, 2 corridor cells, 1 doorway (ignored). Prediction: hall (counts as room),
    room, none | corridor, room | anything.

    >>> import numpy as np
    >>> truth = np.array([[0, 0, 0, 1, 1, 2]])
    >>> pred = np.array([[2, 0, -1, 1, 0, 1]])
    >>> s = type_accuracy(pred, truth)
    >>> s.accuracy, s.recall_room, s.recall_corridor, s.coverage   # 3/5, 2/3, 1/2, 4/5
    (0.6, 0.6666666666666666, 0.5, 0.8)
    >>> s.confusion.tolist()
    [[2, 0, 1], [1, 1, 0]]
    """
    pred = np.asarray(pred_type_map)
    truth = np.asarray(truth)
    if pred.shape != truth.shape:
        raise MapError(None, f"type map has shape {pred.shape} but the truth has {truth.shape}")
    if pred.size and (pred.min() < TYPE_NONE or pred.max() >= len(UNIT_TYPES)):
        raise MapError(None, f"type map codes must lie in [{TYPE_NONE}, {len(UNIT_TYPES) - 1}]")
    valid_truth = (TRUTH_OUTSIDE, TRUTH_ROOM, TRUTH_CORRIDOR, TRUTH_DOORWAY)
    if truth.size and not np.isin(truth, valid_truth).all():
        raise MapError(None, f"truth codes must be among {sorted(valid_truth)}")

    scored = (truth == TRUTH_ROOM) | (truth == TRUTH_CORRIDOR)
    t = truth[scored]
    p = pred[scored]
    # Collapse the prediction to the columns room / corridor / none.
    col = np.where(p == TYPE_NONE, 2, np.where(p == TYPE_CORRIDOR, 1, 0))
    row = np.where(t == TRUTH_CORRIDOR, 1, 0)
    confusion = np.zeros((2, 3), dtype=np.int64)
    np.add.at(confusion, (row, col), 1)

    n = int(scored.sum())
    correct = int(confusion[0, 0] + confusion[1, 1])
    assigned = n - int(confusion[:, 2].sum())
    recall_room = _ratio(confusion[0, 0], confusion[0].sum())
    recall_corridor = _ratio(confusion[1, 1], confusion[1].sum())
    recalls = [r for r in (recall_room, recall_corridor) if not np.isnan(r)]
    return TypeScore(
        accuracy=_ratio(correct, n),
        recall_room=recall_room,
        recall_corridor=recall_corridor,
        balanced_accuracy=float(np.mean(recalls)) if recalls else float("nan"),
        coverage=_ratio(assigned, n),
        accuracy_covered=_ratio(correct, assigned),
        confusion=confusion,
        n_cells=n,
    )


def type_map_from_labels(labels: np.ndarray, unit_types: Mapping[int, str]) -> np.ndarray:
    """Per-cell type map from a label image and the type of each unit id.

    Parameters
    ----------
    labels : np.ndarray of int, shape (H, W)
        Unit id per cell, 0 = none (``labels.png``).
    unit_types : mapping of int to str
        Type name (one of ``UNIT_TYPES``) of each unit id, e.g. from ``world.json``.

    Returns
    -------
    np.ndarray of int8, shape (H, W)
        ``UNIT_TYPES`` index per cell; ``TYPE_NONE`` for label 0 and for ids with no type given.

    Raises
    ------
    MapError
        When a type name is not one of ``UNIT_TYPES``.

    Examples
    --------
    >>> import numpy as np
    >>> type_map_from_labels(np.array([[0, 1, 2, 7]]), {1: "corridor", 2: "hall"}).tolist()
    [[-1, 1, 2, -1]]
    """
    labels = np.asarray(labels)
    ids = np.unique(labels)
    lut_ids = ids[ids > 0]
    codes = np.full(lut_ids.shape, TYPE_NONE, dtype=np.int8)
    for i, uid in enumerate(lut_ids.tolist()):
        name = unit_types.get(uid)
        if name is None:
            continue
        if name not in UNIT_TYPES:
            raise MapError(None, f"unit {uid} has type {name!r}, not one of {list(UNIT_TYPES)}")
        codes[i] = UNIT_TYPES.index(name)
    out = np.full(labels.shape, TYPE_NONE, dtype=np.int8)
    if lut_ids.size:
        pos = np.searchsorted(lut_ids, labels)
        pos = np.clip(pos, 0, lut_ids.size - 1)
        hit = (labels > 0) & (lut_ids[pos] == labels)
        out[hit] = codes[pos[hit]]
    return out
