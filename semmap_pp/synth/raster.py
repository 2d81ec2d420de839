"""The floor plan drawn as cell arrays in the building frame: what blocks a laser ray (walls,
closed doors, furniture), what is window glass, and which unit every cell belongs to.

Array index ``[row, col]`` of a building raster is building cell ``(x, y) = (col + ox, row + oy)``,
with ``(ox, oy)`` = :attr:`BuildingRasters.offset`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from semmap_pp.synth.layout import cells
from semmap_pp.synth.params import SynthParams
from semmap_pp.synth.topology import FloorPlan


@dataclass
class BuildingRasters:
    """Cell arrays of one plan in the building frame."""

    solid: np.ndarray     # (Hb, Wb) bool: stops every ray
    glass: np.ndarray     # (Hb, Wb) bool: window glass, stops some rays
    labels: np.ndarray    # (Hb, Wb) uint16: unit id (index + 1) incl. walls, 0 outside
    inside: np.ndarray    # (Hb, Wb) bool: within the building outline (tiles and walls)
    offset: tuple         # (ox, oy): building cell of raster index [0, 0]
    keep_out: np.ndarray  # (Hb, Wb) bool: door and open-boundary clearances (no furniture)


def _span(coord: int, t: int) -> tuple[int, int]:
    return coord - t // 2, coord - t // 2 + t


def _box(orient: str, coord: int, s0: float, s1: float, t0: int, t1: int):
    """(x0, y0, x1, y1) of a band ``[t0, t1)`` across and ``[s0, s1)`` along a boundary line."""
    if orient == "v":
        return int(coord + t0), int(s0), int(coord + t1), int(s1)
    return int(s0), int(coord + t0), int(s1), int(coord + t1)


def _fill(a: np.ndarray, box, offset, value) -> None:
    x0, y0, x1, y1 = box
    ox, oy = offset
    a[max(0, y0 - oy):max(0, y1 - oy), max(0, x0 - ox):max(0, x1 - ox)] = value


def draw_plan(plan: FloorPlan, p: SynthParams, res: float) -> BuildingRasters:
    """Rasterise walls, doors, windows, exits and unit labels of ``plan``."""
    pad = cells(p.wall_outer_max, res) + 4
    x_min, y_min = int(plan.rects[:, 0].min()) - pad, int(plan.rects[:, 1].min()) - pad
    x_max, y_max = int(plan.rects[:, 2].max()) + pad, int(plan.rects[:, 3].max()) + pad
    offset = (x_min, y_min)
    shape = (y_max - y_min, x_max - x_min)
    walls = np.zeros(shape, dtype=bool)
    t_max = 1
    for o, c, s0, s1, t in plan.walls:
        a, b = _span(c, t)
        _fill(walls, _box(o, c, s0 - t // 2, s1 + t - t // 2, a - c, b - c), offset, True)
        t_max = max(t_max, t)
    solid = walls.copy()
    glass = np.zeros(shape, dtype=bool)
    keep_out = np.zeros(shape, dtype=bool)
    half = t_max // 2 + 1
    for o, c, s0, s1 in plan.windows:
        _fill(solid, _box(o, c, s0, s1, -half, half), offset, False)
        band = np.zeros(shape, dtype=bool)
        _fill(band, _box(o, c, s0, s1, -half, half), offset, True)
        glass |= band & walls
    clearance = cells(1.2, res)
    along = cells(0.4, res)
    for d in plan.doors:
        s0, s1 = d.centre - d.width / 2, d.centre + d.width / 2
        _fill(solid, _box(d.orient, d.coord, s0, s1, -half, half), offset, False)
        if not d.is_open:  # the closed door leaf: a thin line on the wall's centre
            _fill(solid, _box(d.orient, d.coord, s0, s1, -1, 1), offset, True)
        _fill(keep_out, _box(d.orient, d.coord, s0 - along, s1 + along, -clearance, clearance),
              offset, True)
    for _, o, c, s0, s1 in plan.exits:
        _fill(solid, _box(o, c, s0, s1, -half, half), offset, False)
        _fill(glass, _box(o, c, s0, s1, -half, half), offset, False)
        _fill(keep_out, _box(o, c, s0 - along, s1 + along, -clearance, clearance), offset, True)
    for a, b in plan.open_pairs:
        o, c, s0, s1 = plan.shared[(a, b)]
        _fill(keep_out, _box(o, c, s0, s1, -clearance, clearance), offset, True)

    labels = np.zeros(shape, dtype=np.uint16)
    for i, (x0, y0, x1, y1) in enumerate(plan.rects.tolist()):
        _fill(labels, (x0, y0, x1, y1), offset, i + 1)
    # the outer half of an exterior wall belongs to the unit it encloses (nearest tile)
    outer = walls & (labels == 0)
    if outer.any():
        _, (ri, ci) = ndimage.distance_transform_edt(labels == 0, return_indices=True)
        labels[outer] = labels[ri[outer], ci[outer]]
    inside = labels > 0
    return BuildingRasters(solid, glass, labels, inside, offset, keep_out)


def _interior(plan: FloorPlan, i: int, offset, inset: int):
    x0, y0, x1, y1 = plan.rects[i].tolist()
    ox, oy = offset
    return x0 - ox + inset, y0 - oy + inset, x1 - ox - inset, y1 - oy - inset


def furnish(rng: np.random.Generator, plan: FloorPlan, br: BuildingRasters, p: SynthParams,
            res: float) -> np.ndarray:
    """Furniture blobs, table and chair legs, hall pillars and corridor objects added to ``solid``.

    Returns a new ``solid`` array; nothing is placed in a door or open-boundary clearance.
    """
    solid = br.solid.copy()
    inset = max(t for *_, t in plan.walls) // 2 + 1
    m = lambda metres: max(1, int(round(metres / res)))

    def place(box, ellipse=False) -> bool:
        x0, y0, x1, y1 = box
        if x1 <= x0 or y1 <= y0 or br.keep_out[y0:y1, x0:x1].any():
            return False
        if ellipse:
            yy, xx = np.mgrid[y0:y1, x0:x1]
            cy, cx = (y0 + y1 - 1) / 2, (x0 + x1 - 1) / 2
            ry, rx = max((y1 - y0) / 2, 0.5), max((x1 - x0) / 2, 0.5)
            inside = ((yy - cy) / ry) ** 2 + ((xx - cx) / rx) ** 2 <= 1.0
            solid[y0:y1, x0:x1] |= inside
        else:
            solid[y0:y1, x0:x1] = True
        return True

    for i, kind in enumerate(plan.types):
        bx0, by0, bx1, by1 = box = _interior(plan, i, br.offset, inset)
        w, h = bx1 - bx0, by1 - by0
        if w < 4 or h < 4:
            continue
        area = w * h * res * res
        if rng.random() < p.p_pilasters:  # columns or radiators along the walls, at intervals
            _pilasters(rng, place, m, p, box)
        if kind == "corridor":
            _corridor_objects(rng, place, m, p, box, max(w, h) * res)
            continue
        scale = 0.35 if kind == "hall" else 2.0 if kind == "other" else 1.0  # lobby / storage
        _furniture(rng, place, m, box, scale * p.furniture_per_m2 * area)
        _legs(rng, place, m, box, scale * p.legs_per_m2 * area)
        _clutter(rng, place, m, box, scale * p.clutter_per_m2 * area)
        if kind == "hall" and rng.random() < p.p_hall_pillars:
            _pillars(rng, place, m, p, box)
    return solid


def _pilasters(rng, place, m, p: SynthParams, box) -> None:
    """Columns or radiators along the four walls of ``box``, at intervals."""
    bx0, by0, bx1, by1 = box
    step = m(rng.uniform(p.pilaster_spacing_min, p.pilaster_spacing_max))
    along, depth = m(rng.uniform(0.2, 0.5)), m(rng.uniform(0.1, 0.3))
    for s in range(bx0 + step // 2, bx1 - along, step):
        place((s, by0, s + along, by0 + depth))
        place((s, by1 - depth, s + along, by1))
    for s in range(by0 + step // 2, by1 - along, step):
        place((bx0, s, bx0 + depth, s + along))
        place((bx1 - depth, s, bx1, s + along))


def _corridor_objects(rng, place, m, p: SynthParams, box, length: float) -> None:
    """Objects along a corridor's walls, Poisson in its ``length`` (metres)."""
    bx0, by0, bx1, by1 = box
    w, h = bx1 - bx0, by1 - by0
    for _ in range(int(rng.poisson(p.p_corridor_object * length))):
        s = m(rng.uniform(0.3, 0.6))
        t = m(rng.uniform(0.3, 0.5))
        if w >= h:
            x = int(rng.integers(bx0, max(bx0 + 1, bx1 - s)))
            y = by0 if rng.random() < 0.5 else by1 - t
            place((x, y, x + s, y + t))
        else:
            y = int(rng.integers(by0, max(by0 + 1, by1 - s)))
            x = bx0 if rng.random() < 0.5 else bx1 - t
            place((x, y, x + t, y + s))


def _furniture(rng, place, m, box, rate: float) -> None:
    """Furniture blobs (Poisson mean ``rate``): against a wall or free-standing."""
    bx0, by0, bx1, by1 = box
    for _ in range(int(rng.poisson(rate))):
        if rng.random() < 0.7:  # against a wall: desks, shelves, cabinets
            length, depth = m(rng.uniform(0.8, 2.2)), m(rng.uniform(0.4, 0.8))
            gap = int(rng.integers(0, 3))
            side = int(rng.integers(4))
            if side < 2:
                x = int(rng.integers(bx0, max(bx0 + 1, bx1 - length)))
                y = by0 + gap if side == 0 else by1 - gap - depth
                place((x, y, min(x + length, bx1), y + depth))
            else:
                y = int(rng.integers(by0, max(by0 + 1, by1 - length)))
                x = bx0 + gap if side == 2 else bx1 - gap - depth
                place((x, y, x + depth, min(y + length, by1)))
        else:  # free-standing: tables, boxes, round tables
            sx, sy = m(rng.uniform(0.5, 1.6)), m(rng.uniform(0.5, 1.2))
            x = int(rng.integers(bx0, max(bx0 + 1, bx1 - sx)))
            y = int(rng.integers(by0, max(by0 + 1, by1 - sy)))
            place((x, y, min(x + sx, bx1), min(y + sy, by1)), ellipse=rng.random() < 0.3)


def _legs(rng, place, m, box, rate: float) -> None:
    """Tables and chairs, seen as their legs only (Poisson mean ``rate``)."""
    bx0, by0, bx1, by1 = box
    for _ in range(int(rng.poisson(rate))):
        sx, sy = m(rng.uniform(0.4, 1.8)), m(rng.uniform(0.4, 1.0))
        x = int(rng.integers(bx0 + 2, max(bx0 + 3, bx1 - sx - 2)))
        y = int(rng.integers(by0 + 2, max(by0 + 3, by1 - sy - 2)))
        leg = 2 if rng.random() < 0.3 else 1
        for lx, ly in ((x, y), (x + sx, y), (x, y + sy), (x + sx, y + sy)):
            if lx + leg <= bx1 and ly + leg <= by1:
                place((lx, ly, lx + leg, ly + leg))


def _clutter(rng, place, m, box, rate: float) -> None:
    """Small clutter (Poisson mean ``rate``)."""
    bx0, by0, bx1, by1 = box
    for _ in range(int(rng.poisson(rate))):
        sx, sy = m(rng.uniform(0.1, 0.3)), m(rng.uniform(0.1, 0.3))
        x = int(rng.integers(bx0, max(bx0 + 1, bx1 - sx)))
        y = int(rng.integers(by0, max(by0 + 1, by1 - sy)))
        place((x, y, x + sx, y + sy), ellipse=rng.random() < 0.5)


def _pillars(rng, place, m, p: SynthParams, box) -> None:
    """A grid of pillars in a hall."""
    bx0, by0, bx1, by1 = box
    step = m(rng.uniform(p.pillar_spacing_min, p.pillar_spacing_max))
    size = m(rng.uniform(0.3, 0.6))
    edge = m(1.5)
    for y in range(by0 + edge + step // 2, by1 - edge, step):
        for x in range(bx0 + edge + step // 2, bx1 - edge, step):
            place((x, y, x + size, y + size))
