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
from semmap_pp.knowledge.exact import (JunctionTree, calibrate, decode_max, merged_potentials,
                                       scope_marginal)
from semmap_pp.knowledge.ground import ground
from semmap_pp.knowledge.local import LocalModel, is_pairwise
from semmap_pp.knowledge.map import map_clingo, map_rc2
from semmap_pp.knowledge.mcsat import mcsat_marginals
from semmap_pp.knowledge.mcsat_local import LocalClauses, mcsat_local

METHODS = ("exact", "mcsat")
MAP_METHODS = ("jt", "clingo", "rc2")


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
        Types of the most probable world (a ``cells.UNIT_TYPES`` name per unit).
    map_cost : float
        Weight of the soft rules the MAP world violates (MLN units, i.e. thousandths / 1000).
    log_z : float or None
        Log partition function over types and SaLe (exact method only).
    method : str
    """

    types: dict
    sale: dict
    map_types: dict
    map_cost: float
    log_z: float | None
    method: str


class KnowledgeEngine:
    """Inference over one rule set, cached by evidence.

    Parameters
    ----------
    rules : RuleSet
    method : {"exact", "mcsat"}
        Marginals by junction tree (exact) or by MC-SAT sampling.
    map_method : {"jt", "clingo", "rc2"}
        MAP by max-product on the junction tree, clingo optimisation, or RC2 MaxSAT.
    n_chains, n_iter, burn_in : int
        MC-SAT settings (see :func:`~semmap_pp.knowledge.mcsat.mcsat_marginals`).
    cache_size : int
        Results kept (least recently used are dropped).
    seed : int
        Mixed with a hash of the rules and the evidence: MC-SAT results are a deterministic
        function of (rules, evidence, settings).
    fast : bool
        Use cached unit/pair templates (:mod:`~semmap_pp.knowledge.local`, and for MC-SAT
        :mod:`~semmap_pp.knowledge.mcsat_local`) when the rule set is pairwise-local and the MAP
        method is the junction tree.
    """

    def __init__(self, rules: RuleSet, method: str = "exact", map_method: str = "jt",
                 n_chains: int = 768, n_iter: int = 38, burn_in: int = 12,
                 cache_size: int = 4096, seed: int = 0, fast: bool = True):
        if method not in METHODS:
            raise RuleError(rules.path, f"unknown inference method {method!r}; use one of {METHODS}")
        if map_method not in MAP_METHODS:
            raise RuleError(rules.path, f"unknown MAP method {map_method!r}; use one of "
                            f"{MAP_METHODS}")
        self.rules, self.method, self.map_method = rules, method, map_method
        self.mcsat_settings = (int(n_chains), int(n_iter), int(burn_in))
        self.cache_size, self.seed = int(cache_size), int(seed)
        self._cache: OrderedDict = OrderedDict()
        self.local = (LocalModel(rules) if fast and map_method == "jt" and is_pairwise(rules)
                      else None)
        self.local_clauses = (LocalClauses(rules) if self.local is not None and method == "mcsat"
                              else None)
        self.hits = self.misses = 0

    @classmethod
    def from_file(cls, path: str | os.PathLike, method: str = "exact", **settings
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

    def signature_seed(self, evidence: Evidence) -> int:
        """The MC-SAT seed: a hash of (rules, evidence, settings, seed)."""
        text = repr((self.rules.digest, evidence.key, self.mcsat_settings, self.seed))
        return int.from_bytes(hashlib.blake2b(text.encode(), digest_size=8).digest(), "little")

    def _compute(self, ev: Evidence) -> InferenceResult:
        if self.local is not None:
            return self._compute_local(ev)
        g = ground(self.rules, ev, keep_control=self.map_method == "clingo")
        net = g.network
        pots = merged_potentials(net)
        jt = JunctionTree(net.card, [s for s, _ in pots], net.path)
        log_z = None
        if self.method == "exact":
            log_z, marg = calibrate(jt, pots)
            if marg is None:
                raise RuleError(net.path, "the hard rules admit no world for this evidence")
            log_z -= net.offset / 1000.0
        else:
            rng = np.random.default_rng(self.signature_seed(ev))
            n_chains, n_iter, burn_in = self.mcsat_settings
            marg = mcsat_marginals(net, rng, n_chains, n_iter, burn_in, jt=None)
        if self.map_method == "jt":
            x, best = decode_max(jt, pots)
            if not np.isfinite(best):
                raise RuleError(net.path, "the hard rules admit no world for this evidence")
            cost = net.cost(x)
        elif self.map_method == "clingo":
            x, cost = map_clingo(g)
        else:
            x, cost = map_rc2(net)
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
        return InferenceResult(types, sale, map_types, float(cost) / 1000.0, log_z, self.method)

    def _compute_local(self, ev: Evidence) -> InferenceResult:
        card, sum_pots, max_pots, softs, conds = self.local.reduced(ev)
        path = self.rules.path
        jt = JunctionTree(card, [s for s, _ in sum_pots], path)
        if self.local_clauses is not None:
            x, best = decode_max(jt, max_pots)
            if not np.isfinite(best):
                raise RuleError(path, "the hard rules admit no world for this evidence")
            rng = np.random.default_rng(self.signature_seed(ev))
            types, sale = mcsat_local(self.local_clauses, ev, rng, *self.mcsat_settings, jt=jt)
            map_types = {u: UNIT_TYPES[int(x[i]) >> softs[i]] for i, u in enumerate(ev.units)}
            return InferenceResult(types, sale, map_types, -float(best) + 0.0, None, self.method)
        log_z, marg, full = calibrate(jt, sum_pots, return_beliefs=True)
        if marg is None:
            raise RuleError(path, "the hard rules admit no world for this evidence")
        x, best = decode_max(jt, max_pots)
        index = {u: i for i, u in enumerate(ev.units)}
        types, map_types = {}, {}
        for i, u in enumerate(ev.units):
            p = marg[i].reshape(4, 1 << softs[i]).sum(axis=1)
            p.setflags(write=False)
            types[u] = p
            map_types[u] = UNIT_TYPES[int(x[i]) >> softs[i]]
        sale = {}
        for (p_, q_), cond in conds.items():
            pm = scope_marginal(jt, full, (index[p_], index[q_]))
            sale[(p_, q_)] = float(np.sum(pm * cond))
        return InferenceResult(types, sale, map_types, -float(best) + 0.0, float(log_z), self.method)
