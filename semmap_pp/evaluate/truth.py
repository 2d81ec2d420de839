"""Scores of a predicted world against the synthetic generator's truth (``truth.json``).

Units are matched one-to-one by polygon IoU (both polygons rasterised on the map grid, Hungarian
assignment maximising total IoU, a pair kept when its IoU >= ``iou_min``). Through that matching:
unit precision / recall / F1, type accuracy over matched pairs, adjacency precision / recall and
door precision / recall. The expected shapes of both dicts are in docs/evaluation.md.

Pixel frame (docs/world.schema.json, semmap_pp.synth.truth): continuous image coordinates
``[x, y]``, x = column, y = row; the cell ``[row, col]`` covers ``col <= x < col + 1`` and
``row <= y < row + 1``, so its centre is ``(col + 0.5, row + 0.5)``. A cell belongs to a polygon
when its centre lies inside it or on its boundary. Both sides are rasterised the same way, so the
rule cannot favour either.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any, NamedTuple

import numpy as np
from scipy.optimize import linear_sum_assignment

from semmap_pp.errors import MapError

# Boundary tolerance of the point-in-polygon test, in pixels (numerical slack only).
_EPS = 1e-9


def polygon_mask(vertices_px: Sequence[Sequence[float]], shape: tuple[int, int],
                 centre_offset: float = 0.5) -> np.ndarray:
    """Cells of a grid whose centre lies inside a polygon (boundary included).

    Parameters
    ----------
    vertices_px : sequence of [x, y]
        At least three vertices in order (either orientation), x = column, y = row.
    shape : (int, int)
        (rows, cols) of the grid.
    centre_offset : float
        The centre of cell ``[row, col]`` is ``(col + centre_offset, row + centre_offset)``:
        0.5 in the continuous frame of world.json and truth.json; 0 for a frame whose integer
        coordinates are cell centres.

    Returns
    -------
    np.ndarray of bool, shape ``shape``

    Examples
    --------
    The box x in [1, 3], y in [0, 1] covers the cells of columns 1 and 2 in row 0:

    >>> polygon_mask([[1, 0], [3, 0], [3, 1], [1, 1]], (2, 5)).astype(int).tolist()
    [[0, 1, 1, 0, 0], [0, 0, 0, 0, 0]]
    >>> diamond = [[2.5, 0.5], [4.5, 2.5], [2.5, 4.5], [0.5, 2.5]]   # corners on cell centres
    >>> polygon_mask(diamond, (5, 5)).astype(int).tolist()
    [[0, 0, 1, 0, 0], [0, 1, 1, 1, 0], [1, 1, 1, 1, 1], [0, 1, 1, 1, 0], [0, 0, 1, 0, 0]]
    """
    v = np.asarray(vertices_px, dtype=np.float64) - centre_offset  # now in cell-index units
    if v.ndim != 2 or v.shape[1] != 2 or v.shape[0] < 3 or not np.isfinite(v).all():
        raise ValueError(f"a polygon needs >= 3 finite [x, y] vertices, got {v.tolist()}")
    rows, cols = int(shape[0]), int(shape[1])
    mask = np.zeros((rows, cols), dtype=bool)
    c0 = max(int(math.floor(v[:, 0].min())), 0)
    c1 = min(int(math.ceil(v[:, 0].max())), cols - 1)
    r0 = max(int(math.floor(v[:, 1].min())), 0)
    r1 = min(int(math.ceil(v[:, 1].max())), rows - 1)
    if c0 > c1 or r0 > r1:
        return mask
    yy, xx = np.mgrid[r0:r1 + 1, c0:c1 + 1].astype(np.float64)
    a = v
    b = np.roll(v, -1, axis=0)
    # Cross product of each edge with the vector to the point: the sign says which side.
    cross = ((b[:, 0] - a[:, 0])[:, None, None] * (yy - a[:, 1][:, None, None])
             - (b[:, 1] - a[:, 1])[:, None, None] * (xx - a[:, 0][:, None, None]))
    edge_len = np.hypot(b[:, 0] - a[:, 0], b[:, 1] - a[:, 1])[:, None, None]
    dist = cross / np.where(edge_len > 0, edge_len, 1.0)
    area2 = float(np.sum(a[:, 0] * b[:, 1] - b[:, 0] * a[:, 1]))
    if _is_convex(v):
        sign = 1.0 if area2 >= 0 else -1.0
        inside = (sign * dist >= -_EPS).all(axis=0)
    else:
        inside = _crossing_inside(v, xx, yy) | _on_boundary(v, xx, yy)
    mask[r0:r1 + 1, c0:c1 + 1] = inside
    return mask


def _is_convex(v: np.ndarray) -> bool:
    a, b, c = v, np.roll(v, -1, axis=0), np.roll(v, -2, axis=0)
    turn = (b[:, 0] - a[:, 0]) * (c[:, 1] - b[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - b[:, 0])
    turn = turn[np.abs(turn) > _EPS]
    return bool((turn > 0).all() or (turn < 0).all())


def _crossing_inside(v: np.ndarray, xx: np.ndarray, yy: np.ndarray) -> np.ndarray:
    inside = np.zeros(xx.shape, dtype=bool)
    for (x1, y1), (x2, y2) in zip(v, np.roll(v, -1, axis=0)):
        straddles = (y1 > yy) != (y2 > yy)
        with np.errstate(divide="ignore", invalid="ignore"):
            x_at = x1 + (yy - y1) * (x2 - x1) / (y2 - y1)
        inside ^= straddles & (xx < x_at)
    return inside


def _on_boundary(v: np.ndarray, xx: np.ndarray, yy: np.ndarray) -> np.ndarray:
    on = np.zeros(xx.shape, dtype=bool)
    for (x1, y1), (x2, y2) in zip(v, np.roll(v, -1, axis=0)):
        dx, dy = x2 - x1, y2 - y1
        seg2 = dx * dx + dy * dy
        t = np.clip(((xx - x1) * dx + (yy - y1) * dy) / seg2, 0, 1) if seg2 > 0 else 0.0
        on |= np.hypot(xx - (x1 + t * dx), yy - (y1 + t * dy)) <= _EPS
    return on


class WorldScore(NamedTuple):
    """Result of :func:`score_world` (NaN where a ratio has a zero denominator)."""

    unit_precision: float
    unit_recall: float
    unit_f1: float
    type_accuracy: float
    adjacency_precision: float
    adjacency_recall: float
    door_precision: float
    door_recall: float
    matches: dict          # predicted unit id -> true unit id
    match_iou: dict        # predicted unit id -> IoU with its match
    n_pred_units: int
    n_true_units: int
    door_matches: tuple = ()   # per predicted door, in the prediction's order: matched a true door


def _ratio(num: float, den: float) -> float:
    return float(num) / float(den) if den else float("nan")


def _f1(n_match: int, n_pred: int, n_true: int) -> float:
    # 2PR / (P + R) written with counts, so that it is 0 (not NaN) when one side is empty.
    return _ratio(2 * n_match, n_pred + n_true)


def _field(obj: Mapping, key: str, source: str, where: str) -> Any:
    if not isinstance(obj, Mapping) or key not in obj:
        raise MapError(source, f"{where}: missing {key!r}")
    return obj[key]


def _units(side: Mapping, corner_key: str, name: str) -> list[tuple[int, str | None, list]]:
    units = _field(side, "units", name, "top level")
    if not isinstance(units, list):
        raise MapError(name, "'units' must be a list")
    out = []
    for i, u in enumerate(units):
        uid = _field(u, "id", name, f"unit #{i}")
        corners = _field(u, corner_key, name, f"unit {uid}")
        try:
            arr = np.asarray(corners, dtype=np.float64)
        except (TypeError, ValueError):
            arr = np.zeros((0,))
        if arr.ndim != 2 or arr.shape[1] != 2 or arr.shape[0] < 3 or not np.isfinite(arr).all():
            raise MapError(name, f"unit {uid}: {corner_key!r} must be >= 3 [x, y] pairs")
        out.append((uid, u.get("type"), arr.tolist()))
    ids = [u[0] for u in out]
    if len(set(ids)) != len(ids):
        raise MapError(name, "unit ids are not unique")
    return out


def _pairs(side: Mapping, name: str) -> set[frozenset]:
    pairs = side.get("adjacency", [])
    if not isinstance(pairs, list):
        raise MapError(name, "'adjacency' must be a list")
    out = set()
    for p in pairs:
        if (not isinstance(p, (list, tuple)) or len(p) != 2
                or not all(isinstance(x, (int, str)) for x in p)):
            raise MapError(name, f"adjacency entries must be [a, b] id pairs, got {p!r}")
        out.add(frozenset(p))
    return out


def _doors(side: Mapping, name: str) -> list[tuple[frozenset, np.ndarray, float | None]]:
    doors = side.get("doors", [])
    if not isinstance(doors, list):
        raise MapError(name, "'doors' must be a list")
    out = []
    for i, d in enumerate(doors):
        units = _field(d, "units", name, f"door #{i}")
        centre = _field(d, "center_px", name, f"door #{i}")
        if (not isinstance(units, (list, tuple)) or len(units) != 2
                or not all(isinstance(x, (int, str)) for x in units)):
            raise MapError(name, f"door #{i}: 'units' must be [a, b] unit ids")
        try:
            c = np.asarray(centre, dtype=np.float64)
            width = d.get("width_m")
            width = None if width is None else float(width)
        except (TypeError, ValueError):
            raise MapError(name, f"door #{i}: 'center_px' and 'width_m' must be numbers") from None
        if c.shape != (2,) or not np.isfinite(c).all():
            raise MapError(name, f"door #{i}: 'center_px' must be [x, y]")
        out.append((frozenset(units), c, width))
    return out


def match_units(pred_masks: Sequence[np.ndarray], true_masks: Sequence[np.ndarray],
                iou_min: float = 0.5) -> tuple[list[tuple[int, int]], np.ndarray]:
    """One-to-one matching of predicted to true masks by IoU (Hungarian, maximum total IoU).

    Returns the matched (pred index, true index) pairs whose IoU >= ``iou_min`` and the full
    IoU matrix (n_pred, n_true). Masks are boolean arrays of one shape, or (what
    :func:`score_world` passes, to keep memory small on large maps) sorted arrays of the flat
    indices of their cells.

    Examples
    --------
    >>> import numpy as np
    >>> a = np.array([[1, 1, 0, 0]], bool); b = np.array([[0, 1, 1, 1]], bool)
    >>> pairs, iou = match_units([a, b], [b])
    >>> pairs, iou.round(2).tolist()      # a∩b = 1 cell, a∪b = 4 cells
    ([(1, 0)], [[0.25], [1.0]])
    """
    p = [_cells(m) for m in pred_masks]
    t = [_cells(m) for m in true_masks]
    n_p, n_t = len(p), len(t)
    iou = np.zeros((n_p, n_t))
    for i, a in enumerate(p):
        for j, b in enumerate(t):
            if a.size and b.size and a[0] <= b[-1] and b[0] <= a[-1]:
                inter = np.intersect1d(a, b, assume_unique=True).size
                iou[i, j] = inter / (a.size + b.size - inter)
    if n_p and n_t:
        rows, cols = linear_sum_assignment(iou, maximize=True)
        pairs = [(int(r), int(c)) for r, c in zip(rows, cols) if iou[r, c] >= iou_min]
    else:
        pairs = []
    return pairs, iou


def _cells(mask: np.ndarray) -> np.ndarray:
    m = np.asarray(mask)
    return np.flatnonzero(m) if m.dtype == bool else np.asarray(m, dtype=np.int64).ravel()


def score_world(pred: Mapping, truth: Mapping, shape: tuple[int, int] | None = None,
                resolution: float | None = None, *,
                iou_min: float = 0.5, door_tol_m: float = 1.0,
                pred_source: str = "prediction", truth_source: str = "truth") -> WorldScore:
    """Score a predicted world dict against a synthetic truth dict.

    Parameters
    ----------
    pred : mapping
        ``{"units": [{"id", "type", "vertices_px"}], "adjacency": [[a, b]], "doors":
        [{"units": [a, b], "center_px": [x, y], "width_m"}]}`` (a ``world.json``).
    truth : mapping
        The same with ``"corners_px"`` instead of ``"vertices_px"`` (a ``truth.json``).
    shape : (int, int), optional
        (rows, cols) of the map grid both polygons are rasterised on; by default the truth's
        ``[height, width]``.
    resolution : float, optional
        Metres per cell, to compare door centre distances with door widths; by default the
        truth's ``resolution``.
    iou_min : float
        A unit pair matches when its IoU is at least this (0.5).
    door_tol_m : float
        A predicted door matches a true door joining the matched pair of units when the
        centres are within ``max(true width_m, door_tol_m)`` metres (1 m).

    pred_source, truth_source : str
        Names (e.g. file paths) used in error messages.

    Returns
    -------
    WorldScore
        Precision over predicted items, recall over true items. Adjacency pairs and doors whose
        units are not both matched count as false positives (predicted) or misses (true).

    Raises
    ------
    MapError
        When either dict lacks a required field or holds malformed values.

    Examples
    --------
    >>> truth = {"units": [{"id": 1, "type": "room", "corners_px": [[0, 0], [4, 0], [4, 4], [0, 4]]},
    ...                    {"id": 2, "type": "corridor",
    ...                     "corners_px": [[5, 0], [9, 0], [9, 4], [5, 4]]}],
    ...          "adjacency": [[1, 2]],
    ...          "doors": [{"units": [1, 2], "center_px": [4.5, 2], "width_m": 0.9}]}
    >>> pred = {"units": [{"id": 10, "type": "room", "vertices_px": [[0, 0], [4, 0], [4, 4], [0, 4]]},
    ...                   {"id": 11, "type": "room", "vertices_px": [[5, 0], [9, 0], [9, 4], [5, 4]]}],
    ...         "adjacency": [[10, 11]],
    ...         "doors": [{"units": [11, 10], "center_px": [4.5, 10], "width_m": 0.9}]}
    >>> s = score_world(pred, truth, (6, 10), 0.05)
    >>> s.unit_f1, s.type_accuracy, s.adjacency_recall, s.door_recall  # door 8 px = 0.4 m away
    (1.0, 0.5, 1.0, 1.0)
    """
    shape, resolution = _grid_of(truth, shape, resolution, truth_source)
    pred_units = _units(pred, "vertices_px", pred_source)
    true_units = _units(truth, "corners_px", truth_source)
    pairs, to_true, match_iou = _matched(pred_units, true_units, shape, iou_min)
    n_match = len(pairs)
    unit_p = _ratio(n_match, len(pred_units))
    unit_r = _ratio(n_match, len(true_units))
    same_type = sum(pred_units[i][1] == true_units[j][1] for i, j in pairs)

    # Adjacency through the matching.
    true_adj = _pairs(truth, truth_source)
    pred_adj = _pairs(pred, pred_source)
    adj_tp = _adjacency_hits(pred_adj, true_adj, to_true)
    true_doors = _doors(truth, truth_source)
    pred_doors = _doors(pred, pred_source)
    door_hit = _door_hits(pred_doors, true_doors, to_true, resolution, door_tol_m)

    return WorldScore(
        unit_precision=unit_p, unit_recall=unit_r,
        unit_f1=_f1(n_match, len(pred_units), len(true_units)),
        type_accuracy=_ratio(same_type, n_match),
        adjacency_precision=_ratio(adj_tp, len(pred_adj)), adjacency_recall=_ratio(adj_tp, len(true_adj)),
        door_precision=_ratio(sum(door_hit), len(pred_doors)), door_recall=_ratio(sum(door_hit), len(true_doors)),
        matches=to_true, match_iou=match_iou,
        n_pred_units=len(pred_units), n_true_units=len(true_units), door_matches=door_hit,
    )


def _grid_of(truth: Mapping, shape, resolution, truth_source: str) -> tuple:
    """``(shape, resolution)``: those given, else the truth's ``[height, width]`` and
    ``resolution``; checked positive."""
    if shape is None:
        shape = (int(_field(truth, "height", truth_source, "top level")),
                 int(_field(truth, "width", truth_source, "top level")))
    if resolution is None:
        resolution = float(_field(truth, "resolution", truth_source, "top level"))
    if len(shape) != 2 or min(shape) <= 0 or not resolution > 0:
        raise MapError(truth_source, f"need a positive grid shape and resolution, got {shape}, "
                                     f"{resolution}")
    return shape, resolution


def _matched(pred_units, true_units, shape, iou_min: float) -> tuple:
    """``(pairs, predicted id -> true id, predicted id -> IoU)`` of the units matched one to one
    (:func:`match_units` of their polygons rasterised on ``shape``)."""
    pred_cells = [np.flatnonzero(polygon_mask(c, shape)) for _, _, c in pred_units]
    true_cells = [np.flatnonzero(polygon_mask(c, shape)) for _, _, c in true_units]
    pairs, iou = match_units(pred_cells, true_cells, iou_min)
    to_true = {pred_units[i][0]: true_units[j][0] for i, j in pairs}
    match_iou = {pred_units[i][0]: float(iou[i, j]) for i, j in pairs}
    return pairs, to_true, match_iou


def _adjacency_hits(pred_adj, true_adj: set, to_true: dict) -> int:
    """How many predicted adjacent pairs, mapped to true units through the matching, are true."""
    mapped = set()
    for p in pred_adj:
        a = [to_true.get(x) for x in p]
        if None not in a and len(a) == 2:
            mapped.add(frozenset(a))
    return len(mapped & true_adj)


def _door_hits(pred_doors, true_doors, to_true: dict, resolution: float, door_tol_m: float) -> tuple:
    """For each predicted door whether it matches a true door, one to one by distance: eligible
    pairs join the matched unit pair and lie within ``max(true width, door_tol_m)`` metres."""
    big = 1e12
    cost = np.full((len(pred_doors), len(true_doors)), big)
    for i, (units, centre, _) in enumerate(pred_doors):
        m = [to_true.get(x) for x in units]
        if None in m or len(m) != 2:
            continue
        for j, (t_units, t_centre, t_width) in enumerate(true_doors):
            if frozenset(m) != t_units:
                continue
            dist_m = float(np.hypot(*(centre - t_centre))) * resolution
            if dist_m <= max(t_width or 0.0, door_tol_m):
                cost[i, j] = dist_m
    hit = [False] * len(pred_doors)
    if cost.size:
        rows, cols = linear_sum_assignment(cost)
        for i, j in zip(rows, cols):
            hit[int(i)] = bool(cost[i, j] < big)
    return tuple(hit)
