"""Counting and uniform sampling on a junction tree for many MC-SAT chains at once.

The slice of an MC-SAT iteration is a network of 0/1 tables (counts, when a block sums out
private atoms); its uniform solution is drawn by forward filtering, backward sampling on the
junction tree of :mod:`~semmap_pp.knowledge.exact`: the upward pass multiplies each clique's
tables and its children's messages and sums out the clique's own variable, the downward pass
draws that variable given its already drawn separator. Arrays are ``(states, chains)`` float32
with the chain axis last; a table whose variables lie within a larger one's is multiplied into
it with numpy, then one compiled loop per clique counts (upward) or draws (downward) over the
remaining few. Messages are rescaled per chain where their entries could leave float32.
"""

from __future__ import annotations

import numba
import numpy as np

_LOG2_LIMIT = 60.0     # rescale messages before their entries could exceed 2^60 (float32: 2^128)


@numba.njit(cache=True, nogil=True)
def _pick(probs, u, out, marg, acc):
    c, B = probs.shape
    for b in range(B):
        total = 0.0
        for j in range(c):
            total += probs[j, b]
        thr = u[b] * total
        run, k = 0.0, 0
        for j in range(c - 1):
            run += probs[j, b]
            if thr >= run:
                k = j + 1
        out[b] = k
        if acc:
            for j in range(c):
                marg[j, b] += probs[j, b] / total


def pick(probs, u, marginals=None):
    """Inverse-CDF draw along axis 0 of ``probs`` ``(c, ...)`` with uniforms ``u`` ``(...)``.

    ``u < 1`` in float64 keeps ``u * total`` below the total, so a state of zero weight (whose
    running sum equals the previous one) is never picked. With ``marginals`` (``(c, ...)``
    float64), ``probs / total`` is added to it.
    """
    c = probs.shape[0]
    flat = np.ascontiguousarray(probs).reshape(c, -1)
    out = np.empty(flat.shape[1], dtype=np.int64)
    acc = marginals is not None
    marg = marginals.reshape(c, -1) if acc else np.zeros((1, 1))
    _pick(flat, np.ascontiguousarray(u, dtype=np.float64).reshape(-1), out, marg, acc)
    return out.reshape(probs.shape[1:])


@numba.njit(cache=True, nogil=True)
def _count(F, idx, msg, rescale):
    """``msg[m, b] = sum_v prod_f F[idx[f, v, m], b]``, rescaled per chain if asked."""
    n_f, c, M = idx.shape
    B = F.shape[1]
    tmp = np.empty(B, dtype=np.float32)
    for m in range(M):
        out = msg[m]
        out[:] = 0.0
        for v in range(c):
            if n_f == 0:
                out += 1.0
                continue
            row = F[idx[0, v, m]]
            for b in range(B):
                tmp[b] = row[b]
            for f in range(1, n_f):
                row = F[idx[f, v, m]]
                for b in range(B):
                    tmp[b] *= row[b]
            for b in range(B):
                out[b] += tmp[b]
    if rescale:
        for b in range(B):
            top = np.float32(0.0)
            for m in range(M):
                if msg[m, b] > top:
                    top = msg[m, b]
            if top > 0:
                for m in range(M):
                    msg[m, b] /= top


@numba.njit(cache=True, nogil=True)
def _draw(F, idx, sep, u, out, marg, acc):
    """Draw the clique's variable per chain given its drawn separator ``sep`` (flat)."""
    n_f, c, M = idx.shape
    B = u.shape[0]
    probs = np.empty(c)
    for b in range(B):
        m = sep[b]
        total = 0.0
        for v in range(c):
            t = 1.0
            for f in range(n_f):
                t *= F[idx[f, v, m], b]
            probs[v] = t
            total += t
        thr = u[b] * total
        run, k = 0.0, 0
        for v in range(c - 1):
            run += probs[v]
            if thr >= run:
                k = v + 1
        out[b] = k
        if acc:
            for v in range(c):
                marg[v, b] += probs[v] / total


class BatchTree:
    """Upward counting and downward sampling passes over ``B`` chains.

    For each clique, the tables and children's messages it holds are stacked into one
    ``(states, B)`` array and an index map ``(factor, own state, separator state)`` into it, so
    counting and drawing are one compiled loop per clique.

    Parameters
    ----------
    card : list of int
        Cardinality of each junction-tree variable.
    scopes : list of ndarray of int, shape (I, r)
        Scopes of the instances of each clause block (the order of ``counts`` in
        :meth:`upward`).
    jt : JunctionTree
        A tree over those scopes.
    B : int
        Number of chains.
    table_max : list of float, optional
        Largest entry of each block's tables (for the rescaling bound).
    """

    def __init__(self, card, scopes, jt, B, table_max=None):
        self.card, self.jt, self.B = card, jt, B
        n = len(card)
        self.n = n
        # a message is rescaled per chain only where a bound on its entries could leave the
        # float32 range: log2 of (own states x largest table entries x children's bounds)
        log_max = [np.log2(max(float(m), 1.0)) for m in (table_max or [1.0] * len(scopes))]
        bound = [0.0] * n
        self.rescale = [False] * n
        factors = [[] for _ in range(n)]   # per clique: (kind, key, own variables, own shape)
        for b, sc in enumerate(scopes):
            tuples = [tuple(int(v) for v in s) for s in sc]
            for j, (s, pl) in enumerate(zip(tuples, jt.assign(tuples))):
                factors[pl[0]].append(("table", (b, j), s))
                bound[pl[0]] += log_max[b]
        for i in range(n):
            bound[i] += np.log2(card[jt.order[i]])
            p = jt.parent[i]
            if p >= 0:
                factors[p].append(("msg", i, tuple(jt.seps[i])))
                if bound[i] > _LOG2_LIMIT:
                    self.rescale[i] = True
                else:
                    bound[p] += bound[i]
        # multiply each factor whose variables lie within a larger factor's into that one first
        # (at the larger factor's size), so the compiled loops see few factors per clique
        self.groups = []
        for i in range(n):
            groups = []
            for f in sorted(factors[i], key=lambda f: -len(f[2])):
                for g in groups:
                    if set(f[2]) <= set(g[0][2]):
                        g.append(f)
                        break
                else:
                    groups.append([f])
            recipes = []
            for g in groups:
                lead = g[0][2]
                shape = tuple(card[a] for a in lead)
                views = []
                for f in g[1:]:
                    own = f[2]
                    order = sorted(range(len(own)), key=lambda k: lead.index(own[k]))
                    index = tuple(slice(None) if a in own else None for a in lead)
                    views.append((tuple(card[a] for a in own), tuple(order) + (len(own),),
                                  index + (slice(None),)))
                recipes.append((g, shape, views))
            self.groups.append(recipes)
            factors[i] = [g[0] for g in groups]
        self.factors = factors
        self.index = []
        self.rows = []
        self.sep_strides = []
        for i in range(n):
            axes = jt.axes[i]
            shape = tuple(card[a] for a in axes)
            state = np.indices(shape).reshape(len(axes), -1)          # clique states (v, sep)
            where = {a: k for k, a in enumerate(axes)}
            maps, offset = [], 0
            for _kind, _key, own in factors[i]:
                st = _strides([card[a] for a in own])
                flat = sum(state[where[a]] * int(st[k]) for k, a in enumerate(own))
                maps.append(np.asarray(flat).reshape(shape[0], -1) + offset)
                offset += int(np.prod([card[a] for a in own]))
            M = int(np.prod(shape[1:], dtype=np.int64))
            self.index.append(np.array(maps, dtype=np.int64).reshape(len(maps), shape[0], M))
            self.rows.append(offset)
            st = _strides([card[a] for a in jt.seps[i]])
            self.sep_strides.append([(a, int(k)) for a, k in zip(jt.seps[i], st)])
        self.stacked = [None] * n
        self.sent = [None] * n

    def _array(self, f, counts):
        kind, key, _own = f
        if kind == "msg":
            return self.sent[key]
        b, j = key
        return counts[b][j]

    def _stack(self, i, counts):
        """The clique's grouped tables, written one after another into one array."""
        B = self.B
        groups = self.groups[i]
        if not groups:
            return np.ones((1, B), dtype=np.float32)
        out = np.empty((self.rows[i], B), dtype=np.float32)
        row = 0
        for g, shape, views in groups:
            size = int(np.prod(shape, dtype=np.int64))
            dest = out[row:row + size]
            arr = self._array(g[0], counts)
            if not views:
                dest[...] = arr
            else:
                dest = dest.reshape(shape + (B,))
                arr = arr.reshape(shape + (B,))
                for k, (f, (own_shape, perm, index)) in enumerate(zip(g[1:], views)):
                    other = self._array(f, counts).reshape(own_shape + (B,)).transpose(
                        perm)[index]
                    np.multiply(arr if k == 0 else dest, other, out=dest)
            row += size
        return out

    def upward(self, counts, check=False):
        """Count the solutions of the slice given by ``counts`` (``(I, S, B)`` per block).

        With ``check``, returns False if some chain's slice has no solution.
        """
        B, jt = self.B, self.jt
        ok = True
        for i in range(self.n):
            F = self._stack(i, counts)
            self.stacked[i] = F
            idx = self.index[i]
            msg = np.empty((idx.shape[2], B), dtype=np.float32)
            _count(F, idx, msg, self.rescale[i] and not check)
            if check:
                top = msg.max(axis=0)
                if not np.all(top > 0):
                    ok = False
                elif self.rescale[i]:
                    msg /= top
            self.sent[i] = msg
        return ok

    def sample(self, rng, marginals=None):
        """Draw one solution per chain from the last :meth:`upward`: ``(n, B)`` states.

        With ``marginals`` (a list of ``(card, B)`` float64 arrays), each variable's
        distribution given the variables drawn before it (its separator) is added to its entry:
        backward sampling draws from exactly that distribution, so it is a Rao-Blackwellised
        indicator.
        """
        B, jt = self.B, self.jt
        x = np.zeros((self.n, B), dtype=np.int64)
        u = rng.random((self.n, B))
        none = np.zeros((1, 1))
        zero = np.zeros(B, dtype=np.int64)
        for i in range(self.n - 1, -1, -1):
            v = jt.order[i]
            sep = zero
            for a, st in self.sep_strides[i]:
                sep = sep + x[a] * st
            acc = marginals is not None
            _draw(self.stacked[i], self.index[i], sep, u[i], x[v],
                  marginals[v] if acc else none, acc)
        return x


def _strides(shape):
    out, acc = [], 1
    for c in reversed(list(shape)):
        out.append(acc)
        acc *= int(c)
    return np.array(out[::-1], dtype=np.int64)
