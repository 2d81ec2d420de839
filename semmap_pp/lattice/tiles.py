"""A building of several directions on one lattice: one tile per direction, side by side
(docs/architecture.md, "Units at their own orientation").

A map whose walls run in one direction has one lattice, rotated by θ0 (:mod:`semmap_pp.lattice.frame`).
A building with wings at other angles has a *zone* per direction (:mod:`semmap_pp.lattice.zones`):
every image pixel belongs to one zone. Each zone is resampled on a lattice of its own, rotated by
its own angle and cut to the zone's known cells (other zones' pixels read as unknown there), and
the tiles are laid side by side, left to right, with :func:`tile_gap` columns of unknown cells
between them, into one composite lattice of the height of the tallest. A unit is an axis-aligned
rectangle of one tile: on the composite lattice it is a rectangle like any other, so the kernels,
the target and the sampler work on it unchanged; the prior's support holds only the rectangles
that lie inside one tile's columns (:attr:`TiledFrame.spans`), so no unit straddles two tiles.

:class:`TiledFrame` is a :class:`~semmap_pp.lattice.frame.Frame` whose maps between the lattice
and the image go through the tile of each point: a lattice cell's image pixel through its tile's
rotation, an image pixel's lattice cell through its zone's tile. A unit's orientation is its
tile's (:meth:`TiledFrame.unit_theta`). Units of different tiles are never adjacent on the
lattice (the gap is wider than every distance the derivations look across).

Examples
--------
>>> import numpy as np
>>> from semmap_pp.model import load_model
>>> classes = np.zeros((40, 200), np.uint8)
>>> zones = np.zeros((40, 200), np.uint8); zones[:, 100:] = 1
>>> f = build_tiled_frame(classes, 0.05, load_model(), (0.0, 0.3), zones)
>>> len(f.tiles), f.spans[0], round(f.unit_theta((0, f.spans[1][0], 10, f.spans[1][0] + 10)), 3)
(2, (0, 140), 0.3)
"""

from __future__ import annotations

import dataclasses
import functools
import math
from dataclasses import dataclass, field

import numpy as np

from semmap_pp.cells import UNKNOWN
from semmap_pp.lattice.frame import (Frame, build_frame, build_frame_from_classes, doorway_classes,
                                     resample)
from semmap_pp.lattice.zones import building_zones
from semmap_pp.model import Model


def tile_gap(cells) -> int:
    """Columns of unknown cells between two tiles: twice the farthest any derivation looks across
    from a unit (a door's width, the adjacency dilation, an object's extent) plus both wall bands,
    so that nothing of one tile is ever found next to a unit of another."""
    reach = max(int(cells.door_max), int(cells.adjacency_dilation), int(cells.object_max_extent))
    return 2 * reach + 2 * int(cells.wall) + 2


@dataclass(frozen=True, eq=False)
class TiledFrame(Frame):
    """A :class:`Frame` made of one tile per building direction (see the module docstring).

    Attributes (beyond :class:`Frame`'s, where ``theta`` is the first tile's)
    ----------
    tiles : tuple of Frame
        Each zone's own lattice (its ``classes`` hold UNKNOWN on other zones' pixels).
    cols : tuple of int
        The composite lattice column of each tile's column 0.
    zones : (H, W) uint8
        The zone (tile index) of every image pixel.
    image_classes : (H, W) uint8
        The input image's classes.
    """

    tiles: tuple = ()
    cols: tuple = ()
    zones: np.ndarray = field(default=None, repr=False)
    image_classes: np.ndarray = field(default=None, repr=False)

    # ------------------------------------------------------------------ tiles
    @property
    def spans(self) -> tuple[tuple[int, int], ...]:
        """``(c0, c1)``: the composite lattice columns of each tile (c1 exclusive)."""
        return tuple((c, c + t.shape[1]) for t, c in zip(self.tiles, self.cols))

    @functools.cached_property
    def _splits(self) -> np.ndarray:
        """The middle columns of the gaps between tiles."""
        return np.asarray([(self.cols[k - 1] + self.tiles[k - 1].shape[1] + self.cols[k]) / 2.0
                           for k in range(1, len(self.tiles))], np.float64)

    def tile_of_cols(self, cols) -> np.ndarray:
        """The tile of fractional lattice columns: a column of the gap between two tiles goes to
        the nearer one."""
        return np.searchsorted(self._splits, np.asarray(cols, np.float64), side="right")

    def tile_of_rect(self, rect) -> int:
        """The tile that holds a lattice rectangle (that of its first column)."""
        return int(self.tile_of_cols(float(rect[1])))

    def unit_theta(self, rect) -> float:
        """The orientation (radians) of a unit on this lattice: its tile's."""
        return float(self.tiles[self.tile_of_rect(rect)].theta)

    def tile_image_to_lattice(self, k: int, x_px, y_px) -> tuple[np.ndarray, np.ndarray]:
        """Fractional composite-lattice ``(rows, cols)`` of image coordinates on tile ``k``'s
        lattice, whatever zone they lie in."""
        r, c = self.tiles[k].image_to_lattice(x_px, y_px)
        return r, c + self.cols[k]

    @functools.cached_property
    def seen_classes(self) -> np.ndarray:
        """The lattice's classes with each tile's cells showing what the map shows at their pixel,
        the other zones' pixels included (:attr:`classes` holds those unknown: they are explained on
        their own tile), read as the tile's own cells are (:func:`resample`). What a unit's
        surroundings look like, whichever tile they lie on: the exterior test reads them
        (:func:`semmap_pp.derive.exterior.find_exterior`)."""
        out = np.full(self.classes.shape, UNKNOWN, np.uint8)
        for t, c in zip(self.tiles, self.cols):    # a tile is a plain Frame: no zone mask
            cells, ok = resample(t, self.image_classes, 0, t.shape[0], 0, t.shape[1], t.wall_samples,
                                 t.wall_join_px)
            out[:t.shape[0], c:c + t.shape[1]][ok] = cells[ok]
        own = ~self.outside
        out[own] = self.classes[own]     # a tile's own cells as its classes hold them
        out.setflags(write=False)
        return out

    @functools.cached_property
    def image_door_classes(self) -> np.ndarray:
        """The input image's classes with specks made free (:func:`doorway_classes`, as the
        lattice's :attr:`door_classes`): what openings between units of two tiles are read on
        (:mod:`semmap_pp.derive.crossing`)."""
        return doorway_classes(self.image_classes, self.cells.door_speck)

    def _zone_at(self, x_px, y_px) -> np.ndarray:
        h, w = self.image_shape
        xi = np.clip(np.floor(np.asarray(x_px, np.float64) + 0.5).astype(np.intp), 0, w - 1)
        yi = np.clip(np.floor(np.asarray(y_px, np.float64) + 0.5).astype(np.intp), 0, h - 1)
        return self.zones[yi, xi]

    # ------------------------------------------------------------------ maps
    def lattice_to_image(self, rows, cols) -> tuple[np.ndarray, np.ndarray]:
        rows, cols = np.broadcast_arrays(np.asarray(rows, np.float64), np.asarray(cols, np.float64))
        x, y = np.empty(rows.shape), np.empty(rows.shape)
        k = self.tile_of_cols(cols)
        for i, (t, c) in enumerate(zip(self.tiles, self.cols)):
            m = k == i
            if m.any():
                x[m], y[m] = t.lattice_to_image(rows[m], cols[m] - c)
        return x, y

    def image_to_lattice(self, x_px, y_px) -> tuple[np.ndarray, np.ndarray]:
        x, y = np.broadcast_arrays(np.asarray(x_px, np.float64), np.asarray(y_px, np.float64))
        r, cl = np.empty(x.shape), np.empty(x.shape)
        k = self._zone_at(x, y)
        for i, (t, c) in enumerate(zip(self.tiles, self.cols)):
            m = k == i
            if m.any():
                r[m], cl[m] = t.image_to_lattice(x[m], y[m])
                cl[m] += c
        return r, cl

    def rect_vertices_px(self, rect) -> np.ndarray:
        k = self.tile_of_rect(rect)
        r0, c0, r1, c1 = (int(v) for v in rect)
        c = self.cols[k]
        return self.tiles[k].rect_vertices_px((r0, c0 - c, r1, c1 - c))

    def rect_from_vertices_px(self, vertices_px) -> tuple[tuple[int, int, int, int], float]:
        """:meth:`Frame.rect_from_vertices_px` in the tile whose lattice fits the corners best."""
        best = None
        for t, c in zip(self.tiles, self.cols):
            (r0, c0, r1, c1), off = t.rect_from_vertices_px(vertices_px)
            if best is None or off < best[1]:
                best = ((r0, c0 + c, r1, c1 + c), off)
        return best

    def box_to_image(self, box_array: np.ndarray, box, fill=0, window=None, step: int = 1) -> np.ndarray:
        """:meth:`Frame.box_to_image`: each pixel shows its own zone's tile."""
        a, (r0, c0, r1, c1), (y0, y1, x0, x1) = self._box_args(box_array, box, window)
        zone = self.zones[y0:y1:step, x0:x1:step]
        out = np.full(zone.shape + a.shape[2:], fill, dtype=a.dtype)
        for k, (t, c) in enumerate(zip(self.tiles, self.cols)):
            a0, a1, b1 = max(c0, c), min(c1, c + t.shape[1]), min(r1, t.shape[0])
            if a0 >= a1 or r0 >= b1:
                continue
            mine = zone == k
            if not mine.any():
                continue
            img = t.box_to_image(a[:b1 - r0, a0 - c0:a1 - c0], (r0, a0 - c, b1, a1 - c), fill,
                                 (y0, y1, x0, x1), step)
            out[mine] = img[mine]
        return out

    def to_image(self, lattice_array: np.ndarray, fill=0) -> np.ndarray:
        a = np.asarray(lattice_array)
        if a.shape[:2] != self.classes.shape:
            raise ValueError(f"expected a lattice array of shape {self.classes.shape}, got {a.shape}")
        return self.box_to_image(a, (0, 0) + a.shape[:2], fill)

    def lattice_pixels(self, i0: int, i1: int, j0: int = 0, j1: int | None = None):
        j1 = self.classes.shape[1] if j1 is None else j1
        shape = (i1 - i0, j1 - j0)
        xi, yi = np.zeros(shape, np.intp), np.zeros(shape, np.intp)
        inside = np.zeros(shape, bool)
        for k, (t, c) in enumerate(zip(self.tiles, self.cols)):
            a0, a1, b1 = max(j0, c), min(j1, c + t.shape[1]), min(i1, t.shape[0])
            if a0 >= a1 or i0 >= b1:
                continue
            x, y, ok = t.lattice_pixels(i0, b1, a0 - c, a1 - c)
            ok = ok & ~t.outside[i0:b1, a0 - c:a1 - c]
            part = (slice(0, b1 - i0), slice(a0 - j0, a1 - j0))
            xi[part], yi[part], inside[part] = x, y, ok
        return xi, yi, inside


def _tile(classes: np.ndarray, zones: np.ndarray, k: int, theta: float, resolution: float,
          model: Model, origin) -> Frame:
    """Zone ``k``'s own lattice at ``theta``, cut to the zone's known cells and the crop margin:
    other zones' pixels are unknown and outside it."""
    mine = zones == k
    masked = np.where(mine, classes, np.uint8(UNKNOWN)).astype(np.uint8)
    t = build_frame_from_classes(masked, resolution, model, origin, theta=theta, crop_max_share=1.0)
    outside = np.array(t.outside)
    for b0, b1 in t.bands():
        xi, yi, ok = t.lattice_pixels(b0, b1)
        theirs = np.ones(ok.shape, bool)
        theirs[ok] = ~mine[yi[ok], xi[ok]]
        outside[b0:b1] |= theirs
    outside.setflags(write=False)
    own = np.where(outside, np.uint8(UNKNOWN), t.classes)  # a sub-cell may reach a wall of the zone
    own.setflags(write=False)
    return dataclasses.replace(t, classes=own, outside=outside)


def build_tiled_frame(classes: np.ndarray, resolution: float, model: Model, thetas, zones,
                      origin=(0.0, 0.0, 0.0)) -> Frame:
    """The lattice of a map of ``len(thetas)`` building directions, ``zones`` the (H, W) tile
    index of every pixel: a plain :class:`Frame` at ``thetas[0]`` when there is one direction,
    else a :class:`TiledFrame`."""
    classes = np.asarray(classes, dtype=np.uint8)
    thetas = tuple(float(t) for t in thetas)
    if len(thetas) == 1:
        return build_frame_from_classes(classes, resolution, model, origin, theta=thetas[0])
    zones = np.asarray(zones, dtype=np.uint8)
    if zones.shape != classes.shape or int(zones.max()) >= len(thetas):
        raise ValueError(f"zones must be the map's shape {classes.shape} with values below {len(thetas)}")
    tiles = [_tile(classes, zones, k, th, resolution, model, origin) for k, th in enumerate(thetas)]
    gap = tile_gap(tiles[0].cells)
    height = max(t.shape[0] for t in tiles)
    cols, c = [], 0
    for t in tiles:
        cols.append(c)
        c += t.shape[1] + gap
    lat = np.full((height, c - gap), UNKNOWN, np.uint8)
    outside = np.ones(lat.shape, bool)
    for t, c0 in zip(tiles, cols):
        lat[:t.shape[0], c0:c0 + t.shape[1]] = t.classes
        outside[:t.shape[0], c0:c0 + t.shape[1]] = t.outside
    lat.setflags(write=False)
    outside.setflags(write=False)
    zones, classes = zones.copy(), classes.copy()
    zones.setflags(write=False)
    classes.setflags(write=False)
    first = tiles[0]
    return TiledFrame(thetas[0], lat, outside, first.image_shape, first.resolution, first.cells,
                      first.origin, None, first.wall_samples, first.wall_join_px, tuple(tiles),
                      tuple(cols), zones, classes)


def unit_theta(frame, rect) -> float:
    """The orientation (radians) of a unit on ``frame``: its tile's on a :class:`TiledFrame`, the
    frame's θ0 otherwise."""
    return frame.unit_theta(rect) if isinstance(frame, TiledFrame) else float(frame.theta)


def rect_spans(frame) -> tuple[tuple[int, int], ...]:
    """The column ranges a unit must lie within (one of them): a :class:`TiledFrame`'s tiles, none
    (the whole lattice) for a plain :class:`Frame`."""
    return frame.spans if isinstance(frame, TiledFrame) else ()


def building_frame(grid, model: Model) -> Frame:
    """The lattice of an :class:`~semmap_pp.grid.OccupancyGrid`: the building's directions and
    zones (:func:`~semmap_pp.lattice.zones.building_zones`) from the walls, then one lattice at
    θ0 (:func:`~semmap_pp.lattice.frame.build_frame`) when there is one direction, a
    :class:`TiledFrame` of one tile per direction when there are more."""
    frame = build_frame(grid, model)
    zones = building_zones(grid.classes, grid.resolution, model.lattice, frame.theta)
    if len(zones.thetas) == 1:
        return frame
    return build_tiled_frame(grid.classes, grid.resolution, model, zones.thetas, zones.labels,
                             grid.origin)


def directions_text(frame) -> str:
    """``"orientation 12.0 deg"``, or ``"orientations 0.0, 30.1 deg (a lattice each)"`` for a
    building of several directions, for logs."""
    if not rect_spans(frame):
        return f"orientation {math.degrees(frame.theta):.1f} deg"
    return ("orientations " + ", ".join(f"{math.degrees(t.theta):.1f}" for t in frame.tiles)
            + " deg (a lattice each)")
