"""regions.png: units joined into the rooms a person would draw.

A unit is a rectangle; a room of the building may take several (an L-shaped room is two units).
Two units belong to the same *region* when they are adjacent and the wall between them is open:
their connecting wall (:func:`semmap_pp.derive.doors.connecting_wall`) holds a run of input-free
lines wider than a door (``door_max``), which :mod:`semmap_pp.derive.doors` calls an open passage —
"the two units are one space" — or is open along its whole length (a corridor cut in two units: the
opening is as wide as the corridor, which may fit a door's width, but no wall stands beside it).
Adjacent units separated by a closed wall (two offices side by side) stay apart, as they would on a
floor plan; so do units joined by a door in a wall.
Regions are the connected components of that relation (union–find), numbered 1..m by their
smallest unit id.

Examples
--------
>>> join_regions([1, 2, 3, 4], [(2, 3), (3, 4)])
{1: 1, 2: 2, 3: 2, 4: 2}
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Iterable, Sequence

import numpy as np

from semmap_pp import atomic
from semmap_pp.cells import FREE
from semmap_pp.derive.doors import connecting_wall, open_runs
from semmap_pp.outputs.world_json import png_bytes


def join_regions(unit_ids: Sequence[int], pairs: Iterable[tuple[int, int]]) -> dict[int, int]:
    """Union–find: region id (1..m, in order of each region's smallest unit id) of every unit.

    Parameters
    ----------
    unit_ids : sequence of int
        Every unit (a unit in no pair is a region of its own).
    pairs : iterable of (a, b)
        Units to join.
    """
    parent = {int(u): int(u) for u in unit_ids}

    def find(u: int) -> int:
        while parent[u] != u:
            parent[u] = parent[parent[u]]  # path halving
            u = parent[u]
        return u

    for a, b in pairs:
        ra, rb = find(int(a)), find(int(b))
        if ra != rb:
            parent[max(ra, rb)] = min(ra, rb)  # the root is the smallest id of its region
    roots = sorted({find(u) for u in parent})
    number = {r: i + 1 for i, r in enumerate(roots)}
    return {u: number[find(u)] for u in sorted(parent)}


def opening(classes: np.ndarray, rp, rq, wall: int) -> tuple[int, int]:
    """``(widest, length)``: the widest run of open lines across the connecting wall of ``rp`` and
    ``rq``, and the wall's length, in cells.

    A line across the wall is open when every cell on it is input-free (as for doors). ``(0, 0)``
    when the units have no connecting wall or it leaves the map.

    >>> cls = np.zeros((20, 40), np.uint8); cls[:, 18:22] = 2; cls[2:16, 18:22] = 0
    >>> opening(cls, (0, 0, 20, 20), (0, 20, 20, 40), wall=2)
    (14, 16)
    """
    cw = connecting_wall(rp, rq, wall)
    if cw is None:
        return 0, 0
    (r0, c0, r1, c1), vertical = cw
    H, W = classes.shape
    a0, b0, a1, b1 = max(r0, 0), max(c0, 0), min(r1, H), min(c1, W)
    if a0 >= a1 or b0 >= b1 or (a0, b0, a1, b1) != (r0, c0, r1, c1):
        return 0, 0
    strip = classes[a0:a1, b0:b1] == FREE
    line_open = strip.all(axis=1) if vertical else strip.all(axis=0)
    return max((e - s for s, e in open_runs(line_open)), default=0), len(line_open)


def is_passage(widest: int, length: int, cells) -> bool:
    """An open wall: an opening wider than any door, or no wall at all along a wall at least a door wide
    (a corridor cut in two: its opening is the corridor's width, which may fit a door)."""
    return widest > cells.door_max or (length >= cells.door_min and widest == length)


def passage_pairs(sm) -> list[tuple[int, int]]:
    """Adjacent unit-id pairs ``(a, b)``, ``a < b``, whose connecting wall is open (:func:`is_passage`)."""
    d, ids, cells = sm.derived, sm.slot_ids, sm.frame.cells
    pairs = []
    for i, j in zip(*np.nonzero(np.triu(np.asarray(d.adjacency, bool), 1))):
        p, q = int(d.slots[i]), int(d.slots[j])
        if is_passage(*opening(sm.frame.classes, sm.world.rects[p], sm.world.rects[q], cells.wall), cells):
            pairs.append(tuple(sorted((ids[p], ids[q]))))
    return sorted(pairs)


def unit_regions(sm) -> dict[int, int]:
    """Region id of every unit id of a :class:`~semmap_pp.outputs.semantic.SemanticMap`."""
    return join_regions(sm.unit_ids, passage_pairs(sm))


def regions_image(sm, regions: dict[int, int] | None = None) -> np.ndarray:
    """(H, W) uint16 region id per pixel of the input image (0 = no unit), from ``labels_image``."""
    regions = unit_regions(sm) if regions is None else regions
    lut = np.zeros(int(sm.labels_image.max(initial=0)) + 1, np.uint16)
    for uid, rid in regions.items():
        if uid < len(lut):
            lut[uid] = rid
    return lut[sm.labels_image]


def write_regions_png(path: str | os.PathLike, image: np.ndarray) -> Path:
    """regions.png: 16-bit, the input image's size and frame, region id per pixel, 0 none."""
    atomic.write_bytes(path, png_bytes(np.asarray(image).astype(np.uint16)))
    return Path(path)


__all__ = ["join_regions", "opening", "is_passage", "passage_pairs", "unit_regions", "regions_image",
           "write_regions_png"]
