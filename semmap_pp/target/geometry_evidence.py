"""Evidence for the knowledge engine (paper Table 1) and the type/SaLe provider protocol.

Geometry evidence comes from the paper's Table 4 classifier: a unit whose *size* is big is
hall-like; otherwise a big length-to-width *ratio* makes it corridor-like and a small one room-like.
Thresholds and the size measure are in the model file (``[evidence]``). Near a threshold the class
is uncertain, so each unit also gets probabilities

``P(big size) = logistic((size - hall_min_size) / size_scale)``,
``P(big ratio) = logistic((ratio - corridor_min_ratio) / ratio_scale)``,
``P(HaLi) = P(big size)``, ``P(CoLi) = (1 - P(big size)) P(big ratio)``, ``P(RoLi)`` the rest;

a unit whose thresholded class has probability below ``hard_above`` is passed as soft evidence
(:attr:`GeometryEvidence.soft`) instead of a hard fact. ``MulDoor(u)`` holds when ``u`` has at least
``multiple_doors`` doors; with ``muldoor_scope = "space"`` a corridor-like unit counts the doors
of every unit joined to it by open passages (:func:`muldoor_counts`: a corridor cut into
rectangles, an L or a loop, has its doors spread over the pieces). ``Adj`` is the adjacency of
:mod:`semmap_pp.derive.adjacency`.

Unit ids are the world's slot indices.

Examples
--------
>>> import numpy as np
>>> from semmap_pp.model import load_model
>>> p = load_model().evidence
>>> rects = np.array([[0, 0, 80, 100], [0, 0, 40, 400], [0, 0, 200, 240]])  # 0.05 m cells
>>> [GEOMETRY_CLASSES[g] for g in geometry_class(rects, 0.05, p)]
['rolike', 'colike', 'halike']
"""

from __future__ import annotations

import bisect
import functools
from dataclasses import dataclass, field
from typing import Mapping, Protocol

import numba
import numpy as np

from semmap_pp.cells import UNIT_TYPES

GEOMETRY_CLASSES = ("rolike", "colike", "halike")
ROLIKE, COLIKE, HALIKE = 0, 1, 2
# The type each geometry class implies when no knowledge is used (RoLi->room, CoLi->corridor,
# HaLi->hall): the fixed provider's rule, documented in docs/model.md.
GEOMETRY_TYPE = np.array([UNIT_TYPES.index("room"), UNIT_TYPES.index("corridor"),
                          UNIT_TYPES.index("hall")], dtype=np.int8)


def _size_ratio(rects: np.ndarray, resolution: float, params):
    r = np.asarray(rects, dtype=np.float64).reshape(-1, 4)
    h = (r[:, 2] - r[:, 0]) * resolution
    w = (r[:, 3] - r[:, 1]) * resolution
    short, long_ = np.minimum(h, w), np.maximum(h, w)
    size = {"short_side": short, "long_side": long_, "area": h * w}[params.size_measure]
    ratio = long_ / np.maximum(short, 1e-12)
    return size, ratio


def geometry_class(rects: np.ndarray, resolution: float, params) -> np.ndarray:
    """Table 4 classes (ROLIKE / COLIKE / HALIKE) of rectangles (n, 4) in cells at ``resolution``."""
    size, ratio = _size_ratio(rects, resolution, params)
    return np.where(size >= params.hall_min_size, HALIKE,
                    np.where(ratio >= params.corridor_min_ratio, COLIKE, ROLIKE)).astype(np.int8)


def geometry_class_one(rect, resolution: float, params) -> int:
    """:func:`geometry_class` of one rectangle with Python scalars (the sampler's hot path);
    the same floating-point operations, so the two always agree."""
    h = (int(rect[2]) - int(rect[0])) * resolution
    w = (int(rect[3]) - int(rect[1])) * resolution
    short, long_ = min(h, w), max(h, w)
    m = params.size_measure
    size = short if m == "short_side" else long_ if m == "long_side" else h * w
    if size >= params.hall_min_size:
        return HALIKE
    return COLIKE if long_ / max(short, 1e-12) >= params.corridor_min_ratio else ROLIKE


@numba.njit(cache=True, nogil=True)
def geometry_class_compiled(rect, resolution, measure, hall_min_size,
                            corridor_min_ratio):  # pragma: no cover - compiled
    """:func:`geometry_class_one` compiled (``measure``: 0 short side, 1 long side, 2 area, the
    order of ``model.SIZE_MEASURES``); the same floating-point operations, so they always agree."""
    h = (rect[2] - rect[0]) * resolution
    w = (rect[3] - rect[1]) * resolution
    short, long_ = min(h, w), max(h, w)
    size = short if measure == 0 else long_ if measure == 1 else h * w
    if size >= hall_min_size:
        return HALIKE
    return COLIKE if long_ / max(short, 1e-12) >= corridor_min_ratio else ROLIKE


@numba.njit(cache=True, nogil=True)
def _muldoor_counts(openings, colike, out):  # pragma: no cover - compiled
    n = openings.shape[0]
    joined = np.zeros(n, np.bool_)          # has an open passage to some unit
    for i in range(n):
        own = 0
        for j in range(n):
            own += openings[i, j, 0]
            if openings[i, j, 1] > 0:
                joined[i] = True
        out[i] = own
    seen = np.zeros(n, np.bool_)
    members = np.empty(n, np.int64)
    for s in range(n):                      # components of the passage graph (singletons: no change)
        if not joined[s] or seen[s]:
            continue
        seen[s] = True
        members[0] = s
        m, head = 1, 0
        while head < m:                     # breadth first over the passages
            u = members[head]
            head += 1
            for v in range(n):
                if not seen[v] and openings[u, v, 1] > 0:
                    seen[v] = True
                    members[m] = v
                    m += 1
        total = 0
        for a in range(m):
            u = members[a]
            total += out[u]
            for b in range(a + 1, m):
                total -= openings[u, members[b], 0]   # a door between two members, counted once
        for a in range(m):
            if colike[members[a]]:
                out[members[a]] = total


def muldoor_counts(openings: np.ndarray, colike: np.ndarray) -> np.ndarray:
    """Doors that count towards MulDoor, per unit (``muldoor_scope = "space"``).

    A unit counts its own doors; a corridor-like unit joined to other units by open passages
    (transitively) counts every door of that group, each once: the doors of the corridor as a
    space, not of one rectangle of it.

    Parameters
    ----------
    openings : (n, n, 2) int
        Doors (``[..., 0]``) and open passages (``[..., 1]``; non-zero joins the pair) between
        each pair of units (symmetric).
    colike : (n,) bool
        Corridor-like units (the thresholded Table 4 class).

    Examples
    --------
    A corridor in two pieces (0, 1) joined by a passage, with two and one doors to rooms 2, 3, 4;
    room 4 also has a door to room 5. The pieces count the corridor's three doors, the rooms
    their own:

    >>> import numpy as np
    >>> o = np.zeros((6, 6, 2), np.int32)
    >>> for p, q in ((0, 2), (0, 3), (1, 4), (4, 5)):
    ...     o[p, q, 0] = o[q, p, 0] = 1
    >>> o[0, 1, 1] = o[1, 0, 1] = 1
    >>> muldoor_counts(o, np.array([1, 1, 0, 0, 0, 0], bool)).tolist()
    [3, 3, 1, 1, 2, 1]
    """
    openings = np.asarray(openings)
    if openings.dtype != np.int32:
        openings = openings.astype(np.int32)
    out = np.zeros(len(openings), np.int64)
    if len(openings):
        _muldoor_counts(openings, np.asarray(colike, dtype=np.bool_), out)
    return out


#: the geometry item (:func:`unit_geometry`) of a corridor piece: hard corridor-like
PIECE_ITEM = (COLIKE, None)


@numba.njit(cache=True, nogil=True)
def _space_colike(openings, short, classes, ratio, out):  # pragma: no cover - compiled
    n = openings.shape[0]
    width = np.zeros(n, np.float64)
    member = np.zeros(n, np.bool_)
    for u in range(n):
        if classes[u] == 1:                  # COLIKE
            member[u] = True
            width[u] = short[u]
    # the room-like units with open passages, and their passage neighbours (flat lists)
    total = 0
    for u in range(n):
        if classes[u] == 0:
            for v in range(n):
                if openings[u, v, 1] > 0:
                    total += 1
    cand = np.empty(n, np.int64)
    start = np.zeros(n + 1, np.int64)
    nbr = np.empty(total, np.int64)
    k = 0
    e = 0
    for u in range(n):
        if classes[u] != 0:                  # ROLIKE only
            continue
        first = e
        for v in range(n):
            if openings[u, v, 1] > 0:
                nbr[e] = v
                e += 1
        if e > first:
            cand[k] = u
            start[k] = first
            k += 1
            start[k] = e
    changed = True
    while changed:                          # the least fixpoint: members and widths only grow
        changed = False
        for i in range(k):
            u = cand[i]
            best = width[u]
            for j in range(start[i], start[i + 1]):
                v = nbr[j]
                if member[v] and short[u] <= ratio * width[v] and width[v] > best:
                    best = width[v]
            if best > width[u]:
                width[u] = best
                member[u] = True
                changed = True
    for u in range(n):
        out[u] = member[u] and classes[u] == 0


def space_colike(openings: np.ndarray, short: np.ndarray, classes: np.ndarray,
                 ratio: float) -> np.ndarray:
    """Room-like units that are pieces of a corridor space (``colike_scope = "space"``).

    A room-like unit joined by an open passage to a corridor-like unit, or to such a piece, is
    a piece of the corridor (a junction square, a bend, a stretch cut short) when its shorter
    side is at most ``ratio`` times the corridor's width (the corridor-like unit's shorter side;
    along a chain of pieces the widest corridor reached counts). The set is the least fixpoint of
    that rule, so it does not depend on the order of the units.

    Parameters
    ----------
    openings : (n, n, 2) int
        Doors and open passages between each pair of units (``[..., 1]`` non-zero: a passage).
    short : (n,) number
        Each unit's shorter side (any unit of length, the same for all).
    classes : (n,) int
        Table 4 classes (ROLIKE, COLIKE, HALIKE; any other value: no unit).
    ratio : float

    Returns
    -------
    (n,) bool: the room-like units that are corridor pieces (corridor-like units are not listed).

    Examples
    --------
    A corridor 2 units wide (0), a junction square 2 wide joined to it (1), a room 5 wide open
    to the square (2), a square 3 wide behind a door of the corridor (3):

    >>> o = np.zeros((4, 4, 2), np.int32)
    >>> o[0, 1, 1] = o[1, 0, 1] = o[1, 2, 1] = o[2, 1, 1] = 1
    >>> o[0, 3, 0] = o[3, 0, 0] = 1
    >>> space_colike(o, np.array([2, 2, 5, 3]), np.array([COLIKE, ROLIKE, ROLIKE, ROLIKE]), 2.0).tolist()
    [False, True, False, False]
    """
    openings = np.asarray(openings)
    if openings.dtype != np.int32:
        openings = openings.astype(np.int32)
    out = np.zeros(len(openings), np.bool_)
    if len(openings):                # (no passage: no piece; the compiled loop finds none)
        _space_colike(openings, np.asarray(short, np.float64), np.asarray(classes, np.int8),
                      float(ratio), out)
    return out


def _quantise(p: np.ndarray, step: float) -> np.ndarray:
    """``p`` rounded to multiples of ``step`` and kept in ``[step, 1 - step]``."""
    return np.clip(np.round(p / step) * step, step, 1.0 - step)


def _big_long(rects: np.ndarray, resolution: float, params) -> tuple[np.ndarray, np.ndarray]:
    """The two logistic values: P(size is big), P(length-to-width ratio is long)."""
    size, ratio = _size_ratio(rects, resolution, params)
    big = 1.0 / (1.0 + np.exp(-(size - params.hall_min_size) / params.size_scale))
    long_ = 1.0 / (1.0 + np.exp(-(ratio - params.corridor_min_ratio) / params.ratio_scale))
    return big, long_


def _classes(big: np.ndarray, long_: np.ndarray) -> np.ndarray:
    return np.stack([(1 - big) * (1 - long_), (1 - big) * long_, big], axis=1)


def geometry_probabilities(rects: np.ndarray, resolution: float, params) -> np.ndarray:
    """(n, 3) probabilities of RoLi, CoLi, HaLi (logistic in the distance to each threshold)."""
    return _classes(*_big_long(rects, resolution, params))


def soft_probabilities(rects: np.ndarray, resolution: float, params) -> np.ndarray:
    """:func:`geometry_probabilities` with the two logistic values quantised to ``params.soft_step``.

    Soft evidence is a coarse statement about a geometry near a class boundary; a finite set of
    values lets the knowledge engine reuse its work instead of meeting a new number at every
    resize of a unit. Used only for evidence already judged soft (class probability below
    ``hard_above``).
    """
    big, long_ = _big_long(rects, resolution, params)
    return _classes(_quantise(big, params.soft_step), _quantise(long_, params.soft_step))


@dataclass(frozen=True)
class GeometryEvidence:
    """The evidence of one world: hashable, so results can be cached by it.

    Attributes
    ----------
    units : tuple of int
        Unit ids (slot indices), sorted.
    geometry : tuple of (unit, class name)
        The thresholded Table 4 class of every unit.
    soft : tuple of (unit, (p_rolike, p_colike, p_halike))
        Units near a class boundary; they carry no hard geometry fact.
    muldoor : frozenset of int
        Units with multiple doors (empty when doors were not computed: see ``with_doors``).
    adj : frozenset of (p, q), p < q
        Adjacent pairs.
    with_doors : bool
        Whether doors were detected (MulDoor is meaningful).
    """

    units: tuple
    geometry: tuple
    soft: tuple = ()
    muldoor: frozenset = field(default_factory=frozenset)
    adj: frozenset = field(default_factory=frozenset)
    with_doors: bool = True

    def hard_geometry(self) -> dict:
        """``{unit: class name}`` for units with hard geometry evidence."""
        softs = {u for u, _ in self.soft}
        return {u: g for u, g in self.geometry if u not in softs}

    def facts(self) -> str:
        """Hard evidence as clingo facts (``unit/1, rolike/1, colike/1, halike/1, muldoor/1,
        adj/2``; adj in both directions). Soft evidence is in :attr:`soft`, for the engine."""
        lines = [f"unit({u})." for u in self.units]
        lines += [f"{g}({u})." for u, g in sorted(self.hard_geometry().items())]
        lines += [f"muldoor({u})." for u in sorted(self.muldoor)]
        for p, q in sorted(self.adj):
            lines += [f"adj({p},{q}).", f"adj({q},{p})."]
        return "\n".join(lines) + ("\n" if lines else "")

    def to_knowledge(self):
        """The same evidence as the knowledge engine's :class:`semmap_pp.knowledge.Evidence`
        (hard facts with probability 1, soft geometry as the three class probabilities)."""
        from semmap_pp.knowledge.evidence import Evidence as KEvidence  # imports clingo
        unary = {g: {} for g in GEOMETRY_CLASSES}
        for u, g in self.hard_geometry().items():
            unary[g][u] = 1.0
        for u, probs in self.soft:
            for g, p in zip(GEOMETRY_CLASSES, probs):
                unary[g][u] = float(p)
        return KEvidence.build(self.units, rolike=unary["rolike"], colike=unary["colike"],
                               halike=unary["halike"], muldoor=set(self.muldoor), adj=self.adj)

    def soft_log_odds(self) -> dict:
        """``{(class name, unit): log(p / (1 - p))}``: MLN weights of the soft geometry facts."""
        out = {}
        for u, probs in self.soft:
            for g, p in zip(GEOMETRY_CLASSES, probs):
                p = min(max(float(p), 1e-12), 1 - 1e-12)
                out[(g, u)] = float(np.log(p / (1 - p)))
        return out


def build_evidence(units, rects: np.ndarray, adj: np.ndarray, resolution: float, params,
                   door_counts: np.ndarray | None = None, pieces: np.ndarray | None = None) -> GeometryEvidence:
    """Evidence of the units ``units`` with rectangles ``rects`` (n, 4) and adjacency (n, n).

    Parameters
    ----------
    units : sequence of int
        Unit ids (slot indices), one per row of ``rects``.
    rects : (n, 4) int
    adj : (n, n) bool
    resolution : float
        Metres per cell.
    params : EvidenceParams
    door_counts : (n,) int, optional
        Doors per unit; ``None`` when doors were not detected (no MulDoor evidence).
    pieces : (n,) bool, optional
        Room-like units that are pieces of a corridor space (:func:`space_colike`): hard
        corridor-like evidence (:data:`PIECE_ITEM`).
    """
    units = [int(u) for u in units]
    items = [unit_geometry(int(r[2]) - int(r[0]), int(r[3]) - int(r[1]), resolution, params)
             for r in np.asarray(rects).reshape(-1, 4)]
    if pieces is not None:
        items = [PIECE_ITEM if f else it for it, f in zip(items, pieces)]
    geometry = tuple((u, GEOMETRY_CLASSES[c]) for u, (c, _) in zip(units, items))
    soft = tuple((u, pr) for u, (_, pr) in zip(units, items) if pr is not None)
    muldoor = frozenset()
    if door_counts is not None:
        muldoor = frozenset(u for u, k in zip(units, door_counts) if k >= params.multiple_doors)
    iu, ju = np.nonzero(np.triu(np.asarray(adj, dtype=bool), 1))
    pairs = frozenset((min(units[i], units[j]), max(units[i], units[j])) for i, j in zip(iu, ju))
    order = np.argsort(units)
    return GeometryEvidence(units=tuple(sorted(units)), geometry=tuple(geometry[i] for i in order),
                    soft=tuple(sorted(soft)), muldoor=muldoor, adj=pairs,
                    with_doors=door_counts is not None)


@functools.lru_cache(maxsize=1 << 16)
def unit_geometry(height: int, width: int, resolution: float, params) -> tuple:
    """Geometry evidence of one unit of ``height`` x ``width`` cells (cached by size).

    Returns ``(class index, None)`` for hard evidence, or ``(class index, (p_rolike, p_colike,
    p_halike))`` (:func:`soft_probabilities`, rounded to 6 decimals) when the class's
    probability is below ``hard_above``.
    Every evidence of the project is built from this function, so the sampler's incremental
    evidence and :func:`build_evidence` always agree.
    """
    rect = np.array([[0, 0, height, width]])
    c = int(geometry_class(rect, resolution, params)[0])
    pr = geometry_probabilities(rect, resolution, params)[0]
    if pr[c] >= params.hard_above:
        return c, None
    return c, tuple(round(float(v), 6) for v in soft_probabilities(rect, resolution, params)[0])


#: side of the square blocks of sizes :class:`GeometryTable` evaluates at once
GEOMETRY_BLOCK = 16


def unit_geometry_block(heights, widths, resolution: float, params) -> list:
    """``[unit_geometry(h, w, resolution, params) for h, w in zip(heights, widths)]`` in one
    vectorised evaluation (the same elementwise floating-point operations, so equal item by
    item; tests/unit/test_evidence.py checks it). Sizes are positive."""
    n = len(heights)
    rects = np.zeros((n, 4), dtype=np.int64)
    rects[:, 2] = heights
    rects[:, 3] = widths
    classes = geometry_class(rects, resolution, params).tolist()
    pr = geometry_probabilities(rects, resolution, params)
    hard = (pr[np.arange(n), classes] >= params.hard_above).tolist()
    soft = None if all(hard) else soft_probabilities(rects, resolution, params).tolist()
    return [(c, None) if h else (c, tuple(round(float(v), 6) for v in soft[k]))
            for k, (c, h) in enumerate(zip(classes, hard))]


class GeometryTable:
    """:func:`unit_geometry` by size for one resolution and evidence model, filled a block of
    :data:`GEOMETRY_BLOCK` x :data:`GEOMETRY_BLOCK` sizes at a time (the sampler's resizes meet
    a new size at almost every step, mostly near the sizes already seen; one vectorised block
    costs a few times one size)."""

    def __init__(self, resolution: float, params):
        self.resolution, self.params = resolution, params
        self._items: dict = {}
        self.blocks = 0

    def get(self, height: int, width: int) -> tuple:
        """``unit_geometry(height, width, resolution, params)``."""
        item = self._items.get((height, width))
        if item is None:
            b = GEOMETRY_BLOCK
            h0, w0 = max(1, height - height % b), max(1, width - width % b)
            hs, ws = np.meshgrid(np.arange(h0, h0 + b), np.arange(w0, w0 + b), indexing="ij")
            hs, ws = hs.reshape(-1).tolist(), ws.reshape(-1).tolist()
            if len(self._items) > 1 << 20:
                self._items.clear()
            self.blocks += 1
            block = unit_geometry_block(hs, ws, self.resolution, self.params)
            self._items.update(zip(zip(hs, ws), block))
            item = self._items[(height, width)]
        return item


def knowledge_evidence(units, items, muldoor, adj):
    """The knowledge engine's evidence straight from canonical parts (the sampler's fast path).

    Equal to ``build_evidence(...).to_knowledge()`` of the same world: ``units`` sorted slot ids,
    ``items`` their :func:`unit_geometry` values, ``muldoor`` the sorted units with multiple
    doors, ``adj`` the sorted pairs ``(p, q)``, ``p < q``.
    """
    global _KEvidence
    if _KEvidence is None:
        from semmap_pp.knowledge.evidence import Evidence as KEvidence  # imports clingo
        _KEvidence = KEvidence
    lists = ([], [], [])
    for u, (c, soft) in zip(units, items):
        if soft is None:
            lists[c].append((u, 1.0))
        else:
            for lst, p in zip(lists, soft):
                if p > 0.0:
                    lst.append((u, p))
    return _KEvidence(tuple(units), tuple(lists[ROLIKE]), tuple(lists[COLIKE]),
                      tuple(lists[HALIKE]), tuple((u, 1.0) for u in muldoor), tuple(adj))


_KEvidence = None   # semmap_pp.knowledge.evidence.Evidence, imported on first use (clingo)


def _put(entries: tuple, unit: int, new: tuple) -> tuple:
    """``entries`` (sorted ``(unit, ...)`` tuples, at most one per unit) with ``unit``'s entry
    replaced by ``new`` (a tuple of 0 or 1 entries), by slicing: the untouched parts are copied
    as they are."""
    i = bisect.bisect_left(entries, (unit,))
    j = i + 1 if i < len(entries) and entries[i][0] == unit else i
    if j == i and not new:
        return entries
    return entries[:i] + new + entries[j:]


def _unary_entries(item) -> tuple:
    """``(rolike, colike, halike)`` probabilities of a geometry item (None: no unit), as
    :func:`knowledge_evidence` lists them (probability 0 left out)."""
    if item is None:
        return (0.0, 0.0, 0.0)
    c, soft = item
    if soft is None:
        return tuple(1.0 if k == c else 0.0 for k in (ROLIKE, COLIKE, HALIKE))
    return soft


def patch_knowledge_evidence(ev, items: Mapping, muldoor: Mapping, adj_drop, adj_add):
    """:func:`knowledge_evidence` of a world that differs from ``ev``'s in a few units, built by
    editing ``ev`` instead of the whole world (the sampler's proposals change one to three units
    of up to hundreds).

    ``items`` maps a unit to its new :func:`unit_geometry` item (None: the unit is gone);
    ``muldoor`` a unit to whether it now has MulDoor (a unit that goes and had it: False);
    ``adj_drop`` and ``adj_add`` are the adjacent pairs ``(p, q)``, ``p < q``, that go and come.
    Every other part of ``ev`` is kept.
    Equal to the evidence built in full (tests/unit/test_evidence.py); the parts of ``ev`` that do not
    change are the same objects, so comparing and hashing them stays cheap.

    Examples
    --------
    >>> ev = knowledge_evidence([0, 1, 2], [(ROLIKE, None)] * 3, [1], [(0, 1), (1, 2)])
    >>> new = patch_knowledge_evidence(ev, {2: None, 3: (COLIKE, None)}, {1: False, 3: True},
    ...                                [(1, 2)], [(1, 3)])
    >>> new == knowledge_evidence([0, 1, 3], [(ROLIKE, None)] * 2 + [(COLIKE, None)], [3],
    ...                           [(0, 1), (1, 3)])
    True
    """
    units, lists = ev.units, [ev.rolike, ev.colike, ev.halike]
    for u, item in items.items():
        i = bisect.bisect_left(units, u)
        has = i < len(units) and units[i] == u
        if has != (item is not None):
            units = units[:i] + units[i + 1:] if has else units[:i] + (u,) + units[i:]
        for k, p in enumerate(_unary_entries(item)):
            lists[k] = _put(lists[k], u, ((u, p),) if p > 0.0 else ())
    md = ev.muldoor
    for u, flag in muldoor.items():
        md = _put(md, u, ((u, 1.0),) if flag else ())
    pairs = ev.adj
    for pq in adj_drop:
        i = bisect.bisect_left(pairs, pq)
        if i < len(pairs) and pairs[i] == pq:
            pairs = pairs[:i] + pairs[i + 1:]
    for pq in adj_add:
        i = bisect.bisect_left(pairs, pq)
        if i == len(pairs) or pairs[i] != pq:
            pairs = pairs[:i] + (pq,) + pairs[i:]
    return type(ev)(units, lists[0], lists[1], lists[2], md, pairs)


class Result(Protocol):
    """What a provider returns (the knowledge engine's result satisfies this)."""

    types: Mapping[int, np.ndarray]        # unit -> (4,) marginals over UNIT_TYPES
    sale: Mapping[tuple, float]            # (p, q), p < q -> P(SaLe(p, q))
    map_types: Mapping[int, str]           # unit -> MAP type name


class Provider(Protocol):
    """Anything that turns evidence into type and SaLe marginals: ``infer(evidence) -> Result``.

    The knowledge engine (:class:`semmap_pp.knowledge.KnowledgeEngine`) takes its own evidence
    value, :meth:`GeometryEvidence.to_knowledge`; :class:`FixedProvider` takes :class:`GeometryEvidence`.
    """

    def infer(self, evidence: GeometryEvidence) -> Result: ...


@dataclass(frozen=True)
class FixedResult:
    types: dict
    sale: dict
    map_types: dict


class FixedProvider:
    """Types from the geometry class alone (RoLi->room, CoLi->corridor, HaLi->hall) and P(SaLe)
    from the model's fixed table per type pair. Serves before knowledge is switched on.

    It needs no doors (``needs_doors = False``), so the sampler skips door detection.
    """

    needs_doors = False

    def __init__(self, fixed_sale: np.ndarray):
        self.fixed_sale = np.asarray(fixed_sale, dtype=np.float64)

    def types_of(self, geometry: np.ndarray) -> np.ndarray:
        """Type indices of units with geometry classes ``geometry`` (vectorised fast path)."""
        return GEOMETRY_TYPE[np.asarray(geometry, dtype=np.intp)]

    def infer(self, evidence: GeometryEvidence) -> FixedResult:
        eye = np.eye(len(UNIT_TYPES))
        t = {u: int(GEOMETRY_TYPE[GEOMETRY_CLASSES.index(g)]) for u, g in evidence.geometry}
        return FixedResult(
            types={u: eye[k].copy() for u, k in t.items()},
            sale={(p, q): float(self.fixed_sale[t[p], t[q]]) for p, q in sorted(evidence.adj)},
            map_types={u: UNIT_TYPES[k] for u, k in t.items()})
