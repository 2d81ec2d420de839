"""Derived elements of a world on the lattice map: cell states, doors, objects, adjacency,
unexplored areas and exterior units (one module each). :func:`derive_world` computes all of them
for the outputs.

Examples
--------
>>> import numpy as np
>>> from semmap_pp import world as wm
>>> from semmap_pp.model import load_model
>>> from semmap_pp.lattice.frame import build_frame_from_classes
>>> cls = np.full((40, 80), 2, np.uint8); cls[2:38, 2:78] = 0   # free inside outer walls
>>> cls[:, 38:42] = 2; cls[10:26, 38:42] = 0                    # a wall with a door
>>> frame = build_frame_from_classes(cls, 0.05, load_model(), theta=0.0)
>>> w = wm.add(wm.add(wm.empty(4), 0, (0, 0, 40, 40)), 1, (0, 40, 40, 80))
>>> d = derive_world(frame, w)
>>> d.adjacency.tolist(), [(x.p, x.q, x.box) for x in d.doors], d.exterior
([[False, True], [True, False]], [(0, 1, (10, 38, 26, 42))], [])
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from semmap_pp import world as wm
from semmap_pp.derive.adjacency import adjacency_matrix
from semmap_pp.derive.crossing import cross_tile_openings
from semmap_pp.derive.doors import Door, find_gap_passages, find_openings
from semmap_pp.derive.exterior import find_exterior
from semmap_pp.derive.states import Object, cell_states, find_objects
from semmap_pp.derive.unexplored import Unexplored, find_unexplored
from semmap_pp.lattice.tiles import rect_spans

__all__ = ["Derived", "Door", "Exterior", "Object", "Unexplored", "derive_world"]


class Exterior(NamedTuple):
    """An exterior unit (:mod:`semmap_pp.derive.exterior`): its slot and the slots of the
    building's units it is adjacent to."""

    slot: int
    neighbours: tuple


class Derived(NamedTuple):
    """Everything derived from one world.

    ``slots`` are the active slots of the building's units in order (exterior units left out);
    ``adjacency`` is (n, n) over them; doors, passages (open stretches of a shared wall that are
    not doors: wider than a door or without a jamb), gap passages (where two units that do not
    touch face each other across free floor no unit covers: :func:`find_gap_passages`; for the
    outputs' routes, not for regions or the model) and objects name units by slot and join or lie
    in building units only. ``states`` (and so the CPR) and ``unexplored`` come from every unit,
    exterior ones included; ``exterior`` lists those.
    """

    slots: np.ndarray
    states: np.ndarray
    doors: list
    objects: list
    adjacency: np.ndarray
    unexplored: list
    exterior: list
    passages: list = []
    gap_passages: list = []


def _tile_groups(frame, rects: np.ndarray) -> list[np.ndarray]:
    """The indices of ``rects`` by tile on a lattice of several directions (their hulls and
    outlines are each tile's own: the tiles' lattice coordinates are not one plane), else all."""
    if not rect_spans(frame):
        return [np.arange(len(rects))]
    tiles = np.array([frame.tile_of_rect(r) for r in rects], dtype=np.intp)
    return [np.flatnonzero(tiles == k) for k in np.unique(tiles)]


def derive_world(frame, world: wm.World) -> Derived:
    """Cell states, doors, objects, adjacency, unexplored areas and exterior units of ``world`` on
    ``frame``."""
    c = frame.cells
    slots = wm.active_slots(world)
    rects = world.rects[slots]
    adj = adjacency_matrix(rects, c.wall, c.adjacency_dilation)
    doors, passages = find_openings(frame.door_classes, rects, adj, c, slots)
    if rect_spans(frame):      # a tiled lattice: what units of two tiles share, found on the image
        pairs, d, p = cross_tile_openings(frame, rects, slots)
        for i, j in pairs:
            adj[i, j] = adj[j, i] = True
        doors, passages = doors + d, passages + p
    gaps = find_gap_passages(frame.door_classes, rects, adj, c, slots)   # outputs only: no wall there
    objects = find_objects(frame.classes, rects, c.wall, c.object_max_extent, slots)
    states = cell_states(frame.classes, rects, c.wall, c.object_max_extent, doors=doors + passages)
    unexplored = find_unexplored(frame.classes, rects, c.min_side, c.unexplored_min_area)
    ext = np.zeros(len(rects), bool)
    seen = getattr(frame, "seen_classes", frame.classes)   # other zones' pixels as the map shows them
    index = {int(s): i for i, s in enumerate(slots)}
    opened = np.zeros(len(rects), bool)     # units with a door or a passage to another unit
    for d in doors + passages:
        opened[index[int(d.p)]] = opened[index[int(d.q)]] = True
    groups = _tile_groups(frame, rects)
    for group in groups:   # a footprint's hulls are drawn on one lattice
        ext[group] = find_exterior(seen, rects[group], c.wall, c.exterior_max_share,
                                   c.exterior_seen_min, across=c.adjacency_dilation,
                                   fan_seen_max=c.exterior_fan_seen_max,
                                   outline_gap=c.exterior_outline_gap,
                                   object_extent=c.object_max_extent,
                                   outline_walls_max=c.exterior_outline_walls_max,
                                   outline_trust=c.exterior_outline_trust_min,
                                   opened=opened[group], keep=2 if len(groups) == 1 else 1)
    inside = {int(s) for s in slots[~ext]}
    exterior = [Exterior(int(slots[i]), tuple(int(slots[j]) for j in np.flatnonzero(adj[i] & ~ext)))
                for i in np.flatnonzero(ext)]
    return Derived(slots[~ext], states, [d for d in doors if d.p in inside and d.q in inside],
                   [o for o in objects if o.unit in inside], adj[np.ix_(~ext, ~ext)], unexplored,
                   exterior, [d for d in passages if d.p in inside and d.q in inside],
                   [d for d in gaps if d.p in inside and d.q in inside])
