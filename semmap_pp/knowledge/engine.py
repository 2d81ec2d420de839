"""The knowledge engine: evidence in, type and SaLe marginals and MAP types out, cached.

:class:`KnowledgeEngine` keeps the results by evidence and hands each new evidence to one of two
paths: the fast path of a pairwise-local rule set (:mod:`~semmap_pp.knowledge.engine_local`) or
the general path through the ground network (:mod:`~semmap_pp.knowledge.engine_ground`); both
share the junction trees (:mod:`~semmap_pp.knowledge.trees`).

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

import os
from collections import OrderedDict

from semmap_pp.errors import RuleError
from semmap_pp.knowledge.dialect import RuleSet, load_rules
from semmap_pp.knowledge.engine_ground import GroundPath
from semmap_pp.knowledge.engine_local import LocalPath
from semmap_pp.knowledge.evidence import Evidence
from semmap_pp.knowledge.lbp import BPSettings
from semmap_pp.knowledge.local import LocalModel, default_store, is_pairwise
from semmap_pp.knowledge.mcsat import MCSATSettings, mcsat_seed
from semmap_pp.knowledge.mcsat_local import LocalClauses
from semmap_pp.knowledge.result import InferenceResult
from semmap_pp.knowledge.trees import AUTO_MAX_STATES, AUTO_MAX_STATES_GROUND, AutoLimits, TreeCache

__all__ = ["AUTO_MAX_STATES", "AUTO_MAX_STATES_GROUND", "AutoLimits", "InferenceResult",
           "KnowledgeEngine", "MAP_METHODS", "METHODS", "MCSATSettings"]

METHODS = ("auto", "exact", "lbp", "mcsat")
MAP_METHODS = ("jt", "clingo", "rc2")


class KnowledgeEngine:
    """Inference over one rule set, cached by evidence.

    Parameters
    ----------
    rules : RuleSet
    method : {"auto", "exact", "lbp", "mcsat"}
        Marginals by junction tree (exact), loopy belief propagation
        (:mod:`~semmap_pp.knowledge.lbp`), MC-SAT sampling, or ``auto``: exact when the
        junction tree's largest clique has at most ``auto.states`` joint states, else LBP.
        The MAP stays exact: when its own junction tree is too large (``auto``/``lbp``: above
        ``auto.states``) RC2 solves it.
    map_method : {"jt", "clingo", "rc2"}
        MAP by max-product on the junction tree, clingo optimisation, or RC2 MaxSAT. The MAP
        maximises the types and SaLe with the soft evidence atoms summed out (``GroundPath.map_ground``);
        clingo, which optimises whole worlds, refuses evidence with soft atoms.
    mcsat : MCSATSettings
        Chains, iterations and burn-in of MC-SAT (see
        :func:`~semmap_pp.knowledge.mcsat.mcsat_marginals`).
    cache_size : int
        Results kept (least recently used are dropped).
    seed : int
        Mixed with a hash of the rules and the evidence: MC-SAT results are a deterministic
        function of (rules, evidence, settings).
    auto : AutoLimits
        Largest clique ``auto`` hands to the junction tree (``states``), and the same for a
        ground network (``states_ground``: rules that are not pairwise-local), where loopy BP is
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

    def __init__(self, rules: RuleSet, method: str = "auto", map_method: str = "jt", *,
                 mcsat: MCSATSettings = MCSATSettings(), bp: BPSettings = BPSettings(),
                 auto: AutoLimits = AutoLimits(), cache_size: int = 4096, seed: int = 0,
                 fast: bool = True, template_store=True):
        if method not in METHODS:
            raise RuleError(rules.path, f"unknown inference method {method!r}; use one of {METHODS}")
        if map_method not in MAP_METHODS:
            raise RuleError(rules.path, f"unknown MAP method {map_method!r}; use one of "
                            f"{MAP_METHODS}")
        self.rules, self.method, self.map_method = rules, method, map_method
        self.mcsat_settings = mcsat.astuple()
        self.cache_size, self.seed = int(cache_size), int(seed)
        self.bp = bp
        self.trees = TreeCache(method, auto)
        self._cache: OrderedDict = OrderedDict()
        store = (default_store() if template_store is True
                 else (template_store or None))
        self.local = (LocalModel(rules, store=store)
                      if fast and map_method == "jt" and is_pairwise(rules) else None)
        self.local_clauses = (LocalClauses(rules) if self.local is not None and method == "mcsat"
                              else None)
        self.hits = self.misses = 0
        self._ground = GroundPath(rules, method, map_method, self.trees, bp, self.mcsat_settings,
                                  self.seed)
        self._local = (None if self.local is None else
                       LocalPath(rules, method, self.local, self.local_clauses, self.trees, bp,
                                 self.mcsat_settings, self.seed, self._ground))

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
        if self._local is None:
            return self._ground.map_types(evidence)
        return self._local.map_types(evidence, base)

    def signature_seed(self, evidence: Evidence) -> int:
        """The MC-SAT seed: a hash of (rules, evidence, settings, seed)."""
        return mcsat_seed(self.rules.digest, evidence.key, self.mcsat_settings, self.seed)

    def _compute(self, ev: Evidence) -> InferenceResult:
        if self._local is not None:
            return self._local.compute(ev)
        return self._ground.compute(ev)
