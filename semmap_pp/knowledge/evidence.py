"""Evidence for the knowledge engine: the :class:`Evidence` value and its fact syntax.

Hard evidence is a plain fact (``rolike(3).``); soft evidence on the unary evidence predicates
is ``soft(rolike(3), "0.8").``: the probability (a decimal string, since clingo has no
decimals) that the atom holds. It enters the network as a unit factor of weight
``log(p / (1 - p))`` on the atom, so with no rule touching it the atom's marginal is ``p``.
Evidence atoms that are neither facts nor soft are false (closed world). ``adj`` pairs are
unordered (stored ``p < q``).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from typing import Iterable, Mapping

import clingo
import clingo.ast as cast

from semmap_pp.errors import EvidenceError, RuleError
from semmap_pp.knowledge.dialect import (SOFT_PREDICATES, WEIGHT_SCALE, check_lexemes, expand_facts,
                                         strip_includes)

_PROB_RE = re.compile(r"^\d*\.?\d+(?:[eE][-+]?\d+)?$")
_WHERE = "<evidence>"


def _unary(values, name: str, units: frozenset) -> tuple[tuple[int, float], ...]:
    if isinstance(values, Mapping):
        items = values.items()
    else:
        items = ((u, 1.0) for u in values)
    out = {}
    for u, p in items:
        u = int(u)
        p = float(p)
        if u not in units:
            raise EvidenceError(_WHERE, f"{name}({u}): unit {u} is not declared by unit({u})")
        if not (0.0 <= p <= 1.0):  # also rejects NaN
            raise EvidenceError(_WHERE, f"{name}({u}): probability {p} is not in [0, 1]")
        if p > 0.0:
            out[u] = p
    return tuple(sorted(out.items()))


@dataclass(frozen=True)
class Evidence:
    """Evidence about one world: its units, geometry classes, doors and adjacency.

    Build it with :meth:`Evidence.build`, which validates and canonicalises; the value is
    hashable and is the cache key of the engine.

    Attributes
    ----------
    units : tuple of int
        Unit ids, sorted.
    rolike, colike, halike, muldoor : tuple of (unit, probability)
        Units for which the atom holds with probability 1 (hard) or ``0 < p < 1`` (soft).
    adj : tuple of (p, q)
        Adjacent pairs, ``p < q``, sorted.
    """

    units: tuple[int, ...]
    rolike: tuple[tuple[int, float], ...] = ()
    colike: tuple[tuple[int, float], ...] = ()
    halike: tuple[tuple[int, float], ...] = ()
    muldoor: tuple[tuple[int, float], ...] = ()
    adj: tuple[tuple[int, int], ...] = ()
    key: tuple = field(init=False, repr=False, compare=False)

    def __post_init__(self):
        object.__setattr__(self, "key", (self.units, self.rolike, self.colike, self.halike,
                                         self.muldoor, self.adj))

    def __hash__(self):
        return hash(self.key)

    def __eq__(self, other):
        return isinstance(other, Evidence) and self.key == other.key

    @classmethod
    def build(cls, units: Iterable[int], rolike=(), colike=(), halike=(), muldoor=(),
              adj: Iterable[tuple[int, int]] = ()) -> "Evidence":
        """Validate and canonicalise evidence.

        Parameters
        ----------
        units : iterable of int
            Unit ids (non-negative integers).
        rolike, colike, halike, muldoor : iterable of int or mapping int -> float
            A set of units (hard evidence) or a mapping unit -> probability (soft evidence;
            1 is hard, 0 is the same as absent).
        adj : iterable of (int, int)
            Adjacent pairs in any order; ``(p, p)`` is an error.

        Examples
        --------
        >>> ev = Evidence.build([2, 1], rolike={1}, muldoor={2: 0.7}, adj=[(2, 1)])
        >>> ev.adj, ev.rolike, ev.muldoor
        (((1, 2),), ((1, 1.0),), ((2, 0.7),))
        """
        us = sorted({int(u) for u in units})
        if us and us[0] < 0:
            raise EvidenceError(_WHERE, f"unit ids must be non-negative integers, got {us[0]}")
        uset = frozenset(us)
        pairs = set()
        for p, q in adj:
            p, q = int(p), int(q)
            if p == q:
                raise EvidenceError(_WHERE, f"adj({p},{q}): a unit is not adjacent to itself")
            for u in (p, q):
                if u not in uset:
                    raise EvidenceError(_WHERE, f"adj({p},{q}): unit {u} is not declared")
            pairs.add((min(p, q), max(p, q)))
        return cls(tuple(us), _unary(rolike, "rolike", uset), _unary(colike, "colike", uset),
                   _unary(halike, "halike", uset), _unary(muldoor, "muldoor", uset),
                   tuple(sorted(pairs)))

    def unary(self, name: str) -> tuple[tuple[int, float], ...]:
        """The (unit, probability) pairs of evidence predicate ``name``."""
        return getattr(self, name)


def soft_weight(p: float) -> int:
    """Soft-evidence weight in thousandths: ``round(1000 * log(p / (1 - p)))``."""
    return int(round(WEIGHT_SCALE * math.log(p / (1.0 - p))))


def ground_facts(ev: Evidence, weights: bool = True) -> str:
    """The facts the engine grounds with: hard facts plus ``__softw(atom, W)`` for soft ones.

    ``weights=False`` writes every soft atom with ``W = 0`` (open, no weak constraint): the
    evidence's *structure*, which :func:`~semmap_pp.knowledge.ground.ground` grounds once for
    every evidence that differs only in its soft probabilities."""
    parts = [f"unit({u})." for u in ev.units]
    for name in SOFT_PREDICATES:
        for u, p in ev.unary(name):
            if p >= 1.0:
                parts.append(f"{name}({u}).")
            else:
                parts.append(f"__softw({name}({u}),{soft_weight(p) if weights else 0}).")
    parts.extend(f"adj({p},{q})." for p, q in ev.adj)
    return " ".join(parts)


def evidence_to_facts(ev: Evidence) -> str:
    """Write evidence as a facts file (one fact per line) that :func:`evidence_from_facts` reads.

    Examples
    --------
    >>> ev = Evidence.build([1, 2], rolike={1}, halike={2: 0.25}, adj=[(1, 2)])
    >>> print(evidence_to_facts(ev), end="")
    unit(1).
    unit(2).
    rolike(1).
    soft(halike(2), "0.25").
    adj(1,2).
    """
    lines = [f"unit({u})." for u in ev.units]
    for name in SOFT_PREDICATES:
        for u, p in ev.unary(name):
            lines.append(f"{name}({u})." if p >= 1.0 else f'soft({name}({u}), "{p!r}").')
    lines.extend(f"adj({p},{q})." for p, q in ev.adj)
    return "\n".join(lines) + "\n"


def _fact_error(path, node, message) -> EvidenceError:
    return EvidenceError(path, message, node.location.begin.line, node.location.begin.column)


def evidence_from_facts(text: str, path: str = _WHERE) -> Evidence:
    """Read evidence facts (``unit(1). rolike(1). soft(muldoor(1), "0.7"). adj(1,2).``).

    Only ground facts of the evidence predicates and ``soft/2`` are accepted, intervals of integers
    in them standing for the facts of each number (``unit(1..6).``, at most
    :data:`~semmap_pp.knowledge.dialect.MAX_INTERVAL_FACTS` in all); anything else is an
    :class:`~semmap_pp.errors.EvidenceError` ``file:line:col: message``.

    Examples
    --------
    >>> ev = evidence_from_facts('unit(1). unit(2). colike(1). soft(muldoor(1), "0.9"). adj(2,1).')
    >>> ev.colike, ev.muldoor, ev.adj
    (((1, 1.0),), ((1, 0.9),), ((1, 2),))
    """
    statements = _parse_facts(text, path)
    units, unary, adj = [], {n: {} for n in SOFT_PREDICATES}, []
    for st in expand_facts(statements, path, error=EvidenceError):   # unit(1..6). is six facts
        t = st.ast_type
        if t in (cast.ASTType.Program, cast.ASTType.Comment):
            continue
        if (t != cast.ASTType.Rule or len(st.body) or st.head.ast_type != cast.ASTType.Literal
                or st.head.atom.ast_type != cast.ASTType.SymbolicAtom
                or st.head.sign != cast.Sign.NoSign):
            raise _fact_error(path, st, f"only ground evidence facts are allowed, got: {st}")
        try:
            sym = clingo.parse_term(str(st.head.atom.symbol))
        except RuntimeError:
            raise _fact_error(path, st, f"not a ground fact: {st}") from None
        args = sym.arguments if sym.type == clingo.SymbolType.Function else []
        sig = (sym.name, len(args)) if sym.type == clingo.SymbolType.Function else (None, 0)
        if sig == ("soft", 2):
            _soft_fact(path, st, args, unary)
            continue
        if not all(a.type == clingo.SymbolType.Number for a in args):
            text = str(sym)
            text = text if len(text) <= 80 else text[:60] + " ... " + text[-15:]
            raise _fact_error(path, st, f"evidence arguments must be integers, got {text}")
        nums = [a.number for a in args]
        if sig == ("unit", 1):
            units.append(nums[0])
        elif sig[0] in SOFT_PREDICATES and sig[1] == 1:
            if nums[0] in unary[sig[0]]:
                raise _fact_error(path, st, f"{sym} is given twice (or both hard and soft)")
            unary[sig[0]][nums[0]] = 1.0
        elif sig == ("adj", 2):
            adj.append(tuple(nums))
        else:
            raise _fact_error(path, st, f"unknown evidence predicate {sym.name}/{len(args)}: "
                              "expected unit/1 rolike/1 colike/1 halike/1 muldoor/1 adj/2 soft/2")
    try:
        return Evidence.build(units, adj=adj, **unary)
    except EvidenceError as exc:
        raise EvidenceError(path, exc.message) from None


def _parse_facts(text: str, path: str) -> list:
    """The statements of an evidence text: no #include, no lexeme clingo mishandles, and clingo's
    syntax errors as :class:`~semmap_pp.errors.EvidenceError`."""
    try:
        stripped, includes = strip_includes(text, path)
    except Exception as exc:  # RuleError from the include lexer
        raise EvidenceError(path, getattr(exc, "message", str(exc)), getattr(exc, "line", None),
                            getattr(exc, "col", None)) from None
    if includes:
        raise EvidenceError(path, "#include is not allowed in evidence", *includes[0][1:])
    try:  # what clingo's lexer mishandles (non-ASCII aborts the process) is refused first
        check_lexemes(stripped, path)
    except RuleError as exc:
        raise EvidenceError(path, exc.message, exc.line, exc.col) from None
    statements, messages = [], []
    try:
        cast.parse_string(stripped, statements.append,
                          logger=lambda c, m: messages.append(m), message_limit=3)
    except RuntimeError:
        m = re.match(r"^.*?:(\d+):(\d+)(?:-\S*)?:\s*error:\s*(.*)$",
                     (messages or ["::: error: syntax error"])[0].strip().splitlines()[0])
        if m:
            raise EvidenceError(path, m.group(3), int(m.group(1)), int(m.group(2))) from None
        raise EvidenceError(path, "syntax error") from None
    return statements


def _soft_fact(path: str, st, args, unary: dict) -> None:
    """Record ``soft(atom, "p")`` (its arguments ``args``) in ``unary``, checked."""
    atom, prob = args
    if not (atom.type == clingo.SymbolType.Function and atom.name in SOFT_PREDICATES
            and len(atom.arguments) == 1
            and atom.arguments[0].type == clingo.SymbolType.Number):
        raise _fact_error(path, st, "soft/2 takes rolike(U), colike(U), halike(U) or "
                          f"muldoor(U) first, got {atom}")
    if (prob.type != clingo.SymbolType.String or not _PROB_RE.match(prob.string)
            or not 0.0 <= float(prob.string) <= 1.0):
        raise _fact_error(path, st, f'soft evidence probability must be a string '
                          f'"0.xx" in [0, 1], got {prob}')
    u = atom.arguments[0].number
    if u in unary[atom.name]:
        raise _fact_error(path, st, f"{atom} is given twice")
    unary[atom.name][u] = float(prob.string)

