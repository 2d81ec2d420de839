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
``tests/test_knowledge_lbp.py`` and docs/rules.md.
"""

from __future__ import annotations

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
    Deterministic: factors are visited in a fixed order."""
    facs = {k: (tuple(s), np.asarray(t, dtype=np.float64)) for k, (s, t) in
            enumerate(potentials) if len(s) >= 2}
    rest = [(tuple(s), t) for s, t in potentials if len(s) < 2]
    by_var: dict = {}
    for k, (s, _t) in facs.items():
        for v in s:
            by_var.setdefault(v, set()).add(k)
    changed = True
    while changed:
        changed = False
        for f in sorted(facs):
            if f not in facs:
                continue
            sf, tf = facs[f]
            partners = sorted(set().union(*(by_var[v] for v in sf)) - {f})
            for g in partners:
                sg, tg = facs[g]
                union = tuple(sorted(set(sf) | set(sg)))
                shared = len(sf) + len(sg) - len(union)
                if shared < min(2, len(sf), len(sg)):
                    continue
                if int(np.prod([card[v] for v in union])) > max_states:
                    continue
                table = _expand(sf, tf, union, card) + _expand(sg, tg, union, card)
                del facs[g]
                for v in sg:
                    by_var[v].discard(g)
                for v in union:
                    by_var.setdefault(v, set()).add(f)
                facs[f] = sf, tf = union, table
                changed = True
    return rest + [facs[k] for k in sorted(facs)]


def factor_bp(card, potentials, settings: BPSettings = BPSettings()) -> BPResult:
    """Sum-product on a factor network ``P(x) ∝ exp(Σ_f table_f(x_scope_f))``.

    Factors are first merged by :func:`cluster`; factors of one shape then move together: each
    iteration computes every message of the shape's factors in one compiled pass
    (:func:`_factor_messages`, in probability space: each table exponentiated once, shifted by
    its largest finite entry, so an entry more than ~745 nats below it counts as impossible).

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
    # variables of one cardinality share a belief array
    local, by_card = [0] * len(card), {}
    for v, c in enumerate(card):
        local[v] = len(by_card.setdefault(c, []))
        by_card[c].append(v)
    U = {c: np.array([unary[v] for v in vs]) for c, vs in by_card.items()}
    local = np.array(local, dtype=np.int64)
    blocks = []
    for shape, items in sorted(groups.items()):
        scopes = np.array([s for s, _ in items], dtype=np.int64)
        dims = np.array(shape, dtype=np.int64)
        offs = np.concatenate(([0], np.cumsum(dims)[:-1])).astype(np.int64)
        msgs = [np.full((len(items), c), 1.0 / c) for c in shape]
        blocks.append((shape, scopes, _exp_tables([t for _, t in items]), msgs, dims, offs,
                       _joint_columns(dims, offs)))
    a, b = 1.0 - settings.damping, settings.damping

    def log_of(m):
        return np.maximum(np.log(np.maximum(m, 1e-300)), _LOG_FLOOR)

    def beliefs():
        logb = {c: u.copy() for c, u in U.items()}
        for shape, scopes, _e, msgs, _d, _o, _c in blocks:
            for pos, c in enumerate(shape):
                np.add.at(logb[c], local[scopes[:, pos]], log_of(msgs[pos]))
        return logb

    it, converged = 0, False
    while blocks and it < settings.max_iter:
        it += 1
        logb = beliefs()
        delta = 0.0
        new_all = []
        for shape, scopes, etab, msgs, dims, offs, cols in blocks:
            ins = np.empty((len(scopes), int(dims.sum())))
            for pos, c in enumerate(shape):   # what each variable sends in, as probabilities
                vin = logb[c][local[scopes[:, pos]]] - log_of(msgs[pos])
                top = vin.max(axis=1, keepdims=True)
                ins[:, offs[pos]:offs[pos] + c] = np.exp(vin - np.where(np.isfinite(top), top, 0.0))
            new = _factor_messages(etab, ins, cols, dims, offs)
            news = [new[:, offs[pos]:offs[pos] + c] for pos, c in enumerate(shape)]
            delta = max([delta] + [float(np.abs(nw - m).max()) for nw, m in zip(news, msgs)])
            new_all.append(news)
        for (_s, _sc, _e, msgs, _d, _o, _c), news in zip(blocks, new_all):
            for pos, new in enumerate(news):
                msgs[pos] = a * new + b * msgs[pos]
        if delta < settings.tol:
            converged = True
            break
    logb = beliefs()
    marg = [_norm_exp(logb[c][local[v]]) for v, c in enumerate(card)]
    return BPResult(marg, {}, it, converged or not blocks)


def _exp_tables(tables) -> np.ndarray:
    """(n, S) ``exp`` of each log table flattened (C order), shifted by its largest finite entry
    (``-inf`` gives 0; a table with none stays all 0)."""
    t = np.stack([np.asarray(x, dtype=np.float64) for x in tables]).reshape(len(tables), -1)
    top = np.max(np.where(np.isfinite(t), t, -np.inf), axis=1, keepdims=True)
    return np.ascontiguousarray(np.exp(t - np.where(np.isfinite(top), top, 0.0)))


def _joint_columns(dims, offs) -> np.ndarray:
    """(S, r) int64: for each joint state of a factor of shape ``dims`` (C order, the last
    position fastest), the column of its entry of each position in the messages' layout
    (position ``q``'s entries start at ``offs[q]``). Made once per shape of a network."""
    digits = np.indices(tuple(int(d) for d in dims)).reshape(len(dims), -1).T
    return np.ascontiguousarray(digits + np.asarray(offs, dtype=np.int64), dtype=np.int64)


@numba.njit(cache=True, nogil=True)
def _factor_messages(etab, ins, col, dims, offs):  # pragma: no cover - compiled
    """The new messages of ``n`` factors of one shape ``dims`` to each variable of their scopes.

    ``etab`` (n, S): each factor's table in probability space (:func:`_exp_tables`); ``ins``
    (n, Σ dims): the messages the variables send in, position ``q``'s at ``offs[q]``, as
    probabilities of any scale; ``col`` (S, r): :func:`_joint_columns`. Message to position ``p``, entry ``x``: the sum over the joint
    states with ``x_p = x`` of the table times the other positions' incoming entries (the
    product of all positions but ``p`` from prefix and suffix products), then normalised; a
    message whose sum is 0 is uniform. Returns (n, Σ dims) in the layout of ``ins``."""
    n, S = etab.shape
    r = dims.shape[0]
    out = np.zeros((n, ins.shape[1]))
    pre = np.empty(r + 1)
    suf = np.empty(r + 1)
    for i in range(n):
        for j in range(S):
            e = etab[i, j]
            if e == 0.0:
                continue
            pre[0] = 1.0
            for q in range(r):
                pre[q + 1] = pre[q] * ins[i, col[j, q]]
            suf[r] = 1.0
            for q in range(r - 1, -1, -1):
                suf[q] = suf[q + 1] * ins[i, col[j, q]]
            for p in range(r):
                out[i, col[j, p]] += e * pre[p] * suf[p + 1]
        for p in range(r):
            o, c = offs[p], dims[p]
            tot = 0.0
            for x in range(c):
                tot += out[i, o + x]
            for x in range(c):
                out[i, o + x] = out[i, o + x] / tot if tot > 0 else 1.0 / c
    return out
