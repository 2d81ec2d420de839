"""MAP worlds: by clingo optimisation and by python-sat's RC2 weighted MaxSAT.

:func:`map_clingo` and :func:`map_rc2` minimise the cost of a whole world of the network
(integer thousandths): clingo solves the ground program itself (its weak constraints are the
soft rules), RC2 solves a WCNF encoding of the network (one Boolean per type state with
exactly-one clauses, one per binary atom; each violating assignment of a hard factor is a hard
clause; a soft factor gets an indicator ``y`` forced by its violating assignments and a soft
clause ``¬y`` of its weight). The engine uses them only for evidence without soft atoms: its MAP
sums those out first (:func:`semmap_pp.knowledge.exact.sum_out`) and hands the resulting log
tables to :func:`map_tables_rc2` when the junction tree is too large.
"""

from __future__ import annotations

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

    wcnf = WCNF()
    for v, c in enumerate(net.card):
        if c != 2:
            wcnf.append(list(ids[v]))
            for a in range(c):
                for b in range(a + 1, c):
                    wcnf.append([-ids[v][a], -ids[v][b]])
    for scope, viol in net.hard:
        for states in np.argwhere(viol):
            wcnf.append([-lit(v, int(s)) for v, s in zip(scope, states)])
    for scope, t, w in net.soft:
        bad = np.argwhere(t)
        if len(bad) == 1:
            wcnf.append([-lit(v, int(s)) for v, s in zip(scope, bad[0])], weight=int(w))
            continue
        top += 1
        for states in bad:
            wcnf.append([-lit(v, int(s)) for v, s in zip(scope, states)] + [top])
        wcnf.append([-top], weight=int(w))
    with RC2(wcnf) as rc2:
        model = rc2.compute()
        if model is None:
            raise RuleError(net.path, _NO_WORLD)
        cost = int(rc2.cost)
    true = {m for m in model if m > 0}
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
    exactly one per variable; each table entry above its table's minimum cost a soft clause
    against that joint state, each ``-inf`` entry a hard one).

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
        An optimal assignment and its log potential (``-cost``, MLN units).
    """
    if any(not np.isfinite(t).any() for _, t in potentials):
        raise RuleError(path, _NO_WORLD)
    wcnf = WCNF()
    ids, top = [], 0
    for c in card:
        ids.append(list(range(top + 1, top + 1 + int(c))))
        top += int(c)
    for row in ids:
        wcnf.append(list(row))
        for a in range(len(row)):
            for b in range(a + 1, len(row)):
                wcnf.append([-row[a], -row[b]])
    first = [row[0] for row in ids]
    base = 0
    for scope, t in potentials:
        base += _add_costs(wcnf, np.asarray(t), [first[v] for v in scope])
    with RC2(wcnf) as rc2:
        model = rc2.compute()
        if model is None:
            raise RuleError(path, _NO_WORLD)
        cost = int(rc2.cost)
    true = {m for m in model if m > 0}
    x = np.array([next(k for k, i in enumerate(row) if i in true) for row in ids], dtype=np.int64)
    return x, -(cost + base) / COST_SCALE


def _add_costs(wcnf, table, first) -> int:
    """Soft clauses ``¬(conjunction of the entry's states)`` weighted by each entry's cost above
    the table's minimum; hard clauses for ``-inf``; entries in C order (the table's axes are its
    scope's variables, whose state ``k`` is literal ``first[axis] + k``). Returns the minimum
    cost (1 / :data:`COST_SCALE` units)."""
    flat = table.reshape(-1)
    fin = np.isfinite(flat)
    cost = np.where(fin, np.rint(-COST_SCALE * np.where(fin, flat, 0.0)), 0).astype(np.int64)
    low = int(cost[fin].min())
    need = np.flatnonzero(~fin | (cost > low))      # the entries that get a clause, in order
    if need.size:
        states = np.unravel_index(need, table.shape)
        clauses = -np.stack([f + k for f, k in zip(first, states)], axis=1)
        weights = (cost[need] - low).tolist()
        for clause, hard, w in zip(clauses.tolist(), (~fin[need]).tolist(), weights):
            if hard:
                wcnf.append(clause)
            else:
                wcnf.append(clause, weight=w)
    return low
