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
import math

import numba

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
        # downward: parent clique marginalised onto the child's separator, as a transpose that
        # puts the separator's axes last (down_perm, for log-sum-exp) and as a sum over the
        # parent's other axes followed by the transpose that puts the kept axes, left in the
        # parent's order, in separator order (down_sum, for the parent's exp table)
        self.down_perm = [None] * n
        self.down_sum = [None] * n
        for i, p in enumerate(self.parent):
            if p >= 0:
                ax = self.axes[p]
                keep = [ax.index(a) for a in seps[i]]
                rest = [k for k in range(len(ax)) if k not in keep]
                self.down_perm[i] = (tuple(rest + keep), tuple(card[a] for a in seps[i]))
                kept = sorted(keep)
                self.down_sum[i] = (tuple(rest), tuple(kept.index(k) for k in keep))

    def _place(self, scope, axes):
        perm, shape, targets = _placement(scope, axes)
        for j, t in zip(perm, targets):
            shape[t] = self.card[scope[j]]
        return perm, tuple(shape)

    def _per_scopes(self, name: str, scopes, build):
        """``build(key)`` for the scope list ``scopes`` (``key``: it as a tuple), cached in this
        tree under ``name`` (at most 17 scope lists; the engine passes the same scopes with
        new tables again and again)."""
        key = tuple(scopes)
        cache = self.__dict__.setdefault(name, {})
        hit = cache.get(key)
        if hit is None:
            if len(cache) > 16:
                cache.clear()
            hit = cache[key] = build(key)
        return hit

    def plan(self, scopes) -> "Plan":
        """The flat layout of this tree for factors over ``scopes`` (cached per scope list)."""
        return self._per_scopes("_plans", scopes, lambda key: Plan(self, key))

    def assign(self, scopes):
        """Clique index and placement for each factor scope (a list; cached per scope list)."""
        return list(self._per_scopes("_assigned", scopes, self._assign))

    def _assign(self, scopes) -> tuple:
        out = []
        for s in scopes:
            if not s:
                out.append(None)
                continue
            i = min(self.pos[v] for v in s)
            out.append((i,) + self._place(s, self.axes[i]))
        return tuple(out)


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
            beliefs[pl[0]] += _put(table, pl)     # in place: the beliefs are this call's own
    msgs = [None] * n
    for i in range(n):
        b = beliefs[i]
        msgs[i] = b.max(axis=0) if maximize else _lse(b, 0)
        p = jt.parent[i]
        if p >= 0:
            perm, shape = jt.msg_place[i]
            beliefs[p] += np.transpose(msgs[i], perm).reshape(shape)
    return beliefs, msgs, const


def calibrate(jt: JunctionTree, potentials, return_beliefs=False):
    """Sum-product: ``(log_z, marginals)`` with ``marginals[v]`` the distribution of variable v.

    With ``return_beliefs`` also the calibrated clique beliefs (log, unnormalised), for
    :func:`scope_marginal`.

    The downward pass exponentiates each calibrated clique once (:func:`_scaled`) and sums that
    table onto every child's separator and onto the clique's own variable, instead of a
    ``log Σ exp`` of the whole clique per child: a clique of a ground network has several
    children, and its exponentials were most of the time. A clique whose finite entries span
    more than :data:`_EXP_RANGE` nats, where some would underflow, takes :func:`_lse` per child.
    """
    beliefs, msgs, const = upward(jt, potentials)
    n = len(jt.order)
    log_z = const + sum(float(msgs[i]) for i in range(n) if jt.parent[i] < 0)
    if not np.isfinite(log_z):
        return (log_z, None, None) if return_beliefs else (log_z, None)
    full = [None] * n
    scaled = [None] * n     # a clique's exp table, kept until its last child has used it
    marg = [None] * n
    for i in range(n - 1, -1, -1):
        f = beliefs[i]
        p = jt.parent[i]
        if p >= 0:
            with np.errstate(invalid="ignore", divide="ignore"):
                d = _down_lse(jt, i, full[p], scaled[p]) - msgs[i]
            d = np.where(np.isnan(d), -np.inf, d)
            # the separator message enters clique i on its sep axes (axes 1..)
            f += d.reshape((1,) + d.shape)      # in place: f is upward's own belief
            if i == min(jt.children[p]):        # children come in descending order
                scaled[p] = None
        full[i] = f
        mine = _scaled(f)
        if jt.children[i]:
            scaled[i] = mine
        v = jt.order[i]
        if mine is not None:
            top, e = mine
            pm = e.reshape(e.shape[0], -1).sum(axis=1)
        else:
            x = f.reshape(f.shape[0], -1)
            lm = _lse(x, 1) if x.shape[1] > 1 else x[:, 0]
            pm = np.exp(lm - np.max(lm))
        marg[v] = pm / pm.sum()
    return (log_z, marg, full) if return_beliefs else (log_z, marg)


#: Largest span (nats) of a clique's finite log entries for :func:`_scaled`: ``exp(x - max)``
#: then stays a normal float (above 2.2e-308 = e^-708) for every entry, so no sum loses a term.
_EXP_RANGE = 700.0


def _scaled(f):
    """``(top, exp(f - top))`` for a log table whose finite entries lie within
    :data:`_EXP_RANGE` of their maximum ``top``; None when they spread wider or none is finite
    (the callers then take :func:`_lse`)."""
    top = float(f.max())
    if not np.isfinite(top):
        return None
    low = float(np.min(f, where=f > -np.inf, initial=np.inf))
    if top - low > _EXP_RANGE:
        return None
    return top, np.exp(f - top)


def _down_lse(jt: JunctionTree, i: int, parent_full, parent_scaled):
    """``log Σ exp`` of the parent's calibrated clique onto clique ``i``'s separator (in
    separator order); ``-inf`` where the parent has no possible state."""
    if parent_scaled is not None:
        top, e = parent_scaled
        rest, order = jt.down_sum[i]
        s = np.transpose(e.sum(axis=rest) if rest else e, order)
        out = np.full(s.shape, -np.inf)
        np.log(s, out=out, where=s > 0)
        return out + top
    rest_keep, sep_shape = jt.down_perm[i]
    pf = np.transpose(parent_full, rest_keep)
    flat = pf.reshape((-1,) + sep_shape) if sep_shape else pf.reshape(-1)
    return _lse(flat, 0)


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


def sum_out(card, potentials, drop, max_states=MAX_CLIQUE_STATES):
    """Log potentials with the variables ``drop`` summed out, one at a time (variable
    elimination): the factors holding a variable are added over the union of their scopes and
    ``log Σ exp`` is taken over it. Exact. A variable whose factors would join into more than
    ``max_states`` joint states (a soft atom that rules tie to many units) is kept instead.

    The MAP engines take it before maximising, so that soft evidence atoms are summed out and
    only the query atoms (types, SaLe) are maximised (:mod:`semmap_pp.knowledge.engine`).

    Returns
    -------
    (list of (scope, ndarray), float, list of int)
        The factors grouped by scope (sorted tuples), the log constant of those left with no
        variable, and the variables of ``drop`` that were kept.

    >>> t = np.log(np.array([[1.0, 3.0], [2.0, 2.0]]))   # over (type 0, soft atom 1)
    >>> pots, const, kept = sum_out([2, 2], [((0, 1), t)], [1])
    >>> [(s, np.exp(p).round(6).tolist()) for s, p in pots], const, kept
    ([((0,), [4.0, 4.0])], 0.0, [])
    """
    pots = [(tuple(s), np.asarray(t, dtype=np.float64)) for s, t in potentials]
    kept = []
    for v in drop:
        holding = [(s, t) for s, t in pots if v in s]
        if not holding:
            continue
        scope = tuple(sorted(set().union(*(s for s, _ in holding))))
        if int(np.prod([int(card[u]) for u in scope])) > max_states:
            kept.append(v)
            continue
        pots = [(s, t) for s, t in pots if v not in s]
        total = np.zeros(tuple(int(card[u]) for u in scope))
        for s, t in holding:
            total = total + t.reshape([int(card[u]) if u in s else 1 for u in scope])
        pots.append((tuple(u for u in scope if u != v), _lse(total, scope.index(v))))
    groups: dict = {}
    const = 0.0
    for s, t in pots:
        if not s:
            const += float(t)
        else:
            groups[s] = groups[s] + t if s in groups else t
    return list(groups.items()), const, kept


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


# ---- compiled calibration over flat clique tables (the engine's fast path) -------------------
#
# Clique i is stored flat in C order over its axes (eliminated variable first, then its
# separator), so its message to the parent is a log-sum over the leading axis and the downward
# separator term is broadcast along it. Index maps (parent state -> separator state, clique state
# -> factor state) are built once per tree and factor scopes (:meth:`JunctionTree.plan`).


class Plan:
    """Flat layout of a :class:`JunctionTree` and of one list of factor scopes, for
    :func:`calibrate_flat`.

    Attributes
    ----------
    ints : tuple of ndarray
        The integer arrays :func:`_calibrate_flat` reads (clique sizes and offsets, parents,
        separator maps, factor cliques and maps).
    factor_offsets : ndarray
        Where each factor's table starts in the packed potential values.
    n_values : int
        Length of the packed potential values.
    """

    def __init__(self, jt: JunctionTree, scopes):
        card = np.array(jt.card, dtype=np.int64)
        n = len(jt.order)
        cax = np.array([a for ax in jt.axes for a in ax], dtype=np.int64)
        caxoff = np.zeros(n + 1, dtype=np.int64)
        caxoff[1:] = np.cumsum([len(ax) for ax in jt.axes])
        pos = jt.pos
        fcl, fsc = [], []
        for s in scopes:
            if not s:
                raise ValueError("a factor without variables has no clique")
            fcl.append(min(pos[v] for v in s))
            fsc.append(len(s))
        fscoff = np.zeros(len(scopes) + 1, dtype=np.int64)
        fscoff[1:] = np.cumsum(fsc)
        fsv = np.array([v for s in scopes for v in s], dtype=np.int64)
        fcl = np.array(fcl, dtype=np.int64)
        parent = np.array(jt.parent, dtype=np.int64)
        ccard, coff, ssize, soff, emap, eoff, fmap, fmoff, foff = _plan_maps(
            card, cax, caxoff, parent, fsv, fscoff, fcl)
        self.ints = (ccard, coff, ssize, soff, parent, emap, eoff, fcl, fmap, fmoff, foff)
        for a in self.ints:
            a.setflags(write=False)
        self.factor_offsets = foff
        self.n_values = int(foff[-1])
        self.order = np.array(jt.order, dtype=np.int64)
        self.card = list(jt.card)
        self.scopes = list(scopes)
        # where each variable's marginal lies in the flat result, and each scope's table shape
        self.marg_slices, at = [], 0
        for v in jt.order:
            self.marg_slices.append((v, at, at + self.card[v]))
            at += self.card[v]
        self.scope_shapes = [tuple(self.card[v] for v in s) for s in self.scopes]


@numba.njit(cache=True, nogil=True)
def _sub_index(card, ax, sub, out):  # pragma: no cover - compiled
    """``out[t]``: flat index over the variables ``sub`` (C order) of each flat state ``t`` of a
    table over the variables ``ax`` (C order)."""
    a = ax.shape[0]
    stride = np.zeros(a, np.int64)
    st = 1
    for j in range(sub.shape[0] - 1, -1, -1):
        for k in range(a):
            if ax[k] == sub[j]:
                stride[k] = st
        st *= card[sub[j]]
    digit = np.zeros(a, np.int64)
    idx = 0
    for t in range(out.shape[0]):
        out[t] = idx
        k = a - 1   # mixed-radix increment, last axis fastest
        while k >= 0:
            digit[k] += 1
            idx += stride[k]
            if digit[k] < card[ax[k]]:
                break
            idx -= stride[k] * digit[k]
            digit[k] = 0
            k -= 1


@numba.njit(cache=True, nogil=True)
def _plan_maps(card, cax, caxoff, parent, fsv, fscoff, fcl):  # pragma: no cover - compiled
    n = parent.shape[0]
    ccard = np.empty(n, np.int64)
    coff = np.zeros(n + 1, np.int64)
    ssize = np.empty(n, np.int64)
    soff = np.zeros(n + 1, np.int64)
    for i in range(n):
        ax = cax[caxoff[i]:caxoff[i + 1]]
        size = 1
        for k in range(ax.shape[0]):
            size *= card[ax[k]]
        ccard[i] = card[ax[0]]
        coff[i + 1] = coff[i] + size
        ssize[i] = size // ccard[i]
        soff[i + 1] = soff[i] + ssize[i]
    eoff = np.zeros(n + 1, np.int64)
    for i in range(n):
        p = parent[i]
        eoff[i + 1] = eoff[i] + (coff[p + 1] - coff[p] if p >= 0 else 0)
    emap = np.empty(eoff[n], np.int64)
    for i in range(n):
        p = parent[i]
        if p >= 0:   # the child's separator is its axes after the first
            _sub_index(card, cax[caxoff[p]:caxoff[p + 1]], cax[caxoff[i] + 1:caxoff[i + 1]],
                       emap[eoff[i]:eoff[i + 1]])
    nf = fcl.shape[0]
    fmoff = np.zeros(nf + 1, np.int64)
    foff = np.zeros(nf + 1, np.int64)
    for f in range(nf):
        i = fcl[f]
        fmoff[f + 1] = fmoff[f] + coff[i + 1] - coff[i]
        size = 1
        for k in range(fscoff[f], fscoff[f + 1]):
            size *= card[fsv[k]]
        foff[f + 1] = foff[f] + size
    fmap = np.empty(fmoff[nf], np.int64)
    for f in range(nf):
        i = fcl[f]
        _sub_index(card, cax[caxoff[i]:caxoff[i + 1]], fsv[fscoff[f]:fscoff[f + 1]],
                   fmap[fmoff[f]:fmoff[f + 1]])
    return ccard, coff, ssize, soff, emap, eoff, fmap, fmoff, foff


@numba.njit(cache=True, nogil=True)
def _calibrate_flat(ccard, coff, ssize, soff, parent, emap, eoff, fcl, fmap, fmoff, foff, values,
                    want):  # pragma: no cover - compiled
    """Sum-product on flat cliques: ``(log_z, marginals by elimination step, pair marginals of the
    factors in want)``; the marginals are empty when log_z is not finite."""
    belief, msg, log_z = _upward(ccard, coff, ssize, soff, parent, emap, eoff, fcl, fmap, fmoff,
                                 foff, values)
    marg = np.zeros(0)
    pairs = np.zeros(0)
    if not np.isfinite(log_z):
        return log_z, marg, pairs
    marg = _downward(ccard, coff, ssize, soff, parent, emap, eoff, belief, msg)
    pairs = _factor_marginals(coff, fcl, fmap, fmoff, foff, belief, want)
    return log_z, marg, pairs


@numba.njit(cache=True, nogil=True)
def _upward(ccard, coff, ssize, soff, parent, emap, eoff, fcl, fmap, fmoff, foff,
            values):  # pragma: no cover - compiled
    """The factors summed into their cliques' beliefs and the messages sent towards the root:
    ``(beliefs, messages, log_z)``."""
    n = ccard.shape[0]
    belief = np.zeros(coff[n])
    for f in range(fcl.shape[0]):
        i = fcl[f]
        b0, m0, v0 = coff[i], fmoff[f], foff[f]
        for t in range(coff[i + 1] - b0):
            belief[b0 + t] += values[v0 + fmap[m0 + t]]
    msg = np.empty(soff[n])
    log_z = 0.0
    for i in range(n):   # children come before their parents in elimination order
        S, K, b0, s0 = ssize[i], ccard[i], coff[i], soff[i]
        for s in range(S):
            m = -np.inf
            for k in range(K):
                x = belief[b0 + k * S + s]
                if x > m:
                    m = x
            if m == -np.inf:
                msg[s0 + s] = -np.inf
                continue
            acc = 0.0
            for k in range(K):
                acc += np.exp(belief[b0 + k * S + s] - m)
            msg[s0 + s] = np.log(acc) + m
        p = parent[i]
        if p >= 0:
            e0, pb = eoff[i], coff[p]
            for t in range(coff[p + 1] - pb):
                belief[pb + t] += msg[s0 + emap[e0 + t]]
        else:
            log_z += msg[s0]
    return belief, msg, log_z


@numba.njit(cache=True, nogil=True)
def _downward(ccard, coff, ssize, soff, parent, emap, eoff, belief,
              msg):  # pragma: no cover - compiled
    """The downward pass (``belief`` made the calibrated clique beliefs, in place) and the
    marginal of each elimination step's variable."""
    n = ccard.shape[0]
    moff = np.zeros(n + 1, np.int64)
    for i in range(n):
        moff[i + 1] = moff[i] + ccard[i]
    marg = np.empty(moff[n])
    smax = 1
    for i in range(n):
        if ssize[i] > smax:
            smax = ssize[i]
    mx = np.empty(smax)
    acc = np.empty(smax)
    for i in range(n - 1, -1, -1):   # downward: full[i] = belief[i] + (parent's sep term - msg)
        S, K, b0, s0 = ssize[i], ccard[i], coff[i], soff[i]
        p = parent[i]
        if p >= 0:
            e0, pb = eoff[i], coff[p]
            for s in range(S):
                mx[s] = -np.inf
                acc[s] = 0.0
            for t in range(coff[p + 1] - pb):
                x = belief[pb + t]
                s = emap[e0 + t]
                if x > mx[s]:
                    mx[s] = x
            for t in range(coff[p + 1] - pb):
                s = emap[e0 + t]
                if mx[s] > -np.inf:
                    acc[s] += np.exp(belief[pb + t] - mx[s])
            for s in range(S):
                ms = msg[s0 + s]
                if mx[s] == -np.inf or ms == -np.inf:
                    d = -np.inf
                else:
                    d = np.log(acc[s]) + mx[s] - ms
                for k in range(K):
                    belief[b0 + k * S + s] += d
        top = -np.inf
        for k in range(K):
            m = -np.inf
            for s in range(S):
                x = belief[b0 + k * S + s]
                if x > m:
                    m = x
            if m > -np.inf:
                a = 0.0
                for s in range(S):
                    a += np.exp(belief[b0 + k * S + s] - m)
                m = np.log(a) + m
            marg[moff[i] + k] = m
            if m > top:
                top = m
        tot = 0.0
        for k in range(K):
            e = np.exp(marg[moff[i] + k] - top)
            marg[moff[i] + k] = e
            tot += e
        for k in range(K):
            marg[moff[i] + k] /= tot
    return marg


@numba.njit(cache=True, nogil=True)
def _factor_marginals(coff, fcl, fmap, fmoff, foff, belief, want):  # pragma: no cover - compiled
    """The joint marginals of the scopes of the factors ``want`` from the calibrated beliefs."""
    # joint marginals of the wanted factors' scopes (grouped log-sums of their clique)
    poff = np.zeros(want.shape[0] + 1, np.int64)
    for w in range(want.shape[0]):
        f = want[w]
        poff[w + 1] = poff[w] + foff[f + 1] - foff[f]
    pairs = np.empty(poff[want.shape[0]])
    for w in range(want.shape[0]):
        f = want[w]
        i = fcl[f]
        b0, m0, q0, Q = coff[i], fmoff[f], poff[w], poff[w + 1] - poff[w]
        for q in range(Q):
            pairs[q0 + q] = -np.inf
        for t in range(coff[i + 1] - b0):
            x = belief[b0 + t]
            q = fmap[m0 + t]
            if x > pairs[q0 + q]:
                pairs[q0 + q] = x
        mq = pairs[q0:q0 + Q].copy()
        for q in range(Q):
            pairs[q0 + q] = 0.0
        for t in range(coff[i + 1] - b0):
            q = fmap[m0 + t]
            if mq[q] > -np.inf:
                pairs[q0 + q] += np.exp(belief[b0 + t] - mq[q])
        top = -np.inf
        for q in range(Q):
            lm = np.log(pairs[q0 + q]) + mq[q] if mq[q] > -np.inf else -np.inf
            pairs[q0 + q] = lm
            if lm > top:
                top = lm
        tot = 0.0
        for q in range(Q):
            e = np.exp(pairs[q0 + q] - top)
            pairs[q0 + q] = e
            tot += e
        for q in range(Q):
            pairs[q0 + q] /= tot
    return pairs


def calibrate_flat(plan: Plan, tables, want=()):
    """:func:`calibrate` and :func:`scope_marginal` in one compiled pass.

    Parameters
    ----------
    plan : Plan
        Of the tree and the factor scopes of ``tables``.
    tables : list of ndarray
        Log potential of each factor (over its sorted scope), in the plan's scope order.
    want : sequence of int
        Factors whose joint scope marginal is wanted.

    Returns
    -------
    (float, list of ndarray or None, list of ndarray)
        ``log Z``, the marginal of each variable (None when no world is possible) and the joint
        distribution of each wanted factor's scope (shaped as its table).
    """
    values = np.concatenate(tables, axis=None, dtype=np.float64) if len(tables) else np.zeros(0)
    w = np.asarray(want, dtype=np.int64)
    log_z, flat, pairs = _calibrate_flat(*plan.ints, values, w)
    if not np.isfinite(log_z):
        return float(log_z), None, []
    marg = [None] * len(plan.order)
    for v, a, b in plan.marg_slices:
        marg[v] = flat[a:b]
    out, at = [], 0
    for f in want:
        shape = plan.scope_shapes[f]
        size = math.prod(shape)
        out.append(pairs[at:at + size].reshape(shape))
        at += size
    return float(log_z), marg, out
