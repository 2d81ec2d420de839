"""Stand-in targets for the sampler tests (the Tracker contract of docs/architecture.md).

A state with ``n`` units in ``K`` labelled slots has
``log p = log p_n(n) - log C(K, n) + sum_units log p_rect(unit) + ...``: a set of ``n`` iid units has
density ``n! p_n(n) prod p_rect`` and is held by ``K! / (K - n)!`` slot states, so ``-log C(K, n)``
(not ``-log(K!/(K-n)!)``, which would make the number of units follow ``p_n(n) / n!``) keeps ``p_n``
the marginal of the number of units. ``slots="placements"`` selects the other term.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from semmap_pp import world as wm


def log_falling(capacity: int, n: int) -> float:
    """``log(K! / (K - n)!)``."""
    return math.lgamma(capacity + 1) - math.lgamma(capacity - n + 1)


def log_choose(capacity: int, n: int) -> float:
    """``log C(K, n)``."""
    return log_falling(capacity, n) - math.lgamma(n + 1)


class Prop(NamedTuple):
    world: object
    logp: float
    cache: object = None


class Tracker:
    """Full recomputation on every proposal (enough for small tests)."""

    def __init__(self, target, world):
        self.target = target
        self.world = world
        self.logp = target.evaluate(world)

    def propose(self, world, changed_slots):
        return Prop(world, self.target.evaluate(world))

    def accept(self, prop):
        self.world, self.logp = prop.world, prop.logp


class TableTarget:
    """A random log weight per canonical world (slot order ignored), plus the slot term."""

    def __init__(self, rng, capacity: int, scale: float = 2.0):
        self.rng, self.capacity, self.scale = rng, capacity, scale
        self.table: dict = {}

    def evaluate(self, world) -> float:
        key = wm.canonical_key(world)
        if key not in self.table:
            self.table[key] = float(self.rng.normal(0.0, self.scale))
        return self.table[key] - log_choose(self.capacity, wm.n_units(world))

    def start(self, world):
        return Tracker(self, world)


class PriorTarget:
    """Prior only: ``p_n`` a truncated Poisson over 0..K, each unit uniform over valid rectangles."""

    def __init__(self, data, capacity: int, rate: float, slots: str = "sets"):
        self.data, self.capacity = data, capacity
        self.slot_term = log_choose if slots == "sets" else log_falling
        n = np.arange(capacity + 1)
        logpn = n * math.log(rate) - np.array([math.lgamma(k + 1) for k in n])
        self.log_pn = logpn - np.logaddexp.reduce(logpn)
        self.log_rect = -math.log(data.side_counts[0] * data.side_counts[1])

    def evaluate(self, world) -> float:
        if not wm.is_valid(world, self.data.shape, self.data.min_side):
            return -math.inf
        if np.any(wm.heights_widths(world)[0] > self.data.max_side) or \
                np.any(wm.heights_widths(world)[1] > self.data.max_side):
            return -math.inf
        n = wm.n_units(world)
        return float(self.log_pn[n]) - self.slot_term(self.capacity, n) + n * self.log_rect

    def start(self, world):
        return Tracker(self, world)


class CachedTarget:
    """An incremental target: per-slot cell scores plus a pairwise overlap penalty, cached per slot.

    The tracker only recomputes the terms of ``changed_slots``, so a kernel that changes a slot
    without reporting it makes the tracked log density drift away from :meth:`evaluate`.
    """

    def __init__(self, rng, data, capacity: int, rate: float = 3.0, overlap: float = 0.3):
        self.prior = PriorTarget(data, capacity, rate)
        score = rng.normal(0.0, 0.05, data.shape)
        self.cum = np.zeros((data.shape[0] + 1, data.shape[1] + 1))
        self.cum[1:, 1:] = score.cumsum(0).cumsum(1)
        self.overlap = overlap

    def unit_terms(self, world) -> np.ndarray:
        r = world.rects.astype(np.int64)
        c = self.cum
        s = c[r[:, 2], r[:, 3]] - c[r[:, 0], r[:, 3]] - c[r[:, 2], r[:, 1]] + c[r[:, 0], r[:, 1]]
        return np.where(world.active, s, 0.0)

    def pair_terms(self, world, rows=None) -> np.ndarray:
        r = world.rects.astype(np.int64)
        idx = np.arange(len(r)) if rows is None else np.asarray(rows)
        dr = np.minimum(r[idx, None, 2], r[None, :, 2]) - np.maximum(r[idx, None, 0], r[None, :, 0])
        dc = np.minimum(r[idx, None, 3], r[None, :, 3]) - np.maximum(r[idx, None, 1], r[None, :, 1])
        area = np.clip(dr, 0, None) * np.clip(dc, 0, None)
        both = world.active[idx, None] & world.active[None, :] & (idx[:, None] != np.arange(len(r))[None, :])
        return -self.overlap * np.where(both, area, 0)

    def evaluate(self, world) -> float:
        base = self.prior.evaluate(world)
        if base == -math.inf:
            return base
        return base + float(self.unit_terms(world).sum()) + 0.5 * float(self.pair_terms(world).sum())

    def start(self, world):
        return CachedTracker(self, world)


class CachedTracker:
    def __init__(self, target, world):
        self.target = target
        self.world = world
        self.units = target.unit_terms(world)
        self.pairs = target.pair_terms(world)
        self.logp = target.evaluate(world)

    def _total(self, world, units, pairs) -> float:
        base = self.target.prior.evaluate(world)
        return base + float(units.sum()) + 0.5 * float(pairs.sum()) if base > -math.inf else base

    def propose(self, world, changed_slots):
        ch = list(changed_slots)
        units = self.units.copy()
        units[ch] = self.target.unit_terms(world)[ch]
        pairs = self.pairs.copy()
        rows = self.target.pair_terms(world, ch)
        pairs[ch, :] = rows
        pairs[:, ch] = rows.T
        return Prop(world, self._total(world, units, pairs), (units, pairs))

    def accept(self, prop):
        self.world, self.logp = prop.world, prop.logp
        self.units, self.pairs = prop.cache
