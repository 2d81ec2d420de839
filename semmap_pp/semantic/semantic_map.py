"""The semantic map of one world, in the input image's frame: what every output file is written from.

:func:`semantic_map` derives everything once (doors, objects, adjacency, unexplored areas, cell states,
type marginals, CPR) and numbers the units 1..n in reading order (by the image row, then column, of
their centres), so ids do not depend on which slot a unit happened to occupy; or, given the units
of an earlier world.json, carries their ids over (:mod:`semmap_pp.semantic.ids`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from semmap_pp import world as wm
from semmap_pp.cells import UNIT_TYPES, W_FREE, W_OBJECT, W_UNKNOWN, W_WALL
from semmap_pp.derive import derive_world
from semmap_pp.derive.states import interior
from semmap_pp.evaluate import closing_radius_cells, cpr, default_roi
from semmap_pp.model import RoomParams
from semmap_pp.semantic.ids import carry_ids
from semmap_pp.semantic.rooms import Rooms, open_walls, rooms_of
from semmap_pp.semantic.world_json import rect_corners_m
from semmap_pp.target.likelihood import X_WALLLIKE, prepare


@dataclass(frozen=True)
class SemanticMap:
    """Everything the outputs need, with units numbered 1..n.

    Attributes
    ----------
    world : World with types assigned
    slot_ids : dict slot -> unit id
    derived : Derived (slot-indexed, lattice frame)
    marginals : dict unit id -> (4,) type marginals (order of ``UNIT_TYPES``)
    labels_lattice : (H', W') uint16, unit id per lattice cell (walls included), 0 none
    states_image : (H, W) uint8 world cell states in the image frame
    labels_image : (H, W) uint16 unit ids in the image frame
    roi : (H, W) bool, the region of interest of ``cpr``
    cpr : float (NaN when the ROI is empty)
    log_posterior : float
    exterior_ids : dict slot -> exterior id (1..m) of the exterior units (not in ``slot_ids``)
    id_record : dict or None, how the unit ids were carried from an earlier world.json
        (:func:`semmap_pp.semantic.ids.carry_ids`; world.json's ``ids``), None when numbered 1..n
    room_params : the model's ``[rooms]``, how :attr:`rooms` are made
    through_door : frozenset of the slots of the units added over rooms seen through their door
        (each a room of its own in :attr:`rooms`, flagged ``seen_through_door``)
    """

    grid: object
    frame: object
    world: wm.World
    slot_ids: dict
    derived: object
    marginals: dict
    labels_lattice: np.ndarray
    states_image: np.ndarray
    labels_image: np.ndarray
    roi: np.ndarray
    cpr: float
    log_posterior: float
    exterior_ids: dict = field(default_factory=dict)
    id_record: dict | None = None
    room_params: RoomParams = RoomParams()
    through_door: frozenset = frozenset()

    @property
    def unit_ids(self) -> list[int]:
        return sorted(self.slot_ids.values())

    def slot_of(self, unit_id: int) -> int:
        return next(s for s, i in self.slot_ids.items() if i == unit_id)

    def type_of(self, unit_id: int) -> str:
        return UNIT_TYPES[int(self.world.types[self.slot_of(unit_id)])]

    def door_image(self) -> np.ndarray:
        """(H, W) bool, read-only: W*'s door cells in the image frame, each door's lattice box
        warped as :attr:`labels_image` is (the doors of overlay.png and of types.pgm; warped
        once, as warping a rotated map's image takes about 50 bytes a pixel for a moment)."""
        hit = self.__dict__.get("_door_image")
        if hit is None:
            lat = np.zeros(self.frame.shape, bool)
            for d in self.derived.doors:
                r0, c0, r1, c1 = (max(int(v), 0) for v in d.box)
                lat[r0:r1, c0:c1] = True
            hit = self.frame.to_image(lat, fill=False)
            hit.setflags(write=False)
            self.__dict__["_door_image"] = hit     # the dataclass is frozen: its own cache
        return hit

    @property
    def rooms(self) -> Rooms:
        """rooms.png's rooms (:func:`semmap_pp.semantic.rooms.rooms_of`), made once."""
        hit = self.__dict__.get("_rooms")
        if hit is None:
            hit = rooms_of(self, self.room_params)
            self.__dict__["_rooms"] = hit       # the dataclass is frozen: its own cache
        return hit

    def units_text(self) -> str:
        """The units of W* in words, for logs and diagnostics.txt, e.g. ``"20 units (18 room,
        1 corridor, 1 other; +1 exterior)"`` (types with no unit left out)."""
        types = [self.type_of(u) for u in self.unit_ids]
        parts = [f"{types.count(t)} {t}" for t in UNIT_TYPES if t in types]
        ext = f"+{len(self.exterior_ids)} exterior" if self.exterior_ids else ""
        inner = "; ".join(x for x in (", ".join(parts), ext) if x)
        return f"{len(types)} units" + (f" ({inner})" if inner else "")


def number_units(frame, world: wm.World, slots=None) -> dict[int, int]:
    """Unit ids 1..n for ``slots`` (default: the active slots), in reading order of their centres
    in the image."""
    slots = [int(s) for s in (wm.active_slots(world) if slots is None else slots)]
    keys = []
    for s in slots:
        v = frame.rect_vertices_px(world.rects[s])
        cx, cy = v.mean(axis=0)
        keys.append((round(float(cy), 6), round(float(cx), 6), s))
    return {s: i + 1 for i, (_, _, s) in enumerate(sorted(keys))}


def label_lattice(shape, world: wm.World, slot_ids: dict, wall: int) -> np.ndarray:
    """Unit id of every lattice cell, walls included.

    Where units overlap, a unit's interior wins over another's wall band (the cell is *in* that
    unit), and between equals the smaller id wins, so the result does not depend on slot order.
    """
    labels = np.zeros(shape, np.uint16)
    strength = np.zeros(shape, np.uint8)  # 0 none, 1 wall band, 2 interior
    for s, uid in sorted(slot_ids.items(), key=lambda kv: kv[1]):
        r0, c0, r1, c1 = (int(v) for v in world.rects[s])
        box = (slice(r0, r1), slice(c0, c1))
        mine = np.ones((r1 - r0, c1 - c0), np.uint8)
        i0, j0, i1, j1 = interior((r0, c0, r1, c1), wall)
        if i1 > i0 and j1 > j0:
            mine[i0 - r0:i1 - r0, j0 - c0:j1 - c0] = 2
        take = mine > strength[box]
        labels[box][take] = uid
        strength[box][take] = mine[take]
    return labels


def semantic_map(grid, frame, posterior, world: wm.World, *, roi: np.ndarray | None = None,
                 terms=None, previous=None, through_door=()) -> SemanticMap:
    """Derive the semantic map of ``world`` (types re-assigned by ``posterior``); ``terms``:
    ``posterior.evaluate(world)`` when the caller has it already; ``previous``: the units of an
    earlier world.json (:func:`semmap_pp.plans.world_file.read_previous_ids`) whose ids to carry over,
    instead of numbering the units 1..n; ``through_door``: the slots of units added over rooms
    seen through their door (:func:`semmap_pp.sampler.ascent.add_units`)."""

    terms = posterior.evaluate(world) if terms is None else terms
    world = terms.world
    derived = open_walls(derive_world(frame, world), world, frame, through_door, posterior.model.rooms,
                         lambda: prepare(frame, posterior.model).xcode == X_WALLLIKE)
    slot_ids, id_record = number_units(frame, world, derived.slots), None
    if previous is not None:
        order = sorted(slot_ids, key=slot_ids.get)
        corners = {s: rect_corners_m(frame, world.rects[s]) for s in order}   # world.json's vertices_m
        slot_ids, id_record = carry_ids(corners, order, previous)
    exterior_ids = number_units(frame, world, [e.slot for e in derived.exterior])
    result = posterior.knowledge_result(world) if wm.n_units(world) else None
    marginals = {}
    for s, uid in slot_ids.items():
        m = np.asarray(result.types[s], dtype=float) if result is not None else np.zeros(len(UNIT_TYPES))
        marginals[uid] = m
    labels_lat = label_lattice(frame.shape, world, slot_ids, frame.cells.wall)
    states_img = frame.to_image(derived.states, fill=W_UNKNOWN)
    labels_img = frame.to_image(labels_lat, fill=0)
    if roi is None:
        roi = default_roi(grid.classes, closing_radius_cells(posterior.model.evaluate.roi_closing_m,
                                                             grid.resolution))
    rate, _ = cpr(grid.classes, states_img, roi)
    return SemanticMap(grid, frame, world, slot_ids, derived, marginals, labels_lat, states_img,
                       labels_img, roi, float(rate), float(terms.total), exterior_ids, id_record,
                       posterior.model.rooms, frozenset(int(s) for s in through_door))


__all__ = ["SemanticMap", "semantic_map", "number_units", "label_lattice",
           "W_FREE", "W_OBJECT", "W_UNKNOWN", "W_WALL"]
