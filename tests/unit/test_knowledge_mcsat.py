"""MC-SAT internals: keep coins, cached sampling trees, the compiled tree passes."""

import numpy as np

from semmap_pp.knowledge import Evidence, KnowledgeEngine, load_rules, mcsat
from semmap_pp.knowledge.exact import JunctionTree
from semmap_pp.knowledge.mcsat import ClauseStack, ClauseTemplate, keep_probability
from semmap_pp.knowledge.mcsat_tree import BatchTree


def test_keep_coins_have_the_clause_probabilities_and_never_keep_a_violated_clause():
    # 13 distinct clauses on one 8-state variable (two alias chunks of one word); state 0
    # violates none, state 7 some
    rng = np.random.default_rng(3)
    sets = set()
    while len(sets) < 13:
        bits = rng.random(7) < 0.4
        if 0 < bits.sum() < 7:
            sets.add((False,) + tuple(bool(b) for b in bits))
    viol = np.array(sorted(sets))
    weights = rng.integers(100, 3000, size=len(viol))
    tpl = ClauseTemplate((8,), 1, np.ones(8, dtype=bool), viol, weights)
    st = ClauseStack([tpl])
    assert len(st.chunks[0]) == 2 and tpl.k == 13
    n = 200_000
    aux = np.zeros((1, n), dtype=np.int64)
    word, = st.kept(rng, np.zeros((1, n), dtype=np.int64), aux, None)
    bits = (word[0][:, None] >> np.arange(tpl.k)) & 1
    freq = bits.mean(axis=0)
    p = tpl.keep_p
    assert np.all(np.abs(freq - p) < 5 * np.sqrt(p * (1 - p) / n) + 1e-9)
    # at state 7 the clauses it violates are never kept, the others as before
    word, = st.kept(rng, np.full((1, n), 7, dtype=np.int64), aux, None)
    bits = (word[0][:, None] >> np.arange(tpl.k)) & 1
    bad = tpl.viol[:, 0, 7]
    assert bad.any() and not bits[:, bad].any()
    assert np.all(np.abs(bits[:, ~bad].mean(axis=0) - p[~bad])
                  < 5 * np.sqrt(p[~bad] * (1 - p[~bad]) / n) + 1e-9)
    np.testing.assert_allclose(keep_probability([1000]), 1 - np.exp(-1))


def test_a_cached_sampling_tree_gives_the_same_run_as_a_fresh_one():
    rules = load_rules("rules/table3.lp")
    engine = KnowledgeEngine(rules, method="mcsat")
    ev = Evidence.build([1, 2, 3, 4], rolike={1, 3}, colike={2}, muldoor={2},
                        adj=[(1, 2), (2, 3), (3, 4), (2, 4)])
    card, blocks, _ = engine.local_clauses.blocks(ev)
    jt = JunctionTree(card, [tuple(int(v) for v in s) for b in blocks for s in b.scopes])
    cache = {}
    runs = [mcsat.run_mcsat(card, blocks, np.random.default_rng(7), 64, 12, 4, None, jt, c)
            for c in (None, cache, cache)]
    assert len(cache) == 1
    for marg, aux in runs[1:]:
        for a, b in zip(marg, runs[0][0]):
            np.testing.assert_array_equal(a, b)
        for a, b in zip(aux, runs[0][1]):
            assert (a is None and b is None) or np.array_equal(a, b)


def test_tree_passes_count_and_draw_through_grouped_tables_and_messages():
    # a chain 0 - 1 - 2 with a unit table on 1 (grouped into a pair table) and a table over
    # (0, 1) and (1, 2): the draws are uniform over the weighted solutions
    rng = np.random.default_rng(2)
    t01 = rng.integers(0, 3, size=(3, 3)).astype(np.float32)
    t12 = rng.integers(0, 3, size=(3, 3)).astype(np.float32)
    t1 = np.array([1, 2, 1], dtype=np.float32)
    t01[0, 0] = t12[0, 0] = 1.0
    scopes = [np.array([[0, 1], [1, 2]]), np.array([[1]])]
    jt = JunctionTree([3, 3, 3], [(0, 1), (1, 2), (1,)])
    B = 40000
    tree = BatchTree([3, 3, 3], scopes, jt, B, [2.0, 2.0])
    pair = np.stack([t01.reshape(-1), t12.reshape(-1)])[:, :, None]
    assert tree.upward([np.broadcast_to(pair, (2, 9, B)),
                        np.broadcast_to(t1.reshape(1, 3, 1), (1, 3, B))], check=True)
    marg = [np.zeros((3, B)) for _ in range(3)]
    x = tree.sample(rng, marg)
    w = t01[:, :, None] * t12[None, :, :] * t1[None, :, None]
    w = w / w.sum()
    freq = np.bincount(x[0] * 9 + x[1] * 3 + x[2], minlength=27) / B
    np.testing.assert_allclose(freq, w.reshape(-1), atol=0.012)
    for v, axes in enumerate([(1, 2), (0, 2), (0, 1)]):
        np.testing.assert_allclose(marg[v].mean(axis=1), w.sum(axis=axes), atol=0.01)
