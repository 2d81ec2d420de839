"""The rule-file dialect: loading and validating clingo rule files with clingo's AST.

A rule file is a plain clingo program restricted to what an MLN-style knowledge base needs:

* evidence predicates ``unit/1, rolike/1, colike/1, halike/1, muldoor/1, adj/2`` (facts supplied
  by the engine; a rule may derive ``adj/2``, e.g. its symmetric closure);
* query predicates ``room/1, corr/1, hall/1, other/1, sale/2``, opened by the engine's frame
  (:data:`semmap_pp.knowledge.ground.FRAME`); they may only appear in rule bodies;
* helper predicates: any other predicate that is the head of a normal rule in the loaded files;
* hard knowledge as integrity constraints ``:- body.``;
* soft knowledge as weak constraints ``:~ body. [W@0, id, terms]`` with ``W`` an integer number
  of thousandths (``2200`` means an MLN weight of 2.2) or a ``#const`` name bound to one.

Everything else that could run code or reach outside the rules folder is rejected: ``#script``,
``@``-terms, ``#external``, ``#program`` other than ``base``, ``#include`` of absolute paths or of
files outside the folder of the top-level file, choice rules, disjunctions, ``#minimize``,
``#heuristic``, ``#project``, ``#edge``, theory atoms, classical negation. So is what could make
grounding endless or clingo misbehave: intervals ``a..b`` outside facts (a fact's intervals are
written out as the facts they stand for, :func:`expand_facts`, at most
:data:`MAX_INTERVAL_FACTS` of them), derived atoms whose arguments are not
constants or variables of positive body atoms outside arithmetic (``c(X+1) :- c(X).``,
``adj(Q,P) :- adj(P,Q-5).``), integer literals beyond 32 bits
(clingo wraps them silently), non-ASCII characters outside comments and strings (clingo aborts
the process on them), and statements whose grounding could exceed
:data:`~semmap_pp.knowledge.size.MAX_GROUND_STATEMENTS` on a floor of 64 units (many free unit
variables; :mod:`semmap_pp.knowledge.size`). Every problem is a :class:`~semmap_pp.errors.RuleError`
``file:line:col: message`` (docs/robustness.md lists the cases).
"""

from __future__ import annotations

import hashlib
import itertools
import math
import os
import re
from dataclasses import dataclass, field
from pathlib import Path

import clingo
import clingo.ast as cast

from semmap_pp.errors import RuleError
from semmap_pp.knowledge import size
from semmap_pp.knowledge.rule_ast import walk


EVIDENCE_PREDICATES = {("unit", 1), ("rolike", 1), ("colike", 1), ("halike", 1),
                       ("muldoor", 1), ("adj", 2)}
SOFT_PREDICATES = ("rolike", "colike", "halike", "muldoor")
TYPE_PREDICATES = ("room", "corr", "hall", "other")  # same order as cells.UNIT_TYPES
QUERY_PREDICATES = {(p, 1) for p in TYPE_PREDICATES} | {("sale", 2)}
DERIVABLE_EVIDENCE = {("adj", 2)}
RESERVED_NAMES = {p for p, _ in EVIDENCE_PREDICATES | QUERY_PREDICATES} | {"soft"}
WEIGHT_SCALE = 1000          # weak-constraint weights are written in thousandths
MAX_WEIGHT = 50_000          # w = 50: e^-50 ~ 2e-22; anything stronger should be a hard rule
MAX_INTEGER = 2**31 - 1      # clingo's integers are 32-bit: a longer literal wraps around silently
#: The most facts the intervals of the facts of one rule set (a file and its includes) or one
#: evidence file may stand for (``unit(1..6).`` stands for six); an evidence of the largest world
#: (100,000 units) lists as many units.
MAX_INTERVAL_FACTS = 100_000

# Comments, strings, integer literals (not digits inside a name such as w1500 or X2) and
# non-ASCII characters.
_LEXEME_RE = re.compile(r'%\*.*?\*%|%[^\n]*|"(?:[^"\\\n]|\\.)*"|(?<![A-Za-z0-9_\'])\d+|[^\x00-\x7f]',
                        re.S)
_MSG_RE = re.compile(r"^(?P<file>.*?):(?P<line>\d+):(?P<col>\d+)(?:-\d+(?::\d+)?)?:\s*"
                     r"(?P<kind>error|info|warning):\s*(?P<msg>.*)$")


@dataclass(frozen=True)
class RuleSet:
    """A validated rule set.

    Attributes
    ----------
    path : str
        The top-level rule file.
    files : tuple of str
        Every file read (the top-level one first, then its includes).
    program : str
        The validated statements as clingo text (includes inlined, comments dropped).
    digest : str
        SHA-256 of ``program``: the identity of the knowledge, used in cache keys and seeds.
    n_hard, n_soft : int
        Number of integrity and weak constraints.
    helpers : tuple of str
        Helper predicates ``name/arity`` defined by the files.
    bound : GroundingBound
        An upper bound on the ground statements of any evidence
        (:class:`~semmap_pp.knowledge.size.GroundingBound`; not part of the identity).
    """

    path: str
    files: tuple[str, ...]
    program: str
    digest: str
    n_hard: int
    n_soft: int
    helpers: tuple[str, ...]
    bound: size.GroundingBound = field(compare=False, repr=False)


def _pos(text: str, index: int) -> tuple[int, int]:
    line = text.count("\n", 0, index) + 1
    col = index - (text.rfind("\n", 0, index) + 1) + 1
    return line, col


def strip_includes(text: str, path: str) -> tuple[str, list[tuple[str, int, int]]]:
    """Blank out ``#include`` directives (keeping positions) and return them.

    clingo's parser would read included files itself, so directives are removed before the text
    reaches it. Comments are read as clingo reads them (block comments ``%* ... *%`` nest) and
    blanked too, so that clingo is handed no comment at all: what it parses is exactly the text
    checked here, and no directive can hide from this reader in a comment clingo reads otherwise.
    Strings are skipped; a directive that is not ``#include "file".`` is an error.

    Returns
    -------
    text : str
        The text with each directive and each comment replaced by spaces (newlines kept).
    includes : list of (target, line, col)

    Examples
    --------
    >>> t, inc = strip_includes('a. %* %* *% #include "x.lp". *% b.', "r.lp")
    >>> inc, t.split()
    ([], ['a.', 'b.'])
    """
    nul = text.find("\0")
    if nul >= 0:       # clingo reads a C string: it would stop there, silently
        raise RuleError(path, "a NUL byte is not allowed (a rule or evidence file is text)",
                        *_pos(text, nul))
    out = list(text)
    includes = []
    i, n = 0, len(text)

    def blank(a: int, b: int) -> None:
        for k in range(a, b):
            if out[k] != "\n":
                out[k] = " "

    while i < n:
        c = text[i]
        if c == "%":
            start = i
            if text.startswith("%*", i):
                depth, i = 1, i + 2
                while i < n and depth:
                    if text.startswith("%*", i):
                        depth, i = depth + 1, i + 2
                    elif text.startswith("*%", i):
                        depth, i = depth - 1, i + 2
                    else:
                        i += 1
                if depth:
                    line, col = _pos(text, start)
                    raise RuleError(path, "block comment %* is never closed by *%", line, col)
            else:
                j = text.find("\n", i)
                i = n if j < 0 else j
            blank(start, i)
        elif c == '"':
            j = i + 1
            while j < n and text[j] != '"':
                j += 2 if text[j] == "\\" else 1
            i = j + 1
        elif text.startswith("#include", i):
            line, col = _pos(text, i)
            m = re.compile(r'#include\s*"((?:[^"\\\n]|\\.)*)"\s*\.').match(text, i)
            if m is None:
                raise RuleError(path, '#include must have the form #include "file.lp". '
                                "(library includes <...> are not allowed)", line, col)
            includes.append((m.group(1), line, col))
            blank(m.start(), m.end())
            i = m.end()
        else:
            i += 1
    return "".join(out), includes


def check_lexemes(text: str, path: str) -> None:
    """Refuse what clingo's lexer mishandles, outside comments and strings.

    * integer literals beyond clingo's 32-bit range: clingo wraps them around silently;
    * non-ASCII characters: clingo's lexer reports one byte of the character, its Python logger
      fails to decode that message, and clingo aborts the whole process ("PANIC: exception in
      nothrow scope").

    Examples
    --------
    >>> check_lexemes(':~ rolike(U). [w1@0, r, U] % 99999999999 \u00e9\\n', "r.lp")
    >>> check_lexemes(':~ rolike(U). [4294968296@0, r, U]', "r.lp")  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    semmap_pp.errors.RuleError: r.lp:1:16: integer 4294968296 is too large ...
    """
    for m in _LEXEME_RE.finditer(text):
        token = m.group()
        if len(token) == 1 and ord(token) > 0x7f:
            raise RuleError(path, f"character {token!r} (U+{ord(token):04X}) is not allowed outside "
                            "comments and strings (rule files are ASCII)", *_pos(text, m.start()))
        if token[0].isdigit() and (len(token) > 10 or int(token) > MAX_INTEGER):
            raise RuleError(path, f"integer {token[:20]}{'...' if len(token) > 20 else ''} is too "
                            f"large (clingo integers are 32-bit: at most {MAX_INTEGER})",
                            *_pos(text, m.start()))


class _Intervals(cast.Transformer):
    """Collects the intervals of a statement, or (given ``values``) puts one number in each, in
    the order clingo's transformer visits them."""

    def __init__(self, values=None):
        self.found, self.values = [], values

    def visit_Interval(self, node):
        if self.values is None:
            self.found.append(node)
            return node
        return cast.SymbolicTerm(node.location, clingo.Number(next(self.values)))


def _bound(term) -> int | None:
    """An interval's bound as an integer, when it is an integer literal (``3``, ``-3``)."""
    if term.ast_type == cast.ASTType.SymbolicTerm and term.symbol.type == clingo.SymbolType.Number:
        return term.symbol.number
    if (term.ast_type == cast.ASTType.UnaryOperation and term.operator_type == cast.UnaryOperator.Minus
            and term.argument.ast_type == cast.ASTType.SymbolicTerm
            and term.argument.symbol.type == clingo.SymbolType.Number):
        return -term.argument.symbol.number
    return None


def expand_facts(statements: list, path: str, budget: list[int] | None = None,
                 error: type = RuleError) -> list:
    """``statements`` with every fact whose atom holds intervals written out as the facts it stands
    for, as clingo reads them: ``unit(1..3).`` is ``unit(1). unit(2). unit(3).``, ``adj(1..2,3..4).``
    the four pairs, ``p(3..1).`` none. An interval's bounds must be integer literals. More than
    ``budget[0]`` facts in all (:data:`MAX_INTERVAL_FACTS`; the list is shared between the files
    of a rule set and counts down) is an ``error`` at the fact that passes it, before any is made.

    >>> sts = expand_facts(parse_text("unit(1..3). adj(1,2..3). p(X) :- unit(X).", "r.lp"), "r.lp")
    >>> [str(st) for st in sts[1:]]
    ['unit(1).', 'unit(2).', 'unit(3).', 'adj(1,2).', 'adj(1,3).', 'p(X) :- unit(X).']
    """

    budget = [MAX_INTERVAL_FACTS] if budget is None else budget
    plans = []                  # per statement: None (kept as it is) or its intervals' ranges
    for st in statements:       # every count first: a file that stands for too much makes nothing
        finder = _Intervals()
        if (st.ast_type == cast.ASTType.Rule and not len(st.body)
                and st.head.ast_type == cast.ASTType.Literal
                and st.head.atom.ast_type == cast.ASTType.SymbolicAtom):
            finder(st)
        if not finder.found:
            plans.append(None)
            continue
        ranges = []
        for node in finder.found:
            lo, hi = _bound(node.left), _bound(node.right)
            if lo is None or hi is None:
                raise error(path, f"the bounds of the interval {node} must be integers (a fact's "
                                  f"interval stands for the facts of each number in it)", *_loc(node))
            ranges.append(range(lo, hi + 1))
        count = math.prod(len(r) for r in ranges)
        if count > budget[0]:
            text = str(st.head)
            text = text if len(text) <= 60 else text[:57] + "..."
            limit = (f"; a file's facts may stand for at most {MAX_INTERVAL_FACTS:,}"
                     if budget[0] == MAX_INTERVAL_FACTS else
                     f", more than the {budget[0]:,} left of the {MAX_INTERVAL_FACTS:,} a file's facts "
                     f"(its includes too) may stand for")
            raise error(path, f"the intervals of {text} stand for {count:,} facts{limit}", *_loc(st))
        budget[0] -= count
        plans.append(ranges)
    out = []
    for st, ranges in zip(statements, plans):
        if ranges is None:
            out.append(st)
        else:
            out.extend(_Intervals(iter(values))(st) for values in itertools.product(*ranges))
    return out


def resolve_include(target: str, including: Path, root: Path, line: int, col: int) -> Path:
    """Resolve an include target; it must stay inside ``root`` (the rules folder)."""
    if os.path.isabs(target) or target.startswith("~"):
        raise RuleError(including, f"#include of an absolute path is not allowed: {target!r}",
                        line, col)
    resolved = (including.parent / target).resolve()
    if not resolved.is_relative_to(root):
        raise RuleError(including, f"#include outside the rules folder {root}: {target!r}",
                        line, col)
    if not resolved.is_file():
        raise RuleError(including, f"#include: no such file {target!r}", line, col)
    return resolved


def parse_text(text: str, path: str) -> list:
    """Parse clingo text into AST statements; a syntax error becomes a RuleError."""
    statements, messages = [], []

    def logger(code, message):
        messages.append(message)

    try:
        cast.parse_string(text, statements.append, logger=logger, message_limit=5)
    except RuntimeError:
        raise message_error(path, messages, "syntax error") from None
    return statements


def message_error(path, messages: list[str], fallback: str) -> RuleError:
    """Turn clingo's first error message ``<string>:l:c-c: error: ...`` into a RuleError."""
    for message in messages:
        lines = [s.strip() for s in message.strip().splitlines() if s.strip()]
        m = _MSG_RE.match(lines[0]) if lines else None
        if m and m.group("kind") == "error":
            detail = " ".join([m.group("msg")] + lines[1:])
            return RuleError(path, detail, int(m.group("line")), int(m.group("col")))
    detail = " ".join(" ".join(m.split()) for m in messages) or fallback
    return RuleError(path, detail)


def _loc(node) -> tuple[int, int]:
    while "location" not in node.keys():  # e.g. SymbolicAtom: its term carries the location
        node = getattr(node, node.child_keys[0])
    return node.location.begin.line, node.location.begin.column


def atom_signature(symbol_node, path) -> tuple[str, int]:
    """``(name, arity)`` of the term of a SymbolicAtom."""
    t = symbol_node.ast_type
    if t == cast.ASTType.Function:
        return symbol_node.name, len(symbol_node.arguments)
    if t == cast.ASTType.SymbolicTerm and symbol_node.symbol.type == clingo.SymbolType.Function:
        return symbol_node.symbol.name, len(symbol_node.symbol.arguments)
    if t == cast.ASTType.UnaryOperation:
        raise RuleError(path, "classical negation (-p) is not supported; use 'not p'",
                        *_loc(symbol_node))
    raise RuleError(path, f"unsupported atom {symbol_node} (pools and numbers are not atoms here)",
                    *_loc(symbol_node))


def check_head_terms(symbol, body, path) -> None:
    """A derived atom holds only values of its positive body atoms (Datalog).

    Each head argument is a constant or a variable that occurs in a positive body atom outside
    any arithmetic, so grounding can only combine the constants of the evidence and the rule
    files: no arithmetic, function terms or aggregate results in heads, which could make
    grounding endless (e.g. ``chain(X+1) :- chain(X).``), and no head variable that clingo
    solves from an arithmetic body term, which computes new values just the same
    (``adj(Q,P) :- adj(P,Q-5).`` derives ``adj(7,1)`` from ``adj(1,2)``, then ``adj(6,7)``,
    without end; found by ``bench/fuzz.py``).
    """
    bound = set()
    for lit in body:
        if (lit.ast_type == cast.ASTType.Literal and lit.sign == cast.Sign.NoSign
                and lit.atom.ast_type == cast.ASTType.SymbolicAtom):
            bound |= _plain_variables(lit.atom)
    args = symbol.arguments if symbol.ast_type == cast.ASTType.Function else []
    for arg in args:
        if arg.ast_type == cast.ASTType.SymbolicTerm:
            continue
        if arg.ast_type != cast.ASTType.Variable:
            raise RuleError(path, f"head argument {arg} must be a variable or a constant: a derived "
                            "atom cannot compute new values (they could make grounding endless)",
                            *_loc(arg))
        if arg.name not in bound:
            raise RuleError(path, f"head variable {arg.name} must occur in a positive body atom, "
                            "outside arithmetic (a derived atom holds only values of the "
                            "evidence)", *_loc(arg))


_ARITHMETIC = (cast.ASTType.BinaryOperation, cast.ASTType.UnaryOperation)


def _plain_variables(node) -> set[str]:
    """The variables of ``node`` that occur outside arithmetic terms: those a match binds to a
    value that is already there (under ``Q-5`` clingo solves ``Q`` from the value)."""
    if node.ast_type == cast.ASTType.Variable:
        return {node.name}
    if node.ast_type in _ARITHMETIC:
        return set()
    out: set[str] = set()
    for key in node.child_keys:
        value = getattr(node, key)
        if value is None:
            continue
        for item in ([value] if isinstance(value, cast.AST) else value):
            out |= _plain_variables(item)
    return out


_FORBIDDEN = {
    cast.ASTType.Script: "#script is not allowed in rule files (no code)",
    cast.ASTType.External: "#external is not allowed in rule files",
    cast.ASTType.Heuristic: "#heuristic is not allowed in rule files",
    cast.ASTType.ProjectAtom: "#project is not allowed in rule files",
    cast.ASTType.ProjectSignature: "#project is not allowed in rule files",
    cast.ASTType.Edge: "#edge is not allowed in rule files",
    cast.ASTType.TheoryDefinition: "#theory is not allowed in rule files",
    cast.ASTType.Defined: "#defined is not allowed in rule files",
}


def _weight(node, consts: dict[str, int], path) -> int:
    """Parse a weak-constraint weight: an integer literal or a #const name. No evaluation."""
    t = node.ast_type
    value = None
    if t == cast.ASTType.SymbolicTerm:
        sym = node.symbol
        if sym.type == clingo.SymbolType.Number:
            value = sym.number
        elif sym.type == clingo.SymbolType.Function and not sym.arguments and sym.name in consts:
            value = consts[sym.name]
        elif sym.type == clingo.SymbolType.Function and not sym.arguments:
            raise RuleError(path, f"weight {sym.name!r} is not a #const defined in the rule files",
                            *_loc(node))
    elif t == cast.ASTType.Function and not node.arguments and not node.external:
        if node.name not in consts:
            raise RuleError(path, f"weight {node.name!r} is not a #const defined in the rule files",
                            *_loc(node))
        value = consts[node.name]
    elif t == cast.ASTType.UnaryOperation:
        raise RuleError(path, f"negative weight {node}: write the opposite formula instead",
                        *_loc(node))
    elif t == cast.ASTType.Variable:
        raise RuleError(path, f"weight must be a constant, not the variable {node}", *_loc(node))
    if value is None:
        raise RuleError(path, f"weight {node} is not an integer number of thousandths "
                        "(write 2200 for w = 2.2)", *_loc(node))
    if value < 0:
        raise RuleError(path, f"negative weight {value}: write the opposite formula instead",
                        *_loc(node))
    if value > MAX_WEIGHT:
        raise RuleError(path, f"weight {value} is too large (at most {MAX_WEIGHT}, i.e. "
                        f"w = {MAX_WEIGHT // WEIGHT_SCALE}); use an integrity constraint for a "
                        "hard rule", *_loc(node))
    return value


def _read_files(top: Path) -> list[tuple[Path, list]]:
    """Read the top file and its includes (each once), returning parsed statements per file."""
    root = top.parent
    seen, order, stack = set(), [], [top]
    budget = [MAX_INTERVAL_FACTS]        # the facts the intervals of all the files stand for
    while stack:
        path = stack.pop()
        if path in seen:
            continue
        seen.add(path)
        if path.exists() and not path.is_file():       # a FIFO or a device is never opened
            raise RuleError(path, "cannot read rule file: not a regular file")
        try:
            text = path.read_text(encoding="utf-8")
        except (OSError, UnicodeDecodeError) as exc:
            raise RuleError(path, f"cannot read rule file: {exc}") from None
        stripped, includes = strip_includes(text, str(path))
        check_lexemes(stripped, str(path))
        statements = expand_facts(parse_text(stripped, str(path)), str(path), budget)
        order.append((path, statements))
        for target, line, col in reversed(includes):
            stack.append(resolve_include(target, path, root, line, col))
    return order


def validate(files: list[tuple[Path, list]]) -> tuple[list[tuple[Path, object]], dict, set]:
    """Check every statement; return (kept statements with their file, consts, helpers)."""
    consts: dict[str, int] = {}
    helpers: set[tuple[str, int]] = set()
    kept = []
    for path, statements in files:
        for st in statements:
            t = st.ast_type
            if t in _FORBIDDEN:
                raise RuleError(path, _FORBIDDEN[t], *_loc(st))
            _check_nodes(path, st)
            if t == cast.ASTType.Program:
                if st.name != "base" or len(st.parameters):
                    raise RuleError(path, f"#program {st.name} is not allowed: only the base "
                                    "program exists", *_loc(st))
                continue
            if t in (cast.ASTType.Comment, cast.ASTType.ShowSignature, cast.ASTType.ShowTerm):
                continue
            if t == cast.ASTType.Definition:
                v = st.value
                if not (v.ast_type == cast.ASTType.SymbolicTerm
                        and v.symbol.type == clingo.SymbolType.Number):
                    raise RuleError(path, f"#const {st.name} must be an integer literal",
                                    *_loc(st))
                if st.name in consts and consts[st.name] != v.symbol.number:
                    raise RuleError(path, f"#const {st.name} defined twice with different "
                                    "values", *_loc(st))
                consts[st.name] = v.symbol.number
                kept.append((path, st))
                continue
            if t == cast.ASTType.Minimize:
                kept.append((path, st))
                continue
            if t != cast.ASTType.Rule:
                raise RuleError(path, f"statement not allowed in rule files: {st}", *_loc(st))
            _check_head(path, st, helpers)
            kept.append((path, st))
    _check_references(kept, consts, helpers)
    return kept, consts, helpers


def _check_nodes(path: Path, st) -> None:
    """No @-term, theory atom or interval anywhere in statement ``st``."""
    for node in walk(st):
        if node.ast_type == cast.ASTType.Function and node.external:
            raise RuleError(path, f"@-terms (external function calls) are not allowed: "
                            f"@{node.name}", *_loc(node))
        if node.ast_type == cast.ASTType.TheoryAtom:
            raise RuleError(path, "theory atoms are not allowed", *_loc(node))
        if node.ast_type == cast.ASTType.Interval:
            raise RuleError(path, f"intervals ({node}) are not allowed here: a rule works "
                            "on the units of the evidence and makes no new values (a fact "
                            "may hold them: p(1..3).)", *_loc(node))


def _check_head(path: Path, st, helpers: set) -> None:
    """The head of rule ``st``: a plain atom of a helper predicate (added to ``helpers``) or of
    adj/2, or #false; never a query or evidence atom, a reserved name, a choice or disjunction."""
    head = st.head
    if head.ast_type == cast.ASTType.Literal:
        if head.atom.ast_type == cast.ASTType.BooleanConstant:
            if head.atom.value:
                raise RuleError(path, "a rule with head #true is meaningless", *_loc(st))
        elif head.atom.ast_type == cast.ASTType.SymbolicAtom:
            if head.sign != cast.Sign.NoSign:
                raise RuleError(path, "negated heads are not allowed", *_loc(head))
            sig = atom_signature(head.atom.symbol, path)
            if sig in QUERY_PREDICATES:
                raise RuleError(path, f"query atom {sig[0]}/{sig[1]} cannot be derived by "
                                "a rule: the engine opens it (constrain it with :- or :~)",
                                *_loc(head))
            if sig in EVIDENCE_PREDICATES and sig not in DERIVABLE_EVIDENCE:
                raise RuleError(path, f"evidence atom {sig[0]}/{sig[1]} cannot be derived "
                                "by a rule (only adj/2 can, e.g. its symmetric closure)",
                                *_loc(head))
            if sig[0] in RESERVED_NAMES and sig not in DERIVABLE_EVIDENCE:
                raise RuleError(path, f"{sig[0]}/{sig[1]}: {sig[0]} is a reserved "
                                "predicate name", *_loc(head))
            if sig[0].startswith("_"):
                raise RuleError(path, f"{sig[0]}/{sig[1]}: names starting with '_' are "
                                "reserved for the engine", *_loc(head))
            check_head_terms(head.atom.symbol, st.body, path)
            if sig not in DERIVABLE_EVIDENCE:
                helpers.add(sig)
        else:
            raise RuleError(path, f"unsupported rule head {head}", *_loc(st))
    else:
        raise RuleError(path, "choice rules, disjunctions and head aggregates are not "
                        "allowed: the engine's frame opens the query atoms", *_loc(st))


def _check_references(kept, consts: dict, helpers: set) -> None:
    """Every weight of a kept statement reads a known #const and has priority 0; every predicate
    is evidence, a query or defined by a rule."""
    known = EVIDENCE_PREDICATES | QUERY_PREDICATES | helpers
    for path, st in kept:
        if st.ast_type == cast.ASTType.Minimize:
            _weight(st.weight, consts, path)
            pr = st.priority
            if not (pr.ast_type == cast.ASTType.SymbolicTerm
                    and pr.symbol.type == clingo.SymbolType.Number and pr.symbol.number == 0):
                raise RuleError(path, f"priority must be 0 (write [W@0, ...]), got @{pr}",
                                *_loc(pr))
        for node in walk(st):
            if node.ast_type == cast.ASTType.SymbolicAtom:
                sig = atom_signature(node.symbol, path)
                if sig not in known:
                    raise RuleError(path, f"unknown predicate {sig[0]}/{sig[1]}: neither evidence "
                                    "(unit/1 rolike/1 colike/1 halike/1 muldoor/1 adj/2), query "
                                    "(room/1 corr/1 hall/1 other/1 sale/2) nor defined by a rule "
                                    "in the rule files", *_loc(node))


def relocate(st, path: Path):
    """Return ``st`` with its location naming ``path`` (parse_string names it ``<string>``)."""
    b, e = st.location.begin, st.location.end
    loc = cast.Location(cast.Position(str(path), b.line, b.column),
                        cast.Position(str(path), e.line, e.column))
    return st.update(location=loc)


def check_grounding(kept: list[tuple[Path, object]]) -> None:
    """Ground the statements without evidence so that clingo reports unsafe variables etc."""
    messages = []
    ctl = clingo.Control(["--warn=none"], logger=lambda code, msg: messages.append(msg),
                         message_limit=5)
    try:
        with cast.ProgramBuilder(ctl) as builder:
            for path, st in kept:
                builder.add(relocate(st, path))
        ctl.ground([("base", [])])
    except RuntimeError:
        err = message_error(None, messages, "grounding failed")
        # message_error used the file name clingo printed: restore it as the path
        for message in messages:
            m = _MSG_RE.match(message.strip().splitlines()[0])
            if m and m.group("kind") == "error":
                raise RuleError(m.group("file"), err.message, err.line, err.col) from None
        raise RuleError(kept[0][0] if kept else None, err.message) from None


def load_rules(path: str | os.PathLike) -> RuleSet:
    """Load and validate a rule file (and its includes).

    Parameters
    ----------
    path : path-like
        The top-level ``.lp`` file; includes must stay inside its folder.

    Returns
    -------
    RuleSet

    Raises
    ------
    RuleError
        ``file:line:col: message`` for the first problem found.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> d = pathlib.Path(tempfile.mkdtemp())
    >>> _ = (d / "r.lp").write_text(":~ halike(U), not hall(U). [2200@0, hh, U]\\n")
    >>> load_rules(d / "r.lp").n_soft
    1
    >>> _ = (d / "bad.lp").write_text("p(X) :- q(X).\\n")
    >>> load_rules(d / "bad.lp")  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    semmap_pp.errors.RuleError: .../bad.lp:1:9: unknown predicate q/1: ...
    """
    top = Path(path)
    if not top.is_file():
        raise RuleError(path, "not a regular file (a rule file is read, never a FIFO or device)"
                        if top.exists() else "no such rule file")
    try:
        return _load(top.resolve())
    except RecursionError:
        raise RuleError(path, "terms or expressions are nested too deeply to be read "
                              "(thousands of levels)") from None


def _load(top: Path) -> RuleSet:
    """:func:`load_rules` of a resolved regular file."""
    files = _read_files(top)
    kept, _consts, helpers = validate(files)
    check_grounding(kept)
    program = "\n".join(str(st) for _p, st in kept) + "\n"
    n_hard = sum(1 for _p, st in kept if st.ast_type == cast.ASTType.Rule
                 and st.head.ast_type == cast.ASTType.Literal
                 and st.head.atom.ast_type == cast.ASTType.BooleanConstant)
    n_soft = sum(1 for _p, st in kept if st.ast_type == cast.ASTType.Minimize)
    bound = size.GroundingBound(kept)
    bound.check(size.Sizes.floor(size.FLOOR_UNITS), what=f"a floor of {size.FLOOR_UNITS} units "
                f"({size.NEIGHBOURS} neighbours each)")
    return RuleSet(path=str(top), files=tuple(str(p) for p, _ in files), program=program,
                   digest=hashlib.sha256(program.encode()).hexdigest(), n_hard=n_hard,
                   n_soft=n_soft, helpers=tuple(sorted(f"{n}/{a}" for n, a in helpers)),
                   bound=bound)
