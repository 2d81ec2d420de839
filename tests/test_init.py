import numpy as np

from semmap_pp import world as wm
from semmap_pp.cells import FREE, OCCUPIED, UNKNOWN
from semmap_pp.init import dispersed_world, greedy_rectangles, largest_rectangle, start_world


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
    rng = np.random.default_rng(0)
    for _ in range(30):
        mask = rng.random((7, 9)) < 0.75
        area = largest_rectangle(mask)[0]
        best = 0
        for r0 in range(7):
            for r1 in range(r0 + 1, 8):
                for c0 in range(9):
                    for c1 in range(c0 + 1, 10):
                        if mask[r0:r1, c0:c1].all():
                            best = max(best, (r1 - r0) * (c1 - c0))
        assert area == best


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
