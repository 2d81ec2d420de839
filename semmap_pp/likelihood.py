"""The semantic sensor model and the overlap penalty, full and incremental (paper Sec. III-C.2).

``log p(M|W) = Σ_cells [log p(c | state(c), table(c)) + γ(c) log ψ]`` on the building lattice.

Cell bookkeeping (documented in docs/model.md). For a lattice cell let ``n_wall`` be the number of
units that have it in their wall band, ``n_int`` the number that have it in their interior and
``n_corr`` the number of corridor units that cover it at all. Then

* state: WALL if ``n_wall > 0``; otherwise, if ``n_int > 0``, the interior state of its input
  code (FREE for free and wall-like occupied input, OBJECT for unknown and object-like occupied
  input); otherwise UNKNOWN;
* table: the corridor table when every covering unit is a corridor, else the other table;
* overlap: ``k = n_int + [n_wall > 0]`` (wall bands may overlap each other without penalty: two
  rooms share one real wall), ``γ = max(k - 1, 0)``.

Every term depends on the cell only through a *category* (input code x region x corridor flag, 24
of them) and the integer ``γ``, so the log-likelihood is an exact function of integer counts:
``baseline + Σ_cat N_cat · gain_cat + log ψ · Σ γ``, where ``baseline`` is the log-likelihood of
the empty world and ``gain`` the change a category makes relative to an uncovered cell. The
incremental tracker keeps the per-cell count, category and γ rasters and updates the integer
tallies only in the changed windows, so full and incremental evaluations agree exactly (up to the
one final dot product), however many edits are made.

Examples
--------
>>> import numpy as np
>>> from semmap_pp.model import load_model
>>> from semmap_pp.frame import build_frame_from_classes
>>> classes = np.full((50, 50), 1, np.uint8); classes[5:45, 5:45] = 0       # a free room ...
>>> classes[5:45, [5, 6, 43, 44]] = 2; classes[[5, 6, 43, 44], 5:45] = 2     # ... with 2-cell walls
>>> model = load_model()
>>> data = prepare(build_frame_from_classes(classes, 0.05, model), model)
>>> def ll(rect): return full_loglik(data, np.array([rect]), np.array([False]))
>>> bool(ll((5, 5, 45, 45)) > max(ll((5, 5, 46, 45)), ll((5, 5, 44, 45)), ll((4, 4, 46, 46))))
True
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np
from scipy import ndimage

from semmap_pp.cells import FREE, OCCUPIED, UNKNOWN, W_FREE, W_OBJECT, W_UNKNOWN, W_WALL

# Extended input codes: the input class, with occupied split into object-like and wall-like.
X_FREE, X_UNKNOWN, X_OBJECTLIKE, X_WALLLIKE = 0, 1, 2, 3
N_X = 4
# Regions of a cell relative to the world.
R_OUT, R_WALL, R_INTERIOR = 0, 1, 2
N_CATEGORIES = N_X * 3 * 2  # x + 4 * (region + 3 * corridor)

_X_INPUT = np.array([FREE, UNKNOWN, OCCUPIED, OCCUPIED])          # input class of each code
_X_INTERIOR_STATE = np.array([W_FREE, W_OBJECT, W_OBJECT, W_FREE])  # interior state of each code


def category(x: int, region: int, corridor: bool) -> int:
    """Category index of an extended input code in a region, under the corridor table or not."""
    return int(x) + N_X * (int(region) + 3 * int(bool(corridor)))


def wall_like(occupied: np.ndarray, object_max_extent: int) -> np.ndarray:
    """Occupied cells on a straight lattice-axis run longer than ``object_max_extent`` cells.

    Morphological opening with a line of ``object_max_extent + 1`` cells along rows and along
    columns: such a cell belongs to something too long to be an object (DESIGN.md), so inside a
    unit it is a mismatch (an interior wall), not an object.
    """
    n = int(object_max_extent) + 1
    occ = np.asarray(occupied, dtype=bool)
    h = ndimage.binary_opening(occ, structure=np.ones((1, n), bool))
    v = ndimage.binary_opening(occ, structure=np.ones((n, 1), bool))
    return h | v


@dataclass(frozen=True, eq=False)
class LikelihoodData:
    """Per-map products of the sensor model, built once by :func:`prepare`.

    Attributes
    ----------
    xcode : (H', W') uint8
        Extended input code of every lattice cell (``X_*``).
    gain : (24,) float64
        ``log p(input | state, table) - log p(input | UNKNOWN)`` of each category (0 outside).
    baseline : float
        Log-likelihood of the empty world (every cell UNKNOWN).
    log_psi : float
        Log of the overlap penalty factor.
    wall : int
        Wall band thickness in cells.
    n_free : int
        Number of input-free lattice cells (for coverage).
    """

    xcode: np.ndarray
    gain: np.ndarray
    baseline: float
    log_psi: float
    wall: int
    n_free: int
    xhist: np.ndarray   # (24,) category histogram of the empty world (every cell R_OUT)

    @property
    def shape(self) -> tuple[int, int]:
        return self.xcode.shape


def gain_table(sensor) -> np.ndarray:
    """The 24 per-category gains from the model's two sensor tables (see module docstring)."""
    gain = np.zeros(N_CATEGORIES)
    log_unknown = np.log(sensor.other[W_UNKNOWN])  # (3,) over input classes
    for corr, table in ((False, sensor.other), (True, sensor.corridor)):
        logt = np.log(table)
        for x in range(N_X):
            inp = _X_INPUT[x]
            gain[category(x, R_WALL, corr)] = logt[W_WALL, inp] - log_unknown[inp]
            gain[category(x, R_INTERIOR, corr)] = logt[_X_INTERIOR_STATE[x], inp] - log_unknown[inp]
    gain.setflags(write=False)
    return gain


def prepare(frame, model) -> LikelihoodData:
    """Build the per-map sensor-model products for a :class:`~semmap_pp.frame.Frame`."""
    cls = frame.classes
    xcode = np.full(cls.shape, X_FREE, dtype=np.uint8)
    xcode[cls == UNKNOWN] = X_UNKNOWN
    occ = cls == OCCUPIED
    wl = wall_like(occ, frame.cells.object_max_extent)
    xcode[occ & ~wl] = X_OBJECTLIKE
    xcode[occ & wl] = X_WALLLIKE
    xcode.setflags(write=False)
    counts = np.bincount(cls.ravel(), minlength=3)
    baseline = float(np.dot(counts[:3], np.log(model.sensor.other[W_UNKNOWN])))
    xhist = np.bincount(xcode.ravel(), minlength=N_CATEGORIES).astype(np.int64)
    xhist.setflags(write=False)
    return LikelihoodData(xcode=xcode, gain=gain_table(model.sensor), baseline=baseline,
                          log_psi=float(np.log(model.sensor.psi)), wall=frame.cells.wall,
                          n_free=int(counts[FREE]), xhist=xhist)


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
    """``baseline + hist · gain + log ψ · Σγ`` (the one place the float is formed)."""
    return float(data.baseline + np.dot(hist.astype(np.float64), data.gain)
                 + data.log_psi * float(gamma_total))


def _bbox(rects: np.ndarray, shape) -> tuple[int, int, int, int] | None:
    if len(rects) == 0:
        return None
    r = np.asarray(rects).reshape(-1, 4)
    r0, c0 = max(int(r[:, 0].min()), 0), max(int(r[:, 1].min()), 0)
    r1, c1 = min(int(r[:, 2].max()), shape[0]), min(int(r[:, 3].max()), shape[1])
    if r0 >= r1 or c0 >= c1:
        return None
    return r0, c0, r1, c1


def full_tallies(data: LikelihoodData, rects: np.ndarray, corridor: np.ndarray):
    """Category histogram (24,) int64 and Σγ of a world, computed from scratch.

    Only the bounding box of the units is categorised; every cell outside it is R_OUT.
    """
    rects = np.asarray(rects).reshape(-1, 4)
    hist = data.xhist.copy()
    box = _bbox(rects, data.shape)
    if box is None:
        return hist, 0
    r0, c0, r1, c1 = box
    counts = np.zeros((3, r1 - r0, c1 - c0), dtype=np.int16)
    for rect, corr in zip(rects, np.asarray(corridor).reshape(-1)):
        _add_unit(counts, rect, bool(corr), data.wall, +1, r0, c0)
    x = data.xcode[r0:r1, c0:c1]
    cat, gamma = categorise(counts, x)
    hist -= np.bincount(x.ravel(), minlength=N_CATEGORIES)
    hist += np.bincount(cat.ravel(), minlength=N_CATEGORIES)
    return hist, int(gamma.sum(dtype=np.int64))


def full_loglik(data: LikelihoodData, rects, corridor) -> float:
    """``log p(M|W)`` of the units ``rects`` (n, 4) with corridor flags ``corridor`` (n,)."""
    hist, g = full_tallies(data, rects, corridor)
    return loglik_from_tallies(data, hist, g)


# --------------------------------------------------------------------------- incremental


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
    if a is not None:
        a = tuple(int(v) for v in a)
    if b is not None:
        b = tuple(int(v) for v in b)
    if a is not None and b is not None and change.old_corr == change.new_corr:
        diff = [i for i in range(4) if a[i] != b[i]]
        if not diff:
            return None
        if len(diff) == 1:
            i = diff[0]
            lo, hi = min(a[i], b[i]), max(a[i], b[i])
            if i in (0, 1):          # r0 or c0 moved: the band starts at the new/old edge
                lo2, hi2 = lo, hi + wall
            else:                    # r1 or c1 moved
                lo2, hi2 = lo - wall, hi
            box = [min(a[0], b[0]), min(a[1], b[1]), max(a[2], b[2]), max(a[3], b[3])]
            if i in (0, 2):
                box[0], box[2] = max(lo2, box[0]), min(hi2, box[2])
            else:
                box[1], box[3] = max(lo2, box[1]), min(hi2, box[3])
            return tuple(box)
    rects = [r for r in (a, b) if r is not None]
    if not rects:
        return None
    return (min(r[0] for r in rects), min(r[1] for r in rects),
            max(r[2] for r in rects), max(r[3] for r in rects))


def _clip(box, shape):
    r0, c0, r1, c1 = box
    r0, c0, r1, c1 = max(r0, 0), max(c0, 0), min(r1, shape[0]), min(c1, shape[1])
    return (r0, c0, r1, c1) if r0 < r1 and c0 < c1 else None


def _disjoint_boxes(boxes: list) -> list:
    """Merge intersecting boxes into their bounding boxes until all are disjoint."""
    boxes = list(boxes)
    merged = True
    while merged and len(boxes) > 1:
        merged = False
        for i in range(len(boxes)):
            for j in range(i + 1, len(boxes)):
                p, q = boxes[i], boxes[j]
                if p[0] < q[2] and q[0] < p[2] and p[1] < q[3] and q[1] < p[3]:
                    boxes[i] = (min(p[0], q[0]), min(p[1], q[1]), max(p[2], q[2]), max(p[3], q[3]))
                    del boxes[j]
                    merged = True
                    break
            if merged:
                break
    return boxes


@numba.njit(cache=True, nogil=True)
def _apply(cw, rect, corr, wall, sign, r_off, c_off):  # pragma: no cover - compiled
    """:func:`_add_unit` for the compiled window update (same clipping, same channels)."""
    h, w = cw.shape[1], cw.shape[2]
    a0, b0 = max(rect[0] - r_off, 0), max(rect[1] - c_off, 0)
    a1, b1 = min(rect[2] - r_off, h), min(rect[3] - c_off, w)
    if a0 >= a1 or b0 >= b1:
        return
    for i in range(a0, a1):
        for j in range(b0, b1):
            cw[0, i, j] += sign
            if corr:
                cw[2, i, j] += sign
    i0, j0 = max(rect[0] + wall - r_off, 0), max(rect[1] + wall - c_off, 0)
    i1, j1 = min(rect[2] - wall - r_off, h), min(rect[3] - wall - c_off, w)
    for i in range(i0, i1):
        for j in range(j0, j1):
            cw[0, i, j] -= sign
            cw[1, i, j] += sign


@numba.njit(cache=True, nogil=True)
def _window_update(counts, cat, gamma, xcode, r0, c0, r1, c1, old_units, new_units, wall,
                   hist):  # pragma: no cover - compiled
    """Recompute one window after removing ``old_units`` and adding ``new_units``
    (rows ``r0, c0, r1, c1, corridor``).

    Returns the new count, category and γ windows and the change of Σγ; adds the change of the
    category histogram into ``hist``. Same rules as :func:`categorise`.
    """
    h, w = r1 - r0, c1 - c0
    cw = counts[:, r0:r1, c0:c1].copy()
    for k in range(old_units.shape[0]):
        _apply(cw, old_units[k], old_units[k, 4] != 0, wall, -1, r0, c0)
    for k in range(new_units.shape[0]):
        _apply(cw, new_units[k], new_units[k, 4] != 0, wall, 1, r0, c0)
    ncat = np.empty((h, w), np.uint8)
    ngam = np.empty((h, w), np.int16)
    dgamma = 0
    for i in range(h):
        for j in range(w):
            nw, ni, nc = cw[0, i, j], cw[1, i, j], cw[2, i, j]
            if nw > 0:
                region = R_WALL
            elif ni > 0:
                region = R_INTERIOR
            else:
                region = R_OUT
            corr = 1 if (region != R_OUT and nc == nw + ni) else 0
            c = xcode[r0 + i, c0 + j] + N_X * (region + 3 * corr)
            g = ni + (1 if nw > 0 else 0) - 1
            if g < 0:
                g = 0
            ncat[i, j] = c
            ngam[i, j] = g
            hist[c] += 1
            hist[cat[r0 + i, c0 + j]] -= 1
            dgamma += g - gamma[r0 + i, c0 + j]
    return cw, ncat, ngam, dgamma


@dataclass(frozen=True, eq=False)
class LikPatch:
    """A proposed likelihood update: new windows and the tallies they give."""

    windows: tuple
    hist: np.ndarray
    gamma_total: int
    loglik: float


class CoverTracker:
    """Incremental ``log p(M|W)`` for one chain: cover-count, category and γ rasters.

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
        self.counts = cover_counts(data.shape, rects, corridor, data.wall)
        self.cat, self.gamma = categorise(self.counts, data.xcode)
        self.hist = np.bincount(self.cat.ravel(), minlength=N_CATEGORIES).astype(np.int64)
        self.gamma_total = int(self.gamma.sum(dtype=np.int64))
        self.loglik = loglik_from_tallies(data, self.hist, self.gamma_total)

    def propose(self, changes) -> LikPatch:
        """The likelihood after ``changes`` (a sequence of :class:`Change`), without committing."""
        data, shape = self.data, self.data.shape
        boxes = [b for b in (changed_box(ch, data.wall) for ch in changes) if b is not None]
        boxes = [b for b in (_clip(b, shape) for b in boxes) if b is not None]
        hist = self.hist.copy()
        gamma_total = self.gamma_total
        windows = []
        old = [tuple(ch.old_rect) + (ch.old_corr,) for ch in changes if ch.old_rect is not None]
        new = [tuple(ch.new_rect) + (ch.new_corr,) for ch in changes if ch.new_rect is not None]
        old_units = np.array(old, dtype=np.int64).reshape(-1, 5)
        new_units = np.array(new, dtype=np.int64).reshape(-1, 5)
        for box in _disjoint_boxes(boxes):
            r0, c0, r1, c1 = box
            counts, cat, gamma, dg = _window_update(
                self.counts, self.cat, self.gamma, data.xcode, r0, c0, r1, c1,
                old_units, new_units, data.wall, hist)
            gamma_total += int(dg)
            windows.append((box, counts, cat, gamma))
        return LikPatch(tuple(windows), hist, gamma_total,
                        loglik_from_tallies(data, hist, gamma_total))

    def commit(self, patch: LikPatch) -> None:
        """Make a proposed update the current state."""
        for (r0, c0, r1, c1), counts, cat, gamma in patch.windows:
            self.counts[:, r0:r1, c0:c1] = counts
            self.cat[r0:r1, c0:c1] = cat
            self.gamma[r0:r1, c0:c1] = gamma
        self.hist = patch.hist
        self.gamma_total = patch.gamma_total
        self.loglik = patch.loglik

    def covered_free(self, hist: np.ndarray | None = None) -> int:
        """Number of input-free cells covered by some unit (for the knowledge switch)."""
        hist = self.hist if hist is None else hist
        return covered_free(hist)


def covered_free(hist: np.ndarray) -> int:
    """Input-free cells in a wall band or interior, from a category histogram."""
    return int(sum(hist[category(X_FREE, reg, corr)]
                   for reg in (R_WALL, R_INTERIOR) for corr in (False, True)))
