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
  between their two zones that lie within ``door_max`` of both units, that no third unit
  covers (where two lattices at different angles meet, the units' ends leave wedges of floor
  between them that neither covers; the boundary crosses them) and to which no other unit of
  either unit's tile lies nearer (a doorway joins the two spaces on its two sides: the room
  beside the one behind it, also within ``door_max``, is not the doorway's); its *width along a tile* is the
  larger extent of its pixel centres along that tile's two axes, plus one, and it is kept when it
  is at least ``door_min`` wide along both tiles and, unless it is a passage (below), has a *jamb*
  at each end: a pixel of the run touching an occupied pixel within ``wall`` pixels of each of
  its two extreme pixels (along the image axis it extends most along). A doorway ends at the
  wall it is cut in; a run of the free rays of a fan, seen through a window into the space
  between two wings, ends at the unknown cells between the rays;
* an opening is a *passage* when it is wider than ``door_max`` along both tiles (a door lies in
  a wall of one of them, and along that tile's axes its width is the door's: a zones' boundary
  that crosses a doorway at an angle holds a longer run of pixels), or when it spans either
  unit's interior less a wall band on each side, measured along that unit's tile (the open side
  of a corridor cut in two, as a passage without a jamb on the lattice), else a *door*, whose
  width is the smaller of the two.

One compiled definition serves both users: the target's adjacency and opening evidence
(:func:`cross_all` for a world, :func:`cross_update` after an edit: a pair is recomputed only
when an opening pixel's candidacy for it changed, which the cells an edit changed bound, or when
it holds a unit new on its tile or one whose shorter side changed) and
:func:`cross_tile_openings` for ``derive_world``.
On a lattice of one direction there is no pair of tiles and nothing is computed
(:data:`NO_CROSS`).
"""

from __future__ import annotations

import math
import weakref
from typing import NamedTuple

import numba
import numpy as np
from scipy import ndimage

from semmap_pp.cells import FREE, OCCUPIED
from semmap_pp.derive.doors import Door


class CrossData(NamedTuple):
    """A tiled lattice's data for the compiled relations (arrays only: numba reads the tuple).

    ``aff`` (T, 6): per tile ``cos θ, sin θ`` and the image and composite-lattice centres of its
    rotation (``x_img, y_img, col_lat, row_lat``); ``spans`` (2T,): the tiles' flat column
    ranges; ``pix`` (P, 3): the free pixels ``(y, x)`` of the boundary between each pair of
    zones, grouped by pair, and whether an occupied pixel is among each one's 8 neighbours (a
    jamb, 1 or 0); ``nbr`` (P, 8): the index of each pixel's 8-neighbours in the same
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
NO_CROSS = CrossData(_ro(np.zeros((0, 6))), _ro(np.zeros(0, np.int64)), _ro(np.zeros((0, 3), np.int64)),
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
    """The :class:`CrossData` of a lattice: :data:`NO_CROSS` for one of one direction. Built once
    per frame (frames are frozen) and kept while the frame lives."""
    try:
        return _CROSS_DATA[frame]
    except (KeyError, TypeError):
        pass
    xd = _cross_data(frame)
    try:
        _CROSS_DATA[frame] = xd
    except TypeError:        # a frame that cannot be weakly referenced: built every time
        pass
    return xd


#: :func:`cross_data` per frame, dropped with the frame.
_CROSS_DATA = weakref.WeakKeyDictionary()


def _cross_data(frame) -> CrossData:
    spans = getattr(frame, "spans", ())
    if not isinstance(spans, tuple) or len(spans) < 2:
        return NO_CROSS
    n = len(frame.tiles)
    aff = np.zeros((n, 6))
    for k, (t, col) in enumerate(zip(frame.tiles, frame.cols)):
        oxi, oyi, oxl, oyl = t._centres()
        aff[k] = (math.cos(t.theta), math.sin(t.theta), oxi, oyi, oxl + col, oyl)
    free = frame.image_door_classes == FREE
    jamb = ndimage.binary_dilation(frame.image_door_classes == OCCUPIED, structure=np.ones((3, 3), bool))
    pix, nbr, off = [], [], np.zeros(n * n + 1, np.int64)
    count = 0
    for a in range(n):
        for b in range(n):
            off[a * n + b] = count
            if a < b:
                ys, xs = np.nonzero(_zone_edge(frame.zones, a, b) & free)
                pix.append(np.stack([ys, xs, jamb[ys, xs]], axis=1).astype(np.int64))
                near = _neighbours(ys, xs)
                nbr.append(np.where(near >= 0, near + count, -1))
                count += len(ys)
    off[n * n] = count
    c = frame.cells
    return CrossData(_ro(aff), _ro(np.asarray([v for s in spans for v in s], np.int64)),
                     _ro(np.concatenate(pix).reshape(-1, 3)), _ro(np.concatenate(nbr).reshape(-1, 8)),
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
    """The image corners ``(xs, ys)`` (4-tuples, in order round the rectangle) of a unit's cells
    grown by ``grow`` cells on every side."""
    r0, r1 = rect[0] - 0.5 - grow, rect[2] - 0.5 + grow
    c0, c1 = rect[1] - 0.5 - grow, rect[3] - 0.5 + grow
    x0, y0 = _to_image(aff, k, r0, c0)
    x1, y1 = _to_image(aff, k, r0, c1)
    x2, y2 = _to_image(aff, k, r1, c1)
    x3, y3 = _to_image(aff, k, r1, c0)
    return (x0, x1, x2, x3), (y0, y1, y2, y3)


@numba.njit(cache=True, nogil=True)
def _bbox(aff, k, rect, grow):  # pragma: no cover - compiled
    """The image box ``(x0, y0, x1, y1)`` of a unit's cells grown by ``grow`` cells."""
    xs, ys = _corners(aff, k, rect, grow)
    return (min(min(xs[0], xs[1]), min(xs[2], xs[3])), min(min(ys[0], ys[1]), min(ys[2], ys[3])),
            max(max(xs[0], xs[1]), max(xs[2], xs[3])), max(max(ys[0], ys[1]), max(ys[2], ys[3])))


@numba.njit(cache=True, nogil=True)
def _span(xs, ys, ax, ay):  # pragma: no cover - compiled
    a, b = xs[0] * ax + ys[0] * ay, xs[1] * ax + ys[1] * ay
    c, d = xs[2] * ax + ys[2] * ay, xs[3] * ax + ys[3] * ay
    return min(min(a, b), min(c, d)), max(max(a, b), max(c, d))


@numba.njit(cache=True, nogil=True)
def _separated(pxs, pys, qxs, qys, axs, ays):  # pragma: no cover - compiled
    """Whether an edge normal of the rectangle with corners ``(axs, ays)`` separates rectangles
    ``p`` and ``q`` (touching counts as separated: the overlap must have positive area)."""
    for e in range(2):
        ax, ay = axs[e + 1] - axs[e], ays[e + 1] - ays[e]
        plo, phi = _span(pxs, pys, ax, ay)
        qlo, qhi = _span(qxs, qys, ax, ay)
        if phi <= qlo or qhi <= plo:
            return True
    return False


@numba.njit(cache=True, nogil=True)
def grown_overlap(aff, kp, rp, kq, rq, grow):  # pragma: no cover - compiled
    """Whether two units (tiles ``kp``, ``kq``), each grown by ``grow`` cells, overlap."""
    pxs, pys = _corners(aff, kp, rp, grow)
    qxs, qys = _corners(aff, kq, rq, grow)
    return not (_separated(pxs, pys, qxs, qys, pxs, pys) or _separated(pxs, pys, qxs, qys, qxs, qys))


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
def _distance2(aff, k, rects, u, x, y):  # pragma: no cover - compiled
    """Squared distance (pixels²) of image point ``(x, y)`` to the box of the cell centres of unit
    ``u`` (a row of ``rects``, read in place: no view of the row in the inner loops)."""
    r, c = _to_lattice(aff, k, x, y)
    return _distance2_at(rects, u, r, c)


@numba.njit(cache=True, nogil=True)
def _distance2_at(rects, u, r, c):  # pragma: no cover - compiled
    """:func:`_distance2` of the point at ``(r, c)`` on the unit's tile's lattice."""
    dr = max(rects[u, 0] - r, 0.0, r - (rects[u, 2] - 1))
    dc = max(rects[u, 1] - c, 0.0, c - (rects[u, 3] - 1))
    return dr * dr + dc * dc


@numba.njit(cache=True, nogil=True)
def _covers_at(rects, u, r, c):  # pragma: no cover - compiled
    """Whether the point at ``(r, c)`` on the lattice of unit ``u``'s tile (a pixel's centre, by
    :func:`_to_lattice`) lies inside the unit's cells (``u`` a row of ``rects``)."""
    return rects[u, 0] - 0.5 <= r < rects[u, 2] - 0.5 and rects[u, 1] - 0.5 <= c < rects[u, 3] - 0.5


@numba.njit(cache=True, nogil=True)
def _rows(pix, g0, g1, y0, y1):  # pragma: no cover - compiled
    """The index range ``[lo, hi)`` of the pixels of group ``[g0, g1)`` (sorted by row) whose row
    lies in ``[y0, y1]``."""
    lo, hi = g0, g1
    while lo < hi:
        m = (lo + hi) // 2
        if pix[m, 0] < y0:
            lo = m + 1
        else:
            hi = m
    top, hi = lo, g1
    while top < hi:
        m = (top + hi) // 2
        if pix[m, 0] <= y1:
            top = m + 1
        else:
            hi = m
    return lo, top


@numba.njit(cache=True, nogil=True)
def _candidates(rects, active, i, j, ki, kj, pix, lo, hi, box, aff, spans, reach):  # pragma: no cover
    """Which pixels ``[lo, hi)`` of a pair's group may be opening pixels: in the window ``box``,
    within ``reach`` of both units, covered by no third unit and nearer to each of the pair's
    units than to any other unit of its tile (ties keep the pixel: a unit nearer to it than the
    pair's unit of its tile makes it that unit's side of the boundary, not the pair's)."""
    cand = np.zeros(hi - lo, np.bool_)
    K, n_t = rects.shape[0], aff.shape[0]
    third = np.empty((K, 8))          # the other units that may take a pixel (rows of _unit_row):
    tiles = np.empty(K, np.int64)     # cover it, or (on the pair's tiles) lie nearer
    n = 0
    for t in range(K):
        if t != i and t != j and active[t]:
            k = tile_of(rects[t, 1], spans)
            # it covers only pixels in its box grown by half a cell, and lies nearer than the
            # pair's unit of its tile (within reach) only to pixels in its box grown by reach
            x0, y0, x1, y1 = _bbox(aff, k, rects[t], reach + 0.5 if k == ki or k == kj else 0.5)
            if x0 <= box[2] and box[0] <= x1 and y0 <= box[3] and box[1] <= y1:
                _unit_row(rects, t, third[n])
                tiles[n] = k
                n += 1
    r2 = reach * reach
    lat = np.empty((n_t, 2))          # the pixel on each tile's lattice
    for p in range(lo, hi):
        y, x = float(pix[p, 0]), float(pix[p, 1])
        if not _inside(box, x, y):
            continue
        for k in range(n_t):
            lat[k, 0], lat[k, 1] = _to_lattice(aff, k, x, y)
        di = _distance2_at(rects, i, lat[ki, 0], lat[ki, 1])
        dj = _distance2_at(rects, j, lat[kj, 0], lat[kj, 1])
        if di > r2 or dj > r2:
            continue
        free = True
        for m in range(n):
            k = tiles[m]
            r, c = lat[k, 0], lat[k, 1]
            # _covers_at, then _distance2_at, of the unit's row
            if third[m, 4] <= r < third[m, 5] and third[m, 6] <= c < third[m, 7]:
                free = False
                break
            if k == ki or k == kj:
                dr = max(third[m, 0] - r, 0.0, r - third[m, 1])
                dc = max(third[m, 2] - c, 0.0, c - third[m, 3])
                d = dr * dr + dc * dc
                if (k == ki and d < di) or (k == kj and d < dj):
                    free = False
                    break
        cand[p - lo] = free
    return cand


@numba.njit(cache=True, nogil=True)
def _pair_window(rects, i, j, ki, kj, pix, off, aff, reach):  # pragma: no cover - compiled
    """``(box, lo, hi)``: the image box where units ``i`` and ``j`` (tiles ``ki``, ``kj``) both
    reach (their boxes grown by ``reach``, intersected) and the index range of the pixels of
    their zones' group whose rows lie in it (:func:`_rows`)."""
    n_t = aff.shape[0]
    g = min(ki, kj) * n_t + max(ki, kj)
    x0, y0, x1, y1 = _bbox(aff, ki, rects[i], reach)
    u0, v0, u1, v1 = _bbox(aff, kj, rects[j], reach)
    box = np.array([max(x0, u0), max(y0, v0), min(x1, u1), min(y1, v1)])
    lo, hi = _rows(pix, off[g], off[g + 1], box[1], box[3])
    return box, lo, hi


@numba.njit(cache=True, nogil=True)
def pair_components(rects, active, i, j, pix, nbr, off, aff, spans, ip):  # pragma: no cover
    """``(adjacent by the grown rectangles, labels, widths, lo)``: the openings (module
    docstring) of units ``i`` and ``j`` of two tiles, as component labels 1..n of the pixels
    ``lo, lo + 1, ...`` of their zones' group (0: no opening pixel) and each one's widths along
    the axes of the tiles of ``i`` and of ``j`` (``widths[k - 1]``, ``n = len(widths)``;
    :func:`_run_width`); components shorter than ``door_min`` are left out, and so are those
    that would be doors without a jamb at each end (:func:`_jambs`)."""
    ki, kj = tile_of(rects[i, 1], spans), tile_of(rects[j, 1], spans)
    adjacent = grown_overlap(aff, ki, rects[i], kj, rects[j], float(ip[0]))
    reach = float(ip[1])
    box, lo, hi = _pair_window(rects, i, j, ki, kj, pix, off, aff, reach)
    labels = np.zeros(hi - lo, np.int64)
    widths = np.zeros((hi - lo, 2), np.int64)
    if hi == lo:
        return adjacent, labels, widths[:0], lo
    cand = _candidates(rects, active, i, j, ki, kj, pix, lo, hi, box, aff, spans, reach)
    n = 0
    stack = np.empty(hi - lo, np.int64)
    members = np.empty(hi - lo, np.int64)       # the current component's pixels
    for p in range(hi - lo):
        if not cand[p] or labels[p] != 0:
            continue
        n += 1
        labels[p], top, stack[0] = n, 1, p
        members[0], size = p, 1
        while top:
            top -= 1
            q = stack[top]
            for m in range(8):
                s = nbr[lo + q, m] - lo
                if 0 <= s < hi - lo and cand[s] and labels[s] == 0:
                    labels[s] = n
                    stack[top] = s
                    top += 1
                    members[size] = s
                    size += 1
        widths[n - 1, 0] = _run_width(aff, ki, pix, lo, members[:size])
        widths[n - 1, 1] = _run_width(aff, kj, pix, lo, members[:size])
        if min(widths[n - 1, 0], widths[n - 1, 1]) < ip[2] or not (
                _is_passage(widths[n - 1], rects[i], rects[j], ip) or _jambs(pix, lo, members[:size], ip[3])):
            labels[members[:size]] = -1         # not flooded again from its other pixels
            n -= 1
    for q in range(hi - lo):
        labels[q] = max(labels[q], 0)
    return adjacent, labels, widths[:n], lo


@numba.njit(cache=True, nogil=True)
def _jambs(pix, lo, members, reach):  # pragma: no cover - compiled
    """Whether the run of pixels ``pix[lo + p]`` (``p`` in ``members``) has a jamb at each end: a
    pixel of the run touching an occupied one (``pix[:, 2]``) within ``reach`` pixels
    (Chebyshev) of each of its two extreme pixels along the image axis it extends most along."""
    y0 = x0 = np.int64(1) << 62
    y1 = x1 = -(np.int64(1) << 62)
    for p in members:
        y, x = pix[lo + p, 0], pix[lo + p, 1]
        y0, y1, x0, x1 = min(y0, y), max(y1, y), min(x0, x), max(x1, x)
    along_x = x1 - x0 >= y1 - y0
    a = b = -1
    for p in members:
        v = pix[lo + p, 1] if along_x else pix[lo + p, 0]
        if a < 0 and v == (x0 if along_x else y0):
            a = p
        if b < 0 and v == (x1 if along_x else y1):
            b = p
    at_a = at_b = False
    for p in members:
        if pix[lo + p, 2] == 0:
            continue
        y, x = pix[lo + p, 0], pix[lo + p, 1]
        at_a |= max(abs(y - pix[lo + a, 0]), abs(x - pix[lo + a, 1])) <= reach
        at_b |= max(abs(y - pix[lo + b, 0]), abs(x - pix[lo + b, 1])) <= reach
    return at_a and at_b


@numba.njit(cache=True, nogil=True)
def _run_width(aff, k, pix, lo, members):  # pragma: no cover - compiled
    """The larger extent, along tile ``k``'s two axes, of the pixels ``pix[lo + p]`` for ``p`` in
    ``members``, in cells, rounded: an opening's width measured along the walls of
    that tile. A zones' boundary that crosses a doorway at an angle holds a run of pixels longer
    than the door; along the axes of the tile whose wall holds the door the run spans the door's
    width (and its drift across the wall, no more than that at 45 degrees)."""
    r0 = c0 = np.inf
    r1 = c1 = -np.inf
    for p in members:
        r, c = _to_lattice(aff, k, float(pix[lo + p, 1]), float(pix[lo + p, 0]))
        r0, r1, c0, c1 = min(r0, r), max(r1, r), min(c0, c), max(c1, c)
    return int(round(max(r1 - r0, c1 - c0))) + 1


@numba.njit(cache=True, nogil=True)
def _short(rect, wall):  # pragma: no cover - compiled
    return max(min(rect[2] - rect[0], rect[3] - rect[1]) - 2 * wall, 1)


@numba.njit(cache=True, nogil=True)
def cross_pair(rects, active, i, j, pix, nbr, off, aff, spans, ip):  # pragma: no cover
    """``(adjacent, doors, passages)`` of units ``i`` and ``j`` of two tiles."""
    adjacent, _labels, widths, _lo = pair_components(rects, active, i, j, pix, nbr, off, aff, spans, ip)
    if widths.shape[0] == 0:
        return adjacent, 0, 0
    doors = passages = 0
    for m in range(widths.shape[0]):
        if _is_passage(widths[m], rects[i], rects[j], ip):
            passages += 1
        else:
            doors += 1
    return True, doors, passages


@numba.njit(cache=True, nogil=True)
def _is_passage(w, ri, rj, ip):  # pragma: no cover - compiled
    """An opening of widths ``w`` (along the tiles of units ``ri`` and ``rj``) is a passage: wider
    than ``door_max`` along both tiles' walls (a door's width is the smaller one, measured along
    the wall that holds it), or spanning either unit's interior less a wall band on each side,
    measured on that unit's own tile (the open side of a corridor cut in two)."""
    return min(w[0], w[1]) > ip[1] or w[0] >= _short(ri, ip[3]) - 2 * ip[3] or \
        w[1] >= _short(rj, ip[3]) - 2 * ip[3]


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
    set; ``xo`` the old world's openings): the pairs of two tiles whose relation may have changed,
    recomputed in ``adj`` and ``xo`` (see :func:`cross_all`). A pair's openings depend on the
    world only through its units' shorter sides (the passage test) and its *candidate* pixels,
    those :func:`_candidates` keeps; its adjacency on its openings and the overlap of its two
    grown rectangles. So a pair is recomputed when a pixel's candidacy for it changed
    (:func:`_candidacy_changes`), and, when it holds a changed slot, when one of its units is new
    on its tile (born, or moved to another tile) or when a unit's shorter side changed and an
    opening of the pair may be as wide as the passage test's bound (:func:`_kept`); every other
    pair holding a changed slot keeps its openings and takes its adjacency from them and its
    overlap (with ``xo`` empty, adjacency alone, every such pair is recomputed). ``touched`` marks
    the slots of every pair without a changed slot whose relation changed. Equal to
    :func:`cross_all` of the new world (tests/unit/test_tiles.py)."""
    aff, spans = xd[0], xd[1]
    if aff.shape[0] < 2:
        return
    K = rects.shape[0]
    box = _boxes(rects, active, aff, spans, _reach(xd))
    is_changed = np.zeros(K, np.bool_)
    for s in changed:
        is_changed[s] = True
    redo = _candidacy_changes(old_rects, old_active, rects, active, changed, box, xd)
    keep = xo.shape[0] > 0
    for p in range(K):
        for q in range(p + 1, K):
            edited = is_changed[p] or is_changed[q]
            if not (edited or redo[p, q]):
                continue
            if not (active[p] and active[q]) or tile_of(rects[p, 1], spans) == tile_of(rects[q, 1], spans):
                if keep and edited:      # no relation of two tiles now (the lattice's is in adj)
                    xo[p, q, 0] = xo[q, p, 0] = xo[p, q, 1] = xo[q, p, 1] = 0
                continue
            if not edited:
                if _set_pair(rects, active, p, q, box, adj, xo, xd):
                    touched[p] = touched[q] = True
            elif keep and not redo[p, q] and _kept(old_rects, old_active, rects, p, q, xd):
                adj[p, q] = adj[q, p] = xo[p, q, 0] + xo[p, q, 1] > 0 or grown_overlap(
                    aff, tile_of(rects[p, 1], spans), rects[p], tile_of(rects[q, 1], spans), rects[q],
                    float(xd[5][0]))
            else:
                _set_pair(rects, active, p, q, box, adj, xo, xd)


@numba.njit(cache=True, nogil=True)
def _kept(old_rects, old_active, rects, p, q, xd):  # pragma: no cover - compiled
    """Whether the pair ``(p, q)`` of two tiles, holding a changed slot and no pixel whose
    candidacy for it changed, keeps its openings: both units were there on the same tiles, and
    where a unit's shorter side changed no opening of the pair can reach the passage test's width
    along its tile, before or after (:func:`_narrow`)."""
    spans, ip = xd[1], xd[5]
    kp, kq = tile_of(rects[p, 1], spans), tile_of(rects[q, 1], spans)
    if not (old_active[p] and old_active[q]) or tile_of(old_rects[p, 1], spans) != kp or \
            tile_of(old_rects[q, 1], spans) != kq:
        return False
    for u in (p, q):
        before, after = _short(old_rects[u], ip[3]), _short(rects[u], ip[3])
        if before != after and not _narrow(rects, p, q, u, min(before, after) - 2 * ip[3], xd):
            return False
    return True


@numba.njit(cache=True, nogil=True)
def _narrow(rects, p, q, u, width, xd):  # pragma: no cover - compiled
    """Whether every opening of units ``p`` and ``q`` (two tiles) is narrower than ``width`` along
    the tile of ``u`` (``p`` or ``q``) as :func:`_run_width` measures it: the pixels of their
    zones' group within reach of both, of which every opening is made, span less."""
    aff, spans, pix, nbr, off, ip = xd
    kp, kq = tile_of(rects[p, 1], spans), tile_of(rects[q, 1], spans)
    ku = kp if u == p else kq
    reach = float(ip[1])
    r2 = reach * reach
    box, lo, hi = _pair_window(rects, p, q, kp, kq, pix, off, aff, reach)
    r0 = c0 = np.inf
    r1 = c1 = -np.inf
    for i in range(lo, hi):
        y, x = float(pix[i, 0]), float(pix[i, 1])
        if not _inside(box, x, y) or _distance2(aff, kp, rects, p, x, y) > r2 or \
                _distance2(aff, kq, rects, q, x, y) > r2:
            continue
        r, c = _to_lattice(aff, ku, x, y)
        r0, r1, c0, c1 = min(r0, r), max(r1, r), min(c0, c), max(c1, c)
    return r0 > r1 or int(round(max(r1 - r0, c1 - c0))) + 1 < width


@numba.njit(cache=True, nogil=True)
def _candidacy_changes(old_rects, old_active, rects, active, changed, box,
                       xd):  # pragma: no cover - compiled
    """(K, K) bool, upper triangle: the pairs of units of two tiles to which some zone-boundary
    pixel is a candidate (:func:`_candidates`) in one of the old and new worlds and not in the
    other (``box``: the new world's boxes of :func:`_boxes` grown by :func:`_reach`). A pixel's
    candidacy depends on the other units only through which of them cover it and how near they
    lie to it, so only pixels where a changed slot's cover or distance within reach changed are
    looked at, and those lie within reach of the cells that changed: the strip of a unit's moved
    sides, or the whole rectangle of a unit added, removed or moved to another tile.

    At such a pixel of the boundary of tiles ``a`` and ``b`` a world's candidate pairs follow
    :func:`_candidates`' rule: ``u`` of tile ``a`` and ``v`` of tile ``b`` both within reach, no
    other unit covering the pixel, and no other unit of either one's tile nearer to it; so each is
    a nearest unit of its tile (ties kept), and no third unit covers it. The unchanged units near
    the pixel are read once, then each world's changed slots are added to them."""
    aff, spans, pix, nbr, off, ip = xd
    K, n_t = rects.shape[0], aff.shape[0]
    reach = float(ip[1])
    r2 = reach * reach
    far = r2 + 1.0                     # a distance beyond reach: no relation there
    is_changed = np.zeros(K, np.bool_)
    for s in changed:
        is_changed[s] = True
    redo = np.zeros((K, K), np.bool_)
    mark = np.zeros((K, K), np.int8)   # a pixel's pairs: 1 in the old world, 2 in the new
    seen = np.empty((K * K, 2), np.int64)
    # the units a pixel is read against (rows of _unit_rows): the unchanged ones near the window,
    # then the changed slots in the old and in the new world
    rows = np.empty((3, K, 8))
    ids = np.empty((3, K), np.int64)
    tiles = np.empty((3, K), np.int64)
    count = np.zeros(3, np.int64)
    for w in range(2):
        w_rects, w_active = (old_rects, old_active) if w == 0 else (rects, active)
        _table(w_rects, changed, w_active, np.ones(K, np.bool_), None, spans, rows, ids, tiles, count, w + 1)
    ends = np.empty((4, K), np.int64)  # nearest units of tiles a, b: the unchanged, then a world's
    lat = np.empty((n_t, 2))           # the pixel on each tile's lattice
    region = np.empty(4, np.int64)
    window = np.empty(4)
    for s in changed:
        ko, kn = tile_of(old_rects[s, 1], spans), tile_of(rects[s, 1], spans)
        moved = old_active[s] and active[s] and ko == kn
        for which in range(1 if moved else 2):
            if moved:      # one tile: what changed lies near the box of the sides that moved
                if not _moved_box(old_rects[s], rects[s], region):
                    continue
                k = kn
            else:
                r, on, k = (old_rects[s], old_active[s], ko) if which == 0 else (rects[s], active[s], kn)
                if not on:
                    continue
                region[:] = r
            # a pixel's cover by s, or its distance to s within reach, changed only within reach
            # of the region
            x0, y0, x1, y1 = _bbox(aff, k, region, reach + 0.5)
            window[0], window[1], window[2], window[3] = x0, y0, x1, y1
            count[0] = 0
            _table(rects, np.arange(K), active, ~is_changed, (box, window), spans, rows, ids, tiles, count, 0)
            for a in range(n_t):
                for b in range(a + 1, n_t):
                    lo, hi = _rows(pix, off[a * n_t + b], off[a * n_t + b + 1], y0, y1)
                    for p in range(lo, hi):
                        y, x = float(pix[p, 0]), float(pix[p, 1])
                        if x < x0 or x > x1:
                            continue
                        for t in range(n_t):
                            lat[t, 0], lat[t, 1] = _to_lattice(aff, t, x, y)
                        was = old_active[s] and _covers_at(old_rects, s, lat[ko, 0], lat[ko, 1])
                        now = active[s] and _covers_at(rects, s, lat[kn, 0], lat[kn, 1])
                        d_was = min(_distance2_at(old_rects, s, lat[ko, 0], lat[ko, 1]), far) if old_active[s] else far
                        d_now = min(_distance2_at(rects, s, lat[kn, 0], lat[kn, 1]), far) if active[s] else far
                        if was == now and d_was == d_now and (ko == kn or d_was == far):
                            continue
                        n_seen = _pixel_pairs(rows, ids, tiles, count, lat, a, b, r2, ends, mark, seen)
                        for m in range(n_seen):
                            u, v = seen[m, 0], seen[m, 1]
                            if mark[u, v] != 3:
                                redo[min(u, v), max(u, v)] = True
                            mark[u, v] = 0
    return redo


@numba.njit(cache=True, nogil=True)
def _pixel_pairs(rows, ids, tiles, count, lat, a, b, r2, ends, mark, seen):  # pragma: no cover
    """Set 1 in ``mark[u, v]`` for every pair (``u`` of tile ``a``, ``v`` of tile ``b``) to which
    a pixel of their zones' boundary (``lat``: its place on each tile's lattice) is a candidate
    in the old world, and 2 in the new, appending to ``seen`` the pairs marked; returns how many.
    The units it is read against are rows of :func:`_unit_row` (``ids``, ``tiles``, ``count``):
    row 0 the unchanged units near it, rows 1 and 2 the changed slots in the old and in the new
    world. :func:`_candidates`' rule: ``u`` and ``v`` both within reach (``r2``, squared), no other
    unit covering the pixel, and no other unit of either one's tile nearer to it; so each is a
    nearest unit of its tile (ties kept: ``ends``, rows 0 and 1 for the unchanged units, 2 and 3
    for a world's), and no third unit covers it."""
    n_seen = 0
    base_a = base_b = np.inf
    base_na = base_nb = base_covers = 0
    base0 = base1 = -1
    for w in range(3):       # the unchanged units, then each world's changed
        if w == 0:
            near_a = near_b = np.inf
            na = nb = covers = 0
            cover0 = cover1 = -1
        else:
            near_a, near_b, na, nb = base_a, base_b, base_na, base_nb
            covers, cover0, cover1 = base_covers, base0, base1
            for i in range(na):
                ends[2, i] = ends[0, i]
            for i in range(nb):
                ends[3, i] = ends[1, i]
        e = 0 if w == 0 else 2
        for m in range(count[w]):
            k = tiles[w, m]
            r, c = lat[k, 0], lat[k, 1]
            # _distance2_at and _covers_at of the unit's row
            dr = max(rows[w, m, 0] - r, 0.0, r - rows[w, m, 1])
            dc = max(rows[w, m, 2] - c, 0.0, c - rows[w, m, 3])
            d = dr * dr + dc * dc
            if d > r2:       # neither within reach nor covering the pixel
                continue
            u = ids[w, m]
            if rows[w, m, 4] <= r < rows[w, m, 5] and rows[w, m, 6] <= c < rows[w, m, 7]:
                if covers == 0:
                    cover0 = u
                elif covers == 1:
                    cover1 = u
                covers += 1
            if k == a:
                if d < near_a:
                    near_a, na = d, 0
                if d == near_a:
                    ends[e, na] = u
                    na += 1
            elif k == b:
                if d < near_b:
                    near_b, nb = d, 0
                if d == near_b:
                    ends[e + 1, nb] = u
                    nb += 1
        if covers > 2:       # no candidate (the unchanged: in either world)
            if w == 0:
                break
            continue
        if w == 0:
            base_a, base_b, base_na, base_nb = near_a, near_b, na, nb
            base_covers, base0, base1 = covers, cover0, cover1
            continue
        for i in range(na):
            u = ends[2, i]
            for j in range(nb):
                v = ends[3, j]
                if (covers > 0 and cover0 != u and cover0 != v) or \
                        (covers > 1 and cover1 != u and cover1 != v):
                    continue     # a third unit covers the pixel
                if mark[u, v] == 0:
                    seen[n_seen, 0], seen[n_seen, 1] = u, v
                    n_seen += 1
                mark[u, v] |= w
    return n_seen


@numba.njit(cache=True, nogil=True)
def _table(rects, units, active, eligible, near, spans, rows, ids, tiles, count,
           w):  # pragma: no cover - compiled
    """Append to row ``w`` of ``rows``, ``ids``, ``tiles`` (``count[w]`` long) the units of
    ``units`` that are active and ``eligible`` (and, with ``near = (boxes, window)``, whose box
    meets ``window``): each one's :func:`_unit_row`, slot and tile."""
    for u in units:
        if active[u] and eligible[u] and (near is None or _meets(near[0][u], near[1])):
            m = count[w]
            _unit_row(rects, u, rows[w, m])
            ids[w, m], tiles[w, m] = u, tile_of(rects[u, 1], spans)
            count[w] += 1


@numba.njit(cache=True, nogil=True)
def _unit_row(rects, u, out):  # pragma: no cover - compiled
    """Into ``out`` (8 floats): unit ``u``'s (a row of ``rects``) box of cell centres (first and
    last row, first and last column) and its cells' box (rows from, to; columns from, to), as
    :func:`_distance2_at` and :func:`_covers_at` read them."""
    out[0], out[1] = float(rects[u, 0]), float(rects[u, 2] - 1)
    out[2], out[3] = float(rects[u, 1]), float(rects[u, 3] - 1)
    out[4], out[5] = rects[u, 0] - 0.5, rects[u, 2] - 0.5
    out[6], out[7] = rects[u, 1] - 0.5, rects[u, 3] - 0.5


@numba.njit(cache=True, nogil=True)
def _moved_box(a, b, out):  # pragma: no cover - compiled
    """Into ``out``: a box holding every cell in one of rectangles ``a``, ``b`` but not the other
    (the box of both, narrowed to the moved sides' strip when only one side moved along an axis);
    False when they are equal."""
    if a[0] == b[0] and a[1] == b[1] and a[2] == b[2] and a[3] == b[3]:
        return False
    out[0], out[1] = min(a[0], b[0]), min(a[1], b[1])
    out[2], out[3] = max(a[2], b[2]), max(a[3], b[3])
    for lo in range(2):            # axis: rows (0) or columns (1)
        o = 1 - lo                 # the other axis keeps its sides: the strip along this one
        if a[o] == b[o] and a[o + 2] == b[o + 2]:
            if a[lo + 2] == b[lo + 2]:
                out[lo], out[lo + 2] = min(a[lo], b[lo]), max(a[lo], b[lo])
            elif a[lo] == b[lo]:
                out[lo], out[lo + 2] = min(a[lo + 2], b[lo + 2]), max(a[lo + 2], b[lo + 2])
    return True


@numba.njit(cache=True, nogil=True)
def _inside(b, x, y):  # pragma: no cover - compiled
    return b[0] <= x <= b[2] and b[1] <= y <= b[3]


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
    reach = _boxes(rects, active, aff, spans, _reach(xd)) if len(rects) else np.zeros((0, 4))
    pairs, doors, passages = [], [], []
    for i in range(len(rects)):
        for j in range(i + 1, len(rects)):
            if tiles[i] == tiles[j] or not _meets(reach[i], reach[j]):
                continue     # boxes apart by more than a pair's reach: no relation (as cross_all)
            adjacent, labels, widths, lo = pair_components(rects, active, i, j, pix, nbr, off, aff, spans, ip)
            if not (adjacent or len(widths)):
                continue
            pairs.append((i, j))
            for m in range(1, len(widths) + 1):
                ys, xs = pix[lo + np.flatnonzero(labels == m), :2].T
                is_passage = bool(_is_passage(widths[m - 1], rects[i], rects[j], ip))
                door = Door(int(slots[i]), int(slots[j]), _box_on_tile(frame, tiles[i], ys, xs), False,
                            int(widths[m - 1].min()))
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
