"""An upper bound on the size of a rule set's grounding, checked before clingo grounds.

A rule file is Datalog with weak constraints (docs/rules.md): derived atoms hold only values of
the evidence and the files, so grounding always ends. It is still polynomial in the number of
units, with the number of a rule's free unit variables as the exponent:

    :~ unit(A), unit(B), unit(C), unit(D), unit(E), unit(F), room(A). [1@0, many, A, B, C, D, E, F]

grounds n^6 weak-constraint tuples, 64 million for a floor of 20 units: `semmap map` with it
ran for minutes on cartesium without an end in sight.
:class:`GroundingBound` bounds, from the rules alone, how many ground statements clingo can
produce for an evidence of given size (at most :data:`STATEMENTS_PER_INSTANCE` per rule body
instance and per aggregate element); :func:`ground` refuses an
evidence whose bound exceeds :data:`MAX_GROUND_STATEMENTS` with a one-line
:class:`~semmap_pp.errors.RuleError` naming the statement that contributes most, before clingo is
called. ``semmap rules check`` reports from how many units on a file reaches the limit.

How the bound is counted (each step an over-estimate, so the bound holds):

* the atoms of evidence and query predicates number at most: ``unit``, the four types and the
  four geometry atoms ``n`` each (those listed in the evidence, for the geometry atoms), ``adj``
  and ``sale`` twice the adjacent pairs; one bound argument of ``adj``/``sale`` leaves at most
  the largest number of neighbours ``d``;
* a helper predicate holds at most as many atoms as its rules have body instances, and at most
  ``(n + c)^arity`` (``c``: the constants in the files), which is all a recursive one gets;
* a body's instances are counted by joining its positive atoms, each time the atom with the
  fewest new combinations given the variables bound so far (comparisons, negated literals and
  conditions filter, so they are left out); an aggregate or a conditional literal adds its
  elements per instance (an assignment ``N = #count{...}`` multiplies by their number plus one).
"""

from __future__ import annotations

import itertools
from collections import defaultdict
from dataclasses import dataclass

import clingo
import clingo.ast as cast

from semmap_pp.errors import RuleError
from semmap_pp.knowledge.rule_ast import walk

#: Ground statements (the bound of :class:`GroundingBound`) allowed for one evidence: a
#: million weak-constraint tuples take clingo and the network reader 1.65 s and 330 MB on a
#: 2-core Xeon VM (docs/rules.md, "The size of a grounding"), and the sampler grounds hundreds of evidences; above it a
#: run would not end in useful time or memory, so it stops with an error instead.
MAX_GROUND_STATEMENTS = 2_000_000

#: clingo's ground statements per body instance or aggregate element, at most: a weak
#: constraint's body becomes an auxiliary rule and a cost entry, an aggregate a weight rule and
#: a rule per element (tests/integration/test_knowledge_size.py compares the bound with clingo's output).
STATEMENTS_PER_INSTANCE = 2

#: The floor every rule file must be able to ground within the limit (checked when it is
#: loaded): the model's 64 starting slots, each unit with up to 8 neighbours and every geometry
#: atom. A file that cannot is refused at once instead of in the middle of a run.
FLOOR_UNITS = 64
NEIGHBOURS = 8

_T = cast.ASTType
_ANONYMOUS = itertools.count()
_UNARY_EVIDENCE = ("rolike", "colike", "halike", "muldoor")
_TYPES = ("room", "corr", "hall", "other")
_PAIRS = ("adj", "sale")


@dataclass(frozen=True)
class _Atom:
    name: str
    args: tuple          # per argument: a variable name, or None (a constant or an expression)


@dataclass(frozen=True)
class _Join:
    """The positive atoms of a body (or of an aggregate element's condition), its aggregates'
    and conditional literals' element joins, and for each aggregate whether it assigns a
    variable (``N = #count{...}``)."""

    atoms: tuple[_Atom, ...]
    elements: tuple[tuple["_Join", bool], ...]


@dataclass(frozen=True)
class _Statement:
    path: str
    line: int
    col: int
    text: str
    head: tuple | None   # (name, arity) of a helper's head, else None
    body: _Join


@dataclass(frozen=True)
class Sizes:
    """What the bound needs of an evidence: units, adjacent pairs, the largest number of
    neighbours of one unit, and how many units carry each geometry atom."""

    units: int
    pairs: int
    degree: int
    unary: tuple[int, int, int, int] = (0, 0, 0, 0)   # rolike, colike, halike, muldoor

    @classmethod
    def of(cls, ev) -> "Sizes":
        """The sizes of an :class:`~semmap_pp.knowledge.evidence.Evidence`."""
        deg = defaultdict(int)
        for p, q in ev.adj:
            deg[p] += 1
            deg[q] += 1
        return cls(len(ev.units), len(ev.adj), max(deg.values(), default=0),
                   tuple(len(ev.unary(name)) for name in _UNARY_EVIDENCE))

    @classmethod
    def floor(cls, units: int, neighbours: int | None = None) -> "Sizes":
        """A floor of ``units`` units with up to ``neighbours`` neighbours each, every geometry
        atom on every unit (:data:`NEIGHBOURS` by default; the yardstick of
        :func:`~semmap_pp.knowledge.dialect.load_rules` and ``semmap rules check``)."""
        d = min(NEIGHBOURS if neighbours is None else neighbours, max(units - 1, 0))
        return cls(units, units * d // 2, d, (units,) * 4)


def _atom(node) -> _Atom | None:
    """A positive symbolic atom's name and arguments (None: not a predicate atom)."""
    sym = node.symbol
    if sym.ast_type == _T.SymbolicTerm and sym.symbol.type == clingo.SymbolType.Function:
        return _Atom(sym.symbol.name, ())
    if sym.ast_type != _T.Function:
        return None
    args = []
    for a in sym.arguments:
        if a.ast_type == _T.Variable:   # each `_` a variable of its own (counted, not projected)
            args.append(f"_{next(_ANONYMOUS)}" if a.name == "_" else a.name)
        else:
            args.append(None)   # a constant filters; an expression needs its variables bound
    return _Atom(sym.name, tuple(args))


def _join(literals) -> _Join:
    atoms, elements = [], []
    for lit in literals:
        t = lit.ast_type
        if t == _T.ConditionalLiteral:
            elements.append((_join(lit.condition), False))
            continue
        if t != _T.Literal:
            continue
        a = lit.atom
        if a.ast_type == _T.SymbolicAtom:
            if lit.sign == cast.Sign.NoSign:
                got = _atom(a)
                if got is not None:
                    atoms.append(got)
        elif a.ast_type in (_T.BodyAggregate, _T.Aggregate):
            assigns = any(g is not None and g.comparison == cast.ComparisonOperator.Equal
                          and g.term.ast_type == _T.Variable
                          for g in (a.left_guard, a.right_guard))
            for el in a.elements:
                elements.append((_join(el.condition), assigns))
    return _Join(tuple(atoms), tuple(elements))


class GroundingBound:
    """An upper bound on the ground statements of a rule set, from its validated statements
    (``(path, AST statement)`` pairs, as :func:`~semmap_pp.knowledge.dialect.validate` keeps
    them); see the module docstring."""

    def __init__(self, kept):
        self.statements: list[_Statement] = []
        constants = set()
        for path, st in kept:
            for node in walk(st):
                if node.ast_type == _T.SymbolicTerm:     # a constant, a number or a string
                    constants.add(str(node.symbol))
            t = st.ast_type
            if t not in (_T.Rule, _T.Minimize):
                continue
            b = st.location.begin
            head = None
            if t == _T.Rule and st.head.atom.ast_type == _T.SymbolicAtom:
                h = _atom(st.head.atom)
                if h is not None and h.name not in _PAIRS:
                    head = (h.name, len(h.args))
            self.statements.append(_Statement(str(path), b.line, b.column, str(st), head,
                                              _join(st.body)))
        self.constants = len(constants)
        self._helpers = {s.head for s in self.statements if s.head is not None}
        # the helpers each helper's rules read (the order in which their counts are known)
        self._deps = {h: {(a.name, len(a.args)) for st in self.statements if st.head == h
                          for a in _all_atoms(st.body)} & self._helpers for h in self._helpers}

    # ------------------------------------------------------------------ counting

    def _cards(self, z: Sizes) -> dict:
        """Atom counts per predicate ``(name, arity)``, helpers included."""
        n = z.units
        cards = {("unit", 1): n, ("adj", 2): 2 * z.pairs, ("sale", 2): 2 * z.pairs}
        cards.update({(p, 1): n for p in _TYPES})
        cards.update({(p, 1): k for p, k in zip(_UNARY_EVIDENCE, z.unary)})
        dom = float(n + self.constants)
        pending = set(self._helpers)
        while pending:
            ready = [h for h in pending if not self._deps[h] & pending]
            if not ready:        # recursion through helpers: as many atoms as there can be
                cards.update({h: dom ** h[1] for h in pending})
                break
            for h in ready:
                cards[h] = min(dom ** h[1], sum(self._instances(st.body, cards, z, set())[0]
                                                for st in self.statements if st.head == h))
                pending.discard(h)
        return cards

    def _fan(self, atom: _Atom, bound: set, cards: dict, z: Sizes) -> float:
        """How many combinations ``atom`` adds given the variables ``bound``."""
        new = {v for v in atom.args if v is not None and v not in bound}
        if not new:
            return 1.0
        card = float(cards.get((atom.name, len(atom.args)), 0))
        if atom.name in _PAIRS and len(atom.args) == 2 and len(new) == 1 and \
                len(set(atom.args)) == 2:
            return min(card, float(z.degree))
        return min(card, float(z.units + self.constants) ** len(new))

    def _instances(self, join: _Join, cards: dict, z: Sizes, bound: set) -> tuple[float, float]:
        """``(instances, size)`` of a join given the variables ``bound``: its body instances,
        and those plus the elements of its aggregates and conditional literals."""
        bound = set(bound)
        todo = list(join.atoms)
        inst = 1.0
        while todo:
            fans = [self._fan(a, bound, cards, z) for a in todo]
            k = min(range(len(todo)), key=fans.__getitem__)
            inst *= fans[k]
            bound.update(v for v in todo.pop(k).args if v is not None)
            if inst == 0:
                return 0.0, 0.0
        each = [(self._instances(el, cards, z, bound)[1], assigns)
                for el, assigns in join.elements]
        for k, assigns in each:
            if assigns:                      # N = #count{...}: one instance per value of N
                inst *= k + 1
        return inst, inst * (1.0 + sum(k for k, _ in each))

    def costs(self, z: Sizes) -> list[tuple[float, _Statement]]:
        """Each statement's bound of ground statements for evidence sizes ``z``."""
        cards = self._cards(z)
        return [(STATEMENTS_PER_INSTANCE * self._instances(s.body, cards, z, set())[1], s)
                for s in self.statements]

    def total(self, z: Sizes) -> float:
        return float(sum(c for c, _ in self.costs(z)))

    def check(self, z: Sizes, limit: int | None = None, what: str = "") -> None:
        """Raise :class:`RuleError` at the statement that contributes most when the bound for
        ``z`` exceeds ``limit`` (default :data:`MAX_GROUND_STATEMENTS`; ``what`` names the world,
        default: one of ``z.units`` units)."""
        limit = MAX_GROUND_STATEMENTS if limit is None else limit
        costs = self.costs(z)
        total = sum(c for c, _ in costs)
        if total <= limit:
            return
        worst, st = max(costs, key=lambda cs: cs[0])
        what = what or f"a world of {z.units} units"
        text = st.text if len(st.text) <= 60 else st.text[:57] + "..."
        raise RuleError(st.path, f"grounding {what} could take up to {total:.3g} ground "
                        f"statements, over the limit of {limit:,}, {worst:.3g} of them from "
                        f"`{text}`: use fewer unit variables or link them by adj/2 "
                        "(docs/rules.md)", st.line, st.col)

    def limit_units(self, limit: int | None = None, most: int = 100_000) -> int | None:
        """The fewest units of a :meth:`Sizes.floor` whose bound exceeds ``limit`` (default
        :data:`MAX_GROUND_STATEMENTS`), or None when ``most`` units stay within it."""
        limit = MAX_GROUND_STATEMENTS if limit is None else limit
        if self.total(Sizes.floor(most)) <= limit:
            return None
        lo, hi = 0, most                      # total(lo) <= limit < total(hi)
        while hi - lo > 1:
            mid = (lo + hi) // 2
            if self.total(Sizes.floor(mid)) <= limit:
                lo = mid
            else:
                hi = mid
        return hi

    def largest(self, z: Sizes) -> _Statement | None:
        """The statement with the largest bound for ``z``."""
        costs = self.costs(z)
        return max(costs, key=lambda cs: cs[0])[1] if costs else None


def _all_atoms(join: _Join):
    yield from join.atoms
    for el, _ in join.elements:
        yield from _all_atoms(el)


__all__ = ["FLOOR_UNITS", "GroundingBound", "MAX_GROUND_STATEMENTS", "NEIGHBOURS", "Sizes"]
