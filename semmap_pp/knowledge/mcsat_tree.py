"""Counting and uniform sampling on a junction tree for many MC-SAT chains at once.

The slice of an MC-SAT iteration is a network of 0/1 tables (counts, when a block sums out
private atoms); its uniform solution is drawn by forward filtering, backward sampling on the
junction tree of :mod:`~semmap_pp.knowledge.exact`: the upward pass multiplies each clique's
tables and its children's messages and sums out the clique's own variable, the downward pass
draws that variable given its already drawn separator. Arrays are ``(*clique_shape, chains)``
float32 (the chain axis last and contiguous, so every operation is one long vectorised loop);
messages are rescaled per chain, so the counts never overflow.
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


def _view(perm, present):
    """Transpose and ``None`` index that put a chain-last table onto chain-last clique axes."""
    return (tuple(perm) + (len(perm),),
            tuple(slice(None) if p else None for p in present) + (slice(None),))


class BatchTree:
    """Upward counting and downward sampling passes over ``B`` chains.

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
        for b_, sc in enumerate(scopes):
            for c, *_rest in jt.assign([tuple(int(v) for v in s) for s in sc]):
                bound[c] += log_max[b_]
        for i in range(n):
            bound[i] += np.log2(card[jt.order[i]])
            p = jt.parent[i]
            if p >= 0:
                if bound[i] > _LOG2_LIMIT:
                    self.rescale[i] = True
                else:
                    bound[p] += bound[i]
        factors = [[] for _ in range(n)]   # per clique: (kind, key, perm, index, axes)
        for b, sc in enumerate(scopes):
            tuples = [tuple(int(v) for v in s) for s in sc]
            for j, (s, (c, perm, _shape)) in enumerate(zip(tuples, jt.assign(tuples))):
                factors[c].append(("table", (b, j)) + _view(perm, [a in s for a in jt.axes[c]])
                                  + (frozenset(s),))
        for i in range(n):
            p = jt.parent[i]
            if p >= 0:
                perm, _shape = jt.msg_place[i]
                factors[p].append(("msg", i) + _view(perm, [a in jt.seps[i] for a in jt.axes[p]])
                                  + (frozenset(jt.seps[i]),))
        # multiply small tables into larger ones over a superset of their axes first; a group
        # without the clique's own variable (axis 0) only scales the message
        v_axis = [jt.order[i] for i in range(n)]
        self.plan = []
        for i in range(n):
            groups = []
            for f in sorted(factors[i], key=lambda f: -len(f[4])):
                for axes, members in groups:
                    if f[4] <= axes:
                        members.append(f)
                        break
                else:
                    groups.append((f[4], [f]))
            # groups with the clique's variable, ordered so that products grow slowly
            rest = [g for g in groups if v_axis[i] in g[0]]
            ordered = []
            while rest:
                span = frozenset().union(*(g[0] for g in ordered))
                best = min(rest, key=lambda g: np.prod([card[a] for a in span | g[0]]))
                ordered.append(best)
                rest.remove(best)
            with_v = [m for axes, m in ordered]
            without = [m for axes, m in groups if v_axis[i] not in axes]
            # for sampling: (variable, stride) of each separator axis a group spans
            # sampling reads each group at the drawn separator: flat offsets of (state, chain)
            # plus (variable, stride x B) of each separator axis the group spans
            gather = []
            for axes, m in ordered:
                span, acc = [], 1
                for a in reversed(jt.axes[i][1:]):
                    if a in axes:
                        span.append((a, acc * B))
                        acc *= card[a]
                c = card[v_axis[i]]
                base = (np.arange(c) * (acc * B))[:, None] + np.arange(B)[None, :]
                gather.append((span, base))
            self.plan.append((with_v, without, gather))
        self.sep_shapes = [tuple(card[a] for a in sep) for sep in jt.seps]
        self.tables = [tuple(card[v] for v in sc[0]) if len(sc) else () for sc in scopes]
        self.groups = [None] * n
        self.sent = [None] * n

    def _factor(self, f, counts):
        kind, key, perm, index, _axes = f
        if kind == "msg":
            arr = self.sent[key]
        else:
            b, j = key
            arr = counts[b][:, j].reshape(self.tables[b] + (self.B,))
        return arr.transpose(perm)[index]

    def _group(self, members, counts):
        g = self._factor(members[0], counts)
        for f in members[1:]:
            g = g * self._factor(f, counts)
        return g

    def upward(self, counts, check=False):
        """Count the solutions of the slice given by ``counts`` (``(S, I, B)`` per block).

        With ``check``, returns False if some chain's slice has no solution.
        """
        B, jt = self.B, self.jt
        ok = True
        for i in range(self.n):
            with_v, without, _gather = self.plan[i]
            groups = [self._group(m, counts) for m in with_v]
            self.groups[i] = groups
            c = self.card[jt.order[i]]
            # message: sum over the clique's variable of the product of its groups, one
            # state at a time (never the whole clique table)
            if len(groups) == 1:
                msg = groups[0].sum(axis=0)
            elif groups:
                msg = None
                for v in range(c):
                    t = groups[0][v]
                    for g in groups[1:]:
                        t = t * g[v]
                    msg = t if msg is None else msg + t
            else:
                msg = np.full((1,) * len(self.sep_shapes[i]) + (B,), float(c), dtype=np.float32)
            for m in without:
                msg = msg * self._group(m, counts)[0]
            full = self.sep_shapes[i] + (B,)
            if msg.shape != full:
                msg = np.broadcast_to(msg, full)
            if check and not np.all(msg.reshape(-1, B).max(axis=0) > 0):
                ok = False
            elif self.rescale[i]:
                msg = msg / msg.reshape(-1, B).max(axis=0)
            self.sent[i] = msg
        return ok

    def sample(self, rng, marginals=None):
        """Draw one solution per chain from the last :meth:`upward`: ``(n, B)`` states.

        With ``marginals`` (a list of ``(card, B)`` arrays), each variable's distribution given
        the variables drawn before it (its separator) is added to its entry: backward sampling
        draws from exactly that distribution, so it is a Rao-Blackwellised indicator.
        """
        B, jt = self.B, self.jt
        x = np.zeros((self.n, B), dtype=np.int64)
        u = rng.random((self.n, B))
        for i in range(self.n - 1, -1, -1):
            v = jt.order[i]
            c = self.card[v]
            probs = None
            for g, (span, base) in zip(self.groups[i], self.plan[i][2]):
                g = np.ascontiguousarray(g).reshape(-1)
                if span:
                    off = None
                    for a, st in span:
                        off = x[a] * st if off is None else off + x[a] * st
                    t = g.take(base + off)
                else:
                    t = g.take(base)
                probs = t if probs is None else probs * t
            if probs is None:
                x[v] = (u[i] * c).astype(np.int64)
                if marginals is not None:
                    marginals[v] += 1.0 / c
                continue
            x[v] = pick(probs, u[i], None if marginals is None else marginals[v])
        return x
