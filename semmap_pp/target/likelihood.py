"""The semantic sensor model and the overlap penalty, full and incremental (paper Sec. III-C.2).

``log p(M|W) = Σ_cells [log p(c | state(c), table(c)) + γ(c) log ψ]`` on the building lattice.

Cell bookkeeping (documented in docs/model.md). For a lattice cell let ``n_wall`` be the number of
units that have it in their wall band, ``n_int`` the number that have it in their interior and
``n_corr`` the number of corridor units that cover it at all. Then

* state: WALL if ``n_wall > 0``; otherwise, if ``n_int > 0``, the interior state of its input
  code (FREE for free and wall-like occupied input, OBJECT for unknown and object-like occupied
  input); otherwise UNKNOWN. A free cell beside a wall thinner than the band (a *shadow*,
  :func:`thin_wall_shadow`) is read by a wall band as the wall's occupied cell, by an interior as
  free;
* table: the corridor table when every covering unit is a corridor, else the other table;
* overlap: ``k = n_int + [n_wall > 0]`` (wall bands may overlap each other without penalty: two
  rooms share one real wall), ``γ = max(k - 1, 0)``.

Every term depends on the cell only through a *category* (input code x region x corridor flag, 30
of them) and the integer ``γ``, so the log-likelihood is an exact function of integer counts:
``baseline + Σ_cat N_cat · gain_cat + log ψ · Σ γ``, where ``baseline`` is the log-likelihood of
the empty world and ``gain`` the change a category makes relative to an uncovered cell. The full
evaluation rasterises the counts over the units' bounding box. The incremental update needs no
raster: the edges of the units near an edit cut the changed box into pieces of constant cover, and
the cells of each input code in a piece come from per-map prefix sums; only the integer tallies
change, so full and incremental evaluations agree exactly (up to the one final dot product),
however many edits are made.

Examples
--------
>>> import numpy as np
>>> from semmap_pp.model import load_model
>>> from semmap_pp.lattice.frame import build_frame_from_classes
>>> classes = np.full((50, 50), 1, np.uint8); classes[5:45, 5:45] = 0       # a free room ...
>>> classes[5:45, [5, 6, 43, 44]] = 2; classes[[5, 6, 43, 44], 5:45] = 2     # ... with 2-cell walls
>>> model = load_model()
>>> data = prepare(build_frame_from_classes(classes, 0.05, model), model)
>>> def ll(rect): return full_loglik(data, np.array([rect]), np.array([False]))
>>> bool(ll((5, 5, 45, 45)) > max(ll((5, 5, 46, 45)), ll((5, 5, 44, 45)), ll((4, 4, 46, 46))))
True
"""

from __future__ import annotations

import dataclasses
import math
import weakref
from dataclasses import dataclass

import numba
import numpy as np
from scipy import ndimage

from semmap_pp.cells import FREE, OCCUPIED, UNKNOWN, W_FREE, W_OBJECT, W_UNKNOWN, W_WALL

# Extended input codes: the input class, with occupied split into object-like and wall-like, and
# the free cells beside a wall thinner than the band apart (thin_wall_shadow).
X_FREE, X_UNKNOWN, X_OBJECTLIKE, X_WALLLIKE, X_SHADOW = 0, 1, 2, 3, 4
N_X = 5
# A side band with fewer seen (free or occupied) cells than this share of its cells has not been
# seen: the enclosure term counts it as a wall (enclosure_loglik).
SEEN_MIN = 0.05
# Regions of a cell relative to the world.
R_OUT, R_WALL, R_INTERIOR = 0, 1, 2
N_CATEGORIES = N_X * 3 * 2  # x + N_X * (region + 3 * corridor)

_X_INPUT = np.array([FREE, UNKNOWN, OCCUPIED, OCCUPIED, FREE])          # input class of each code
_X_INTERIOR_STATE = np.array([W_FREE, W_OBJECT, W_OBJECT, W_FREE, W_FREE])  # interior state of each code
# A wall band reads a free cell beside a wall line thinner than the band as the wall's occupied cell.
_X_WALL_INPUT = np.array([FREE, UNKNOWN, OCCUPIED, OCCUPIED, OCCUPIED])


def category(x: int, region: int, corridor: bool) -> int:
    """Category index of an extended input code in a region, under the corridor table or not."""
    return int(x) + N_X * (int(region) + 3 * int(bool(corridor)))


def wall_like(occupied: np.ndarray, object_max_extent: int, tolerance: int = 0,
              gap: int = 0) -> np.ndarray:
    """Occupied cells on a lattice-axis line longer than ``object_max_extent`` cells.

    A line along the rows is found in the occupied cells spread ``tolerance`` cells up and down
    (a wall drawn by a laser is ragged: its cells step a row up or down, and no single row of it
    is one straight run), with gaps of at most ``gap`` cells along the line closed; a morphological
    opening with a line of ``object_max_extent + 1`` cells keeps the runs that are long enough,
    and an occupied cell within ``tolerance`` rows of such a run is wall-like. The same along the
    columns. Such a cell belongs to something too long to be an object (docs/model.md), so inside a
    unit it is a mismatch (an interior wall), not an object. ``tolerance = gap = 0`` is the strict
    rule: one straight run of ``object_max_extent + 1`` cells.

    Examples
    --------
    A 7-cell wall that steps down one row half-way is two straight runs of 4 and 3 cells: an
    object under the strict rule, a wall with one row of tolerance.

    >>> occ = np.zeros((4, 9), bool); occ[1, 1:5] = True; occ[2, 5:8] = True
    >>> int(wall_like(occ, 5).sum()), int(wall_like(occ, 5, tolerance=1).sum())
    (0, 7)
    >>> occ = np.zeros((3, 9), bool); occ[1, 1:4] = True; occ[1, 5:8] = True  # a 1-cell gap
    >>> int(wall_like(occ, 5).sum()), int(wall_like(occ, 5, gap=1).sum())
    (0, 6)
    """
    occ = np.asarray(occupied, dtype=bool)
    out = np.zeros(occ.shape, dtype=bool)
    for along in (1, 0):  # lines along the rows (axis 1), then along the columns (axis 0)
        out |= wall_like_axis(occ, object_max_extent, tolerance, gap, along)
    return out


def wall_like_axis(occupied: np.ndarray, object_max_extent: int, tolerance: int, gap: int,
                   along: int) -> np.ndarray:
    """:func:`wall_like`'s cells on lines along one axis (1: along the rows, 0: the columns)."""
    n = int(object_max_extent) + 1
    tol, gap = int(tolerance), int(gap)
    if tol < 0 or gap < 0:
        raise ValueError(f"tolerance and gap must be >= 0, got {tolerance}, {gap}")
    occ = np.asarray(occupied, dtype=bool)
    across = 1 - along
    band = occ
    if tol:
        band = ndimage.maximum_filter1d(occ.view(np.uint8), 2 * tol + 1, axis=across,
                                        mode="constant").astype(bool)
    if gap:
        pad = gap + 1  # padded so that the map border does not close anything
        line = np.ones((1, gap + 1) if along == 1 else (gap + 1, 1), bool)
        band = ndimage.binary_closing(np.pad(band, pad), structure=line)[pad:-pad, pad:-pad]
    runs = ndimage.binary_opening(band, structure=np.ones((1, n) if along == 1 else (n, 1), bool))
    if tol:
        runs = ndimage.maximum_filter1d(runs.view(np.uint8), 2 * tol + 1, axis=across,
                                        mode="constant").astype(bool)
    return occ & runs


def thin_wall_shadow(occupied: np.ndarray, free: np.ndarray, lines, wall: int) -> np.ndarray:
    """Free cells beside a wall thinner than the wall band (docs/model.md, "A wall thinner than the
    band"): a cell of a wall-like line whose occupied run across the line is ``t < wall`` cells,
    with a free cell at each end of that run (a wall between two seen spaces, not the face of
    something the laser saw from one side), makes the free cells within ``wall - t`` cells of it
    across the line shadows. ``lines``: the wall-like cells on lines along the rows and along the
    columns (:func:`wall_like_axis` with ``along`` 1 and 0).

    >>> occ = np.zeros((5, 8), bool); occ[2, :] = True          # a wall one cell thick ...
    >>> free = ~occ; free[3:, 5:] = False                        # ... seen from one side at the right
    >>> lines = [wall_like_axis(occ, 4, 0, 0, along) for along in (1, 0)]
    >>> thin_wall_shadow(occ, free, lines, 2).astype(int)
    array([[0, 0, 0, 0, 0, 0, 0, 0],
           [1, 1, 1, 1, 1, 0, 0, 0],
           [0, 0, 0, 0, 0, 0, 0, 0],
           [1, 1, 1, 1, 1, 0, 0, 0],
           [0, 0, 0, 0, 0, 0, 0, 0]])
    """
    occ = np.asarray(occupied, dtype=bool)
    free = np.asarray(free, dtype=bool)
    out = np.zeros(occ.shape, dtype=bool)
    if wall < 2:
        return out
    for along, line in zip((1, 0), lines):
        across = 1 - along
        thin = np.zeros(occ.shape, dtype=bool)
        for t in range(1, wall):   # runs of exactly t occupied cells with free cells at both ends
            start = _shift(free, 1, across) & _shift(free, -t, across)
            for j in range(t):
                start &= _shift(occ, -j, across)
            for j in range(t):
                thin |= _shift(start, j, across)
        thin &= line
        out |= ndimage.maximum_filter1d(thin.view(np.uint8), 2 * (wall - 1) + 1, axis=across,
                                        mode="constant").astype(bool)
    return out & free


def _shift(a: np.ndarray, k: int, axis: int) -> np.ndarray:
    """``a`` moved by ``k`` cells along ``axis`` (``out[i] = a[i - k]``), False where nothing
    comes in."""
    out = np.zeros_like(a)
    if k == 0:
        out[...] = a
        return out
    src = [slice(None)] * a.ndim
    dst = [slice(None)] * a.ndim
    src[axis], dst[axis] = (slice(None, -k), slice(k, None)) if k > 0 else (slice(-k, None), slice(None, k))
    out[tuple(dst)] = a[tuple(src)]
    return out


@dataclass(frozen=True, eq=False)
class LikelihoodData:
    """Per-map products of the sensor model, built once by :func:`prepare`.

    Attributes
    ----------
    xcode : (H', W') uint8
        Extended input code of every lattice cell (``X_*``).
    gain : (30,) float64
        ``log p(input | state, table) - log p(input | UNKNOWN)`` of each category (0 outside).
    baseline : float
        Log-likelihood of the empty world (every cell UNKNOWN).
    log_psi : float
        Log of the overlap penalty factor.
    wall : int
        Wall band thickness in cells.
    n_free : int
        Number of input-free lattice cells (for coverage).
    xhist : (30,) int64
        Category histogram of the empty world (every cell R_OUT).
    xsum : (H'+1, W'+1, N_X) int32
        Prefix sums of the extended codes (:func:`prefix_sums`), for the incremental update.
    """

    xcode: np.ndarray
    gain: np.ndarray
    baseline: float
    log_psi: float
    wall: int
    n_free: int
    xhist: np.ndarray   # (30,) category histogram of the empty world (every cell R_OUT)
    xsum: np.ndarray    # (H'+1, W'+1, N_X) int32 prefix sums of the extended codes (prefix_sums)

    @property
    def shape(self) -> tuple[int, int]:
        return self.xcode.shape


def gain_table(sensor) -> np.ndarray:
    """The 30 per-category gains from the model's two sensor tables (see module docstring)."""
    gain = np.zeros(N_CATEGORIES)
    log_unknown = np.log(sensor.other[W_UNKNOWN])  # (3,) over input classes
    for corr, table in ((False, sensor.other), (True, sensor.corridor)):
        logt = np.log(table)
        for x in range(N_X):
            inp = _X_INPUT[x]
            winp = _X_WALL_INPUT[x]
            gain[category(x, R_WALL, corr)] = logt[W_WALL, winp] - log_unknown[winp]
            gain[category(x, R_INTERIOR, corr)] = logt[_X_INTERIOR_STATE[x], inp] - log_unknown[inp]
    gain.setflags(write=False)
    return gain


#: The products :func:`prepare` made, per frame (weakly: they go with the frame) and sensor model.
_PREPARED: "weakref.WeakKeyDictionary" = weakref.WeakKeyDictionary()


def prepare(frame, model) -> LikelihoodData:
    """The per-map sensor-model products for a :class:`~semmap_pp.lattice.frame.Frame`.

    Made once per frame and sensor model (the same objects): a run builds its target several times
    (start worlds, sampling, W*'s scoring, the sample around W*, the typed sampled worlds), and on a
    campus map each build was tens of seconds and several hundred MB of the same read-only arrays.
    """
    cached = _PREPARED.get(frame)
    if cached is not None and cached[0] is model.sensor:
        return cached[1]
    data = _prepare(frame, model)
    _PREPARED[frame] = (model.sensor, data)
    return data


def remember(frame, model, data: LikelihoodData) -> None:
    """Make ``data`` what :func:`prepare` returns for ``frame`` and ``model`` from now on: the same
    products held otherwise (mapped from files a run shares with its chains' processes)."""
    _PREPARED[frame] = (model.sensor, data)


def _prepare(frame, model) -> LikelihoodData:
    """:func:`prepare`, made anew."""
    cls = frame.classes
    xcode = np.full(cls.shape, X_FREE, dtype=np.uint8)
    xcode[cls == UNKNOWN] = X_UNKNOWN
    occ = cls == OCCUPIED
    c = frame.cells
    lines = [wall_like_axis(occ, c.object_max_extent, c.wall_line_tolerance, c.wall_line_gap, along)
             for along in (1, 0)]         # wall_like's two halves, read again by the shadows
    wl = lines[0] | lines[1]
    xcode[occ & ~wl] = X_OBJECTLIKE
    xcode[occ & wl] = X_WALLLIKE
    xcode[thin_wall_shadow(occ, cls == FREE, lines, c.wall)] = X_SHADOW
    xcode.setflags(write=False)
    counts = np.bincount(cls.ravel(), minlength=3)
    baseline = float(np.dot(counts[:3], np.log(model.sensor.other[W_UNKNOWN])))
    xhist = np.bincount(xcode.ravel(), minlength=N_CATEGORIES).astype(np.int64)
    xhist.setflags(write=False)
    return LikelihoodData(xcode=xcode, gain=gain_table(model.sensor), baseline=baseline,
                          log_psi=float(np.log(model.sensor.psi)), wall=frame.cells.wall,
                          n_free=int(counts[FREE]), xhist=xhist, xsum=prefix_sums(xcode))


def tempered_data(data: LikelihoodData, beta: float) -> LikelihoodData:
    """``data`` with the likelihood raised to the power ``beta``: every per-cell log term is a
    gain, the baseline or ``γ log ψ``, so scaling those three scales ``log p(M|W)`` exactly by
    ``beta`` (the lattice arrays are shared, not copied). ``beta = 1`` returns ``data`` itself."""
    beta = float(beta)
    if not (math.isfinite(beta) and beta > 0.0):
        raise ValueError(f"a likelihood exponent must be a positive number, got {beta}")
    if beta == 1.0:
        return data
    gain = data.gain * beta
    gain.setflags(write=False)
    return dataclasses.replace(data, gain=gain, baseline=data.baseline * beta,
                               log_psi=data.log_psi * beta)


def _add_unit(counts: np.ndarray, rect, corr: bool, wall: int, sign: int,
              r_off: int = 0, c_off: int = 0) -> None:
    """Add (sign=+1) or remove (-1) one unit's cover from a (3, h, w) count window.

    The window's top-left lattice cell is ``(r_off, c_off)``; the rectangle is clipped to it.
    Channels: 0 wall-band cover, 1 interior cover, 2 corridor cover.
    """
    _, h, w = counts.shape
    r0, c0, r1, c1 = (int(v) for v in rect)
    a0, b0, a1, b1 = max(r0 - r_off, 0), max(c0 - c_off, 0), min(r1 - r_off, h), min(c1 - c_off, w)
    if a0 >= a1 or b0 >= b1:
        return
    counts[0, a0:a1, b0:b1] += sign
    if corr:
        counts[2, a0:a1, b0:b1] += sign
    i0, j0 = max(r0 + wall - r_off, 0), max(c0 + wall - c_off, 0)
    i1, j1 = min(r1 - wall - r_off, h), min(c1 - wall - c_off, w)
    if i0 < i1 and j0 < j1:
        counts[0, i0:i1, j0:j1] -= sign
        counts[1, i0:i1, j0:j1] += sign


def categorise(counts: np.ndarray, xcode: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per-cell category (uint8) and overlap exponent γ (int16) of a count window."""
    nw, ni, nc = counts[0], counts[1], counts[2]
    has_wall = nw > 0
    region = np.where(has_wall, R_WALL, np.where(ni > 0, R_INTERIOR, R_OUT)).astype(np.uint8)
    corr = (nc == nw + ni) & (region != R_OUT)
    cat = xcode + N_X * (region + 3 * corr.astype(np.uint8))
    gamma = np.maximum(ni + has_wall - 1, 0).astype(np.int16)
    return cat.astype(np.uint8), gamma


def cover_counts(shape, rects: np.ndarray, corridor: np.ndarray, wall: int) -> np.ndarray:
    """(3, H', W') int16 cover counts of the given units (see :func:`_add_unit`)."""
    counts = np.zeros((3,) + tuple(shape), dtype=np.int16)
    for rect, corr in zip(np.asarray(rects).reshape(-1, 4), np.asarray(corridor).reshape(-1)):
        _add_unit(counts, rect, bool(corr), wall, +1)
    return counts


def loglik_from_tallies(data: LikelihoodData, hist: np.ndarray, gamma_total: int) -> float:
    """``baseline + hist · gain + log ψ · Σγ`` (the one place the float is formed:
    :func:`tallies_loglik`, which the compiled hot path calls too)."""
    return float(tallies_loglik(hist, data.gain, data.baseline, data.log_psi, int(gamma_total)))


@numba.njit(cache=True, nogil=True, inline="always")
def _box_count(xsum, ra, ca, rb, cb, x):  # pragma: no cover - compiled
    """Cells of extended code ``x`` in rows ``ra:rb``, columns ``ca:cb`` (from the prefix sums)."""
    return xsum[rb, cb, x] - xsum[ra, cb, x] - xsum[rb, ca, x] + xsum[ra, ca, x]


@numba.njit(cache=True, nogil=True)
def enclosure_loglik(xsum, rects, active, wall, min_share, cost):  # pragma: no cover - compiled
    """The enclosure term of a world (docs/model.md, "Enclosure"); 0 when ``min_share`` or
    ``cost`` is 0.

    Per side of an active unit, its wall band's *occupied share* is occupied / (occupied + free)
    input cells (a side whose band holds fewer seen cells than ``SEEN_MIN`` of its cells has not
    been seen and counts 1). A unit whose second largest share is below ``min_share`` (rays pass
    through three of its walls) adds ``-cost · area · (1 - share / min_share)``."""
    total = 0.0
    if min_share <= 0.0 or cost <= 0.0:
        return total
    share = np.empty(4)
    for s in range(rects.shape[0]):
        if not active[s]:
            continue
        r0, c0, r1, c1 = rects[s, 0], rects[s, 1], rects[s, 2], rects[s, 3]
        b = min(wall, r1 - r0, c1 - c0)
        for k in range(4):
            if k == 0:
                ra, ca, rb, cb = r0, c0, r0 + b, c1
            elif k == 1:
                ra, ca, rb, cb = r1 - b, c0, r1, c1
            elif k == 2:
                ra, ca, rb, cb = r0, c0, r1, c0 + b
            else:
                ra, ca, rb, cb = r0, c1 - b, r1, c1
            occ = (_box_count(xsum, ra, ca, rb, cb, X_OBJECTLIKE)
                   + _box_count(xsum, ra, ca, rb, cb, X_WALLLIKE))
            seen = (occ + _box_count(xsum, ra, ca, rb, cb, X_FREE)
                    + _box_count(xsum, ra, ca, rb, cb, X_SHADOW))
            share[k] = occ / seen if seen >= SEEN_MIN * (rb - ra) * (cb - ca) else 1.0
        share.sort()
        s2 = share[2]
        if s2 < min_share:
            total -= cost * (r1 - r0) * (c1 - c0) * (1.0 - s2 / min_share)
    return total


@numba.njit(cache=True, nogil=True)
def tallies_loglik(hist, gain, baseline, log_psi, gamma_total):  # pragma: no cover - compiled
    """:func:`loglik_from_tallies` on plain arguments (a fixed summation order)."""
    dot = 0.0
    for k in range(hist.shape[0]):
        dot += hist[k] * gain[k]
    return baseline + dot + log_psi * gamma_total


def _bbox(rects: np.ndarray, shape) -> tuple[int, int, int, int] | None:
    if len(rects) == 0:
        return None
    r = np.asarray(rects).reshape(-1, 4)
    r0, c0 = max(int(r[:, 0].min()), 0), max(int(r[:, 1].min()), 0)
    r1, c1 = min(int(r[:, 2].max()), shape[0]), min(int(r[:, 3].max()), shape[1])
    if r0 >= r1 or c0 >= c1:
        return None
    return r0, c0, r1, c1


#: Side of the tiles :func:`full_tallies` categorises one at a time, cells.
TALLY_TILE = 512


def full_tallies(data: LikelihoodData, rects: np.ndarray, corridor: np.ndarray):
    """Category histogram (30,) int64 and Σγ of a world, computed from scratch.

    The units' bounding box is categorised tile by tile (:data:`TALLY_TILE` cells a side), each
    tile with the units that reach into it; a tile no unit reaches is left out (its cells are
    R_OUT, as in the empty world). The tallies are integer counts, so they are those of the whole
    box at once; the work and memory follow the units' cover, not their bounding box (the units
    along a campus's corridor loop span the whole map).
    """
    rects = np.asarray(rects).reshape(-1, 4)
    corridor = np.asarray(corridor).reshape(-1)
    hist = data.xhist.copy()
    box = _bbox(rects, data.shape)
    if box is None:
        return hist, 0
    r0, c0, r1, c1 = box
    gamma_total = 0
    for a0 in range(r0, r1, TALLY_TILE):
        a1 = min(a0 + TALLY_TILE, r1)
        across = (rects[:, 0] < a1) & (rects[:, 2] > a0)
        for b0 in range(c0, c1, TALLY_TILE):
            b1 = min(b0 + TALLY_TILE, c1)
            here = np.flatnonzero(across & (rects[:, 1] < b1) & (rects[:, 3] > b0))
            if here.size == 0:
                continue
            counts = np.zeros((3, a1 - a0, b1 - b0), dtype=np.int16)
            for i in here:
                _add_unit(counts, rects[i], bool(corridor[i]), data.wall, +1, a0, b0)
            x = data.xcode[a0:a1, b0:b1]
            cat, gamma = categorise(counts, x)
            hist -= np.bincount(x.ravel(), minlength=N_CATEGORIES)
            hist += np.bincount(cat.ravel(), minlength=N_CATEGORIES)
            gamma_total += int(gamma.sum(dtype=np.int64))
    return hist, gamma_total


def full_loglik(data: LikelihoodData, rects, corridor) -> float:
    """``log p(M|W)`` of the units ``rects`` (n, 4) with corridor flags ``corridor`` (n,)."""
    hist, g = full_tallies(data, rects, corridor)
    return loglik_from_tallies(data, hist, g)


# --------------------------------------------------------------------------- incremental
#
# The incremental update works on rectangles, not rasters. Inside a box the rectangles' edges
# (outer edges and wall-band inner edges) cut the lattice into *pieces* on which every unit's
# cover is constant, so each piece has one category offset and one γ; the number of input cells
# of each extended code in a piece is read from per-map prefix sums (``LikelihoodData.xsum``).
# An edit of one unit changes the tallies only on the pieces where that unit's cover changes,
# so its cost grows with the number of units near the edit, not with the edited area.


@dataclass(frozen=True)
class Change:
    """One unit's edit: its rectangle and corridor flag before and after (``None`` = no unit)."""

    old_rect: tuple | None
    old_corr: bool
    new_rect: tuple | None
    new_corr: bool


def changed_box(change: Change, wall: int) -> tuple[int, int, int, int] | None:
    """The lattice box outside which the edit changes no cell's counts.

    A move of one side is a strip ``wall`` cells wider than the move (the old or new wall band
    becomes interior or the reverse, and the two side bands lengthen or shorten); anything else
    (birth, death, type change, several sides) is the union of the two rectangles.
    """
    a, b = change.old_rect, change.new_rect
    a = np.zeros(4, np.int64) if a is None else np.array([int(v) for v in a], np.int64)
    b = np.zeros(4, np.int64) if b is None else np.array([int(v) for v in b], np.int64)
    box = np.zeros(4, np.int64)
    ok = _changed_box(a, change.old_rect is not None, bool(change.old_corr),
                      b, change.new_rect is not None, bool(change.new_corr), int(wall), box)
    return tuple(int(v) for v in box) if ok else None


@numba.njit(cache=True, nogil=True)
def _changed_box(a, a_on, a_corr, b, b_on, b_corr, wall, box):  # pragma: no cover - compiled
    """:func:`changed_box` into ``box`` (4,); False when nothing changes."""
    if a_on and b_on:
        box[0], box[1] = min(a[0], b[0]), min(a[1], b[1])
        box[2], box[3] = max(a[2], b[2]), max(a[3], b[3])
        if a_corr == b_corr:
            nd, k = 0, -1
            for i in range(4):
                if a[i] != b[i]:
                    nd += 1
                    k = i
            if nd == 0:
                return False
            if nd == 1:
                lo, hi = min(a[k], b[k]), max(a[k], b[k])
                if k < 2:            # r0 or c0 moved: the band starts at the new/old edge
                    lo2, hi2 = lo, hi + wall
                else:                # r1 or c1 moved
                    lo2, hi2 = lo - wall, hi
                if k == 0 or k == 2:
                    box[0], box[2] = max(lo2, box[0]), min(hi2, box[2])
                else:
                    box[1], box[3] = max(lo2, box[1]), min(hi2, box[3])
        return True
    if a_on:
        box[:] = a[:4]
        return True
    if b_on:
        box[:] = b[:4]
        return True
    return False


def prefix_sums(xcode: np.ndarray) -> np.ndarray:
    """(H'+1, W'+1, N_X) int32: ``S[r, c, x]`` = cells of code ``x`` in rows < r and columns < c."""
    h, w = xcode.shape
    s = np.zeros((h + 1, w + 1, N_X), dtype=np.int32)
    for x in range(N_X):
        s[1:, 1:, x] = np.cumsum(np.cumsum(xcode == x, axis=0, dtype=np.int32), axis=1,
                                 dtype=np.int32)
    s.setflags(write=False)
    return s


@numba.njit(cache=True, nogil=True, inline="always")
def _state(r, wall, i, j):  # pragma: no cover - compiled
    """Cover of cell (i, j) by rectangle ``r``: 0 none, 1 wall band, 2 interior."""
    if i < r[0] or i >= r[2] or j < r[1] or j >= r[3]:
        return 0
    if r[0] + wall <= i < r[2] - wall and r[1] + wall <= j < r[3] - wall:
        return 2
    return 1


@numba.njit(cache=True, nogil=True, inline="always")
def _offset_gamma(nw, ni, nc):  # pragma: no cover - compiled
    """Category offset (``N_X * (region + 3 corridor)``) and γ of a cell's counts."""
    if nw > 0:
        region = R_WALL
    elif ni > 0:
        region = R_INTERIOR
    else:
        return 0, 0
    corr = 1 if nc == nw + ni else 0
    g = ni + (1 if nw > 0 else 0) - 1
    return N_X * (region + 3 * corr), (g if g > 0 else 0)


@numba.njit(cache=True, nogil=True)
def _breaks(lo, hi, rects, idx, n, a, a_on, b, b_on, wall, axis):  # pragma: no cover - compiled
    """Sorted distinct cut positions in ``[lo, hi]`` of the listed rectangles along ``axis``."""
    out = np.empty(2 + 4 * (n + 2), np.int64)
    out[0], out[1] = lo, hi
    m = 2
    for k in range(n + 2):
        if k < n:
            r = rects[idx[k]]
        elif k == n:
            if not a_on:
                continue
            r = a
        else:
            if not b_on:
                continue
            r = b
        for v in (r[axis], r[axis] + wall, r[axis + 2] - wall, r[axis + 2]):
            if lo < v < hi:
                out[m] = v
                m += 1
    out = np.sort(out[:m])
    u = 1
    for k in range(1, m):
        if out[k] != out[u - 1]:
            out[u] = out[k]
            u += 1
    return out[:u]


@numba.njit(cache=True, nogil=True)
def _change_delta(xsum, rects, corr, on, skip, a, a_on, a_corr, b, b_on, b_corr, wall,
                  hist):  # pragma: no cover - compiled
    """Tally change of one unit's edit ``a -> b`` among the units ``on`` (slot ``skip`` excluded).

    Adds the change of the category histogram into ``hist`` and returns the change of Σγ.
    """
    box = np.empty(4, np.int64)
    if not _changed_box(a, a_on, a_corr, b, b_on, b_corr, wall, box):
        return 0
    H, W = xsum.shape[0] - 1, xsum.shape[1] - 1
    R0, C0, R1, C1 = max(box[0], 0), max(box[1], 0), min(box[2], H), min(box[3], W)
    if R0 >= R1 or C0 >= C1:
        return 0
    idx = np.empty(rects.shape[0], np.int64)
    n = 0
    for t in range(rects.shape[0]):
        if on[t] and t != skip:
            r = rects[t]
            if r[0] < R1 and r[2] > R0 and r[1] < C1 and r[3] > C0:
                idx[n] = t
                n += 1
    rows = _breaks(R0, R1, rects, idx, n, a, a_on, b, b_on, wall, 0)
    cols = _breaks(C0, C1, rects, idx, n, a, a_on, b, b_on, wall, 1)
    dgamma = 0
    for i in range(rows.shape[0] - 1):
        ra, rb = rows[i], rows[i + 1]
        for j in range(cols.shape[0] - 1):
            ca, cb = cols[j], cols[j + 1]
            sa = _state(a, wall, ra, ca) if a_on else 0
            sb = _state(b, wall, ra, ca) if b_on else 0
            if sa == sb and (sa == 0 or a_corr == b_corr):
                continue
            nw = ni = nc = 0
            for k in range(n):
                t = idx[k]
                st = _state(rects[t], wall, ra, ca)
                if st == 1:
                    nw += 1
                elif st == 2:
                    ni += 1
                if st > 0 and corr[t]:
                    nc += 1
            off_a, g_a = _offset_gamma(nw + (sa == 1), ni + (sa == 2),
                                       nc + (sa > 0 and a_corr))
            off_b, g_b = _offset_gamma(nw + (sb == 1), ni + (sb == 2),
                                       nc + (sb > 0 and b_corr))
            if off_a == off_b and g_a == g_b:
                continue
            dgamma += (g_b - g_a) * (rb - ra) * (cb - ca)
            if off_a != off_b:
                for x in range(N_X):
                    cnt = _box_count(xsum, ra, ca, rb, cb, x)
                    hist[x + off_b] += cnt
                    hist[x + off_a] -= cnt
    return dgamma


@numba.njit(cache=True, nogil=True)
def world_delta(xsum, old_rects, old_on, old_corr, new_rects, new_on, new_corr, wall,
                hist):  # pragma: no cover - compiled
    """Tally change from one slot-indexed set of units to another (the sampler's hot path).

    Slots whose unit differs (rectangle, presence or corridor flag) are edited one after the
    other; adds the histogram change into ``hist`` (30,) and returns the change of Σγ.
    """
    K = old_rects.shape[0]
    cur = np.empty((K, 4), np.int64)
    on = np.empty(K, np.bool_)
    corr = np.empty(K, np.bool_)
    for s in range(K):
        on[s] = old_on[s]
        corr[s] = old_corr[s] and old_on[s]
        for k in range(4):
            cur[s, k] = old_rects[s, k]
    b = np.empty(4, np.int64)
    dgamma = 0
    for s in range(K):
        b_on = new_on[s]
        if not on[s] and not b_on:
            continue
        b_corr = new_corr[s] and b_on
        for k in range(4):
            b[k] = new_rects[s, k]
        if on[s] == b_on and corr[s] == b_corr and cur[s, 0] == b[0] and cur[s, 1] == b[1] \
                and cur[s, 2] == b[2] and cur[s, 3] == b[3]:
            continue
        dgamma += _change_delta(xsum, cur, corr, on, s, cur[s].copy(), on[s], corr[s],
                                b, b_on, b_corr, wall, hist)
        on[s], corr[s] = b_on, b_corr
        for k in range(4):
            cur[s, k] = b[k]
    return dgamma


@dataclass(frozen=True, eq=False)
class LikPatch:
    """A proposed likelihood update: the units and the tallies they give."""

    units: tuple
    hist: np.ndarray
    gamma_total: int
    loglik: float


class CoverTracker:
    """Incremental ``log p(M|W)`` for one chain: the units and the integer tallies.

    Parameters
    ----------
    data : LikelihoodData
    rects : (n, 4) int
        The active units.
    corridor : (n,) bool
        Their corridor flags.
    """

    def __init__(self, data: LikelihoodData, rects, corridor):
        self.data = data
        rects = np.asarray(rects).reshape(-1, 4)
        corridor = np.asarray(corridor, dtype=bool).reshape(-1)
        self.units = tuple((tuple(int(v) for v in r), bool(c)) for r, c in zip(rects, corridor))
        self.hist, self.gamma_total = full_tallies(data, rects, corridor)
        self.loglik = loglik_from_tallies(data, self.hist, self.gamma_total)

    def propose(self, changes) -> LikPatch:
        """The likelihood after ``changes`` (a sequence of :class:`Change`, applied in order;
        each ``old_rect`` must be a current unit), without committing."""
        units = list(self.units)
        hist = self.hist.copy()
        gamma_total = self.gamma_total
        for ch in changes:
            a = None if ch.old_rect is None else (tuple(int(v) for v in ch.old_rect),
                                                  bool(ch.old_corr))
            if a is not None:
                units.remove(a)
            n = len(units)
            rects = np.array([r for r, _ in units], np.int64).reshape(n, 4)
            corr = np.array([c for _, c in units], np.bool_).reshape(n)
            ar = np.array(a[0] if a is not None else (0, 0, 0, 0), np.int64)
            br = np.array(ch.new_rect if ch.new_rect is not None else (0, 0, 0, 0), np.int64)
            gamma_total += int(_change_delta(
                self.data.xsum, rects, corr, np.ones(n, np.bool_), -1, ar, a is not None,
                bool(ch.old_corr), br, ch.new_rect is not None, bool(ch.new_corr),
                self.data.wall, hist))
            if ch.new_rect is not None:
                units.append((tuple(int(v) for v in ch.new_rect), bool(ch.new_corr)))
        return LikPatch(tuple(units), hist, gamma_total,
                        loglik_from_tallies(self.data, hist, gamma_total))

    def commit(self, patch: LikPatch) -> None:
        """Make a proposed update the current state."""
        self.units = patch.units
        self.hist = patch.hist
        self.gamma_total = patch.gamma_total
        self.loglik = patch.loglik

    def covered_free(self, hist: np.ndarray | None = None) -> int:
        """Number of input-free cells covered by some unit (for the knowledge switch)."""
        hist = self.hist if hist is None else hist
        return covered_free(hist)


_FREE_COVERED = np.array([category(x, reg, corr) for x in (X_FREE, X_SHADOW)
                          for reg in (R_WALL, R_INTERIOR) for corr in (False, True)])


def covered_free(hist: np.ndarray) -> int:
    """Input-free cells in a wall band or interior, from a category histogram."""
    return int(hist[_FREE_COVERED].sum())
