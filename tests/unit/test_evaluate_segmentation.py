"""Room-segmentation scores (semmap_pp.evaluate.segmentation)."""

import math
from collections import deque
from pathlib import Path

import numpy as np
import pytest

from semmap_pp.errors import MapError
from semmap_pp.evaluate.io import ipa_gt_labels, read_ipa_gt
from semmap_pp.evaluate.segmentation import overlap_table, segmentation_scores

DATA = Path(__file__).parents[1] / "data" / "ipa"
ALL = dict(min_room_cells=0, min_segment_cells=0)   # no size filter, for tiny literal cases


# --------------------------------------------------------------------------------------------
# An independent implementation of the published protocol, written from the definition in
# /work/shared/data/README.md and ipa_room_segmentation's evaluation code, with Python sets and
# a breadth-first flood fill (no scipy, no numpy indexing tricks): ground-truth rooms are the
# 8-connected components of pixels > 250 with more than 100 pixels; segments are the pixel sets
# of each non-zero label with more than 100 pixels, taken whole; overlap = |S ∩ G|.
def published_scores(gt_grey, seg_labels):
    h, w = len(gt_grey), len(gt_grey[0])
    seen = set()
    rooms = []
    for y in range(h):
        for x in range(w):
            if gt_grey[y][x] > 250 and (y, x) not in seen:
                blob, queue = set(), deque([(y, x)])
                seen.add((y, x))
                while queue:
                    cy, cx = queue.popleft()
                    blob.add((cy, cx))
                    for dy in (-1, 0, 1):
                        for dx in (-1, 0, 1):
                            ny, nx = cy + dy, cx + dx
                            if (0 <= ny < h and 0 <= nx < w and (ny, nx) not in seen
                                    and gt_grey[ny][nx] > 250):
                                seen.add((ny, nx))
                                queue.append((ny, nx))
                if len(blob) > 100:
                    rooms.append(blob)
    by_label = {}
    for y in range(h):
        for x in range(w):
            if seg_labels[y][x] != 0:
                by_label.setdefault(seg_labels[y][x], set()).add((y, x))
    segs = [s for s in by_label.values() if len(s) > 100]
    ov = [[len(s & g) for g in rooms] for s in segs]
    p_micro = sum(max(row, default=0) / len(s) for row, s in zip(ov, segs)) / len(segs)
    r_micro = sum(max((ov[v][u] for v in range(len(segs))), default=0) / len(g)
                  for u, g in enumerate(rooms)) / len(rooms)
    p_macro = sum(max(row, default=0) for row in ov) / sum(len(s) for s in segs)
    r_macro = (sum(max((ov[v][u] for v in range(len(segs))), default=0)
                   for u in range(len(rooms))) / sum(len(g) for g in rooms))
    return p_micro, r_micro, p_macro, r_macro
# --------------------------------------------------------------------------------------------


def two_rooms():
    """GT image 20 x 31: room A = columns 0-14 (300 px), black wall column 15, room B = 16-30."""
    img = np.full((20, 31), 255, np.uint8)
    img[:, 15] = 0
    return img


def test_published_recall_on_a_hand_built_case():
    img = two_rooms()
    seg = np.zeros((20, 31), np.int32)
    seg[:, 0:20] = 1            # 400 px: all of A (300), the wall (20), 4 columns of B (80)
    seg[:, 20:31] = 2           # 220 px of B ...
    seg[0:5, 26:31] = 3         # ... minus a 25-px segment 3, which is <= 100 px and dropped
    # published (segments taken whole): seg 1 = 400, seg 2 = 195
    #   precision micro = (300/400 + 195/195) / 2 = 0.875
    #   recall micro    = (300/300 + max(80, 195)/300) / 2 = (1 + 0.65) / 2 = 0.825
    #   precision macro = (300 + 195) / (400 + 195) = 495/595
    #   recall macro    = (300 + 195) / 600 = 0.825
    gt = ipa_gt_labels(img)
    s = segmentation_scores(gt, seg, restrict_to_gt=False)
    assert (s.n_rooms, s.n_segments) == (2, 2)
    assert s.precision == pytest.approx(0.875)
    assert s.recall == pytest.approx(0.825)
    assert s.precision_macro == pytest.approx(495 / 595)
    assert s.recall_macro == pytest.approx(0.825)
    # The independent implementation of the published definition agrees.
    assert published_scores(img.tolist(), seg.tolist()) == pytest.approx(
        (s.precision, s.recall, s.precision_macro, s.recall_macro))
    # Restricted to GT room cells (default): seg 1 loses the 20 wall pixels -> 380 px.
    #   precision = (300/380 + 1) / 2; recall unchanged
    r = segmentation_scores(gt, seg)
    assert r.precision == pytest.approx((300 / 380 + 1) / 2)
    assert r.recall == pytest.approx(0.825)
    # IoU (restricted sizes): seg1-A = 300/380, seg2-B = 195/300, seg1-B = 80/(380+300-80)
    #   Hungarian: seg1-A + seg2-B; best per room: A 300/380, B max(0.65, 80/600) = 0.65
    assert r.iou == pytest.approx((300 / 380 + 0.65) / 2)
    assert r.iou_best == pytest.approx((300 / 380 + 0.65) / 2)


def test_matches_independent_published_implementation_on_random_layouts():
    # Random floor plans: a grid of rooms with random wall positions, random door gaps left
    # closed, and a random blocky segmentation; published protocol on both sides.
    rng = np.random.default_rng(7)
    for _ in range(4):
        h, w = 36, 44
        img = np.full((h, w), 255, np.uint8)
        for c in rng.choice(np.arange(6, w - 6), size=2, replace=False):
            img[:, c] = 0
        img[int(rng.integers(8, h - 8)), :] = 0
        img[0:2, 0:3] = 0 if rng.random() < 0.5 else 255
        seg = np.zeros((h, w), np.int32)
        bounds_r = np.sort(rng.choice(np.arange(4, h - 4), size=2, replace=False))
        bounds_c = np.sort(rng.choice(np.arange(4, w - 4), size=3, replace=False))
        rr = np.searchsorted(bounds_r, np.arange(h), side="right")
        cc = np.searchsorted(bounds_c, np.arange(w), side="right")
        seg[:] = 1 + rr[:, None] * 10 + cc[None, :]
        seg[rng.random((h, w)) < 0.05] = 0          # some unlabelled cells
        s = segmentation_scores(ipa_gt_labels(img), seg, restrict_to_gt=False)
        ref = published_scores(img.tolist(), seg.tolist())
        assert (s.precision, s.recall, s.precision_macro, s.recall_macro) == pytest.approx(ref)


def test_under_segmentation_hungarian_iou_is_stricter_than_best_match():
    gt = ipa_gt_labels(two_rooms())
    seg = np.where(gt > 0, 4, 0)                 # one segment covering both rooms (600 px)
    s = segmentation_scores(gt, seg)
    # precision = 300/600; recall = (300/300 + 300/300)/2 = 1
    # IoU of the segment with either room = 300/600; Hungarian gives it to one room only.
    assert s.precision == pytest.approx(0.5) and s.recall == pytest.approx(1.0)
    assert s.iou_best == pytest.approx(0.5)
    assert s.iou == pytest.approx((0.5 + 0.0) / 2)


def test_over_segmentation_keeps_precision_and_halves_recall():
    gt = ipa_gt_labels(two_rooms())
    seg = np.zeros_like(gt)
    seg[:10, 0:15], seg[10:, 0:15] = 1, 2        # room A split into two 150-px halves
    seg[:10, 16:31], seg[10:, 16:31] = 3, 4      # room B too
    s = segmentation_scores(gt, seg)
    # every segment lies in one room -> precision 1; best overlap per room 150/300 -> recall 0.5
    assert s.precision == 1.0 and s.recall == 0.5
    assert s.iou == pytest.approx(0.5)           # 150 / 300 for each room


def test_perfect_prediction_scores_one():
    gt = np.array([[1, 1, 0, 2], [1, 1, 0, 2]])
    s = segmentation_scores(gt, gt * 7, **ALL)   # ids need not be equal, only the partition
    assert s[:6] == (1.0, 1.0, 1.0, 1.0, 1.0, 1.0)


def test_empty_prediction():
    gt = np.array([[1, 1, 2]])
    s = segmentation_scores(gt, np.zeros_like(gt), **ALL)
    assert math.isnan(s.precision) and math.isnan(s.precision_macro)   # mean over no segment
    assert s.recall == 0.0 and s.recall_macro == 0.0 and s.iou == 0.0 and s.iou_best == 0.0
    assert s.n_segments == 0


def test_empty_ground_truth():
    pred = np.array([[1, 1, 2]])
    gt = np.zeros_like(pred)
    published = segmentation_scores(gt, pred, restrict_to_gt=False, **ALL)
    assert published.precision == 0.0           # segments exist but overlap no room
    assert math.isnan(published.recall) and math.isnan(published.iou)
    restricted = segmentation_scores(gt, pred, **ALL)
    assert restricted.n_segments == 0 and math.isnan(restricted.precision)


def test_size_filters_are_strictly_greater_than():
    gt = np.zeros((1, 7), np.int32)
    gt[0, :3], gt[0, 3:] = 1, 2                  # rooms of 3 and 4 cells
    t = overlap_table(gt, gt, min_room_cells=3, min_segment_cells=3)
    assert t.room_ids.tolist() == [2] and t.segment_ids.tolist() == [2]


def test_shape_mismatch_is_a_map_error():
    with pytest.raises(MapError):
        segmentation_scores(np.zeros((2, 2), int), np.zeros((2, 3), int))


def test_bundled_office_a_ground_truth_as_its_own_prediction():
    gt = read_ipa_gt(DATA / "office_a_gt_segmentation.png")
    for restrict in (True, False):
        s = segmentation_scores(gt, gt, restrict_to_gt=restrict)
        assert s[:6] == (1.0, 1.0, 1.0, 1.0, 1.0, 1.0)
        assert s.n_rooms == s.n_segments == 27
    # Merging two rooms lowers precision and IoU but not recall.
    merged = np.where(gt == 2, 1, gt)
    s = segmentation_scores(gt, merged)
    assert s.recall == 1.0 and s.precision < 1.0 and s.iou < 1.0
