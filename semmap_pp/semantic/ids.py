"""Unit ids carried over from an earlier world.json (``semmap map --ids-from FILE``).

A robot's map grows as it explores, and its semantic map is built again. Each world.json numbers
its units afresh, in reading order (:func:`semmap_pp.semantic.semantic_map.number_units`), so unit 7
of one run need not be unit 7 of the next. A planner or a person who has named "room 7" wants it
to stay 7. Given the units of an earlier world.json in map-frame metres
(:func:`semmap_pp.plans.world_file.read_previous_ids`), :func:`carry_ids` gives each unit of a new
world the id of the earlier unit it overlaps with an intersection over union of at least
:data:`MIN_IOU` (one to one, best pairs first), and every other unit an id that the earlier file
never used, in reading order. An id therefore never names two different places across updates:
the earlier file's ``ids.next`` (the first id it left unused) is honoured, so an id that went
away is not given again.

The overlap is measured between the units' rectangles in the map frame (convex polygons, exact:
:func:`overlap_iou`), so the two maps may differ in size, origin and orientation estimate, as a
SLAM map does between updates while its ``map`` frame stays put.
"""

from __future__ import annotations

import numpy as np

from semmap_pp.errors import SemmapError

#: The largest unit id labels.png can hold (16-bit, 0 = no unit); world_file's reader checks it too.
MAX_ID = 2 ** 16 - 1

#: Two units are the same place when their rectangles' intersection over union reaches this (as
#: ``semmap stability`` and the evaluation match units). At 0.5 a unit matches at most one other
#: unit of a world whose units do not overlap beyond their shared wall bands.
MIN_IOU = 0.5


def _ccw(poly: np.ndarray) -> np.ndarray:
    """``poly`` with its vertices counter-clockwise (positive signed area)."""
    return poly if signed_area(poly) >= 0 else poly[::-1]


def signed_area(poly: np.ndarray) -> float:
    """Shoelace area of a polygon, positive when its vertices run counter-clockwise.

    >>> signed_area(np.array([[0, 0], [2, 0], [2, 1], [0, 1]], float))
    2.0
    """
    x, y = poly[:, 0], poly[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))


def clip_convex(subject: np.ndarray, clip: np.ndarray) -> np.ndarray:
    """The intersection of two convex polygons (Sutherland–Hodgman), as a polygon (possibly empty).

    >>> a = np.array([[0, 0], [2, 0], [2, 2], [0, 2]], float)
    >>> abs(signed_area(clip_convex(a, a + 1.0)))
    1.0
    """
    out = _ccw(np.asarray(subject, float))
    clip = _ccw(np.asarray(clip, float))
    for i in range(len(clip)):
        if len(out) == 0:
            break
        a, b = clip[i], clip[(i + 1) % len(clip)]
        edge = b - a
        side = edge[0] * (out[:, 1] - a[1]) - edge[1] * (out[:, 0] - a[0])   # >= 0: inside
        kept = []
        for j in range(len(out)):
            p, q = out[j], out[(j + 1) % len(out)]
            sp, sq = side[j], side[(j + 1) % len(out)]
            if sp >= 0:
                kept.append(p)
            if (sp >= 0) != (sq >= 0):
                kept.append(p + (q - p) * (sp / (sp - sq)))
        out = np.asarray(kept, float).reshape(-1, 2)
    return out


def overlap_iou(a: np.ndarray, b: np.ndarray) -> float:
    """Intersection over union of two convex polygons: 1 for the same corners (even without
    area), else 0 when either has no area.

    >>> a = np.array([[0, 0], [2, 0], [2, 1], [0, 1]], float)
    >>> round(overlap_iou(a, a + [1.0, 0.0]), 6), overlap_iou(a[[0, 0, 0, 0]], a[[0, 0, 0, 0]])
    (0.333333, 1.0)
    """
    if np.array_equal(a, b):
        return 1.0
    area_a, area_b = abs(signed_area(a)), abs(signed_area(b))
    if area_a <= 0 or area_b <= 0:
        return 0.0
    inter = clip_convex(a, b)
    common = abs(signed_area(inter)) if len(inter) >= 3 else 0.0
    return common / (area_a + area_b - common)


def overlap_iou_matrix(a, b) -> np.ndarray:
    """(len(a), len(b)) :func:`overlap_iou` of the convex quadrilaterals ``a[i]`` and ``b[j]``
    (each (4, 2)); a pair whose bounding boxes do not meet is 0 without clipping.

    >>> sq = np.array([[0, 0], [2, 0], [2, 2], [0, 2]], float)
    >>> overlap_iou_matrix([sq, sq + 5.0], [sq + [1.0, 0.0]]).round(3).tolist()
    [[0.333], [0.0]]
    """
    a = np.asarray(a, float).reshape(-1, 4, 2)
    b = np.asarray(b, float).reshape(-1, 4, 2)
    out = np.zeros((len(a), len(b)))
    lo, hi = b.min(axis=1), b.max(axis=1)
    for i, c in enumerate(a):
        near = np.flatnonzero(np.all(lo <= c.max(axis=0), axis=1) & np.all(hi >= c.min(axis=0), axis=1))
        for k in near.tolist():
            out[i, k] = overlap_iou(c, b[k])
    return out


#: :func:`overlap_pairs` gives up when the bounding boxes of more than this many pairs per unit
#: (of the larger list) meet. Two plans of one building meet a unit's own and its neighbours'
#: (about 9, up to about 16 on a lattice turned by 45 degrees); only units piled on each other
#: meet more, and every such pair costs a polygon clipping.
MAX_PAIRS_PER_UNIT = 64


def overlap_pairs(a, b, *, path=None) -> list[tuple[int, int, float]]:
    """``(i, j, iou)`` for every pair of the convex quadrilaterals ``a[i]`` and ``b[j]`` (each
    (4, 2)) whose :func:`overlap_iou` is positive, by ``i`` then ``j``: the nonzero entries of
    :func:`overlap_iou_matrix`, without its ``len(a) x len(b)`` array. Raises
    :class:`~semmap_pp.errors.SemmapError` naming ``path`` when the bounding boxes of more than
    :data:`MAX_PAIRS_PER_UNIT` pairs per unit meet (units piled on each other), before clipping any.

    >>> sq = np.array([[0, 0], [2, 0], [2, 2], [0, 2]], float)
    >>> [(i, j, round(v, 3)) for i, j, v in overlap_pairs([sq, sq + 5.0], [sq + [1.0, 0.0], sq + 5.0])]
    [(0, 0, 0.333), (1, 1, 1.0)]
    """
    a = np.asarray(a, float).reshape(-1, 4, 2)
    b = np.asarray(b, float).reshape(-1, 4, 2)
    lo, hi = b.min(axis=1), b.max(axis=1)
    limit = MAX_PAIRS_PER_UNIT * max(len(a), len(b))
    near, total = [], 0
    for c in a:
        k = np.flatnonzero(np.all(lo <= c.max(axis=0), axis=1) & np.all(hi >= c.min(axis=0), axis=1))
        total += len(k)
        if total > limit:
            raise SemmapError(path, f"more than {limit} pairs of the {len(a)} and {len(b)} units overlap "
                                    f"(at most {MAX_PAIRS_PER_UNIT} per unit): units piled on each other, "
                                    f"not a floor plan")
        near.append(k)
    out = []
    for i, ks in enumerate(near):
        for k in ks.tolist():
            v = overlap_iou(a[i], b[k])
            if v > 0:
                out.append((i, k, v))
    return out


def greedy_pairs(pairs, min_iou: float = MIN_IOU) -> list[tuple[int, int, float]]:
    """One-to-one matches of :func:`overlap_pairs` ``(i, j, iou)``, greedily from the highest IoU
    (ties: the lower ``i``, then ``j``), each at least ``min_iou`` (> 0); sorted by ``i``: the
    matches :func:`semmap_pp.studies.stability.greedy_matches` makes of the whole matrix.

    >>> greedy_pairs([(0, 0, 0.9), (0, 1, 0.6), (1, 0, 0.7), (1, 1, 0.2)])
    [(0, 0, 0.9)]
    """
    out, used_a, used_b = [], set(), set()
    for i, j, v in sorted(pairs, key=lambda t: (-t[2], t[0], t[1])):
        if v < min_iou:
            break
        if i in used_a or j in used_b:
            continue
        used_a.add(i)
        used_b.add(j)
        out.append((i, j, float(v)))
    return sorted(out)


def carry_ids(corners_m: dict, order: list, previous, min_iou: float = MIN_IOU) -> tuple[dict, dict]:
    """Unit ids for the units ``corners_m`` (slot -> (4, 2) corners in map-frame metres), carried
    from ``previous`` (:class:`semmap_pp.plans.world_file.PreviousIds`).

    Pairs of a new and an earlier unit with IoU at least ``min_iou`` are matched best first, each
    unit at most once; a matched unit takes the earlier id. The others get ids from
    ``previous.next_id`` on, in ``order`` (the slots in reading order).

    Returns ``(slot_ids, record)``: slot -> id, and the record world.json keeps under ``ids``:
    the file, the next id never used, and which ids were carried, are new and are gone.
    """
    slots = list(corners_m)
    pairs = [(-v, previous.ids[k], slots[i]) for i, k, v in
             overlap_pairs([corners_m[s] for s in slots], previous.corners_m, path=previous.path)
             if v >= min_iou]
    slot_ids, taken = {}, set()
    for _, uid, s in sorted(pairs):
        if s not in slot_ids and uid not in taken:
            slot_ids[s] = uid
            taken.add(uid)
    carried = sorted(taken)
    nxt = int(previous.next_id)
    new = []
    for s in order:
        if s not in slot_ids:
            slot_ids[s] = nxt
            new.append(nxt)
            nxt += 1
    if nxt - 1 > MAX_ID:
        raise SemmapError(previous.path, f"the new units would need ids beyond {MAX_ID} (labels.png "
                                         "holds 16-bit ids); number them afresh (no --ids-from)")
    record = {"from": str(previous.path), "next": nxt, "carried": carried, "new": new,
              "gone": sorted(set(previous.ids) - taken)}
    return slot_ids, record


def carried_text(record: dict) -> str:
    """One line on the unit ids carried from an earlier world.json (``SemanticMap.id_record``).

    >>> carried_text({"from": "old/world.json", "next": 23, "carried": [1, 2, 4], "new": [21, 22], "gone": [3]})
    'unit ids from old/world.json: 3 carried, 2 new (21, 22), 1 gone (3); the next new id is 23'
    """
    def ids(values):
        shown = ", ".join(str(v) for v in values[:12])
        return f" ({shown}{', ...' if len(values) > 12 else ''})" if values else ""

    return (f"unit ids from {record['from']}: {len(record['carried'])} carried, "
            f"{len(record['new'])} new{ids(record['new'])}, {len(record['gone'])} gone"
            f"{ids(record['gone'])}; the next new id is {record['next']}")
