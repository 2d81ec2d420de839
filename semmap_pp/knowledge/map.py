"""MAP worlds: by clingo optimisation and by python-sat's RC2 weighted MaxSAT.

:func:`map_clingo` and :func:`map_rc2` minimise the cost of a whole world of the network
(integer thousandths): clingo solves the ground program itself (its weak constraints are the
soft rules), RC2 solves a WCNF encoding of the network (one Boolean per type state with
exactly-one clauses, one per binary atom; a factor's violating assignments are covered by
disjoint boxes, each a hard clause for a hard factor and a soft clause of the factor's weight
for a soft one: :func:`_clauses_of`). The engine uses them only for evidence without soft atoms: its MAP
sums those out first (:func:`semmap_pp.knowledge.exact.sum_out`) and hands the resulting log
tables to :func:`map_tables_rc2` when the junction tree is too large.
"""

from __future__ import annotations

import functools

import numpy as np
from pysat.examples.rc2 import RC2
from pysat.formula import WCNF

from semmap_pp.errors import RuleError
from semmap_pp.knowledge.dialect import TYPE_PREDICATES
from semmap_pp.knowledge.ground import Grounding, Network

_NO_WORLD = "the hard rules admit no world for this evidence"


def map_clingo(grounding: Grounding) -> tuple[np.ndarray, int]:
    """Optimal assignment and its cost (thousandths) by clingo's optimisation.

    ``grounding`` must come from ``ground(..., keep_control=True)``.
    """
    net, ctl = grounding.network, grounding.control
    ctl.configuration.solve.opt_mode = "opt"
    unit_index = {u: i for i, u in enumerate(net.units)}
    by_name = {name: v for v, name in enumerate(net.names) if v >= len(net.units)}
    best = None
    with ctl.solve(yield_=True) as handle:
        for model in handle:
            best = (model.symbols(atoms=True), list(model.cost))
    if best is None:
        raise RuleError(net.path, _NO_WORLD)
    x = np.zeros(net.n_vars, dtype=np.int64)
    for sym in best[0]:
        if sym.name in TYPE_PREDICATES and len(sym.arguments) == 1:
            x[unit_index[sym.arguments[0].number]] = TYPE_PREDICATES.index(sym.name)
        else:
            v = by_name.get(str(sym))
            if v is not None:
                x[v] = 1
    return x, int(best[1][0]) if best[1] else 0


def map_rc2(net: Network) -> tuple[np.ndarray, int]:
    """Optimal assignment and its cost (thousandths) by RC2 on a WCNF encoding of ``net``."""
    ids = []
    top = 0
    for c in net.card:
        ids.append(list(range(top + 1, top + 1 + (1 if c == 2 else int(c)))))
        top += 1 if c == 2 else int(c)

    def lit(v, s):
        if net.card[v] == 2:
            return ids[v][0] if s else -ids[v][0]
        return ids[v][s]

    hard, soft, wght = [], [], []
    for v, c in enumerate(net.card):
        if c != 2:
            _exactly_one(hard, ids[v])
    for scope, viol in net.hard:       # boxes of forbidden states: hard clauses
        for _w, template in _cost_clauses(np.where(viol, _HARD, 0)):
            hard.append([lit(scope[a], k) for a, k in template])
    for scope, t, w in net.soft:       # disjoint boxes of violating states, each weight w
        for _w, template in _cost_clauses(np.where(t, 1, 0)):
            soft.append([lit(scope[a], k) for a, k in template])
            wght.append(int(w))
    true, cost = _solve(hard, soft, wght, top, net.path)
    x = np.zeros(net.n_vars, dtype=np.int64)
    for v, c in enumerate(net.card):
        if c == 2:
            x[v] = int(ids[v][0] in true)
        else:
            x[v] = next(k for k, i in enumerate(ids[v]) if i in true)
    return x, cost + int(net.offset)


def map_pairwise_rc2(unary, pairs, path) -> tuple[np.ndarray, float]:
    """Exact MAP of a pairwise log-potential network by RC2: :func:`map_tables_rc2` with a
    variable per unary table (its length the number of states) and the pair tables over two
    of them. Log tables hold ``-inf`` for forbidden states.

    Returns
    -------
    (ndarray of int, float)
        An optimal assignment and its log potential (``-cost``, MLN units).
    """
    pots = [((v,), u) for v, u in enumerate(unary)] + [((i, j), t) for i, j, t in pairs]
    return map_tables_rc2([len(u) for u in unary], pots, path)


#: Log potentials are rounded to multiples of 1 / COST_SCALE for RC2's integer weights: the
#: rule files' thousandths exactly, and log-sums of them (soft evidence summed out) to 1e-6.
COST_SCALE = 1_000_000


def map_tables_rc2(card, potentials, path) -> tuple[np.ndarray, float]:
    """MAP of a network of log tables by RC2 weighted MaxSAT (one Boolean per variable state,
    exactly one per variable; each table's entries above its minimum cost are covered by
    disjoint boxes of equal cost, each a soft clause against the box, and its ``-inf`` entries
    by hard clauses: :func:`_table_boxes`).

    Parameters
    ----------
    card : list of int
        States of each variable.
    potentials : list of (scope, ndarray)
        Log tables over sorted scopes (axes in scope order). Exact when their finite entries are
        multiples of 1 / :data:`COST_SCALE`, else to that rounding.
    path : str
        Named in the error when no assignment is allowed.

    Returns
    -------
    (ndarray of int, float)
        An optimal assignment and its log potential (``-cost``, MLN units). Among assignments of
        equal cost the solver's search picks one, the same one for the same input.
    """
    if any(not np.isfinite(t).any() for _, t in potentials):
        raise RuleError(path, _NO_WORLD)
    ids, top = [], 0
    for c in card:
        ids.append(list(range(top + 1, top + 1 + int(c))))
        top += int(c)
    hard, soft, wght = [], [], []
    for row in ids:
        _exactly_one(hard, row)
    base = 0
    for scope, t in potentials:
        base += _add_costs(hard, soft, wght, t, [ids[v][0] for v in scope])
    true, cost = _solve(hard, soft, wght, top, path)
    x = np.array([next(k for k, i in enumerate(row) if i in true) for row in ids], dtype=np.int64)
    return x, -(cost + base) / COST_SCALE


def _exactly_one(hard, row) -> None:
    """Hard clauses: exactly one of the literals ``row`` (a variable's states) is true."""
    hard.append(list(row))
    for a in range(len(row)):
        for b in range(a + 1, len(row)):
            hard.append([-row[a], -row[b]])


def _solve(hard, soft, wght, nv, path) -> tuple[set, int]:
    """RC2 on the clauses: (the true literals of an optimal model, its cost); RuleError naming
    ``path`` when the hard clauses admit none."""
    wcnf = WCNF()               # filled directly: WCNF.append costs a Python call per clause
    wcnf.hard, wcnf.soft, wcnf.wght, wcnf.nv = hard, soft, wght, nv
    wcnf.topw = sum(wght) + 1
    with RC2(wcnf) as rc2:
        model = rc2.compute()
        if model is None:
            raise RuleError(path, _NO_WORLD)
        cost = int(rc2.cost)
    return {m for m in model if m > 0}, cost


_HARD = -1   # marks a forbidden entry in the integer cost tables of _clauses_of
_CACHED_ENTRIES = 4096   # larger tables are not cached (at most 1,024 of 32 kB keys each)


def _by_content(cached, table):
    """``cached(shape, bytes)`` (an ``lru_cache`` keyed by a table's content) for ``table``; a
    table above :data:`_CACHED_ENTRIES` entries is computed without entering the cache."""
    fn = cached if table.size <= _CACHED_ENTRIES else cached.__wrapped__
    return fn(table.shape, table.tobytes())


def _add_costs(hard, soft, wght, table, first) -> int:
    """Clauses for one log table (:func:`_table_boxes`); returns its minimum cost
    (1 / :data:`COST_SCALE` units), which the clauses leave out.

    Parameters
    ----------
    hard, soft, wght : list
        Appended to: hard clauses, soft clauses and their weights.
    table : ndarray
        Log table, axes in scope order, ``-inf`` for forbidden entries, not all forbidden.
    first : list of int
        Per axis, the literal of the variable's state 0 (state ``k`` is ``first + k``).
    """
    low, boxes = _by_content(_table_boxes, np.ascontiguousarray(table, dtype=np.float64))
    for w, template in boxes:
        clause = [first[a] + k for a, k in template]
        if w == _HARD:
            hard.append(clause)
        else:
            soft.append(clause)
            wght.append(w)
    return low


@functools.lru_cache(maxsize=1024)
def _table_boxes(shape, data) -> tuple[int, tuple]:
    """A table's minimum cost and its clauses as ``(weight or _HARD, ((axis, state), ...))``,
    cached by content: a sampler's networks repeat a few dozen tables thousands of times.

    The entries above the minimum cost are covered by disjoint boxes (a set of states per
    axis) of one cost each: the states of the first axis whose sub-tables are equal form one
    side of a box, the sub-table is split the same way on the next axis, and so on. A box
    becomes the clause "some variable lies outside its set": the literals of the states
    outside it (none for an axis whose set is all its states). Under exactly one state per
    variable such a clause is false just on the box, so an assignment's violated soft weights
    sum to its entry's cost above the minimum, and a hard clause rules out exactly its box of
    ``-inf`` entries. A rule such as "a hall with no corridor among its four neighbours"
    (3⁴ entries of one cost) is one clause instead of 81.
    """
    table = np.frombuffer(data, dtype=np.float64).reshape(shape)
    fin = np.isfinite(table)
    cost = np.where(fin, np.rint(-COST_SCALE * np.where(fin, table, 0.0)), 0).astype(np.int64)
    low = int(cost[fin].min())
    return low, _clauses_of(np.where(fin, cost - low, _HARD))


def _cost_clauses(cost) -> tuple:
    """:func:`_clauses_of` an integer cost table, cached by content as :func:`_table_boxes`."""
    return _by_content(_cached_cost_clauses, np.ascontiguousarray(cost, dtype=np.int64))


@functools.lru_cache(maxsize=1024)
def _cached_cost_clauses(shape, data) -> tuple:
    return _clauses_of(np.frombuffer(data, dtype=np.int64).reshape(shape))


def _clauses_of(cost) -> tuple:
    """The clauses of an integer cost table (0: none, ``_HARD``: forbidden, else a weight):
    ``((weight or _HARD, ((axis, state), ...)), ...)``, a clause per box of :func:`_boxes`, its
    literals the states outside the box."""
    boxes: list = []
    _boxes(cost, (), boxes)
    shape = cost.shape
    return tuple((w, tuple((a, k) for a, states in enumerate(sets) if len(states) < shape[a]
                           for k in range(shape[a]) if k not in states))
                 for sets, w in boxes)


def _boxes(cost, prefix, out) -> None:
    """Append ``(sets, cost)`` for disjoint boxes covering the nonzero entries of ``cost``
    (integer; zero needs no clause): the first axis's states grouped by equal sub-tables, in
    order of their first state, each group's sub-table split the same way."""
    if cost.ndim == 0:
        out.append((prefix, int(cost)))
        return
    groups: dict = {}
    for k in range(cost.shape[0]):
        if cost[k].any():
            groups.setdefault(cost[k].tobytes(), []).append(k)
    for states in groups.values():
        _boxes(cost[states[0]], prefix + (frozenset(states),), out)
