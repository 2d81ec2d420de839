"""Hand edits of a world on its map's lattice: what ``semmap edit`` applies to a world.json.

A person who knows the building better than the search (a room the search left joined to the
corridor, a wall it missed) says so in the terms the outputs give: units by the id that
world.json, overlay.png and labels.png show (``7``, or ``R7`` / ``C7`` / ``H7`` / ``E7`` as
overlay.png labels it; ``X2`` for exterior unit 2), and places by points read off the map, in
map-frame metres (as world.json's ``vertices_m`` and world.geojson) or, with ``pixels=True``,
in the input image's pixel frame (as ``vertices_px``: x = column, y = row). Every point becomes
a fractional lattice coordinate (:class:`Point`; an integer is a cell's centre), and every edit
is a change of lattice rectangles:

* ``drop ID [ID ...]``: the units go;
* ``merge ID ID [ID ...]``: the units become their bounding box, under the first one's id;
* ``cut ID X0 Y0 X1 Y1``: a new wall along the line from the first point to the second (its
  direction snapped to the nearer lattice axis, placed at the points' mean), the two pieces
  sharing its band as the SPLIT kernel's pieces do; a point one might read off the wall's two
  ends;
* ``wall ID X Y``: the unit's side nearest the point moves so that its wall band is centred on it;
* ``add X0 Y0 X1 Y1``: a new unit whose walls are centred on the two opposite corners.

A point read off a map is a few centimetres off the wall it means; ``semmap edit`` then moves
the edited units' walls to their best positions nearby (:func:`semmap_pp.sampler.ascent.snap_walls`).

Edits apply in the order given; a unit dropped, merged away or cut cannot be named by a later
edit of the same call (its pieces have no id yet: edit the written file again). Each edit's
result must be a valid unit of the model (sides within ``[world] min_unit_side_m`` ..
``max_unit_side_m``, inside the lattice); else :class:`~semmap_pp.errors.SemmapError` names the
world file and the edit. Pure: rectangles in, rectangles out.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from semmap_pp.errors import SemmapError
from semmap_pp.plans.places import unit_key
from semmap_pp.sampler.kernels.split_merge import pieces
from semmap_pp.lattice.tiles import rect_spans
from semmap_pp.target.prior import rect_faults

#: The edits and the number of arguments each takes (``None``: one id or more).
EDITS = {"drop": None, "merge": None, "cut": 5, "wall": 3, "add": 4}


@dataclass(frozen=True)
class Edit:
    """One edit as given: its kind (a key of :data:`EDITS`) and its arguments as typed."""

    kind: str
    args: tuple[str, ...]

    def __str__(self) -> str:
        return f"--{self.kind} {' '.join(self.args)}"


def _number(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise ValueError(f"{text!r} is not a number") from None
    if not math.isfinite(v):
        raise ValueError(f"{text!r} is not a finite number")
    return v


def check_args(edit: Edit) -> None:
    """Raise ValueError unless ``edit``'s arguments have the right count and form (ids, numbers)."""
    n = EDITS[edit.kind]
    a = edit.args
    if n is None:
        if len(a) < (2 if edit.kind == "merge" else 1):
            raise ValueError(f"--{edit.kind} needs {'two unit ids or more' if edit.kind == 'merge' else 'a unit id'}")
        for t in a:
            unit_key(t)
        return
    if len(a) != n:
        raise ValueError(f"--{edit.kind} takes {n} values, got {len(a)}")
    ids = 0 if edit.kind == "add" else 1
    for t in a[:ids]:
        unit_key(t)
    for t in a[ids:]:
        _number(t)


@dataclass(frozen=True)
class Point:
    """A point as a fractional lattice coordinate (row, col); an integer is a cell's centre."""

    row: float
    col: float


def to_image(frame, x: float, y: float, *, pixels: bool = False) -> tuple[float, float]:
    """The image point ``[x, y]`` (continuous pixel frame) of a map-frame point in metres, or of an
    image point given in pixels."""
    if not pixels:
        x, y = frame.metres_to_image(x, y)
    return float(x), float(y)


def to_lattice(frame, x: float, y: float, *, pixels: bool = False, tile: int | None = None) -> Point:
    """The lattice coordinate of a map-frame point (metres), or of an image point (pixels); on a
    lattice of several directions, on tile ``tile``'s (default: the tile of the point's zone)."""
    x, y = to_image(frame, x, y, pixels=pixels)
    if tile is not None and rect_spans(frame):
        r, c = frame.tile_image_to_lattice(tile, x - 0.5, y - 0.5)
    else:
        r, c = frame.image_to_lattice(x - 0.5, y - 0.5)
    return Point(float(r), float(c))


def _band_start(centre: float, t: int) -> int:
    """The first row (or column) of a ``t``-cell band whose centre lies nearest ``centre``."""
    return int(math.floor(centre - (t - 1) / 2.0 + 0.5))


def _cut(rect, p: Point, q: Point, g: int):
    """``rect`` cut along the line p-q; the pieces share a ``g``-cell band centred on the line."""
    axis = 0 if abs(q.row - p.row) <= abs(q.col - p.col) else 1   # a line along columns bounds rows
    centre = (p.row + q.row) / 2 if axis == 0 else (p.col + q.col) / 2
    s = _band_start(centre, g) + g
    return axis, s, pieces(rect, axis, s, g)


def _wall(rect, p: Point, t: int):
    """``rect`` with its side nearest ``p`` moved so that its ``t``-cell band is centred on ``p``."""
    r0, c0, r1, c1 = rect
    centres = {0: r0 + (t - 1) / 2, 2: r1 - 1 - (t - 1) / 2, 1: c0 + (t - 1) / 2, 3: c1 - 1 - (t - 1) / 2}
    at = {0: p.row, 2: p.row, 1: p.col, 3: p.col}
    side = min(centres, key=lambda k: (abs(at[k] - centres[k]), k))
    start = _band_start(at[side], t)
    out = list(rect)
    out[side] = start if side < 2 else start + t
    return tuple(out)


def _box(p: Point, q: Point, t: int):
    """The rectangle whose wall bands are centred on the corners ``p`` and ``q``."""
    lo_r, hi_r = sorted((p.row, q.row))
    lo_c, hi_c = sorted((p.col, q.col))
    return (_band_start(lo_r, t), _band_start(lo_c, t), _band_start(hi_r, t) + t, _band_start(hi_c, t) + t)


def edit_origins(edits: list[Edit]) -> list[str]:
    """The edit that made each new unit of :func:`apply_edits` (its key-None entries), in its
    order: two pieces per ``--cut``, one unit per ``--add``.

    >>> [str(o) for o in edit_origins([Edit("drop", ("3",)), Edit("cut", ("1", "0", "0", "1", "1")),
    ...                                Edit("add", ("0", "0", "2", "2"))])]
    ['--cut 1 0 0 1 1', '--cut 1 0 0 1 1', '--add 0 0 2 2']
    """
    out = []
    for edit in edits:
        out += [str(edit)] * {"cut": 2, "add": 1}.get(edit.kind, 0)
    return out


def id_changes(edited: list[tuple], origins: list[str], slot_ids: dict, exterior_ids: dict,
               letters: dict) -> list[dict]:
    """What each unit of the written world was: ``edited`` as :func:`apply_edits` returns it,
    slot ``i`` holding its ``i``-th unit (:func:`semmap_pp.plans.world_file.pack_world`), ``origins``
    from :func:`edit_origins`, and the written world's numbering (``slot_ids``: slot -> id,
    ``exterior_ids``: slot -> exterior id; ``letters``: slot -> its type's letter). One
    ``{"was", "now", "by"}`` per unit, in the new file's order (the building's units, then the
    exterior ones): ``was`` the key in the edited file (None for a new unit), ``now`` the id in
    the written one (``"R3"``, ``"X2"``), ``by`` the edit that made a new unit (else None)."""
    new_origin = iter(origins)
    rows = []
    for i, (key, _rect, _changed) in enumerate(edited):
        by = next(new_origin) if key is None else None
        if i in slot_ids:
            rows.append(((0, slot_ids[i]), {"was": key, "now": f"{letters.get(i, '')}{slot_ids[i]}", "by": by}))
        elif i in exterior_ids:
            rows.append(((1, exterior_ids[i]), {"was": key, "now": f"X{exterior_ids[i]}", "by": by}))
    return [row for _order, row in sorted(rows, key=lambda r: r[0])]


def apply_edits(units: list[tuple[str, tuple]], edits: list[Edit], frame, *, pixels: bool = False,
                path=None) -> list[tuple[str | None, tuple, bool]]:
    """``units`` (key, lattice rectangle) after ``edits``, in order, each as ``(key, rect,
    edited)``: the units left in the file's order, then the new ones (key None); ``edited`` says
    whether an edit made or changed the rectangle.

    ``frame`` gives the lattice (shape, the model's cell sizes) and the points' conversion;
    ``path`` is the world file named in errors.
    """
    keys = [k for k, _ in units]
    dup = sorted({k for k in keys if keys.count(k) > 1})
    if dup:
        raise SemmapError(path, f"unit id {dup[0]} appears twice; ids must be unique to edit by id")
    editor = _Editor(dict(units), frame, pixels, path)
    for edit in edits:
        editor.apply(edit)
    return ([(k, tuple(int(v) for v in r), k in editor.changed) for k, r in editor.current.items()]
            + [(None, tuple(int(v) for v in r), True) for r in editor.new])


class _Editor:
    """The units of a world as :func:`apply_edits` edits them, one edit at a time."""

    def __init__(self, current: dict, frame, pixels: bool, path):
        self.current = current               # key -> rect, in the file's order
        self.gone: dict[str, str] = {}       # key -> the edit that removed it
        self.new: list[tuple] = []
        self.changed: set[str] = set()       # keys whose rectangle an edit made
        self.frame, self.pixels, self.path = frame, pixels, path

    def fail(self, edit: Edit, message: str):
        raise SemmapError(self.path, f"{edit}: {message}")

    def unit(self, edit: Edit, text: str) -> str:
        k = unit_key(text)
        if k in self.gone:
            self.fail(edit, f"unit {text} no longer exists after {self.gone[k]} (edits apply in order; "
                            f"edit the written file again to change its pieces)")
        if k not in self.current:
            listed = ", ".join(sorted(self.current, key=lambda s: (s.startswith("X"), len(s), s)))
            self.fail(edit, f"no unit {text} in this world (its units: {listed or 'none'})")
        return k

    def point(self, edit: Edit, x: str, y: str, rect=None) -> Point:
        """The lattice point of ``x y``; on a lattice of several directions, on the tile of
        ``rect`` when given (a wall or a cut of that unit, or the first corner of a new one)."""
        frame, pixels = self.frame, self.pixels
        px, py = to_image(frame, _number(x), _number(y), pixels=pixels)
        h, w = frame.image_shape
        if not (0 <= px <= w and 0 <= py <= h):
            self.fail(edit, f"the point {x} {y} lies outside the map ({w} x {h} pixels"
                            f"{'' if pixels else '; points are map-frame metres, --pixels for pixels'})")
        tile = frame.tile_of_rect(rect) if rect is not None and rect_spans(frame) else None
        return to_lattice(frame, px, py, pixels=True, tile=tile)

    def check(self, edit: Edit, rect, what: str = "the result") -> tuple:
        frame, c = self.frame, self.frame.cells
        r0, c0, r1, c1 = (int(v) for v in rect)
        sides = (r1 - r0, c1 - c0)
        res = frame.resolution
        faults = rect_faults((r0, c0, r1, c1), frame.shape, c.min_side, c.max_side, rect_spans(frame))
        if "small" in faults:
            self.fail(edit, f"{what} would be {sides[0] * res:.2f} x {sides[1] * res:.2f} m; a unit's sides "
                            f"are at least {c.min_side * res:.2f} m, walls included ([world] min_unit_side_m)")
        if "large" in faults:
            self.fail(edit, f"{what} would be {sides[0] * res:.2f} x {sides[1] * res:.2f} m; a unit's sides "
                            f"are at most {c.max_side * res:.2f} m ([world] max_unit_side_m)")
        if "outside" in faults:
            self.fail(edit, f"{what} would reach beyond the map's lattice")
        if "straddles" in faults:
            self.fail(edit, f"{what} would lie across two of the building's directions (zones of the "
                            f"lattice at different angles): a unit lies in one")
        return (r0, c0, r1, c1)

    def remove(self, k: str, edit: Edit) -> None:
        del self.current[k]
        self.gone[k] = str(edit)

    def apply(self, edit: Edit) -> None:
        """One edit: drop, merge, cut, wall or add."""
        try:
            check_args(edit)
        except ValueError as exc:
            self.fail(edit, str(exc))
        a, current, wall = edit.args, self.current, self.frame.cells.wall
        if edit.kind == "drop":
            for t in a:
                self.remove(self.unit(edit, t), edit)
        elif edit.kind == "merge":
            ks = [self.unit(edit, t) for t in a]
            if len(set(ks)) < len(ks):
                self.fail(edit, "a unit is named twice")
            rs = np.array([current[k] for k in ks])
            box = (rs[:, 0].min(), rs[:, 1].min(), rs[:, 2].max(), rs[:, 3].max())
            current[ks[0]] = self.check(edit, box, "the merged unit")
            self.changed.add(ks[0])
            for k in ks[1:]:
                self.remove(k, edit)
        elif edit.kind == "cut":
            self.cut(edit)
        elif edit.kind == "wall":
            k = self.unit(edit, a[0])
            current[k] = self.check(edit, _wall(current[k], self.point(edit, *a[1:3], current[k]), wall))
            self.changed.add(k)
        else:   # add
            first = self.point(edit, *a[0:2])      # the second corner on the first one's lattice
            home = (first.row, first.col, first.row, first.col)
            self.new.append(self.check(edit, _box(first, self.point(edit, *a[2:4], home), wall),
                                       "the new unit"))

    def cut(self, edit: Edit) -> None:
        """A unit cut in two along a new wall through two points."""
        a, wall = edit.args, self.frame.cells.wall
        k = self.unit(edit, a[0])
        rect = self.current[k]
        axis, s, (first, second) = _cut(rect, self.point(edit, *a[1:3], rect), self.point(edit, *a[3:5], rect),
                                        wall)
        if not rect[axis] < s - wall < s < rect[axis + 2]:
            self.fail(edit, f"the line does not cross unit {a[0]} (it runs along the "
                            f"{'rows' if axis == 0 else 'columns'} of the lattice; give two points on the "
                            f"new wall, inside the unit)")
        self.check(edit, first, "a piece")
        self.check(edit, second, "a piece")
        self.remove(k, edit)
        self.new += [first, second]
