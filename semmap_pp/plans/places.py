"""Questions a robot's program asks of a world.json: which unit holds a map point, and which
doors and passages lead from one place to another.

Everything is in map-frame metres, as tf gives a robot's pose in the ``map`` frame and as
world.json's ``vertices_m``, ``center_m`` and the openings' ``center_m`` are. A unit is the
rectangle of its four ``vertices_m`` (walls included), so a point on the wall two units share lies
in both. Units are joined by their **doors** and **passages** (open stretches of a shared wall,
where a corridor was cut into pieces or opens into a hall, and free floor between two units that
do not touch; world.json's ``passages``; a file of an older semmap_pp has none, and
:attr:`Places.has_passages` says so).

A route (:meth:`Places.route`) is the shortest chain of straight segments from the start through
opening centres to the goal, each segment inside one unit's rectangle (a rectangle is convex, so
a segment between two points of it stays in it). Its length is what those segments add up to; it
does not steer around furniture, which is the local planner's job. Units joined only by a wall
(world.json's ``adjacency`` without an opening) are not passable, and exterior units (free space
outside the building) are never on a route.

Pure: a world.json's content in, answers out; :func:`read_places` checks the file and says in one
line (:class:`~semmap_pp.errors.SemmapError`, naming it) what is wrong.
"""

from __future__ import annotations

import heapq
import math
import os
import re
from collections import Counter
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

import numpy as np

from semmap_pp.cells import TYPE_LETTER
from semmap_pp.errors import SemmapError
from semmap_pp.plans.world_file import corners, finite, read_run_world

_ID = re.compile(r"^([RCHEX]?)(\d+)$", re.IGNORECASE)

#: A point this far (metres) outside a rectangle still lies in it: world.json rounds metres to 1e-4.
EDGE_TOLERANCE_M = 1e-3

#: Coordinates farther than this (metres) from the map frame's origin are refused: no building is
#: that large, and products of such numbers overflow.
MAX_COORD_M = 1e9

#: The most doors and passages one unit may have. A route looks at every opening of a unit from
#: each of them, so its cost grows with the square of this; a long corridor of a large building
#: has some tens.
MAX_UNIT_OPENINGS = 256


def unit_key(text: str) -> str:
    """The key of a unit id as typed: ``"7"``, ``"R7"``, ``"c7"`` -> ``"7"``; ``"X2"`` -> ``"X2"``
    (exterior unit 2). Raises ValueError for anything else.

    >>> [unit_key(t) for t in ("7", "R7", "e12", "x2")]
    ['7', '7', '12', 'X2']
    """
    m = _ID.match(text.strip())
    if not m:
        raise ValueError(f"{text!r} is not a unit id (7, R7, C7, H7, E7, or X2 for an exterior unit)")
    return ("X" if m.group(1).upper() == "X" else "") + str(int(m.group(2)))


@dataclass(frozen=True)
class Unit:
    """A unit of a world.json: ``key`` is its id as text (``"7"``, ``"X2"`` for an exterior unit)."""

    key: str
    type: str                     # room / corridor / hall / other; "exterior" for an exterior unit
    corners: np.ndarray           # (4, 2) vertices_m, in order around the rectangle
    center: tuple[float, float]

    @property
    def exterior(self) -> bool:
        return self.key.startswith("X")

    @property
    def label(self) -> str:
        """``R7`` / ``C7`` / ``H7`` / ``E7`` as overlay.png shows it, ``X2`` for an exterior unit."""
        return self.key if self.exterior else TYPE_LETTER.get(self.type, "") + self.key

    @property
    def size_m(self) -> tuple[float, float]:
        """``(length, width)`` of the rectangle, walls included."""
        a, b = (float(np.hypot(*(self.corners[i + 1] - self.corners[i]))) for i in (0, 1))
        return max(a, b), min(a, b)

    def holds(self, x: float, y: float) -> bool:
        """Whether the map point lies in the rectangle (its edges, within
        :data:`EDGE_TOLERANCE_M`, included).

        >>> u = Unit("1", "room", np.array([[0., 0.], [4., 0.], [4., 3.], [0., 3.]]), (2., 1.5))
        >>> u.holds(4.0, 1.0), u.holds(4.01, 1.0), u.holds(2.0, -0.0005)
        (True, False, True)
        """
        v, p = self.corners, np.array([x, y], float)
        edges = np.roll(v, -1, axis=0) - v
        lengths = np.hypot(edges[:, 0], edges[:, 1])
        cross = edges[:, 0] * (p[1] - v[:, 1]) - edges[:, 1] * (p[0] - v[:, 0])
        dist = cross / np.where(lengths > 0, lengths, 1.0)     # signed distance from each edge
        sign = 1.0 if _area(v) >= 0 else -1.0
        return bool(np.all(sign * dist >= -EDGE_TOLERANCE_M))


@dataclass(frozen=True)
class Opening:
    """A door or a passage between two units (world.json ``doors[]`` / ``passages[]``)."""

    kind: str                     # "door" or "passage"
    id: int
    units: tuple[str, str]
    center: tuple[float, float]
    width_m: float

    def other(self, key: str) -> str:
        return self.units[1] if self.units[0] == key else self.units[0]


@dataclass(frozen=True)
class Step:
    """One opening passed on a route, from one unit into the next."""

    opening: Opening
    from_unit: Unit
    into: Unit


@dataclass(frozen=True)
class Route:
    """The shortest way through doors and passages (:meth:`Places.route`)."""

    start: tuple[float, float]
    goal: tuple[float, float]
    start_unit: Unit
    goal_unit: Unit
    steps: tuple[Step, ...]
    length_m: float

    @property
    def waypoints(self) -> list[tuple[float, float]]:
        """The start, every opening's centre and the goal, in metres."""
        return [self.start, *(s.opening.center for s in self.steps), self.goal]

    @property
    def units(self) -> list[str]:
        """The keys of the units the route passes through, in order."""
        return [self.start_unit.key, *(s.into.key for s in self.steps)]

    def to_dict(self) -> dict:
        def unit(u: Unit) -> dict:
            return {"id": int(u.key), "type": u.type, "label": u.label}
        return {"from": {**unit(self.start_unit), "point_m": _rounded(self.start)},
                "to": {**unit(self.goal_unit), "point_m": _rounded(self.goal)},
                "length_m": round(self.length_m, 3),
                "units": [int(k) for k in self.units],
                "steps": [{"kind": s.opening.kind, "id": s.opening.id, "width_m": s.opening.width_m,
                           "center_m": _rounded(s.opening.center), "from": int(s.from_unit.key),
                           "into": int(s.into.key)} for s in self.steps],
                "waypoints_m": [_rounded(p) for p in self.waypoints]}

    def text(self) -> str:
        """The route as lines a person reads: one per opening passed."""
        counts = {k: sum(s.opening.kind == k for s in self.steps) for k in ("door", "passage")}
        parts = [f"{n} {k}{'s' if n != 1 else ''}" for k, n in counts.items() if n]
        lines = [f"route from {self.start_unit.label} ({self.start_unit.type}) to {self.goal_unit.label} "
                 f"({self.goal_unit.type}): {self.length_m:.2f} m"
                 + (f" through {' and '.join(parts)}" if parts else ", inside one unit")]
        lines.append(f"  {'start':<11}{_xy(self.start)}  in {self.start_unit.label}")
        for s in self.steps:
            o = s.opening
            lines.append(f"  {o.kind + ' ' + str(o.id):<11}{_xy(o.center)}  {o.width_m:.2f} m wide, "
                         f"from {s.from_unit.label} into {s.into.label} ({s.into.type})")
        lines.append(f"  {'goal':<11}{_xy(self.goal)}  in {self.goal_unit.label}")
        return "\n".join(lines)


def _rounded(p) -> list[float]:
    return [round(float(v), 4) for v in p]


def _xy(p) -> str:
    return f"x {p[0]:9.3f}  y {p[1]:9.3f}"


def _area(v: np.ndarray) -> float:
    return 0.5 * float(np.sum(v[:, 0] * np.roll(v[:, 1], -1) - np.roll(v[:, 0], -1) * v[:, 1]))


@dataclass(frozen=True)
class Places:
    """The units and openings of one world.json (:func:`read_places`)."""

    path: Path | None
    units: tuple[Unit, ...]           # the building's units, in the file's order
    exterior: tuple[Unit, ...]
    openings: tuple[Opening, ...]     # doors, then passages
    has_passages: bool                # False for a file written before world.json listed passages

    def unit(self, key: str) -> Unit:
        """The unit with this id as typed (``7``, ``R7``, ``X2``); an unknown one is a
        :class:`SemmapError` naming the file and the ids it has."""
        try:
            k = unit_key(key)
        except ValueError as exc:
            raise SemmapError(self.path, str(exc)) from None
        if k in self.by_key:
            return self.by_key[k]
        listed = ", ".join(u.label for u in self.units)
        raise SemmapError(self.path, f"no unit {key} in this world (its units: {listed or 'none'})")

    @cached_property
    def by_key(self) -> dict[str, Unit]:
        """Unit key (``"7"``, ``"X2"``) -> the unit: the building's units and exterior units."""
        return {u.key: u for u in (*self.units, *self.exterior)}

    def units_at(self, x: float, y: float) -> list[Unit]:
        """Every unit whose rectangle holds the map point: the building's units in the file's
        order, then exterior units. Two when the point lies on the wall two units share."""
        return [u for u in (*self.units, *self.exterior) if u.holds(x, y)]

    def openings_of(self, key: str) -> list[Opening]:
        return [self.openings[i] for i in self._openings_by_unit.get(key, ())]

    @cached_property
    def _openings_by_unit(self) -> dict[str, list[int]]:
        """Unit key -> the indices of its openings, in the file's order."""
        out: dict[str, list[int]] = {}
        for i, o in enumerate(self.openings):
            for k in dict.fromkeys(o.units):
                out.setdefault(k, []).append(i)
        return out

    def route(self, start, goal) -> Route | None:
        """The shortest route from ``start`` to ``goal`` through doors and passages, or None when
        no chain of openings joins them. Each end is a :class:`Unit` (its centre) or a map point
        ``(x, y)`` in metres inside a building unit (on a shared wall: either unit will do).
        A point in no building unit is a :class:`SemmapError`."""
        (p0, starts), (p1, goals) = self._end(start, "start"), self._end(goal, "goal")
        by_key = {u.key: u for u in self.units}
        # nodes: "S", "G" and the openings' indices; an edge is a straight segment inside one unit
        best: dict = {"S": 0.0}
        back: dict = {}
        heap = [(0.0, 0, "S")]
        tie = 1
        seen = set()
        while heap:
            d, _, node = heapq.heappop(heap)
            if node in seen:
                continue
            seen.add(node)
            if node == "G":
                break
            for nxt, unit, length in self._edges(node, p0, p1, starts, goals):
                nd = d + length
                if nd < best.get(nxt, math.inf) - 1e-12:
                    best[nxt], back[nxt] = nd, (node, unit)
                    heapq.heappush(heap, (nd, tie, nxt))
                    tie += 1
        if "G" not in seen:
            return None
        path = ["G"]
        while path[-1] != "S":
            path.append(back[path[-1]][0])
        path.reverse()
        units = [back[n][1] for n in path[1:]]         # the unit of each segment, in order
        steps = tuple(Step(self.openings[n], by_key[units[i]], by_key[units[i + 1]])
                      for i, n in enumerate(path[1:-1]))
        return Route(p0, p1, by_key[units[0]], by_key[units[-1]], steps, best["G"])

    def _end(self, end, what: str) -> tuple[tuple[float, float], list[str]]:
        if isinstance(end, Unit):
            if end.exterior:
                raise SemmapError(self.path, f"the {what} {end.label} is an exterior unit (free space "
                                             f"outside the building): no door leads there")
            return end.center, [end.key]
        x, y = (float(v) for v in end)
        inside = [u.key for u in self.units if u.holds(x, y)]
        if not inside:
            outside = [u.label for u in self.exterior if u.holds(x, y)]
            where = f" (it lies in exterior unit {outside[0]})" if outside else ""
            raise SemmapError(self.path, f"no unit of the building holds the {what} point "
                                         f"{x:g} {y:g}{where}")
        return (x, y), inside

    def _edges(self, node, p0, p1, starts, goals):
        """``(next node, unit key, length)`` of every segment from ``node``."""
        if node == "S":
            here = [(k, p0) for k in starts]
        else:
            o = self.openings[node]
            here = [(k, o.center) for k in o.units]
        for key, p in here:
            for i in self._openings_by_unit.get(key, ()):
                if i != node:
                    yield i, key, math.dist(p, self.openings[i].center)
            if key in goals:
                yield "G", key, math.dist(p, p1)


def _point(value) -> tuple[float, float] | None:
    """``[x, y]`` as two finite floats, or None."""

    xy = [finite(v) for v in value] if isinstance(value, list) and len(value) == 2 else None
    if xy is None or None in xy or max(abs(xy[0]), abs(xy[1])) > MAX_COORD_M:
        return None
    return xy[0], xy[1]


def read_places(path: str | os.PathLike) -> Places:
    """The units, exterior units, doors and passages of the world.json at ``path`` (or in the
    folder ``path``, a run's), checked as :func:`places_from_doc` says."""

    path, doc = read_run_world(path)
    return places_from_doc(doc, Path(path))


def places_from_doc(doc: dict, path: Path | None = None) -> Places:
    """The places of a world.json's content. Each unit needs an integer ``id`` (unique), a
    ``type`` and four finite ``vertices_m``; each door and passage an integer ``id``, two
    ``units`` of the file, a finite ``center_m`` and ``width_m``; coordinates lie within
    :data:`MAX_COORD_M`. Anything else is one :class:`SemmapError` naming ``path``."""

    found: dict[str, list[Unit]] = {}
    where: dict[bytes, str] = {}        # a unit's corners -> the first unit with them
    for key, prefix in (("units", ""), ("exterior", "X")):
        listed = doc.get(key, [])
        if not isinstance(listed, list):
            raise SemmapError(path, f"'{key}' must be a list")
        out = found.setdefault(key, [])
        for i, u in enumerate(listed):
            uid = u.get("id") if isinstance(u, dict) else None
            if isinstance(uid, bool) or not isinstance(uid, int) or uid < 1:
                raise SemmapError(path, f"{key}[{i}]: 'id' must be an integer of at least 1")
            name = f"{'exterior ' if prefix else ''}unit {prefix}{uid}"
            kind = "exterior" if prefix else u.get("type")
            if not isinstance(kind, str):
                raise SemmapError(path, f"{name}: 'type' must be a string")
            v = corners(path, u, name, "vertices_m")
            if np.abs(v).max() > MAX_COORD_M:
                raise SemmapError(path, f"{name}: 'vertices_m' lie beyond {MAX_COORD_M:g} m of the origin")
            same = where.setdefault((v + 0.0).tobytes(), name)     # + 0.0: -0.0 is 0.0
            if same != name:
                raise SemmapError(path, f"{name} has the same corners as {same}: a unit given twice "
                                        f"(remove one)")
            c = _point(u.get("center_m"))     # the file's own centre, else the corners' mean
            out.append(Unit(f"{prefix}{uid}", kind, v,
                            c if c is not None else (float(v[:, 0].mean()), float(v[:, 1].mean()))))
    counts = Counter(u.key for u in found["units"] + found["exterior"])
    twice = sorted(k for k, n in counts.items() if n > 1)
    if twice:
        raise SemmapError(path, f"unit id {twice[0]} is used twice")
    inside = {u.key for u in found["units"]}
    openings = []
    for key, kind in (("doors", "door"), ("passages", "passage")):
        listed = doc.get(key, [])
        if not isinstance(listed, list):
            raise SemmapError(path, f"'{key}' must be a list")
        for i, o in enumerate(listed):
            oid = o.get("id") if isinstance(o, dict) else None
            if isinstance(oid, bool) or not isinstance(oid, int) or oid < 1:
                raise SemmapError(path, f"{key}[{i}]: 'id' must be an integer of at least 1")
            name = f"{kind} {oid}"
            pair = o.get("units")
            if not isinstance(pair, list) or len(pair) != 2 or not all(
                    not isinstance(k, bool) and isinstance(k, int) and str(k) in inside for k in pair):
                raise SemmapError(path, f"{name}: 'units' must be two ids of the file's units")
            xy = _point(o.get("center_m"))
            width = finite(o.get("width_m"))
            if xy is None:
                raise SemmapError(path, f"{name}: 'center_m' must be two finite numbers within "
                                        f"{MAX_COORD_M:g} m of the origin")
            if width is None or width <= 0:
                raise SemmapError(path, f"{name}: 'width_m' must be a positive number")
            openings.append(Opening(kind, oid, (str(pair[0]), str(pair[1])), xy, width))
    per_unit = Counter(k for o in openings for k in dict.fromkeys(o.units))
    busiest = max(per_unit, key=per_unit.get, default=None)
    if busiest is not None and per_unit[busiest] > MAX_UNIT_OPENINGS:
        raise SemmapError(path, f"unit {busiest} has {per_unit[busiest]} doors and passages; a unit has "
                                f"at most {MAX_UNIT_OPENINGS}")
    return Places(path, tuple(found["units"]), tuple(found["exterior"]), tuple(openings), "passages" in doc)


__all__ = ["EDGE_TOLERANCE_M", "MAX_COORD_M", "MAX_UNIT_OPENINGS", "Opening", "Places", "Route", "Step", "TYPE_LETTER", "Unit",
           "places_from_doc", "read_places", "unit_key"]
