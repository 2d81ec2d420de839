"""The kernels propose exactly what they proposed before their speed-ups.

``tests/data/kernels_frozen.npz`` holds, for the cartesium lattice (its class map stored in the file)
and worlds reached by a random walk of the kernels on it, the outcome of a few thousand seeded
proposals per kernel made by the code of commit 6e5ed88: a hash of the proposed world, the log
proposal ratio, the changed slots and the next number of the generator (so the kernel consumed the
random stream the same way). Any change to what a kernel proposes, its log ratio, or how many
random numbers it draws fails here. ``python tests/unit/test_kernels_frozen.py`` rewrites the fixture
(only when a change of the proposal distribution is intended).
"""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np
import pytest

from semmap_pp import world as wm
from semmap_pp.sampler.kernels import KERNELS, Mix, build_data

FIXTURE = Path(__file__).parents[1] / "data" / "kernels_frozen.npz"
N_PER_KERNEL = 2000
NO_PROPOSAL = -1.0e300          # log ratio stored for a ``None`` proposal


def _data(classes, params):
    min_side, max_side, wall, share, door_min, door_max = (int(v) for v in params)
    return build_data(classes, min_side=min_side, max_side=max_side, wall_cells=wall, wall_share=share,
                      door_min=door_min, door_max=door_max)


def _world_hash(world) -> int:
    h = hashlib.blake2b(digest_size=8)
    for a in (world.rects, world.active, world.types):
        h.update(np.ascontiguousarray(a).tobytes())
    return int.from_bytes(h.digest(), "little", signed=True)


def _record(kernel, worlds, data):
    """(hash, log ratio, changed slots (padded -1), next random) of seeded proposals of ``kernel``."""
    n = N_PER_KERNEL
    hashes, ratios = np.zeros(n, np.int64), np.zeros(n)
    changed, nxt = np.full((n, 2), -1, np.int64), np.zeros(n)
    for i in range(n):
        rng = np.random.default_rng([7, i])
        world = worlds[i % len(worlds)]
        p = kernel(rng, world, data)
        if p is None:
            ratios[i] = NO_PROPOSAL
        else:
            hashes[i], ratios[i] = _world_hash(p.world), p.log_ratio
            changed[i, :len(p.changed_slots)] = p.changed_slots
            assert p.world.rects.dtype == np.int32 and p.world.active.dtype == bool
        nxt[i] = rng.random()
    return hashes, ratios, changed, nxt


def _walk_worlds(data, capacity, steps=3000, every=60):
    """Worlds visited by a walk of all kernels, every proposal accepted (deterministic, seeded)."""
    rng = np.random.default_rng(2026)
    mix = Mix([(KERNELS[k], w) for k, w in [("add_remove", 1), ("split_merge", 2), ("allocate_delete", 3),
                                            ("shrink_dilate", 2), ("interchange", 2)]])
    w, out = wm.empty(capacity), []
    for step in range(1, steps + 1):
        _, p = mix(rng, w, data)
        if p is not None:
            w = p.world
        if step % every == 0:
            out.append(w)
    return out


def write_fixture() -> None:
    from semmap_pp.lattice.frame import build_frame
    from semmap_pp.grid import load_map
    from semmap_pp.model import load_model

    model = load_model()
    root = Path(__file__).resolve().parents[2]
    frame = build_frame(load_map(root / "data/maps/ubremen-cartesium.yaml"), model)
    c = frame.cells
    params = np.array([c.min_side, c.max_side, c.wall, c.wall, c.door_min, c.door_max], np.int64)
    classes = np.ascontiguousarray(frame.classes, np.uint8)
    data = _data(classes, params)
    worlds = _walk_worlds(data, model.prior.k_max)
    out = {"classes": classes, "params": params,
           "rects": np.stack([w.rects for w in worlds]), "active": np.stack([w.active for w in worlds]), "types": np.stack([w.types for w in worlds])}
    for kind, kernel in KERNELS.items():
        for name, a in zip(("hash", "ratio", "changed", "next"), _record(kernel, worlds, data)):
            out[f"{kind}_{name}"] = a
    np.savez_compressed(FIXTURE, **out)


@pytest.fixture(scope="module")
def frozen():
    f = np.load(FIXTURE)
    data = _data(f["classes"], f["params"])
    worlds = [wm.make(r, a, t) for r, a, t in zip(f["rects"], f["active"], f["types"])]
    return f, data, worlds


def test_fixture_worlds_hold_units(frozen):
    f, _, worlds = frozen
    sizes = [wm.n_units(w) for w in worlds]
    assert max(sizes) >= 20 and np.mean(sizes) >= 10 and min(sizes) == 0   # the empty world too


@pytest.mark.parametrize("kind", list(KERNELS))
def test_kernel_proposes_as_frozen(frozen, kind):
    f, data, worlds = frozen
    hashes, ratios, changed, nxt = _record(KERNELS[kind], worlds, data)
    none = f[f"{kind}_ratio"] == NO_PROPOSAL
    assert 0.05 < np.mean(~none)             # the fixture exercises real proposals
    np.testing.assert_array_equal(ratios == NO_PROPOSAL, none)
    np.testing.assert_array_equal(nxt, f[f"{kind}_next"])
    np.testing.assert_array_equal(changed, f[f"{kind}_changed"])
    np.testing.assert_array_equal(hashes, f[f"{kind}_hash"])
    np.testing.assert_array_equal(ratios, f[f"{kind}_ratio"])   # bit for bit, infinities included


if __name__ == "__main__":
    write_fixture()


def test_compiled_pairs_match_the_python_reference(frozen):
    from semmap_pp.sampler.kernels.common import attach_pairs, attach_pairs_py

    _, data, worlds = frozen
    rng = np.random.default_rng(3)
    small = []
    for _ in range(200):     # dense random worlds on a small lattice: many shared walls, g in 0..2
        r0, c0 = rng.integers(0, 6, (2, 12))
        rects = np.stack([r0, c0, r0 + rng.integers(2, 5, 12), c0 + rng.integers(2, 5, 12)], 1)
        small.append((wm.make(rects, rng.random(12) < 0.8, np.zeros(12)), int(rng.integers(0, 3))))
    for w, g in [(w, data.wall_share) for w in worlds] + small:
        m = data.min_side if g == data.wall_share else 2
        assert attach_pairs(w.rects, w.active, m, g) == attach_pairs_py(w.rects, w.active, m, g)


def test_compiled_allocate_q_matches_the_numpy_reference(frozen):
    import importlib

    ad = importlib.import_module("semmap_pp.sampler.kernels.allocate_delete")

    _, data, worlds = frozen
    rng = np.random.default_rng(4)
    checked = nonzero = 0
    for w in worlds[::5]:
        for a in np.flatnonzero(w.active).tolist():
            a_rect = w.rects[a]
            for side in range(4):
                rg = ad.ranges(a_rect, side, data)
                if rg is None:
                    continue
                axis, near, far, s0, s1 = rg
                span0, span1 = int(a_rect[1 - axis]), int(a_rect[3 - axis])
                for _ in range(3):
                    seed = np.array([int(rng.integers(span0, span1))])
                    b0, b1, bf = (int(v[0]) + int(rng.integers(-2, 3)) for v in ad.boxes(a_rect, side, near, data, seed))
                    b = [0, 0, 0, 0]
                    b[1 - axis], b[3 - axis] = b0, b1
                    b[axis], b[axis + 2] = (near, bf) if side % 2 == 0 else (bf, near)
                    q = ad.allocate_q(b, a_rect, side, data)
                    assert q == ad.allocate_q_py(b, a_rect, side, data)
                    checked += 1
                    nonzero += q > 0
    assert checked > 500 and nonzero > 100


def test_compiled_helpers_match_their_references(frozen):
    from semmap_pp.sampler.kernels import common

    _, data, worlds = frozen
    rng = np.random.default_rng(5)
    h, w = data.shape
    for _ in range(300):     # band weights: ranges that run off the lattice at either end
        axis = int(rng.integers(0, 2))
        cum = common.line_cum(data, axis)
        lo = int(rng.integers(-5, cum.shape[0] + 5))
        hi = lo + int(rng.integers(0, 40))
        a = -int(rng.integers(0, 4))
        b = a + int(rng.integers(1, 5))
        s0 = int(rng.integers(0, cum.shape[1] - 2))
        s1 = int(rng.integers(s0 + 1, cum.shape[1]))
        got = common.band_weights(cum, lo, hi, a, b, s0, s1, 0.05)
        np.testing.assert_array_equal(got, common.band_weights_py(cum, lo, hi, a, b, s0, s1, 0.05))
    for _ in range(2000):    # jumps: numpy's cumsum and right-sided search, dips at k included
        n = int(rng.integers(2, 30))
        wts = rng.choice([0.05, 0.1, 1 / 3, 0.7, 1e-17, 1e17], n) * rng.random(n)
        k, r = int(rng.integers(0, n)), float(rng.random())
        cdf = np.cumsum(wts)
        cdf[k:] -= wts[k]
        assert common._jump(wts, k, r) == np.searchsorted(cdf, r * cdf[-1], side="right")
    for wd in worlds[::3]:
        for s in np.flatnonzero(wd.active).tolist():
            r = wd.rects[s].copy()
            for rect in (r, r + np.array([0, 0, 2, 0]), r - np.array([2, 2, 0, 0])):
                assert (common.attached_to(rect, wd.rects, wd.active, data.min_side, data.wall_share)
                        == common.attached_to_py(rect, wd.rects, wd.active, data.min_side, data.wall_share))


def test_compiled_pairwise_sum_is_numpys_sum():
    from semmap_pp.sampler.kernels.common import _pair_q, pairwise_sum, position_q

    rng = np.random.default_rng(6)
    for n in list(range(0, 300)) + [511, 512, 513, 1023, 1400, 1601, 2048, 3001, 5000]:
        for a in (rng.random(n), rng.standard_normal(n) * 10.0 ** rng.integers(-12, 12, n),
                  0.05 + rng.integers(0, 4, n) / 7):
            assert pairwise_sum(a, 0, n) == a.sum()
            if n > 4:
                assert pairwise_sum(a, 3, n - 4) == a[3:n - 1].sum()
        if n > 8:
            w = 0.05 + rng.random(n)
            x, x2 = int(rng.integers(0, n)), int(rng.integers(0, n))
            total = float(w.sum())
            assert _pair_q(x + 5, x2 + 5, 5, w, 0.5, 3) == (position_q(x2 + 5, x + 5, 5, w, total, 0.5, 3),
                                                            position_q(x + 5, x2 + 5, 5, w, total, 0.5, 3))
