"""Counting and uniform sampling on a junction tree for many MC-SAT chains at once.

The slice of an MC-SAT iteration is a network of 0/1 tables (counts, when a block sums out
private atoms); its uniform solution is drawn by forward filtering, backward sampling on the
junction tree of :mod:`~semmap_pp.knowledge.exact`: the upward pass multiplies each clique's
tables and its children's messages and sums out the clique's own variable, the downward pass
draws that variable given its already drawn separator. Every table, message and product of
tables has fixed rows of one ``(rows, chains)`` float32 array (the chain axis last), so the
count tables are written into it in place and each pass is one compiled loop over the cliques.
A table whose variables lie within a larger one's is multiplied into it first (at the larger
one's size, into rows of its own), so the count and draw loops see few factors per clique.
Messages are rescaled per chain where their entries could leave float32.
"""

from __future__ import annotations

import copy

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
def _upward(G, pp, prod_base, sp, src, idx, ip, nf, cc, MM, msg_row, rescale, check):
    """The upward pass, cliques in elimination order (children first). Per clique: multiply
    its grouped tables into their product rows, then count ``msg[m, b] = sum_v prod_f
    G[idx[f, v, m], b]`` into its message rows, rescaled per chain where flagged. Returns
    False if ``check`` and some chain's message is all zero (its slice has no solution)."""
    B = G.shape[1]
    tmp = np.empty(B, dtype=np.float32)
    ok = True
    for i in range(len(nf)):
        for p in range(pp[i], pp[i + 1]):
            dest = G[prod_base + p]
            first = G[src[sp[p]]]
            for b in range(B):
                dest[b] = first[b]
            for t in range(sp[p] + 1, sp[p + 1]):
                row = G[src[t]]
                for b in range(B):
                    dest[b] *= row[b]
        n_f, c, M, base, m0 = nf[i], cc[i], MM[i], ip[i], msg_row[i]
        for m in range(M):
            out = G[m0 + m]
            for b in range(B):
                out[b] = 0.0
            for v in range(c):
                if n_f == 0:
                    for b in range(B):
                        out[b] += 1.0
                    continue
                row = G[idx[base + v * M + m]]
                for b in range(B):
                    tmp[b] = row[b]
                for f in range(1, n_f):
                    row = G[idx[base + (f * c + v) * M + m]]
                    for b in range(B):
                        tmp[b] *= row[b]
                for b in range(B):
                    out[b] += tmp[b]
        if rescale[i] or check:
            for b in range(B):
                top = np.float32(0.0)
                for m in range(M):
                    if G[m0 + m, b] > top:
                        top = G[m0 + m, b]
                if top > 0:
                    if rescale[i]:
                        for m in range(M):
                            G[m0 + m, b] /= top
                else:
                    ok = False
    return ok


@numba.njit(cache=True, nogil=True)
def _sample(G, idx, ip, nf, cc, MM, order, sep_ptr, sep_var, sep_stride, u, x, marg, moff,
            acc):
    """The downward pass: per clique (root first) draw its variable per chain given the drawn
    separator, and with ``acc`` add that conditional distribution to ``marg``."""
    B = G.shape[1]
    probs = np.empty(int(cc.max()) if len(cc) else 1, dtype=np.float32)
    for i in range(len(nf) - 1, -1, -1):
        v_out = order[i]
        n_f, c, M, base = nf[i], cc[i], MM[i], ip[i]
        xo = x[v_out]
        ui = u[i]
        for b in range(B):
            m = 0
            for k in range(sep_ptr[i], sep_ptr[i + 1]):
                m += x[sep_var[k], b] * sep_stride[k]
            total = np.float32(0.0)
            for v in range(c):
                t = np.float32(1.0)
                for f in range(n_f):
                    t *= G[idx[base + (f * c + v) * M + m], b]
                probs[v] = t
                total += t
            thr = ui[b] * total
            run, k = np.float32(0.0), 0
            for v in range(c - 1):
                run += probs[v]
                if thr >= run:
                    k = v + 1
            xo[b] = k
            if acc:
                r0 = moff[v_out]
                inv = 1.0 / np.float64(total)
                for v in range(c):
                    marg[r0 + v, b] += probs[v] * inv


class BatchTree:
    """Upward counting and downward sampling passes over ``B`` chains.

    ``G`` (``(rows, B)`` float32) holds every table instance (rows ``table_rows[b][j]`` ...
    ``+ S``, row-major over its scope), every message and every product of a group of tables;
    row 0 is all ones. Each clique has an index map ``(factor, own state, separator state)``
    into ``G``, so counting and drawing are one compiled loop over all cliques.

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
        factors, rows, msg_row, rescale = self._place_factors(card, scopes, jt, table_max)
        prod_rows, pp, grouped = self._group_factors(card, factors, n)
        prod_base = rows
        rows += len(prod_rows)
        self.G = np.ones((rows, B), dtype=np.float32)
        self.prod_base = int(prod_base)
        idx, ip, nf, cc, MM, sep_ptr, sep_var, sep_stride = self._clique_maps(card, jt, grouped,
                                                                              prod_base, n)
        i64 = lambda a: np.array(a, dtype=np.int64)   # noqa: E731
        lens = [len(r) for r in prod_rows]
        self._up = (self.G, i64(pp), int(prod_base), i64(np.concatenate([[0], np.cumsum(lens)])
                                                             if lens else [0]),
                    i64([t for r in prod_rows for t in r]), i64(idx), i64(ip[:-1]), i64(nf),
                    i64(cc), i64(MM), i64(msg_row), np.array(rescale, dtype=np.bool_))
        self._down = (self.G, i64(idx), i64(ip[:-1]), i64(nf), i64(cc), i64(MM),
                      i64(jt.order), i64(sep_ptr), i64(sep_var), i64(sep_stride))
        self.rescale = rescale
        self._x = self._u = None
        self.marg_offsets = i64(np.concatenate([[0], np.cumsum(card)]))


    def _place_factors(self, card, scopes, jt, table_max):
        """Each block's tables and each clique's message given rows of G, each factor placed on
        its clique: ``(factors per clique, rows so far, message rows, cliques rescaled)``; sets
        :attr:`table_rows` and :attr:`sizes`."""
        n = len(card)
        size = lambda vs: int(np.prod([card[a] for a in vs], dtype=np.int64))   # noqa: E731
        # a message is rescaled per chain only where a bound on its entries could leave the
        # float32 range: log2 of (own states x largest table entries x children's bounds)
        log_max = [np.log2(max(float(m), 1.0)) for m in (table_max or [1.0] * len(scopes))]
        bound = [0.0] * n
        rescale = [False] * n
        factors = [[] for _ in range(n)]   # per clique: (row of G, own variables)
        rows = 1                           # row 0: ones
        self.table_rows = []
        self.sizes = []
        for b, sc in enumerate(scopes):
            tuples = [tuple(int(v) for v in s) for s in sc]
            S = size(tuples[0]) if tuples else 1
            start = rows + S * np.arange(len(tuples), dtype=np.int64)
            rows += S * len(tuples)
            self.table_rows.append(start)
            self.sizes.append(S)
            for j, (s, pl) in enumerate(zip(tuples, jt.assign(tuples))):
                factors[pl[0]].append((int(start[j]), s))
                bound[pl[0]] += log_max[b]
        msg_row = []
        for i in range(n):
            msg_row.append(rows)
            rows += size(jt.seps[i])
        for i in range(n):
            bound[i] += np.log2(card[jt.order[i]])
            p = jt.parent[i]
            if p >= 0:
                factors[p].append((msg_row[i], tuple(jt.seps[i])))
                if bound[i] > _LOG2_LIMIT:
                    rescale[i] = True
                else:
                    bound[p] += bound[i]
        return factors, rows, msg_row, rescale

    @staticmethod
    def _group_factors(card, factors, n):
        """The factors of each clique grouped under the largest factor holding their variables:
        ``(product rows, their offsets per clique, each clique's group heads)``."""
        # multiply each factor whose variables lie within a larger factor's into that one first
        # (at the larger factor's size, into rows of its own)
        prod_rows = []        # per product row: rows of G to multiply
        pp = [0]
        grouped = []
        for i in range(n):
            groups = []
            for f in sorted(factors[i], key=lambda f: -len(f[1])):
                for g in groups:
                    if set(f[1]) <= set(g[0][1]):
                        g.append(f)
                        break
                else:
                    groups.append([f])
            heads = []
            for g in groups:
                lead = g[0][1]
                if len(g) == 1:
                    heads.append(g[0])
                    continue
                state = np.indices([card[a] for a in lead]).reshape(len(lead), -1)
                terms = [g[0][0] + np.arange(state.shape[1])]
                for row0, own in g[1:]:
                    st = _strides([card[a] for a in own])
                    terms.append(row0 + sum(state[lead.index(a)] * int(st[k])
                                            for k, a in enumerate(own)))
                heads.append((len(prod_rows), lead, True))
                prod_rows.extend(np.array(terms).T.tolist())
            grouped.append(heads)
            pp.append(len(prod_rows))
        return prod_rows, pp, grouped

    @staticmethod
    def _clique_maps(card, jt, grouped, prod_base, n):
        """Per clique, the rows of G each of its states reads, and its separator's variables and
        strides: ``(idx, ip, nf, cc, MM, sep_ptr, sep_var, sep_stride)``."""
        idx, ip, nf, cc, MM = [], [0], [], [], []
        sep_ptr, sep_var, sep_stride = [0], [], []
        for i in range(n):
            axes = jt.axes[i]
            shape = tuple(card[a] for a in axes)
            state = np.indices(shape).reshape(len(axes), -1)          # clique states (v, sep)
            where = {a: k for k, a in enumerate(axes)}
            M = int(np.prod(shape[1:], dtype=np.int64))
            maps = []
            for head in grouped[i]:
                row0, own = (prod_base + head[0], head[1]) if len(head) == 3 else head
                st = _strides([card[a] for a in own])
                flat = sum(state[where[a]] * int(st[k]) for k, a in enumerate(own))
                maps.append(np.asarray(flat).reshape(shape[0], M) + row0)
            idx.extend(np.array(maps, dtype=np.int64).reshape(-1).tolist())
            ip.append(len(idx))
            nf.append(len(maps))
            cc.append(shape[0])
            MM.append(M)
            st = _strides([card[a] for a in jt.seps[i]])
            sep_var.extend(int(a) for a in jt.seps[i])
            sep_stride.extend(int(k) for k in st)
            sep_ptr.append(len(sep_var))
        return idx, ip, nf, cc, MM, sep_ptr, sep_var, sep_stride

    def fresh(self):
        """A tree of the same structure with rows of its own (for reuse across runs)."""
        out = copy.copy(self)
        out.G = np.ones(self.G.shape, dtype=np.float32)
        out._x = out._u = None
        out._up = (out.G,) + self._up[1:]
        out._down = (out.G,) + self._down[1:]
        return out

    def load(self, b, table):
        """Write the tables ``(I, S, B)`` of block ``b`` into their rows."""
        rows = self.table_rows[b][:, None] + np.arange(self.sizes[b])
        self.G[rows.reshape(-1)] = np.asarray(table, dtype=np.float32).reshape(-1, self.B)

    def upward(self, counts=None, check=False):
        """Count the solutions of the slice given by ``counts`` (``(I, S, B)`` per block, or
        None when the tables are already in their rows of ``G``).

        With ``check``, returns False if some chain's slice has no solution.
        """
        if counts is not None:
            for b, t in enumerate(counts):
                self.load(b, t)
        return bool(_upward(*self._up, bool(check)))

    def sample(self, rng, marginals=None):
        """Draw one solution per chain from the last :meth:`upward`: ``(n, B)`` states (one
        array, overwritten by the next call).

        With ``marginals`` (a list of ``(card, B)`` float64 arrays, or one ``(sum card, B)``
        array with the variables' rows at ``marg_offsets``), each variable's distribution given
        the variables drawn before it (its separator) is added to its entry: backward sampling
        draws from exactly that distribution, so it is a Rao-Blackwellised indicator.
        """
        B = self.B
        if self._x is None:
            self._x = np.zeros((self.n, B), dtype=np.int64)
            self._u = np.empty((self.n, B))
        x = self._x                                   # reused: valid until the next call
        u = rng.random(out=self._u)
        acc = marginals is not None
        flat = marginals
        if isinstance(marginals, list):
            flat = np.zeros((int(self.marg_offsets[-1]), B))
        elif not acc:
            flat = np.zeros((1, 1))
        _sample(*self._down, u, x, flat, self.marg_offsets, acc)
        if isinstance(marginals, list):
            for v, m in enumerate(marginals):
                m += flat[self.marg_offsets[v]:self.marg_offsets[v + 1]]
        return x


def _strides(shape):
    out, acc = [], 1
    for c in reversed(list(shape)):
        out.append(acc)
        acc *= int(c)
    return np.array(out[::-1], dtype=np.int64)
