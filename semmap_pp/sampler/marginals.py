"""Posterior marginals of W*'s units and doors, counted over sampled worlds.

The knowledge engine's type marginals (world.json's ``type_marginals``) are conditional: the
types of W*'s units given W*'s geometry. These are the posterior's own, read off the sampled
worlds (the sample around W*: :func:`semmap_pp.run.spread.posterior_worlds`), each world counted
once per draw:

* a unit of W* **exists** in a sampled world when some unit of that world covers the same place:
  lattice rectangles with intersection over union at least :data:`MATCH_IOU` (0.5, the rule
  ``--ids-from`` matches units by). Over 0.5 a world has at most one such unit unless its own
  units overlap; the one of the largest IoU is the match (the lower slot on a tie);
* its **type** distribution: the types of its matches, over the worlds that have one (so it is
  conditional on existing; ``None`` when no world has a match);
* a door of W* **is there** in a sampled world when one of that world's doors
  (:func:`semmap_pp.derive.doors.find_openings` between its adjacent units) lies on the same
  place: their lattice boxes intersect once W*'s door box is grown by the wall band's thickness
  on every side (a wall moved by a band is the same door).

Examples
--------
>>> import numpy as np
>>> from semmap_pp import world as wm
>>> wstar = wm.add(wm.add(wm.empty(4), 0, (0, 0, 10, 10), type_index=0), 1, (0, 10, 10, 20), type_index=1)
>>> same = wstar
>>> moved = wm.add(wm.empty(4), 2, (0, 0, 10, 8), type_index=1)     # unit 0 only, IoU 0.8, typed 1
>>> gone = wm.add(wm.empty(4), 0, (0, 0, 10, 4), type_index=0)      # IoU 0.4 with unit 0: no match
>>> m = unit_marginals(wstar, [same, moved, gone, same])
>>> [round(m[s].exists, 3) for s in (0, 1)]
[0.75, 0.5]
>>> m[0].types, m[1].types
((0.6666666666666666, 0.3333333333333333, 0.0, 0.0), (0.0, 1.0, 0.0, 0.0))
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from semmap_pp import world as wm
from semmap_pp.cells import UNIT_TYPES
from semmap_pp.derive.adjacency import adjacency_matrix
from semmap_pp.derive.crossing import cross_tile_openings
from semmap_pp.derive.doors import find_openings
from semmap_pp.lattice.tiles import rect_spans

#: A sampled unit is a W* unit's match when their rectangles' intersection over union is at least this.
MATCH_IOU = 0.5


@dataclass(frozen=True)
class UnitMarginal:
    """One unit of W* over the sampled worlds: the share of worlds with a match (``exists``), the
    type distribution of the matches (``types``, in :data:`~semmap_pp.cells.UNIT_TYPES` order;
    ``None`` without any match) and the number of worlds counted (``n``)."""

    exists: float
    types: tuple | None
    n: int


def iou(a, b) -> float:
    """Intersection over union of two half-open lattice rectangles ``(r0, c0, r1, c1)``.

    >>> iou((0, 0, 10, 10), (0, 0, 10, 8)), iou((0, 0, 2, 2), (2, 2, 4, 4))
    (0.8, 0.0)
    """
    return float(iou_matrix(np.asarray(a)[None], np.asarray(b)[None])[0, 0])


def best_match(rect, world: wm.World) -> int | None:
    """The slot of ``world``'s unit matching ``rect`` (largest IoU, at least :data:`MATCH_IOU`;
    the lower slot on a tie), or None."""
    best, slot = MATCH_IOU, None
    for s in wm.active_slots(world):
        v = iou(rect, world.rects[s])
        if v >= best and (slot is None or v > best):
            best, slot = v, int(s)
    return slot


def iou_matrix(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The :func:`iou` of every rectangle of ``a`` (n, 4) with every one of ``b`` (m, 4): (n, m).

    >>> iou_matrix(np.array([(0, 0, 10, 10)]), np.array([(0, 0, 10, 8), (0, 0, 2, 2)])).round(2).tolist()
    [[0.8, 0.04]]
    """
    a = np.asarray(a, np.int64).reshape(-1, 1, 4)
    b = np.asarray(b, np.int64).reshape(1, -1, 4)
    inter = (np.maximum(np.minimum(a[..., 2], b[..., 2]) - np.maximum(a[..., 0], b[..., 0]), 0)
             * np.maximum(np.minimum(a[..., 3], b[..., 3]) - np.maximum(a[..., 1], b[..., 1]), 0))
    union = (a[..., 2] - a[..., 0]) * (a[..., 3] - a[..., 1]) + (b[..., 2] - b[..., 0]) * (b[..., 3] - b[..., 1]) - inter
    out = np.zeros(inter.shape, np.float64)
    np.divide(inter, union, out=out, where=union > 0)
    return out


def unit_marginals(wstar: wm.World, worlds) -> dict[int, UnitMarginal]:
    """Per active slot of ``wstar``: its :class:`UnitMarginal` over the typed ``worlds``.

    Each world's matches are :func:`best_match`'s, found for all of W*'s units at once
    (:func:`iou_matrix`)."""
    worlds = list(worlds)
    slots = wm.active_slots(wstar)
    mine = np.asarray(wstar.rects[slots], np.int64).reshape(-1, 4)
    counts = np.zeros((len(slots), len(UNIT_TYPES)), np.int64)
    found = np.zeros(len(slots), np.int64)
    rows = np.arange(len(slots))
    for w in worlds:
        theirs = wm.active_slots(w)
        if not len(theirs) or not len(slots):
            continue
        v = iou_matrix(mine, w.rects[theirs])
        best = np.argmax(v, axis=1)                  # the lower slot on a tie, as best_match
        hit = v[rows, best] >= MATCH_IOU
        found += hit
        t = np.asarray(w.types, np.int64)[np.asarray(theirs)[best]]
        ok = hit & (t >= 0) & (t < len(UNIT_TYPES))
        np.add.at(counts, (rows[ok], t[ok]), 1)
    out = {}
    for i, s in enumerate(slots):
        typed = int(counts[i].sum())
        out[int(s)] = UnitMarginal(int(found[i]) / len(worlds) if worlds else float("nan"),
                                   tuple(float(c) / typed for c in counts[i]) if typed else None, len(worlds))
    return out


def world_doors(frame, world: wm.World, pair_cache: dict | None = None) -> list:
    """The doors of ``world`` between its adjacent units (:func:`~semmap_pp.derive.doors.find_openings`
    on ``frame``'s door classes, and on a tiled lattice those between units of two tiles:
    :func:`~semmap_pp.derive.crossing.cross_tile_openings`; passages left out).

    ``pair_cache``: :func:`~semmap_pp.derive.doors.find_openings`'s cache of the pairs of units of
    one tile, kept across calls on one frame."""
    c = frame.cells
    slots = wm.active_slots(world)
    rects = world.rects[slots]
    adj = adjacency_matrix(rects, c.wall, c.adjacency_dilation)
    doors = find_openings(frame.door_classes, rects, adj, c, slots, cache=pair_cache)[0]
    if rect_spans(frame):
        doors = doors + cross_tile_openings(frame, rects, slots)[1]
    return doors


def door_there(box, doors, grow: int) -> bool:
    """Whether one of ``doors`` has a box intersecting ``box`` grown by ``grow`` cells each side.

    >>> from semmap_pp.derive.doors import Door
    >>> d = [Door(0, 1, (10, 20, 11, 25), False, 5)]
    >>> door_there((11, 20, 12, 25), d, 1), door_there((13, 20, 14, 25), d, 1)
    (True, False)
    """
    r0, c0, r1, c1 = box[0] - grow, box[1] - grow, box[2] + grow, box[3] + grow
    return any(max(r0, d.box[0]) < min(r1, d.box[2]) and max(c0, d.box[1]) < min(c1, d.box[3]) for d in doors)


def door_marginals(frame, wstar_doors, worlds, doors_of=None) -> list[float]:
    """For each of ``wstar_doors`` (:class:`~semmap_pp.derive.doors.Door`), the share of ``worlds``
    with a door at its place (:func:`door_there`, grown by ``frame.cells.wall``). A world repeated
    in ``worlds`` has its doors found once (``doors_of(frame, world)``; by default
    :func:`world_doors` with one pair cache for all the worlds)."""
    worlds = list(worlds)
    if not worlds:
        return [float("nan")] * len(wstar_doors)
    found = np.zeros(len(wstar_doors), np.int64)
    cache: dict[bytes, list] = {}
    if doors_of is None:
        pairs: dict = {}
        doors_of = functools.partial(world_doors, pair_cache=pairs)
    grow = int(frame.cells.wall)
    for w in worlds:
        key = w.rects.tobytes() + w.active.tobytes()
        if key not in cache:
            doors = doors_of(frame, w)
            cache[key] = [door_there(d.box, doors, grow) for d in wstar_doors]
        found += np.asarray(cache[key], np.int64)
    return [float(v) / len(worlds) for v in found]


__all__ = ["MATCH_IOU", "UnitMarginal", "iou", "iou_matrix", "best_match", "unit_marginals", "world_doors", "door_there",
           "door_marginals"]
