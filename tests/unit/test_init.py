import numpy as np

from semmap_pp import world as wm
from semmap_pp.cells import FREE, OCCUPIED, UNKNOWN
from semmap_pp.sampler.start_worlds import dispersed_world, greedy_rectangles, largest_rectangle, start_world


def corridor_with_rooms():
    """A 2-cell-walled corridor (rows 20..27) with two rooms above it and one below, doors in the walls."""
    m = np.full((60, 90), UNKNOWN, np.uint8)
    m[2:48, 2:88] = OCCUPIED
    m[4:18, 4:40] = FREE       # room A
    m[4:18, 42:86] = FREE      # room B
    m[20:28, 4:86] = FREE      # corridor
    m[30:46, 4:86] = FREE      # room C
    m[18:20, 10:16] = FREE     # doors
    m[18:20, 60:66] = FREE
    m[28:30, 30:36] = FREE
    m[10, 20] = OCCUPIED       # furniture speckle inside room A
    return m


def test_largest_rectangle_brute_force():
    """Against every rectangle of small random masks (several shapes, densities, empty ones): the
    largest area, an all-True rectangle of that area, and of equal areas the one with the topmost
    bottom edge, then the leftmost right edge, then the tallest."""
    rng = np.random.default_rng(0)
    for k in range(300):
        h, w = int(rng.integers(0, 8)), int(rng.integers(0, 10))
        mask = rng.random((h, w)) < rng.choice([0.3, 0.75, 0.95, 1.0])
        area, r0, c0, r1, c1 = largest_rectangle(mask)
        best = [(0, 0, 0, 0, 0)]
        for a0 in range(h):
            for a1 in range(a0 + 1, h + 1):
                for b0 in range(w):
                    for b1 in range(b0 + 1, w + 1):
                        if mask[a0:a1, b0:b1].all():
                            best.append(((a1 - a0) * (b1 - b0), a0, b0, a1, b1))
        top = max(b[0] for b in best)
        assert area == top
        if top:
            assert mask[r0:r1, c0:c1].all() and (r1 - r0) * (c1 - c0) == area
            first = min((b for b in best if b[0] == top), key=lambda b: (b[3], b[4], b[1]))
            assert (area, r0, c0, r1, c1) == first


def test_rooms_and_corridor_are_found_with_walls_on_the_wall_lines():
    rects = greedy_rectangles(corridor_with_rooms(), min_side=6, wall_cells=2, factor=2, max_units=10)
    assert sorted(rects) == [(2, 2, 20, 42), (2, 40, 20, 88), (18, 2, 30, 88), (28, 2, 48, 88)]


def test_empty_and_unknown_maps_give_no_units():
    assert greedy_rectangles(np.full((30, 30), UNKNOWN, np.uint8), min_side=6, wall_cells=2,
                             factor=2, max_units=5) == []
    assert wm.n_units(start_world(np.zeros((0, 0), np.uint8), 4, min_side=6, wall_cells=2, factor=2)) == 0


def test_dispersed_worlds_are_valid_and_differ():
    m = corridor_with_rooms()
    base = start_world(m, 8, min_side=6, wall_cells=2, factor=2)
    rng = np.random.default_rng(5)
    keys = set()
    for _ in range(10):
        w = dispersed_world(rng, base, m.shape, min_side=6)
        assert wm.is_valid(w, m.shape, 6)
        keys.add(wm.canonical_key(w))
    assert len(keys) > 5
