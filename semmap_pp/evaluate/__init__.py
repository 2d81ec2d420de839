"""The yardsticks: every metric semmap_pp reports, as pure functions over arrays and dicts.

* :mod:`~semmap_pp.evaluate.cpr` -- cell prediction rate (the seed paper's measure) and its ROI.
* :mod:`~semmap_pp.evaluate.segmentation` -- room segmentation: ipa / ROSE2 precision and recall
  ("micro" and "macro"), mean IoU (Hungarian and best-match).
* :mod:`~semmap_pp.evaluate.types` -- per-cell room / corridor accuracy against ipa place types.
* :mod:`~semmap_pp.evaluate.truth` -- units, types, adjacency and doors against synthetic truth.
* :mod:`~semmap_pp.evaluate.lshape` -- the same with the truth's L-shaped spaces cut either way.
* :mod:`~semmap_pp.evaluate.calibration` -- reliability tables and the expected calibration error.
* :mod:`~semmap_pp.evaluate.io` -- readers of the ground-truth and prediction files.

Definitions and the choices behind them: docs/evaluation.md.
"""

from semmap_pp.evaluate.cpr import (CORRECT_PAIRS, closing_radius_cells, cpr, default_roi, disk,
                                    load_roi)
from semmap_pp.evaluate.io import (IPA_MIN_REGION_CELLS, ROSE2_MIN_ROOM_CELLS, SEGMENTATION_FORMATS,
                                   colour_room_labels, colour_segment_labels, ipa_gt_labels,
                                   read_ipa_gt, read_ipa_types, read_json, read_label_image,
                                   read_segmentation, read_segmentation_truth)
from semmap_pp.evaluate.segmentation import (OverlapTable, SegmentationScore, iou_matrix,
                                             overlap_table, protocol_scores, scores_from_table,
                                             segmentation_scores)
from semmap_pp.evaluate.lshape import recut_l, score_world_either_l
from semmap_pp.evaluate.truth import WorldScore, match_units, polygon_mask, score_world
from semmap_pp.evaluate.types import (TRUTH_CORRIDOR, TRUTH_DOORWAY, TRUTH_OUTSIDE, TRUTH_ROOM,
                                      TYPE_NONE, TypeScore, type_accuracy, type_map_from_labels)

__all__ = [
    "CORRECT_PAIRS", "IPA_MIN_REGION_CELLS", "OverlapTable", "SegmentationScore", "TRUTH_CORRIDOR",
    "TRUTH_DOORWAY", "TRUTH_OUTSIDE", "TRUTH_ROOM", "TYPE_NONE", "TypeScore", "WorldScore",
    "closing_radius_cells", "cpr", "default_roi", "disk", "iou_matrix", "ipa_gt_labels",
    "load_roi", "match_units", "overlap_table", "polygon_mask", "read_ipa_gt", "read_ipa_types",
    "read_json", "read_label_image", "recut_l", "score_world", "score_world_either_l",
    "scores_from_table", "segmentation_scores", "protocol_scores", "ROSE2_MIN_ROOM_CELLS",
    "SEGMENTATION_FORMATS", "colour_room_labels", "colour_segment_labels", "read_segmentation",
    "read_segmentation_truth",
    "type_accuracy", "type_map_from_labels",
]
