"""The knowledge engine's junction trees, within the size its method allows, cached.

``method="auto"`` runs the junction tree when its largest clique has at most
:attr:`AutoLimits.states` joint states, loopy BP otherwise (docs/benchmarks.md, "Knowledge
engine", for the measurement); a ground network (rules that are not pairwise-local) allows up to
:attr:`AutoLimits.states_ground`.
"""

from __future__ import annotations

from collections import OrderedDict
from dataclasses import dataclass

from semmap_pp.knowledge.exact import MAX_CLIQUE_STATES, JunctionTree, TooDense

#: ``method="auto"`` runs the junction tree when its largest clique has at most this many joint
#: states, loopy BP otherwise (docs/benchmarks.md, "Knowledge engine", for the measurement).
AUTO_MAX_STATES = 1 << 10
#: The same bound for a rule set's ground network (the general path, rules that are not
#: pairwise-local): there loopy BP runs over general factors in Python and the junction tree is
#: faster up to cliques of this size (docs/benchmarks.md, "Knowledge engine": 86 against 267 ms
#: at 2^18 states under rules/halls_to_corridors.lp).
AUTO_MAX_STATES_GROUND = 1 << 18


@dataclass(frozen=True)
class AutoLimits:
    """The largest clique ``method="auto"`` hands to the junction tree: ``states`` for the fast
    path's type networks, ``states_ground`` for a ground network (where loopy BP is slower and
    the tree pays up to larger cliques)."""

    states: int = AUTO_MAX_STATES
    states_ground: int = AUTO_MAX_STATES_GROUND


class TreeCache:
    """Junction trees for one inference method, cached by cardinalities, scopes and limit."""

    def __init__(self, method: str, auto: AutoLimits = AutoLimits()):
        self.method = method
        self.auto_max_states = int(auto.states)
        self.auto_max_states_ground = int(auto.states_ground)
        self._trees: OrderedDict = OrderedDict()       # (card, scopes) -> JunctionTree or None

    def limit(self, grounded: bool = False) -> int:
        """Largest clique the junction tree may have for the marginals and the MAP
        (``grounded``: of a ground network, where ``auto`` allows :data:`AUTO_MAX_STATES_GROUND`)."""
        if self.method in ("exact", "mcsat"):
            return MAX_CLIQUE_STATES
        if grounded and self.method == "auto":
            return self.auto_max_states_ground
        return self.auto_max_states

    def tree(self, card, scopes, path, grounded: bool = False):
        """A junction tree within :meth:`limit`, or None when ``auto``/``lbp`` must fall back
        (cached by cardinalities, scopes and the limit: a tree is a pure function of them, and
        the sampler's networks keep their structure across most evidence changes)."""
        limit = self.limit(grounded)
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
