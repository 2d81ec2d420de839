"""The target the sampler sees: likelihood + prior + types from knowledge, full and incremental.

Types are a deterministic function of the geometry: the MAP types of the provider given the
evidence of the world (:mod:`semmap_pp.target.geometry_evidence`). Before knowledge is switched on (or without a
knowledge engine) the provider is :class:`~semmap_pp.target.geometry_evidence.FixedProvider` (types from the
geometry class alone, P(SaLe) from the model's fixed table); :attr:`Posterior.knowledge_on` switches
to the engine between sampling phases, once :meth:`Tracker.coverage` reaches the model's
``coverage_threshold``.

Examples
--------
>>> import numpy as np
>>> from semmap_pp import world as wm
>>> from semmap_pp.model import load_model
>>> from semmap_pp.lattice.frame import build_frame_from_classes
>>> classes = np.full((40, 60), 1, np.uint8); classes[5:35, 5:55] = 0
>>> post = Posterior(build_frame_from_classes(classes, 0.05, load_model()), load_model())
>>> w = wm.add(wm.empty(8), 0, (5, 5, 35, 30))
>>> tr = post.start(w)
>>> prop = tr.propose(wm.replace(tr.world, 0, (5, 5, 35, 55)), [0])
>>> abs(prop.logp - post.evaluate(prop.world).total) < 1e-9
True
"""

from __future__ import annotations

import bisect
import math
from collections import OrderedDict
from typing import NamedTuple

import numba
import numpy as np

from semmap_pp import world as wm
from semmap_pp.cells import UNIT_TYPES
from semmap_pp.derive.adjacency import adjacency_row, adjacency_rows
from semmap_pp.derive.crossing import NO_CROSS, cross_all, cross_data, cross_update, rect_tiles, tile_of
from semmap_pp.derive.doors import opening_counts
from semmap_pp.target.geometry_evidence import (COLIKE, GEOMETRY_TYPE, FixedProvider, GeometryTable,
                                build_evidence, geometry_class, geometry_class_compiled,
                                muldoor_counts, space_colike)
from semmap_pp.target.likelihood import (covered_free, enclosure_loglik, full_tallies,
                                  loglik_from_tallies, prepare, tallies_loglik, world_delta)
from semmap_pp.model import SIZE_MEASURES
from semmap_pp.lattice.tiles import rect_spans
from semmap_pp.target.prior import _all_valid, _sale_pairs, all_valid, flat_spans, log_p_n_table, \
    log_p_rect_const, log_slots, sale_log_factor_slots
from semmap_pp.target.tracker_knowledge import KnowledgeTracking

CORRIDOR = UNIT_TYPES.index("corridor")


class Terms(NamedTuple):
    """A full evaluation: log-likelihood, log-prior, their sum, and the world with types."""

    loglik: float
    logprior: float
    total: float
    world: wm.World


class _Typing:
    """Types, adjacency and SaLe marginals of one world (all slot-indexed, (K,) / (K, K)).

    ``sale`` is ``None`` when P(SaLe) = fixed_sale[type p, type q]. ``adj`` holds the pairs of two
    tiles too (:mod:`semmap_pp.derive.crossing`), ``cross`` their openings.
    """

    __slots__ = ("world", "geometry", "adj", "sale", "cross")

    def __init__(self, world: wm.World, geometry: np.ndarray, adj: np.ndarray, sale, cross=None):
        self.world, self.geometry, self.adj, self.sale = world, geometry, adj, sale
        #: (K, K, 2) (doors, passages) between units of two tiles (a tiled lattice), else None
        self.cross = cross


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
        self.spans = rect_spans(frame)
        self.cross = cross_data(frame)     # the relations of units of two tiles (none: one tile)
        self._tile_starts = tuple(c1 for _c0, c1 in self.spans[:-1])   # a tile's columns end there
        self.log_rect = log_p_rect_const(frame.shape, self.cells.min_side, self.cells.max_side,
                                         self.spans)
        self._prior_n: dict[int, np.ndarray] = {}
        self._door_cache: dict = {}
        self._typing_cache: OrderedDict = OrderedDict()   # (provider, evidence key, K) -> arrays
        self._map_cache: OrderedDict = OrderedDict()      # same key -> MAP types alone
        self._geometry = GeometryTable(frame.cells.resolution, model.evidence)
        c, p, e = self.cells, model.prior, model.evidence
        # per category, the larger gain of its corridor and non-corridor variants: with it the
        # tallies of any typing bound the log-likelihood of every typing of the same geometry
        g = self.data.gain.reshape(2, -1)
        self._gain_max = _ro(np.concatenate([np.maximum(g[0], g[1])] * 2))
        self._ip = np.array([CORRIDOR, c.wall, c.adjacency_dilation, frame.shape[0], frame.shape[1],
                             c.min_side, c.max_side,
                             SIZE_MEASURES.index(e.size_measure)] + list(flat_spans(self.spans)),
                            np.int64)
        self._fp = np.array([c.resolution, e.hall_min_size, e.corridor_min_ratio, p.sale_threshold,
                             1.0 / (2.0 * p.sale_sigma_m ** 2), self.data.baseline,
                             self.data.log_psi, model.sensor.enclosure_min_share,
                             model.sensor.enclosure_cost], np.float64)

    # ------------------------------------------------------------------ pieces
    @property
    def provider(self):
        """The provider in use: the knowledge engine when switched on, else the fixed one."""
        if self.knowledge_on and self.knowledge is not None:
            return self.knowledge
        return self.fixed

    def prior_n(self, capacity: int) -> np.ndarray:
        """``log p_n(n) - log C(K, n) + n log p_rect`` for ``n = 0..K`` (the prior without SaLe)."""
        table = self._prior_n.get(capacity)
        if table is None:
            log_pn = log_p_n_table(capacity, self.model.prior)
            table = np.array([float(log_pn[n] - log_slots(n, capacity) + (n * self.log_rect if n else 0.0))
                              for n in range(capacity + 1)])
            table.setflags(write=False)
            self._prior_n[capacity] = table
        return table

    def door_counts(self, rects: np.ndarray, adj: np.ndarray,
                    cross: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """``(doors, pieces)``: the doors of each unit that count towards MulDoor
        (:meth:`muldoor_counts`) and the room-like units that are pieces of a corridor space
        (:meth:`corridor_pieces`), from the openings between adjacent units (cached per pair of
        rectangles); ``cross`` (n, n, 2): those of the pairs of two tiles (a tiled lattice)."""
        n = len(rects)
        openings = np.zeros((n, n, 2), dtype=np.int32)
        tiles = rect_tiles(rects, self.cross)
        for p, q in zip(*np.nonzero(np.triu(adj, 1))):
            openings[p, q] = openings[q, p] = (self.pair_openings(rects[p], rects[q])
                                               if tiles[p] == tiles[q] else cross[p, q])
        return self.opening_evidence(openings, rects,
                                     geometry_class(rects, self.cells.resolution, self.model.evidence))

    def opening_evidence(self, openings: np.ndarray, rects: np.ndarray, classes: np.ndarray):
        """``(doors, pieces)`` from the (doors, passages) ``openings`` (n, n, 2) between units with
        rectangles ``rects`` and Table 4 ``classes`` (-1: no unit): the doors that count towards
        MulDoor (:meth:`muldoor_counts`, corridor pieces counting as corridor-like) and the
        corridor pieces (:meth:`corridor_pieces`). The full evaluation and the tracker both
        derive the evidence here."""
        pieces = self.corridor_pieces(openings, rects, classes)
        return self.muldoor_counts(openings, (classes == COLIKE) | pieces), pieces

    def corridor_pieces(self, openings: np.ndarray, rects: np.ndarray, classes: np.ndarray) -> np.ndarray:
        """Room-like units that count as corridor-like (bool (n,)): with ``[evidence]
        colike_scope = "space"`` :func:`semmap_pp.target.geometry_evidence.space_colike` (pieces of a corridor
        space), none with ``"unit"``. ``classes`` are the Table 4 classes (-1: no unit)."""
        e = self.model.evidence
        if e.colike_scope != "space" or len(rects) == 0:
            return np.zeros(len(classes), dtype=bool)
        r = np.asarray(rects)
        short = np.minimum(r[:, 2] - r[:, 0], r[:, 3] - r[:, 1])
        return space_colike(openings, short, classes, e.space_width_ratio)

    def muldoor_counts(self, openings: np.ndarray, colike: np.ndarray) -> np.ndarray:
        """Doors counted towards MulDoor per unit, from ``openings`` (n, n, 2) (doors, passages)
        between each pair and the corridor-like units ``colike`` (n,): each unit's own doors, or
        with ``[evidence] muldoor_scope = "space"`` :func:`semmap_pp.target.geometry_evidence.muldoor_counts`."""
        if self.model.evidence.muldoor_scope == "space":
            return muldoor_counts(openings, colike)
        return openings[..., 0].sum(axis=1)

    def same_tile(self, rp, rq) -> bool:
        """Whether two rectangles lie on one tile (always, on a lattice of one direction)."""
        starts = self._tile_starts
        return bisect.bisect_right(starts, int(rp[1])) == bisect.bisect_right(starts, int(rq[1]))

    def pair_openings(self, rp, rq) -> tuple[int, int]:
        """``(doors, passages)`` between two rectangles (cached per pair)."""
        key = (*np.asarray(rp).tolist(), *np.asarray(rq).tolist())
        k = self._door_cache.get(key)
        if k is None:
            if len(self._door_cache) > 200_000:
                self._door_cache.clear()
            k = opening_counts(self.frame.door_classes, rp, rq, self.cells)
            self._door_cache[key] = k
        return k

    def _evidence(self, world: wm.World, adj: np.ndarray, provider, cross=None):
        """The evidence of the active units of ``world`` (adjacency ``adj``, the openings of
        pairs of two tiles ``cross``), their doors and corridor pieces counted when ``provider``
        needs them."""
        slots = wm.active_slots(world)
        rects = world.rects[slots]
        sub = adj[np.ix_(slots, slots)]
        sub_cross = None if cross is None else cross[np.ix_(slots, slots)]
        doors, pieces = (self.door_counts(rects, sub, sub_cross)
                         if getattr(provider, "needs_doors", True) else (None, None))
        return build_evidence(slots, rects, sub, self.cells.resolution, self.model.evidence, doors,
                              pieces)

    def _infer(self, world: wm.World, adj: np.ndarray, provider, cross=None):
        """The provider's result (types, SaLe, MAP types) for the active units of ``world``."""
        ev = self._evidence(world, adj, provider, cross)
        return provider.infer(ev.to_knowledge() if not isinstance(provider, FixedProvider) else ev)

    def _cached_arrays(self, provider, evidence, capacity: int):
        """:meth:`_result_arrays` when the result is cached, else None."""
        hit = self._typing_cache.get((id(provider), evidence.key, capacity))
        if hit is None or hit[0] is not provider:
            return None
        return self._result_arrays(provider, evidence, capacity)

    def _map_arrays(self, provider, evidence, capacity: int, base=None) -> np.ndarray:
        """Slot-indexed MAP types (K,) alone (``provider.map_types``: no marginals computed),
        equal to the types of :meth:`_result_arrays` (cached by the evidence); ``base``, the
        current world's evidence, lets a provider that :attr:`updates_map` (the knowledge
        engine) update its MAP rather than rebuild it."""
        key = (id(provider), evidence.key, capacity)
        hit = self._map_cache.get(key)
        if hit is not None and hit[0] is provider:
            self._map_cache.move_to_end(key)
            return hit[1]
        map_types = (provider.map_types(evidence, base=base)
                     if base is not None and getattr(provider, "updates_map", False)
                     else provider.map_types(evidence))
        types = np.full(capacity, wm.NO_TYPE, dtype=np.int8)
        for s in evidence.units:
            types[s] = UNIT_TYPES.index(map_types[int(s)])
        types.setflags(write=False)
        self._map_cache[key] = (provider, types)
        if len(self._map_cache) > 4096:
            self._map_cache.popitem(last=False)
        return types

    def _result_arrays(self, provider, evidence, capacity: int):
        """Slot-indexed MAP types (K,) and P(SaLe) (K, K) of the provider's result for a
        knowledge evidence (cached compactly by the evidence: the provider is a function of it)."""
        key = (id(provider), evidence.key, capacity)
        hit = self._typing_cache.get(key)
        if hit is not None and hit[0] is provider:
            self._typing_cache.move_to_end(key)
            _, types, pairs, values = hit
        else:
            result = provider.infer(evidence)
            types = np.full(capacity, wm.NO_TYPE, dtype=np.int8)
            for s in evidence.units:
                types[s] = UNIT_TYPES.index(result.map_types[int(s)])
            types.setflags(write=False)
            items = sorted(result.sale.items())
            pairs = np.array([pq for pq, _ in items], dtype=np.intp).reshape(-1, 2)
            values = np.array([v for _, v in items], dtype=np.float64)
            self._typing_cache[key] = (provider, types, pairs, values)
            if len(self._typing_cache) > 4096:
                self._typing_cache.popitem(last=False)
        sale = np.zeros((capacity, capacity))
        sale[pairs[:, 0], pairs[:, 1]] = values
        sale[pairs[:, 1], pairs[:, 0]] = values
        return types, sale

    def __getstate__(self):
        state = self.__dict__.copy()   # caches stay behind (per process)
        state["_door_cache"], state["_typing_cache"] = {}, OrderedDict()
        state["_map_cache"] = OrderedDict()
        state["_geometry"] = GeometryTable(self.cells.resolution, self.model.evidence)
        return state

    def _types(self, world: wm.World, geometry: np.ndarray, adj: np.ndarray, cross=None):
        """Type indices (K,) and P(SaLe) (K, K) of the active slots from the current provider.

        With the fixed provider the SaLe matrix is ``None`` (read from the fixed table by type).
        """
        provider = self.provider
        if isinstance(provider, FixedProvider):
            types = np.where(world.active, GEOMETRY_TYPE[geometry], wm.NO_TYPE).astype(np.int8)
            return types, None
        ev = self._evidence(world, adj, provider, cross)
        types, sale = self._result_arrays(provider, ev.to_knowledge(), world.capacity)
        return types.copy(), sale

    def knowledge_evidence(self, world: wm.World):
        """The evidence the knowledge engine gets for ``world``'s active units (keys: slots), as
        a :class:`semmap_pp.knowledge.Evidence` (``semmap rules evidence`` writes it as facts);
        the same with knowledge on or off: geometry classes, MulDoor and corridor pieces from the
        doors (counted whatever the provider), adjacency."""
        adj, cross = self.relations(world)
        return self._evidence(world, adj, None, cross).to_knowledge()

    def knowledge_result(self, world: wm.World):
        """Type marginals, SaLe marginals and MAP types of ``world`` from the provider in use.

        Keys are slots. With knowledge off the marginals are those of the fixed provider (one-hot
        on the geometry class), which is what the sampler used.
        """
        typ = self.typing(world)
        return self._infer(typ.world, typ.adj, self.provider, typ.cross)

    def _typed(self, world: wm.World, types: np.ndarray) -> wm.World:
        types.setflags(write=False)
        return wm.World(world.rects, world.active, types)

    def adjacency(self, world: wm.World) -> np.ndarray:
        """(K, K) bool: which active slots of ``world`` are adjacent (walls dilated, paper Fig. 4;
        on a tiled lattice units of two tiles too: :mod:`semmap_pp.derive.crossing`)."""
        return self.relations(world)[0]

    def relations(self, world: wm.World) -> tuple[np.ndarray, np.ndarray | None]:
        """``(adjacency, cross)``: :meth:`adjacency` and the (K, K, 2) (doors, passages) of the
        pairs of two tiles (None on a lattice of one direction), from scratch."""
        K = world.capacity
        adj = np.zeros((K, K), dtype=bool)
        slots = wm.active_slots(world)
        if len(slots):
            adj[np.ix_(slots, slots)] = adjacency_rows(
                world.rects[slots], np.arange(len(slots)), self.cells.wall, self.cells.adjacency_dilation)
        if not self.spans:
            return adj, None
        cross = np.zeros((K, K, 2), np.int32)
        cross_all(_ro(world.rects), _ro(world.active), adj, cross, self.cross)
        return adj, cross

    def typing(self, world: wm.World) -> _Typing:
        """Geometry classes, adjacency, types and SaLe marginals of a world, from scratch."""
        geometry = np.zeros(world.capacity, dtype=np.int8)
        adj, cross = self.relations(world)
        slots = wm.active_slots(world)
        if len(slots):
            geometry[slots] = geometry_class(world.rects[slots], self.cells.resolution, self.model.evidence)
        types, sale = self._types(world, geometry, adj, cross)
        return _Typing(self._typed(world, types), geometry, adj, sale, cross)

    def enclosure(self, world: wm.World) -> float:
        """The enclosure term of the likelihood (:func:`~semmap_pp.target.likelihood.enclosure_loglik`)."""
        return float(enclosure_loglik(self.data.xsum, _ro(world.rects), _ro(world.active),
                                      self.cells.wall, self._fp[F_ENC_MIN], self._fp[F_ENC_COST]))

    def _logprior(self, typ: _Typing) -> float:
        w = typ.world
        n, K = int(np.count_nonzero(w.active)), w.capacity
        c = self.cells
        if not all_valid(w.rects, w.active, self.frame.shape, c.min_side, c.max_side, self.spans):
            return -math.inf
        if typ.sale is None:
            sale = sale_log_factor_slots(w.rects, w.active, typ.adj, self.model.prior,
                                         c.resolution, types=w.types, table=self.fixed.fixed_sale,
                                         cross=self.cross)
        else:
            sale = sale_log_factor_slots(w.rects, w.active, typ.adj, self.model.prior,
                                         c.resolution, sale=typ.sale, cross=self.cross)
        return float(self.prior_n(K)[n] + sale)

    # ------------------------------------------------------------------ full
    def evaluate(self, world: wm.World) -> Terms:
        """Full, stateless evaluation (types assigned from the geometry)."""
        typ = self.typing(world)
        w = typ.world
        slots = wm.active_slots(w)
        hist, g = full_tallies(self.data, w.rects[slots], w.types[slots] == CORRIDOR)
        loglik = loglik_from_tallies(self.data, hist, g) + self.enclosure(w)
        logprior = self._logprior(typ)
        return Terms(loglik, logprior, loglik + logprior, w)

    def start(self, world: wm.World) -> "Tracker":
        """The incremental tracker of one chain, starting at ``world``."""
        return Tracker(self, world)


# ---------------------------------------------------------------------- incremental (compiled)
#
# Packed arguments of the compiled hot path (one call per proposal; fewer arguments, cheaper call).
# ints: corridor type, wall, adjacency dilation, lattice height, width, min side, max side, size
# measure; floats: resolution, hall_min_size, corridor_min_ratio, sale threshold, 1/(2 σ²),
# likelihood baseline, log ψ, enclosure min share and cost.
I_CORR, I_WALL, I_DIL, I_H, I_W, I_LO, I_HI, I_MEASURE, I_SPANS = range(9)   # I_SPANS: from there
# on, a tiled lattice's flat tile spans (prior.flat_spans; none on a lattice of one direction)
F_RES, F_HALL, F_RATIO, F_THRESH, F_INV2S2, F_BASE, F_LOGPSI, F_ENC_MIN, F_ENC_COST = range(9)
_NO_AFF = NO_CROSS.aff     # a lattice of one direction: no tile rotations (the SaLe of one lattice)


@numba.njit(cache=True, nogil=True)
def _retype_changed(old_rects, old_active, rects, active, changed, geometry, adj, types,
                    fixed_types, ip, fp, cross, touched, xd):  # pragma: no cover - compiled
    """Geometry class and adjacency row (in place) of each ``changed`` slot of a world (edited
    from ``old_rects``, ``old_active``); with ``fixed_types`` (the fixed provider's type per
    geometry class, empty otherwise) its type too. On a tiled lattice (``xd``) the pairs of two
    tiles follow (:func:`~semmap_pp.derive.crossing.cross_update`: into ``adj``, their openings
    into ``cross`` unless it is empty; ``touched`` marks the slots of the pairs without a
    changed slot whose relation changed)."""
    K = rects.shape[0]
    row = np.empty(K, np.bool_)
    fixed = fixed_types.shape[0] > 0
    for s in changed:
        for t in range(K):
            adj[s, t] = False
            adj[t, s] = False
        if active[s]:
            g = geometry_class_compiled(rects[s], fp[F_RES], ip[I_MEASURE], fp[F_HALL],
                                        fp[F_RATIO])
            geometry[s] = g
            adjacency_row(rects, active, s, ip[I_WALL], ip[I_DIL], row)
            for t in range(K):
                if row[t]:
                    adj[s, t] = True
                    adj[t, s] = True
            if fixed:
                types[s] = fixed_types[g]
        elif fixed:
            types[s] = -1
    if xd is not None:     # None on a lattice of one direction: the branch is compiled away
        cross_update(old_rects, old_active, rects, active, changed, adj, cross, touched, xd)


@numba.njit(cache=True, nogil=True)
def _score(xsum, gain, old_rects, old_active, old_types, new_rects, new_active, new_types, hist,
           gamma_total, adj, sale, table, use_table, prior_n, ip, fp, aff):  # pragma: no cover
    """Log-likelihood and log-prior of a proposed world; the new tallies go into ``hist``
    (returns the new Σγ as well)."""
    K = old_rects.shape[0]
    old_corr = np.empty(K, np.bool_)
    new_corr = np.empty(K, np.bool_)
    n = 0
    corridor = ip[I_CORR]
    for s in range(K):
        old_corr[s] = old_types[s] == corridor
        new_corr[s] = new_types[s] == corridor
        n += 1 if new_active[s] else 0
    gamma_total += world_delta(xsum, old_rects, old_active, old_corr, new_rects, new_active,
                               new_corr, ip[I_WALL], hist)
    loglik = tallies_loglik(hist, gain, fp[F_BASE], fp[F_LOGPSI], gamma_total) + \
        enclosure_loglik(xsum, new_rects, new_active, ip[I_WALL], fp[F_ENC_MIN], fp[F_ENC_COST])
    logprior = -np.inf
    if _all_valid(new_rects, new_active, ip[I_H], ip[I_W], ip[I_LO], ip[I_HI], ip[I_SPANS:]):
        if aff is None:    # a lattice of one direction (compiled away)
            sp = _sale_pairs(new_rects, new_active, adj, sale, new_types, table, use_table,
                             fp[F_THRESH], fp[F_RES], fp[F_INV2S2], ip[I_SPANS:], _NO_AFF)
        else:
            sp = _sale_pairs(new_rects, new_active, adj, sale, new_types, table, use_table,
                             fp[F_THRESH], fp[F_RES], fp[F_INV2S2], ip[I_SPANS:], aff)
        logprior = prior_n[n] + sp
    return loglik, logprior, gamma_total


@numba.njit(cache=True, nogil=True)
def _propose_fixed(xsum, gain, old_rects, old_active, old_types, new_rects, new_active, changed,
                   geometry, adj, types, fixed_types, hist, gamma_total, table, prior_n, ip,
                   fp, cross, touched, xd):  # pragma: no cover - compiled
    """:func:`_retype_changed` then :func:`_score` with the fixed provider, in one call."""
    _retype_changed(old_rects, old_active, new_rects, new_active, changed, geometry, adj, types,
                    fixed_types, ip, fp, cross, touched, xd)
    if xd is None:
        return _score(xsum, gain, old_rects, old_active, old_types, new_rects, new_active, types,
                      hist, gamma_total, adj, np.zeros((1, 1)), table, True, prior_n, ip, fp, None)
    return _score(xsum, gain, old_rects, old_active, old_types, new_rects, new_active, types,
                  hist, gamma_total, adj, np.zeros((1, 1)), table, True, prior_n, ip, fp, xd[0])


@numba.njit(cache=True, nogil=True)
def _fixed_bound(xsum, gain, old_rects, old_active, old_types, new_rects, new_active, changed,
                 geometry, adj, types, fixed_types, hist, gamma_total, table, prior_n, ip, fp,
                 cross, touched, aff):  # pragma: no cover - compiled
    """An upper bound of a proposal's log posterior under the fixed provider on a tiled lattice,
    without the relations of pairs of two tiles: the changed slots retyped on the lattice alone
    (their geometry classes, hence their fixed types and the likelihood, are exact), and every
    pair of two tiles left out of the SaLe factor (a pair's factor is at most 1). No argument is
    written (copies are retyped)."""
    g, a, t = geometry.copy(), adj.copy(), types.copy()
    _retype_changed(old_rects, old_active, new_rects, new_active, changed, g, a, t, fixed_types,
                    ip, fp, cross, touched, None)
    spans = ip[I_SPANS:]
    K = new_rects.shape[0]
    for p in range(K):
        if new_active[p]:
            for q in range(p + 1, K):
                if a[p, q] and tile_of(new_rects[p, 1], spans) != tile_of(new_rects[q, 1], spans):
                    a[p, q] = a[q, p] = False
    loglik, logprior, _g = _score(xsum, gain, old_rects, old_active, old_types, new_rects,
                                  new_active, t, hist.copy(), gamma_total, a, np.zeros((1, 1)),
                                  table, True, prior_n, ip, fp, aff)
    return 0 + loglik + logprior


@numba.njit(cache=True, nogil=True)
def _type_free_bound(xsum, gain_max, old_rects, old_active, old_types, new_rects, new_active, adj,
                     hist, gamma_total, no_sale, never_sale, prior_n, ip, fp,
                     aff):  # pragma: no cover - compiled
    """The type-free upper bound of a proposal's log posterior: :func:`_score` with the better
    gain per category and the SaLe factor at most 1; ``hist`` is not written. It depends on no
    unit's type, geometry class or adjacency (``adj`` is only read, and no pair passes the SaLe
    threshold), so it is taken before :func:`_retype_changed` derives them: a proposal below its
    floor never pays for them (on a tiled lattice, the pairs of two tiles)."""
    loglik, logprior, _g = _score(xsum, gain_max, old_rects, old_active, old_types, new_rects,
                                  new_active, old_types, hist.copy(), gamma_total, adj, no_sale,
                                  never_sale, True, prior_n, ip, fp, aff)
    return 0 + loglik + logprior


def below_floor(bound: float, floor: float) -> bool:
    """Whether an upper bound ``bound`` of a proposal's log posterior shows it below ``floor``
    (a relative slack of 1e-9 for rounding; a bound of ``-inf``, an invalid world, always is).
    The tracker's skips and the ascent's early stop (:meth:`Climb.best_proposal
    <semmap_pp.sampler.ascent_walls.Climb.best_proposal>`) use this one test."""
    return bound == -math.inf or bound + 1e-9 * abs(bound) < floor


def _ro(a):
    """``a`` as a read-only array (a view when it is writable). The compiled calls get every
    input read-only, whatever made it: one signature each, not one per mix of writable and
    read-only arguments (each of which a new process loads or compiles, ~0.1 s each)."""
    if a.flags.writeable:
        a = a.view()
        a.setflags(write=False)
    return a


def _score_ro(xsum, gain, old_rects, old_active, old_types, new_rects, new_active, new_types,
              hist, gamma_total, adj, sale, table, use_table, prior_n, ip, fp, aff):
    """:func:`_score` with read-only inputs (see :func:`_ro`); ``hist`` is written."""
    return _score(xsum, _ro(gain), _ro(old_rects), _ro(old_active), _ro(old_types),
                  _ro(new_rects), _ro(new_active), _ro(new_types), hist, gamma_total, _ro(adj),
                  _ro(sale), _ro(table), use_table, _ro(prior_n), ip, fp, aff)


class ScoredProposal:
    """A proposed world with its log posterior (the tracker's, not a kernel's
    :class:`semmap_pp.sampler.kernels.Proposal`); pass it to :meth:`Tracker.accept` to commit.

    Attributes: ``world`` (types assigned), ``logp``, ``loglik``, ``logprior``, ``typing``
    (its :class:`_Typing`) and ``patch`` (the likelihood tallies).
    """

    __slots__ = ("world", "logp", "loglik", "logprior", "typing", "patch", "bounded")

    def __init__(self, world, logp, loglik, logprior, typing, patch, bounded=False):
        self.world, self.logp, self.loglik, self.logprior = world, logp, loglik, logprior
        self.typing, self.patch, self.bounded = typing, patch, bounded


_NO_TYPES = np.zeros(0, np.int8)   # written by _retype_changed only with fixed types
_NO_SALE = _ro(np.zeros((1, 1)))
# P(SaLe) of every pair below any threshold: the SaLe factor's upper bound 1 (log 0)
_NEVER_SALE = _ro(np.full((len(UNIT_TYPES), len(UNIT_TYPES)), -np.inf))


class Tracker(KnowledgeTracking):
    """Incremental log posterior of one chain (the one stateful object; see architecture.md).

    A proposal re-derives the geometry class and adjacency row of the changed slots only, the
    types of every unit from the provider (with the fixed provider only the changed slots can
    change type; with knowledge the current evidence is edited at the changed slots and at the
    slots whose MulDoor or corridor-piece flag changed, from per-size and per-pair caches, and
    the provider is asked only when it differs from the current world's), the likelihood tallies
    from the units whose rectangle, presence or corridor flag changed, and the prior's validity
    and SaLe sum over the slots (compiled).
    """

    #: ``propose`` takes ``floor`` (see :func:`semmap_pp.sampler.mcmc.mh_green`).
    supports_floor = True

    def __init__(self, post: Posterior, world: wm.World):
        self.post = post
        self._provider = post.provider
        self._typ = post.typing(world)
        w = self._typ.world
        slots = wm.active_slots(w)
        self.hist, self.gamma_total = full_tallies(post.data, w.rects[slots],
                                                   w.types[slots] == CORRIDOR)
        self.loglik = loglik_from_tallies(post.data, self.hist, self.gamma_total) + \
            post.enclosure(w)
        self.logprior = post._logprior(self._typ)
        self.logp = self.loglik + self.logprior
        self._prior_n = post.prior_n(w.capacity)
        self._fixed = isinstance(self._provider, FixedProvider)
        self._openings = self._evidence = None
        #: proposals skipped below their floor: by the type-free bound, by the MAP-types bound
        self.skipped = [0, 0]
        if not self._fixed:
            self._start_knowledge(post, w)

    @property
    def world(self) -> wm.World:
        return self._typ.world

    def coverage(self, hist=None) -> float:
        """Fraction of the input-free lattice cells covered by some unit."""
        hist = self.hist if hist is None else hist
        return covered_free(hist) / max(self.post.data.n_free, 1)

    def propose(self, new_world: wm.World, changed_slots, floor: float | None = None,
                bound: float | None = None) -> ScoredProposal:
        """Evaluate ``new_world`` (which differs from :attr:`world` only in ``changed_slots``).

        Types of *every* unit are re-derived (evidence of a neighbour may change with the edit);
        units whose type changed are recomputed in the likelihood along with the edited ones.

        ``floor`` (optional): the caller will reject the proposal unless its log posterior
        reaches ``floor`` (MH with the uniform drawn first: ``floor = log π(W) + T (log u -
        log_ratio)``). With knowledge on, when an upper bound of ``log π(W')`` over every
        possible typing is already below ``floor``, the provider is not asked and the proposal
        comes back with ``logp = -inf`` (``bounded`` set; never accept it). ``bound``: that bound,
        when the caller has it from :meth:`upper_bound` of the same current world.
        """
        post = self.post
        if post.provider is not self._provider:   # knowledge switched without a resync
            self.resync()
        old = self._typ
        ow = old.world
        changed = np.array(changed_slots, dtype=np.int64)
        data = post.data
        # a tiled lattice: the relations of pairs of two tiles (None, compiled away, otherwise)
        tiled = old.cross is not None
        xd = post.cross if tiled else None
        touched = np.zeros(ow.capacity, np.bool_) if tiled else None
        aff = xd.aff if tiled else None
        if floor is not None and self._below_floor(new_world, changed, floor, old.cross, touched, aff,
                                                   bound):
            return self._bounded(new_world)      # (the bound only reads the current arrays)
        geometry = old.geometry.copy()
        adj = old.adj.copy()
        hist = self.hist.copy()
        xo = cross = old.cross.copy() if tiled else None
        if self._fixed:
            types = ow.types.copy()
            loglik, logprior, gamma_total = _propose_fixed(
                data.xsum, _ro(data.gain), _ro(ow.rects), _ro(ow.active), _ro(ow.types),
                _ro(new_world.rects), _ro(new_world.active), changed, geometry, adj, types,
                GEOMETRY_TYPE, hist, self.gamma_total, _ro(post.fixed.fixed_sale),
                _ro(self._prior_n), post._ip, post._fp, xo, touched, xd)
            types.setflags(write=False)
            knowledge = sale = None
        else:
            _retype_changed(_ro(ow.rects), _ro(ow.active), _ro(new_world.rects),
                            _ro(new_world.active), changed, geometry, adj, _NO_TYPES,
                            _NO_TYPES, post._ip, post._fp, xo, touched, xd)
            types, sale, knowledge = self._knowledge_types(new_world, adj, geometry, changed,
                                                           map_only=floor is not None,
                                                           cross=cross, touched=touched)
            if sale is None:
                # bound 2, the MAP types alone (no marginals yet): the exact log-likelihood and
                # the prior with the SaLe factor at most 1
                bound = sum(_score_ro(
                    data.xsum, data.gain, ow.rects, ow.active, ow.types, new_world.rects,
                    new_world.active, types, hist.copy(), self.gamma_total, adj, _NO_SALE,
                    _NEVER_SALE, True, self._prior_n, post._ip, post._fp, aff)[:2])
                if below_floor(bound, floor):
                    self.skipped[1] += 1
                    return self._bounded(new_world)
                types, sale = post._result_arrays(self._provider, knowledge[1], new_world.capacity)
            loglik, logprior, gamma_total = _score_ro(
                data.xsum, data.gain, ow.rects, ow.active, ow.types, new_world.rects,
                new_world.active, types, hist, self.gamma_total, adj, sale,
                post.fixed.fixed_sale, False, self._prior_n, post._ip, post._fp, aff)
        new = wm.World(new_world.rects, new_world.active, types)
        return ScoredProposal(new, loglik + logprior, loglik, logprior,
                        _Typing(new, geometry, adj, sale, cross), (hist, gamma_total, knowledge))

    def _below_floor(self, new_world, changed, floor, xo, touched, aff, bound=None) -> bool:
        """Whether :meth:`upper_bound` of ``new_world`` (``bound`` when given) lies below
        ``floor`` (counted in :attr:`skipped`: the type-free bound with knowledge, else the fixed
        provider's)."""
        if bound is None:
            bound = self._bound(new_world, changed, xo, touched, aff)
        if below_floor(bound, floor):
            self.skipped[1 if self._fixed else 0] += 1
            return True
        return False

    def upper_bound(self, new_world: wm.World, changed_slots) -> float:
        """An upper bound of :meth:`propose`'s log posterior of ``new_world`` (which differs from
        :attr:`world` only in ``changed_slots``), taken before its changed slots are retyped and
        its pairs of two tiles computed; ``inf`` when there is none (the fixed provider on a
        lattice of one direction). :meth:`propose` with a ``floor`` above it would skip the
        proposal; a caller choosing the best of many proposals tries them in the order of this
        bound (:meth:`semmap_pp.sampler.ascent_walls.Climb.best_proposal`)."""
        if self.post.provider is not self._provider:   # knowledge switched without a resync
            self.resync()
        old = self._typ
        tiled = old.cross is not None
        changed = np.array(changed_slots, dtype=np.int64)
        return self._bound(new_world, changed, old.cross if tiled else None,
                           np.zeros(old.world.capacity, np.bool_) if tiled else None,
                           self.post.cross.aff if tiled else None)

    def _bound(self, new_world, changed, xo, touched, aff) -> float:
        """With knowledge the type-free bound (bound 1); with the fixed provider on a tiled
        lattice the proposal's score without the pairs of two tiles, which cost several times the
        score (the fixed types and the likelihood are exact without them, and each pair's SaLe
        factor is at most 1); on one lattice no bound (``inf``: it would only add a score). ``xo``
        and ``touched`` are only read."""
        post, old = self.post, self._typ
        ow, data = old.world, post.data
        if not self._fixed:
            return float(_type_free_bound(
                data.xsum, post._gain_max, _ro(ow.rects), _ro(ow.active), _ro(ow.types),
                _ro(new_world.rects), _ro(new_world.active), _ro(old.adj), _ro(self.hist),
                self.gamma_total, _NO_SALE, _NEVER_SALE, self._prior_n, post._ip, post._fp, aff))
        if aff is not None:      # a tiled lattice (``aff``: its tiles' rotations)
            return float(_fixed_bound(
                data.xsum, _ro(data.gain), _ro(ow.rects), _ro(ow.active), _ro(ow.types),
                _ro(new_world.rects), _ro(new_world.active), changed, _ro(old.geometry),
                _ro(old.adj), _ro(ow.types), GEOMETRY_TYPE, _ro(self.hist), self.gamma_total,
                _ro(post.fixed.fixed_sale), _ro(self._prior_n), post._ip, post._fp, xo, touched,
                aff))
        return math.inf

    @staticmethod
    def _bounded(world) -> ScoredProposal:
        return ScoredProposal(world, -math.inf, -math.inf, -math.inf, None, None, bounded=True)

    def resync(self) -> None:
        """Rebuild every cache from the current geometry (call after switching
        :attr:`Posterior.knowledge_on`: the provider, hence the types, changed)."""
        self.__init__(self.post, self.world)

    def loglik_under(self, post: Posterior) -> float:
        """The log-likelihood of the current world under ``post``, a tempered copy of this
        tracker's target (:mod:`semmap_pp.target.tempering`: the same lattice, types and prior,
        the likelihood raised to another power), from the tracker's tallies."""
        return loglik_from_tallies(post.data, self.hist, self.gamma_total) + post.enclosure(self.world)

    def retarget(self, post: Posterior) -> None:
        """Make ``post`` (a tempered copy of this tracker's target) the tracker's target, keeping
        the world, its types and every cache but the likelihood's float (a replica exchange)."""
        self.post = post
        self.loglik = self.loglik_under(post)
        self.logp = self.loglik + self.logprior

    def accept(self, prop: ScoredProposal) -> None:
        """Commit a proposal (a rejected one is simply dropped)."""
        if prop.bounded:
            raise ValueError("a proposal bounded below its floor cannot be accepted")
        self.hist, self.gamma_total, knowledge = prop.patch
        self._typ = prop.typing
        if knowledge is not None:
            self._openings, self._evidence, self._many, self._pieces = knowledge
        self.loglik, self.logprior, self.logp = prop.loglik, prop.logprior, prop.logp
