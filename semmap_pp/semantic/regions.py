"""regions.png: units joined into the rooms a person would draw.

A unit is a rectangle; a room of the building may take several (an L-shaped room is two units).
Two units belong to the same *region* when they are adjacent and the wall between them is open:
their connecting wall holds an open passage (:mod:`semmap_pp.derive.doors`: a run of open lines
wider than a door, or one without a jamb on the shared wall — a corridor cut in two units, whose
opening is as wide as the corridor and may fit a door's width, but no wall stands beside it).
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

from semmap_pp.semantic.world_json import write_labels_png


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


def unit_pairs(sm, openings) -> list[tuple[int, int]]:
    """Unit-id pairs ``(a, b)``, ``a < b``, that ``openings`` (doors or passages by slot) join."""
    ids = sm.slot_ids
    return sorted({tuple(sorted((ids[d.p], ids[d.q]))) for d in openings})


def passage_pairs(sm) -> list[tuple[int, int]]:
    """Unit-id pairs ``(a, b)``, ``a < b``, whose connecting wall holds an open passage
    (``sm.derived.passages``)."""
    return unit_pairs(sm, sm.derived.passages)


def unit_regions(sm) -> dict[int, int]:
    """Region id of every unit id of a :class:`~semmap_pp.semantic.semantic_map.SemanticMap`."""
    return join_regions(sm.unit_ids, passage_pairs(sm))


def region_lut(regions: dict[int, int], size: int, dtype=np.int32) -> np.ndarray:
    """A table of ``size`` entries holding each unit id's region id (``regions``), 0 for the
    others: ``region_lut(regions, n)[ids]`` maps an array of unit ids below ``n`` to regions.

    >>> region_lut({1: 1, 2: 2, 3: 2}, 5).tolist()
    [0, 1, 2, 2, 0]
    """
    lut = np.zeros(size, dtype)
    for uid, rid in regions.items():
        if uid < size:
            lut[uid] = rid
    return lut


def regions_image(sm, regions: dict[int, int] | None = None) -> np.ndarray:
    """(H, W) uint16 region id per pixel of the input image (0 = no unit), from ``labels_image``."""
    regions = unit_regions(sm) if regions is None else regions
    return region_lut(regions, int(sm.labels_image.max(initial=0)) + 1, np.uint16)[sm.labels_image]


def write_regions_png(path: str | os.PathLike, image: np.ndarray) -> Path:
    """regions.png: 16-bit, the input image's size and frame, region id per pixel, 0 none
    (:func:`~semmap_pp.semantic.world_json.write_labels_png`, as labels.png and rooms.png)."""
    return write_labels_png(path, np.asarray(image))


__all__ = ["join_regions", "passage_pairs", "unit_pairs", "unit_regions", "region_lut", "regions_image",
           "write_regions_png"]
