"""A world.json read back onto a map's lattice: the start world of ``semmap map --start FILE``.

world.json (docs/outputs.md) gives each unit and exterior unit as four corners in the input image's
pixel frame. On the lattice of the map that run used, each is one lattice rectangle
(:meth:`semmap_pp.lattice.frame.Frame.rect_from_vertices_px`). The file may come from another run on the same
map (the paper's Fig. 7 samples from W*) or be edited by hand (a wall moved, a unit added: any
rectangle of the lattice will do; corners within :data:`MAX_OFF_PX` of one are snapped to it).
What cannot start a chain is refused with a one-line :class:`~semmap_pp.errors.SemmapError`
naming the file: not a world.json, a field of the wrong type (named by its key), written for a
map of another size or resolution, a unit that is not a rectangle of this map's lattice (the
building's orientation differs: another map, or a model whose lattice settings changed), a unit
outside the lattice or outside the prior's side range, a unit given twice (the same lattice
rectangle), or more units than a building on this map can hold (:func:`check_unit_count`,
:func:`check_overlap`: what a building's units can be is bounded by the lattice, and whatever
reads a world costs at least the number of pairs of overlapping units).

Every reader of a world.json goes through :func:`read_world_doc`, which bounds what is read
before anything is built from it: the file's size (:data:`MAX_BYTES`), its nesting and integer
digits (those of :func:`semmap_pp.evaluate.io.read_json`), and the number of units and of openings
(:data:`MAX_UNITS`, :data:`MAX_OPENINGS`).

:func:`read_previous_ids` reads a world.json's units in map-frame metres instead, for a new run on
a map that has grown since (``semmap map --ids-from FILE``: the units' ids carried over).
"""

from __future__ import annotations

import math
import os
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from semmap_pp import world as wm
from semmap_pp.errors import SemmapError
from semmap_pp.evaluate.io import read_json
from semmap_pp.model import MAX_K
from semmap_pp.semantic.ids import MAX_ID
from semmap_pp.semantic.world_json import FORMAT
from semmap_pp.lattice.tiles import rect_spans
from semmap_pp.target.prior import rect_faults

#: Corners farther than this (pixels) from their lattice rectangle's are not of this lattice.
#: world.json rounds pixel coordinates to 3 decimals, so a unit of this lattice lies within 0.001;
#: a corner moved by hand is snapped to the nearest lattice rectangle when it lies within a pixel.
MAX_OFF_PX = 1.0

#: A larger file is refused before it is read. cartesium's world.json (1237 x 672 cells, 20 units,
#: 2122 objects) is 0.3 MB, intel's (586 x 587 cells, 40 units) 0.2 MB.
MAX_BYTES = 32 * 2 ** 20

#: A file with more JSON objects and lists (``{`` and ``[``) than this is refused before it is
#: parsed: each costs 56-64 bytes of memory or more (``[{}, {}, ...]`` of 60 MB took 1.5 GB).
#: cartesium's world.json has 6,952 (one per 48 bytes), so a file of :data:`MAX_BYTES` written by
#: semmap has about 700,000.
MAX_CONTAINERS = 2_000_000

#: The most units and exterior units one world.json may list. A building's units tile its floor,
#: so their number is bounded by the map (:func:`check_unit_count`); this bounds it for the readers
#: that have no map (``semmap where``, ``route``, ``diff``, ``--ids-from``). cartesium has 20 units,
#: intel 40; a floor of 20,000 rooms would be a 400 x 400 m building of 4 x 5 m rooms.
MAX_UNITS = 20_000

#: The most doors and passages one world.json may list (a planar floor plan of n units has fewer
#: than 3n adjacent pairs; each door or passage joins one).
MAX_OPENINGS = 4 * MAX_UNITS

#: A lattice cell may lie inside (walls left out) at most this many units' rectangles. Units that
#: share a wall overlap only in their wall bands, so a building's cell lies in one unit's interior;
#: each further one costs the likelihood log(1/psi) per cell, and W* of every map run so far has at
#: most 2. A world with deeper overlap is no building, and it is what makes reading a world
#: quadratic: every two overlapping units are adjacent (2,000 copies of one unit: 2 million pairs).
MAX_OVERLAP = 4


def finite(x) -> float | None:
    """``x`` as a finite float, or None (not a number, a bool, infinite, or an int beyond floats)."""
    if isinstance(x, bool) or not isinstance(x, (int, float)):
        return None
    try:
        v = float(x)
    except OverflowError:
        return None
    return v if math.isfinite(v) else None


def _brief(x) -> str:
    """``x`` for a message: a file's value shown whole unless it is long (a 400-digit width)."""
    text = repr(x) if isinstance(x, str) else str(x)
    return text if len(text) <= 24 else text[:20] + "..."


def kind(x) -> str:
    """What a JSON value is, for a message: ``"a string"``, ``"a list"``, ``"null"``, ...

    >>> kind("395"), kind(True), kind(None), kind([1]), kind({}), kind(2.5)
    ('a string', 'true', 'null', 'a list', 'an object', 'a number')
    """
    if x is None:
        return "null"
    if isinstance(x, bool):
        return "true" if x else "false"
    if isinstance(x, str):
        return "a string"
    if isinstance(x, (int, float)):
        return "a number"
    return "a list" if isinstance(x, list) else "an object" if isinstance(x, dict) else type(x).__name__


def got(x) -> str:
    """``x`` as a message shows what a file gave: the value, and its kind unless it is a number.

    >>> got("395"), got(1.5), got([1, 2])
    ("'395' (a string)", '1.5', 'a list')
    """
    if isinstance(x, (list, dict)):
        return kind(x)
    if isinstance(x, (int, float)) and not isinstance(x, bool):
        return _brief(x)
    return f"{_brief(x)} ({kind(x)})" if isinstance(x, str) else kind(x)


_SURROGATE_ESCAPE = re.compile(rb"\\u[dD][89a-fA-F]")


def lone_surrogate(doc) -> str | None:
    """The key path (``units[0].type``) of the first string of ``doc`` (keys too) that holds a
    lone surrogate, which JSON's ``\\ud800`` escapes make and no UTF-8 output can write, or None.

    >>> lone_surrogate({"units": [{"type": "room"}, {"type": "r\\ud800"}]}), lone_surrogate({"a": ["\\U0001f600"]})
    ('units[1].type', None)
    """
    def bad(text: str) -> bool:
        try:
            text.encode("utf-8")
            return False
        except UnicodeEncodeError:
            return True

    stack = [("", doc)]
    while stack:
        where, x = stack.pop()
        if isinstance(x, str) and bad(x):
            return where or "the file"
        if isinstance(x, dict):
            for k in reversed(list(x)):
                if bad(k):
                    return f"{where or 'the file'}: a key"
                stack.append((f"{where}.{k}" if where else k, x[k]))
        elif isinstance(x, list):
            stack.extend((f"{where}[{i}]", v) for i, v in reversed(list(enumerate(x))))
    return None


def _integer(x) -> bool:
    return isinstance(x, int) and not isinstance(x, bool)


def corners(path, item, name: str, key: str = "vertices_px") -> np.ndarray:
    """``item[key]`` as four finite ``[x, y]`` corners, else one error naming ``path`` and ``name``."""
    v = item.get(key) if isinstance(item, dict) else None
    try:
        arr = np.asarray(v, dtype=np.float64)
    except (TypeError, ValueError, OverflowError):   # an int beyond floats too
        arr = None
    if arr is None or arr.shape != (4, 2) or not np.all(np.isfinite(arr)):
        raise SemmapError(path, f"{name}: '{key}' must be four [x, y] numbers")
    return arr


def read_world_doc(path, not_file: str = "not a regular file") -> dict:
    """The top-level object of the world.json at ``path``, refused when it is not a regular
    file (``not_file`` says so), is larger than :data:`MAX_BYTES`, or is not of :data:`FORMAT`."""

    p = Path(path)
    if p.exists() and not p.is_file():   # a directory, FIFO or device would fail or block
        raise SemmapError(path, not_file)
    if p.exists() and p.stat().st_size > MAX_BYTES:
        raise SemmapError(path, f"{p.stat().st_size} bytes is too large for a world.json "
                                f"(at most {MAX_BYTES})")
    try:
        with open(p, "rb") as fh:
            raw = fh.read(MAX_BYTES + 1)
    except OSError:
        raw = b""                        # read_json says what is wrong
    if len(raw) > MAX_BYTES:             # grown since its size was read
        raise SemmapError(path, f"more than {MAX_BYTES} bytes is too large for a world.json")
    containers = raw.count(b"{") + raw.count(b"[")
    if containers > MAX_CONTAINERS:
        raise SemmapError(path, f"{containers} JSON objects and lists are too many for a world.json "
                                f"(at most {MAX_CONTAINERS}; not parsed)")
    doc = read_json(path)
    if not isinstance(doc, dict) or doc.get("format") != FORMAT:
        raise SemmapError(path, f"not a world.json of semmap_pp (expected \"format\": \"{FORMAT}\")")
    if _SURROGATE_ESCAPE.search(raw):       # "\ud800": JSON escapes a character text cannot hold
        where = lone_surrogate(doc)
        if where is not None:
            raise SemmapError(path, f"{where} holds an escape of half a UTF-16 pair (\\ud800-\\udfff) "
                                    f"alone, which is no character: not text")
    for keys, most in ((("units", "exterior"), MAX_UNITS), (("doors", "passages"), MAX_OPENINGS)):
        for key in keys:
            if not isinstance(doc.get(key, []), list):
                raise SemmapError(path, f"'{key}' must be a list, got {got(doc[key])}")
        n = sum(len(doc.get(key, [])) for key in keys)
        if n > most:
            raise SemmapError(path, f"{n} {' and '.join(keys)}; a world.json holds at most {most}")
    return doc


def read_start_world(path: str | os.PathLike, frame, grid, capacity: int) -> wm.World:
    """The units and exterior units of the world.json at ``path`` as a world on ``frame``'s lattice
    (types unassigned), in ``capacity`` slots or, for more units, the smallest doubling of it
    (at most :data:`semmap_pp.model.MAX_K`).

    ``grid`` is the map the run reads (:class:`semmap_pp.grid.OccupancyGrid`): the file must have
    been written for a map of the same width, height and resolution.
    """
    return pack_world([rect for _, rect in read_world_units(path, frame, grid)], capacity, path)


def through_door_keys(path: str | os.PathLike) -> set[str]:
    """The keys (:func:`read_world_units`) of the units of the world.json at ``path`` flagged
    ``"seen_through_door": true`` (added over a room seen only through its door); a flag that is
    not a boolean is an error naming the unit."""
    doc = read_world_doc(path)
    keys = set()
    for i, u in enumerate(doc.get("units", [])):
        flag = u.get("seen_through_door", False) if isinstance(u, dict) else False
        if not isinstance(flag, bool):
            raise SemmapError(path, f"units[{i}]: 'seen_through_door' must be true or false, got {got(flag)}")
        if flag:
            keys.add(str(u.get("id", i + 1)))
    return keys


def pack_world(rects, capacity: int, path=None) -> wm.World:
    """Lattice rectangles as a world (types unassigned) in ``capacity`` slots or the smallest
    doubling of it that holds them; more than :data:`semmap_pp.model.MAX_K` is an error naming
    ``path``."""
    if len(rects) > MAX_K:
        raise SemmapError(path, f"{len(rects)} units; a world holds at most {MAX_K}")
    size_k = max(1, int(capacity))
    while size_k < len(rects):   # doubled as the ascent grows a full world (ascent._Ascent.free)
        size_k = min(2 * size_k, MAX_K)
    world = wm.empty(size_k)
    for slot, rect in enumerate(rects):
        world = wm.add(world, slot, rect)
    return world


def read_world_units(path: str | os.PathLike, frame, grid) -> list[tuple[str, tuple[int, int, int, int]]]:
    """The units and exterior units of the world.json at ``path`` on ``frame``'s lattice, in the
    file's order, each as ``(key, rect)``: the key is the unit's id as text (``"7"``; ``"X2"`` for
    exterior unit 2), the position in its list when it has none. Checked as
    :func:`read_start_world` says."""
    doc = read_world_doc(path)
    m = check_map_size(path, doc, grid)
    items = []
    for key, prefix, noun in (("units", "", "unit "), ("exterior", "X", "exterior unit ")):
        for i, u in enumerate(doc.get(key, [])):
            if not isinstance(u, dict):
                raise SemmapError(path, f"{key}[{i}] must be an object, got {got(u)}")
            uid = u.get("id", i + 1)
            if not _integer(uid) or uid < 1:
                raise SemmapError(path, f"{key}[{i}]: 'id' must be an integer of at least 1, got {got(uid)}")
            items.append((f"{noun}{prefix}{uid}", f"{prefix}{uid}", u, f"{key}[{i}]"))
    c = frame.cells
    check_unit_count(path, len(items), frame.shape, c.min_side, c.wall)
    rects, first = [], {}
    for name, key, item, place in items:
        rect, off = frame.rect_from_vertices_px(corners(path, item, name))
        if off > MAX_OFF_PX:
            raise SemmapError(path, f"{name} is not a rectangle of this map's lattice (its corners lie "
                                    f"{off:.2f} px from the nearest one; the building's orientation here "
                                    f"is {math.degrees(frame.theta):.1f} deg, the file's "
                                    f"{_brief(m.get('orientation_deg', '?'))}): was it written for this "
                                    f"map and model?")
        r0, c0, r1, c1 = rect
        faults = rect_faults(rect, frame.shape, c.min_side, c.max_side, rect_spans(frame))
        if "outside" in faults:
            raise SemmapError(path, f"{name} reaches beyond the map's lattice ({frame.shape[0]} x "
                                    f"{frame.shape[1]} cells; the unit spans rows {r0}..{r1}, columns "
                                    f"{c0}..{c1})")
        if "straddles" in faults:
            raise SemmapError(path, f"{name} lies across two of the building's directions (zones of "
                                    f"the lattice at different angles): was it written for this map "
                                    f"and model?")
        if faults:
            raise SemmapError(path, f"{name} is {r1 - r0} x {c1 - c0} cells; the model allows sides of "
                                    f"{c.min_side} to {c.max_side} cells ([world] min_unit_side_m, "
                                    f"max_unit_side_m)")
        if rect in first:
            was, where = first[rect]
            this, that = (name, was) if name != was else (f"{name} ({place})", f"{was} ({where})")
            raise SemmapError(path, f"{this} is the same lattice rectangle as {that}: a unit given "
                                    f"twice (remove one)")
        first[rect] = (name, place)
        rects.append((key, rect))
    check_overlap(path, [name for name, *_ in items], [r for _, r in rects], frame.shape, c.wall)
    return rects


def check_map_size(path, doc: dict, grid) -> dict:
    """``doc["map"]``, refused unless its ``width``, ``height`` and ``resolution`` are numbers of
    the right kind (each named when it is not) and those of ``grid``."""
    m = doc.get("map")
    if not isinstance(m, dict):
        raise SemmapError(path, f"'map' must be an object with the map's width, height and "
                                f"resolution, got {got(m)}")
    for key in ("width", "height"):
        if not _integer(m.get(key)) or m[key] < 1:
            raise SemmapError(path, f"map.{key} must be a positive integer (pixels), got {got(m.get(key))}")
    given = m.get("resolution")
    if isinstance(given, bool) or not isinstance(given, (int, float)):
        raise SemmapError(path, f"map.resolution must be a number (m/cell), got {got(given)}")
    res = finite(given)         # None beyond floats: not this map's either
    here = (grid.width, grid.height, grid.resolution)
    if (m["width"], m["height"]) != here[:2] or res is None or not math.isclose(res, here[2], rel_tol=1e-9):
        raise SemmapError(path, f"written for a {_brief(m['width'])}x{_brief(m['height'])} map at "
                                f"{_brief(m['resolution'])} m/cell; this map is {here[0]}x{here[1]} "
                                f"at {here[2]} m/cell")
    return m


def lattice_fit(shape, min_side: int, wall: int) -> int:
    """How many units of the smallest side fit on a lattice of ``shape`` side by side, each two
    neighbours sharing a wall band of ``wall`` cells (as a building's rooms do).

    >>> lattice_fit((100, 60), 20, 3), lattice_fit((19, 500), 20, 3)
    (15, 0)
    """
    pitch = max(1, min_side - wall)
    rows, cols = ((max(0, n - min_side) // pitch + 1) if n >= min_side else 0 for n in shape)
    return rows * cols


def check_unit_count(path, n: int, shape, min_side: int, wall: int) -> None:
    """Refuse ``n`` units (and exterior units) on a lattice of ``shape`` when they are more than
    :data:`MAX_OVERLAP` layers of the units that fit it side by side (:func:`lattice_fit`):
    more than any world of this map whose units overlap at most that deep could hold. Checked
    before any unit is read."""
    fit = lattice_fit(shape, min_side, wall)
    if n > MAX_OVERLAP * fit:
        raise SemmapError(path, f"{n} units and exterior units; this map holds at most "
                                f"{MAX_OVERLAP * fit}: {fit} units of the smallest side ({min_side} x "
                                f"{min_side} cells, neighbours sharing a {wall}-cell wall) fit its "
                                f"lattice of {shape[0]} x {shape[1]} cells, and a world's units overlap "
                                f"at most {MAX_OVERLAP} deep")


def check_overlap(path, names: list[str], rects: list, shape, wall: int) -> None:
    """Refuse lattice rectangles whose interiors (each side less its wall band of ``wall``
    cells) overlap more than :data:`MAX_OVERLAP` deep at some cell, naming the units there.
    Costs one pass over the lattice (a cumulative count of the interiors' corners)."""
    if len(rects) <= MAX_OVERLAP:
        return
    r = np.asarray(rects, np.int64).reshape(-1, 4)
    inner = np.column_stack([r[:, 0] + wall, r[:, 1] + wall, r[:, 2] - wall, r[:, 3] - wall])
    inner = inner[(inner[:, 2] > inner[:, 0]) & (inner[:, 3] > inner[:, 1])]
    depth = np.zeros((shape[0] + 1, shape[1] + 1), np.int32)
    for (r0, c0, r1, c1), sign in ((inner[:, [0, 1, 2, 3]].T, 1), (inner[:, [0, 3, 2, 1]].T, -1)):
        np.add.at(depth, (r0, c0), sign)
        np.add.at(depth, (r1, c1), sign)
    np.cumsum(depth, axis=0, out=depth)
    np.cumsum(depth, axis=1, out=depth)
    deepest = int(depth.max(initial=0))
    if deepest <= MAX_OVERLAP:
        return
    row, col = np.unravel_index(int(np.argmax(depth)), depth.shape)
    here = [names[i] for i in range(len(rects)) if rects[i][0] + wall <= row < rects[i][2] - wall
            and rects[i][1] + wall <= col < rects[i][3] - wall]
    shown = ", ".join(here[:4]) + (f" and {len(here) - 4} more" if len(here) > 4 else "")
    raise SemmapError(path, f"{deepest} units overlap at lattice row {row}, column {col} ({shown}): "
                            f"a world's units overlap at most {MAX_OVERLAP} deep (walls left out)")


@dataclass(frozen=True)
class PreviousIds:
    """The units of an earlier world.json in map-frame metres, whose ids a new run carries over
    (``semmap map --ids-from FILE``, :func:`semmap_pp.semantic.ids.carry_ids`)."""

    path: Path
    ids: tuple[int, ...]
    corners_m: np.ndarray      # (n, 4, 2) each unit's ``vertices_m``
    next_id: int               # the first id the file's numbering never used


def read_run_world(path: str | os.PathLike) -> tuple:
    """``(path, doc)``: the world.json at ``path``, or in the folder ``path`` (a run's), read as
    :func:`read_world_doc` reads it; ``path`` is then the file's, for messages."""
    p = Path(path)
    if p.is_dir() and (p / "world.json").is_file():   # a run's folder
        path = p / "world.json"
    return path, read_world_doc(path, "not a regular file (a world.json, or a run's folder that holds one)")


def read_previous_ids(path: str | os.PathLike) -> PreviousIds:
    """The units of the world.json at ``path`` (or in the folder ``path``, an earlier run's) with
    their ids and corners in metres.

    Unlike :func:`read_world_units` it does not ask for the same map: a SLAM map grows between
    updates (size and origin change, the ``map`` frame stays), so units are read in metres. Each
    unit needs an integer ``id`` of at least 1, unique in the file, and four finite ``vertices_m``;
    the next id is the file's own ``ids.next`` when it carries one (ids that went away are not
    given again), else its largest id + 1. Anything else is one :class:`SemmapError` naming the
    file. Exterior units are not read: their ids are numbered afresh in every file.
    """
    path, doc = read_run_world(path)
    return previous_ids_from_doc(doc, path)


def previous_ids_from_doc(doc: dict, path) -> PreviousIds:
    """:func:`read_previous_ids` of a world.json's content, already read from ``path``."""
    units = doc.get("units", [])
    if not isinstance(units, list):
        raise SemmapError(path, "'units' must be a list")
    ids, quads, seen, where = [], [], set(), {}
    for i, u in enumerate(units):
        uid = u.get("id") if isinstance(u, dict) else None
        if isinstance(uid, bool) or not isinstance(uid, int) or not 1 <= uid <= MAX_ID:
            raise SemmapError(path, f"unit {i + 1} of the list: 'id' must be an integer from 1 to "
                                    f"{MAX_ID}, got {_brief(uid)}")
        if uid in seen:
            raise SemmapError(path, f"unit id {uid} is used twice")
        quads.append(corners(path, u, f"unit {uid}", "vertices_m"))
        same = where.setdefault((quads[-1] + 0.0).tobytes(), uid)
        if same != uid:
            raise SemmapError(path, f"unit {uid} has the same corners as unit {same}: a unit given "
                                    f"twice (remove one)")
        ids.append(uid)
        seen.add(uid)
    nxt = max(ids, default=0) + 1
    listed = doc.get("ids")
    if isinstance(listed, dict) and "next" in listed:
        given = listed["next"]
        if isinstance(given, bool) or not isinstance(given, int) or not 1 <= given <= MAX_ID:
            raise SemmapError(path, f"ids.next must be an integer from 1 to {MAX_ID}, got {_brief(given)}")
        nxt = max(nxt, given)
    if nxt > MAX_ID:
        raise SemmapError(path, f"no unit id is left after {MAX_ID} (labels.png holds 16-bit ids)")
    return PreviousIds(Path(path), tuple(ids), np.asarray(quads, np.float64).reshape(-1, 4, 2), nxt)
