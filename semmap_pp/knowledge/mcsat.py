"""MC-SAT marginals (Poon & Domingos 2006), all chains at once.

Each iteration keeps every soft clause (ground weak-constraint tuple) that the current world
satisfies with probability ``1 - e^-w`` and draws the next world uniformly from the worlds that
satisfy the hard clauses and the kept soft clauses. The uniform draw is exact, not SampleSAT's
near-uniform one: the slice is a 0/1 factor network on a junction tree, so a counting (upward)
pass and a sampling (downward) pass draw a uniform solution (forward filtering, backward
sampling). MC-SAT is then a slice sampler whose only error is Monte Carlo error.

All chains move together: every array has the chain axis last, so one iteration is a few
compiled loops per clause block (keep coins, count tables, private atoms) and one per tree pass
(:mod:`~semmap_pp.knowledge.mcsat_tree`), over arrays reused by every iteration. Clauses come in :class:`ClauseBlock` s, instances of
one :class:`ClauseTemplate`: the clauses on a scope of junction-tree variables plus *private*
atoms that occur in no other block (e.g. the SaLe atoms of an adjacent pair on the pairwise fast
path), which are counted inside the block and drawn uniformly among the allowed ones once the
scope is drawn. A template's clauses are bits of an integer word; the kept clauses of an instance
in a chain are one word, and its 0/1 table is read from a table indexed by that word.

The estimate is Rao-Blackwellised: every kept iteration adds, for each variable, the
distribution the backward pass draws it from (its conditional given the variables drawn before
it, in the slice), and for each reported private atom its probability given the drawn scope.
Each is the conditional expectation of the indicator it replaces, so the estimate keeps its mean
and loses part of its variance. Chains start from a world of the hard clauses weighted by the
single-variable blocks' clauses alone (the unit rules, pair rules ignored), closer to the target
than a uniform world, so a shorter burn-in suffices.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass

import numba
import numpy as np

from semmap_pp.errors import RuleError
from semmap_pp.knowledge.dialect import WEIGHT_SCALE
from semmap_pp.knowledge.exact import JunctionTree
from semmap_pp.knowledge.mcsat_tree import BatchTree, pick

_NO_WORLD = "the hard rules admit no world for this evidence"
WORD_BITS = 62        # clauses per int64 word (bit 62 marks hard-forbidden states)
CHUNK_BITS = 8        # clauses whose keep coins are drawn together from one alias table
LUT_BITS = 16         # a template with at most this many clauses counts by table look-up ...
LUT_ENTRIES = 1 << 22  # ... if the table has at most this many entries
_HARD_BIT = np.int64(1) << np.int64(WORD_BITS)   # marks (scope, private) states hard rules forbid


def keep_probability(weights) -> np.ndarray:
    """``1 - e^-w`` for weights ``w`` in thousandths (the rule files' integers)."""
    return -np.expm1(-np.asarray(weights, dtype=np.float64) / WEIGHT_SCALE)


@numba.njit(cache=True, nogil=True)
def _alias_draw(u, n, cut, alias, tid, shift, word):
    """Alias method: slot ``i = floor(u n)`` keeps ``i`` if the fraction is below ``q[i]``."""
    I, B = u.shape
    for r in range(I):
        base = tid[r] * n
        for b in range(B):
            v = u[r, b] * n
            i = int(v)
            j = base + i
            word[r, b] |= (i if v < cut[j] else alias[j]) << shift


@numba.njit(cache=True, nogil=True)
def _lut_gather(lut, word, col, out):
    """``out[i, s, b] = lut[s, word[i, b] + col[i]]`` as float32."""
    I, B = word.shape
    S = lut.shape[0]
    for i in range(I):
        for s in range(S):
            row = lut[s]
            o = out[i, s]
            for b in range(B):
                o[b] = row[word[i, b] + col[i]]


@numba.njit(cache=True, nogil=True)
def _lut_rows(lut, word, col, rows, G):
    """``G[rows[i] + s, b] = lut[s, word[i, b] + col[i]]``: count tables into their rows."""
    I, B = word.shape
    S = lut.shape[0]
    for i in range(I):
        for s in range(S):
            row = lut[s]
            o = G[rows[i] + s]
            for b in range(B):
                o[b] = row[word[i, b] + col[i]]


@numba.njit(cache=True, nogil=True)
def _kept_word(u, base, n, c0, cut, alias, tid, mask, aux, cell, word):
    """One word of keep coins per instance and chain, all chunks at once (alias method per
    chunk ``j``: table ``base[j] + tid * n[j]``), minus the clauses the current state
    ``(aux, cell)`` violates."""
    J, I, B = u.shape
    for r in range(I):
        t = tid[r]
        for b in range(B):
            w = np.int64(0)
            for j in range(J):
                v = u[j, r, b] * n[j]
                i = int(v)
                k = base[j] + t * n[j] + i
                a = alias[k]
                w |= (i if v < cut[k] else a) << c0[j]
            word[r, b] = w & ~mask[aux[r, b], cell[r, b]]


@numba.njit(cache=True, nogil=True)
def _cells(x, scopes, strides, tid, S, out):
    """``out[i, b] = tid[i] * S + sum_r x[scopes[i, r], b] * strides[r]``: each instance's
    drawn scope state, as a column of its stack's tables."""
    I, R = scopes.shape
    B = x.shape[1]
    for i in range(I):
        o = out[i]
        t = tid[i] * S
        for b in range(B):
            o[b] = t
        for r in range(R):
            xr = x[scopes[i, r]]
            st = strides[r]
            for b in range(B):
                o[b] += xr[b] * st


@numba.njit(cache=True, nogil=True)
def _drop_violated(word, mask, aux, cell):
    """Clear the bits of clauses the current state ``(aux, cell)`` violates (never kept)."""
    I, B = word.shape
    for r in range(I):
        for b in range(B):
            word[r, b] &= ~mask[aux[r, b], cell[r, b]]


@numba.njit(cache=True, nogil=True)
def _draw_private(mask, hard_bit, cell, word, u, on, aux, est, acc):
    """Private state drawn uniformly among the allowed ones at the drawn scope state, and
    (with ``acc``) the fraction of them in which the reported atom holds added to ``est``."""
    A = mask.shape[0]
    I, B = cell.shape
    for r in range(I):
        for b in range(B):
            c = cell[r, b]
            w = word[r, b] | hard_bit
            n = 0
            n_on = 0
            for a in range(A):
                if (mask[a, c] & w) == 0:
                    n += 1
                    if on[a]:
                        n_on += 1
            target = int(u[r, b] * n)
            seen = 0
            for a in range(A):
                if (mask[a, c] & w) == 0:
                    if seen == target:
                        aux[r, b] = a
                        break
                    seen += 1
            if acc:
                est[r, b] += n_on / n


def _buffer(buf, name, shape, dtype, zero=False):
    """A reusable array of ``buf`` (a fresh one without ``buf``): no page faults per call."""
    arr = None if buf is None else buf.get(name)
    if arr is None or arr.shape != tuple(shape) or arr.dtype != dtype:
        arr = np.zeros(shape, dtype=dtype) if zero else np.empty(shape, dtype=dtype)
        if buf is not None:
            buf[name] = arr
    return arr


def _alias(prob):
    """Walker/Vose alias table ``(q, alias)`` of a discrete distribution."""
    n = len(prob)
    scaled = np.asarray(prob, dtype=np.float64) * n / np.sum(prob)
    q, alias = np.ones(n), np.arange(n)
    small = [i for i in range(n) if scaled[i] < 1.0]
    large = [i for i in range(n) if scaled[i] >= 1.0]
    while small and large:
        s, g = small.pop(), large.pop()
        q[s], alias[s] = scaled[s], g
        scaled[g] -= 1.0 - scaled[s]
        (small if scaled[g] < 1.0 else large).append(g)
    return q, alias


class ClauseTemplate:
    """The clauses of one kind of block (hard allowed states, merged soft clauses).

    Parameters
    ----------
    shape : tuple of int
        Cardinalities of the scope variables.
    n_aux : int
        Joint states of the private atoms (1 if none).
    hard : ndarray of bool, shape (D,)
        Assignments of (scope, private atoms) allowed by the hard clauses, ``D =
        prod(shape) * n_aux``, row-major with the private atoms last.
    viol : ndarray of bool, shape (k, D)
        Violation table of each soft clause.
    weights : sequence of int
        Weight (thousandths) of each soft clause.
    aux_on : ndarray of bool, shape (n_aux,), optional
        Private states in which the reported private atom (e.g. ``sale(p,q)``) holds.
    """

    def __init__(self, shape, n_aux, hard, viol, weights, aux_on=None):
        self.shape = tuple(int(c) for c in shape)
        self.n_states = S = int(np.prod(self.shape, dtype=np.int64))
        hard = np.asarray(hard, dtype=bool).reshape(S, int(n_aux))
        # private states no scope state allows are never drawn: drop them
        live = np.flatnonzero(hard.any(axis=0))
        if len(live) == 0:
            live = np.array([0])
        self.n_aux = A = len(live)
        self.hard = np.ascontiguousarray(hard[:, live].T)                         # (A, S)
        viol = np.asarray(viol, dtype=bool).reshape(len(weights), S, int(n_aux))[:, :, live]
        viol = viol.transpose(0, 2, 1) & self.hard                                # (k, A, S)
        cost = (np.asarray(weights, dtype=np.float64)[:, None, None] * viol).sum(axis=0)
        # a clause's only effect on the slice is the set of states it forbids when kept, and
        # two clauses with one violation set are kept together with probability
        # 1 - e^-(w1 + w2): merge them; drop clauses that no reachable state violates or
        # satisfies (never constraining, or never kept)
        merged: dict = {}
        n_live = int(self.hard.sum())
        for t, w in zip(viol, weights):
            n_bad = int(t.sum())
            if 0 < n_bad < n_live:
                key = t.tobytes()
                merged[key] = (t, merged.get(key, (t, 0))[1] + int(w))
        self.viol = np.array([t for t, _ in merged.values()], dtype=bool).reshape(-1, A, S)
        self.k = len(self.viol)
        self.keep_p = keep_probability([w for _, w in merged.values()])
        # weights of the states by this block's clauses alone (a chain's starting distribution)
        finite = np.where(self.hard, cost, np.inf)
        low = finite.min() if np.isfinite(finite).any() else 0.0
        self.prior = np.where(self.hard, np.exp(-(cost - low) / WEIGHT_SCALE), 0.0).sum(axis=0)
        self.aux_on = None if aux_on is None else np.asarray(aux_on, dtype=bool)[live]
        self._alias: dict = {}

    def stack_key(self):
        """Templates with equal keys can share one :class:`ClauseStack`."""
        on = None if self.aux_on is None else self.aux_on.tobytes()
        return (self.shape, self.n_aux, on, self.k <= WORD_BITS)

    def alias(self, c0, width):
        """Alias table ``(i + q, alias)`` of the keep coins of clauses ``c0 .. c0+width-1``."""
        hit = self._alias.get((c0, width))
        if hit is None:
            p = np.zeros(width)
            part = self.keep_p[c0:c0 + width]
            p[:len(part)] = part                      # clauses beyond k: never kept
            outcomes = np.arange(1 << width)
            on = ((outcomes[:, None] >> np.arange(width)) & 1).astype(bool)
            q, alias = _alias(np.where(on, p, 1.0 - p).prod(axis=1))
            hit = self._alias[(c0, width)] = (outcomes + q, alias)
        return hit


class ClauseStack:
    """Clause templates of one shape compiled together for batched MC-SAT.

    Each instance of a block names its template; tables are laid side by side so that one
    gather serves every template: clause masks ``(A, T*S)``, alias tables ``T*n`` and count
    tables ``(S, T * 2^k)``, read at offsets ``tid * S``, ``tid * n`` and ``tid << k``.
    """

    def __init__(self, templates):
        t0 = templates[0]
        self.templates = templates
        self.shape, self.n_states, self.n_aux = t0.shape, t0.n_states, t0.n_aux
        self.aux_on = t0.aux_on
        T, S, A = len(templates), self.n_states, self.n_aux
        self.T = T
        k = max(t.k for t in templates)
        self.k = k
        hard = np.concatenate([t.hard for t in templates], axis=1)              # (A, T*S)
        self.prior = np.array([t.prior for t in templates])                     # (T, S)
        # masks[w][a, tid * S + s]: bit c set when clause 62 w + c of template tid is violated;
        # the first word also has bit 62 set where the hard clauses forbid (a, s)
        self.masks, self.chunks = [], []
        for w0 in range(0, max(k, 1), WORD_BITS):
            n = min(WORD_BITS, k - w0)
            bits = np.int64(1) << np.arange(max(n, 0), dtype=np.int64)
            parts = []
            for t in templates:
                v = t.viol[w0:w0 + n]
                parts.append(np.bitwise_or.reduce(
                    np.where(v, bits[:len(v), None, None], np.int64(0)), axis=0)
                    if len(v) else np.zeros((A, S), dtype=np.int64))
            self.masks.append(np.concatenate(parts, axis=1))
            chunks = []
            for c0 in range(0, n, CHUNK_BITS):
                width = min(CHUNK_BITS, n - c0)
                tables = [t.alias(w0 + c0, width) for t in templates]
                chunks.append((c0, 1 << width, np.concatenate([c for c, _ in tables]),
                               np.concatenate([a for _, a in tables])))
            self.chunks.append(chunks)
        self.masks[0] = np.where(hard, self.masks[0], self.masks[0] | _HARD_BIT)
        if len(self.chunks) == 1:      # one word: all chunks' tables end to end (_kept_word)
            ch = self.chunks[0]
            sizes = [len(c[2]) for c in ch]
            self.flat_chunks = (np.cumsum([0] + sizes[:-1]).astype(np.int64),
                                np.array([c[1] for c in ch], dtype=np.int64),
                                np.array([c[0] for c in ch], dtype=np.int64),
                                np.concatenate([c[2] for c in ch]) if ch else np.zeros(0),
                                np.concatenate([c[3] for c in ch]).astype(np.int64)
                                if ch else np.zeros(0, dtype=np.int64))
        self.hard = hard
        self.lut = None
        if len(self.masks) == 1 and k <= LUT_BITS and (T * S) << k <= LUT_ENTRIES:
            words = np.arange(1 << k, dtype=np.int64) | _HARD_BIT
            table = np.zeros((S, T << k), dtype=np.uint8 if A < 256 else np.float32)
            for tid in range(T):
                m = self.masks[0][:, tid * S:(tid + 1) * S]
                for a in range(A):
                    table[:, tid << k:(tid + 1) << k] += (m[a][:, None] & words[None, :]) == 0
            self.lut = table

    def offsets(self, tids):
        """Per-instance offsets ``(states, alias, count table)`` for template ids ``tids``."""
        if self.T == 1:
            return None
        t = np.asarray(tids, dtype=np.int64)[:, None]
        return t * self.n_states, t, t << self.k

    def draw_words(self, rng, shape, off):
        """Independent keep coins of every clause, packed in words: list of int64 ``shape``."""
        tid = np.zeros(shape[0], dtype=np.int64) if off is None else off[1][:, 0]
        out = []
        for chunks in self.chunks:
            word = np.zeros(shape, dtype=np.int64)
            for c0, n, cut, alias in chunks:
                _alias_draw(rng.random(shape), n, cut, alias, tid, c0, word)
            out.append(word)
        return out

    def kept(self, rng, cell, aux, off, buf=None):
        """Kept-clause words ``(I, B)``: the coin came up and the clause holds at ``(aux,
        cell)`` (``cell``: scope state plus the template's offset ``off[0]``). ``buf`` (a dict)
        keeps the arrays for the next call (the returned words are overwritten then)."""
        if len(self.masks) == 1:
            base, n, c0, cut, alias = self.flat_chunks
            tid = np.zeros(cell.shape[0], dtype=np.int64) if off is None else off[1][:, 0]
            word = _buffer(buf, "word", cell.shape, np.int64)
            u = rng.random(out=_buffer(buf, "u_keep", (len(n),) + cell.shape, np.float64))
            _kept_word(u, base, n, c0, cut, alias, tid, self.masks[0], aux, cell, word)
            return [word]
        words = self.draw_words(rng, cell.shape, off)
        for w, m in zip(words, self.masks):
            _drop_violated(w, m, aux, cell)
        return words

    def draw_private(self, rng, kept, cell, off, est=None, buf=None):
        """Private states ``(I, B)`` drawn uniformly among those the kept clauses allow at the
        drawn scope states (``cell`` as in :meth:`kept`); with ``est``, add the probability of
        the reported atom to it. ``buf`` as in :meth:`kept`."""
        if self.n_aux == 1:
            if est is not None:
                est += float(self.aux_on[0])
            return _buffer(buf, "aux0", cell.shape, np.int64, zero=True)
        u = rng.random(out=_buffer(buf, "u_aux", cell.shape, np.float64))
        on = np.zeros(self.n_aux, dtype=bool) if self.aux_on is None else self.aux_on
        if len(self.masks) == 1:
            aux = _buffer(buf, "aux", cell.shape, np.int64)
            _draw_private(self.masks[0], _HARD_BIT, cell, kept[0], u, on, aux,
                          np.zeros((1, 1)) if est is None else est, est is not None)
            return aux
        ok = self.allowed_at(kept, cell, None).view(np.uint8)
        if est is not None:
            est += ok[on].sum(axis=0) / ok.sum(axis=0)
        return pick(ok, u)

    def counts(self, kept, n_inst, B, off):
        """Allowed private assignments per scope state, ``(I, S, B)`` float32."""
        S = self.n_states
        tid = np.zeros(n_inst, dtype=np.int64) if off is None else off[1][:, 0]
        if kept is None:
            ok = ((self.masks[0] & _HARD_BIT) == 0).sum(axis=0, dtype=np.float32)  # (T*S,)
            rows = ok.reshape(self.T, S)[tid]
            return np.ascontiguousarray(np.broadcast_to(rows[:, :, None], (n_inst, S, B)))
        if self.lut is not None:
            out = np.empty((n_inst, S, B), dtype=np.float32)
            _lut_gather(self.lut, kept[0], tid << self.k, out)
            return out
        ok = None
        for w, (mask, word) in enumerate(zip(self.masks, kept)):
            word = word | _HARD_BIT if w == 0 else word
            m = mask.reshape(self.n_aux, self.T, S)[:, tid]                     # (A, I, S)
            t = (m[:, :, :, None] & word[None, :, None, :]) == 0                 # (A, I, S, B)
            ok = t if ok is None else ok & t
        return ok.sum(axis=0, dtype=np.float32)

    def counts_into(self, kept, n_inst, B, off, tree, b):
        """:meth:`counts` written into the rows of block ``b`` of ``tree`` (a BatchTree)."""
        if self.lut is not None:
            tid = np.zeros(n_inst, dtype=np.int64) if off is None else off[1][:, 0]
            _lut_rows(self.lut, kept[0], tid << self.k, tree.table_rows[b], tree.G)
        else:
            tree.load(b, self.counts(kept, n_inst, B, off))

    def allowed_at(self, kept, s, off):
        """Allowed private states ``(A, I, B)`` at the drawn scope states ``s`` ``(I, B)``."""
        cell = s if off is None else s + off[0]
        ok = None
        for w, (mask, word) in enumerate(zip(self.masks, kept)):
            word = word | _HARD_BIT if w == 0 else word
            t = (mask[:, cell] & word) == 0
            ok = t if ok is None else ok & t
        return ok

    def start_counts(self, n_inst, B, off):
        """Weights of the scope states by each template's clauses alone, ``(I, S, B)``."""
        tid = np.zeros(n_inst, dtype=np.int64) if off is None else off[1][:, 0]
        return np.ascontiguousarray(np.broadcast_to(
            self.prior[tid].astype(np.float32)[:, :, None], (n_inst, self.n_states, B)))


@dataclass(frozen=True)
class ClauseBlock:
    """Instances of the templates of one :class:`ClauseStack`.

    Attributes
    ----------
    stack : ClauseStack
    scopes : ndarray of int, shape (I, r)
        Junction-tree variables of each instance, in the templates' axis order.
    tids : ndarray of int, shape (I,)
        Template of each instance (an index into ``stack.templates``).
    """

    stack: ClauseStack
    scopes: np.ndarray
    tids: np.ndarray


def stack_blocks(instances, cache=None):
    """Blocks from ``[(template, scope), ...]``: one per group of stackable templates.

    Returns the blocks and, per block, the positions in ``instances`` of its instances.
    ``cache`` (a dict) keeps compiled stacks by their templates, for reuse across calls.
    """
    groups: dict = {}
    for pos, (tpl, _scope) in enumerate(instances):
        key = tpl.stack_key()
        if not key[-1]:
            key = key + (id(tpl),)      # more than one word of clauses: a stack of its own
        groups.setdefault(key, []).append(pos)
    blocks = []
    for members in groups.values():
        templates = sorted({id(instances[m][0]): instances[m][0] for m in members}.values(),
                           key=id)
        tid = {id(t): i for i, t in enumerate(templates)}
        key = tuple(tid)
        stack = None if cache is None else cache.get(key)
        if stack is None:
            stack = ClauseStack(templates)
            if cache is not None:
                cache[key] = stack
        blocks.append(ClauseBlock(
            stack, np.array([instances[m][1] for m in members], dtype=np.int64),
            np.array([tid[id(instances[m][0])] for m in members], dtype=np.int64)))
    return blocks, list(groups.values())


def blocks_from_network(net) -> list[ClauseBlock]:
    """Clause blocks of a ground network: one instance per factor scope, grouped by template.

    Every variable of ``net`` is a junction-tree variable (no private atoms).
    """
    by_scope: dict = {}
    for scope, viol in net.hard:
        entry = by_scope.setdefault(scope, [np.zeros(viol.shape, dtype=bool), []])
        entry[0] |= viol
    for scope, t, w in net.soft:
        entry = by_scope.setdefault(scope, [np.zeros(t.shape, dtype=bool), []])
        entry[1].append((t, int(w)))
    groups: dict = {}
    for scope, (bad, soft) in by_scope.items():
        key = (bad.shape, bad.tobytes(), tuple((t.tobytes(), w) for t, w in soft))
        groups.setdefault(key, (bad, soft, []))[2].append(scope)
    instances = []
    for bad, soft, scopes in groups.values():
        viol = np.array([t.reshape(-1) for t, _ in soft], dtype=bool).reshape(len(soft), bad.size)
        tpl = ClauseTemplate(bad.shape, 1, ~bad.reshape(-1), viol, [w for _, w in soft])
        instances.extend((tpl, scope) for scope in scopes)
    return stack_blocks(instances)[0]


def _strides(shape):
    out, acc = [], 1
    for c in reversed(shape):
        out.append(acc)
        acc *= c
    return np.array(out[::-1], dtype=np.int64)


_TREE_CACHE_SIZE = 64   # compiled trees kept per cache (one per floor structure and chain count)


def _batch_tree(card, blocks, jt, B, cache):
    """The :class:`BatchTree` of these blocks on ``jt``, from ``cache`` when its structure was
    built before (its index arrays reused, its rows fresh)."""
    stacks = [blk.stack for blk in blocks]
    key = None
    if cache is not None:
        key = (B, tuple(card), tuple(jt.axes), tuple(jt.parent),
               tuple((id(blk.stack), blk.scopes.shape, blk.scopes.tobytes()) for blk in blocks))
        hit = cache.get(key)
        if hit is not None and all(a is b for a, b in zip(hit[0], stacks)):
            return hit[1].fresh()
    tree = BatchTree(card, [blk.scopes for blk in blocks], jt, B, [st.n_aux for st in stacks])
    if cache is not None:
        if len(cache) >= _TREE_CACHE_SIZE:
            cache.pop(next(iter(cache)))
        cache[key] = (stacks, tree)
        tree = tree.fresh()
    return tree


def run_mcsat(card, blocks, rng, n_chains, n_iter, burn_in, path=None, jt=None,
              tree_cache=None):
    """MC-SAT over junction-tree variables of cardinalities ``card`` and clause ``blocks``.

    Parameters
    ----------
    card : sequence of int
    blocks : list of ClauseBlock
    rng : numpy.random.Generator
    n_chains, n_iter, burn_in : int
        Chains run together, iterations per chain, iterations discarded per chain.
    path : str, optional
        Named in the error when the hard clauses admit no world.
    jt : JunctionTree, optional
        A tree over the block scopes (built if absent).
    tree_cache : dict, optional
        Keeps the compiled sampling tree of each structure for later runs (the stacks of the
        blocks must outlive it, as :class:`~semmap_pp.knowledge.mcsat_local.LocalClauses`'
        cached stacks do).

    Returns
    -------
    marg : list of ndarray
        Estimated distribution of each junction-tree variable.
    aux : list of ndarray or None
        Per block whose templates have ``aux_on``: estimated probability of the reported private
        atom of each instance.
    """
    card = [int(c) for c in card]
    B, n_iter, burn_in = int(n_chains), int(n_iter), int(burn_in)
    if B < 1 or n_iter <= burn_in or burn_in < 0:
        raise RuleError(path, f"MC-SAT needs n_chains >= 1 and 0 <= burn_in < n_iter "
                        f"(got {B}, {n_iter}, {burn_in})")
    if jt is None:
        jt = JunctionTree(card, [tuple(int(v) for v in s) for blk in blocks for s in blk.scopes],
                          path)
    stacks = [blk.stack for blk in blocks]
    offs = [st.offsets(blk.tids) for st, blk in zip(stacks, blocks)]
    sizes = [len(blk.scopes) for blk in blocks]
    strides = [_strides(st.shape) for st in stacks]
    tree = _batch_tree(card, blocks, jt, B, tree_cache)

    tids = [np.zeros(n, dtype=np.int64) if o is None else np.ascontiguousarray(o[1][:, 0])
            for n, o in zip(sizes, offs)]

    bufs = [{} for _ in stacks]     # per block: arrays reused by every iteration
    cells = [np.empty((n, B), dtype=np.int64) for n in sizes]

    def scope_cells(x):
        for blk, st, t, stack, c in zip(blocks, strides, tids, stacks, cells):
            _cells(x, blk.scopes, st, t, stack.n_states, c)
        return cells

    # start: a world of the hard clauses weighted by the single-variable clauses alone
    start = [st.start_counts(n, B, o) if blk.scopes.shape[1] == 1 else st.counts(None, n, B, o)
             for st, n, blk, o in zip(stacks, sizes, blocks, offs)]
    if not tree.upward(start, check=True):
        raise RuleError(path, _NO_WORLD)
    x = tree.sample(rng)
    states = scope_cells(x)
    aux = [st.draw_private(rng, [np.zeros(s.shape, dtype=np.int64)] * len(st.masks), s, o)
           for st, s, o in zip(stacks, states, offs)]
    marg = np.zeros((int(tree.marg_offsets[-1]), B))
    aux_sum = [None if st.aux_on is None else np.zeros((n, B)) for st, n in zip(stacks, sizes)]
    items = list(zip(range(len(stacks)), stacks, sizes, offs, aux_sum))
    for it in range(n_iter):
        keep = it >= burn_in
        kept = [st.kept(rng, s, a, o, bf)
                for st, s, a, o, bf in zip(stacks, states, aux, offs, bufs)]
        for b, st, n, o, _ in items:
            st.counts_into(kept[b], n, B, o, tree, b)
        tree.upward()
        x = tree.sample(rng, marg if keep else None)
        states = scope_cells(x)
        aux = [st.draw_private(rng, kept[b], states[b], o, est if keep else None, bufs[b])
               for b, st, n, o, est in items]
    total = (n_iter - burn_in) * B
    est = marg.sum(axis=1) / total
    return ([est[tree.marg_offsets[v]:tree.marg_offsets[v + 1]] for v in range(len(card))],
            [None if a is None else a.sum(axis=1) / total for a in aux_sum])


@dataclass(frozen=True)
class MCSATSettings:
    """Chains, iterations and burn-in of MC-SAT (:func:`mcsat_marginals`)."""

    n_chains: int = 768
    n_iter: int = 38
    burn_in: int = 12

    def astuple(self) -> tuple[int, int, int]:
        return (int(self.n_chains), int(self.n_iter), int(self.burn_in))


def mcsat_seed(digest: str, evidence_key, settings: tuple[int, int, int], seed: int) -> int:
    """The MC-SAT seed of one evidence: a hash of (rules, evidence, settings, seed), so MC-SAT
    results are a deterministic function of them."""
    text = repr((digest, evidence_key, settings, seed))
    return int.from_bytes(hashlib.blake2b(text.encode(), digest_size=8).digest(), "little")


def mcsat_marginals(net, rng, n_chains=768, n_iter=38, burn_in=12, jt=None):
    """Marginals of every variable of a ground network by MC-SAT.

    Parameters
    ----------
    net : Network
    rng : numpy.random.Generator
    n_chains, n_iter, burn_in : int
        Chains run together, iterations per chain, iterations discarded per chain.
    jt : JunctionTree, optional
        A tree over the factor scopes of ``net`` (built if absent).

    Returns
    -------
    list of ndarray
        ``marg[v]`` is the estimated distribution of variable ``v``.
    """
    marg, _ = run_mcsat(net.card, blocks_from_network(net), rng, n_chains, n_iter, burn_in,
                        net.path, jt)
    return marg
