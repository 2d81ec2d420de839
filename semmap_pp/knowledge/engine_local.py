"""The knowledge engine's fast path: a pairwise-local rule set, through cached unit and pair
templates (:mod:`~semmap_pp.knowledge.local`, and for MC-SAT :mod:`~semmap_pp.knowledge.mcsat_local`).

The type network of an evidence is assembled from the templates, its MAP decoded per unit, by
the junction tree or by RC2, and updated from a close evidence's where no pair couples its units
(:func:`~semmap_pp.knowledge.local.map_net_update`); its marginals by the compiled calibration,
loopy BP or MC-SAT.
"""

from __future__ import annotations

from collections import OrderedDict

import numpy as np

from semmap_pp.cells import UNIT_TYPES
from semmap_pp.errors import RuleError
from semmap_pp.knowledge.dialect import RuleSet
from semmap_pp.knowledge.engine_ground import GroundPath
from semmap_pp.knowledge.evidence import Evidence
from semmap_pp.knowledge.exact import JunctionTree, calibrate_flat, decode_max
from semmap_pp.knowledge.lbp import BPSettings, pairwise_bp
from semmap_pp.knowledge.local import LocalModel, map_net, map_net_update
from semmap_pp.knowledge.map import map_pairwise_rc2
from semmap_pp.knowledge.mcsat import mcsat_seed
from semmap_pp.knowledge.mcsat_local import LocalClauses, mcsat_local
from semmap_pp.knowledge.result import InferenceResult
from semmap_pp.knowledge.trees import TreeCache


class LocalPath:
    """Marginals and MAP from a :class:`~semmap_pp.knowledge.local.LocalModel`'s templates
    (caches of type networks, MAPs and MAP networks)."""

    def __init__(self, rules: RuleSet, method: str, local: LocalModel,
                 local_clauses: LocalClauses | None, trees: TreeCache, bp: BPSettings,
                 mcsat_settings: tuple[int, int, int], seed: int, ground_path: GroundPath):
        self.rules, self.method, self.local, self.local_clauses = rules, method, local, local_clauses
        self.trees, self.bp, self.mcsat_settings, self.seed = trees, bp, mcsat_settings, seed
        self.ground_path = ground_path
        self._map_cache: OrderedDict = OrderedDict()   # evidence key -> (type network, MAP)
        self._map_nets: OrderedDict = OrderedDict()    # evidence key -> MapNet, None: general path

    def map_types(self, evidence: Evidence, base: Evidence | None = None) -> dict:
        """The MAP types of ``evidence`` without its marginals, updated from ``base``'s when no
        pair of the network couples its units."""
        if base is not None:
            net = self.map_net(evidence, base)
            if net is not None:
                return net.map_types()
        tn, x, _best, _method = self.local_map(evidence)
        return {u: UNIT_TYPES[int(x[i]) >> tn.shift[i]] for i, u in enumerate(evidence.units)}

    def map_net(self, ev: Evidence, base: Evidence):
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

    def local_map(self, ev: Evidence):
        """Type network and exact MAP of ``ev`` (cached by evidence, small LRU)."""
        hit = self._map_cache.get(ev.key)
        if hit is not None:
            self._map_cache.move_to_end(ev.key)
            return hit
        tn = self.local.type_network(ev)
        if any(tn.shift):
            # a pair rule reads some unit's soft evidence atoms, so they stay in its variable;
            # summing them out couples the pair: the ground network's MAP does it exactly
            xg, cost, map_method = self.ground_path.summed_map(ev)
            x = np.array([int(xg[i]) << tn.shift[i] for i in range(len(ev.units))], dtype=np.int64)
            best = -cost
        else:
            x, best, map_method = self.map_local(tn, self.rules.path)
        hit = self._map_cache[ev.key] = (tn, x, best, map_method)
        if len(self._map_cache) > 256:
            self._map_cache.popitem(last=False)
        return hit

    def map_local(self, tn, path):
        """Exact MAP of a type network: per unit, junction tree, or RC2 when the tree is large."""
        n = len(tn.units)
        if not tn.max_pairs:
            if any(not np.isfinite(t).any() for t in tn.unary_max):
                raise RuleError(path, "the hard rules admit no world for this evidence")
            x = np.array([int(np.argmax(t)) for t in tn.unary_max], dtype=np.int64)
            return x, float(sum(t[k] for t, k in zip(tn.unary_max, x))), "jt"
        pots = [((i,), t) for i, t in enumerate(tn.unary_max)]
        pots += [((i, j), t) for i, j, t in tn.max_pairs]
        jt = self.trees.tree(tn.card, [s for s, _ in pots], path)
        if jt is None:
            x, best = map_pairwise_rc2(tn.unary_max, tn.max_pairs, path)
            return x, best, "rc2"
        x, best = decode_max(jt, pots)
        if not np.isfinite(best) or len(x) != n:
            raise RuleError(path, "the hard rules admit no world for this evidence")
        return x, float(best), "jt"

    def compute(self, ev: Evidence) -> InferenceResult:
        """Marginals and MAP of ``ev``: MC-SAT over the local clauses, else :meth:`compute_exact`."""
        if self.local_clauses is not None:
            return self.compute_mcsat(ev)
        return self.compute_exact(ev)

    def compute_mcsat(self, ev: Evidence) -> InferenceResult:
        card, sum_pots = self.local.reduced(ev)
        tn, x, best, map_method = self.local_map(ev)
        jt = JunctionTree(card, [s for s, _ in sum_pots], self.rules.path)
        rng = np.random.default_rng(mcsat_seed(self.rules.digest, ev.key, self.mcsat_settings,
                                               self.seed))
        types, sale = mcsat_local(self.local_clauses, ev, rng, *self.mcsat_settings, jt=jt)
        map_types = {u: UNIT_TYPES[int(x[i]) >> tn.shift[i]] for i, u in enumerate(ev.units)}
        return InferenceResult(types, sale, map_types, -float(best) + 0.0, None, self.method,
                               map_method)

    def compute_exact(self, ev: Evidence) -> InferenceResult:
        """Marginals by the compiled calibration of the junction tree, or loopy BP."""
        path = self.rules.path
        tn, x, best, map_method = self.local_map(ev)
        self._map_cache.pop(ev.key, None)   # the full result is cached from now on
        pots = [((i,), t) for i, t in enumerate(tn.unary_sum)]
        pots += [((i, j), t) for i, j, t in tn.sum_pairs]
        jt = None if self.method == "lbp" else self.trees.tree(tn.card, [s for s, _ in pots], path)
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
            given = {pq: float(np.vdot(pm, c[2]))
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
