"""Tests of semmap_pp.target.geometry_evidence: Table 4 classes, soft evidence, facts, providers."""

import numpy as np
import pytest

from semmap_pp.target.geometry_evidence import (COLIKE, HALIKE, ROLIKE, FixedProvider, build_evidence,
                                geometry_class, geometry_probabilities)
from semmap_pp.model import load_model

MODEL = load_model()
P = MODEL.evidence
RES = 0.05


def cells(h_m, w_m):
    return np.array([[0, 0, round(h_m / RES), round(w_m / RES)]])


@pytest.mark.parametrize("h,w,cls", [
    (4, 5, ROLIKE),      # an office
    (2, 20, COLIKE),     # a corridor: long and narrow
    (10, 12, HALIKE),    # a hall: big short side
    (8, 40, HALIKE),     # big size wins over the ratio (Table 4)
    (3, 8.9, ROLIKE),    # ratio 2.97 < 3
    (3, 9.1, COLIKE),
])
def test_table4_classes(h, w, cls):
    assert geometry_class(cells(h, w), RES, P)[0] == cls


def test_probabilities_are_soft_near_a_threshold_and_hard_far_from_it():
    far = geometry_probabilities(cells(4, 5), RES, P)[0]
    near = geometry_probabilities(cells(3, 9.05), RES, P)[0]
    assert far.sum() == pytest.approx(1) and near.sum() == pytest.approx(1)
    assert far[ROLIKE] > 0.95
    assert 0.3 < near[COLIKE] < 0.7 and 0.3 < near[ROLIKE] < 0.7


def test_build_evidence_and_facts():
    rects = np.vstack([cells(4, 5), cells(2, 20), cells(3, 9.05)])
    adj = np.array([[0, 1, 0], [1, 0, 1], [0, 1, 0]], bool)
    md = P.multiple_doors            # MulDoor from this many doors on (one fewer: not)
    ev = build_evidence([7, 3, 5], rects, adj, RES, P, door_counts=np.array([md - 1, md, 0]))
    assert ev.units == (3, 5, 7)
    assert ev.adj == frozenset({(3, 7), (3, 5)})
    assert ev.muldoor == frozenset({3})
    assert [u for u, _ in ev.soft] == [5]
    facts = ev.facts().splitlines()
    assert "rolike(7)." in facts and "colike(3)." in facts and "muldoor(3)." in facts
    assert not any(f.endswith("(5).") and not f.startswith("unit") for f in facts)
    assert "adj(3,7)." in facts and "adj(7,3)." in facts
    assert hash(ev) == hash(build_evidence([7, 3, 5], rects, adj, RES, P, np.array([md - 1, md, 0])))


def test_to_knowledge_carries_hard_and_soft_evidence():
    rects = np.vstack([cells(4, 5), cells(3, 9.05)])
    ev = build_evidence([0, 1], rects, np.array([[0, 1], [1, 0]], bool), RES, P,
                        np.array([P.multiple_doors, 0]))
    k = ev.to_knowledge()
    assert k.rolike[0] == (0, 1.0) and k.muldoor == ((0, 1.0),) and k.adj == ((0, 1),)
    assert dict(k.colike)[1] == pytest.approx(dict(ev.soft)[1][COLIKE], abs=1e-6)


def test_fixed_provider_types_and_sale():
    rects = np.vstack([cells(4, 5), cells(4, 5), cells(2, 20)])
    adj = np.array([[0, 1, 1], [1, 0, 0], [1, 0, 0]], bool)
    ev = build_evidence([0, 1, 2], rects, adj, RES, P)
    r = FixedProvider(MODEL.knowledge.fixed_sale).infer(ev)
    assert r.map_types == {0: "room", 1: "room", 2: "corridor"}
    assert r.sale[(0, 1)] == MODEL.knowledge.fixed_sale[0, 0]
    assert r.sale[(0, 2)] == MODEL.knowledge.fixed_sale[0, 1]
    assert r.types[2].tolist() == [0, 1, 0, 0]


def test_scalar_geometry_class_equals_the_vectorised_one():
    from semmap_pp.target.geometry_evidence import geometry_class_one
    rng = np.random.default_rng(1)
    rects = np.stack([np.zeros(500, int), np.zeros(500, int),
                      rng.integers(20, 400, 500), rng.integers(20, 400, 500)], 1)
    for measure in ("short_side", "long_side", "area"):
        p = P.__class__(**{**P.__dict__, "size_measure": measure})
        vec = geometry_class(rects, RES, p)
        assert [geometry_class_one(r, RES, p) for r in rects] == vec.tolist()


def test_soft_evidence_takes_few_values():
    """Soft probabilities are quantised: many unit sizes near a boundary give few distinct values."""
    from semmap_pp.target.geometry_evidence import unit_geometry
    values = set()
    for h in range(40, 80):
        for w in range(120, 220):
            _, soft = unit_geometry(h, w, RES, P)
            if soft is not None:
                values.add(soft)
                assert abs(sum(soft) - 1) < 1e-5 and min(soft) > 0
    step = P.soft_step
    assert 1 < len(values) <= (round(1 / step) + 1) ** 2


def test_geometry_table_equals_unit_geometry_size_by_size():
    """The sampler's block-vectorised size table gives exactly unit_geometry's items (hard and
    soft, every size measure), including block edges and sizes below the first block."""
    from semmap_pp.target.geometry_evidence import GEOMETRY_BLOCK, GeometryTable, unit_geometry
    rng = np.random.default_rng(3)
    b = GEOMETRY_BLOCK
    for measure in ("short_side", "long_side", "area"):
        p = P.__class__(**{**P.__dict__, "size_measure": measure})
        table = GeometryTable(RES, p)
        sizes = [(int(h), int(w)) for h, w in rng.integers(1, 500, (400, 2))]
        sizes += [(1, 1), (b - 1, b), (b, b - 1), (2 * b, 3 * b - 1), (140, 60), (60, 140)]
        n_soft = 0
        for h, w in sizes:
            item = table.get(h, w)
            assert item == unit_geometry(h, w, RES, p), (measure, h, w)
            n_soft += item[1] is not None
        assert n_soft > 0 and table.blocks < len(sizes)


def test_muldoor_counts_equal_a_reference_over_random_door_and_passage_graphs():
    """Own doors for every unit; for a corridor-like unit in a passage-joined group, the doors
    of the whole group, a door between two members once (reference: networkx components)."""
    import itertools

    import networkx as nx

    from semmap_pp.target.geometry_evidence import muldoor_counts

    rng = np.random.default_rng(5)
    grouped = 0
    for _ in range(300):
        n = int(rng.integers(1, 9))
        d = np.triu(rng.integers(0, 3, (n, n)) * (rng.random((n, n)) < 0.4), 1)
        d = d + d.T
        g = np.triu(rng.random((n, n)) < 0.25, 1)
        g = g | g.T
        colike = rng.random(n) < 0.5
        want = d.sum(axis=1)
        graph = nx.Graph(list(zip(*np.nonzero(g))))
        for comp in nx.connected_components(graph):
            comp = sorted(int(u) for u in comp)
            total = d[comp].sum() - sum(d[u, v] for u, v in itertools.combinations(comp, 2))
            for u in comp:
                if colike[u]:
                    want[u] = total
                    grouped += total != d[u].sum()
        assert muldoor_counts(np.stack([d, g], axis=2), colike).tolist() == want.tolist()
    assert grouped >= 50


def _pieces_reference(passage, short, classes, ratio):
    """space_colike by its definition: grow (member, width) until nothing changes."""
    n = len(classes)
    width = {u: float(short[u]) for u in range(n) if classes[u] == COLIKE}
    while True:
        changed = False
        for u in range(n):
            if classes[u] != ROLIKE:
                continue
            ok = [width[v] for v in width if passage[u][v] and short[u] <= ratio * width[v]]
            if ok and max(ok) > width.get(u, 0.0):
                width[u] = max(ok)
                changed = True
        if not changed:
            return [classes[u] == ROLIKE and u in width for u in range(n)]


def test_corridor_pieces_equal_their_definition_whatever_the_order_of_the_units():
    from semmap_pp.target.geometry_evidence import space_colike

    rng = np.random.default_rng(11)
    found = 0
    for _ in range(300):
        n = int(rng.integers(1, 12))
        passage = np.triu(rng.random((n, n)) < 0.3, 1)
        passage = passage | passage.T
        openings = np.zeros((n, n, 2), np.int32)
        openings[..., 1] = passage
        openings[..., 0] = rng.integers(0, 2, (n, n))
        short = rng.integers(4, 40, n)
        classes = rng.choice([ROLIKE, COLIKE, HALIKE, -1], n, p=[0.5, 0.25, 0.15, 0.1])
        ratio = float(rng.choice([1.0, 1.5, 2.0, 3.0]))
        got = space_colike(openings, short, classes, ratio)
        assert got.tolist() == _pieces_reference(passage, short, classes, ratio)
        perm = rng.permutation(n)
        again = space_colike(openings[np.ix_(perm, perm)], short[perm], classes[perm], ratio)
        assert again.tolist() == got[perm].tolist()
        found += int(got.sum())
    assert found > 50


def test_patched_knowledge_evidence_equals_the_evidence_built_anew():
    """patch_knowledge_evidence: random worlds edited at random (units gone and new, items
    changed between hard and soft, MulDoor flags, pairs dropped and added) give the evidence
    knowledge_evidence builds from the edited world itself; the parts not edited are kept as
    the same objects."""
    from semmap_pp.target.geometry_evidence import knowledge_evidence, patch_knowledge_evidence

    rng = np.random.default_rng(2)

    def item():
        c = int(rng.integers(0, 3))
        if rng.random() < 0.5:
            return c, None
        p = rng.dirichlet([1, 1, 1]).round(2)
        p[rng.random(3) < 0.3] = 0.0
        return c, tuple(float(v) for v in p)

    def build(units, md, pairs):
        us = sorted(units)
        return knowledge_evidence(us, [units[u] for u in us], sorted(u for u in md if u in units),
                                  sorted(pairs))

    edits = 0
    for _ in range(300):
        k = int(rng.integers(1, 12))
        units = {int(u): item() for u in rng.choice(k + 4, k, replace=False)}
        md = {u for u in units if rng.random() < 0.3}
        pairs = {(p, q) for p in units for q in units if p < q and rng.random() < 0.3}
        ev = build(units, md, pairs)
        new_units, new_md, new_pairs = dict(units), set(md), set(pairs)
        items, flags = {}, {}
        for u in rng.choice(k + 6, int(rng.integers(0, 4)), replace=False).tolist():
            items[u] = None if (u in units and rng.random() < 0.4) else item()
            if items[u] is None:
                new_units.pop(u, None)
                new_pairs = {pq for pq in new_pairs if u not in pq}
            else:
                new_units[u] = items[u]
        for u in new_units:
            if rng.random() < 0.2:
                flags[u] = u not in new_md
                (new_md.add if flags[u] else new_md.discard)(u)
        for u in new_md - set(new_units):       # a unit that goes loses its flag (the caller's part)
            flags[u] = False
        new_md &= set(new_units)
        drop = sorted(pq for pq in pairs if pq not in new_pairs or rng.random() < 0.2)
        new_pairs -= set(drop)
        add = sorted({(p, q) for p in new_units for q in new_units if p < q and rng.random() < 0.1})
        new_pairs |= set(add)
        got = patch_knowledge_evidence(ev, items, flags, drop, add)
        assert got == build(new_units, new_md, new_pairs)
        edits += bool(items or flags or drop or add)
        if not items:
            assert got.rolike is ev.rolike and got.units is ev.units
    assert edits > 250
