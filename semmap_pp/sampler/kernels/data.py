"""Data-driven products of one map, built once and read by every kernel.

Kernels propose where the map shows structure: births from the free space (distance-transform maxima
and free-space regions, each grown to the box of free cells around it), split lines and wall moves
towards *line evidence* (runs of occupied cells along lattice rows and columns, doorways included),
allocations sized from the free space behind a wall. Everything here is a table or a prefix sum, so a
kernel pays a few array lookups per proposal.

The lattice conventions are those of :mod:`semmap_pp.cells` and :mod:`semmap_pp.world`: arrays are
``[row, col]``, a unit is a half-open rectangle ``(r0, c0, r1, c1)`` that includes its wall band of
``wall_cells`` cells.

Examples
--------
>>> import numpy as np
>>> from semmap_pp import cells
>>> classes = np.full((8, 10), cells.FREE, np.uint8)
>>> classes[0, :] = classes[-1, :] = classes[:, 0] = classes[:, -1] = cells.OCCUPIED
>>> data = build_data(classes, min_side=3, wall_cells=1)
>>> data.shape, data.birth_rects[0].tolist()
((8, 10), [0, 0, 8, 10])
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from scipy import ndimage

from semmap_pp import cells
from semmap_pp.model import KernelSettings

class KernelData(NamedTuple):
    """Read-only products of one lattice map (see :func:`build_data`)."""

    shape: tuple          # (H, W) of the lattice
    min_side: int         # m: shortest side of a unit, cells (wall bands included)
    max_side: int         # M: longest side of a unit
    wall_cells: int       # t: thickness of a unit's wall band
    wall_share: int       # g: cells two adjacent units' rectangles overlap across their shared wall
    settings: KernelSettings
    hcum: np.ndarray      # (H, W+1) prefix sums along columns of the horizontal line mask
    vcum: np.ndarray      # (W, H+1) prefix sums along rows of the vertical line mask
    free_up: np.ndarray   # (H, W) free run lengths from each cell (cell included, 0 if not free)
    free_down: np.ndarray
    free_left: np.ndarray
    free_right: np.ndarray
    birth_rects: np.ndarray    # (N, 4) int64 candidate rectangles
    birth_weights: np.ndarray  # (N,) float, sums to 1 (empty table: birth_uniform acts as 1)
    side_counts: tuple    # (N_rows, N_cols): valid (lo, hi) pairs along each axis
    side_cdfs: tuple      # per axis: (lengths, cdf) to draw a length with weight L - h + 1
    wall_lines: np.ndarray     # (L, 4): axis (0 = along a row), line index, start, end (half-open)
    door_candidates: np.ndarray  # (D, 4): same layout, free gaps in walls of door width
    dt_maxima: np.ndarray      # (P, 2): row, col of distance-transform maxima of free space


def runs(mask: np.ndarray):
    """Runs of True along each row: ``(row, start, end)`` arrays, ``end`` exclusive.

    >>> runs(np.array([[1, 1, 0, 1], [0, 0, 0, 0]], bool))
    (array([0, 0]), array([0, 3]), array([2, 4]))
    """
    h, w = mask.shape
    pad = np.zeros((h, w + 2), np.int8)
    pad[:, 1:-1] = mask
    d = np.diff(pad, axis=1)
    rows, starts = np.nonzero(d == 1)
    _, ends = np.nonzero(d == -1)
    return rows, starts, ends


#: Rows :func:`_run_back` works on at a time (its int64 temporaries are a band's, not the map's).
RUN_BAND_ROWS = 256


def _run_back(mask: np.ndarray) -> np.ndarray:
    """Length of the run of True ending at each cell going left (cell included; 0 if False).

    >>> _run_back(np.array([[1, 1, 0, 1], [0, 1, 1, 1]], bool)).tolist()
    [[1, 2, 0, 1], [0, 1, 2, 3]]
    """
    h, w = mask.shape
    out = np.empty((h, w), np.int32)
    idx = np.arange(w)
    for r0 in range(0, h, RUN_BAND_ROWS):
        last_false = np.maximum.accumulate(np.where(mask[r0:r0 + RUN_BAND_ROWS], -1, idx), axis=1)
        out[r0:r0 + RUN_BAND_ROWS] = idx - last_false
    return out


def free_runs(free: np.ndarray, store=None):
    """``(up, down, left, right)`` run lengths of free cells from every cell, cell included; each
    passed through ``store`` (see :func:`build_data`) as soon as it is made."""
    store = _keep if store is None else store
    up = store(np.ascontiguousarray(_run_back(free.T).T))
    down = store(np.ascontiguousarray(_run_back(free.T[:, ::-1])[:, ::-1].T))
    left = store(np.ascontiguousarray(_run_back(free)))
    right = store(np.ascontiguousarray(_run_back(free[:, ::-1])[:, ::-1]))
    return up, down, left, right


def _keep(array: np.ndarray) -> np.ndarray:
    return array


def _lines_and_doors(occ: np.ndarray, free: np.ndarray, line_min: int, door_min: int, door_max: int):
    """Wall lines and door gaps along rows of ``occ``; returns (lines, doors, door_mask).

    A door gap is a run of free cells of door width *in a wall line*: the occupied runs that end
    just before it and start just after it along the same row are each at least ``line_min`` cells
    long. Without that condition every row across a corridor narrower than ``door_max`` (a free run
    between its two walls) counted as a door, which put line evidence across every corridor and
    made SPLIT cut corridors into pieces at random rows.
    """
    r, s, e = runs(occ)
    keep = (e - s) >= line_min
    lines = np.stack([r[keep], s[keep], e[keep]], axis=1)
    fr, fs, fe = runs(free)
    w = occ.shape[1]
    width = fe - fs
    inner = (fs > 0) & (fe < w)
    ok = inner & (width >= door_min) & (width <= door_max)
    back = _run_back(occ)                              # occupied run ending at each cell
    ahead = _run_back(occ[:, ::-1])[:, ::-1]           # occupied run starting at each cell
    ok[ok] = ((back[fr[ok], fs[ok] - 1] >= line_min)
              & (ahead[fr[ok], np.minimum(fe[ok], w - 1)] >= line_min))
    doors = np.stack([fr[ok], fs[ok], fe[ok]], axis=1)
    mask = np.zeros_like(occ)
    for row, a, b in doors:
        mask[row, a:b] = True
    return lines, doors, mask


def _side_tables(length: int, m: int, big: int):
    lengths = np.arange(m, min(big, length) + 1)
    counts = (length - lengths + 1).astype(float)
    total = int(counts.sum())
    cdf = np.cumsum(counts) / counts.sum() if total else np.zeros(0)
    return total, (lengths, cdf)


def _box(r, c, up, down, left, right, t, shape):
    h, w = shape
    return (max(r - up[r, c] + 1 - t, 0), max(c - left[r, c] + 1 - t, 0),
            min(r + down[r, c] + t, h), min(c + right[r, c] + t, w))


def build_data(classes: np.ndarray, *, min_side: int, wall_cells: int, wall_share: int = 0,
               max_side: int | None = None, door_min: int = 1, door_max: int = 0,
               settings: KernelSettings | None = None, store=None) -> KernelData:
    """Build the kernels' data from the lattice class map.

    Parameters
    ----------
    classes : (H, W) uint8
        Lattice classes (``cells.FREE / UNKNOWN / OCCUPIED``).
    min_side, max_side : int
        Side range of a unit in cells, wall bands included (``max_side`` defaults to the lattice).
    wall_cells : int
        Wall band thickness ``t``.
    wall_share : int
        ``g``: adjacent units sharing a wall overlap by ``g`` cells across it (0 = they abut).
        Must satisfy ``0 <= g <= t`` and ``g < min_side``.
    door_min, door_max : int
        Widths of a free gap in a wall that counts as a door candidate (``door_max=0``: none).
    settings : KernelSettings, optional
    store : callable(array) -> array, optional
        Each lattice-sized table (line prefix sums, free-run lengths) is passed through it as soon
        as it is made and the result kept (a run maps them from files it shares with its chains'
        processes: ``run.shared.share``), so that the tables made so far need not all be held in
        memory while the next is made. Default: kept as made.

    Returns
    -------
    KernelData
    """
    classes = np.asarray(classes)
    if classes.ndim != 2 or min(classes.shape) < 1:
        raise ValueError("classes must be a non-empty 2-D array")
    s = settings or KernelSettings()
    h, w = classes.shape
    m, t, g = int(min_side), int(wall_cells), int(wall_share)
    big = int(max_side) if max_side is not None else max(h, w)
    if not (m >= 1 and t >= 1 and 0 <= g <= t and g < m and big >= m):
        raise ValueError("need min_side >= 1, wall_cells >= 1, 0 <= wall_share <= wall_cells, "
                         "wall_share < min_side <= max_side")
    free = classes == cells.FREE
    occ = classes == cells.OCCUPIED

    store = _keep if store is None else store
    hcum, vcum, wall_lines, doors = _line_evidence(occ, free, s.wall_line_min, door_min, door_max, store)

    up, down, left, right = free_runs(free, store)

    cand, pr, pc = _birth_boxes(free, up, down, left, right, m, t, big, s.max_candidates)
    birth_rects = np.array(cand, np.int64).reshape(-1, 4)
    birth_weights = np.full(len(birth_rects), 1.0 / max(len(birth_rects), 1))

    n_rows, cdf_rows = _side_tables(h, m, big)
    n_cols, cdf_cols = _side_tables(w, m, big)
    for a in (hcum, vcum, up, down, left, right, birth_rects, birth_weights, wall_lines, doors):
        a.setflags(write=False)
    maxima = np.column_stack([pr, pc]).astype(np.int64)
    maxima.setflags(write=False)
    return KernelData((h, w), m, big, t, g, s, hcum, vcum, up, down, left, right, birth_rects,
                      birth_weights, (n_rows, n_cols), (cdf_rows, cdf_cols), wall_lines, doors, maxima)


def _line_evidence(occ, free, line_min: int, door_min: int, door_max: int, store=_keep):
    """``(hcum, vcum, wall_lines, doors)``: per row and per column the cumulative count of wall or
    door cells (each passed through ``store``), and the wall lines and door candidates found along
    both axes."""
    h, w = occ.shape
    hlines, hdoors, hdoor_mask = _lines_and_doors(occ, free, line_min, door_min, door_max)
    hcum = np.zeros((h, w + 1), np.int32)     # the masks summed as bool into int32: no int32 copies
    np.cumsum(occ | hdoor_mask, axis=1, out=hcum[:, 1:])
    del hdoor_mask
    hcum = store(hcum)
    vlines, vdoors, vdoor_mask = _lines_and_doors(occ.T, free.T, line_min, door_min, door_max)
    vcum = np.zeros((w, h + 1), np.int32)
    np.cumsum(occ.T | vdoor_mask, axis=1, out=vcum[:, 1:])
    del vdoor_mask
    vcum = store(vcum)

    def tag(a, axis):
        return np.column_stack([np.full(len(a), axis), a]) if len(a) else np.zeros((0, 4), int)
    wall_lines = np.concatenate([tag(hlines, 0), tag(vlines, 1)]).astype(np.int64)
    doors = np.concatenate([tag(hdoors, 0), tag(vdoors, 1)]).astype(np.int64)
    return hcum, vcum, wall_lines, doors


#: Side of the tiles :func:`dt_maxima` works on, cells.
DT_TILE = 512
#: Its first halo beyond the maximum filter's reach, cells (doubled until the distances are exact).
DT_HALO = 64


def _tile_maxima(free, box, m: int, t: int):
    """:func:`dt_maxima` of the cells of ``box`` ``(r0, c0, r1, c1)``, from a crop of ``free``
    around it: rows, columns (in the lattice) and distances."""
    h, w = free.shape
    r0, c0, r1, c1 = box
    halo = m + DT_HALO
    while True:
        a0, b0, a1, b1 = max(r0 - halo, 0), max(c0 - halo, 0), min(r1 + halo, h), min(c1 + halo, w)
        crop = free[a0:a1, b0:b1]
        dt = ndimage.distance_transform_edt(crop)
        whole = (a0, b0, a1, b1) == (0, 0, h, w)
        # a cell's distance in the crop is the lattice's when it is at most the cell's distance to
        # the crop's border inside the lattice: every cell the filter reads lies halo - m from it
        near = dt[max(r0 - m, 0) - a0:min(r1 + m, h) - a0, max(c0 - m, 0) - b0:min(c1 + m, w) - b0]
        if whole or ((~crop).any() and near.max() <= halo - m):
            break
        halo *= 2
    inner = (slice(r0 - a0, r1 - a0), slice(c0 - b0, c1 - b0))
    top = ndimage.maximum_filter(dt, size=2 * m + 1)[inner]
    dt = dt[inner]
    rr, cc = np.nonzero((dt == top) & (dt >= max(1.0, t)))
    return rr + r0, cc + c0, dt[rr, cc]


def dt_maxima(free: np.ndarray, m: int, t: int):
    """The maxima of the free space's distance transform: the cells whose distance (at least
    ``max(1, t)``) is the largest within the ``2m+1`` square around them; their rows, columns in
    row-major order and distances. The same cells and values as the transform and its maximum
    filter over the whole lattice, computed tile by tile (:data:`DT_TILE`) on the tiles that hold
    free cells, each from a crop around it large enough for exact distances: a campus floor's
    lattice is mostly unknown canvas, and the whole lattice's float64 transform and filter were
    16 bytes per cell beside scipy's int32 feature transform."""
    h, w = free.shape
    rows, cols, dist = [], [], []
    for r0 in range(0, h, DT_TILE):
        for c0 in range(0, w, DT_TILE):
            box = (r0, c0, min(r0 + DT_TILE, h), min(c0 + DT_TILE, w))
            if free[box[0]:box[2], box[1]:box[3]].any():
                r, c, d = _tile_maxima(free, box, m, t)
                rows.append(r)
                cols.append(c)
                dist.append(d)
    if not rows:
        return np.zeros(0, np.intp), np.zeros(0, np.intp), np.zeros(0)
    rows, cols, dist = np.concatenate(rows), np.concatenate(cols), np.concatenate(dist)
    order = np.lexsort((cols, rows))
    return rows[order], cols[order], dist[order]


def _birth_boxes(free, up, down, left, right, m: int, t: int, big: int, max_candidates: int):
    """Birth candidates: the free box around each distance-transform maximum and each region
    centre (at most ``max_candidates``, sides within ``[m, big]``); and the maxima's rows and
    columns."""
    pr, pc, peak_dt = dt_maxima(free, m, t)
    order = np.argsort(-peak_dt, kind="stable")
    pr, pc = pr[order], pc[order]
    seeds = list(zip(pr.tolist(), pc.tolist()))
    labels, n_regions = ndimage.label(free)
    for sl, idx in zip(ndimage.find_objects(labels), range(1, n_regions + 1)):
        rr, cc = np.nonzero(labels[sl] == idx)
        k = len(rr) // 2
        seeds.append((int(rr[k] + sl[0].start), int(cc[k] + sl[1].start)))
    cand, seen = [], set()
    for r, c in seeds:
        box = _box(r, c, up, down, left, right, t, free.shape)
        bh, bw = box[2] - box[0], box[3] - box[1]
        if box in seen or not (m <= bh <= big and m <= bw <= big):
            continue
        seen.add(box)
        cand.append(box)
        if len(cand) >= max_candidates:
            break
    return cand, pr, pc


def data_from_frame(frame, settings: KernelSettings | None = None, store=None) -> KernelData:
    """Kernel data for a :class:`~semmap_pp.lattice.frame.Frame`, sizes from its model cells
    (``store``: as :func:`build_data`).

    Adjacent units share a wall by overlapping their wall bands (``wall_share = wall``), the
    convention of :mod:`semmap_pp.target.likelihood` (overlapping wall bands cost no overlap penalty).
    """
    c = frame.cells
    return build_data(frame.classes, min_side=c.min_side, max_side=c.max_side, wall_cells=c.wall,
                      wall_share=c.wall, door_min=c.door_min, door_max=c.door_max, settings=settings,
                      store=store)
