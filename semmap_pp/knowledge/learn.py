"""Learning the weights of a rule file's soft rules from labelled maps (``semmap rules learn``).

A *labelled example* is an evidence (units, geometry classes, MulDoor, adjacency: what the engine
gets for a world) together with the true type of some or all of its units
(:func:`read_example`). The weights ``w`` (MLN units, the file's thousandths / 1000) are chosen
to maximise

``Σ_examples log P(labelled types | evidence; w)  -  Σ_k (w_k - m_k)² / (2 σ²)``

with ``P`` the engine's own distribution (:mod:`~semmap_pp.knowledge.ground`: the frame, the hard
rules, the soft rules and the soft evidence). SaLe, the soft evidence atoms and the types of
unlabelled units are not observed: they are summed out. So

``log P(labels | ev) = log Z(labels clamped) - log Z``  and
``∂/∂w_k = E[n_k] - E[n_k | labels]``

where ``n_k`` counts the ground tuples of rule ``k`` that a world violates: expected counts minus
the counts the labels imply (themselves expectations over what is not observed). Both terms come
exactly from a junction tree over the example's ground network (:mod:`~semmap_pp.knowledge.exact`):
the calibrated clique beliefs give every factor's marginal. When the network of an example is too
densely connected for that (a clique above :data:`EXACT_MAX_STATES`), the example's term is the
*pseudo-likelihood* ``Σ_u log P(type_u | the other labelled types, ev)``, each term again exact
(a small tree once the other labelled units are clamped).

The prior is a Gaussian of standard deviation ``sigma`` (:data:`SIGMA`) around ``m``: the rule
file's own weights (``prior_mean="file"``, the default: a rule the data say nothing about keeps
its weight) or 0. Weights stay within the dialect's range 0 … 50 (L-BFGS-B with bounds). The
standard error of each learned weight is the square root of the diagonal of the inverse of the
negative Hessian of the objective at the optimum (observed information plus the prior's
``1/σ²``), the Hessian taken by central differences of the exact gradient.

Parameters are the file's weights as written: a literal weight is one parameter, a ``#const``
name is one parameter shared by every rule that uses it (tied weights). Weights written in an
included file stay fixed (only the top-level file is rewritten).
"""

from __future__ import annotations

import math
import re
import shutil
import tempfile
import textwrap
from dataclasses import dataclass, field, replace
from pathlib import Path

import clingo
import clingo.ast as cast
import numpy as np
from scipy.optimize import minimize

from semmap_pp.cells import UNIT_TYPES
from semmap_pp.errors import EvidenceError, RuleError
from semmap_pp.knowledge.dialect import (MAX_WEIGHT, WEIGHT_SCALE, RuleSet, _read_files,
                                         check_lexemes, load_rules, strip_includes, validate)
from semmap_pp.knowledge.evidence import Evidence, evidence_from_facts, ground_facts
from semmap_pp.knowledge.exact import JunctionTree, TooDense, calibrate, scope_marginal
from semmap_pp.knowledge.ground import _build, _check_size, _clingo_ground, _with_soft_weights
from semmap_pp.knowledge.engine import KnowledgeEngine

#: Default standard deviation of the Gaussian prior on each weight (MLN units: 1.0 = 1000
#: thousandths). A weight of the file is believed to within about ±1 before any data.
SIGMA = 1.0
#: Largest junction-tree clique (joint states) for the exact likelihood of one example; a denser
#: example's term is the pseudo-likelihood.
EXACT_MAX_STATES = 1 << 18
#: Step of the central differences of the gradient that give the Hessian (MLN units).
HESSIAN_STEP = 1e-4
#: Predicates of a labelled example besides the evidence: ``label(U, T)`` (unit U has type T),
#: ``cells(U, T, N)`` (N truth cells of type T lie in unit U) and ``uncovered(T, N)`` (N truth cells
#: of type T lie in no unit), T one of room, corridor, hall, other.
LABEL_PREDICATES = {("label", 2), ("cells", 3), ("uncovered", 2)}


# ---- the rule file's parameters -----------------------------------------------------------------

@dataclass
class Parameter:
    """One learnable weight: a literal weight of one soft rule, or a ``#const`` of several.

    Attributes
    ----------
    name : str
        The rule's id (its first term) or the ``#const`` name.
    value : int
        The weight in the file (thousandths).
    rules : list of int
        Indices of the soft rules (in program order) that carry it.
    learnable : bool
        False for a weight written in an included file (kept as it is).
    const : bool
        Whether it is a ``#const`` name.
    where : tuple (path, line, col_begin, col_end) or None
        The span of the number to rewrite (the literal, or the value of the ``#const``), and
        ``end_line``: the last line of the statement, where the comment goes.
    """

    name: str
    value: int
    rules: list
    learnable: bool
    const: bool
    where: tuple | None = None
    end_line: int | None = None


@dataclass
class SoftRules:
    """The soft rules of a rule file and their parameters (:func:`soft_rules`)."""

    rules: RuleSet
    ids: list              # rule index -> its id (first term of its tuple)
    params: list           # Parameter
    tagged: RuleSet        # the program with rule k at priority k + 1 and weight 1

    @property
    def rule_param(self) -> list:
        """Rule index -> parameter index."""
        out = [0] * len(self.ids)
        for j, p in enumerate(self.params):
            for k in p.rules:
                out[k] = j
        return out

    def weights(self, values) -> np.ndarray:
        """Per-rule weights (MLN units) for parameter values (MLN units)."""
        v = np.asarray(values, dtype=np.float64)
        return v[np.asarray(self.rule_param, dtype=np.int64)] if self.ids else np.zeros(0)

    def matrix(self) -> np.ndarray:
        """``A`` with ``weights = A @ values`` (rules x parameters)."""
        a = np.zeros((len(self.ids), len(self.params)))
        for j, p in enumerate(self.params):
            a[p.rules, j] = 1.0
        return a


def soft_rules(path) -> SoftRules:
    """Load ``path`` and name its soft rules' parameters.

    Raises
    ------
    RuleError
        Whatever :func:`~semmap_pp.knowledge.dialect.load_rules` raises; a file with no soft rule
        (nothing to learn); two soft rules with the same id (clingo would count their violations
        as one, so they could not get weights of their own).
    """
    rules = load_rules(path)
    top = Path(rules.path)
    files = _read_files(top)
    kept, consts, _helpers = validate(files)
    if rules.n_soft == 0:
        raise RuleError(rules.path, "has no soft rule (:~ body. [W@0, id, Vars]): there is no "
                                    "weight to learn")
    const_where = {}
    for fpath, st in kept:
        if st.ast_type == cast.ASTType.Definition and st.name not in const_where:
            loc = st.value.location
            const_where[st.name] = (fpath, loc.begin.line, loc.begin.column, loc.end.column,
                                    st.location.end.line)
    ids, params, by_const, seen = [], [], {}, {}
    statements = []
    k = 0
    for fpath, st in kept:
        if st.ast_type != cast.ASTType.Minimize:
            statements.append(str(st))
            continue
        rid = str(st.terms[0]) if len(st.terms) else f"rule{k + 1}"
        if rid in seen:
            raise RuleError(fpath, f"soft rules {seen[rid]} and {k + 1} share the id {rid!r}: "
                            "clingo counts their violations once, so they cannot be given weights "
                            "of their own; give each soft rule its own id",
                            st.location.begin.line, st.location.begin.column)
        seen[rid] = k + 1
        ids.append(rid)
        w = st.weight
        name = _const_name(w)
        learnable = Path(fpath) == top
        if name is not None:
            if name not in by_const:
                cw = const_where.get(name)
                by_const[name] = len(params)
                params.append(Parameter(name, int(consts[name]), [], cw is not None and
                                        Path(cw[0]) == top, True, cw and cw[:4],
                                        cw and cw[4]))
            params[by_const[name]].rules.append(k)
        else:
            loc = w.location
            params.append(Parameter(rid, int(w.symbol.number), [k], learnable, False,
                                    (fpath, loc.begin.line, loc.begin.column, loc.end.column),
                                    st.location.end.line))
        one = cast.SymbolicTerm(w.location, clingo.Number(1))
        prio = cast.SymbolicTerm(st.priority.location, clingo.Number(k + 1))
        statements.append(str(st.update(weight=one, priority=prio)))
        k += 1
    tagged = replace(rules, program="\n".join(statements) + "\n")
    return SoftRules(rules, ids, params, tagged)


def _const_name(node) -> str | None:
    if node.ast_type == cast.ASTType.SymbolicTerm:
        sym = node.symbol
        return sym.name if sym.type == clingo.SymbolType.Function else None
    if node.ast_type == cast.ASTType.Function:
        return node.name
    return None


# ---- labelled examples ------------------------------------------------------------------------

@dataclass
class Example:
    """A labelled evidence (:func:`read_example`).

    Attributes
    ----------
    path : str
    evidence : Evidence
    labels : dict int -> tuple of int
        Unit -> the indices in :data:`~semmap_pp.cells.UNIT_TYPES` its true type is one of (one
        ``label`` fact: that type; several: any of them, e.g. room, hall or other for a truth
        that knows rooms and corridors only).
    cells : dict int -> ndarray (4,)
        Unit -> its truth cells of each type (empty when the file gives none).
    uncovered : ndarray (4,)
        Truth cells of each type that no unit covers.
    """

    path: str
    evidence: Evidence
    labels: dict
    cells: dict = field(default_factory=dict)
    uncovered: np.ndarray = field(default_factory=lambda: np.zeros(4, np.int64))

    def __post_init__(self):
        # a single type index stands for the set of that type alone
        self.labels = {u: tuple(sorted(set(t))) if isinstance(t, (tuple, list, set, frozenset))
                       else (int(t),) for u, t in self.labels.items()}


def _type_index(sym, path, st) -> int:
    name = sym.name if sym.type == clingo.SymbolType.Function and not sym.arguments else None
    if name not in UNIT_TYPES:
        raise EvidenceError(path, f"a type is one of {', '.join(UNIT_TYPES)}, got {sym}",
                            st.location.begin.line, st.location.begin.column)
    return UNIT_TYPES.index(name)


def _count(sym, path, st) -> int:
    if sym.type != clingo.SymbolType.Number or sym.number < 0:
        raise EvidenceError(path, f"a cell count is an integer >= 0, got {sym}",
                            st.location.begin.line, st.location.begin.column)
    return sym.number


def example_from_text(text: str, path: str) -> Example:
    """A labelled example from the text of a labelled evidence file: the evidence facts of
    ``semmap rules evidence`` (:func:`~semmap_pp.knowledge.evidence.evidence_from_facts`) plus
    ``label(U, T).`` facts (several for one unit: its type is one of them), and optionally ``cells(U, T, N).`` and ``uncovered(T, N).``
    (:data:`LABEL_PREDICATES`). Errors are :class:`~semmap_pp.errors.EvidenceError`
    ``file:line:col: message``.

    >>> ex = example_from_text("unit(1). unit(2). rolike(1). adj(1,2). label(1, room). "
    ...                        "label(2, corridor). cells(1, room, 40).", "ex.lp")
    >>> ex.labels, ex.cells[1].tolist()
    ({1: (0,), 2: (1,)}, [40, 0, 0, 0])
    """
    try:
        stripped, includes = strip_includes(text, path)
        check_lexemes(stripped, path)
    except RuleError:
        return _as_example(evidence_from_facts(text, path), path)   # raises its EvidenceError
    if includes:
        raise EvidenceError(path, "#include is not allowed in evidence", *includes[0][1:])
    statements = []
    try:
        cast.parse_string(stripped, statements.append, logger=lambda c, m: None, message_limit=0)
    except RuntimeError:
        evidence_from_facts(stripped, path)       # raises the syntax error with its position
        raise EvidenceError(path, "syntax error") from None
    lines = stripped.split("\n")
    labels, cells, uncovered = {}, {}, np.zeros(4, np.int64)
    for st in statements:
        if (st.ast_type != cast.ASTType.Rule or len(st.body)
                or st.head.ast_type != cast.ASTType.Literal
                or st.head.atom.ast_type != cast.ASTType.SymbolicAtom):
            continue
        try:
            sym = clingo.parse_term(str(st.head.atom.symbol))
        except RuntimeError:
            continue
        if sym.type != clingo.SymbolType.Function or (sym.name, len(sym.arguments)) not in \
                LABEL_PREDICATES:
            continue
        args = sym.arguments
        if sym.name == "uncovered":
            uncovered[_type_index(args[0], path, st)] += _count(args[1], path, st)
        else:
            if args[0].type != clingo.SymbolType.Number:
                raise EvidenceError(path, f"a unit is an integer, got {args[0]}",
                                    st.location.begin.line, st.location.begin.column)
            u, t = args[0].number, _type_index(args[1], path, st)
            if sym.name == "label":
                labels[u] = tuple(sorted(set(labels.get(u, ())) | {t}))
            else:
                cells.setdefault(u, np.zeros(4, np.int64))[t] += _count(args[2], path, st)
        _blank(lines, st.location)
    ev = evidence_from_facts("\n".join(lines), path)
    units = set(ev.units)
    for u in list(labels) + list(cells):
        if u not in units:
            raise EvidenceError(path, f"unit {u} is labelled but is not a unit of the evidence")
    return Example(path, ev, labels, cells, uncovered)


def _as_example(ev, path):      # pragma: no cover - evidence_from_facts raised before
    return Example(path, ev, {})


def _blank(lines: list, loc) -> None:
    """Replace the text of ``loc`` (1-based lines and byte columns, end exclusive) by spaces."""
    b, e = loc.begin, loc.end
    for ln in range(b.line, e.line + 1):
        raw = lines[ln - 1].encode("utf-8")
        lo = b.column - 1 if ln == b.line else 0
        hi = e.column - 1 if ln == e.line else len(raw)
        raw = raw[:lo] + b" " * (hi - lo) + raw[hi:]
        lines[ln - 1] = raw.decode("utf-8")


def read_example(path) -> Example:
    """:func:`example_from_text` of the file ``path``; one that labels no unit is an error."""
    p = Path(path)
    if not p.is_file():
        raise EvidenceError(p, "not a regular file" if p.exists() else "no such file")
    try:
        text = p.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise EvidenceError(p, f"cannot read labelled evidence: {exc}") from None
    ex = example_from_text(text, str(p))
    if not ex.labels:
        raise EvidenceError(p, "labels no unit: a labelled example needs label(U, T) facts "
                               "(T one of room, corridor, hall, other; docs/rules.md)")
    return ex


def data_files(paths) -> list[Path]:
    """The labelled evidence files named by ``paths``: a file itself, a directory its ``*.lp``
    files (sorted, not recursive). A missing path or a directory without one is an error."""
    out = []
    for path in paths:
        p = Path(path)
        if p.is_dir():
            found = sorted(f for f in p.glob("*.lp") if f.is_file())
            if not found:
                raise EvidenceError(p, "holds no labelled evidence file (*.lp); write them with "
                                       "`semmap rules label` (docs/rules.md)")
            out.extend(found)
        elif p.exists():
            out.append(p)
        else:
            raise EvidenceError(p, "no such file or directory")
    if not out:
        raise EvidenceError(None, "no labelled data given (--data FILE_OR_DIR)")
    return out


def read_data(paths) -> list[Example]:
    """Every labelled example of :func:`data_files` ``(paths)``."""
    return [read_example(f) for f in data_files(paths)]


# ---- the likelihood of one example ------------------------------------------------------------

class _Network:
    """The ground network of one example, its soft factors split into the rules' features and
    the fixed rest (hard rules, soft evidence)."""

    def __init__(self, sr: SoftRules, ex: Example):
        ev = ex.evidence
        _check_size(sr.rules, ev)
        obs, _ctl = _clingo_ground(sr.tagged, ground_facts(ev, weights=False))
        tags: list = []
        net = _build(sr.rules.path, ev, obs, None, tags=tags)
        net = _with_soft_weights(net, ev)
        self.card = [int(c) for c in net.card]
        self.units = net.units
        self.fixed = [(tuple(s), np.where(v, -np.inf, 0.0)) for s, v in net.hard]
        self.features = []            # (scope, table 0/1, rule, count)
        for k, (s, t, w) in enumerate(net.soft):
            prio = tags[k] if k < len(tags) else 0
            if prio >= 1:
                self.features.append((tuple(s), np.asarray(t, np.float64), prio - 1, int(w)))
            else:
                self.fixed.append((tuple(s), -(w / WEIGHT_SCALE) * np.asarray(t, np.float64)))
        self.n_rules = len(sr.ids)
        index = {u: i for i, u in enumerate(self.units)}
        self.clamp = {index[u]: tuple(t) for u, t in ex.labels.items()}

    def groundings(self) -> np.ndarray:
        """Ground tuples of each rule in this network (those a world can violate)."""
        out = np.zeros(self.n_rules)
        for _s, _t, k, c in self.features:
            out[k] += 1
        return out


def _reduce(scope, table, clamp, new_index):
    """``table`` over ``scope`` with the variables clamped to one state fixed (``clamp``: var ->
    state): (reduced scope, table)."""
    idx = tuple(clamp[v] if v in clamp else slice(None) for v in scope)
    rest = tuple(new_index[v] for v in scope if v not in clamp)
    return rest, table[idx]


def _split_clamp(clamp: dict) -> tuple[dict, dict]:
    """``clamp`` (var -> allowed states) as (var -> its one state, var -> allowed states of the
    variables that may take several)."""
    one = {v: s[0] for v, s in clamp.items() if len(s) == 1}
    many = {v: s for v, s in clamp.items() if len(s) > 1}
    return one, many


class _Term:
    """log Z and the expected rule counts of an example's network with some type variables
    clamped (var -> the states allowed), as functions of the rule weights (one junction tree,
    built once)."""

    def __init__(self, net: _Network, clamp_sets: dict, max_states: int):
        clamp, many = _split_clamp(clamp_sets)
        free = [v for v in range(len(net.card)) if v not in clamp]
        new_index = {v: i for i, v in enumerate(free)}
        self.card = [net.card[v] for v in free]
        k = net.n_rules
        fixed, stack = {}, {}
        self.const_fixed = 0.0
        self.const_counts = np.zeros(k)
        masks = []
        for v, states in many.items():
            m = np.full(net.card[v], -np.inf)
            m[list(states)] = 0.0
            masks.append(((v,), m))
        for s, t in net.fixed + masks:
            rs, rt = _reduce(s, t, clamp, new_index)
            if not rs:
                self.const_fixed += float(rt)
            else:
                fixed[rs] = fixed[rs] + rt if rs in fixed else np.array(rt, np.float64)
        for s, t, r, c in net.features:
            rs, rt = _reduce(s, t, clamp, new_index)
            if not rs:
                self.const_counts[r] += c * float(rt)
                continue
            if rs not in stack:
                stack[rs] = np.zeros((k,) + rt.shape)
            stack[rs][r] += c * rt
        scopes = sorted(set(fixed) | set(stack))
        self.scopes = scopes
        self.fixed = [fixed.get(s, 0.0) for s in scopes]
        self.stack = [stack.get(s) for s in scopes]
        self.jt = JunctionTree(self.card, scopes, max_states=max_states) if self.card else None
        self.largest = self.jt.largest if self.jt is not None else 1

    def value(self, w: np.ndarray) -> tuple[float, np.ndarray]:
        """``(log Z, E[n])`` at rule weights ``w`` (MLN units); log Z is -inf when the hard
        rules (or the clamped labels) admit no world."""
        logz = self.const_fixed - float(w @ self.const_counts)
        expect = self.const_counts.copy()
        if self.jt is None or not np.isfinite(logz):
            return logz, expect
        pots = []
        for s, f, st in zip(self.scopes, self.fixed, self.stack):
            t = f if st is None else f - np.tensordot(w, st, axes=1)
            pots.append((s, np.broadcast_to(t, tuple(self.card[v] for v in s)).astype(np.float64)))
        lz, marg, full = calibrate(self.jt, pots, return_beliefs=True)
        if marg is None:
            return -math.inf, expect
        for s, st in zip(self.scopes, self.stack):
            if st is not None:
                pm = scope_marginal(self.jt, full, s)
                expect += st.reshape(st.shape[0], -1) @ pm.reshape(-1)
        return logz + lz, expect


class ExampleLikelihood:
    """The log likelihood of the labels of the examples that share one evidence, and its
    gradient in the rule weights: exact, or the pseudo-likelihood when the evidence's network is
    too dense (:attr:`method`). The network is ground once; for the exact likelihood so is the
    unclamped term, which every labelling of the evidence shares."""

    def __init__(self, sr: SoftRules, examples, objective: str = "auto",
                 max_states: int = EXACT_MAX_STATES):
        ex = examples[0]
        self.path = ex.path
        self.paths = [e.path for e in examples]
        net = _Network(sr, ex)
        self.net = net
        index = {u: i for i, u in enumerate(net.units)}
        clamps: dict = {}
        for e in examples:
            key = tuple(sorted((index[u], tuple(t)) for u, t in e.labels.items()))
            clamps[key] = clamps.get(key, 0) + 1
        self.count = len(examples)
        self.n_labels = sum(len(e.labels) for e in examples)
        self.observed = [(n, _Term(net, dict(k), max_states=1 << 22)) for k, n in clamps.items()]
        for (k, _n), (_n2, term) in zip(clamps.items(), self.observed):
            if not np.isfinite(term.value(np.zeros(net.n_rules))[0]):
                bad = next(e.path for e in examples
                           if tuple(sorted((index[u], tuple(t)) for u, t in e.labels.items())) == k)
                raise EvidenceError(bad, "the labels break the hard rules of the rule file: no "
                                         "world has them")
        self.free = None
        if objective in ("auto", "exact"):
            try:
                self.free = _Term(net, {}, max_states)
                self.method = "exact"
            except TooDense:
                if objective == "exact":
                    raise RuleError(sr.rules.path, f"{ex.path}: the network is too densely "
                                    f"connected for the exact likelihood (a clique above "
                                    f"{max_states} states); use the pseudo-likelihood") from None
        if self.free is None:
            self.method = "pseudo"
            self.pseudo = [[_Term(net, {v: s for v, s in k if v != u}, 1 << 22) for u, _s in k]
                           for k in clamps]

    def value(self, w: np.ndarray) -> tuple[float, np.ndarray]:
        """``(log likelihood, gradient)`` at rule weights ``w``, summed over the examples."""
        ll, grad = 0.0, np.zeros_like(w)
        if self.method == "exact":
            lf, ef = self.free.value(w)
            for n, term in self.observed:
                lo, eo = term.value(w)
                ll += n * (lo - lf)
                grad += n * (ef - eo)
            return ll, grad
        for (n, term), others in zip(self.observed, self.pseudo):
            lo, eo = term.value(w)
            for t in others:
                lf, ef = t.value(w)
                ll += n * (lo - lf)
                grad += n * (ef - eo)
        return ll, grad


# ---- the fit ----------------------------------------------------------------------------------

@dataclass
class Learned:
    """The result of :func:`learn`.

    Attributes
    ----------
    soft : SoftRules
    values : ndarray
        Learned parameter values (MLN units), rounded to thousandths.
    start : ndarray
        The file's values (MLN units).
    se : ndarray
        Standard error of each parameter (MLN units; the prior's ``sigma`` for one the data do
        not inform; NaN for a fixed one).
    groundings : ndarray
        Ground tuples of each parameter's rules over the data.
    at_bound : list of bool
        Parameters that ended at 0 or at the dialect's maximum.
    methods : dict str -> str
        Example path -> "exact" or "pseudo".
    log_likelihood : float
        Σ log (pseudo-)likelihood at the learned values; ``start_log_likelihood`` at the file's.
    """

    soft: SoftRules
    values: np.ndarray
    start: np.ndarray
    se: np.ndarray
    groundings: np.ndarray
    at_bound: list
    methods: dict
    log_likelihood: float
    start_log_likelihood: float
    sigma: float
    prior_mean: str
    n_examples: int
    n_labels: int
    iterations: int


class Objective:
    """The negative log posterior of the parameters over a set of examples and its gradient."""

    def __init__(self, sr: SoftRules, examples, sigma: float = SIGMA, prior_mean: str = "file",
                 objective: str = "auto", max_states: int = EXACT_MAX_STATES):
        if sigma <= 0 or not math.isfinite(sigma):
            raise RuleError(sr.rules.path, f"the prior's sigma must be a positive number, got "
                                           f"{sigma}")
        if prior_mean not in ("file", "zero"):
            raise RuleError(sr.rules.path, f"prior mean {prior_mean!r}: use 'file' or 'zero'")
        if objective not in ("auto", "exact", "pseudo"):
            raise RuleError(sr.rules.path, f"objective {objective!r}: use auto, exact or pseudo")
        self.sr, self.sigma = sr, float(sigma)
        groups: dict = {}
        for ex in examples:
            groups.setdefault(ex.evidence.key, []).append(ex)
        self.terms = [ExampleLikelihood(sr, g, objective, max_states) for g in groups.values()]
        self.a = sr.matrix()
        self.start = np.array([p.value / WEIGHT_SCALE for p in sr.params])
        self.mean = self.start.copy() if prior_mean == "file" else np.zeros(len(sr.params))
        self.learnable = np.array([p.learnable for p in sr.params], dtype=bool)

    def full(self, free: np.ndarray) -> np.ndarray:
        """All parameter values from the learnable ones (the fixed keep the file's)."""
        v = self.start.copy()
        v[self.learnable] = free
        return v

    def log_likelihood(self, values: np.ndarray) -> tuple[float, np.ndarray]:
        """Σ of the examples' log (pseudo-)likelihoods and its gradient in the parameters."""
        w = self.a @ values
        ll, g = 0.0, np.zeros(len(w))
        for t in self.terms:
            a, b = t.value(w)
            ll += a
            g += b
        return ll, self.a.T @ g

    def __call__(self, free: np.ndarray) -> tuple[float, np.ndarray]:
        """Negative log posterior of the learnable parameters and its gradient."""
        v = self.full(free)
        ll, g = self.log_likelihood(v)
        d = (v - self.mean) / self.sigma ** 2
        f = -ll + 0.5 * float(np.sum(((v - self.mean) ** 2)[self.learnable])) / self.sigma ** 2
        return f, (-g + d)[self.learnable]


def learn(path, examples, sigma: float = SIGMA, prior_mean: str = "file",
          objective: str = "auto", max_states: int = EXACT_MAX_STATES) -> Learned:
    """Fit the soft weights of the rule file ``path`` to ``examples`` (see the module docstring).

    Raises
    ------
    RuleError
        The file has no soft rule, or none whose weight is written in it.
    EvidenceError
        An example's labels break the hard rules.
    """

    sr = path if isinstance(path, SoftRules) else soft_rules(path)
    if not examples:
        raise EvidenceError(None, "no labelled example to learn from")
    obj = Objective(sr, examples, sigma, prior_mean, objective, max_states)
    if not obj.learnable.any():
        raise RuleError(sr.rules.path, "every soft weight is written in an included file; only "
                                       "the top-level file's weights are learned")
    hi = MAX_WEIGHT / WEIGHT_SCALE
    x0 = np.clip(obj.start[obj.learnable], 0.0, hi)
    res = minimize(obj, x0, jac=True, method="L-BFGS-B", bounds=[(0.0, hi)] * len(x0),
                   options={"maxiter": 500, "ftol": 1e-12, "gtol": 1e-7})
    free = np.round(res.x * WEIGHT_SCALE) / WEIGHT_SCALE
    values = obj.full(free)
    se = np.full(len(values), np.nan)
    se[obj.learnable] = standard_errors(obj, free)
    groundings = obj.a.T @ sum((t.count * t.net.groundings() for t in obj.terms),
                               np.zeros(len(sr.ids)))
    at_bound = [bool(p.learnable and (v <= 0.0 or v >= hi)) for p, v in zip(sr.params, values)]
    return Learned(sr, values, obj.start, se, groundings, at_bound,
                   {p: t.method for t in obj.terms for p in t.paths}, obj.log_likelihood(values)[0],
                   obj.log_likelihood(obj.start)[0], obj.sigma, prior_mean, len(examples),
                   sum(t.n_labels for t in obj.terms), int(res.nit))


def hessian(obj: Objective, free: np.ndarray, step: float = HESSIAN_STEP) -> np.ndarray:
    """Hessian of the negative log posterior at ``free`` by central differences of the exact
    gradient (symmetrised)."""
    n = len(free)
    h = np.zeros((n, n))
    for j in range(n):
        e = np.zeros(n)
        e[j] = step
        h[:, j] = (obj(free + e)[1] - obj(free - e)[1]) / (2 * step)
    return 0.5 * (h + h.T)


def standard_errors(obj: Objective, free: np.ndarray) -> np.ndarray:
    """``sqrt(diag(H^-1))`` of the negative log posterior's Hessian at ``free`` (the prior makes
    it positive definite for the exact likelihood; a non-positive diagonal entry of the inverse,
    possible with unobserved variables, is NaN)."""
    h = hessian(obj, free)
    try:
        cov = np.linalg.inv(h)
    except np.linalg.LinAlgError:
        cov = np.linalg.pinv(h)
    d = np.diag(cov)
    return np.where(d > 0, np.sqrt(np.abs(d)), np.nan)


# ---- typing with given weights, and the score of a typing --------------------------------------

def map_types(sr: SoftRules, values, ex: Example) -> dict:
    """The MAP types (unit -> type index) of ``ex``'s evidence under the rule file with the
    parameters ``values`` (MLN units): the engine's own MAP (types and SaLe maximised, soft
    evidence summed out), on a rule set whose weights are the rounded values."""
    r = _engine_with(sr, values).infer(ex.evidence)
    return {u: UNIT_TYPES.index(t) for u, t in r.map_types.items()}


_ENGINES: dict = {}


def _engine_with(sr: SoftRules, values):
    """A :class:`~semmap_pp.knowledge.engine.KnowledgeEngine` over the rule file with the
    parameter ``values``: the rewritten file read from a temporary folder, its includes copied
    beside it (they lie in the file's folder), so it is validated as any rule file is."""

    text = rewritten_text(sr, values)
    key = (sr.rules.path, text)
    eng = _ENGINES.get(key)
    if eng is None:
        top = Path(sr.rules.path)
        with tempfile.TemporaryDirectory(prefix="semmap-learn-") as d:
            for f in sr.rules.files[1:]:
                dest = Path(d) / Path(f).relative_to(top.parent)
                dest.parent.mkdir(parents=True, exist_ok=True)
                shutil.copyfile(f, dest)
            (Path(d) / top.name).write_text(text, encoding="utf-8")
            rs = load_rules(Path(d) / top.name)
        eng = KnowledgeEngine(replace(rs, path=str(top)), template_store=False)
        if len(_ENGINES) > 32:
            _ENGINES.clear()
        _ENGINES[key] = eng
    return eng


def correct_cells(t_true: int, t_pred: int) -> bool:
    """Whether a truth cell of type ``t_true`` is right under the prediction ``t_pred``: the ipa
    score's reading (:mod:`semmap_pp.evaluate.types`), where a hall or an *other* is a room."""
    room = UNIT_TYPES.index("room")
    return t_true == t_pred or (t_true == room and UNIT_TYPES[t_pred] in ("hall", "other"))


def score(ex: Example, types: dict) -> dict:
    """How well ``types`` (unit -> type index) match ``ex``: unit accuracy over the labelled
    units (right when the type is among the unit's labels), and when the example has cell counts the per-cell accuracy (cells of no unit count as
    wrong) and the recall of room and corridor cells, as :func:`semmap_pp.evaluate.type_accuracy`
    scores a type map against the ipa truth."""
    lab = ex.labels
    unit_acc = (sum(types[u] in t for u, t in lab.items()) / len(lab)) if lab else float("nan")
    out = {"units": len(lab), "unit_accuracy": unit_acc}
    if ex.cells:
        good = np.zeros(4)
        total = ex.uncovered.astype(np.float64).copy()
        for u, c in ex.cells.items():
            total += c
            for t in range(4):
                if c[t] and correct_cells(t, types[u]):
                    good[t] += c[t]
        n = total.sum()
        out["cells"] = int(n)
        out["cell_accuracy"] = float(good.sum() / n) if n else float("nan")
        for name in ("room", "corridor"):
            k = UNIT_TYPES.index(name)
            out[f"recall_{name}"] = float(good[k] / total[k]) if total[k] else float("nan")
    return out


# ---- the learned file --------------------------------------------------------------------------

_NOTE_RE = re.compile(r"\s*% learned: .*$")
HEADER = "%% learned by `semmap rules learn`"


def rewritten_text(sr: SoftRules, values, notes: dict | None = None, header=()) -> str:
    """The top-level rule file's text with each learnable parameter's number replaced by
    ``round(1000 * value)``; ``notes`` (parameter index -> text) become a ``% learned: TEXT``
    comment at the end of the statement's last line (an earlier such comment is replaced), and
    ``header`` lines open the file after a previous header of this kind is dropped."""
    top = Path(sr.rules.path)
    lines = top.read_text(encoding="utf-8").split("\n")
    edits = {}
    for j, p in enumerate(sr.params):
        if not p.learnable or p.where is None:
            continue
        _f, line, c0, c1 = p.where
        edits.setdefault(line, []).append((c0, c1, str(int(round(values[j] * WEIGHT_SCALE)))))
    for line, spans in edits.items():
        raw = lines[line - 1].encode("utf-8")
        for c0, c1, text in sorted(spans, reverse=True):
            raw = raw[:c0 - 1] + text.encode() + raw[c1 - 1:]
        lines[line - 1] = raw.decode("utf-8")
    for j, note in (notes or {}).items():
        p = sr.params[j]
        if p.end_line is None:
            continue
        k = p.end_line - 1
        lines[k] = _NOTE_RE.sub("", lines[k]) + f"  % learned: {note}"
    if lines and lines[0].startswith(HEADER):        # the header of an earlier learning
        while lines and lines[0].startswith("%% "):
            lines.pop(0)
    return "\n".join([*header, *lines])


def learned_text(result: Learned, data_desc: str) -> str:
    """The learned rule file: the input file with the learned weights, a comment with each
    one's standard error, and a header saying how they were learned."""
    sr = result.soft
    notes = {}
    for j, p in enumerate(sr.params):
        if not p.learnable:
            continue
        w, se, g = result.values[j], result.se[j], int(result.groundings[j])
        bound = " (at the bound)" if result.at_bound[j] else ""
        notes[j] = (f"w = {w:.3f} +- {se:.3f} s.e.{bound}, file {result.start[j]:.3f}, "
                    f"{g} ground tuples in the data")
    methods = sorted(set(result.methods.values()))
    header = [f"{HEADER} (docs/rules.md, \"Learning weights\"). Data: {data_desc}; "
              f"{result.n_examples} examples, {result.n_labels} "
              f"labelled units, {'/'.join(methods)} likelihood, Gaussian prior sigma "
              f"{result.sigma:g} around the {'weights of the input file' if result.prior_mean == 'file' else 'zero weight'};",
              f"%% log likelihood {result.start_log_likelihood:.3f} with the input weights, "
              f"{result.log_likelihood:.3f} with the learned ones. Each learned weight's comment "
              "gives its standard error."]
    text = " ".join(h[3:] if h.startswith("%% ") else h for h in header)
    return rewritten_text(sr, result.values, notes,
                          ["%% " + w for w in textwrap.wrap(text, 94, break_on_hyphens=False)])


def cross_validate(sr: SoftRules, examples, **settings) -> dict:
    """Leave each example out in turn: learn on the others (:func:`learn` with ``settings``) and
    type the one left out with the file's weights and with the learned ones (:func:`map_types`),
    scored by :func:`score`. Returns ``{"rows": [...], "means": {...}}``."""
    if len(examples) < 2:
        raise EvidenceError(examples[0].path if examples else None,
                            "cross-validation needs at least two labelled examples")
    rows = []
    for i, ex in enumerate(examples):
        rest = examples[:i] + examples[i + 1:]
        fit = learn(sr, rest, **settings)
        row = {"example": ex.path}
        for tag, values in (("file", fit.start), ("learned", fit.values)):
            for k, v in score(ex, map_types(sr, values, ex)).items():
                if k in ("units", "cells"):
                    row[k] = v
                else:
                    row[f"{k}_{tag}"] = v
        row["weights"] = {p.name: int(round(v * WEIGHT_SCALE)) for p, v in zip(sr.params,
                                                                                fit.values)}
        rows.append(row)
    keys = [k for k in rows[0] if k.endswith(("_file", "_learned"))]
    means = {k: float(np.nanmean([r.get(k, np.nan) for r in rows])) for k in keys}
    return {"rows": rows, "means": means}
