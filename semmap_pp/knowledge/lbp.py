"""Loopy belief propagation: approximate marginals when the junction tree is too large.

Sum-product on a pairwise network (one variable per unit, :func:`pairwise_bp`) or on a general
factor network (:func:`factor_bp`), in probability space with log-space beliefs. The schedule is
fixed: every message is recomputed from the previous iteration's messages at once ("flooding"),
then damped, ``m <- (1 - damping) * new + damping * m``; the run stops when no message entry
moved by more than ``tol`` or after ``max_iter`` iterations. There is no randomness and the order
of every floating-point operation is fixed, so the marginals are a deterministic function of
the network (the MCMC target built on them stays a fixed function of the world).

On a tree the fixed point is exact; on loopy graphs it is the Bethe approximation. For the
weak, symmetric couplings of ``rules/table3.lp`` the error against enumeration is measured in
``tests/unit/test_knowledge_lbp.py`` and docs/rules.md.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np


_LOG_FLOOR = -690.0   # log of the smallest message entry kept (exp(-690) ~ 1e-300)


@dataclass(frozen=True)
class BPSettings:
    """Damping, iteration cap and tolerance of a run (algorithm settings, not model choices)."""

    damping: float = 0.5
    max_iter: int = 200
    tol: float = 1e-7
    cluster_states: int = 1 << 8   # factor_bp: merge factors sharing two variables up to this


@dataclass
class BPResult:
    """Marginals of a run.

    Attributes
    ----------
    marginals : list of ndarray
        Normalised belief of each variable.
    pair_beliefs : dict int -> ndarray
        Normalised joint belief of the requested pairs (by their index in the pair list).
    iterations : int
    converged : bool
    """

    marginals: list
    pair_beliefs: dict
    iterations: int
    converged: bool


def _norm_exp(logb, axis=-1):
    m = np.max(logb, axis=axis, keepdims=True)
    m = np.where(np.isfinite(m), m, 0.0)
    p = np.exp(logb - m)
    s = p.sum(axis=axis, keepdims=True)
    return p / np.where(s > 0, s, 1.0)


def pairwise_bp(unary, pairs, want=(), settings: BPSettings = BPSettings()) -> BPResult:
    """Sum-product on ``P(x) ∝ exp(Σ_i unary_i(x_i) + Σ_e pair_e(x_i, x_j))``.

    Parameters
    ----------
    unary : list of ndarray
        Log table of each variable (its length is the variable's cardinality; ``-inf`` forbids).
    pairs : list of (i, j, ndarray)
        Log tables over ``(x_i, x_j)``, ``i != j``.
    want : iterable of int
        Indices into ``pairs`` whose joint belief is returned.
    settings : BPSettings

    Returns
    -------
    BPResult
    """
    n = len(unary)
    k = max((len(u) for u in unary), default=1)
    if all(len(u) == k for u in unary):
        U = np.stack(unary)
    else:
        U = np.full((n, k), -np.inf)
        for i, u in enumerate(unary):
            U[i, :len(u)] = u
    e = len(pairs)
    if e == 0:
        return BPResult([_norm_exp(U[i, :len(u)]) for i, u in enumerate(unary)], {}, 0, True)
    ii = np.array([p[0] for p in pairs], dtype=np.int64)
    jj = np.array([p[1] for p in pairs], dtype=np.int64)
    src = np.concatenate([ii, jj])
    dst = np.concatenate([jj, ii])
    rev = np.concatenate([np.arange(e, 2 * e), np.arange(e)])
    T = np.full((2 * e, k, k), -np.inf)
    if all(t.shape == (k, k) for _i, _j, t in pairs):
        T[:e] = np.stack([t for _i, _j, t in pairs])
    else:
        for d, (i, j, t) in enumerate(pairs):
            T[d, :t.shape[0], :t.shape[1]] = t
    T[e:] = T[:e].transpose(0, 2, 1)
    top = np.max(T.reshape(2 * e, -1), axis=1)
    expT = np.exp(T - np.where(np.isfinite(top), top, 0.0)[:, None, None])
    order = np.argsort(dst, kind="stable")
    indptr = np.zeros(n + 1, dtype=np.int64)
    np.cumsum(np.bincount(dst, minlength=n), out=indptr[1:])
    valid = np.isfinite(U)[dst]
    m = valid / valid.sum(axis=1, keepdims=True)
    logm = np.empty_like(m)
    logB = np.empty_like(U)
    it, converged = _flood(U, src, rev, expT, indptr, order.astype(np.int64),
                           float(settings.damping), int(settings.max_iter), float(settings.tol),
                           m, logm, logB)
    P = _norm_exp(logB)
    marg = [P[i, :len(u)] for i, u in enumerate(unary)]
    want = np.asarray(list(want), dtype=np.int64)
    beliefs = {}
    if len(want):
        ca = logB[src[want]] - logm[rev[want]]
        cb = logB[dst[want]] - logm[want]
        lb = ca[:, :, None] + cb[:, None, :] + T[want]
        pb = _norm_exp(lb.reshape(len(want), -1)).reshape(lb.shape)
        for w, b in zip(want.tolist(), pb):
            t = pairs[w][2]
            beliefs[w] = b[:t.shape[0], :t.shape[1]]
    return BPResult(marg, beliefs, int(it), bool(converged))


@numba.njit(cache=True, nogil=True)
def _beliefs(U, logm, indptr, inedges, logB):
    n, k = U.shape
    for i in range(n):
        for a in range(k):
            s = U[i, a]
            for t in range(indptr[i], indptr[i + 1]):
                s += logm[inedges[t], a]
            logB[i, a] = s


@numba.njit(cache=True, nogil=True)
def _flood(U, src, rev, expT, indptr, inedges, damping, max_iter, tol, m, logm, logB):
    """The flooding schedule in place on messages ``m`` (D, K); leaves the final ``logm`` and
    beliefs ``logB``. Returns (iterations, converged)."""
    n_dir, k = m.shape
    for d in range(n_dir):
        for a in range(k):
            logm[d, a] = max(np.log(max(m[d, a], 1e-300)), _LOG_FLOOR)
    new = np.empty((n_dir, k))
    cav = np.empty(k)
    it = 0
    converged = False
    while it < max_iter:
        it += 1
        _beliefs(U, logm, indptr, inedges, logB)
        delta = 0.0
        for d in range(n_dir):
            i, r = src[d], rev[d]
            top = -np.inf
            for a in range(k):
                cav[a] = logB[i, a] - logm[r, a]
                if cav[a] > top:
                    top = cav[a]
            if top == -np.inf:
                top = 0.0
            for a in range(k):
                cav[a] = np.exp(cav[a] - top)
            total = 0.0
            for b in range(k):
                acc = 0.0
                for a in range(k):
                    acc += cav[a] * expT[d, a, b]
                new[d, b] = acc
                total += acc
            for b in range(k):
                v = new[d, b] / total if total > 0.0 else 0.0
                diff = abs(v - m[d, b])
                if diff > delta:
                    delta = diff
                new[d, b] = v
        for d in range(n_dir):
            for a in range(k):
                m[d, a] = (1.0 - damping) * new[d, a] + damping * m[d, a]
                logm[d, a] = max(np.log(max(m[d, a], 1e-300)), _LOG_FLOOR)
        if delta < tol:
            converged = True
            break
    _beliefs(U, logm, indptr, inedges, logB)
    return it, converged


def _expand(scope, table, union, card):
    """``table`` over sorted ``scope`` broadcast to the full sorted ``union``."""
    shape = [card[v] if v in scope else 1 for v in union]
    return np.broadcast_to(np.asarray(table).reshape(shape), [card[v] for v in union])


def cluster(card, potentials, max_states):
    """Merge factors that share two or more variables (or whose scope another contains) while
    the merged scope has at most ``max_states`` joint states. Exact (the product of the factors
    is unchanged); BP on the merged network no longer runs around the short, tight loops that
    e.g. a SaLe atom, its mirror and their hard symmetry rule make between two types.

    Deterministic: passes over the factors in a fixed order until one merges nothing; each
    factor tries its partners of the pass's start in index order. A factor is skipped in a pass
    when neither its scope nor the scope of any factor sharing a variable with it changed since
    it was last tried: its pairs would be refused again (``tests/unit/test_knowledge_lbp.py`` checks
    the result against the plain passes)."""
    facs = {k: (tuple(s), np.asarray(t, dtype=np.float64)) for k, (s, t) in
            enumerate(potentials) if len(s) >= 2}
    rest = [(tuple(s), t) for s, t in potentials if len(s) < 2]
    sets = {k: frozenset(s) for k, (s, _t) in facs.items()}
    by_var: dict = {}
    for k, (s, _t) in facs.items():
        for v in s:
            by_var.setdefault(v, set()).add(k)
    clock = 0
    grown: dict = {}       # factor -> clock when its scope last grew
    touched: dict = {}     # variable -> clock when a factor holding it last grew
    tried: dict = {}       # factor -> clock when its partners were last tried
    changed = True
    while changed:
        changed = False
        for f in sorted(facs):
            if f not in facs:
                continue
            sf, tf = facs[f]
            last = tried.get(f)
            if last is not None and grown.get(f, 0) < last and \
                    all(touched.get(v, 0) < last for v in sf):
                continue
            clock += 1
            tried[f] = clock
            set_f = sets[f]
            for g in sorted(set().union(*(by_var[v] for v in sf)) - {f}):
                set_g = sets[g]
                if len(set_f & set_g) < 2:   # every factor here has two or more variables
                    continue
                union = tuple(sorted(set_f | set_g))
                if math.prod([card[v] for v in union]) > max_states:
                    continue
                sg, tg = facs[g]
                table = _expand(sf, tf, union, card) + _expand(sg, tg, union, card)
                del facs[g], sets[g]
                for v in sg:
                    by_var[v].discard(g)
                for v in union:
                    by_var.setdefault(v, set()).add(f)
                facs[f] = sf, tf = union, table
                sets[f] = set_f = frozenset(union)
                clock += 1
                grown[f] = clock
                for v in union:
                    touched[v] = clock
                changed = True
    return rest + [facs[k] for k in sorted(facs)]


def factor_bp(card, potentials, settings: BPSettings = BPSettings()) -> BPResult:
    """Sum-product on a factor network ``P(x) ∝ exp(Σ_f table_f(x_scope_f))``.

    Factors are first merged by :func:`cluster`, then ordered by their shape. The flooding
    schedule runs compiled (:func:`_factor_flood`): each iteration sums every variable's
    incoming log messages into its belief (in that fixed order), then computes every factor's
    messages (:func:`_one_factor`, in probability space: each table exponentiated once,
    shifted by its largest finite entry, so an entry more than ~745 nats below it counts as
    impossible).

    Parameters
    ----------
    card : sequence of int
        Cardinality of each variable.
    potentials : list of (tuple of int, ndarray)
        Sorted scopes and log tables (``-inf`` forbids); as from
        :func:`~semmap_pp.knowledge.exact.merged_potentials`.
    settings : BPSettings

    Returns
    -------
    BPResult
        Variable marginals (no pair beliefs).
    """
    card = [int(c) for c in card]
    unary = [np.zeros(c) for c in card]
    groups: dict = {}
    for scope, table in cluster(card, potentials, settings.cluster_states):
        if len(scope) == 0:
            continue
        if len(scope) == 1:
            unary[scope[0]] = unary[scope[0]] + table
        else:
            groups.setdefault(table.shape, []).append((scope, table))
    voff = np.zeros(len(card) + 1, dtype=np.int64)
    np.cumsum(card, out=voff[1:])
    U = np.concatenate(unary) if card else np.zeros(0)
    fvars: list = []
    fstart, toff, moff = [0], [0], [0]
    etabs, edge_var, edge_msg = [], [], []
    for shape, items in sorted(groups.items()):
        first = len(fstart) - 1
        etabs.append(_exp_tables([t for _, t in items]).ravel())
        for scope, table in items:
            fvars.extend(scope)
            fstart.append(len(fvars))
            toff.append(toff[-1] + table.size)
            moff.append(moff[-1] + sum(shape))
        offs = np.concatenate(([0], np.cumsum(shape)[:-1]))
        for pos in range(len(shape)):     # beliefs sum the messages in this order
            for i, (scope, _t) in enumerate(items):
                edge_var.append(scope[pos])
                edge_msg.append(moff[first + i] + int(offs[pos]))
    logb = U.copy()
    it, converged = 0, True
    if len(fstart) > 1:
        i64 = np.int64
        fcard = np.array(card, dtype=i64)[np.array(fvars, dtype=i64)]
        m = np.repeat(1.0 / fcard, fcard)     # uniform messages, in the layout of moff
        it, converged = _factor_flood(
            U, voff, np.array(card, dtype=i64), np.array(fvars, dtype=i64),
            np.array(fstart, dtype=i64), np.concatenate(etabs), np.array(toff, dtype=i64),
            np.array(moff, dtype=i64), np.array(edge_var, dtype=i64),
            np.array(edge_msg, dtype=i64), float(settings.damping), int(settings.max_iter),
            float(settings.tol), m, logb)
    marg = np.split(_norm_exp_runs(logb, voff), voff[1:-1]) if card else []
    return BPResult(marg, {}, int(it), bool(converged))


def _norm_exp_runs(logb, voff) -> np.ndarray:
    """:func:`_norm_exp` of each run ``logb[voff[v]:voff[v + 1]]`` (every run non-empty)."""
    top = np.maximum.reduceat(logb, voff[:-1])
    top = np.where(np.isfinite(top), top, 0.0)
    p = np.exp(logb - np.repeat(top, np.diff(voff)))
    s = np.add.reduceat(p, voff[:-1])
    return p / np.repeat(np.where(s > 0, s, 1.0), np.diff(voff))


def _exp_tables(tables) -> np.ndarray:
    """(n, S) ``exp`` of each log table flattened (C order), shifted by its largest finite entry
    (``-inf`` gives 0; a table with none stays all 0)."""
    t = np.stack([np.asarray(x, dtype=np.float64) for x in tables]).reshape(len(tables), -1)
    top = np.max(np.where(np.isfinite(t), t, -np.inf), axis=1, keepdims=True)
    return np.ascontiguousarray(np.exp(t - np.where(np.isfinite(top), top, 0.0)))


@numba.njit(cache=True, nogil=True, inline="always")
def _add_products(ins, col, r, e, pre, suf, out):  # pragma: no cover - compiled
    """For one joint state (``col[q]``: the message entry of position ``q``'s state) add ``e``
    times the product of the other positions' incoming entries to each position's outgoing
    entry, by prefix and suffix products (no division, so zero entries are exact)."""
    pre[0] = 1.0
    for q in range(r):
        pre[q + 1] = pre[q] * ins[col[q]]
    suf[r] = 1.0
    for q in range(r - 1, -1, -1):
        suf[q] = suf[q + 1] * ins[col[q]]
    for p in range(r):
        out[col[p]] += e * pre[p] * suf[p + 1]


@numba.njit(cache=True, nogil=True, inline="always")
def _normalise(out, dims):  # pragma: no cover - compiled
    """Each position's message in ``out`` (position ``p``'s entries after those of positions
    ``< p``) clamped at 0 (a sparse correction can round an entry below it) and normalised; a
    message whose sum is 0 becomes uniform."""
    o = 0
    for p in range(dims.shape[0]):
        c = dims[p]
        tot = 0.0
        for x in range(c):
            v = max(out[o + x], 0.0)
            out[o + x] = v
            tot += v
        for x in range(c):
            out[o + x] = out[o + x] / tot if tot > 0 else 1.0 / c
        o += c


@numba.njit(cache=True, nogil=True)
def _one_factor(etab, ins, out, dims, pre, suf, digit, col):  # pragma: no cover - compiled
    """The new messages of one factor of shape ``dims`` to each variable of its scope.

    ``etab`` (S,): the table in probability space, flattened in C order (:func:`_exp_tables`);
    ``ins`` (Σ dims,): the messages the variables send in, position ``q``'s entries after those
    of positions ``< q``, as probabilities of any scale. Message to position ``p``, entry ``x``:
    the sum over the joint states with ``x_p = x`` of the table times the other positions'
    incoming entries (the product of all positions but ``p`` from prefix and suffix products),
    then normalised; a message whose sum is 0 is uniform. Written into ``out`` (layout of
    ``ins``); ``pre``, ``suf`` (r + 1,), ``digit`` and ``col`` (r,) are scratch."""
    r = dims.shape[0]
    for t in range(out.shape[0]):
        out[t] = 0.0
    for q in range(r):
        digit[q] = 0
    for j in range(etab.shape[0]):
        if j > 0:                       # the next joint state, last position fastest
            q = r - 1
            digit[q] += 1
            while digit[q] == dims[q] and q > 0:
                digit[q] = 0
                q -= 1
                digit[q] += 1
        e = etab[j]
        if e == 0.0:
            continue
        o = 0
        for q in range(r):
            col[q] = o + digit[q]
            o += dims[q]
        _add_products(ins, col, r, e, pre, suf, out)
    _normalise(out, dims)


#: a table of at least this many joint states whose entries mostly share one value is handled as
#: that value plus a sparse correction (:func:`_sparse_plan`)
_SPARSE_MIN_STATES = 64


@numba.njit(cache=True, nogil=True)
def _sparse_plan(etab, toff):  # pragma: no cover - compiled
    """For each factor, whether its table (probability space) is its most common value ``c``
    plus a few entries that differ: at least :data:`_SPARSE_MIN_STATES` states, at most a
    quarter of them differ from ``c``, and no entry is below ``1e-6 c`` unless ``c`` is 0 (so
    the subtraction of the correction cannot wipe out a small entry). Returns the common values
    (n,), the offsets (n + 1,) into the differing entries' flat indices and ``e - c``, and
    those two arrays; a dense factor has no entries there."""
    n = toff.shape[0] - 1
    mode = np.zeros(n)
    soff = np.zeros(n + 1, dtype=np.int64)
    sidx = np.empty(etab.shape[0], dtype=np.int64)
    sval = np.empty(etab.shape[0])
    at = 0
    for k in range(n):
        soff[k] = at
        t = etab[toff[k]:toff[k + 1]]
        S = t.shape[0]
        mode[k] = -1.0
        if S < _SPARSE_MIN_STATES:
            continue
        v = np.sort(t)
        best, best_n, run = v[0], 1, 1
        for j in range(1, S):
            run = run + 1 if v[j] == v[j - 1] else 1
            if run > best_n:
                best, best_n = v[j], run
        if 4 * (S - best_n) > S or (best > 0.0 and v[0] < 1e-6 * best):
            continue
        mode[k] = best
        for j in range(S):
            if t[j] != best:
                sidx[at] = j
                sval[at] = t[j] - best
                at += 1
    soff[n] = at
    return mode, soff, sidx[:at], sval[:at]


@numba.njit(cache=True, nogil=True)
def _sparse_factor(c, sidx, sval, ins, out, dims, pre, suf, start, col):  # pragma: no cover
    """:func:`_one_factor` for a table that is ``c`` everywhere but at the flat joint indices
    ``sidx``, where it is ``c + sval``: the constant part's message to position ``p`` is ``c``
    times the product of the other positions' incoming sums (prefix and suffix products); the
    correction is summed over the listed states alone. An entry that rounding leaves below 0
    is 0. ``pre``, ``suf`` (r + 1,), ``start`` and ``col`` (r,) are scratch."""
    r = dims.shape[0]
    o = 0
    for q in range(r):
        start[q] = o
        tot = 0.0
        for x in range(dims[q]):
            tot += ins[o + x]
        suf[q] = tot
        o += dims[q]
    pre[0] = 1.0
    for q in range(r):
        pre[q + 1] = pre[q] * suf[q]
    suf[r] = 1.0
    for q in range(r - 1, -1, -1):
        suf[q] = suf[q + 1] * suf[q]
    for p in range(r):
        base = c * pre[p] * suf[p + 1]
        for x in range(dims[p]):
            out[start[p] + x] = base
    for t in range(sidx.shape[0]):
        j = sidx[t]
        for q in range(r - 1, -1, -1):
            col[q] = start[q] + j % dims[q]
            j //= dims[q]
        _add_products(ins, col, r, sval[t], pre, suf, out)
    _normalise(out, dims)


@numba.njit(cache=True, nogil=True)
def _log_of(x):  # pragma: no cover - compiled
    return max(np.log(max(x, 1e-300)), _LOG_FLOOR)


@numba.njit(cache=True, nogil=True)
def _factor_beliefs(U, voff, card, edge_var, edge_msg, logm, logb):  # pragma: no cover
    for t in range(U.shape[0]):
        logb[t] = U[t]
    for e in range(edge_var.shape[0]):
        v, at = edge_var[e], edge_msg[e]
        for x in range(card[v]):
            logb[voff[v] + x] += logm[at + x]


@numba.njit(cache=True, nogil=True)
def _factor_flood(U, voff, card, fvars, fstart, etab, toff, moff, edge_var, edge_msg, damping,
                  max_iter, tol, m, logb):  # pragma: no cover - compiled
    """The flooding schedule of :func:`factor_bp` in place on the messages ``m`` (factor ``k``'s
    to its positions at ``moff[k]``, in scope order); leaves the final beliefs in ``logb``.
    Factor ``k`` has the variables ``fvars[fstart[k]:fstart[k + 1]]`` and the table
    ``etab[toff[k]:toff[k + 1]]``; edge ``e`` adds the message at ``edge_msg[e]`` to variable
    ``edge_var[e]``'s belief. Returns (iterations, converged)."""
    n_msg = m.shape[0]
    logm = np.empty(n_msg)
    for t in range(n_msg):
        logm[t] = _log_of(m[t])
    new = np.empty(n_msg)
    ins = np.empty(n_msg)
    r_max = 0
    for k in range(fstart.shape[0] - 1):
        r_max = max(r_max, fstart[k + 1] - fstart[k])
    pre, suf = np.empty(r_max + 1), np.empty(r_max + 1)
    digit = np.empty(r_max, dtype=np.int64)
    col = np.empty(r_max, dtype=np.int64)
    dims = np.empty(r_max, dtype=np.int64)
    mode, soff, sidx, sval = _sparse_plan(etab, toff)
    it = 0
    converged = False
    while it < max_iter:
        it += 1
        _factor_beliefs(U, voff, card, edge_var, edge_msg, logm, logb)
        for k in range(fstart.shape[0] - 1):
            at = moff[k]
            for t in range(fstart[k], fstart[k + 1]):   # what each variable sends in
                v = fvars[t]
                c = card[v]
                top = -np.inf
                for x in range(c):
                    ins[at + x] = logb[voff[v] + x] - logm[at + x]
                    top = max(top, ins[at + x])
                if not np.isfinite(top):
                    top = 0.0
                for x in range(c):
                    ins[at + x] = np.exp(ins[at + x] - top)
                at += c
            r = fstart[k + 1] - fstart[k]
            for q in range(r):
                dims[q] = card[fvars[fstart[k] + q]]
            if mode[k] >= 0.0:
                _sparse_factor(mode[k], sidx[soff[k]:soff[k + 1]], sval[soff[k]:soff[k + 1]],
                               ins[moff[k]:moff[k + 1]], new[moff[k]:moff[k + 1]], dims[:r],
                               pre[:r + 1], suf[:r + 1], digit[:r], col[:r])
            else:
                _one_factor(etab[toff[k]:toff[k + 1]], ins[moff[k]:moff[k + 1]],
                            new[moff[k]:moff[k + 1]], dims[:r], pre[:r + 1], suf[:r + 1],
                            digit[:r], col[:r])
        delta = 0.0
        for t in range(n_msg):
            delta = max(delta, abs(new[t] - m[t]))
        for t in range(n_msg):
            m[t] = (1.0 - damping) * new[t] + damping * m[t]
            logm[t] = _log_of(m[t])
        if delta < tol:
            converged = True
            break
    _factor_beliefs(U, voff, card, edge_var, edge_msg, logm, logb)
    return it, converged
