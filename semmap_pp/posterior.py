"""The target the sampler sees: likelihood + prior + types from knowledge, full and incremental.

Types are a deterministic function of the geometry: the MAP types of the provider given the
evidence of the world (:mod:`semmap_pp.evidence`). Before knowledge is switched on (or without a
knowledge engine) the provider is :class:`~semmap_pp.evidence.FixedProvider` (types from the
geometry class alone, P(SaLe) from the model's fixed table); :attr:`Posterior.knowledge_on` switches
to the engine between sampling phases, once :meth:`Tracker.coverage` reaches the model's
``coverage_threshold``.

Examples
--------
>>> import numpy as np
>>> from semmap_pp import world as W
>>> from semmap_pp.model import load_model
>>> from semmap_pp.frame import build_frame_from_classes
>>> classes = np.full((40, 60), 1, np.uint8); classes[5:35, 5:55] = 0
>>> post = Posterior(build_frame_from_classes(classes, 0.05, load_model()), load_model())
>>> w = W.add(W.empty(8), 0, (5, 5, 35, 30))
>>> tr = post.start(w)
>>> prop = tr.propose(W.replace(tr.world, 0, (5, 5, 35, 55)), [0])
>>> abs(prop.logp - post.evaluate(prop.world).total) < 1e-9
True
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from semmap_pp import world as W
from semmap_pp.cells import UNIT_TYPES
from semmap_pp.derive.adjacency import adjacency_row, adjacency_rows
from semmap_pp.evidence import (GEOMETRY_TYPE, FixedProvider, build_evidence, geometry_class,
                                geometry_class_one)
from semmap_pp.likelihood import (Change, CoverTracker, LikPatch, full_tallies,
                                  loglik_from_tallies, prepare)
from semmap_pp.prior import all_valid, log_p_n_table, log_p_rect_const, log_slots, sale_log_factor_slots

CORRIDOR = UNIT_TYPES.index("corridor")


class Terms(NamedTuple):
    """A full evaluation: log-likelihood, log-prior, their sum, and the world with types."""

    loglik: float
    logprior: float
    total: float
    world: W.World


@dataclass(frozen=True)
class _Typing:
    """Types, adjacency and SaLe marginals of one world (all slot-indexed, (K,) / (K, K))."""

    world: W.World
    geometry: np.ndarray
    adj: np.ndarray
    sale: np.ndarray | None   # None: P(SaLe) = fixed_sale[type p, type q]


class Posterior:
    """``log p(W | M) + const`` for worlds on one map.

    Parameters
    ----------
    frame : Frame
        The building lattice of the map.
    model : Model
    knowledge : Provider, optional
        The knowledge engine (``infer(evidence)``); used only while :attr:`knowledge_on`.
    """

    def __init__(self, frame, model, knowledge=None):
        self.frame, self.model, self.knowledge = frame, model, knowledge
        self.cells = frame.cells
        self.data = prepare(frame, model)
        self.fixed = FixedProvider(model.knowledge.fixed_sale)
        self.knowledge_on = False
        self.log_rect = log_p_rect_const(frame.shape, self.cells.min_side, self.cells.max_side)
        self._log_pn: dict[int, np.ndarray] = {}
        self._door_cache: dict = {}

    # ------------------------------------------------------------------ pieces
    @property
    def provider(self):
        """The provider in use: the knowledge engine when switched on, else the fixed one."""
        if self.knowledge_on and self.knowledge is not None:
            return self.knowledge
        return self.fixed

    def _log_pn_table(self, capacity: int) -> np.ndarray:
        if capacity not in self._log_pn:
            self._log_pn[capacity] = log_p_n_table(capacity, self.model.prior)
        return self._log_pn[capacity]

    def door_counts(self, rects: np.ndarray, adj: np.ndarray) -> np.ndarray:
        """Doors of each unit (cached per pair of rectangles)."""
        from semmap_pp.derive.doors import doors_between
        n = len(rects)
        counts = np.zeros(n, dtype=np.int64)
        for p, q in zip(*np.nonzero(np.triu(adj, 1))):
            key = (tuple(int(v) for v in rects[p]), tuple(int(v) for v in rects[q]))
            k = self._door_cache.get(key)
            if k is None:
                if len(self._door_cache) > 200_000:
                    self._door_cache.clear()
                k = len(doors_between(self.frame.classes, rects[p], rects[q], self.cells))
                self._door_cache[key] = k
            counts[p] += k
            counts[q] += k
        return counts

    def _infer(self, world: W.World, adj: np.ndarray, provider):
        """The provider's result (types, SaLe, MAP types) for the active units of ``world``."""
        slots = W.active_slots(world)
        rects = world.rects[slots]
        sub = adj[np.ix_(slots, slots)]
        doors = (self.door_counts(rects, sub) if getattr(provider, "needs_doors", True) else None)
        ev = build_evidence(slots, rects, sub, self.cells.resolution, self.model.evidence, doors)
        return provider.infer(ev.to_knowledge() if not isinstance(provider, FixedProvider) else ev)

    def _types(self, world: W.World, geometry: np.ndarray, adj: np.ndarray):
        """Type indices (K,) and P(SaLe) (K, K) of the active slots from the current provider.

        With the fixed provider the SaLe matrix is ``None`` (read from the fixed table by type).
        """
        provider = self.provider
        if isinstance(provider, FixedProvider):
            types = np.where(world.active, GEOMETRY_TYPE[geometry], W.NO_TYPE).astype(np.int8)
            return types, None
        result = self._infer(world, adj, provider)
        types = np.full(world.capacity, W.NO_TYPE, dtype=np.int8)
        sale = np.zeros((world.capacity, world.capacity))
        for s in W.active_slots(world):
            types[s] = UNIT_TYPES.index(result.map_types[int(s)])
        for (p, q), v in result.sale.items():
            sale[p, q] = sale[q, p] = v
        return types, sale

    def knowledge_result(self, world: W.World):
        """Type marginals, SaLe marginals and MAP types of ``world`` from the provider in use.

        Keys are slots. With knowledge off the marginals are those of the fixed provider (one-hot
        on the geometry class), which is what the sampler used.
        """
        typ = self.typing(world)
        return self._infer(typ.world, typ.adj, self.provider)

    def _typed(self, world: W.World, types: np.ndarray) -> W.World:
        types.setflags(write=False)
        return W.World(world.rects, world.active, types)

    def typing(self, world: W.World) -> _Typing:
        """Geometry classes, adjacency, types and SaLe marginals of a world, from scratch."""
        K = world.capacity
        geometry = np.zeros(K, dtype=np.int8)
        adj = np.zeros((K, K), dtype=bool)
        slots = W.active_slots(world)
        if len(slots):
            rects = world.rects[slots]
            geometry[slots] = geometry_class(rects, self.cells.resolution, self.model.evidence)
            adj[np.ix_(slots, slots)] = adjacency_rows(
                rects, np.arange(len(slots)), self.cells.wall, self.cells.adjacency_dilation)
        types, sale = self._types(world, geometry, adj)
        return _Typing(self._typed(world, types), geometry, adj, sale)

    def _logprior(self, typ: _Typing) -> float:
        w = typ.world
        n, K = int(np.count_nonzero(w.active)), w.capacity
        c = self.cells
        if not all_valid(w.rects, w.active, self.frame.shape, c.min_side, c.max_side):
            return -math.inf
        if typ.sale is None:
            sale = sale_log_factor_slots(w.rects, w.active, typ.adj, self.model.prior,
                                         c.resolution, types=w.types, table=self.fixed.fixed_sale)
        else:
            sale = sale_log_factor_slots(w.rects, w.active, typ.adj, self.model.prior,
                                         c.resolution, sale=typ.sale)
        return float(self._log_pn_table(K)[n] - log_slots(n, K) + n * self.log_rect + sale)

    # ------------------------------------------------------------------ full
    def evaluate(self, world: W.World) -> Terms:
        """Full, stateless evaluation (types assigned from the geometry)."""
        typ = self.typing(world)
        w = typ.world
        slots = W.active_slots(w)
        hist, g = full_tallies(self.data, w.rects[slots], w.types[slots] == CORRIDOR)
        loglik = loglik_from_tallies(self.data, hist, g)
        logprior = self._logprior(typ)
        return Terms(loglik, logprior, loglik + logprior, w)

    def start(self, world: W.World) -> "Tracker":
        """The incremental tracker of one chain, starting at ``world``."""
        return Tracker(self, world)


@dataclass(frozen=True, eq=False)
class Proposal:
    """A proposed world with its log posterior; pass it to :meth:`Tracker.accept` to commit."""

    world: W.World
    logp: float
    loglik: float
    logprior: float
    typing: _Typing
    patch: LikPatch


class Tracker:
    """Incremental log posterior of one chain (the one stateful object; see architecture.md)."""

    def __init__(self, post: Posterior, world: W.World):
        self.post = post
        self._typ = post.typing(world)
        w = self._typ.world
        slots = W.active_slots(w)
        self.cover = CoverTracker(post.data, w.rects[slots], w.types[slots] == CORRIDOR)
        self.loglik = self.cover.loglik
        self.logprior = post._logprior(self._typ)
        self.logp = self.loglik + self.logprior

    @property
    def world(self) -> W.World:
        return self._typ.world

    def coverage(self, hist=None) -> float:
        """Fraction of the input-free lattice cells covered by some unit."""
        return self.cover.covered_free(hist) / max(self.post.data.n_free, 1)

    def _retype(self, new_world: W.World, changed: list) -> _Typing:
        """Types after an edit of ``changed`` slots: geometry and adjacency rows of the changed
        slots are recomputed, then the provider types *every* unit again."""
        post, old = self.post, self._typ
        geometry = old.geometry.copy()
        adj = old.adj.copy()
        act, rects = new_world.active, new_world.rects
        c = post.cells
        row = np.empty(new_world.capacity, dtype=np.bool_)
        for s in changed:
            adj[s, :] = False
            adj[:, s] = False
            if act[s]:
                geometry[s] = geometry_class_one(rects[s], c.resolution, post.model.evidence)
                adjacency_row(rects, act, s, c.wall, c.adjacency_dilation, row)
                adj[s, :] = row
                adj[:, s] = row
        types, sale = post._types(new_world, geometry, adj)
        return _Typing(post._typed(new_world, types), geometry, adj, sale)

    def propose(self, new_world: W.World, changed_slots) -> Proposal:
        """Evaluate ``new_world`` (which differs from :attr:`world` only in ``changed_slots``).

        Types of *every* unit are re-derived (evidence of a neighbour may change with the edit);
        units whose type changed are recomputed in the likelihood along with the edited ones.
        """
        old = self._typ.world
        changed = sorted({int(s) for s in changed_slots})
        typ = self._retype(new_world, changed)
        new = typ.world
        touched = set(changed)
        touched.update(np.flatnonzero(new.types != old.types).tolist())
        changes = []
        for s in sorted(touched):
            a = tuple(old.rects[s].tolist()) if old.active[s] else None
            b = tuple(new.rects[s].tolist()) if new.active[s] else None
            ca = bool(old.active[s] and old.types[s] == CORRIDOR)
            cb = bool(new.active[s] and new.types[s] == CORRIDOR)
            if a != b or ca != cb:
                changes.append(Change(a, ca, b, cb))
        patch = self.cover.propose(changes)
        logprior = self.post._logprior(typ)
        return Proposal(new, patch.loglik + logprior, patch.loglik, logprior, typ, patch)

    def resync(self) -> None:
        """Rebuild every cache from the current geometry (call after switching
        :attr:`Posterior.knowledge_on`: the provider, hence the types, changed)."""
        self.__init__(self.post, self.world)

    def accept(self, prop: Proposal) -> None:
        """Commit a proposal (a rejected one is simply dropped)."""
        self.cover.commit(prop.patch)
        self._typ = prop.typing
        self.loglik, self.logprior, self.logp = prop.loglik, prop.logprior, prop.logp
