"""Room-segmentation scores: the ipa / ROSE2 precision and recall, and mean IoU.

Notation: ``G_u`` are the ground-truth rooms, ``S_v`` the predicted segments (as evaluated, see
``restrict_to_gt``), ``o(v, u) = |S_v ∩ G_u|`` their overlap in cells.

* precision ("micro", the published figure) = mean over v of  max_u o(v, u) / |S_v|
* recall    ("micro", the published figure) = mean over u of  max_v o(v, u) / |G_u|
* precision_macro = Σ_v max_u o(v, u) / Σ_v |S_v|    (area-weighted)
* recall_macro    = Σ_u max_v o(v, u) / Σ_u |G_u|    (area-weighted)
* IoU(v, u) = o / (|S_v| + |G_u| − o);
  ``iou`` (default) = Σ over a one-to-one assignment (Hungarian, maximising total IoU) / #rooms,
  ``iou_best`` = mean over u of max_v IoU(v, u) (a segment may serve several rooms).

"micro" and "macro" follow the naming of ipa_room_segmentation's evaluation code, which ROSE2
reports; it is the reverse of the usual machine-learning usage. See docs/evaluation.md.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from scipy.optimize import linear_sum_assignment

from semmap_pp.errors import MapError
from semmap_pp.evaluate.io import IPA_MIN_REGION_CELLS, ROSE2_MIN_ROOM_CELLS


class OverlapTable(NamedTuple):
    """Overlaps between kept predicted segments (rows) and kept ground-truth rooms (columns)."""

    overlap: np.ndarray      # int64, shape (n_segments, n_rooms)
    segment_sizes: np.ndarray  # int64, shape (n_segments,), |S_v| as evaluated
    room_sizes: np.ndarray   # int64, shape (n_rooms,)
    segment_ids: np.ndarray  # label value of each row
    room_ids: np.ndarray     # label value of each column


class SegmentationScore(NamedTuple):
    """Result of :func:`segmentation_scores` (NaN where a mean is over an empty set)."""

    precision: float
    recall: float
    precision_macro: float
    recall_macro: float
    iou: float
    iou_best: float
    n_rooms: int
    n_segments: int


def _kept_ids(labels: np.ndarray, min_cells: int) -> tuple[np.ndarray, np.ndarray]:
    ids, counts = np.unique(labels[labels > 0], return_counts=True)
    keep = counts > min_cells
    return ids[keep], counts[keep].astype(np.int64)


def overlap_table(gt_labels: np.ndarray, pred_labels: np.ndarray, *,
                  restrict_to_gt: bool = True,
                  min_room_cells: int = IPA_MIN_REGION_CELLS,
                  min_segment_cells: int = IPA_MIN_REGION_CELLS) -> OverlapTable:
    """Overlap counts between predicted segments and ground-truth rooms.

    Parameters
    ----------
    gt_labels, pred_labels : np.ndarray of int, shape (H, W)
        Room / segment id per cell, 0 = none.
    restrict_to_gt : bool
        True (default): only cells inside a kept ground-truth room are evaluated, so each
        segment is cut to ``S_v ∩ (∪ G_u)`` before its size is taken; predicted cells on walls,
        door lines or outside the rooms play no part. False: the published protocol, segments are
        taken whole, so their cells outside every room enlarge ``|S_v|`` (lowering precision)
        but never add to an overlap.
    min_room_cells, min_segment_cells : int
        Rooms / segments of at most this many cells are dropped (the benchmark's 100). The
        segment size is taken after the cut of ``restrict_to_gt``.

    Returns
    -------
    OverlapTable

    Examples
    --------
    >>> import numpy as np
    >>> gt = np.array([[1, 1, 0, 2]])
    >>> pred = np.array([[5, 5, 5, 5]])
    >>> t = overlap_table(gt, pred, min_room_cells=0, min_segment_cells=0)
    >>> t.overlap.tolist(), t.segment_sizes.tolist()      # the cut drops the cell on gt 0
    ([[2, 1]], [3])
    >>> overlap_table(gt, pred, restrict_to_gt=False, min_room_cells=0,
    ...               min_segment_cells=0).segment_sizes.tolist()
    [4]
    """
    gt = np.asarray(gt_labels)
    pred = np.asarray(pred_labels)
    if gt.shape != pred.shape:
        raise MapError(None, f"segmentation has shape {pred.shape} but the ground truth has "
                             f"{gt.shape}")
    for name, arr in (("ground truth", gt), ("segmentation", pred)):
        if not np.issubdtype(arr.dtype, np.integer):
            raise MapError(None, f"{name} labels must be integers, got {arr.dtype}")
    room_ids, room_sizes = _kept_ids(gt, min_room_cells)
    in_room = np.isin(gt, room_ids)
    if restrict_to_gt:
        pred = np.where(in_room, pred, 0)
    seg_ids, seg_sizes = _kept_ids(pred, min_segment_cells)

    both = in_room & np.isin(pred, seg_ids)
    n_seg, n_room = seg_ids.size, room_ids.size
    if n_seg and n_room and both.any():
        v = np.searchsorted(seg_ids, pred[both])
        u = np.searchsorted(room_ids, gt[both])
        overlap = np.bincount(v * n_room + u, minlength=n_seg * n_room).reshape(n_seg, n_room)
    else:
        overlap = np.zeros((n_seg, n_room), dtype=np.int64)
    return OverlapTable(overlap.astype(np.int64), seg_sizes, room_sizes, seg_ids, room_ids)


def _mean(values: np.ndarray) -> float:
    return float(values.mean()) if values.size else float("nan")


def _ratio(num: float, den: float) -> float:
    return float(num) / float(den) if den else float("nan")


def iou_matrix(table: OverlapTable) -> np.ndarray:
    """IoU of every (segment, room) pair of an :class:`OverlapTable`, shape (n_seg, n_rooms)."""
    o = table.overlap.astype(np.float64)
    union = table.segment_sizes[:, None] + table.room_sizes[None, :] - o
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(union > 0, o / np.where(union > 0, union, 1), 0.0)


def scores_from_table(table: OverlapTable) -> SegmentationScore:
    """All segmentation scores of an overlap table (see the module docstring for formulas)."""
    o = table.overlap
    n_seg, n_room = o.shape
    best_for_seg = o.max(axis=1) if n_room else np.zeros(n_seg, dtype=np.int64)
    best_for_room = o.max(axis=0) if n_seg else np.zeros(n_room, dtype=np.int64)
    iou = iou_matrix(table)
    if n_room == 0:
        iou_h = iou_b = float("nan")
    elif n_seg == 0:
        iou_h = iou_b = 0.0
    else:
        rows, cols = linear_sum_assignment(iou, maximize=True)
        iou_h = float(iou[rows, cols].sum()) / n_room   # unassigned rooms score 0
        iou_b = float(iou.max(axis=0).mean())
    return SegmentationScore(
        precision=_mean(best_for_seg / np.maximum(table.segment_sizes, 1)),
        recall=_mean(best_for_room / np.maximum(table.room_sizes, 1)),
        precision_macro=_ratio(best_for_seg.sum(), table.segment_sizes.sum()),
        recall_macro=_ratio(best_for_room.sum(), table.room_sizes.sum()),
        iou=iou_h,
        iou_best=iou_b,
        n_rooms=int(n_room),
        n_segments=int(n_seg),
    )


def segmentation_scores(gt_labels: np.ndarray, pred_labels: np.ndarray, *,
                        restrict_to_gt: bool = True,
                        min_room_cells: int = IPA_MIN_REGION_CELLS,
                        min_segment_cells: int = IPA_MIN_REGION_CELLS) -> SegmentationScore:
    """Precision, recall (ipa "micro" and "macro") and mean IoU of a room segmentation.

    Parameters
    ----------
    gt_labels : np.ndarray of int, shape (H, W)
        Ground-truth room id per cell, 0 = not a room (e.g. :func:`~semmap_pp.evaluate.io.read_ipa_gt`).
    pred_labels : np.ndarray of int, shape (H, W)
        Predicted segment id per cell, 0 = none (``labels.png``).
    restrict_to_gt, min_room_cells, min_segment_cells
        See :func:`overlap_table`. For the published protocol use ``restrict_to_gt=False``.

    Returns
    -------
    SegmentationScore
        ``precision``/``recall`` are the published ("micro") figures, ``iou`` the Hungarian
        one-to-one mean IoU. Precision is NaN without segments, recall and IoU are NaN without
        rooms; without segments recall and IoU are 0.

    Examples
    --------
    Two rooms of 4 cells; one segment covers all of room 1 and half of room 2, a second segment
    the other half of room 2.

    >>> import numpy as np
    >>> gt   = np.array([[1, 1, 2, 2], [1, 1, 2, 2]])
    >>> pred = np.array([[7, 7, 7, 8], [7, 7, 7, 8]])
    >>> s = segmentation_scores(gt, pred, min_room_cells=0, min_segment_cells=0)
    >>> s.precision, s.recall          # (4/6 + 2/2) / 2,  (4/4 + 2/4) / 2
    (0.8333333333333333, 0.75)
    >>> s.precision_macro, s.recall_macro   # (4 + 2) / 8,  (4 + 2) / 8
    (0.75, 0.75)
    >>> s.iou, s.iou_best              # (4/6 + 2/4) / 2 both ways here
    (0.5833333333333333, 0.5833333333333333)
    """
    table = overlap_table(gt_labels, pred_labels, restrict_to_gt=restrict_to_gt,
                          min_room_cells=min_room_cells, min_segment_cells=min_segment_cells)
    return scores_from_table(table)


def protocol_scores(gt_labels: np.ndarray, pred_labels: np.ndarray, fmt: str = "rose2") -> SegmentationScore:
    """The published figures of a segmentation (segments taken whole, not cut to the rooms):
    ``fmt`` "rose2" (rooms of more than 200 cells, every segment) or "ipa" (rooms and segments of
    more than 100 cells, Bormann et al.'s benchmark).

    >>> gt = np.zeros((20, 30), int); gt[:, :15] = 1; gt[:, 15:] = 2
    >>> pred = np.ones((20, 30), int); pred[:, 25:] = 3          # room 2 cut: 10 + 5 columns
    >>> s = protocol_scores(gt, pred)
    >>> round(s.precision, 3), round(s.recall, 3)     # (300/500 + 100/100) / 2, (300/300 + 200/300) / 2
    (0.8, 0.833)
    """
    if fmt == "ipa":
        return segmentation_scores(gt_labels, pred_labels, restrict_to_gt=False)
    return segmentation_scores(gt_labels, pred_labels, restrict_to_gt=False,
                               min_room_cells=ROSE2_MIN_ROOM_CELLS, min_segment_cells=0)
