"""MC-SAT on the pairwise fast path: clause templates per unit and per adjacent pair, cached.

For a pairwise-local rule set (:func:`~semmap_pp.knowledge.local.is_pairwise`) every ground
clause either lies on one unit (its type and soft evidence atoms: the unit's *super-state*) or on
an adjacent pair (both super-states and the pair's SaLe atoms). As in
:class:`~semmap_pp.knowledge.local.LocalModel`, one clingo grounding of a lone unit per evidence
pattern, and of one adjacent pair per pattern pair, gives every clause ever needed; a pair's own
clauses are those of the pair grounding minus the two units' clauses (as multisets of violation
tables and weights). MC-SAT then keeps or drops each *ground clause* individually, SaLe atoms
included; the SaLe atoms of a pair are private to it, so they are counted and drawn inside the
pair (:class:`~semmap_pp.knowledge.mcsat.ClauseBlock` with ``n_aux`` states) and the junction
tree has one variable per unit.
"""

from __future__ import annotations

from collections import Counter

import numpy as np

from semmap_pp.errors import RuleError
from semmap_pp.knowledge.dialect import SOFT_PREDICATES, RuleSet
from semmap_pp.knowledge.evidence import Evidence
from semmap_pp.knowledge.ground import ground
from semmap_pp.knowledge.local import LocalModel, _pattern_evidence, _unit_key
from semmap_pp.knowledge.mcsat import ClauseTemplate, run_mcsat, stack_blocks


def _expand(scope, table, order, card):
    """A table over ``scope`` as a dense boolean array over all of ``order`` (row-major)."""
    where = {v: i for i, v in enumerate(order)}
    shape = tuple(int(card[v]) for v in order)
    pos = [where[v] for v in scope]
    perm = sorted(range(len(scope)), key=lambda j: pos[j])
    sh = [1] * len(order)
    for j in perm:
        sh[pos[j]] = table.shape[j]
    return np.broadcast_to(np.transpose(table, perm).reshape(sh), shape).reshape(-1)


def _clauses(net, order):
    """Hard-allowed mask and soft clauses ``[(viol, w)]`` of ``net`` dense over ``order``."""
    if sorted(order) != list(range(net.n_vars)):
        raise RuleError(net.path, "internal: a template grounding has atoms outside its units")
    allowed = np.ones(int(np.prod([net.card[v] for v in order])), dtype=bool)
    for scope, viol in net.hard:
        allowed &= ~_expand(scope, viol, order, net.card)
    soft = [(_expand(scope, t, order, net.card), int(w)) for scope, t, w in net.soft]
    return allowed, soft


class LocalClauses:
    """Clause templates of one pairwise-local rule set, cached by evidence pattern."""

    def __init__(self, rules: RuleSet):
        self.rules = rules
        self._units: dict = {}
        self._unit_raw: dict = {}
        self._pairs: dict = {}
        self._stacks: dict = {}
        self.trees: dict = {}       # compiled sampling trees by floor structure (run_mcsat)

    def _unit_clauses(self, key):
        hit = self._unit_raw.get(key)
        if hit is None:
            net = ground(self.rules, _pattern_evidence([(1, key)], [])).network
            hit = self._unit_raw[key] = _clauses(net, LocalModel._unit_order(net, 1))
        return hit

    def unit(self, key) -> ClauseTemplate:
        """Clauses of a lone unit with evidence pattern ``key`` over its super-state."""
        hit = self._units.get(key)
        if hit is None:
            allowed, soft = self._unit_clauses(key)
            hit = self._units[key] = _template((len(allowed),), 1, allowed, soft)
        return hit

    def pair(self, kp, kq):
        """Clauses of an adjacent pair over (super p, super q, SaLe atoms), units' removed.

        The private atoms are the pair's SaLe atoms; the reported one is ``sale(p,q)``.
        """
        hit = self._pairs.get((kp, kq))
        if hit is not None:
            return hit
        net = ground(self.rules, _pattern_evidence([(1, kp), (2, kq)], [(1, 2)])).network
        o1, o2 = LocalModel._unit_order(net, 1), LocalModel._unit_order(net, 2)
        sale_vars = sorted(net.sale.values())
        allowed, soft = _clauses(net, o1 + o2 + sale_vars)
        (a1, s1), (a2, s2) = self._unit_clauses(kp), self._unit_clauses(kq)
        n1, n2 = len(a1), len(a2)
        n_aux = allowed.size // (n1 * n2)
        bag = Counter((t.tobytes(), w) for t, w in soft)
        for t, w in s1:
            bag[(np.broadcast_to(t[:, None, None], (n1, n2, n_aux)).tobytes(), w)] -= 1
        for t, w in s2:
            bag[(np.broadcast_to(t[None, :, None], (n1, n2, n_aux)).tobytes(), w)] -= 1
        if any(c < 0 for c in bag.values()):
            raise RuleError(self.rules.path, "internal: a unit clause is missing from its pair "
                            "grounding")
        own = []
        for t, w in soft:
            key = (t.tobytes(), w)
            if bag[key] > 0:
                bag[key] -= 1
                own.append((t, w))
        v12 = net.sale.get((1, 2))
        on = np.zeros(n_aux, dtype=bool)
        if v12 is not None:
            bit = len(sale_vars) - 1 - sale_vars.index(v12)
            on = ((np.arange(n_aux) >> bit) & 1).astype(bool)
        hit = self._pairs[(kp, kq)] = _template((n1, n2), n_aux, allowed, own, on)
        return hit

    def blocks(self, ev: Evidence):
        """Cardinalities of the unit super-states, clause blocks, and per block the pair
        ``(p, q)`` (or None for a unit) of each instance."""
        maps = {name: dict(ev.unary(name)) for name in SOFT_PREDICATES}
        keys = [_unit_key(maps, u) for u in ev.units]
        index = {u: i for i, u in enumerate(ev.units)}
        card = [self.unit(key).n_states for key in keys]
        instances = [(self.unit(key), [i]) for i, key in enumerate(keys)]
        labels = [None] * len(keys)
        for p, q in ev.adj:
            instances.append((self.pair(keys[index[p]], keys[index[q]]), [index[p], index[q]]))
            labels.append((p, q))
        # templates of one shape share a block; compiled stacks are cached by their templates
        blocks, members = stack_blocks(instances, self._stacks)
        return card, blocks, [[labels[m] for m in ms] for ms in members]


def _template(shape, n_aux, allowed, soft, aux_on=None):
    viol = np.array([t for t, _ in soft], dtype=bool).reshape(len(soft), allowed.size)
    return ClauseTemplate(shape, n_aux, allowed, viol, [w for _, w in soft], aux_on)


def mcsat_local(clauses: LocalClauses, ev: Evidence, rng, n_chains, n_iter, burn_in, jt=None):
    """MC-SAT type and SaLe marginals of ``ev`` on the fast path.

    Parameters
    ----------
    clauses : LocalClauses
    ev : Evidence
    rng : numpy.random.Generator
    n_chains, n_iter, burn_in : int
        See :func:`~semmap_pp.knowledge.mcsat.run_mcsat`.
    jt : JunctionTree, optional
        A tree over the units with an edge per adjacent pair.

    Returns
    -------
    types : dict int -> ndarray (4,)
    sale : dict (p, q) -> float
    """
    card, blocks, labels = clauses.blocks(ev)
    marg, aux = run_mcsat(card, blocks, rng, n_chains, n_iter, burn_in, clauses.rules.path, jt,
                          clauses.trees)
    types = {}
    for i, u in enumerate(ev.units):
        p = marg[i].reshape(4, -1).sum(axis=1)
        p.setflags(write=False)
        types[u] = p
    sale = {}
    for members, est in zip(labels, aux):
        for pq, e in zip(members, est if est is not None else [0.0] * len(members)):
            if pq is not None:
                sale[pq] = float(e)
    return types, {pq: sale[pq] for pq in ev.adj}
