"""Adjacency, doors and passages between units of two tiles of a tiled lattice
(:mod:`semmap_pp.lattice.tiles`: a building of several directions), for the target and for the
final world alike.

Units of two tiles are never adjacent on the lattice: the tiles lie apart there. In the image
they may share a wall (a room of one wing beside the link corridor of another) or an open side (a
corridor the zones' boundary cuts in two). What they share is read in the image, each unit being
the rectangle its tile's rotation puts there (a pixel is *covered* by a unit when its tile's
lattice puts the pixel's centre inside the unit's cells; its *distance* to a unit is the
Euclidean distance, in pixels, from its centre to the box of the unit's cell centres):

* two units are *adjacent* when their rectangles, each grown by ``adjacency_dilation`` cells on
  every side (the lattice's square dilation, at each unit's own angle), overlap with positive
  area (a rotated-rectangle test), or when an opening joins them;
* an *opening* is an 8-connected run of the free pixels (specks made free) of the boundary
  between their two zones that lie within ``door_max`` of both units and that no third unit
  covers (where two lattices at different angles meet, the units' ends leave wedges of floor
  between them that neither covers; the boundary crosses them), at least ``door_min`` long (its
  bounding box's longer side);
* an opening is a *passage* when it is longer than ``door_max``, or spans the narrower unit's
  interior less a wall band on each side (the open side of a corridor cut in two, as a passage
  without a jamb on the lattice), else a *door*.

One compiled definition serves both users: the target's adjacency and opening evidence
(:func:`cross_all` for a world, :func:`cross_update` after an edit: a pair is recomputed when it
holds an edited unit or when an edited unit's old or new rectangle reaches its window, since a
third unit's cover changes its openings) and :func:`cross_tile_openings` for ``derive_world``.
On a lattice of one direction there is no pair of tiles and nothing is computed
(:data:`NO_CROSS`).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba
import numpy as np
from scipy import ndimage

from semmap_pp.cells import FREE
from semmap_pp.derive.doors import Door


class CrossData(NamedTuple):
    """A tiled lattice's data for the compiled relations (arrays only: numba reads the tuple).

    ``aff`` (T, 6): per tile ``cos θ, sin θ`` and the image and composite-lattice centres of its
    rotation (``x_img, y_img, col_lat, row_lat``); ``spans`` (2T,): the tiles' flat column
    ranges; ``pix`` (P, 2): the free pixels ``(y, x)`` of the boundary between each pair of
    zones, grouped by pair; ``nbr`` (P, 8): the index of each pixel's 8-neighbours in the same
    group (-1: none); ``off`` (T·T + 1,): where the group of tiles ``(a, b)``, ``a < b``, starts
    (index ``a·T + b``); ``ip``: ``adjacency_dilation, door_max, door_min, wall`` in cells."""

    aff: np.ndarray
    spans: np.ndarray
    pix: np.ndarray
    nbr: np.ndarray
    off: np.ndarray
    ip: np.ndarray


def _ro(a):
    a = np.ascontiguousarray(a)
    a.setflags(write=False)
    return a


#: a lattice of one direction: no tiles to relate (the compiled calls return at once)
NO_CROSS = CrossData(_ro(np.zeros((0, 6))), _ro(np.zeros(0, np.int64)), _ro(np.zeros((0, 2), np.int64)),
                     _ro(np.zeros((0, 8), np.int64)), _ro(np.zeros(1, np.int64)), _ro(np.zeros(4, np.int64)))


def _zone_edge(zones: np.ndarray, a: int, b: int) -> np.ndarray:
    """The pixels of zone ``a`` or ``b`` with a 4-neighbour in the other."""
    za, zb = zones == a, zones == b
    four = ndimage.generate_binary_structure(2, 1)
    return (za & ndimage.binary_dilation(zb, structure=four)) | (zb & ndimage.binary_dilation(za, structure=four))


def _neighbours(ys: np.ndarray, xs: np.ndarray) -> np.ndarray:
    """(n, 8) index of each pixel's 8-neighbours among ``(ys, xs)`` (-1 where none)."""
    index = {(int(y), int(x)): i for i, (y, x) in enumerate(zip(ys.tolist(), xs.tolist()))}
    out = np.full((len(ys), 8), -1, np.int64)
    steps = [(dy, dx) for dy in (-1, 0, 1) for dx in (-1, 0, 1) if dy or dx]
    for i, (y, x) in enumerate(zip(ys.tolist(), xs.tolist())):
        for k, (dy, dx) in enumerate(steps):
            out[i, k] = index.get((y + dy, x + dx), -1)
    return out


def cross_data(frame) -> CrossData:
    """The :class:`CrossData` of a lattice: :data:`NO_CROSS` for one of one direction."""
    spans = getattr(frame, "spans", ())
    if not isinstance(spans, tuple) or len(spans) < 2:
        return NO_CROSS
    n = len(frame.tiles)
    aff = np.zeros((n, 6))
    for k, (t, col) in enumerate(zip(frame.tiles, frame.cols)):
        oxi, oyi, oxl, oyl = t._centres()
        aff[k] = (math.cos(t.theta), math.sin(t.theta), oxi, oyi, oxl + col, oyl)
    free = frame.image_door_classes == FREE
    pix, nbr, off = [], [], np.zeros(n * n + 1, np.int64)
    count = 0
    for a in range(n):
        for b in range(n):
            off[a * n + b] = count
            if a < b:
                ys, xs = np.nonzero(_zone_edge(frame.zones, a, b) & free)
                pix.append(np.stack([ys, xs], axis=1).astype(np.int64))
                near = _neighbours(ys, xs)
                nbr.append(np.where(near >= 0, near + count, -1))
                count += len(ys)
    off[n * n] = count
    c = frame.cells
    return CrossData(_ro(aff), _ro(np.asarray([v for s in spans for v in s], np.int64)),
                     _ro(np.concatenate(pix).reshape(-1, 2)), _ro(np.concatenate(nbr).reshape(-1, 8)),
                     _ro(off), _ro(np.array([c.adjacency_dilation, c.door_max, c.door_min, c.wall],
                                            np.int64)))


# ---------------------------------------------------------------------- compiled geometry

@numba.njit(cache=True, nogil=True)
def tile_of(c0, spans):  # pragma: no cover - compiled
    """The tile whose columns hold column ``c0`` (0 without spans)."""
    for k in range(0, spans.shape[0] - 1, 2):
        if c0 < spans[k + 1]:
            return k // 2
    return spans.shape[0] // 2 - 1


@numba.njit(cache=True, nogil=True)
def _to_lattice(aff, k, x, y):  # pragma: no cover - compiled
    """Composite-lattice ``(row, col)`` of image point ``(x, y)`` on tile ``k``."""
    c, s = aff[k, 0], aff[k, 1]
    u, v = x - aff[k, 2], y - aff[k, 3]
    return -s * u + c * v + aff[k, 5], c * u + s * v + aff[k, 4]


@numba.njit(cache=True, nogil=True)
def _to_image(aff, k, r, col):  # pragma: no cover - compiled
    c, s = aff[k, 0], aff[k, 1]
    u, v = col - aff[k, 4], r - aff[k, 5]
    return c * u - s * v + aff[k, 2], s * u + c * v + aff[k, 3]


@numba.njit(cache=True, nogil=True)
def _corners(aff, k, rect, grow):  # pragma: no cover - compiled
    """(4, 2) image corners ``[x, y]`` of a unit's cells grown by ``grow`` cells on every side."""
    out = np.empty((4, 2))
    r0, r1 = rect[0] - 0.5 - grow, rect[2] - 0.5 + grow
    c0, c1 = rect[1] - 0.5 - grow, rect[3] - 0.5 + grow
    rs, cs = (r0, r0, r1, r1), (c0, c1, c1, c0)
    for i in range(4):
        out[i, 0], out[i, 1] = _to_image(aff, k, rs[i], cs[i])
    return out


@numba.njit(cache=True, nogil=True)
def _bbox(aff, k, rect, grow):  # pragma: no cover - compiled
    """The image box ``(x0, y0, x1, y1)`` of a unit's cells grown by ``grow`` cells."""
    p = _corners(aff, k, rect, grow)
    return p[:, 0].min(), p[:, 1].min(), p[:, 0].max(), p[:, 1].max()


@numba.njit(cache=True, nogil=True)
def _separated(p, q, axis_from):  # pragma: no cover - compiled
    """Whether an edge normal of rectangle ``axis_from`` separates ``p`` and ``q`` (touching
    counts as separated: the overlap must have positive area)."""
    for e in range(2):
        ax, ay = axis_from[e + 1, 0] - axis_from[e, 0], axis_from[e + 1, 1] - axis_from[e, 1]
        plo = phi = p[0, 0] * ax + p[0, 1] * ay
        qlo = qhi = q[0, 0] * ax + q[0, 1] * ay
        for i in range(1, 4):
            a = p[i, 0] * ax + p[i, 1] * ay
            b = q[i, 0] * ax + q[i, 1] * ay
            plo, phi, qlo, qhi = min(plo, a), max(phi, a), min(qlo, b), max(qhi, b)
        if phi <= qlo or qhi <= plo:
            return True
    return False


@numba.njit(cache=True, nogil=True)
def grown_overlap(aff, kp, rp, kq, rq, grow):  # pragma: no cover - compiled
    """Whether two units (tiles ``kp``, ``kq``), each grown by ``grow`` cells, overlap."""
    p, q = _corners(aff, kp, rp, grow), _corners(aff, kq, rq, grow)
    return not (_separated(p, q, p) or _separated(p, q, q))


@numba.njit(cache=True, nogil=True)
def facing_lengths(aff, kp, rp, kq, rq):  # pragma: no cover - compiled
    """The lengths (cells) of the sides of two units of two tiles that face each other, for the
    SaLe factor: each unit's side towards the other's centre, a side along its columns (its
    height) when the other's centre lies farther beyond its columns than beyond its rows (as
    :func:`~semmap_pp.target.prior.connecting_length_difference` on one lattice)."""
    out = np.empty(2)
    for w in range(2):
        k, r, ko, o = (kp, rp, kq, rq) if w == 0 else (kq, rq, kp, rp)
        x, y = _to_image(aff, ko, (o[0] + o[2] - 1) / 2.0, (o[1] + o[3] - 1) / 2.0)
        rr, cc = _to_lattice(aff, k, x, y)
        h, wd = r[2] - r[0], r[3] - r[1]
        gap_c = abs(cc - (r[1] + r[3] - 1) / 2.0) - wd / 2.0
        gap_r = abs(rr - (r[0] + r[2] - 1) / 2.0) - h / 2.0
        out[w] = h if gap_c >= gap_r else wd
    return out[0], out[1]


@numba.njit(cache=True, nogil=True)
def _distance(aff, k, rect, x, y):  # pragma: no cover - compiled
    """Distance (pixels) of image point ``(x, y)`` to the box of a unit's cell centres."""
    r, c = _to_lattice(aff, k, x, y)
    dr = max(rect[0] - r, 0.0, r - (rect[2] - 1))
    dc = max(rect[1] - c, 0.0, c - (rect[3] - 1))
    return math.sqrt(dr * dr + dc * dc)


@numba.njit(cache=True, nogil=True)
def _covers(aff, k, rect, x, y):  # pragma: no cover - compiled
    r, c = _to_lattice(aff, k, x, y)
    return rect[0] - 0.5 <= r < rect[2] - 0.5 and rect[1] - 0.5 <= c < rect[3] - 0.5


@numba.njit(cache=True, nogil=True)
def pair_components(rects, active, i, j, pix, nbr, off, aff, spans, ip):  # pragma: no cover
    """``(adjacent by the grown rectangles, labels, n)``: the openings (module docstring) of
    units ``i`` and ``j`` of two tiles, as component labels 1..n over their zones' pixel group
    (0: no opening pixel); components shorter than ``door_min`` are left out (label 0)."""
    ki, kj = tile_of(rects[i, 1], spans), tile_of(rects[j, 1], spans)
    a, b = min(ki, kj), max(ki, kj)
    n_t = aff.shape[0]
    g0, g1 = off[a * n_t + b], off[a * n_t + b + 1]
    labels = np.zeros(g1 - g0, np.int64)
    adjacent = grown_overlap(aff, ki, rects[i], kj, rects[j], float(ip[0]))
    reach = float(ip[1])
    x0, y0, x1, y1 = _bbox(aff, ki, rects[i], reach)
    u0, v0, u1, v1 = _bbox(aff, kj, rects[j], reach)
    x0, y0, x1, y1 = max(x0, u0), max(y0, v0), min(x1, u1), min(y1, v1)
    cand = np.zeros(g1 - g0, np.bool_)
    for p in range(g0, g1):
        y, x = float(pix[p, 0]), float(pix[p, 1])
        if x < x0 or x > x1 or y < y0 or y > y1:
            continue
        if _distance(aff, ki, rects[i], x, y) > reach or _distance(aff, kj, rects[j], x, y) > reach:
            continue
        free = True
        for t in range(rects.shape[0]):
            if t != i and t != j and active[t] and _covers(aff, tile_of(rects[t, 1], spans), rects[t], x, y):
                free = False
                break
        cand[p - g0] = free
    n = 0
    stack = np.empty(g1 - g0, np.int64)
    for p in range(g1 - g0):
        if not cand[p] or labels[p] != 0:
            continue
        n += 1
        labels[p], top, stack[0] = n, 1, p
        ylo = yhi = pix[g0 + p, 0]
        xlo = xhi = pix[g0 + p, 1]
        while top:
            top -= 1
            q = stack[top]
            for m in range(8):
                s = nbr[g0 + q, m]
                if s >= 0 and cand[s - g0] and labels[s - g0] == 0:
                    labels[s - g0] = n
                    stack[top] = s - g0
                    top += 1
                    ylo, yhi = min(ylo, pix[s, 0]), max(yhi, pix[s, 0])
                    xlo, xhi = min(xlo, pix[s, 1]), max(xhi, pix[s, 1])
        if max(yhi - ylo + 1, xhi - xlo + 1) < ip[2]:
            for q in range(g1 - g0):
                if labels[q] == n:
                    labels[q] = -1
            n -= 1
    for q in range(g1 - g0):
        labels[q] = max(labels[q], 0)
    return adjacent, labels, n


@numba.njit(cache=True, nogil=True)
def _width(labels, pix, g0, m):  # pragma: no cover - compiled
    ylo = xlo = 1 << 40
    yhi = xhi = -1
    for q in range(labels.shape[0]):
        if labels[q] == m:
            ylo, yhi = min(ylo, pix[g0 + q, 0]), max(yhi, pix[g0 + q, 0])
            xlo, xhi = min(xlo, pix[g0 + q, 1]), max(xhi, pix[g0 + q, 1])
    return max(yhi - ylo + 1, xhi - xlo + 1)


@numba.njit(cache=True, nogil=True)
def _short(rect, wall):  # pragma: no cover - compiled
    return max(min(rect[2] - rect[0], rect[3] - rect[1]) - 2 * wall, 1)


@numba.njit(cache=True, nogil=True)
def cross_pair(rects, active, i, j, pix, nbr, off, aff, spans, ip):  # pragma: no cover
    """``(adjacent, doors, passages)`` of units ``i`` and ``j`` of two tiles."""
    adjacent, labels, n = pair_components(rects, active, i, j, pix, nbr, off, aff, spans, ip)
    if n == 0:
        return adjacent, 0, 0
    ki, kj = tile_of(rects[i, 1], spans), tile_of(rects[j, 1], spans)
    g0 = off[min(ki, kj) * aff.shape[0] + max(ki, kj)]
    shared = min(_short(rects[i], ip[3]), _short(rects[j], ip[3]))
    doors = passages = 0
    for m in range(1, n + 1):
        w = _width(labels, pix, g0, m)
        if w > ip[1] or w >= shared - 2 * ip[3]:
            passages += 1
        else:
            doors += 1
    return True, doors, passages


@numba.njit(cache=True, nogil=True)
def _boxes(rects, active, aff, spans, grow):  # pragma: no cover - compiled
    """(K, 4) image boxes of the active units grown by ``grow`` cells (NaN for empty slots)."""
    out = np.full((rects.shape[0], 4), np.nan)
    for s in range(rects.shape[0]):
        if active[s]:
            out[s, 0], out[s, 1], out[s, 2], out[s, 3] = _bbox(aff, tile_of(rects[s, 1], spans), rects[s], grow)
    return out


@numba.njit(cache=True, nogil=True)
def _meets(a, b):  # pragma: no cover - compiled
    return a[0] <= b[2] and b[0] <= a[2] and a[1] <= b[3] and b[1] <= a[3]


@numba.njit(cache=True, nogil=True)
def _set_pair(rects, active, p, q, reach_box, adj, xo, xd):  # pragma: no cover - compiled
    """Recompute the pair ``(p, q)`` into ``adj`` and ``xo`` (``xo`` empty: adjacency alone);
    returns whether anything changed."""
    aff, spans, pix, nbr, off, ip = xd
    a, d, g = False, 0, 0
    if _meets(reach_box[p], reach_box[q]):
        a, d, g = cross_pair(rects, active, p, q, pix, nbr, off, aff, spans, ip)
    changed = adj[p, q] != a
    adj[p, q] = adj[q, p] = a
    if xo.shape[0] > 0:
        changed = changed or xo[p, q, 0] != d or xo[p, q, 1] != g
        xo[p, q, 0] = xo[q, p, 0] = d
        xo[p, q, 1] = xo[q, p, 1] = g
    return changed


@numba.njit(cache=True, nogil=True)
def _reach(xd):  # pragma: no cover - compiled
    """How far (cells) from a unit a pair's relation can reach: the door width or the dilation."""
    return float(max(xd[5][0], xd[5][1]))


@numba.njit(cache=True, nogil=True)
def cross_all(rects, active, adj, xo, xd):  # pragma: no cover - compiled
    """Every pair of active units of two tiles into ``adj`` (K, K) and ``xo`` (K, K, 2) (doors,
    passages; may be empty), from scratch."""
    aff, spans = xd[0], xd[1]
    if aff.shape[0] < 2:
        return
    box = _boxes(rects, active, aff, spans, _reach(xd))
    for p in range(rects.shape[0]):
        if not active[p]:
            continue
        for q in range(p + 1, rects.shape[0]):
            if active[q] and tile_of(rects[p, 1], spans) != tile_of(rects[q, 1], spans):
                _set_pair(rects, active, p, q, box, adj, xo, xd)


@numba.njit(cache=True, nogil=True)
def cross_update(old_rects, old_active, rects, active, changed, adj, xo, touched,
                 xd):  # pragma: no cover - compiled
    """After an edit of the slots ``changed`` (the old world ``old_*``, the new ``rects``,
    ``active``; ``adj``'s rows of the changed slots already cleared and their lattice adjacency
    set): the pairs of two tiles that hold a changed slot, and those whose window a changed
    slot's old or new rectangle reaches (a third unit's cover changes their openings),
    recomputed in ``adj`` and ``xo`` (see :func:`cross_all`); ``touched`` marks the slots of
    every pair without a changed slot that changed. Equal to :func:`cross_all` of the new world
    (tests/unit/test_tiles.py)."""
    aff, spans = xd[0], xd[1]
    if aff.shape[0] < 2:
        return
    K = rects.shape[0]
    box = _boxes(rects, active, aff, spans, _reach(xd))
    is_changed = np.zeros(K, np.bool_)
    for s in changed:
        is_changed[s] = True
        if xo.shape[0] > 0:
            xo[s, :, :] = 0
            xo[:, s, :] = 0
    for s in changed:
        if not active[s]:
            continue
        for t in range(K):
            if t != s and active[t] and (not is_changed[t] or t > s) and \
                    tile_of(rects[s, 1], spans) != tile_of(rects[t, 1], spans):
                _set_pair(rects, active, s, t, box, adj, xo, xd)
    near = np.zeros(K, np.bool_)
    sb = np.empty(4)
    for s in changed:
        for which in range(2):
            r, on = (old_rects[s], old_active[s]) if which == 0 else (rects[s], active[s])
            if not on:
                continue
            sb[0], sb[1], sb[2], sb[3] = _bbox(aff, tile_of(r[1], spans), r, 0.5)
            for t in range(K):
                if active[t] and not is_changed[t] and _meets(box[t], sb):
                    near[t] = True
    for p in range(K):
        if not near[p]:
            continue
        for q in range(p + 1, K):
            if near[q] and tile_of(rects[p, 1], spans) != tile_of(rects[q, 1], spans):
                if _set_pair(rects, active, p, q, box, adj, xo, xd):
                    touched[p] = touched[q] = True


def cross_tile_openings(frame, rects: np.ndarray, slots, xd: CrossData | None = None):
    """``(pairs, doors, passages)`` between units of different tiles: ``pairs`` the adjacent
    index pairs ``(i, j)`` into ``rects`` (``i < j``), the openings as :class:`Door` with slots
    from ``slots``; an opening's box is the lattice box of its pixels on the first unit's tile (a
    door drawn on that tile's lattice, as any other door)."""
    xd = cross_data(frame) if xd is None else xd
    rects = np.ascontiguousarray(np.asarray(rects, np.int64).reshape(-1, 4))
    active = np.ones(len(rects), np.bool_)
    aff, spans, pix, nbr, off, ip = xd
    tiles = [int(tile_of(r[1], spans)) for r in rects]
    pairs, doors, passages = [], [], []
    for i in range(len(rects)):
        for j in range(i + 1, len(rects)):
            if tiles[i] == tiles[j]:
                continue
            adjacent, labels, n = pair_components(rects, active, i, j, pix, nbr, off, aff, spans, ip)
            if not (adjacent or n):
                continue
            pairs.append((i, j))
            a, b = sorted((tiles[i], tiles[j]))
            g0 = int(off[a * len(aff) + b])
            shared = min(int(_short(rects[i], ip[3])), int(_short(rects[j], ip[3])))
            for m in range(1, n + 1):
                ys, xs = pix[g0 + np.flatnonzero(labels == m)].T
                width = max(int(ys.max() - ys.min() + 1), int(xs.max() - xs.min() + 1))
                is_passage = width > ip[1] or width >= shared - 2 * ip[3]
                door = Door(int(slots[i]), int(slots[j]), _box_on_tile(frame, tiles[i], ys, xs), False, width)
                (passages if is_passage else doors).append(door)
    return pairs, doors, passages


def _box_on_tile(frame, k: int, ys, xs):
    """The lattice box, on tile ``k`` of a tiled frame, of the pixels ``(ys, xs)``."""
    r, c = frame.tile_image_to_lattice(k, xs.astype(np.float64), ys.astype(np.float64))
    r0, c0 = int(np.floor(r.min() + 0.5)), int(np.floor(c.min() + 0.5))
    r1, c1 = int(np.floor(r.max() + 0.5)) + 1, int(np.floor(c.max() + 0.5)) + 1
    lo, hi = frame.spans[k]
    return (max(r0, 0), max(c0, lo), max(min(r1, frame.shape[0]), r0 + 1), max(min(c1, hi), c0 + 1))


def rect_tiles(rects, xd: CrossData) -> np.ndarray:
    """The tile of each rectangle (n, 4) (all 0 on a lattice of one direction)."""
    r = np.asarray(rects).reshape(-1, 4)
    if len(xd.aff) < 2:
        return np.zeros(len(r), np.intp)
    return np.array([tile_of(int(c0), xd.spans) for c0 in r[:, 1].tolist()], np.intp)
