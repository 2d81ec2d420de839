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

from semmap_pp.knowledge.exact import _lse

_LOG_FLOOR = -690.0   # log of the smallest message entry kept (exp(-690) ~ 1e-300)


@dataclass(frozen=True)
class BPSettings:
    """Damping, iteration cap and tolerance of a run (algorithm settings, not model choices)."""

    damping: float = 0.5
    max_iter: int = 200
    tol: float = 1e-7


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


def factor_bp(card, potentials, settings: BPSettings = BPSettings()) -> BPResult:
    """Sum-product on a factor network ``P(x) ∝ exp(Σ_f table_f(x_scope_f))``.

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
    n = len(card)
    unary = [np.zeros(c) for c in card]
    factors = []
    for scope, table in potentials:
        if len(scope) == 0:
            continue
        if len(scope) == 1:
            unary[scope[0]] = unary[scope[0]] + table
        else:
            factors.append((scope, np.asarray(table, dtype=np.float64)))
    # messages factor -> variable (probability, normalised), one per (factor, position)
    f2v = [[np.ones(card[v]) / card[v] for v in scope] for scope, _ in factors]
    a, b = 1.0 - settings.damping, settings.damping

    def beliefs():
        logb = [u.copy() for u in unary]
        for (scope, _), msgs in zip(factors, f2v):
            for v, msg in zip(scope, msgs):
                logb[v] += np.maximum(np.log(np.maximum(msg, 1e-300)), _LOG_FLOOR)
        return logb

    it, converged = 0, False
    while factors and it < settings.max_iter:
        it += 1
        logb = beliefs()
        delta = 0.0
        new_all = []
        for (scope, table), msgs in zip(factors, f2v):
            r = len(scope)
            ins = []
            for pos, (v, msg) in enumerate(zip(scope, msgs)):
                lm = np.maximum(np.log(np.maximum(msg, 1e-300)), _LOG_FLOOR)
                vin = logb[v] - lm           # variable -> factor
                top = np.max(vin)
                vin = vin - (top if np.isfinite(top) else 0.0)
                shape = [1] * r
                shape[pos] = card[v]
                vin = vin.reshape(shape)
                ins.append(vin)
            out = []
            for pos in range(r):
                t = table
                for q, vin in enumerate(ins):
                    if q != pos:
                        t = t + vin
                flat = np.moveaxis(t, pos, 0).reshape(card[scope[pos]], -1)
                new = _norm_exp(_lse(flat, 1))
                if not new.any():
                    new = np.ones(len(new)) / len(new)
                delta = max(delta, float(np.abs(new - msgs[pos]).max()))
                out.append(new)
            new_all.append(out)
        f2v = [[a * nw + b * old for nw, old in zip(news, olds)]
               for news, olds in zip(new_all, f2v)]
        if delta < settings.tol:
            converged = True
            break
    logb = beliefs()
    return BPResult([_norm_exp(lb) for lb in logb], {}, it, converged or not factors)
