"""MC-SAT marginals (Poon & Domingos 2006), run as many chains at once.

Each iteration keeps every soft rule that the current world satisfies with probability
``1 - e^-w`` and draws the next world uniformly from the worlds that satisfy the hard rules and
the kept soft rules. The uniform draw is exact here, not SampleSAT's near-uniform one: the slice
is a 0/1 factor network on the junction tree of :mod:`~semmap_pp.knowledge.exact`, so counting
(upward pass) and drawing (downward pass) cost what exact inference costs, and MC-SAT is then a
slice sampler whose only error is Monte Carlo error. ``n_chains`` chains run vectorised; each
starts from a uniform draw over the hard-feasible worlds and discards ``burn_in`` iterations.
"""

from __future__ import annotations

import numpy as np

from semmap_pp.errors import RuleError
from semmap_pp.knowledge.exact import JunctionTree


def _strides(shape):
    out, acc = [], 1
    for c in reversed(shape):
        out.append(acc)
        acc *= c
    return np.array(out[::-1], dtype=np.int64)


def mcsat_marginals(net, rng, n_chains=256, n_iter=24, burn_in=4, jt=None):
    """Marginals of every variable of ``net`` by MC-SAT.

    Parameters
    ----------
    net : Network
    rng : numpy.random.Generator
    n_chains, n_iter, burn_in : int
        Chains run in parallel, iterations per chain, iterations discarded per chain.
    jt : JunctionTree, optional
        A tree over the scopes of ``net`` (built if absent).

    Returns
    -------
    list of ndarray
        ``marg[v]`` is the estimated distribution of variable ``v``.
    """
    card = [int(c) for c in net.card]
    n = len(card)
    scopes = [s for s, _ in net.hard] + [s for s, _t, _w in net.soft]
    if jt is None:
        jt = JunctionTree(card, scopes, net.path)
    B = int(n_chains)
    # fixed hard potentials per clique (linear space, 0/1)
    base = [np.ones((1,) + sh) for sh in jt.shapes]
    for (s, viol), pl in zip(net.hard, jt.assign([s for s, _ in net.hard])):
        i, perm, shape = pl
        base[i] = base[i] * np.transpose(~viol, perm).reshape((1,) + shape)
    # soft factors grouped by scope
    groups: dict = {}
    for s, t, w in net.soft:
        groups.setdefault(s, []).append((t.reshape(-1), w))
    soft = []
    for s, items in groups.items():
        V = np.array([t for t, _ in items], dtype=np.float64)          # (k, D)
        keep_p = 1.0 - np.exp(-np.array([w for _, w in items]) / 1000.0)
        i, perm, shape = jt.assign([s])[0]
        shp = tuple(card[v] for v in s)
        soft.append((list(s), _strides(shp), V, keep_p, i, shp, (0,) + tuple(p + 1 for p in perm),
                     (B,) + shape))
    sep_strides = [_strides(tuple(card[a] for a in sep)) for sep in jt.seps]
    rows = np.arange(B)

    def draw(pots):
        beliefs = list(pots)
        for i in range(n):
            b = beliefs[i]
            msg = b.sum(axis=1)
            scale = msg.reshape(B, -1).max(axis=1)
            if not np.all(scale > 0):
                raise RuleError(net.path, "the hard rules admit no world for this evidence")
            msg = msg / scale.reshape((B,) + (1,) * (msg.ndim - 1))
            p = jt.parent[i]
            if p >= 0:
                perm, shape = jt.msg_place[i]
                beliefs[p] = beliefs[p] * np.transpose(
                    msg, (0,) + tuple(q + 1 for q in perm)).reshape((B,) + shape)
        x = np.zeros((B, n), dtype=np.int64)
        u = rng.random((n, B))
        for i in range(n - 1, -1, -1):
            b = beliefs[i].reshape(B, card[jt.order[i]], -1)
            sep = jt.seps[i]
            sidx = x[:, list(sep)] @ sep_strides[i] if sep else np.zeros(B, dtype=np.int64)
            probs = b[rows, :, sidx]
            cum = np.cumsum(probs, axis=1)
            pick = (u[i][:, None] * cum[:, -1:] >= cum).sum(axis=1)
            x[:, jt.order[i]] = np.minimum(pick, card[jt.order[i]] - 1)
        return x

    pots0 = [np.broadcast_to(b, (B,) + b.shape[1:]) for b in base]
    x = draw(pots0)
    counts = [np.zeros(c) for c in card]
    kept_iters = 0
    for it in range(int(n_iter)):
        pots = list(pots0)
        for scope, strides, V, keep_p, i, shp, perm, shape in soft:
            idx = x[:, scope] @ strides
            viol_now = V[:, idx].T                                   # (B, k)
            keep = (viol_now == 0) & (rng.random(viol_now.shape) < keep_p)
            allowed = (keep.astype(np.float64) @ V) == 0              # (B, D)
            pots[i] = pots[i] * np.transpose(allowed.reshape((B,) + shp), perm).reshape(shape)
        x = draw(pots)
        if it >= burn_in:
            kept_iters += 1
            for v in range(n):
                counts[v] += np.bincount(x[:, v], minlength=card[v])
    total = kept_iters * B
    return [c / total for c in counts]
