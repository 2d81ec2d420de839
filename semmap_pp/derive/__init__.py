"""Derived elements of a world on the lattice map: cell states, doors, objects, adjacency and
unexplored areas (one module each). :func:`derive_world` computes all of them for the outputs.

Examples
--------
>>> import numpy as np
>>> from semmap_pp import world as W
>>> from semmap_pp.model import load_model
>>> from semmap_pp.frame import build_frame_from_classes
>>> cls = np.zeros((40, 80), np.uint8); cls[:, 38:42] = 2; cls[10:26, 38:42] = 0
>>> frame = build_frame_from_classes(cls, 0.05, load_model(), theta=0.0)
>>> w = W.add(W.add(W.empty(4), 0, (0, 0, 40, 40)), 1, (0, 40, 40, 80))
>>> d = derive_world(frame, w)
>>> d.adjacency.tolist(), [(x.p, x.q, x.box) for x in d.doors]
([[False, True], [True, False]], [(0, 1, (10, 38, 26, 42))])
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from semmap_pp import world as W
from semmap_pp.derive.adjacency import adjacency_matrix
from semmap_pp.derive.doors import Door, find_doors
from semmap_pp.derive.states import Object, cell_states, find_objects
from semmap_pp.derive.unexplored import Unexplored, find_unexplored

__all__ = ["Derived", "Door", "Object", "Unexplored", "derive_world"]


class Derived(NamedTuple):
    """Everything derived from one world.

    ``slots`` are the active slots in order; ``adjacency`` is (n, n) over them; doors and objects
    name units by slot.
    """

    slots: np.ndarray
    states: np.ndarray
    doors: list
    objects: list
    adjacency: np.ndarray
    unexplored: list


def derive_world(frame, world: W.World) -> Derived:
    """Cell states, doors, objects, adjacency and unexplored areas of ``world`` on ``frame``."""
    c = frame.cells
    slots = W.active_slots(world)
    rects = world.rects[slots]
    adj = adjacency_matrix(rects, c.wall, c.adjacency_dilation)
    doors = find_doors(frame.classes, rects, adj, c, slots)
    objects = find_objects(frame.classes, rects, c.wall, c.object_max_extent, slots)
    states = cell_states(frame.classes, rects, c.wall, c.object_max_extent, doors=doors)
    unexplored = find_unexplored(frame.classes, rects, c.min_side, c.unexplored_min_area)
    return Derived(slots, states, doors, objects, adj, unexplored)
