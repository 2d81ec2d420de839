"""Grounding a rule set with evidence into a weighted factor network.

clingo grounds the engine's :data:`FRAME`, the rule set and the evidence facts; an observer
records the ground program. Its variables are one 4-state type variable per unit (the one-hot
assignments of ``room/corr/hall/other``), one binary variable per open ``sale`` atom and one per
soft evidence atom. Every other atom is a fact, false, or derived by rules; a derived atom is read
as the disjunction of its rule bodies (Clark completion), which is exact for the acyclic
programs the dialect allows (a recursive definition through open atoms is an error); when its
bodies span many open atoms, the disjunction is a chain of auxiliary variables instead
(:data:`CHAIN_STATES`). Each ground
integrity constraint becomes a hard factor (the set of assignments of its scope that violate
it) and each ground weak-constraint tuple a soft factor (a violation indicator with its weight),
exactly as clingo itself counts them (one cost per distinct tuple).

Soft evidence only opens its atom and puts a unit weight on it (:data:`FRAME`), so the ground
program depends on the evidence's *structure* alone (units, adjacency, each evidence atom absent,
hard or soft): :func:`ground` grounds the structure (every soft weight 0) and adds each soft
atom's weight as a unary factor, and with a ``cache`` grounds each structure once (the sampler's
proposals mostly move walls, which change soft probabilities, not structures).
"""

from __future__ import annotations

import math
from collections import OrderedDict, defaultdict
from dataclasses import dataclass, replace

import clingo
import numpy as np

from semmap_pp.errors import RuleError
from semmap_pp.knowledge.dialect import SOFT_PREDICATES, TYPE_PREDICATES, RuleSet
from semmap_pp.knowledge.evidence import Evidence, ground_facts, soft_weight
from semmap_pp.knowledge.size import Sizes

#: The engine's frame: exactly one type per unit, SaLe open between adjacent units, soft evidence
#: atoms open with a unit weak constraint of weight ``log(p / (1 - p))`` (thousandths).
FRAME = "\n".join(
    ["1 { room(U); corr(U); hall(U); other(U) } 1 :- unit(U).",
     "{ sale(P,Q) } :- adj(P,Q), P != Q."]
    + [f"{{ {p}(U) }} :- __softw({p}(U), W)." for p in SOFT_PREDICATES]
    + [f":~ __softw({p}(U), W), W > 0, not {p}(U). [W@0, __soft, {p}, U]" for p in SOFT_PREDICATES]
    + [f":~ __softw({p}(U), W), W < 0, {p}(U). [-W@0, __soft, {p}, U]" for p in SOFT_PREDICATES]
) + "\n"

MAX_SCOPE_STATES = 1 << 16   # a ground rule whose scope has more joint states is refused
#: A derived atom whose bodies together span more joint states than this is not read inline but
#: as a chain of auxiliary variables (``Network.aux``): inline, a rule that also reads another
#: atom would multiply its table again (``hall(U), not nextcorr(U)`` at a corridor with eight
#: neighbours: 4 x 4^8 states).
CHAIN_STATES = 1 << 10
_TYPE_INDEX = {p: k for k, p in enumerate(TYPE_PREDICATES)}
_ONE_HOT = [np.eye(4, dtype=bool)[k] for k in range(4)]
_BINARY = np.array([False, True])
_TRUE = np.array(True)
_FALSE = np.array(False)


@dataclass
class Network:
    """A weighted factor network (log-linear model) over discrete variables.

    ``P(x) ∝ exp(-Σ_soft w_f · viol_f(x)) · Π_hard [not viol_h(x)]`` with weights in units of
    1/1000 (integers, exactly as in the rule files).

    Attributes
    ----------
    path : str
        The rule file (for error messages).
    units : tuple of int
        Variable ``i < len(units)`` is the type of unit ``units[i]`` (states in
        ``cells.UNIT_TYPES`` order).
    card : ndarray of int
        Number of states of each variable (4 for types, 2 for binary atoms).
    names : list of str
        A readable name per variable.
    sale : dict (p, q) -> int
        Variable of each open ``sale(p,q)`` atom (directed, as grounded).
    hard : list of (scope, ndarray of bool)
        Scope is a sorted tuple of variables; the table marks the violating assignments.
    soft : list of (scope, ndarray of bool, int)
        Violation table and weight (thousandths).
    offset : int
        Constant cost (thousandths) of weak constraints violated by the evidence alone.
    aux : tuple of int
        Auxiliary binary variables: a derived atom whose bodies together couple too many open
        atoms to be read inline is a chain of them, each the OR of the previous and one body
        (hard factors; a deterministic function of the other variables, so no distribution
        changes). Neither query nor evidence atoms.
    """

    path: str
    units: tuple[int, ...]
    card: np.ndarray
    names: list[str]
    sale: dict
    hard: list
    soft: list
    offset: int = 0
    aux: tuple = ()

    @property
    def n_vars(self) -> int:
        return len(self.card)

    def cost(self, x) -> float:
        """Cost (thousandths) of a full assignment ``x``; ``inf`` if a hard factor is violated."""
        x = np.asarray(x)
        for scope, viol in self.hard:
            if viol[tuple(x[list(scope)])]:
                return float("inf")
        return float(self.offset + sum(w for s, t, w in self.soft if t[tuple(x[list(s)])]))


class _Observer(clingo.Observer):
    def __init__(self):
        self.rules, self.wrules, self.mins, self.outputs = [], [], [], []

    def rule(self, choice, head, body):
        self.rules.append((choice, head, body))

    def weight_rule(self, choice, head, lower_bound, body):
        self.wrules.append((choice, head, lower_bound, body))

    def minimize(self, priority, literals):
        self.mins.append((priority, literals))

    def output_atom(self, symbol, atom):
        self.outputs.append((symbol, atom))


def _align(scope, arr, union):
    if scope == union:
        return arr
    shape = [1] * len(union)
    j = 0
    for i, v in enumerate(union):
        if j < len(scope) and scope[j] == v:
            shape[i] = arr.shape[j]
            j += 1
    return arr.reshape(shape)


class _Evaluator:
    """Truth tables of ground atoms and bodies over the network variables."""

    def __init__(self, path, card, facts, var_of_atom, defs, max_states=None):
        self.path, self.card = path, list(card)
        self.facts, self.var_of_atom, self.defs = facts, var_of_atom, defs
        self.memo = {}
        self.max_states = MAX_SCOPE_STATES if max_states is None else int(max_states)
        self.aux_hard, self.aux_names = [], []

    def atom(self, a):
        hit = self.memo.get(a)
        if hit is not None:
            if hit is False:
                raise RuleError(self.path, "a helper predicate is defined recursively through "
                                "query atoms; the dialect needs acyclic definitions")
            return hit
        if a in self.facts:
            out = ((), _TRUE)
        elif a in self.var_of_atom:
            var, k = self.var_of_atom[a]
            out = ((var,), _BINARY if k is None else _ONE_HOT[k])
        elif a in self.defs:
            self.memo[a] = False
            parts = [self.body(b) for b in self.defs[a]]
            if len(parts) > 1 and self._states(set().union(*(s for s, _ in parts))) > min(
                    CHAIN_STATES, self.max_states):
                out = self._chain_or(a, parts)
            else:
                out = self.combine(parts, np.logical_or)
        else:
            out = ((), _FALSE)
        self.memo[a] = out
        return out

    def lit(self, lit):
        s, t = self.atom(abs(lit))
        return (s, t) if lit > 0 else (s, ~t)

    def body(self, b):
        if b[0] == "n":
            if not b[1]:
                return (), _TRUE
            return self.combine([self.lit(x) for x in b[1]], np.logical_and)
        _, lower, wlits = b
        parts = [self.lit(x) for x, _w in wlits]
        union = self.union([s for s, _ in parts])
        total = np.zeros(self.shape(union), dtype=np.int64)
        for (s, t), (_x, w) in zip(parts, wlits):
            total = total + w * _align(s, t, union)
        return union, total >= lower

    def _states(self, scope) -> int:
        card = self.card
        return math.prod(int(card[v]) for v in scope)

    def _within(self, scope):
        """``scope``, or the error of a ground rule whose scope has too many joint states."""
        if self._states(scope) > self.max_states:
            raise RuleError(self.path, f"a ground rule couples {len(scope)} open atoms (more than "
                            f"{self.max_states} joint states); split the rule or use helpers "
                            "that depend on fewer units")
        return scope

    def union(self, scopes):
        if len(scopes) == 1:
            return scopes[0]
        return self._within(tuple(sorted(set().union(*scopes))))

    def _chain_or(self, a, parts):
        """A derived atom whose bodies together couple too many open atoms (``nextcorr(U) :-
        adj(U,V), corr(V).`` at a unit with many neighbours): auxiliary binary variables
        ``o_1 .. o_n``, ``o_1 = body_1`` and ``o_k = o_(k-1) or body_k``, each tied by a hard
        factor over its own few atoms; the atom is ``o_n``. The same truth function as the
        inline OR, so the distribution over the other variables is unchanged."""
        prev = None
        for k, (s, t) in enumerate(parts, 1):
            o = len(self.card)
            self.card.append(2)
            self.aux_names.append(f"__or{k}({a})")
            linked = {o} if prev is None else {o, prev}
            scope = self._within(tuple(sorted(set(s) | linked)))
            value = _align(s, t, scope)
            if prev is not None:
                value = value | _align((prev,), _BINARY, scope)
            viol = _align((o,), _BINARY, scope) != value
            self.aux_hard.append((scope, np.broadcast_to(viol, self.shape(scope)).copy()))
            prev = o
        return (prev,), _BINARY

    def shape(self, union):
        return tuple(int(self.card[v]) for v in union)

    def combine(self, parts, op):
        if len(parts) == 1:
            return parts[0]
        union = self.union([s for s, _ in parts])
        out = _align(parts[0][0], parts[0][1], union)
        for s, t in parts[1:]:
            out = op(out, _align(s, t, union))
        return union, np.broadcast_to(out, self.shape(union)).copy() if out.shape != self.shape(
            union) else out


@dataclass
class Grounding:
    """The network and the grounded clingo control (reused for MAP by optimisation)."""

    network: Network
    control: clingo.Control


#: Structures a :func:`ground` cache keeps (least recently used dropped).
CACHE_SIZE = 256


def ground(rules: RuleSet, ev: Evidence, keep_control: bool = False,
           max_states: int | None = None, cache: OrderedDict | None = None) -> Grounding:
    """Ground ``rules`` with evidence ``ev`` into a :class:`Network`.

    Parameters
    ----------
    rules : RuleSet
    ev : Evidence
    keep_control : bool
        Keep the clingo control (for MAP by clingo optimisation), grounded with the soft weights.
    max_states : int, optional
        Largest joint state count of one factor (default :data:`MAX_SCOPE_STATES`). A derived
        atom whose bodies span more than :data:`CHAIN_STATES` (or ``max_states`` when smaller)
        becomes a chain of auxiliary variables (``Network.aux``).
    cache : OrderedDict, optional
        The networks of the structures grounded so far (one per rule set: the key is the
        structure's facts), filled and used here; the soft weights are added to a copy.

    Raises
    ------
    RuleError
        If the rule set's hard rules are violated by the evidence alone, a construct falls
        outside what the network can represent, or the grounding could exceed
        :data:`~semmap_pp.knowledge.size.MAX_GROUND_STATEMENTS` (checked before clingo runs).
    """
    if keep_control:
        _check_size(rules, ev)
        obs, ctl = _clingo_ground(rules, ground_facts(ev))
        return Grounding(_build(rules.path, ev, obs, max_states), ctl)
    key = (ground_facts(ev, weights=False), max_states)
    net = cache.get(key) if cache is not None else None
    if net is None:
        _check_size(rules, ev)
        obs, _ctl = _clingo_ground(rules, key[0])
        net = _build(rules.path, ev, obs, max_states)
        if cache is not None:
            cache[key] = net
            if len(cache) > CACHE_SIZE:
                cache.popitem(last=False)
    else:
        cache.move_to_end(key)
    return Grounding(_with_soft_weights(net, ev), None)


def _check_size(rules: RuleSet, ev: Evidence) -> None:
    """Refuse an evidence whose grounding could exceed
    :data:`~semmap_pp.knowledge.size.MAX_GROUND_STATEMENTS` (RuleError naming the statement)."""
    rules.bound.check(Sizes.of(ev))


def _clingo_ground(rules: RuleSet, facts: str):
    """clingo's ground program of the frame, the rules and ``facts``: (observer, control)."""
    obs = _Observer()
    messages = []
    ctl = clingo.Control(["--warn=none"], logger=lambda c, m: messages.append(m),
                         message_limit=3)
    ctl.register_observer(obs)
    try:
        ctl.add("base", [], FRAME + rules.program + facts)
        ctl.ground([("base", [])])
    except RuntimeError:
        raise RuleError(rules.path, "grounding failed: " + " ".join(
            " ".join(m.split()) for m in messages)) from None
    return obs, ctl


def _with_soft_weights(net: Network, ev: Evidence) -> Network:
    """``net`` (the structure's network, every soft weight 0) with each soft atom's weak
    constraint of :data:`FRAME` as a unary factor: weight ``W`` when the atom is false (``W >
    0``), ``-W`` when it is true (``W < 0``), none when ``W = 0``."""
    extra = []
    var = None
    for name in SOFT_PREDICATES:
        for u, p in ev.unary(name):
            w = soft_weight(p) if p < 1.0 else 0
            if w:
                if var is None:
                    var = {n: v for v, n in enumerate(net.names)}
                extra.append(((var[f"{name}({u})"],), ~_BINARY if w > 0 else _BINARY, abs(w)))
    return replace(net, soft=net.soft + extra) if extra else net


def _build(path: str, ev: Evidence, obs: _Observer, max_states: int | None = None,
           tags: list | None = None) -> Network:
    """The :class:`Network` of the ground program ``obs`` recorded; with ``tags`` (a list),
    the weak-constraint priority of each soft factor is appended to it in the order of
    ``Network.soft`` (:mod:`semmap_pp.knowledge.learn` grounds each soft rule at a priority of
    its own to tell the rules' factors apart)."""
    units = ev.units
    unit_index = {u: i for i, u in enumerate(units)}
    facts, choice = set(), set()
    defs = defaultdict(list)
    constraints = []
    choice_bodies = []
    for is_choice, head, body in obs.rules:
        if is_choice:
            choice.update(head)
            choice_bodies.extend(body)
        elif not head:
            constraints.append(("n", body))
        elif len(head) == 1:
            if body:
                defs[head[0]].append(("n", body))
            else:
                facts.add(head[0])
        else:
            raise RuleError(path, "disjunctive rules are not supported")
    for is_choice, head, lower, body in obs.wrules:
        if is_choice:
            raise RuleError(path, "choice rules with weights are not supported")
        b = ("w", lower, body)
        if head:
            defs[head[0]].append(b)
        else:
            constraints.append(b)
    for lit in choice_bodies:
        if lit < 0 or lit not in facts:
            raise RuleError(path, "query atoms must be opened by facts: adj/2 may only be "
                            "derived from evidence, not from query atoms")
    card = [4] * len(units)
    names = [f"type({u})" for u in units]
    var_of_atom, sale = {}, {}
    for sym, atom in obs.outputs:
        if atom == 0 or atom not in choice:
            continue
        name, args = sym.name, sym.arguments
        if name in _TYPE_INDEX:
            var_of_atom[atom] = (unit_index[args[0].number], _TYPE_INDEX[name])
        else:
            var_of_atom[atom] = (len(card), None)
            if name == "sale":
                if not all(a.type == clingo.SymbolType.Number and a.number in unit_index
                           for a in args):
                    raise RuleError(path, f"adj/2 must pair two units of the evidence, but the "
                                    f"rules derive adj({args[0]},{args[1]})")
                sale[(args[0].number, args[1].number)] = len(card)
            card.append(2)
            names.append(str(sym))
    n_base = len(card)
    ev_ = _Evaluator(path, card, facts, var_of_atom, defs, max_states)
    hard, soft, offset = [], [], 0
    for b in constraints:
        scope, viol = ev_.body(b)
        if not viol.any():
            continue
        if not scope:
            raise RuleError(path, "the hard rules admit no world for this evidence (an integrity "
                            "constraint is violated by the evidence alone)")
        hard.append((scope, viol))
    for _priority, lits in obs.mins:
        for lit, w in lits:
            scope, t = ev_.lit(lit)
            if not scope:
                offset += int(w) if bool(t) else 0
            elif t.any() and w != 0:
                soft.append((scope, t, int(w)))
                if tags is not None:
                    tags.append(_priority)
    hard += ev_.aux_hard
    card = np.array(ev_.card, dtype=np.int64)
    return Network(path, tuple(units), card, names + ev_.aux_names, sale, hard, soft, offset,
                   tuple(range(n_base, len(card))))
