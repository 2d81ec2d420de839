"""Adjacency, doors and passages between units of two tiles of a tiled lattice
(:mod:`semmap_pp.lattice.tiles`: a building of several directions).

Units of two tiles are never adjacent on the lattice: the tiles lie apart there. In the image
they may share a wall (a room of one wing beside the link corridor of another) or an open side (a
corridor the zones' boundary cuts in two). What they share is read on the image's pixels, the
doorways' classes (specks made free):

* two units are *adjacent* when their rectangles, each grown by ``adjacency_dilation``, overlap
  (the same dilation as on the lattice), or when an opening joins them;
* an *opening* is a run (8-connected) of free pixels of the boundary between their two zones
  that lies within ``door_max`` of both rectangles (where two lattices at different angles meet,
  the units' ends leave wedges of floor between them that neither covers; the boundary crosses
  them), at least ``door_min`` long;
* an opening is a *passage* when it is longer than ``door_max``, or spans the narrower unit's
  interior less a wall band on each side (the open side of a corridor cut in two, as a passage
  without a jamb on the lattice), else a *door*.

An opening's ``box`` is the lattice box of its pixels on the first unit's tile (a door drawn on
that tile's lattice, as any other door).
"""

from __future__ import annotations

import math

import numpy as np
from scipy import ndimage

from semmap_pp.cells import FREE
from semmap_pp.derive.doors import Door


def _footprint(frame, rect, pad: int):
    """The image pixels of a unit's rectangle (those whose centre its tile's lattice puts inside
    it): ``(mask, (y0, x0))`` of its bounding box grown by ``pad`` pixels, clipped to the image."""
    k = frame.tile_of_rect(rect)
    v = frame.rect_vertices_px(rect)
    h, w = frame.image_shape
    x0, y0 = max(int(math.floor(v[:, 0].min())) - pad, 0), max(int(math.floor(v[:, 1].min())) - pad, 0)
    x1, y1 = min(int(math.ceil(v[:, 0].max())) + pad, w), min(int(math.ceil(v[:, 1].max())) + pad, h)
    yy, xx = np.mgrid[y0:max(y1, y0), x0:max(x1, x0)]
    r, c = frame.tile_image_to_lattice(k, xx.astype(np.float64), yy.astype(np.float64))
    r0, c0, r1, c1 = (int(v) for v in rect)
    mask = (r >= r0 - 0.5) & (r < r1 - 0.5) & (c >= c0 - 0.5) & (c < c1 - 0.5)
    return mask, (y0, x0)


def _distance_within(fp, box):
    """Distance (pixels) of every pixel of the window ``box`` ``(y0, x0, y1, x1)`` to a footprint."""
    mask, (oy, ox) = fp
    y0, x0, y1, x1 = box
    out = np.zeros((y1 - y0, x1 - x0), bool)
    a0, b0 = max(oy, y0), max(ox, x0)
    a1, b1 = min(oy + mask.shape[0], y1), min(ox + mask.shape[1], x1)
    if a1 > a0 and b1 > b0:
        out[a0 - y0:a1 - y0, b0 - x0:b1 - x0] = mask[a0 - oy:a1 - oy, b0 - ox:b1 - ox]
    if not out.any():
        return np.full(out.shape, np.inf)
    return ndimage.distance_transform_edt(~out)


def _window(fp_p, fp_q, reach: int, shape):
    """The window ``(y0, x0, y1, x1)`` of pixels within ``reach`` of both footprints' boxes, or
    None when their boxes lie farther apart."""
    (mp, (py, px)), (mq, (qy, qx)) = fp_p, fp_q
    y0, x0 = max(py, qy) - reach, max(px, qx) - reach
    y1 = min(py + mp.shape[0], qy + mq.shape[0]) + reach
    x1 = min(px + mp.shape[1], qx + mq.shape[1]) + reach
    y0, x0, y1, x1 = max(y0, 0), max(x0, 0), min(y1, shape[0]), min(x1, shape[1])
    return (y0, x0, y1, x1) if y1 > y0 and x1 > x0 else None


def _zone_edge(zones: np.ndarray, a: int, b: int) -> np.ndarray:
    """The pixels of zone ``a`` or ``b`` with a 4-neighbour in the other."""
    za, zb = zones == a, zones == b
    near_b = ndimage.binary_dilation(zb, structure=ndimage.generate_binary_structure(2, 1))
    near_a = ndimage.binary_dilation(za, structure=ndimage.generate_binary_structure(2, 1))
    return (za & near_b) | (zb & near_a)


def openings_on_edge(free_edge: np.ndarray, cells, shared: int):
    """``(width, is_passage, (ys, xs))`` of every opening (module docstring) among the free edge
    pixels ``free_edge`` of a window; ``shared``: the narrower interior's short side."""
    labels, n = ndimage.label(free_edge, structure=np.ones((3, 3), bool))
    out = []
    for k, sl in enumerate(ndimage.find_objects(labels), start=1):
        width = max(sl[0].stop - sl[0].start, sl[1].stop - sl[1].start)
        if width < cells.door_min:
            continue
        ys, xs = np.nonzero(labels[sl] == k)
        is_passage = width > cells.door_max or width >= shared - 2 * cells.wall
        out.append((width, is_passage, (ys + sl[0].start, xs + sl[1].start)))
    return out


def _short_side(rect, wall: int) -> int:
    """The short side of a unit's interior, in cells."""
    r0, c0, r1, c1 = (int(v) for v in rect)
    return max(min(r1 - r0, c1 - c0) - 2 * wall, 1)


def _box_on_tile(frame, k: int, ys, xs):
    """The lattice box, on tile ``k`` of a tiled frame, of the pixels ``(ys, xs)``."""
    r, c = frame.tile_image_to_lattice(k, xs.astype(np.float64), ys.astype(np.float64))
    r0, c0 = int(np.floor(r.min() + 0.5)), int(np.floor(c.min() + 0.5))
    r1, c1 = int(np.floor(r.max() + 0.5)) + 1, int(np.floor(c.max() + 0.5)) + 1
    lo, hi = frame.spans[k]
    return (max(r0, 0), max(c0, lo), max(min(r1, frame.shape[0]), r0 + 1), max(min(c1, hi), c0 + 1))


def _cover(fps, shape) -> np.ndarray:
    """How many units' footprints cover each pixel."""
    cover = np.zeros(shape, np.int16)
    for mask, (oy, ox) in fps:
        cover[oy:oy + mask.shape[0], ox:ox + mask.shape[1]] += mask
    return cover


def _pair(frame, fps, rects, i, j, edge, classes_img, cells, cover):
    """``(adjacent, openings)`` of units ``i`` and ``j`` of two tiles (module docstring): the
    openings on free edge pixels within reach of both that no third unit covers."""
    d, reach = int(cells.adjacency_dilation), int(cells.door_max)
    box = _window(fps[i], fps[j], reach, frame.image_shape)
    if box is None:
        return False, []
    y0, x0, y1, x1 = box
    di, dj = _distance_within(fps[i], box), _distance_within(fps[j], box)
    adjacent = bool(((di <= d) & (dj <= d)).any())
    others = cover[y0:y1, x0:x1] - (di == 0) - (dj == 0) > 0
    cand = (edge[y0:y1, x0:x1] & (di <= reach) & (dj <= reach) & ~others
            & (classes_img[y0:y1, x0:x1] == FREE))
    shared = min(_short_side(rects[i], cells.wall), _short_side(rects[j], cells.wall))
    found = [(w, p, (ys + y0, xs + x0)) for w, p, (ys, xs) in openings_on_edge(cand, cells, shared)]
    return adjacent or bool(found), found


def cross_tile_openings(frame, rects: np.ndarray, slots, classes_img: np.ndarray, cells):
    """``(pairs, doors, passages)`` between units of different tiles: ``pairs`` the adjacent
    index pairs ``(i, j)`` into ``rects`` (``i < j``), the openings as :class:`Door` with slots
    from ``slots``. ``classes_img``: the image's classes with specks made free."""
    rects = np.asarray(rects).reshape(-1, 4)
    tiles = [frame.tile_of_rect(r) for r in rects]
    fps = [_footprint(frame, r, 0) for r in rects]
    cover = _cover(fps, frame.image_shape)
    edges: dict = {}
    pairs, doors, passages = [], [], []
    for i in range(len(rects)):
        for j in range(i + 1, len(rects)):
            a, b = sorted((tiles[i], tiles[j]))
            if a == b:
                continue
            if (a, b) not in edges:
                edges[(a, b)] = _zone_edge(frame.zones, a, b)
            adjacent, found = _pair(frame, fps, rects, i, j, edges[(a, b)], classes_img, cells, cover)
            if not adjacent:
                continue
            pairs.append((i, j))
            for width, is_passage, (ys, xs) in found:
                box = _box_on_tile(frame, tiles[i], ys, xs)
                door = Door(int(slots[i]), int(slots[j]), box, False, int(width))
                (passages if is_passage else doors).append(door)
    return pairs, doors, passages
