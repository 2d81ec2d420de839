"""The semantic world state W = {U, T, R} as an immutable value.

A world lives on the *building lattice* of a map (see :mod:`semmap_pp.lattice.frame`): the classified input
map resampled once onto a grid aligned with the building's dominant orientation θ0. On that lattice a
space unit is an axis-aligned rectangle of whole cells, so the paper's oriented rectangle
(centre, size, orientation) is ``(r0, c0, r1, c1)`` in lattice cells (half-open: rows r0..r1-1,
columns c0..c1-1) with orientation θ0. The rectangle *includes* its walls: the outer
``wall_cells`` rows and columns of the rectangle are the unit's wall band, the rest is its interior.

The state has a fixed capacity of ``K`` slots and an ``active`` mask, so PyMC points, traces and ArviZ
see fixed shapes. Worlds are values: every function here returns a new world and never edits its
argument (arrays are marked read-only to make an accidental in-place edit fail loudly).

Adjacency R is not stored: it is derived from the rectangles (:mod:`semmap_pp.derive`).
Types T are stored as indices into :data:`semmap_pp.cells.UNIT_TYPES`, ``-1`` for an empty slot.

Examples
--------
>>> w = empty(4)
>>> w = add(w, 0, (0, 0, 10, 20), type_index=1)
>>> n_units(w), w.rects[0].tolist(), int(w.types[0])
(1, [0, 0, 10, 20], 1)
>>> w2 = remove(w, 0)
>>> n_units(w2), n_units(w)
(0, 1)
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

NO_TYPE = -1


class World(NamedTuple):
    """Fixed-capacity world state (all arrays read-only).

    Attributes
    ----------
    rects : (K, 4) int32
        ``r0, c0, r1, c1`` of each slot on the building lattice; zeros where inactive.
    active : (K,) bool
        Which slots hold a unit.
    types : (K,) int8
        Type index of each unit (order of ``UNIT_TYPES``), ``-1`` where inactive.
    """

    rects: np.ndarray
    active: np.ndarray
    types: np.ndarray

    @property
    def capacity(self) -> int:
        return int(self.active.shape[0])


def _frozen(a: np.ndarray) -> np.ndarray:
    a.setflags(write=False)
    return a


def make(rects, active, types) -> World:
    """Build a world from array-likes (copied, checked for shape, frozen)."""
    rects = np.array(rects, dtype=np.int32).reshape(-1, 4)
    active = np.array(active, dtype=bool).reshape(-1)
    types = np.array(types, dtype=np.int8).reshape(-1)
    if not (rects.shape[0] == active.shape[0] == types.shape[0]):
        raise ValueError("rects, active and types must have the same number of slots")
    rects[~active] = 0
    types[~active] = NO_TYPE
    return World(_frozen(rects), _frozen(active), _frozen(types))


def empty(capacity: int) -> World:
    """A world with ``capacity`` slots and no unit."""
    return make(np.zeros((capacity, 4)), np.zeros(capacity, bool), np.full(capacity, NO_TYPE))


def grow(world: World, capacity: int) -> World:
    """The same units in ``capacity`` slots (the new slots empty; ``capacity`` >= the old one).

    >>> w = grow(add(empty(2), 1, (0, 0, 5, 5)), 4)
    >>> w.capacity, active_slots(w).tolist(), w.rects[1].tolist()
    (4, [1], [0, 0, 5, 5])
    """
    extra = int(capacity) - world.capacity
    if extra < 0:
        raise ValueError(f"cannot shrink a world of {world.capacity} slots to {capacity}")
    return make(np.concatenate([world.rects, np.zeros((extra, 4), world.rects.dtype)]),
                np.concatenate([world.active, np.zeros(extra, bool)]),
                np.concatenate([world.types, np.full(extra, NO_TYPE, world.types.dtype)]))


def fit(world: World, capacity: int) -> World:
    """The same units in ``capacity`` slots: slot order kept, units moved into the first slots
    when the world has more slots than ``capacity`` (which must hold them all), empty slots added
    when it has fewer.

    >>> w = fit(add(empty(8), 5, (0, 0, 5, 5)), 2)
    >>> w.capacity, active_slots(w).tolist()
    (2, [0])
    """
    n = n_units(world)
    if n > capacity:
        raise ValueError(f"{n} units do not fit in {capacity} slots")
    if world.capacity <= capacity:
        return grow(world, capacity)
    slots = active_slots(world)
    rects = np.zeros((capacity, 4), world.rects.dtype)
    types = np.full(capacity, NO_TYPE, world.types.dtype)
    rects[:n], types[:n] = world.rects[slots], world.types[slots]
    return make(rects, np.arange(capacity) < n, types)


def n_units(world: World) -> int:
    return int(np.count_nonzero(world.active))


def active_slots(world: World) -> np.ndarray:
    return np.flatnonzero(world.active)


def free_slots(world: World) -> np.ndarray:
    return np.flatnonzero(~world.active)


def add(world: World, slot: int, rect, type_index: int = NO_TYPE) -> World:
    """Put a unit with ``rect`` into the empty ``slot``."""
    if world.active[slot]:
        raise ValueError(f"slot {slot} is already active")
    rects, active, types = world.rects.copy(), world.active.copy(), world.types.copy()
    rects[slot] = rect
    active[slot] = True
    types[slot] = type_index
    return World(_frozen(rects), _frozen(active), _frozen(types))


def remove(world: World, slot: int) -> World:
    """Empty ``slot``."""
    if not world.active[slot]:
        raise ValueError(f"slot {slot} is not active")
    rects, active, types = world.rects.copy(), world.active.copy(), world.types.copy()
    rects[slot] = 0
    active[slot] = False
    types[slot] = NO_TYPE
    return World(_frozen(rects), _frozen(active), _frozen(types))


def replace(world: World, slot: int, rect) -> World:
    """Give the unit in ``slot`` a new rectangle (type kept)."""
    if not world.active[slot]:
        raise ValueError(f"slot {slot} is not active")
    rects = world.rects.copy()
    rects[slot] = rect
    return World(_frozen(rects), world.active, world.types)


def with_types(world: World, types) -> World:
    """Same geometry, new type indices (``-1`` kept for inactive slots)."""
    types = np.array(types, dtype=np.int8).reshape(world.types.shape)
    types[~world.active] = NO_TYPE
    return World(world.rects, world.active, _frozen(types))


def canonical_key(world: World) -> tuple:
    """Slot-order-free identity of a world: the sorted tuple of (rect, type) of its units.

    Two states that differ only by which slots hold which units describe the same world.
    """
    units = [tuple(int(v) for v in world.rects[s]) + (int(world.types[s]),) for s in active_slots(world)]
    return tuple(sorted(units))


def heights_widths(world: World) -> tuple[np.ndarray, np.ndarray]:
    """Rows and columns spanned by each slot (0 for inactive slots)."""
    r = world.rects
    return (r[:, 2] - r[:, 0]), (r[:, 3] - r[:, 1])


def is_valid(world: World, shape: tuple[int, int], min_side: int) -> bool:
    """True when every active rectangle lies inside ``shape`` and spans at least ``min_side`` cells."""
    r = world.rects[world.active]
    if r.size == 0:
        return True
    h, w = r[:, 2] - r[:, 0], r[:, 3] - r[:, 1]
    return bool(np.all(r[:, 0] >= 0) and np.all(r[:, 1] >= 0) and np.all(r[:, 2] <= shape[0])
                and np.all(r[:, 3] <= shape[1]) and np.all(h >= min_side) and np.all(w >= min_side))
