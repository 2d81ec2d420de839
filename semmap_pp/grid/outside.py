"""Free space outside the building: maps that mark every cell a long ray crossed as free.

Most SLAM maps leave the outside of a building unknown: the robot saw it only through windows and
exits, as thin ray fans. Some renderings (the Radish map freiburg-079, maps drawn from raw logs with
the full beam length) mark every cell any ray crossed as free, so the building sits in a sea of free
space that reaches the image border. One unit over everything then explains such a map best (its
walls read as clutter inside it; docs/robustness.md).

:func:`outside_free` finds that sea: free space farther than ``seal_gap / 2`` from every occupied
cell and joined to the image border (so a wall with gaps narrower than ``seal_gap`` keeps it out),
grown back by ``seal_gap / 2`` to reach the walls' outer faces. :func:`clear_outside` reads those
cells as unknown before anything else sees the map, when the model's ``[outside] mode`` says so:
``"unknown"`` always, ``"auto"`` when at least ``border_open_min`` of the image's border cells are
free and farther than ``seal_gap / 2`` from every occupied cell (:func:`border_open_share`;
freiburg-079: 0.93; cartesium, intel, the ipa plans: 0; aces 0.02; the bundled test crop of a
corner of intel, whose border runs through its rooms and corridors, 0.01 with 0.26 of its
border cells free), ``"keep"`` never.

Limits: a map cropped through large rooms, so that a quarter of its border runs through open
floor, looks like a map with its outside free (``mode = "keep"`` is the way out); an exit or a
gap in an outer wall wider than ``seal_gap`` lets the sea in, and through a narrower one the grown
border bites a little way into the room behind it; free pockets in a concave corner of the outer
wall, farther than ``seal_gap / 2`` from the sea's core, stay free.
"""

from __future__ import annotations

import dataclasses

import numpy as np
from scipy import ndimage

from semmap_pp.cells import FREE, OCCUPIED, UNKNOWN, border_cells
from semmap_pp.model import OUTSIDE_MODES, OutsideParams


def _wall_distance(classes: np.ndarray) -> np.ndarray:
    """Distance of every cell to the nearest occupied cell, on ``classes`` padded by one cell of
    open space (``inf`` everywhere without an occupied cell)."""
    padded = np.pad(np.asarray(classes) == OCCUPIED, 1)
    if not padded.any():
        return np.full(padded.shape, np.inf)
    return ndimage.distance_transform_edt(~padded)


def border_open_share(classes: np.ndarray, seal_radius: int, wall_distance=None) -> float:
    """Share of the image's border cells (first and last row and column) that are free and farther
    than ``seal_radius`` cells from every occupied cell: open space, as around a building in a map
    that shows its outside as free. A map cropped through its rooms has free border cells too, but
    few of them far from a wall.

    >>> c = np.full((4, 6), UNKNOWN, np.uint8); c[0] = FREE; c[1, 5] = OCCUPIED
    >>> border_open_share(c, 1)  # 6 of the 16 border cells are free, 5 of them far from (1, 5)
    0.3125

    ``wall_distance``: :func:`_wall_distance` of ``classes`` when the caller has it.
    """
    c = np.asarray(classes)
    free = border_cells(c) == FREE
    if not free.any():
        return 0.0                      # the common case (no free border cell): no distance transform
    d = _wall_distance(c) if wall_distance is None else wall_distance
    return float(((border_cells(d[1:-1, 1:-1]) > seal_radius) & free).mean())


def seal_radius(seal_gap_m: float, resolution: float) -> int:
    """Cells of half the seal gap at ``resolution``: at least one, at most 10^9 (a radius beyond
    any map: nothing is open, nothing cleared).

    >>> seal_radius(1.5, 0.05), seal_radius(1e-9, 0.05), seal_radius(1e308, 1e-3)
    (15, 1, 1000000000)
    """
    cells = 0.5 * seal_gap_m / resolution
    return int(max(1, round(cells))) if cells < 1e9 else 10 ** 9


def outside_free(classes: np.ndarray, seal_radius: int, wall_distance=None) -> np.ndarray:
    """Free cells of the space outside the building, as a bool mask of ``classes``' shape.

    The core is the free and unknown space farther than ``seal_radius`` cells from every occupied
    cell (gaps of the occupied cells narrower than ``2 * seal_radius + 1`` are closed) that is
    joined to the image border; the mask is its free cells within ``seal_radius`` of the core and
    nearer to it than to the core of any space inside (the rest of that free space: the rooms).
    Through a gap in an outer wall the mask reaches a little way into the room behind it, at most
    ``seal_radius`` cells, less the nearer the room's own core is.

    >>> c = np.full((40, 40), FREE, np.uint8)
    >>> c[10, 10:30] = c[29, 10:30] = OCCUPIED; c[10:30, 10] = c[10:30, 29] = OCCUPIED
    >>> c[29, 18:21] = FREE                      # a 3-cell door in the bottom wall
    >>> out = outside_free(c, 3)
    >>> bool(out[0, 0]), bool(out[20, 20]), bool(out[28, 19]), int(out[11:29, 11:29].sum())
    (True, False, False, 0)

    ``wall_distance``: :func:`_wall_distance` of ``classes`` when the caller has it.
    """
    c = np.asarray(classes)
    r = int(seal_radius)
    if r < 1:
        raise ValueError(f"seal_radius must be >= 1 cell, got {seal_radius}")
    # padded with open space, so that the border itself is outside and joins every border region;
    # distance transforms rather than dilations with a disc: linear in the cells at any radius
    d = _wall_distance(c) if wall_distance is None else wall_distance
    labels, _ = ndimage.label(d > r)
    ring = border_cells(labels)
    core = np.isin(labels, np.unique(ring[ring > 0]))
    if not core.any():
        return np.zeros(c.shape, bool)
    d_out = ndimage.distance_transform_edt(~core)
    grown = d_out <= r
    inner = (labels > 0) & ~core          # the rooms' own cores: a cell nearer one stays inside
    if inner.any():
        grown &= d_out < ndimage.distance_transform_edt(~inner)
    grown = grown[1:-1, 1:-1]
    return grown & (c == FREE)


def clear_outside(grid, params: OutsideParams):
    """``(grid, note)``: the grid with :func:`outside_free`'s cells read as unknown, and a note.

    ``params`` is the model's ``[outside]`` table (mode one of :data:`OUTSIDE_MODES`); the note
    (``None`` when nothing changed) says how many free cells were read as unknown and how to keep
    them. The occupancy values stay as they are (``semmap info`` shows the map as loaded).
    """
    mode, seal_gap_m = params.mode, params.seal_gap_m
    if mode not in OUTSIDE_MODES:
        raise ValueError(f"mode must be one of {OUTSIDE_MODES}, got {mode!r}")
    if mode == "keep":
        return grid, None
    radius = seal_radius(seal_gap_m, grid.resolution)
    if mode == "auto" and not (border_cells(grid.classes) == FREE).any():
        return grid, None               # the common case, before any distance transform
    dist = _wall_distance(grid.classes)
    share = border_open_share(grid.classes, radius, dist)
    if mode == "auto" and share < params.border_open_min:
        return grid, None
    mask = outside_free(grid.classes, radius, dist)
    n_free = int((grid.classes == FREE).sum())
    if not mask.any():
        return grid, None
    classes = np.array(grid.classes, copy=True)
    classes[mask] = UNKNOWN
    why = (f"{share:.0%} of the map's border cells are open free space" if mode == "auto"
           else "[outside] mode = \"unknown\"")
    note = (f"{why}: {int(mask.sum())} free cells ({mask.sum() / max(n_free, 1):.0%} of the free "
            f"cells) joined to the border through gaps wider than {seal_gap_m:g} m are read as "
            f"unknown, the outside of the building (docs/robustness.md); a model file with "
            f"[outside] mode = \"keep\" keeps them free")
    return dataclasses.replace(grid, classes=classes, notes=tuple(grid.notes) + (note,)), note


__all__ = ["OUTSIDE_MODES", "border_open_share", "seal_radius", "outside_free", "clear_outside"]
