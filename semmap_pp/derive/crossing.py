"""Adjacency, doors and passages between units of two tiles of a tiled lattice
(:mod:`semmap_pp.lattice.tiles`: a building of several directions).

Units of two tiles are never adjacent on the lattice: the tiles lie apart there. In the image
they may share a wall (a room of one wing beside the link corridor of another) or an open side (a
corridor the zones' boundary cuts in two). The rules are those of :mod:`semmap_pp.derive.doors`,
read on the image's pixels instead of a shared wall strip of the lattice:

* two units are *adjacent* when their rectangles, each grown by ``adjacency_dilation``, overlap
  (the same dilation as on the lattice); the overlap is their *contact*, a band along the side
  they share;
* the contact's lines across (one per pixel along the band's long axis, its principal axis) are
  *open* when every pixel of the line is free (the doorways' classes, specks made free), *walled*
  when one is occupied;
* a run of open lines at least ``door_min`` long is an opening: a *passage* when it is longer than
  ``door_max`` or has no jamb (open or unknown lines up to both ends of the contact), else a
  *door*.

An opening's ``box`` is the lattice box of its pixels on the first unit's tile (a door drawn on
that tile's lattice, as any other door).
"""

from __future__ import annotations

import math

import numpy as np
from scipy import ndimage

from semmap_pp.cells import FREE, OCCUPIED
from semmap_pp.derive.doors import Door, open_runs


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


def _grown(fp, d: int, box):
    """A footprint grown by ``d`` pixels, on the window ``box`` ``(y0, x0, y1, x1)``."""
    mask, (oy, ox) = fp
    y0, x0, y1, x1 = box
    out = np.zeros((y1 - y0 + 2 * d, x1 - x0 + 2 * d), bool)     # the window and d around it
    a0, b0 = max(oy, y0 - d), max(ox, x0 - d)
    a1, b1 = min(oy + mask.shape[0], y1 + d), min(ox + mask.shape[1], x1 + d)
    if a1 > a0 and b1 > b0:
        out[a0 - y0 + d:a1 - y0 + d, b0 - x0 + d:b1 - x0 + d] = mask[a0 - oy:a1 - oy, b0 - ox:b1 - ox]
    if d > 0:
        out = ndimage.binary_dilation(out, iterations=d)
    return out[d:d + y1 - y0, d:d + x1 - x0]


def _contact(fp_p, fp_q, d: int):
    """The pixels of the contact of two footprints (each grown by ``d``): ``(ys, xs)`` or None."""
    (mp, (py, px)), (mq, (qy, qx)) = fp_p, fp_q
    y0, x0 = max(py, qy) - d, max(px, qx) - d
    y1, x1 = min(py + mp.shape[0], qy + mq.shape[0]) + d, min(px + mp.shape[1], qx + mq.shape[1]) + d
    if y1 <= y0 or x1 <= x0:
        return None
    y0, x0 = max(y0, 0), max(x0, 0)
    both = _grown(fp_p, d, (y0, x0, y1, x1)) & _grown(fp_q, d, (y0, x0, y1, x1))
    ys, xs = np.nonzero(both)
    return (ys + y0, xs + x0) if len(ys) else None


def _inner(frame, rect, wall: int):
    r0, c0, r1, c1 = (int(v) for v in rect)
    return (r0 + wall, c0 + wall, max(r1 - wall, r0 + wall + 1), max(c1 - wall, c0 + wall + 1))


def _short_side(rect, wall: int) -> int:
    r0, c0, r1, c1 = (int(v) for v in rect)
    return max(min(r1 - r0, c1 - c0) - 2 * wall, 1)


def openings_in_contact(classes_img: np.ndarray, ys, xs, towards: np.ndarray, cells,
                        shared: int):
    """``(width, is_passage, pixels)`` of every opening of a contact: a component (8-connected)
    of its free pixels at least ``door_min`` wide, its width its extent across ``towards`` (the
    direction from one unit's interior to the other's); a passage when wider than ``door_max``
    or when it spans ``shared`` (the narrower interior's short side) less a wall band on each
    side: an open side, not a door in a wall."""
    free = classes_img[ys, xs] == FREE
    if not free.any():
        return []
    y0, x0 = ys.min(), xs.min()
    grid = np.zeros((ys.max() - y0 + 1, xs.max() - x0 + 1), bool)
    grid[ys[free] - y0, xs[free] - x0] = True
    labels, n = ndimage.label(grid, structure=np.ones((3, 3), bool))
    across = np.array([-towards[1], towards[0]])
    out = []
    for k in range(1, n + 1):
        py, px = np.nonzero(labels == k)
        t = (px + x0) * across[0] + (py + y0) * across[1]
        width = int(round(t.max() - t.min())) + 1
        if width < cells.door_min:
            continue
        is_passage = width > cells.door_max or width >= shared - 2 * cells.wall
        out.append((width, is_passage, (py + y0, px + x0)))
    return out


def _centre(frame, rect, wall: int) -> np.ndarray:
    """A unit's interior centre ``[x, y]`` in the image."""
    return frame.rect_vertices_px(_inner(frame, rect, wall)).mean(axis=0)


def _box_on_tile(frame, k: int, ys, xs):
    """The lattice box, on tile ``k`` of a tiled frame, of the pixels ``(ys, xs)``."""
    r, c = frame.tile_image_to_lattice(k, xs.astype(np.float64), ys.astype(np.float64))
    r0, c0 = int(np.floor(r.min() + 0.5)), int(np.floor(c.min() + 0.5))
    r1, c1 = int(np.floor(r.max() + 0.5)) + 1, int(np.floor(c.max() + 0.5)) + 1
    lo, hi = frame.spans[k]
    return (max(r0, 0), max(c0, lo), max(min(r1, frame.shape[0]), r0 + 1), max(min(c1, hi), c0 + 1))


def cross_tile_openings(frame, rects: np.ndarray, slots, classes_img: np.ndarray, cells):
    """``(pairs, doors, passages)`` between units of different tiles: ``pairs`` the adjacent
    index pairs ``(i, j)`` into ``rects`` (``i < j``), the openings as :class:`Door` with slots
    from ``slots``. ``classes_img``: the image's classes with specks made free."""
    rects = np.asarray(rects).reshape(-1, 4)
    tiles = [frame.tile_of_rect(r) for r in rects]
    d = int(cells.adjacency_dilation)
    fps = [_footprint(frame, r, 0) for r in rects]
    pairs, doors, passages = [], [], []
    for i in range(len(rects)):
        for j in range(i + 1, len(rects)):
            if tiles[i] == tiles[j]:
                continue
            contact = _contact(fps[i], fps[j], d)
            if contact is None:
                continue
            pairs.append((i, j))
            ys, xs = contact
            towards = _centre(frame, rects[j], cells.wall) - _centre(frame, rects[i], cells.wall)
            towards = towards / max(np.hypot(*towards), 1e-9)
            shared = min(_short_side(rects[i], cells.wall), _short_side(rects[j], cells.wall))
            for width, is_passage, (py, px) in openings_in_contact(classes_img, ys, xs, towards,
                                                                   cells, shared):
                box = _box_on_tile(frame, tiles[i], py, px)
                door = Door(int(slots[i]), int(slots[j]), box, False, int(width))
                (passages if is_passage else doors).append(door)
    return pairs, doors, passages
