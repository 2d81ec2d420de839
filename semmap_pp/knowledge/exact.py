"""Exact inference on a :class:`~semmap_pp.knowledge.ground.Network`: a junction tree.

The tree comes from greedy min-weight variable elimination: eliminating variable ``v`` creates
the clique ``{v} ∪ N(v)`` whose separator to its parent is ``N(v)``, so every clique removes
exactly one variable. Sum-product (log space) gives log Z and every marginal after one upward and
one downward (Hugin) pass; max-product with back-tracking gives the MAP assignment. The rule
networks are small and of low treewidth (a SaLe atom couples two units' types), so this is exact
and fast; a clique of more than :data:`MAX_CLIQUE_STATES` joint states is refused.
"""

from __future__ import annotations

import heapq

import numpy as np

from semmap_pp.errors import RuleError

MAX_CLIQUE_STATES = 1 << 22


class TooDense(RuleError):
    """The junction tree would have a clique above the allowed number of joint states."""


def merged_potentials(net) -> list[tuple[tuple[int, ...], np.ndarray]]:
    """Log potentials of ``net`` grouped by scope: ``-Σ w/1000 · viol`` and ``-inf`` for hard."""
    groups: dict = {}
    for scope, viol in net.hard:
        arr = groups.get(scope)
        if arr is None:
            arr = groups[scope] = np.zeros(viol.shape)
        arr[viol] = -np.inf
    for scope, t, w in net.soft:
        arr = groups.get(scope)
        if arr is None:
            arr = groups[scope] = np.zeros(t.shape)
        arr -= (w / 1000.0) * t
    return list(groups.items())


def _placement(scope, axes):
    """Transpose + reshape that put a table over sorted ``scope`` onto clique ``axes``."""
    where = {v: i for i, v in enumerate(axes)}
    order = sorted(range(len(scope)), key=lambda j: where[scope[j]])
    perm = tuple(order)
    shape = [1] * len(axes)
    return perm, shape, [where[scope[j]] for j in order]


class JunctionTree:
    """Clique structure for a set of factor scopes over variables of given cardinalities.

    Parameters
    ----------
    card : array of int
        Cardinality of each variable.
    scopes : list of tuple of int
        Sorted factor scopes.
    path : str
        Named in the error when the tree would be too large.
    max_states : int
        Largest clique allowed (joint states); a larger one raises :class:`TooDense`.

    Attributes
    ----------
    largest : int
        Joint states of the largest clique.
    """

    def __init__(self, card, scopes, path=None, max_states=MAX_CLIQUE_STATES):
        card = [int(c) for c in card]
        n = len(card)
        self.card = card
        nbrs = [set() for _ in range(n)]
        for s in scopes:
            for v in s:
                nbrs[v].update(s)
        for v in range(n):
            nbrs[v].discard(v)

        def weight(v):
            w = card[v]
            for a in nbrs[v]:
                w *= card[a]
            return w

        current = [weight(v) for v in range(n)]
        heap = [(current[v], v) for v in range(n)]
        heapq.heapify(heap)
        done = [False] * n
        order, seps = [], []
        largest = 1
        while heap:
            w, v = heapq.heappop(heap)
            if done[v] or w != current[v]:
                continue
            if w > max_states:
                raise TooDense(path, f"the ground network is too densely connected for exact "
                               f"inference (a clique of {w} states); use method='auto' or 'lbp'")
            largest = max(largest, w)
            done[v] = True
            sep = sorted(nbrs[v])
            for a in sep:
                nbrs[a].discard(v)
                nbrs[a].update(b for b in sep if b != a)
            for a in sep:
                current[a] = weight(a)
                heapq.heappush(heap, (current[a], a))
            order.append(v)
            seps.append(tuple(sep))
        pos = [0] * n
        for i, v in enumerate(order):
            pos[v] = i
        self.order, self.seps, self.pos, self.largest = order, seps, pos, largest
        self.axes = [(v,) + s for v, s in zip(order, seps)]
        self.shapes = [tuple(card[a] for a in ax) for ax in self.axes]
        self.parent = [min((pos[a] for a in s), default=-1) for s in seps]
        self.children = [[] for _ in range(n)]
        for i, p in enumerate(self.parent):
            if p >= 0:
                self.children[p].append(i)
        # where each child's message (over its separator) lands in the parent clique
        self.msg_place = [None] * n
        for i, p in enumerate(self.parent):
            if p >= 0:
                self.msg_place[i] = self._place(seps[i], self.axes[p])
        # downward: parent clique marginalised onto the child's separator
        self.down_perm = [None] * n
        for i, p in enumerate(self.parent):
            if p >= 0:
                ax = self.axes[p]
                keep = [ax.index(a) for a in seps[i]]
                rest = [k for k in range(len(ax)) if k not in keep]
                self.down_perm[i] = (tuple(rest + keep), tuple(card[a] for a in seps[i]))

    def _place(self, scope, axes):
        perm, shape, targets = _placement(scope, axes)
        for j, t in zip(perm, targets):
            shape[t] = self.card[scope[j]]
        return perm, tuple(shape)

    def assign(self, scopes):
        """Clique index and placement for each factor scope."""
        out = []
        for s in scopes:
            if not s:
                out.append(None)
                continue
            i = min(self.pos[v] for v in s)
            out.append((i,) + self._place(s, self.axes[i]))
        return out


def _lse(x, axis):
    """``log Σ exp`` along ``axis`` (``-inf`` where every entry is ``-inf``)."""
    m = x.max(axis=axis, keepdims=True)
    fin = np.isfinite(m)
    if not fin.all():
        m = np.where(fin, m, 0.0)
    s = np.exp(x - m).sum(axis=axis)
    pos = s > 0
    if pos.all():
        out = np.log(s)
    else:
        out = np.full(s.shape, -np.inf)
        np.log(s, out=out, where=pos)
    out += m.reshape(out.shape)
    return out


def _put(table, placement):
    _i, perm, shape = placement
    return np.transpose(table, perm).reshape(shape)


def upward(jt: JunctionTree, potentials, maximize=False):
    """Clique beliefs after the upward pass and the messages sent to parents."""
    scopes = [s for s, _ in potentials]
    placed = jt.assign(scopes)
    n = len(jt.order)
    beliefs = [np.zeros(shape) for shape in jt.shapes]
    const = 0.0
    for (s, table), pl in zip(potentials, placed):
        if pl is None:
            const += float(table)
        else:
            beliefs[pl[0]] = beliefs[pl[0]] + _put(table, pl)
    msgs = [None] * n
    for i in range(n):
        b = beliefs[i]
        msgs[i] = b.max(axis=0) if maximize else _lse(b, 0)
        p = jt.parent[i]
        if p >= 0:
            perm, shape = jt.msg_place[i]
            beliefs[p] = beliefs[p] + np.transpose(msgs[i], perm).reshape(shape)
    return beliefs, msgs, const


def calibrate(jt: JunctionTree, potentials, return_beliefs=False):
    """Sum-product: ``(log_z, marginals)`` with ``marginals[v]`` the distribution of variable v.

    With ``return_beliefs`` also the calibrated clique beliefs (log, unnormalised), for
    :func:`scope_marginal`.
    """
    beliefs, msgs, const = upward(jt, potentials)
    n = len(jt.order)
    log_z = const + sum(float(msgs[i]) for i in range(n) if jt.parent[i] < 0)
    if not np.isfinite(log_z):
        return (log_z, None, None) if return_beliefs else (log_z, None)
    full = [None] * n
    marg = [None] * n
    for i in range(n - 1, -1, -1):
        f = beliefs[i]
        p = jt.parent[i]
        if p >= 0:
            rest_keep, sep_shape = jt.down_perm[i]
            pf = np.transpose(full[p], rest_keep)
            k = len(sep_shape)
            flat = pf.reshape((-1,) + sep_shape) if k else pf.reshape(-1)
            with np.errstate(invalid="ignore"):
                d = _lse(flat, 0) - msgs[i]
            d = np.where(np.isnan(d), -np.inf, d)
            perm, shape = jt.msg_place[i]
            # the separator message enters clique i on its sep axes (axes 1..)
            f = f + d.reshape((1,) + d.shape)
        full[i] = f
        v = jt.order[i]
        x = f.reshape(f.shape[0], -1)
        lm = _lse(x, 1) if x.shape[1] > 1 else x[:, 0]
        pm = np.exp(lm - np.max(lm))
        marg[v] = pm / pm.sum()
    return (log_z, marg, full) if return_beliefs else (log_z, marg)


def scope_marginal(jt: JunctionTree, full, scope):
    """Joint distribution of the sorted ``scope`` (contained in one clique) from beliefs."""
    i = min(jt.pos[v] for v in scope)
    ax = jt.axes[i]
    keep = [ax.index(v) for v in scope]
    rest = [k for k in range(len(ax)) if k not in keep]
    t = np.transpose(full[i], rest + keep).reshape((-1,) + tuple(jt.card[v] for v in scope))
    lm = _lse(t, 0)
    pm = np.exp(lm - np.max(lm))
    return pm / pm.sum()


def decode_max(jt: JunctionTree, potentials):
    """Max-product MAP assignment (lowest state wins ties) and its log potential."""
    beliefs, msgs, const = upward(jt, potentials, maximize=True)
    n = len(jt.order)
    best = const + sum(float(msgs[i]) for i in range(n) if jt.parent[i] < 0)
    x = np.zeros(n, dtype=np.int64)
    for i in range(n - 1, -1, -1):
        idx = (slice(None),) + tuple(int(x[a]) for a in jt.seps[i])
        x[jt.order[i]] = int(np.argmax(beliefs[i][idx]))
    return x, best
