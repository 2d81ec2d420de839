"""Exact detailed balance of the whole kernel mix on tiny lattices whose states can all be listed.

Every slot state of a tiny lattice is enumerated, the full transition matrix of the mix (proposal
probabilities from each kernel's ``enumerate``, acceptance from the log ratio the kernel *reports*)
is built, and ``pi_i P_ij = pi_j P_ji`` is checked for every pair, with ``pi`` a random target.
A wrong reverse density, a missing reverse move or a slot count left out of a ratio breaks it.
"""

import importlib
import itertools
import math

import numpy as np
import pytest
from scipy import sparse
from scipy.sparse import csgraph

from semmap_pp import cells
from semmap_pp import world as wm
from semmap_pp.sampler.kernels import KERNELS, KernelSettings, build_data, default_mix
from semmap_pp.sampler.kernels.common import world_key
from standin import TableTarget

SETTINGS = KernelSettings(local_radius=1, birth_jitter=1, box_jitter=1, wall_line_min=2)


def tiny_classes(shape):
    """Free lattice with one wall line (occupied row with a door gap) so line evidence varies."""
    c = np.full(shape, cells.FREE, np.uint8)
    if shape[0] >= 4:
        c[shape[0] // 2, :] = cells.OCCUPIED
        c[shape[0] // 2, 1] = cells.FREE
    else:
        c[:, shape[1] // 2] = cells.OCCUPIED
    c[0, -1] = cells.UNKNOWN
    return c


def all_states(data, capacity):
    h, w = data.shape
    rects = [(r0, c0, r1, c1) for r0, r1, c0, c1 in itertools.product(range(h + 1), range(h + 1),
                                                                       range(w + 1), range(w + 1))
             if data.min_side <= r1 - r0 <= data.max_side and data.min_side <= c1 - c0 <= data.max_side]
    states = []
    for choice in itertools.product([None] + rects, repeat=capacity):
        active = [r is not None for r in choice]
        states.append(wm.make([r or (0, 0, 0, 0) for r in choice], active, [-1] * capacity))
    return states


def transition_matrix(states, data, mix, logpi):
    index = {world_key(s): i for i, s in enumerate(states)}
    rows, cols, vals = [], [], []
    q_kernel = {}   # (kernel, i, j) -> (forward probability, reported log ratio)
    for i, s in enumerate(states):
        for kernel, weight in zip(mix.kernels, mix.probabilities):
            total = 0.0
            for prop, q in kernel.enumerate(s, data):
                assert wm.is_valid(prop.world, data.shape, data.min_side)
                j = index[world_key(prop.world)]
                assert j != i
                changed = np.flatnonzero(np.any(prop.world.rects != s.rects, axis=1)
                                         | (prop.world.active != s.active))
                assert set(changed.tolist()) == set(prop.changed_slots)
                key = (kernel.kind, i, j)
                old = q_kernel.get(key)
                if old is not None:
                    assert old[1] == pytest.approx(prop.log_ratio, abs=1e-12)
                q_kernel[key] = ((old[0] if old else 0.0) + q, prop.log_ratio)
                total += q
                acc = min(1.0, math.exp(min(0.0, logpi[j] - logpi[i] + prop.log_ratio)))
                rows.append(i), cols.append(j), vals.append(weight * q * acc)
            assert total <= 1.0 + 1e-12
    n = len(states)
    p = sparse.coo_matrix((vals, (rows, cols)), shape=(n, n)).tocsr()
    p = p + sparse.diags(1.0 - np.asarray(p.sum(axis=1)).ravel())
    return p, q_kernel


@pytest.mark.parametrize("shape,capacity,g,big", [((4, 5), 2, 0, None), ((4, 4), 2, 1, None),
                                                  ((3, 4), 3, 0, 3)])
@pytest.mark.slow
def test_detailed_balance_of_the_mix(shape, capacity, g, big):
    data = build_data(tiny_classes(shape), min_side=2, wall_cells=1, wall_share=g, max_side=big,
                      door_min=1, door_max=1, settings=SETTINGS)
    assert len(data.birth_rects) > 0
    mix = default_mix(SETTINGS)
    states = all_states(data, capacity)
    target = TableTarget(np.random.default_rng(7), capacity)
    logpi = np.array([target.evaluate(s) for s in states])
    pi = np.exp(logpi - logpi.max())
    pi /= pi.sum()
    p, q_kernel = transition_matrix(states, data, mix, logpi)

    # each reported log ratio is log q(reverse) - log q(forward) of the same kernel, and the reverse exists
    for (kind, i, j), (q, lr) in q_kernel.items():
        back = q_kernel.get((kind, j, i))
        assert back is not None, (kind, states[i], states[j])
        assert lr == pytest.approx(math.log(back[0]) - math.log(q), abs=1e-9), (kind, states[i], states[j])

    flow = sparse.diags(pi) @ p
    diff = abs(flow - flow.T)
    scale = abs(flow) + abs(flow.T)
    bad = diff > 1e-12 * scale.max()
    assert bad.nnz == 0
    coo = diff.tocoo()
    rel = coo.data / np.maximum(scale.tocsr()[coo.row, coo.col].A1, 1e-300)
    assert rel.max(initial=0.0) < 1e-12
    assert np.max(np.abs(pi @ p - pi)) < 1e-12 * pi.max()
    n_comp, _ = csgraph.connected_components(p, directed=True, connection="strong")
    assert n_comp == 1  # irreducible: every state reaches every other


def test_balance_detects_a_wrong_ratio(monkeypatch):
    """The check above can fail: a merge that forgets the number of mergeable pairs breaks balance."""
    sm = importlib.import_module("semmap_pp.sampler.kernels.split_merge")  # the module, not the kernel

    data = build_data(tiny_classes((4, 4)), min_side=2, wall_cells=1, settings=SETTINGS)
    states = all_states(data, 2)
    target = TableTarget(np.random.default_rng(3), 2)
    logpi = np.array([target.evaluate(s) for s in states])
    monkeypatch.setattr(sm, "mergeable", lambda w, d, f=sm.mergeable: f(w, d) * 2 if f(w, d) else [])
    mix = type(default_mix(SETTINGS))([(KERNELS["split_merge"], 1.0)])
    p, q_kernel = transition_matrix(states, data, mix, logpi)
    wrong = [abs(lr - (math.log(q_kernel[(k, j, i)][0]) - math.log(q)))
             for (k, i, j), (q, lr) in q_kernel.items() if (k, j, i) in q_kernel]
    assert max(wrong) > 1e-3


@pytest.mark.slow
@pytest.mark.parametrize("shape", [(3, 5), (5, 3)])
def test_interchange_balance_where_it_makes_or_breaks_adjacency(shape):
    """Mutant class "the interchange reverse" (docs/robustness.md, "Mutants"): three units on a
    3 x 5 lattice (and its transpose), sides 2..4, wall bands shared (g = 1), every slot state
    enumerated. A unit wide enough to lie under both units of a pair (or none) is attached to
    one of them fewer or more after their shared wall moves, so INTERCHANGE changes the number
    of adjacent pairs N_adj in thousands of its moves; each reported log ratio is still
    log q(reverse) - log q(forward) of the enumerated densities (``log N_adj(W) - log N_adj(W')``
    included), and the kernel alone keeps a random target in detailed balance."""
    from semmap_pp.sampler.kernels.interchange import n_adjacent

    data = build_data(tiny_classes(shape), min_side=2, wall_cells=1, wall_share=1, max_side=4,
                      door_min=1, door_max=1, settings=SETTINGS)
    mix = type(default_mix(SETTINGS))([(KERNELS["interchange"], 1.0)])
    states = all_states(data, 3)
    target = TableTarget(np.random.default_rng(11), 3)
    logpi = np.array([target.evaluate(s) for s in states])
    pi = np.exp(logpi - logpi.max())
    pi /= pi.sum()
    p, q_kernel = transition_matrix(states, data, mix, logpi)
    n_adj = {}

    def adjacent(i):
        if i not in n_adj:
            n_adj[i] = n_adjacent(states[i], data)
        return n_adj[i]

    changes = 0
    for (kind, i, j), (q, lr) in q_kernel.items():
        back = q_kernel.get((kind, j, i))
        assert back is not None, (states[i], states[j])
        assert lr == pytest.approx(math.log(back[0]) - math.log(q), abs=1e-9), (states[i], states[j])
        changes += adjacent(i) != adjacent(j)
    assert changes > 1000          # 7,176 of the 11,760 moves on the 3 x 5 lattice
    flow = sparse.diags(pi) @ p
    diff = abs(flow - flow.T)
    assert diff.max() <= 1e-12 * abs(flow).max()
    assert np.max(np.abs(pi @ p - pi)) < 1e-12 * pi.max()
