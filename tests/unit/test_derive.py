"""Tests of semmap_pp.derive on small literal maps whose answer can be seen by eye.

Map legend: '#' occupied, '.' free, '?' unknown.
"""

import dataclasses

import numpy as np

from semmap_pp import world as wm
from semmap_pp.cells import FREE, OCCUPIED, UNKNOWN, W_FREE, W_OBJECT, W_UNKNOWN, W_WALL
from semmap_pp.derive import derive_world
from semmap_pp.derive.adjacency import adjacency_matrix, adjacency_raster
from semmap_pp.derive.doors import doors_between
from semmap_pp.derive.states import cell_states, find_objects
from semmap_pp.derive.unexplored import find_unexplored
from semmap_pp.lattice.frame import build_frame_from_classes
from semmap_pp.target.likelihood import wall_like
from semmap_pp.model import CellParams, load_model

CELLS = CellParams(resolution=0.05, wall=1, object_max_extent=4, door_min=2, door_max=4,
                   min_side=4, max_side=100, adjacency_dilation=1, unexplored_min_area=2)


def grid(text):
    code = {"#": OCCUPIED, ".": FREE, "?": UNKNOWN}
    return np.array([[code[ch] for ch in line] for line in text.split()], np.uint8)


DOORS = grid("""
###############
#......#......#
#.............#
#.............#
#.............#
#......#......#
#......#......#
#.............#
#......#......#
#......#......#
#......#......#
###############
""")


def test_door_is_a_run_of_free_cells_on_the_shared_wall():
    doors = doors_between(DOORS, (0, 0, 12, 8), (0, 7, 12, 15), CELLS, 1, 2)
    # rows 2..4 of column 7 are open (3 cells, within 2..4); row 7 alone is too narrow
    assert [(d.p, d.q, d.box, d.vertical, d.width) for d in doors] == [(1, 2, (2, 7, 5, 8), True, 3)]


def test_a_speck_in_a_doorway_does_not_cut_the_door():
    """Doors are looked for on the map with its specks made free (``doorway_classes``): up to
    ``speck`` touching non-free cells, not part of a wall."""
    from semmap_pp.derive.doors import door_count
    from semmap_pp.lattice.frame import doorway_classes
    import dataclasses

    wide = dataclasses.replace(CELLS, door_min=4, door_max=6)

    def widths(m, speck):
        d = doorway_classes(m, speck)
        found = [x.width for x in doors_between(d, (0, 0, 12, 8), (0, 7, 12, 15), wide)]
        assert door_count(d, (0, 0, 12, 8), (0, 7, 12, 15), wide) == len(found)
        return found

    m = DOORS.copy()
    m[1:11, 7] = OCCUPIED
    m[3:8, 7] = FREE                 # a 5-cell doorway (rows 3..7) ...
    assert widths(m, 1) == [5]
    m[5, 7] = OCCUPIED               # ... with a speck of noise in its middle: still one door
    assert widths(m, 1) == [5]
    assert doors_between(m, (0, 0, 12, 8), (0, 7, 12, 15), wide) == []   # on the raw map: two gaps
    m[5, 6] = UNKNOWN                # a chair leg and the unseen cell behind it: two cells
    assert widths(m, 1) == [] and widths(m, 2) == [5]
    m[5, 5] = OCCUPIED               # three touching cells are clutter at two cells
    assert widths(m, 2) == [] and widths(m, 3) == [5]
    m[5, 5:7] = FREE
    m[4, 7] = UNKNOWN                # cells touching the jamb are part of the wall, whatever the size
    m[3, 7] = OCCUPIED
    assert widths(m, 3) == []


def test_too_wide_an_opening_is_a_passage_not_a_door():
    m = DOORS.copy()
    m[1:11, 7] = FREE            # the whole wall is open: 10 cells > door_max
    assert doors_between(m, (0, 0, 12, 8), (0, 7, 12, 15), CELLS) == []


def test_door_on_a_horizontal_wall_between_stacked_units():
    m = DOORS.T.copy()           # the same map transposed: units one above the other
    doors = doors_between(m, (0, 0, 8, 12), (7, 0, 15, 12), CELLS)
    assert [(d.box, d.vertical) for d in doors] == [((7, 2, 8, 5), False)]


OBJECTS = grid("""
############
#..........#
#.##.......#
#.##....?..#
#..........#
#.########.#
#..........#
#.....#....#
#......#...#
############
""")


def test_objects_are_small_non_free_components_inside_a_unit():
    objs = find_objects(OBJECTS, np.array([(0, 0, 10, 12)]), 1, CELLS.object_max_extent, [5])
    # the 2x2 block, the unknown cell and the diagonal pair; the 8-long interior wall is no object
    assert sorted((o.unit, o.box, o.cells) for o in objs) == [
        (5, (2, 2, 4, 4), 4), (5, (3, 8, 4, 9), 1), (5, (7, 6, 9, 8), 2)]


def test_cell_states_of_one_unit():
    s = cell_states(OBJECTS, np.array([(0, 0, 10, 12)]), 1, CELLS.object_max_extent)
    assert s[0, 0] == W_WALL and s[9, 5] == W_WALL
    assert s[2, 2] == W_OBJECT and s[3, 8] == W_OBJECT      # object, unknown-as-object
    assert s[5, 4] == W_FREE                               # interior wall: a mismatch, not an object
    assert s[1, 1] == W_FREE
    outside = cell_states(OBJECTS, np.array([(0, 0, 5, 6)]), 1, CELLS.object_max_extent)
    assert outside[8, 8] == W_UNKNOWN


def test_component_and_line_object_rules_differ_on_a_long_staircase():
    # a diagonal staircase 6 cells long: no straight run > 4 (lines: object),
    # but its component spans 6 > 4 cells (components: not an object, a mismatch)
    m = np.zeros((10, 10), np.uint8)
    for k in range(6):
        m[2 + k, 2 + k] = OCCUPIED
    rect = np.array([(0, 0, 10, 10)])
    comp = cell_states(m, rect, 1, 4)
    lines = cell_states(m, rect, 1, 4, objects="lines", wall_like=wall_like(m == OCCUPIED, 4))
    assert comp[4, 4] == W_FREE and lines[4, 4] == W_OBJECT
    # on the map above (straight runs only) the two rules agree
    wl = wall_like(OBJECTS == OCCUPIED, 4)
    a = cell_states(OBJECTS, np.array([(0, 0, 10, 12)]), 1, 4)
    b = cell_states(OBJECTS, np.array([(0, 0, 10, 12)]), 1, 4, objects="lines", wall_like=wl)
    assert np.array_equal(a, b)


def test_adjacency_as_in_the_paper_figure():
    # units 0 | 1 | 2 in a row, one free column between neighbours: dilated walls meet
    rects = np.array([(0, 0, 10, 10), (0, 11, 10, 21), (0, 22, 10, 32)])
    expected = [[False, True, False], [True, False, True], [False, True, False]]
    assert adjacency_matrix(rects, 1, 1).tolist() == expected
    assert adjacency_raster((12, 34), rects + [1, 1, 1, 1], 1, 1).tolist() == expected
    # three free columns between them: too far apart for a dilation of 1
    far = np.array([(0, 0, 10, 10), (0, 13, 10, 23)])
    assert not adjacency_matrix(far, 1, 1).any()
    # a small unit deep inside a big one touches none of its walls
    nested = np.array([(0, 0, 30, 30), (10, 10, 20, 20)])
    assert not adjacency_matrix(nested, 1, 1).any()


def test_closed_form_adjacency_equals_the_raster():
    rng = np.random.default_rng(7)
    for _ in range(150):
        n = int(rng.integers(2, 6))
        r0, c0 = rng.integers(5, 40, n), rng.integers(5, 40, n)
        rects = np.stack([r0, c0, r0 + rng.integers(4, 25, n), c0 + rng.integers(4, 25, n)], 1)
        wall, dil = int(rng.integers(1, 3)), int(rng.integers(1, 3))
        assert np.array_equal(adjacency_matrix(rects, wall, dil),
                              adjacency_raster((80, 80), rects, wall, dil))


UNEXPLORED = grid("""
??????????????????
?.....?...????????
?.....?...?......?
?.....?...?......?
?.....??????.....?
?.....?...?......?
?.....???.?......?
??????????????????
""")


def test_unexplored_areas_are_small_free_components_outside_units():
    units = np.array([(0, 0, 8, 7)])          # covers the left block
    areas = find_unexplored(UNEXPLORED, units, CELLS.min_side, CELLS.unexplored_min_area)
    # the 3x3 pocket and the 4-cell pocket below it are unexplored; the 6x5 block could be a unit
    assert [(a.box, a.cells) for a in areas] == [((1, 7, 4, 10), 9), ((5, 7, 7, 10), 4)]
    tiny = UNEXPLORED.copy()
    tiny[1:7, 7:10] = UNKNOWN
    tiny[5, 8] = FREE                          # a single free cell is noise
    assert find_unexplored(tiny, units, CELLS.min_side, CELLS.unexplored_min_area) == []


def test_derive_world_puts_doors_into_the_states():
    frame = build_frame_from_classes(DOORS, 0.05, load_model(), theta=0.0)
    frame = frame.__class__(frame.theta, frame.classes, frame.outside, frame.image_shape,
                            frame.resolution, CELLS, frame.origin)
    w = wm.add(wm.add(wm.empty(3), 0, (0, 0, 12, 8)), 2, (0, 7, 12, 15))
    d = derive_world(frame, w)
    assert d.slots.tolist() == [0, 2]
    assert [(x.p, x.q) for x in d.doors] == [(0, 2)]
    assert d.states[3, 7] == W_FREE and d.states[6, 7] == W_WALL
    assert d.adjacency.tolist() == [[False, True], [True, False]]


def test_compiled_adjacency_row_equals_the_closed_form():
    from semmap_pp.derive.adjacency import adjacency_row, adjacency_rows
    rng = np.random.default_rng(8)
    for _ in range(200):
        K = 8
        r0, c0 = rng.integers(0, 40, K), rng.integers(0, 40, K)
        rects = np.stack([r0, c0, r0 + rng.integers(4, 25, K), c0 + rng.integers(4, 25, K)], 1)
        active = rng.random(K) < 0.7
        s = int(rng.integers(K))
        active[s] = True
        out = np.zeros(K, bool)
        adjacency_row(rects.astype(np.int64), active, s, 2, 1, out)
        assert np.array_equal(out, adjacency_rows(rects, [s], 2, 1)[0] & active)


#: A corridor (rows 3..8, columns 2..8) ending in a hall (rows 0..4): the whole wall they share,
#: row 3 between the corridor's walls, is open.
HALL_END = grid("""
##########
#........#
#........#
###....###
..#....#..
..#....#..
..#....#..
..######..
""")
HALL, CORRIDOR = (0, 0, 4, 10), (3, 2, 8, 8)


def test_an_opening_without_a_jamb_is_a_passage_and_its_cells_are_free():
    """A corridor ending in a hall: the whole wall the two units share is open. Within door
    width, but with no jamb on the shared wall (none wider than the wall band): a passage, not a
    door; its cells are FREE in the world's states, as door cells are."""
    from semmap_pp.derive.doors import door_count, openings_between

    m, hall, corridor = HALL_END, HALL, CORRIDOR
    doors, passages = openings_between(m, hall, corridor, CELLS, 1, 2)
    assert doors == [] and [(d.box, d.width) for d in passages] == [((3, 3, 4, 7), 4)]
    assert door_count(m, hall, corridor, CELLS) == 0
    m2 = m.copy()
    m2[3, 3:5] = OCCUPIED            # a jamb of two cells: the opening narrowed to 2 is a door
    doors, passages = openings_between(m2, hall, corridor, CELLS, 1, 2)
    assert [(d.box, d.width) for d in doors] == [((3, 5, 4, 7), 2)] and passages == []
    assert door_count(m2, hall, corridor, CELLS) == 1
    cells = dataclasses.replace(load_model().cells(0.05), wall=1, door_min=2, door_max=4)
    frame = build_frame_from_classes(m, 0.05, load_model(), theta=0.0)
    frame = dataclasses.replace(frame, cells=cells)
    d = derive_world(frame, wm.add(wm.add(wm.empty(3), 0, hall), 1, corridor))
    assert d.doors == [] and len(d.passages) == 1
    assert (d.states[3, 3:7] == W_FREE).all() and d.states[3, 2] == W_WALL


def test_unknown_lines_beside_an_opening_are_no_jamb():
    """A jamb is a wall the map shows. Where the lines between an opening and the end of the
    shared wall hold unknown cells alone (the unseen margin along a wall where a corridor
    narrows), the opening reaches that end: a passage. An occupied cell next to the opening is a
    jamb, whatever lies beyond it."""
    from semmap_pp.derive.doors import opening_counts, openings_between

    m, hall, corridor = HALL_END.copy(), HALL, CORRIDOR
    m[3, 3:5] = UNKNOWN              # ###??..###: the opening's first two lines unseen
    doors, passages = openings_between(m, hall, corridor, CELLS, 1, 2)
    assert doors == [] and [(d.box, d.width) for d in passages] == [((3, 5, 4, 7), 2)]
    assert opening_counts(m, hall, corridor, CELLS) == (0, 1)
    m[3, 4] = OCCUPIED               # ###?#..###: a jamb beside the opening, unknown beyond it
    doors, passages = openings_between(m, hall, corridor, CELLS, 1, 2)
    assert [(d.box, d.width) for d in doors] == [((3, 5, 4, 7), 2)] and passages == []
    assert opening_counts(m, hall, corridor, CELLS) == (1, 0)


def test_compiled_opening_counts_equal_the_detector_on_unknown_rich_maps():
    """The compiled (doors, passages) count equals ``openings_between``'s on random maps with
    many unknown cells (the jamb test's unknown lines) and random pairs of rectangles."""
    from semmap_pp.derive.doors import opening_counts, openings_between

    rng = np.random.default_rng(5)
    seen = set()
    for _ in range(300):
        m = rng.choice(np.array([FREE, UNKNOWN, OCCUPIED], np.uint8), size=(30, 30), p=[0.6, 0.25, 0.15])
        r0, c0 = rng.integers(0, 12, 2)
        a = (int(r0), int(c0), int(r0 + rng.integers(4, 18)), int(c0 + rng.integers(4, 18)))
        if rng.random() < 0.5:          # stacked, sharing the band, overlapping along the wall
            b = (a[2] - 1, int(c0 + rng.integers(-3, 4)), a[2] + int(rng.integers(4, 10)),
                 int(c0 + rng.integers(6, 20)))
        else:                           # side by side
            b = (int(r0 + rng.integers(-3, 4)), a[3] - 1, int(r0 + rng.integers(6, 20)),
                 a[3] + int(rng.integers(4, 10)))
        m[max(a[2] - 1, 0):a[2], a[1]:a[3]] = rng.choice([FREE, UNKNOWN], size=a[3] - a[1])
        doors, passages = openings_between(m, a, b, CELLS)
        assert opening_counts(m, a, b, CELLS) == (len(doors), len(passages))
        seen.add((len(doors) > 0, len(passages) > 0))
    assert seen >= {(True, False), (False, True)}


def test_a_wall_beside_the_shared_band_makes_a_would_be_passage_a_door():
    """Two rooms whose rectangles share a band the map shows free, but whose wall stands one
    cell beside it (a slanted wall, a band rounded to the lattice), over all but a door's width:
    the units are walled apart there, so the opening is a door of that width, not a passage
    that would make them one space. With the wall gone the opening is a passage again; a wall
    beyond the widened strip (two bands away), or one beside the band shorter than a door, does
    not count."""
    from semmap_pp.derive.doors import opening_counts, openings_between

    cells = load_model().cells(0.05)                     # wall 2, doors 10..50 cells
    m = np.zeros((60, 60), np.uint8)
    m[0, :] = m[-1, :] = m[:, 0] = m[:, -1] = OCCUPIED
    left, right = (0, 0, 60, 30), (0, 28, 60, 60)         # shared band: columns 28..29
    m[2:40, 30] = OCCUPIED                                # the wall, beside the band, rows 2..39
    doors, passages = openings_between(m, left, right, cells)
    assert [(d.box, d.width) for d in doors] == [((40, 28, 58, 30), 18)] and passages == []
    assert opening_counts(m, left, right, cells) == (1, 0)
    m[2:40, 30] = FREE
    doors, passages = openings_between(m, left, right, cells)
    assert doors == [] and [d.width for d in passages] == [56]
    assert opening_counts(m, left, right, cells) == (0, 1)
    m[2:40, 32] = OCCUPIED                                # two bands away from the shared one
    assert opening_counts(m, left, right, cells) == (0, 1)
    assert [d.width for d in openings_between(m, left, right, cells)[1]] == [56]
    m[20:29, 30] = OCCUPIED                               # beside the band, shorter than a door:
    assert opening_counts(m, left, right, cells) == (0, 1)   # a jagged corner, not a wall
    assert [d.width for d in openings_between(m, left, right, cells)[1]] == [56]
