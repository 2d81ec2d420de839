"""Tests of semmap_pp.evidence: Table 4 classes, soft evidence, facts, providers."""

import numpy as np
import pytest

from semmap_pp.evidence import (COLIKE, HALIKE, ROLIKE, FixedProvider, build_evidence,
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
    from semmap_pp.evidence import geometry_class_one
    rng = np.random.default_rng(1)
    rects = np.stack([np.zeros(500, int), np.zeros(500, int),
                      rng.integers(20, 400, 500), rng.integers(20, 400, 500)], 1)
    for measure in ("short_side", "long_side", "area"):
        p = P.__class__(**{**P.__dict__, "size_measure": measure})
        vec = geometry_class(rects, RES, p)
        assert [geometry_class_one(r, RES, p) for r in rects] == vec.tolist()


def test_soft_evidence_takes_few_values():
    """Soft probabilities are quantised: many unit sizes near a boundary give few distinct values."""
    from semmap_pp.evidence import unit_geometry
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
    from semmap_pp.evidence import GEOMETRY_BLOCK, GeometryTable, unit_geometry
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

    from semmap_pp.evidence import muldoor_counts

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
    from semmap_pp.evidence import space_colike

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
