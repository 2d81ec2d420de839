"""MAP worlds: by clingo optimisation and by python-sat's RC2 weighted MaxSAT.

Both minimise the same cost as the network (integer thousandths): clingo solves the ground
program itself (its weak constraints are the soft rules), RC2 solves a WCNF encoding of the
network (one Boolean per type state with exactly-one clauses, one per binary atom; each
violating assignment of a hard factor is a hard clause; a soft factor gets an indicator ``y``
forced by its violating assignments and a soft clause ``¬y`` of its weight).
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
    """Exact MAP of a pairwise log-potential network by RC2 (one Boolean per variable state).

    Parameters
    ----------
    unary : list of ndarray
        Log tables whose finite entries are multiples of 1/1000 (negated costs of soft rules),
        ``-inf`` for forbidden states.
    pairs : list of (i, j, ndarray)
        Log pair tables of the same kind.
    path : str
        Named in the error when no assignment is allowed.

    Returns
    -------
    (ndarray of int, float)
        An optimal assignment and its log potential (``-cost``, MLN units).
    """
    if any(not np.isfinite(t).any() for t in list(unary) + [p[2] for p in pairs]):
        raise RuleError(path, _NO_WORLD)
    wcnf = WCNF()
    ids, top = [], 0
    for u in unary:
        ids.append(list(range(top + 1, top + 1 + len(u))))
        top += len(u)
    base = 0
    for v, u in enumerate(unary):
        wcnf.append(list(ids[v]))
        for a in range(len(u)):
            for b in range(a + 1, len(u)):
                wcnf.append([-ids[v][a], -ids[v][b]])
        base += _add_costs(wcnf, u.reshape(-1), [[ids[v][a]] for a in range(len(u))])
    for i, j, t in pairs:
        lits = [[ids[i][a], ids[j][b]] for a in range(t.shape[0]) for b in range(t.shape[1])]
        base += _add_costs(wcnf, t.reshape(-1), lits)
    with RC2(wcnf) as rc2:
        model = rc2.compute()
        if model is None:
            raise RuleError(path, _NO_WORLD)
        cost = int(rc2.cost)
    true = {m for m in model if m > 0}
    x = np.array([next(k for k, i in enumerate(row) if i in true) for row in ids], dtype=np.int64)
    return x, -(cost + base) / 1000.0


def _add_costs(wcnf, table, lits) -> int:
    """Soft clauses ``¬(conjunction)`` weighted by each entry's cost above the table's minimum;
    hard clauses for ``-inf``. Returns the minimum cost (thousandths)."""
    fin = np.isfinite(table)
    cost = np.where(fin, np.rint(-1000.0 * np.where(fin, table, 0.0)), 0).astype(np.int64)
    low = int(cost[fin].min())
    for k, conj in enumerate(lits):
        if not fin[k]:
            wcnf.append([-lit for lit in conj])
        elif cost[k] > low:
            wcnf.append([-lit for lit in conj], weight=int(cost[k] - low))
    return low
