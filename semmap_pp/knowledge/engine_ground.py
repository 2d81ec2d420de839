"""The knowledge engine's general path: any rule set, through its ground network.

The network is grounded per evidence (:func:`~semmap_pp.knowledge.ground.ground`), its MAP decoded
first (exact, and it raises when the hard rules admit no world), its marginals then added by the
junction tree, loopy BP or MC-SAT (:class:`~semmap_pp.knowledge.engine.KnowledgeEngine`).
"""

from __future__ import annotations

from collections import OrderedDict

import numpy as np

from semmap_pp.cells import UNIT_TYPES
from semmap_pp.errors import RuleError
from semmap_pp.knowledge.dialect import RuleSet
from semmap_pp.knowledge.evidence import Evidence
from semmap_pp.knowledge.exact import calibrate, decode_max, merged_potentials, sum_out
from semmap_pp.knowledge.ground import ground
from semmap_pp.knowledge.lbp import BPSettings, factor_bp
from semmap_pp.knowledge.map import map_clingo, map_rc2, map_tables_rc2
from semmap_pp.knowledge.mcsat import mcsat_marginals, mcsat_seed
from semmap_pp.knowledge.result import InferenceResult
from semmap_pp.knowledge.trees import TreeCache


class GroundPath:
    """Marginals and MAP of a rule set's ground network (caches of groundings and MAPs)."""

    def __init__(self, rules: RuleSet, method: str, map_method: str, trees: TreeCache,
                 bp: BPSettings, mcsat_settings: tuple[int, int, int], seed: int):
        self.rules, self.method, self.map_method = rules, method, map_method
        self.trees, self.bp, self.mcsat_settings, self.seed = trees, bp, mcsat_settings, seed
        self._ground_maps: OrderedDict = OrderedDict()  # evidence key -> ground network and MAP
        self._groundings: OrderedDict = OrderedDict()   # evidence structure -> its network

    def map_types(self, ev: Evidence) -> dict:
        """The MAP types of ``ev`` without its marginals (:meth:`ground_map`)."""
        g, _pots, _jt, x, _cost, _method = self.ground_map(ev)
        return {u: UNIT_TYPES[int(x[i])] for i, u in enumerate(g.network.units)}

    def ground_map(self, ev: Evidence):
        """The ground network of ``ev``, its merged potentials, junction tree (None: too large
        or not wanted) and exact MAP ``(g, pots, jt, x, cost, map_method)``, cached by evidence
        (small LRU) until :meth:`compute` adds the marginals: the MAP types of the general
        path are grounded and decoded once for both."""
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
            self.trees.tree(net.card, scopes, net.path, grounded=True)
        # MAP first: it is exact and raises when the hard rules admit no world
        x, cost, map_method = self.map_ground(g, pots, jt)
        hit = self._ground_maps[ev.key] = (g, pots, jt, x, cost, map_method)
        if len(self._ground_maps) > 64:
            self._ground_maps.popitem(last=False)
        return hit

    def summed_map(self, ev: Evidence):
        """The exact MAP of ``ev``'s ground network with its soft evidence atoms summed out
        (the fast path's when a pair rule reads some unit's soft evidence):
        ``(assignment, cost, method)``."""
        g = ground(self.rules, ev, cache=self._groundings)
        return self.map_ground(g, merged_potentials(g.network), None)

    def compute(self, ev: Evidence) -> InferenceResult:
        """Marginals and MAP of ``ev``."""
        g, pots, jt, x, cost, map_method = self.ground_map(ev)
        self._ground_maps.pop(ev.key, None)   # the full result is cached from now on
        net = g.network
        log_z, method = None, self.method
        if self.method == "mcsat":
            rng = np.random.default_rng(mcsat_seed(self.rules.digest, ev.key, self.mcsat_settings,
                                                   self.seed))
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

    def map_ground(self, g, pots, jt):
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
        tree = (self.trees.tree(net.card, [s for s, _ in mpots], path, grounded=True)
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
