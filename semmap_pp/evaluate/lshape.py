"""Either cut of an L: scoring against a truth whose L-shaped open spaces may be cut both ways.

The synthetic generator (:mod:`semmap_pp.synth`) turns some wide room slots into an L-shaped
space made of two rectangles joined by an open boundary (no wall between them), listed in
``truth["l_shapes"]``. An L can be cut into two rectangles in two ways, along either of the
lines through its inner corner; the generator picks one, and nothing in the map tells which:
the two rectangles of a prediction that cut the same L the other way are as right as the
truth's, yet the strict :func:`~semmap_pp.evaluate.truth.score_world` matches neither of them
(IoU < 0.5) and counts two missed and two false units.

:func:`recut_l` rewrites a truth dict with one L cut the other way (each new piece keeps the id
and type of the old piece it overlaps most; doors, exits, adjacency and open boundaries follow
the geometry), and :func:`score_world_either_l` scores a prediction against the truth with each
L cut whichever way matches more of the prediction's units (then doors). It reports the strict
score beside it; docs/evaluation.md says when to read which.
"""

from __future__ import annotations

import copy
from collections.abc import Mapping, Sequence

import numpy as np

from semmap_pp.errors import MapError
from semmap_pp.evaluate.truth import WorldScore, score_world

# Two coordinates closer than this many pixels are one line of the L (corners are rounded to
# 1e-3 px by the generator; rotated floors put them a fraction of a pixel apart at most).
_TOL_PX = 0.75


def _frame(corners: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """An orthonormal frame (origin, u, v) along the first edge of a rectangle (None if the
    edge has no length)."""
    u = corners[1] - corners[0]
    n = float(np.hypot(*u))
    if not n > 0:
        return None
    u = u / n
    return corners[0], u, np.array([-u[1], u[0]])


def _box(corners: np.ndarray, frame) -> tuple[float, float, float, float]:
    o, u, v = frame
    cu, cv = (corners - o) @ u, (corners - o) @ v
    return float(cu.min()), float(cu.max()), float(cv.min()), float(cv.max())


def _lines(values: Sequence[float]) -> list[float]:
    out: list[float] = []
    for x in sorted(values):
        if not out or x - out[-1] > _TOL_PX:
            out.append(x)
    return out


def _same_box(a, b) -> bool:
    return max(abs(x - y) for x, y in zip(a, b)) <= _TOL_PX


def _corners(box, frame) -> list[list[float]]:
    o, u, v = frame
    u0, u1, v0, v1 = box
    return [[round(float(x), 3) for x in o + a * u + b * v]
            for a, b in ((u0, v0), (u1, v0), (u1, v1), (u0, v1))]


def _overlap(a, b) -> float:
    du = min(a[1], b[1]) - max(a[0], b[0])
    dv = min(a[3], b[3]) - max(a[2], b[2])
    return max(du, 0.0) * max(dv, 0.0)


def _touch(a, b) -> bool:
    """Two boxes share a boundary of positive length (edges within tolerance)."""
    for lo, hi, olo, ohi in ((0, 1, 2, 3), (2, 3, 0, 1)):
        if (abs(a[hi] - b[lo]) <= _TOL_PX or abs(b[hi] - a[lo]) <= _TOL_PX) and \
                min(a[ohi], b[ohi]) - max(a[olo], b[olo]) > _TOL_PX:
            return True
    return False


def _dist_to_box(p: np.ndarray, box) -> float:
    du = max(box[0] - p[0], 0.0, p[0] - box[1])
    dv = max(box[2] - p[1], 0.0, p[1] - box[3])
    if du == 0.0 and dv == 0.0:       # inside: distance to the nearest edge
        return -min(p[0] - box[0], box[1] - p[0], p[1] - box[2], box[3] - p[1])
    return float(np.hypot(du, dv))


def other_cut(corners_a, corners_b) -> tuple[list, list] | None:
    """The two rectangles of the other cut of the L that rectangles ``a`` and ``b`` form.

    Returns ``(piece_a, piece_b)`` as four ``[x, y]`` corners each, ``piece_a`` the piece that
    overlaps ``a`` most, or None when the two rectangles do not form an L (three distinct lines
    on each axis of ``a``'s frame, three of the four cells between them covered).

    Examples
    --------
    A 4 x 2 bar with a 2 x 2 block below its left end, cut the other way: a 2 x 4 column on the
    left and a 2 x 2 block on the right.

    >>> a = [[0, 0], [4, 0], [4, 2], [0, 2]]; b = [[0, 2], [2, 2], [2, 4], [0, 4]]
    >>> pa, pb = other_cut(a, b)
    >>> pa, pb
    ([[2.0, 0.0], [4.0, 0.0], [4.0, 2.0], [2.0, 2.0]], [[0.0, 0.0], [2.0, 0.0], [2.0, 4.0], [0.0, 4.0]])
    """
    ca, cb = np.asarray(corners_a, float), np.asarray(corners_b, float)
    frame = _frame(ca)
    if frame is None:
        return None
    ba, bb = _box(ca, frame), _box(cb, frame)
    us, vs = _lines([ba[0], ba[1], bb[0], bb[1]]), _lines([ba[2], ba[3], bb[2], bb[3]])
    if len(us) != 3 or len(vs) != 3:
        return None
    covered = {(i, j) for i in range(2) for j in range(2)
               if any(b[0] < (us[i] + us[i + 1]) / 2 < b[1] and b[2] < (vs[j] + vs[j + 1]) / 2 < b[3]
                      for b in (ba, bb))}
    if len(covered) != 3:
        return None
    cuts = []
    for axis in (0, 1):          # 0: pieces are the columns i of the grid, 1: the rows j
        pieces = []
        for k in range(2):
            run = sorted(c[1 - axis] for c in covered if c[axis] == k)
            lo, hi = run[0], run[-1] + 1
            pieces.append((us[k], us[k + 1], vs[lo], vs[hi]) if axis == 0
                          else (us[lo], us[hi], vs[k], vs[k + 1]))
        cuts.append(pieces)
    current = [c for c in cuts if any(_same_box(p, ba) for p in c)]
    others = [c for c in cuts if not any(_same_box(p, ba) for p in c)]
    if len(current) != 1 or len(others) != 1:
        return None
    p, q = others[0]
    if _overlap(p, ba) + _overlap(q, bb) < _overlap(q, ba) + _overlap(p, bb):
        p, q = q, p
    return _corners(p, frame), _corners(q, frame)


def recut_l(truth: Mapping, pair: Sequence) -> dict | None:
    """``truth`` with the L of units ``pair = [a, b]`` cut the other way, or None if they form no
    L. Each new piece keeps the id and type of the old piece it overlaps most; doors and exits of
    the two go to the piece whose boundary is nearest their centre; adjacency and open-boundary
    pairs with a third unit are kept for the pieces that touch it."""
    a, b = pair
    units = {u["id"]: u for u in truth.get("units", [])}
    if a not in units or b not in units:
        return None
    cut = other_cut(units[a]["corners_px"], units[b]["corners_px"])
    if cut is None:
        return None
    out = copy.deepcopy(dict(truth))
    frame = _frame(np.asarray(units[a]["corners_px"], float))
    new = {a: cut[0], b: cut[1]}
    boxes = {a: _box(np.asarray(cut[0], float), frame), b: _box(np.asarray(cut[1], float), frame)}
    for u in out["units"]:
        if u["id"] in new:
            c = np.asarray(new[u["id"]], float)
            u["corners_px"] = new[u["id"]]
            u["center_px"] = [round(float(x), 3) for x in c.mean(axis=0)]

    def nearest(point) -> int:
        o, uu, vv = frame
        p = np.asarray(point, float) - o
        q = np.array([p @ uu, p @ vv])
        return min((a, b), key=lambda k: _dist_to_box(q, boxes[k]))

    for d in out.get("doors", []):
        ids = list(d.get("units", []))
        if len(ids) == 2 and (a in ids) != (b in ids):
            k = nearest(d["center_px"])
            d["units"] = sorted(k if x in (a, b) else x for x in ids)
    for e in out.get("exits", []):
        if e.get("unit") in (a, b):
            e["unit"] = nearest(e["center_px"])
    for key in ("adjacency", "open_boundaries"):
        if key not in out:
            continue
        kept, seen = [], set()
        for p in out[key]:
            p = list(p)
            if (a in p) == (b in p):          # the L's own boundary, or a pair without it
                cand = [p]
            else:
                c = p[0] if p[1] in (a, b) else p[1]
                if c not in units:
                    cand = [p]
                else:
                    bc = _box(np.asarray(units[c]["corners_px"], float), frame)
                    cand = [sorted([k, c]) for k in (a, b) if _touch(boxes[k], bc)]
            for q in cand:
                if frozenset(q) not in seen:
                    seen.add(frozenset(q))
                    kept.append(q)
        out[key] = kept
    return out


def score_world_either_l(pred: Mapping, truth: Mapping, shape=None, resolution=None,
                         **kwargs) -> tuple[WorldScore, WorldScore, list]:
    """Score ``pred`` against ``truth`` with each of its L-shaped spaces cut whichever way suits it.

    For each pair of ``truth["l_shapes"]`` in turn, the truth with that L cut the other way
    (:func:`recut_l`) replaces the current one when it matches more predicted units, or as many
    and more doors. The number of true units, doors and predicted items is the same under both
    cuts, so precision, recall and F1 stay comparable with the strict score.

    Returns ``(score, strict score, the pairs recut)``; keyword arguments go to
    :func:`~semmap_pp.evaluate.truth.score_world`.
    """
    strict = score_world(pred, truth, shape, resolution, **kwargs)
    pairs = truth.get("l_shapes", []) or []
    if not isinstance(pairs, list) or not all(
            isinstance(p, (list, tuple)) and len(p) == 2 and all(isinstance(x, (int, str)) for x in p)
            for p in pairs):
        raise MapError(kwargs.get("truth_source", "truth"),
                       "'l_shapes' must be a list of [a, b] unit id pairs")
    best, best_truth, recut = strict, truth, []

    def key(s: WorldScore):
        return (len(s.matches), 0.0 if s.door_recall != s.door_recall else s.door_recall)

    for pair in pairs:
        alt = recut_l(best_truth, pair)
        if alt is None:
            continue
        s = score_world(pred, alt, shape, resolution, **kwargs)
        if key(s) > key(best):
            best, best_truth = s, alt
            recut.append(list(pair))
    return best, strict, recut
