"""The knowledge engine: evidence in, type and SaLe marginals and MAP types out, cached.

Examples
--------
>>> from semmap_pp.knowledge import KnowledgeEngine, Evidence
>>> engine = KnowledgeEngine.from_file("rules/table3.lp")
>>> r = engine.infer(Evidence.build([1, 2], rolike={1, 2}, adj=[(1, 2)]))
>>> r.map_types
{1: 'room', 2: 'room'}
>>> round(r.sale[(1, 2)], 2)
0.67
"""

from __future__ import annotations

import hashlib
import os
from collections import OrderedDict
from dataclasses import dataclass

import numpy as np

from semmap_pp.cells import UNIT_TYPES
from semmap_pp.errors import RuleError
from semmap_pp.knowledge.dialect import RuleSet, load_rules
from semmap_pp.knowledge.evidence import Evidence
from semmap_pp.knowledge.exact import (MAX_CLIQUE_STATES, JunctionTree, TooDense, calibrate,
                                       calibrate_flat, decode_max, merged_potentials, sum_out)
from semmap_pp.knowledge.ground import ground
from semmap_pp.knowledge.lbp import BPSettings, factor_bp, pairwise_bp
from semmap_pp.knowledge.local import (LocalModel, default_store, is_pairwise, map_net,
                                       map_net_update)
from semmap_pp.knowledge.map import map_clingo, map_pairwise_rc2, map_rc2, map_tables_rc2
from semmap_pp.knowledge.mcsat import mcsat_marginals
from semmap_pp.knowledge.mcsat_local import LocalClauses, mcsat_local

METHODS = ("auto", "exact", "lbp", "mcsat")
MAP_METHODS = ("jt", "clingo", "rc2")
#: ``method="auto"`` runs the junction tree when its largest clique has at most this many joint
#: states, loopy BP otherwise (docs/benchmarks.md, "Knowledge engine", for the measurement).
AUTO_MAX_STATES = 1 << 10
#: The same bound for a rule set's ground network (the general path, rules that are not
#: pairwise-local): there loopy BP runs over general factors in Python and the junction tree is
#: faster up to cliques of this size (docs/benchmarks.md, "Knowledge engine": 86 against 267 ms
#: at 2^18 states under rules/halls_to_corridors.lp).
AUTO_MAX_STATES_GROUND = 1 << 18


@dataclass(frozen=True)
class InferenceResult:
    """Marginals and MAP of one evidence.

    Attributes
    ----------
    types : dict int -> ndarray (4,)
        Type marginals per unit, in ``cells.UNIT_TYPES`` order (room, corridor, hall, other).
    sale : dict (p, q) -> float
        ``P(sale(p,q))`` for each adjacent pair, ``p < q``.
    map_types : dict int -> str
        The most probable types (a ``cells.UNIT_TYPES`` name per unit), maximised jointly with
        SaLe, the soft evidence atoms summed out.
    map_cost : float
        ``-log`` of the MAP's unnormalised weight (MLN units): without soft evidence the weight
        of the soft rules the MAP world violates; with it, summed over the soft atoms' states,
        so it can be negative.
    log_z : float or None
        Log partition function over types and SaLe (exact marginals only).
    method : str
        How the marginals were computed: ``"exact"``, ``"lbp"`` or ``"mcsat"``.
    map_method : str
        How the MAP was found: ``"jt"`` (max-product on a junction tree, or per unit when
        no pair couples the MAP), ``"rc2"`` or ``"clingo"``; all exact. ``"jt+max"`` /
        ``"rc2+max"``: a soft atom tied to too many units was maximised, not summed out.
    """

    types: dict
    sale: dict
    map_types: dict
    map_cost: float
    log_z: float | None
    method: str
    map_method: str = "jt"


class KnowledgeEngine:
    """Inference over one rule set, cached by evidence.

    Parameters
    ----------
    rules : RuleSet
    method : {"auto", "exact", "lbp", "mcsat"}
        Marginals by junction tree (exact), loopy belief propagation
        (:mod:`~semmap_pp.knowledge.lbp`), MC-SAT sampling, or ``auto``: exact when the
        junction tree's largest clique has at most ``auto_max_states`` joint states, else LBP.
        The MAP stays exact: when its own junction tree is too large (``auto``/``lbp``: above
        ``auto_max_states``) RC2 solves it.
    map_method : {"jt", "clingo", "rc2"}
        MAP by max-product on the junction tree, clingo optimisation, or RC2 MaxSAT. The MAP
        maximises the types and SaLe with the soft evidence atoms summed out (``_map_ground``);
        clingo, which optimises whole worlds, refuses evidence with soft atoms.
    n_chains, n_iter, burn_in : int
        MC-SAT settings (see :func:`~semmap_pp.knowledge.mcsat.mcsat_marginals`).
    cache_size : int
        Results kept (least recently used are dropped).
    seed : int
        Mixed with a hash of the rules and the evidence: MC-SAT results are a deterministic
        function of (rules, evidence, settings).
    auto_max_states : int
        Largest clique ``auto`` hands to the junction tree.
    auto_max_states_ground : int
        The same for a ground network (rules that are not pairwise-local), where loopy BP is
        slower and the tree pays up to larger cliques.
    bp : BPSettings
        Damping, iteration cap and tolerance of loopy BP.
    fast : bool
        Use cached unit/pair templates (:mod:`~semmap_pp.knowledge.local`, and for MC-SAT
        :mod:`~semmap_pp.knowledge.mcsat_local`) when the rule set is pairwise-local and the MAP
        method is the junction tree.
    template_store : bool or path
        Where the fast path keeps its grounded templates between processes: ``True`` the
        default directory (:func:`~semmap_pp.knowledge.local.default_store`, which the
        ``SEMMAP_TEMPLATE_CACHE`` variable sets or turns off), a directory, or ``False`` for
        none (every process grounds its own).
    """

    def __init__(self, rules: RuleSet, method: str = "auto", map_method: str = "jt",
                 n_chains: int = 768, n_iter: int = 38, burn_in: int = 12,
                 cache_size: int = 4096, seed: int = 0, fast: bool = True,
                 auto_max_states: int = AUTO_MAX_STATES, bp: BPSettings = BPSettings(),
                 template_store=True, auto_max_states_ground: int = AUTO_MAX_STATES_GROUND):
        if method not in METHODS:
            raise RuleError(rules.path, f"unknown inference method {method!r}; use one of {METHODS}")
        if map_method not in MAP_METHODS:
            raise RuleError(rules.path, f"unknown MAP method {map_method!r}; use one of "
                            f"{MAP_METHODS}")
        self.rules, self.method, self.map_method = rules, method, map_method
        self.mcsat_settings = (int(n_chains), int(n_iter), int(burn_in))
        self.cache_size, self.seed = int(cache_size), int(seed)
        self.auto_max_states, self.bp = int(auto_max_states), bp
        self.auto_max_states_ground = int(auto_max_states_ground)
        self._cache: OrderedDict = OrderedDict()
        store = (default_store() if template_store is True
                 else (template_store or None))
        self.local = (LocalModel(rules, store=store)
                      if fast and map_method == "jt" and is_pairwise(rules) else None)
        self.local_clauses = (LocalClauses(rules) if self.local is not None and method == "mcsat"
                              else None)
        self.hits = self.misses = 0
        self._map_cache: OrderedDict = OrderedDict()   # evidence key -> (type network, MAP)
        self._map_nets: OrderedDict = OrderedDict()    # evidence key -> MapNet, None: general path
        self._trees: OrderedDict = OrderedDict()       # (card, scopes) -> JunctionTree or None
        self._ground_maps: OrderedDict = OrderedDict()  # evidence key -> ground network and MAP
        self._groundings: OrderedDict = OrderedDict()   # evidence structure -> its network

    @classmethod
    def from_file(cls, path: str | os.PathLike, method: str = "auto", **settings
                  ) -> "KnowledgeEngine":
        """Load and validate ``path`` and build an engine over it."""
        return cls(load_rules(path), method=method, **settings)

    def infer(self, evidence: Evidence) -> InferenceResult:
        """Marginals and MAP types for ``evidence`` (cached)."""
        key = evidence.key
        hit = self._cache.get(key)
        if hit is not None:
            self._cache.move_to_end(key)
            self.hits += 1
            return hit
        self.misses += 1
        result = self._compute(evidence)
        self._cache[key] = result
        if len(self._cache) > self.cache_size:
            self._cache.popitem(last=False)
        return result

    #: :meth:`map_types` takes ``base=`` (an evidence to update the MAP from)
    updates_map = True

    @property
    def has_map_only(self) -> bool:
        """Whether :meth:`map_types` can find the MAP types without the marginals: the fast
        path with exact or ``auto`` marginals, and the general path (a ground network's MAP is
        decoded before its marginals, which :meth:`infer` then adds to the same grounding)."""
        return self.local is None or self.local_clauses is None

    def map_types(self, evidence: Evidence, base: Evidence | None = None) -> dict:
        """``infer(evidence).map_types`` without computing the marginals when they are not
        cached: the same type network and the same MAP decoding as :meth:`infer` (which then
        reuses them), so the types are identical. Needs :attr:`has_map_only`.

        ``base`` (optional): an evidence close to this one (the sampler's current world). When no
        pair of the network couples its units, the MAP side is updated from ``base``'s
        (:func:`~semmap_pp.knowledge.local.map_net_update`: the units whose evidence or cut
        differs and their neighbours), not rebuilt over every unit; the types are the same."""
        hit = self._cache.get(evidence.key)
        if hit is not None:
            return hit.map_types
        if self.local is None:
            g, _pots, _jt, x, _cost, _method = self._ground_map(evidence)
            return {u: UNIT_TYPES[int(x[i])] for i, u in enumerate(g.network.units)}
        if base is not None:
            net = self._map_net(evidence, base)
            if net is not None:
                return net.map_types()
        tn, x, _best, _method = self._local_map(evidence)
        return {u: UNIT_TYPES[int(x[i]) >> tn.shift[i]] for i, u in enumerate(evidence.units)}

    def _map_net(self, ev: Evidence, base: Evidence):
        """The :class:`~semmap_pp.knowledge.local.MapNet` of ``ev``, updated from ``base``'s
        (built first when not cached); None when a pair of either couples its units: the
        general path (small LRU)."""
        nets = self._map_nets
        hit = nets.get(ev.key, False)
        if hit is not False:
            nets.move_to_end(ev.key)
            return hit
        path = self.rules.path
        prev = nets.get(base.key, False)
        if prev is False:
            prev = nets[base.key] = map_net(self.local, base, path)
        net = None if prev is None else map_net_update(self.local, prev, ev, path)
        nets[ev.key] = net
        while len(nets) > 256:
            nets.popitem(last=False)
        return net

    def _local_map(self, ev: Evidence):
        """Type network and exact MAP of ``ev`` (cached by evidence, small LRU)."""
        hit = self._map_cache.get(ev.key)
        if hit is not None:
            self._map_cache.move_to_end(ev.key)
            return hit
        tn = self.local.type_network(ev)
        if any(tn.shift):
            # a pair rule reads some unit's soft evidence atoms, so they stay in its variable;
            # summing them out couples the pair: the ground network's MAP does it exactly
            g = ground(self.rules, ev, cache=self._groundings)
            xg, cost, map_method = self._map_ground(g, merged_potentials(g.network), None)
            x = np.array([int(xg[i]) << tn.shift[i] for i in range(len(ev.units))], dtype=np.int64)
            best = -cost
        else:
            x, best, map_method = self._map_local(tn, self.rules.path)
        hit = self._map_cache[ev.key] = (tn, x, best, map_method)
        if len(self._map_cache) > 256:
            self._map_cache.popitem(last=False)
        return hit

    def signature_seed(self, evidence: Evidence) -> int:
        """The MC-SAT seed: a hash of (rules, evidence, settings, seed)."""
        text = repr((self.rules.digest, evidence.key, self.mcsat_settings, self.seed))
        return int.from_bytes(hashlib.blake2b(text.encode(), digest_size=8).digest(), "little")

    def _limit(self, grounded: bool = False) -> int:
        """Largest clique the junction tree may have for the marginals and the MAP
        (``grounded``: of a ground network, where ``auto`` allows :data:`AUTO_MAX_STATES_GROUND`)."""
        if self.method in ("exact", "mcsat"):
            return MAX_CLIQUE_STATES
        if grounded and self.method == "auto":
            return self.auto_max_states_ground
        return self.auto_max_states

    def _tree(self, card, scopes, path, grounded: bool = False):
        """A junction tree within :meth:`_limit`, or None when ``auto``/``lbp`` must fall back
        (cached by cardinalities, scopes and the limit: a tree is a pure function of them, and
        the sampler's networks keep their structure across most evidence changes)."""
        limit = self._limit(grounded)
        key = (tuple(int(c) for c in card), tuple(scopes), limit)
        hit = self._trees.get(key, False)
        if hit is not False:
            self._trees.move_to_end(key)
            return hit
        try:
            jt = JunctionTree(card, scopes, path, max_states=limit)
        except TooDense:
            if self.method in ("exact", "mcsat"):
                raise
            jt = None
        self._trees[key] = jt
        if len(self._trees) > 256:
            self._trees.popitem(last=False)
        return jt

    def _ground_map(self, ev: Evidence):
        """The ground network of ``ev``, its merged potentials, junction tree (None: too large
        or not wanted) and exact MAP ``(g, pots, jt, x, cost, map_method)``, cached by evidence
        (small LRU) until :meth:`infer` adds the marginals: :meth:`map_types` of the general
        path grounds and decodes once for both."""
        hit = self._ground_maps.get(ev.key)
        if hit is not None:
            self._ground_maps.move_to_end(ev.key)
            return hit
        g = ground(self.rules, ev, keep_control=self.map_method == "clingo",
                   cache=self._groundings)
        net = g.network
        pots = merged_potentials(net)
        scopes = [s for s, _ in pots]
        jt = None if self.method == "lbp" and self.map_method != "jt" else \
            self._tree(net.card, scopes, net.path, grounded=True)
        # MAP first: it is exact and raises when the hard rules admit no world
        x, cost, map_method = self._map_ground(g, pots, jt)
        hit = self._ground_maps[ev.key] = (g, pots, jt, x, cost, map_method)
        if len(self._ground_maps) > 64:
            self._ground_maps.popitem(last=False)
        return hit

    def _compute(self, ev: Evidence) -> InferenceResult:
        if self.local is not None:
            if self.local_clauses is not None:
                return self._compute_local_mcsat(ev)
            return self._compute_local(ev)
        g, pots, jt, x, cost, map_method = self._ground_map(ev)
        self._ground_maps.pop(ev.key, None)   # the full result is cached from now on
        net = g.network
        log_z, method = None, self.method
        if self.method == "mcsat":
            rng = np.random.default_rng(self.signature_seed(ev))
            n_chains, n_iter, burn_in = self.mcsat_settings
            marg = mcsat_marginals(net, rng, n_chains, n_iter, burn_in, jt=None)
        elif jt is not None and self.method != "lbp":
            log_z, marg = calibrate(jt, pots)
            if marg is None:
                raise RuleError(net.path, "the hard rules admit no world for this evidence")
            log_z -= net.offset / 1000.0
            method = "exact"
        else:
            marg = factor_bp(net.card, pots, self.bp).marginals
            method = "lbp"
        types, map_types = {}, {}
        for i, u in enumerate(net.units):
            p = np.asarray(marg[i], dtype=np.float64)
            p.setflags(write=False)
            types[u] = p
            map_types[u] = UNIT_TYPES[int(x[i])]
        sale = {}
        for p_, q_ in ev.adj:
            v = net.sale.get((p_, q_))
            sale[(p_, q_)] = float(marg[v][1]) if v is not None else 0.0
        return InferenceResult(types, sale, map_types, float(cost), log_z, method, map_method)

    def _map_ground(self, g, pots, jt):
        """MAP of a ground network ``g.network`` with log potentials ``pots`` (merged) and its
        junction tree ``jt`` (None: too large): ``(assignment, cost in MLN units, method)``.

        The MAP maximises the query atoms (types, SaLe) with the soft evidence atoms summed out
        (:func:`~semmap_pp.knowledge.exact.sum_out`): the most probable types given uncertain
        evidence. Maximising the evidence atoms as well would let a unit with soft geometry
        take *no* geometry class, which no rule reads, and get a type by tie-breaking. clingo
        optimises the ground program, so it maximises them: it is refused with soft evidence.
        A soft atom whose factors would join into a table above the junction tree's limit (a
        rule tying it to many units) is maximised with the types; the method then ends in
        ``+max``.
        """
        net = g.network
        path = net.path
        other = set(net.sale.values()) | set(net.aux)
        soft = [v for v in range(len(net.units), net.n_vars) if v not in other]
        if self.map_method == "clingo":
            if soft:
                raise RuleError(path, "MAP by clingo maximises the soft evidence atoms instead "
                                      "of summing them out; with soft evidence use the MAP method "
                                      "'jt' or 'rc2'")
            x, cost = map_clingo(g)
            return x, cost / 1000.0, "clingo"
        if not soft:
            if self.map_method == "jt" and jt is not None:
                x, best = decode_max(jt, pots)
                if not np.isfinite(best):
                    raise RuleError(path, "the hard rules admit no world for this evidence")
                return x, net.cost(x) / 1000.0, "jt"
            x, cost = map_rc2(net)
            return x, cost / 1000.0, "rc2"
        mpots, const, kept = sum_out(net.card, pots, soft)
        tree = (self._tree(net.card, [s for s, _ in mpots], path, grounded=True)
                if self.map_method == "jt" else None)
        if tree is not None:
            x, best = decode_max(tree, mpots)
            method = "jt"
        else:
            x, best = map_tables_rc2(net.card, mpots, path)
            method = "rc2"
        if not np.isfinite(best):
            raise RuleError(path, "the hard rules admit no world for this evidence")
        # a soft atom tied to too many units to sum out exactly is maximised with the types
        return x, -(best + const) + net.offset / 1000.0, method + ("+max" if kept else "")

    def _compute_local_mcsat(self, ev: Evidence) -> InferenceResult:
        card, sum_pots = self.local.reduced(ev)
        tn, x, best, map_method = self._local_map(ev)
        jt = JunctionTree(card, [s for s, _ in sum_pots], self.rules.path)
        rng = np.random.default_rng(self.signature_seed(ev))
        types, sale = mcsat_local(self.local_clauses, ev, rng, *self.mcsat_settings, jt=jt)
        map_types = {u: UNIT_TYPES[int(x[i]) >> tn.shift[i]] for i, u in enumerate(ev.units)}
        return InferenceResult(types, sale, map_types, -float(best) + 0.0, None, self.method,
                               map_method)

    def _map_local(self, tn, path):
        """Exact MAP of a type network: per unit, junction tree, or RC2 when the tree is large."""
        n = len(tn.units)
        if not tn.max_pairs:
            if any(not np.isfinite(t).any() for t in tn.unary_max):
                raise RuleError(path, "the hard rules admit no world for this evidence")
            x = np.array([int(np.argmax(t)) for t in tn.unary_max], dtype=np.int64)
            return x, float(sum(t[k] for t, k in zip(tn.unary_max, x))), "jt"
        pots = [((i,), t) for i, t in enumerate(tn.unary_max)]
        pots += [((i, j), t) for i, j, t in tn.max_pairs]
        jt = self._tree(tn.card, [s for s, _ in pots], path)
        if jt is None:
            x, best = map_pairwise_rc2(tn.unary_max, tn.max_pairs, path)
            return x, best, "rc2"
        x, best = decode_max(jt, pots)
        if not np.isfinite(best) or len(x) != n:
            raise RuleError(path, "the hard rules admit no world for this evidence")
        return x, float(best), "jt"

    def _compute_local(self, ev: Evidence) -> InferenceResult:
        path = self.rules.path
        tn, x, best, map_method = self._local_map(ev)
        self._map_cache.pop(ev.key, None)   # the full result is cached from now on
        pots = [((i,), t) for i, t in enumerate(tn.unary_sum)]
        pots += [((i, j), t) for i, j, t in tn.sum_pairs]
        jt = None if self.method == "lbp" else self._tree(tn.card, [s for s, _ in pots], path)
        sale = {}
        if jt is not None:
            # compiled calibration and pair marginals (exact.calibrate_flat; equal to
            # exact.calibrate + scope_marginal within rounding, tests/test_knowledge_exact.py)
            scopes = [s for s, _ in pots]
            n1 = len(tn.unary_sum)
            where = {(i, j): n1 + k for k, (i, j, _t) in enumerate(tn.sum_pairs)}
            conds = [(pq, c) for pq, c in tn.sale.items() if not isinstance(c, float)]
            log_z, marg, joint = calibrate_flat(jt.plan(scopes), [t for _, t in pots],
                                                [where[(c[0], c[1])] for _, c in conds])
            if marg is None:
                raise RuleError(path, "the hard rules admit no world for this evidence")
            method = "exact"
            given = {pq: float(np.dot(pm.reshape(-1), c[2].reshape(-1)))
                     for (pq, c), pm in zip(conds, joint)}
            for pq, c in tn.sale.items():
                sale[pq] = c if isinstance(c, float) else given[pq]
        else:
            where = {(i, j): k for k, (i, j, _t) in enumerate(tn.sum_pairs)}
            want = [where[(c[0], c[1])] for c in tn.sale.values() if not isinstance(c, float)]
            bp = pairwise_bp(tn.unary_sum, tn.sum_pairs, want, self.bp)
            marg, log_z, method = bp.marginals, None, "lbp"
            for pq, c in tn.sale.items():
                if isinstance(c, float):
                    sale[pq] = c
                else:
                    i, j, cond = c
                    sale[pq] = float(np.sum(bp.pair_beliefs[where[(i, j)]] * cond))
        types, map_types = {}, {}
        for i, u in enumerate(ev.units):
            p = np.asarray(marg[i], dtype=np.float64)
            if tn.shift[i]:
                p = p.reshape(4, 1 << tn.shift[i]).sum(axis=1)
            p.setflags(write=False)
            types[u] = p
            map_types[u] = UNIT_TYPES[int(x[i]) >> tn.shift[i]]
        return InferenceResult(types, sale, map_types, -float(best) + 0.0, log_z, method,
                               map_method)
