"""The prior p(W): number of units, unit parameters, and the SaLe factor (paper Sec. III-C.1).

``log p(W) = log p_n(n) - log C(K, n) + Σ_units log p_rect(rect) + Σ_pairs log b(p, q)``

* ``p_n``: truncated Poisson (or geometric) on ``0..K`` with the model's mean, ``K`` the world's
  number of slots. Units sit in ``K`` labelled slots: a set of ``n`` units (density
  ``n! p_n(n) Π p_rect``) is held by ``K!/(K-n)!`` slot states, so each has ``p_n(n) Π p_rect / C(K, n)``
  and ``p_n`` stays the law of the number of units (:func:`log_slots`).
* ``p_rect``: uniform over every lattice rectangle inside the lattice whose two sides (wall band
  included) lie in ``[min_side, max_side]`` cells; the count is in closed form
  (:func:`n_rects`). A rectangle outside that set has probability 0.
* ``b(p, q) = exp(-d² / 2σ²)`` for adjacent pairs with ``P(SaLe(p, q)) > threshold``, ``d`` the
  length difference (metres) of their connecting walls: the heights when the two units sit side by
  side along the columns, the widths when one is above the other. The paper's normaliser η is a
  constant of the target (types are a function of the geometry), so it is left out: the SaLe
  factor is at most 1, so the prior stays proper.

Examples
--------
>>> n_rects(5, 3, 5)   # sides 3, 4, 5 in a line of 5 cells: 3 + 2 + 1
6
"""

from __future__ import annotations

import math

import numba
import numpy as np

from semmap_pp.derive.crossing import NO_CROSS, facing_lengths, tile_of


def n_rects(length: int, min_side: int, max_side: int) -> int:
    """Number of intervals ``[a, a + s)`` inside ``[0, length)`` with ``min_side <= s <= max_side``."""
    a, b = int(min_side), min(int(max_side), int(length))
    if b < a:
        return 0
    k = b - a + 1
    return k * (int(length) + 1) - (a + b) * k // 2


def log_p_rect_const(shape, min_side: int, max_side: int, spans=()) -> float:
    """``log p_rect`` of any valid rectangle on a lattice of ``shape`` (uniform); with ``spans``
    (``(c0, c1)`` column ranges, a tiled lattice's tiles: :mod:`semmap_pp.lattice.tiles`) the
    support holds only the rectangles whose columns lie within one of them."""
    widths = [c1 - c0 for c0, c1 in spans] if len(spans) else [shape[1]]
    total = n_rects(shape[0], min_side, max_side) * sum(n_rects(w, min_side, max_side) for w in widths)
    return -math.log(total) if total > 0 else -math.inf


def _in_spans(c0: np.ndarray, c1: np.ndarray, spans) -> np.ndarray:
    """Whether columns ``[c0, c1)`` lie within one of ``spans`` (always, when there are none)."""
    if not len(spans):
        return np.ones(np.shape(c0), bool)
    return np.any([(c0 >= a) & (c1 <= b) for a, b in spans], axis=0)


def rects_valid(rects: np.ndarray, shape, min_side: int, max_side: int, spans=()) -> np.ndarray:
    """(n,) bool: each rectangle lies inside ``shape`` (and one of ``spans``, if any: see
    :func:`log_p_rect_const`) with both sides in [min_side, max_side]."""
    r = np.asarray(rects).reshape(-1, 4)
    h, w = r[:, 2] - r[:, 0], r[:, 3] - r[:, 1]
    return ((r[:, 0] >= 0) & (r[:, 1] >= 0) & (r[:, 2] <= shape[0]) & (r[:, 3] <= shape[1])
            & (h >= min_side) & (h <= max_side) & (w >= min_side) & (w <= max_side)
            & _in_spans(r[:, 1], r[:, 3], spans))


def rect_faults(rect, shape, min_side: int, max_side: int, spans=()) -> frozenset:
    """Why one rectangle ``(r0, c0, r1, c1)`` is outside the prior's support, for a message: the
    set of ``"small"`` (a side below ``min_side``), ``"large"`` (a side above ``max_side``),
    ``"outside"`` (beyond the lattice ``shape``) and ``"straddles"`` (across two of ``spans``, a
    tiled lattice's tiles) that apply; empty exactly when :func:`rects_valid` holds (tested).

    >>> sorted(rect_faults((-1, 0, 10, 30), (100, 100), 20, 80)), rect_faults((0, 0, 30, 30), (100, 100), 20, 80)
    (['outside', 'small'], frozenset())
    """
    r0, c0, r1, c1 = (int(v) for v in rect)
    out = set()
    if min(r1 - r0, c1 - c0) < min_side:
        out.add("small")
    if max(r1 - r0, c1 - c0) > max_side:
        out.add("large")
    if r0 < 0 or c0 < 0 or r1 > shape[0] or c1 > shape[1]:
        out.add("outside")
    elif not _in_spans(np.array(c0), np.array(c1), spans):
        out.add("straddles")
    return frozenset(out)


def log_p_rect(rect, shape, min_side: int, max_side: int, spans=()) -> float:
    """``log p_rect`` of one rectangle (``-inf`` outside the support)."""
    if not rects_valid(np.asarray(rect).reshape(1, 4), shape, min_side, max_side, spans)[0]:
        return -math.inf
    return log_p_rect_const(shape, min_side, max_side, spans)


def log_p_n_table(capacity: int, params) -> np.ndarray:
    """``log p_n(n)`` for ``n = 0..capacity`` (normalised over that range)."""
    n = np.arange(capacity + 1, dtype=np.float64)
    mean = params.n_mean
    if params.n_prior == "poisson":
        logw = n * math.log(mean) - np.array([math.lgamma(k + 1) for k in n])
    else:  # geometric with the given mean: p(n) ∝ ρ^n, ρ = mean / (1 + mean)
        logw = n * math.log(mean / (1.0 + mean))
    m = logw.max()
    return logw - (m + math.log(np.exp(logw - m).sum()))


def log_p_n(n: int, capacity: int, params) -> float:
    """``log p_n(n)``: truncated Poisson/geometric prior on the number of units."""
    if not 0 <= n <= capacity:
        return -math.inf
    return float(log_p_n_table(capacity, params)[n])


def log_slots(n: int, capacity: int) -> float:
    """``log C(K, n)``: the slot term that keeps ``p_n`` the law of the number of units.

    A set of ``n`` distinct units has density ``n! p_n(n) prod p_rect`` (any of its ``n!`` orders),
    and ``K! / (K - n)!`` slot states hold it; dividing the first by the second leaves
    ``p_n(n) prod p_rect / C(K, n)`` per slot state. Dividing by ``K! / (K - n)!`` alone would make
    the number of units follow ``p_n(n) / n!`` instead (tests/unit/test_mcmc.py shows both).
    """
    return math.lgamma(capacity + 1) - math.lgamma(capacity - n + 1) - math.lgamma(n + 1)


def connecting_length_difference(rp, rq, resolution: float) -> np.ndarray:
    """``d`` in metres for pairs of rectangles (broadcasting over leading axes).

    Side by side along the columns (their column gap exceeds their row gap): the connecting walls
    are vertical, compare heights; otherwise compare widths.
    """
    rp, rq = np.asarray(rp), np.asarray(rq)
    col_gap = np.maximum(rp[..., 1], rq[..., 1]) - np.minimum(rp[..., 3], rq[..., 3])
    row_gap = np.maximum(rp[..., 0], rq[..., 0]) - np.minimum(rp[..., 2], rq[..., 2])
    hp, hq = rp[..., 2] - rp[..., 0], rq[..., 2] - rq[..., 0]
    wp, wq = rp[..., 3] - rp[..., 1], rq[..., 3] - rq[..., 1]
    return np.where(col_gap >= row_gap, np.abs(hp - hq), np.abs(wp - wq)) * resolution


def sale_log_factor(rects: np.ndarray, adj: np.ndarray, sale_prob: np.ndarray,
                    resolution: float, params) -> float:
    """``Σ log b(p, q)`` over unordered adjacent pairs with ``P(SaLe) > threshold``.

    Parameters
    ----------
    rects : (n, 4)
    adj : (n, n) bool
    sale_prob : (n, n) float
        P(SaLe(p, q)) (only adjacent entries are read).
    """
    rects = np.asarray(rects).reshape(-1, 4)
    on = np.triu(np.asarray(adj, dtype=bool) & (np.asarray(sale_prob) > params.sale_threshold), 1)
    i, j = np.nonzero(on)
    if i.size == 0:
        return 0.0
    d = connecting_length_difference(rects[i], rects[j], resolution)
    return float(-np.sum(d * d) / (2.0 * params.sale_sigma_m ** 2))


def log_prior(rects: np.ndarray, capacity: int, shape, min_side: int, max_side: int,
              adj: np.ndarray, sale_prob: np.ndarray, resolution: float, params) -> float:
    """The full ``log p(W)`` of the active units ``rects`` (n, 4)."""
    rects = np.asarray(rects).reshape(-1, 4)
    n = len(rects)
    if n > capacity or not np.all(rects_valid(rects, shape, min_side, max_side)):
        return -math.inf
    return (log_p_n(n, capacity, params) - log_slots(n, capacity)
            + (n * log_p_rect_const(shape, min_side, max_side) if n else 0.0)  # 0 units: no -inf * 0
            + sale_log_factor(rects, adj, sale_prob, resolution, params))


@numba.njit(cache=True, nogil=True)
def _sale_pairs(rects, active, adj, sale, types, table, use_table, threshold, resolution,
                inv_two_sigma2, spans, aff):  # pragma: no cover - compiled
    """``spans`` (flat) and ``aff`` of a tiled lattice (:class:`~semmap_pp.derive.crossing.CrossData`;
    empty on one of one direction): a pair of two tiles compares the sides that face each other
    (:func:`~semmap_pp.derive.crossing.facing_lengths`)."""
    total = 0.0
    K = rects.shape[0]
    tiled = aff.shape[0] > 1
    for p in range(K):
        if not active[p]:
            continue
        for q in range(p + 1, K):
            if not (active[q] and adj[p, q]):
                continue
            prob = table[types[p], types[q]] if use_table else sale[p, q]
            if prob <= threshold:
                continue
            rp, rq = rects[p], rects[q]
            if tiled and tile_of(rp[1], spans) != tile_of(rq[1], spans):
                lp, lq = facing_lengths(aff, tile_of(rp[1], spans), rp, tile_of(rq[1], spans), rq)
                d = abs(lp - lq) * resolution
            else:
                col_gap = max(rp[1], rq[1]) - min(rp[3], rq[3])
                row_gap = max(rp[0], rq[0]) - min(rp[2], rq[2])
                if col_gap >= row_gap:
                    d = abs((rp[2] - rp[0]) - (rq[2] - rq[0])) * resolution
                else:
                    d = abs((rp[3] - rp[1]) - (rq[3] - rq[1])) * resolution
            total -= d * d * inv_two_sigma2
    return total


def sale_log_factor_slots(rects, active, adj, params, resolution, sale=None, types=None,
                          table=None, cross=NO_CROSS) -> float:
    """:func:`sale_log_factor` over slot-indexed arrays (K, 4), (K,), (K, K), compiled.

    P(SaLe) comes from ``sale`` (K, K), or from ``table[types[p], types[q]]`` when a fixed table
    is used (no (K, K) matrix to build per proposal); ``cross``: a tiled lattice's
    :class:`~semmap_pp.derive.crossing.CrossData` (its pairs of two tiles compare the sides that
    face each other).
    """
    K = len(active)
    use_table = sale is None
    if use_table:
        sale = np.zeros((1, 1))
    else:
        types, table = np.zeros(K, np.int8), np.zeros((1, 1))
    return float(_sale_pairs(np.asarray(rects), np.asarray(active, np.bool_), adj, sale,
                             np.asarray(types), np.asarray(table, np.float64),
                             use_table, float(params.sale_threshold), float(resolution),
                             1.0 / (2.0 * params.sale_sigma_m ** 2), cross.spans, cross.aff))


@numba.njit(cache=True, nogil=True)
def _all_valid(rects, active, h, w, lo, hi, spans):  # pragma: no cover - compiled
    """``spans``: the flat ``c0, c1, c0, c1, ...`` of :func:`rects_valid`'s spans (empty: none)."""
    for s in range(rects.shape[0]):
        if not active[s]:
            continue
        r = rects[s]
        a, b = r[2] - r[0], r[3] - r[1]
        if r[0] < 0 or r[1] < 0 or r[2] > h or r[3] > w or a < lo or a > hi or b < lo or b > hi:
            return False
        if spans.shape[0] > 0:
            inside = False
            for k in range(0, spans.shape[0] - 1, 2):
                if r[1] >= spans[k] and r[3] <= spans[k + 1]:
                    inside = True
            if not inside:
                return False
    return True


def flat_spans(spans) -> np.ndarray:
    """``spans`` as the flat int64 array :func:`_all_valid` reads."""
    return np.asarray([v for span in spans for v in span], np.int64).reshape(-1)


def all_valid(rects, active, shape, min_side: int, max_side: int, spans=()) -> bool:
    """Every active slot satisfies :func:`rects_valid` (compiled, for the sampler's hot path)."""
    return bool(_all_valid(np.asarray(rects), np.asarray(active, np.bool_),
                           int(shape[0]), int(shape[1]), int(min_side), int(max_side),
                           flat_spans(spans)))
