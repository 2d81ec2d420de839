"""Exterior units (semmap_pp.derive.exterior): free space seen outside the building through its
windows is flagged, rooms and pieces of a corridor are not, and the outputs list the flagged units
apart without changing the world's cell states or CPR."""

import dataclasses
import json
from pathlib import Path

import jsonschema
from hypothesis import given, settings
from hypothesis import strategies as st
import numpy as np
from PIL import Image

from semmap_pp import world as wm
from semmap_pp.cells import FREE, OCCUPIED, UNKNOWN
from semmap_pp.derive.exterior import find_exterior, side_shares
from semmap_pp.lattice.frame import build_frame
from semmap_pp.grid import OccupancyGrid
from semmap_pp.model import load_model
from semmap_pp.semantic.semantic_map import semantic_map
from semmap_pp.semantic.world_json import world_dict, write_labels_png
from semmap_pp.outputs.geojson import geojson_dict
from semmap_pp.outputs.graphml import world_graph
from semmap_pp.target.posterior import Posterior

SCHEMA = json.loads((Path(__file__).parents[2] / "docs" / "world.schema.json").read_text())
MODEL = load_model()


def room_with_window():
    """A 3 x 2.6 m room (walls 2 cells) with a 1 m window in its right wall, and the rays that
    left through the window: a fan of free lines, unknown between them, nothing hit."""
    c = np.full((80, 160), UNKNOWN, np.uint8)
    c[10:62, 10:72] = OCCUPIED
    c[12:60, 12:70] = FREE
    c[60:80, 10:72] = OCCUPIED                            # a second room below it
    c[62:78, 12:70] = FREE
    c[26:46, 70:72] = FREE                                # the window
    for row in range(-40, 120, 3):                        # rays beyond it, spreading out
        r = np.linspace(36, row, 80).round().astype(int)
        ok = (r >= 0) & (r < 79)
        c[r[ok], np.arange(72, 152)[ok]] = FREE
        c[r[ok] + 1, np.arange(72, 152)[ok]] = FREE
    return c


def grid_of(c):
    return OccupancyGrid(classes=c, occupancy=np.zeros(c.shape, np.float32), resolution=0.05,
                         origin=(0.0, 0.0, 0.0), source=None, image_path=None)


ROOM, FAN, ROOM2 = (10, 10, 62, 72), (20, 70, 54, 150), (60, 10, 80, 72)


def test_a_fan_beyond_a_window_is_exterior_and_the_room_is_not():
    c = room_with_window()
    flags = find_exterior(c, np.array([ROOM, FAN, ROOM2]), wall=2, max_share=0.3, seen_min=0.1)
    assert flags.tolist() == [False, True, False]
    # the fan's shares: its left side is the wall with the window (enclosed), rays leave the others
    count = np.zeros(c.shape, np.int32)
    for r0, c0, r1, c1 in (ROOM, FAN, ROOM2):
        count[r0:r1, c0:c1] += 1
    shares = np.sort(side_shares(c, FAN, count, 2, 0.1))
    assert shares[3] > 0.9 and shares[2] < 0.3


def test_the_test_is_off_at_zero_and_order_does_not_matter():
    c = room_with_window()
    assert not find_exterior(c, np.array([ROOM, FAN, ROOM2]), 2, 0.0, 0.1).any()
    assert find_exterior(c, np.array([ROOM2, FAN, ROOM]), 2, 0.3, 0.1).tolist() == [False, True, False]


def test_pieces_of_a_corridor_are_not_exterior():
    """A corridor junction: walls above, free space continuing left, right and down into
    neighbouring units. Its open sides lead into units, not out of the building."""
    c = np.full((60, 120), UNKNOWN, np.uint8)
    c[12:14, 0:120] = OCCUPIED                            # the wall above the corridor
    c[14:30, 0:120] = FREE                                # the corridor
    c[30:32, 0:50] = OCCUPIED                             # the wall below, broken by a branch
    c[30:32, 70:120] = OCCUPIED
    c[30:60, 50:70] = FREE                                # the branch going down
    c[30:60, 48:50] = OCCUPIED
    c[30:60, 70:72] = OCCUPIED
    rects = np.array([(12, 0, 32, 50), (12, 48, 32, 72), (12, 70, 32, 120), (30, 48, 60, 72)])
    assert not find_exterior(c, rects, 2, 0.3, 0.1).any()
    # without its neighbours' cover the junction's shares would flag it
    alone = np.zeros(c.shape, np.int32)
    alone[12:32, 48:72] = 1
    assert np.sort(side_shares(c, rects[1], alone, 2, 0.1))[2] < 0.3


def test_a_side_seen_too_little_counts_as_enclosed():
    """A room seen only through its door: the far half unknown. Its far side has almost no seen
    cells, so it counts as enclosed; the room is not exterior."""
    c = np.full((60, 60), UNKNOWN, np.uint8)
    c[10:50, 10:12] = OCCUPIED                            # left wall, seen
    c[10:12, 10:30] = OCCUPIED; c[48:50, 10:30] = OCCUPIED  # top and bottom walls, half seen
    c[12:48, 12:30] = FREE                                 # half of the inside seen
    c[20:40, 48:50] = FREE                                 # a sliver of the far side
    flags = find_exterior(c, np.array([(10, 10, 50, 50)]), 2, 0.3, 0.1)
    assert flags.tolist() == [False]


def fan_map():
    g = grid_of(room_with_window())
    f = build_frame(g, MODEL)
    assert f.theta == 0.0
    w = wm.add(wm.add(wm.add(wm.empty(4), 0, ROOM), 1, FAN), 2, ROOM2)
    return g, f, w


def test_outputs_list_exterior_units_apart_and_keep_the_cpr(tmp_path):
    g, f, w = fan_map()
    sm = semantic_map(g, f, Posterior(f, MODEL), w)
    off = dataclasses.replace(MODEL, world=dataclasses.replace(MODEL.world, exterior_max_share=0.0))
    f_off = build_frame(g, off)
    sm_off = semantic_map(g, f_off, Posterior(f_off, off), w)
    doc, doc_off = world_dict(sm), world_dict(sm_off)
    jsonschema.validate(doc, SCHEMA)
    assert [u["id"] for u in doc["units"]] == [1, 2] and len(doc_off["units"]) == 3
    assert len(doc["exterior"]) == 1 and doc_off["exterior"] == []
    x = doc["exterior"][0]
    assert x["id"] == 1 and x["units"] == [1]
    assert x["vertices_px"] == [[70.0, 20.0], [150.0, 20.0], [150.0, 54.0], [70.0, 54.0]]
    assert doc["adjacency"] == [[1, 2]] and doc["doors"] == []    # the window joins no two units
    assert doc["cpr"] == doc_off["cpr"] and doc["log_posterior"] == doc_off["log_posterior"]
    assert np.array_equal(sm.states_image, sm_off.states_image)
    # labels.png: the room only; the fan's cells are 0 where the room does not reach
    write_labels_png(tmp_path / "labels.png", sm.labels_image)
    lab = np.asarray(Image.open(tmp_path / "labels.png"))
    assert set(np.unique(lab).tolist()) == {0, 1, 2}
    assert (lab[20:54, 75:150] == 0).all() and (lab[12:60, 12:70] == 1).all()
    kinds = [ft["properties"]["kind"] for ft in geojson_dict(sm, doc)["features"]]
    assert kinds.count("exterior") == 1 and kinds.count("unit") == 2
    g = world_graph(sm, doc)
    assert [n for n, a in g.nodes(data=True) if a["kind"] == "exterior"] == ["x1"]
    assert g.edges["x1", "u1"]["relation"] == "next_to" and g.degree("x1") == 1


def test_a_unit_inside_the_building_footprint_is_not_exterior():
    """A fan of rays through a door into a room the robot never entered looks like a window fan,
    but it lies within the convex hull of the other units: the building's footprint."""
    c = room_with_window()
    far = (10, 150, 62, 160)           # another unit right of the fan: the fan is now between
    c[10:62, 150:160] = OCCUPIED
    c[12:60, 152:158] = FREE
    flags = find_exterior(c, np.array([ROOM, FAN, ROOM2, far]), 2, 0.3, 0.1)
    assert flags.tolist() == [False, False, False, False]
    # a footprint needs two units besides the one tested: a world keeps at least two
    assert find_exterior(c, np.array([ROOM, FAN]), 2, 0.3, 0.1).tolist() == [False, False]


def test_the_units_of_one_tile_keep_one_unit_not_two():
    """On a lattice of several directions each tile's units are tested on their own and the
    world's other tiles hold units too: a tile of a room and the fan beyond its window loses the
    fan (``keep=1``, what ``derive_world`` passes when there are several tiles), a world of those
    two units alone keeps both (``keep=2``, the default)."""
    c = room_with_window()
    rects = np.array([ROOM, FAN])
    assert find_exterior(c, rects, 2, 0.3, 0.1, keep=1).tolist() == [False, True]
    assert find_exterior(c, rects, 2, 0.3, 0.1).tolist() == [False, False]
    assert find_exterior(c, rects[:1], 2, 0.3, 0.1, keep=1).tolist() == [False]


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(1, 7))
def test_flags_do_not_depend_on_order_and_two_units_always_remain(seed, n):
    """Random maps and rectangles (some reaching past the map): the flags follow the units when
    their order is permuted, a world keeps at least two (or all, below three) of its units, and
    the input arrays are not edited."""
    rng = np.random.default_rng(seed)
    c = rng.choice(np.array([FREE, UNKNOWN, OCCUPIED], np.uint8), size=(40, 50), p=[0.5, 0.3, 0.2])
    r0, c0 = rng.integers(-5, 35, n), rng.integers(-5, 45, n)
    rects = np.stack([r0, c0, r0 + rng.integers(4, 20, n), c0 + rng.integers(4, 20, n)], axis=1)
    c_before, rects_before = c.copy(), rects.copy()
    flags = find_exterior(c, rects, 1, 0.6, 0.1)
    assert np.array_equal(c, c_before) and np.array_equal(rects, rects_before)
    assert np.count_nonzero(~flags) >= min(n, 2)
    perm = rng.permutation(n)
    assert np.array_equal(find_exterior(c, rects[perm], 1, 0.6, 0.1), flags[perm])
    one = find_exterior(c, rects, 1, 0.6, 0.1, keep=1)    # a tile's units: one kept
    assert np.count_nonzero(~one) >= min(n, 1) and np.all(one[flags])
    assert np.array_equal(find_exterior(c, rects[perm], 1, 0.6, 0.1, keep=1), one[perm])
    # with the building's outline as well (the random occupied cells: walls, or objects)
    for gap, extent in ((4, 0), (6, 2)):
        out = find_exterior(c, rects, 1, 0.6, 0.1, outline_gap=gap, object_extent=extent)
        assert np.count_nonzero(~out) >= min(n, 2)
        assert np.array_equal(find_exterior(c, rects[perm], 1, 0.6, 0.1, outline_gap=gap,
                                            object_extent=extent), out[perm])


def test_two_fans_side_by_side_do_not_shield_each_other():
    """A fan cut into two units: each covers the other's shared side, but neither is enclosed by
    walls of its own, so neither gives cover: both are exterior."""
    c = room_with_window()
    fan_a, fan_b = (20, 70, 54, 112), (20, 110, 54, 150)
    flags = find_exterior(c, np.array([ROOM, fan_a, fan_b, ROOM2]), 2, 0.3, 0.1)
    assert flags.tolist() == [False, True, True, False]
    # with the other fan's cover, fan_a's shares would keep it
    count = np.zeros(c.shape, np.int32)
    for r0, c0, r1, c1 in (ROOM, fan_a, fan_b, ROOM2):
        count[r0:r1, c0:c1] += 1
    assert np.sort(side_shares(c, fan_a, count, 2, 0.1))[2] >= 0.3


def test_fans_do_not_widen_the_footprint():
    """Two fans stacked along the open side of a hall (floor 6 of the synthetic benchmark): each
    lies mostly inside the convex hull of the hall and the *other* fan, so a footprint of every
    unit not flagged kept both. The footprint is the enclosed units' hull: both are exterior."""
    c = np.full((120, 160), UNKNOWN, np.uint8)
    c[10:110, 40:150] = OCCUPIED
    c[12:108, 42:128] = FREE
    c[12:108, 130:148] = FREE                             # a room beside the hall
    c[20:100, 40:42] = FREE                               # the hall's glass side
    c[15:105, 0:40] = FREE                                # rays beyond it
    hall, fan_a, fan_b = (10, 40, 110, 130), (20, 2, 60, 42), (60, 2, 100, 42)
    rects = np.array([hall, fan_a, fan_b, (10, 128, 110, 150)])
    assert find_exterior(c, rects, 2, 0.3, 0.1).tolist() == [False, True, True, False]
    # each fan is less than half outside the hull of the hall and the other fan
    from semmap_pp.derive.exterior import _hull, _outside_share
    assert _outside_share(np.array(fan_a), _hull(np.array([hall, fan_b]))) < 0.5
    assert _outside_share(np.array(fan_b), _hull(np.array([hall, fan_a]))) < 0.5


def test_a_corridor_stub_open_at_its_end_does_not_widen_the_footprint():
    """A corridor along the top of a room reaches past the room's window wall, over the fan of
    rays beyond the window (aces' north-west stub): its own walls enclose two of its sides (its
    floor and its closed end), so it is enclosed, but it does not widen the footprint. With it
    in the hull the fan would lie mostly inside; without it the fan is exterior."""
    from semmap_pp.derive.exterior import _hull, _outside_share

    c = np.full((110, 170), UNKNOWN, np.uint8)
    c[30:82, 10:72] = OCCUPIED
    c[32:80, 12:70] = FREE                                # a room ...
    c[44:68, 70:72] = FREE                                # ... with a window on its right
    c[80:100, 10:72] = OCCUPIED
    c[82:98, 12:70] = FREE                                # a room below it
    c[10:32, 10:150] = FREE                               # a corridor above, open above and right
    c[30:32, 10:150] = OCCUPIED                           # its floor wall drawn
    c[10:32, 10:12] = OCCUPIED                            # its closed left end
    c[40:43, 72:150:2] = FREE                             # rays beyond the window
    for row in range(34, 110, 3):
        r = np.linspace(56, row, 78).round().astype(int)
        ok = (r >= 34) & (r < 109)
        c[r[ok], np.arange(72, 150)[ok]] = FREE
    room, room2, stub, fan = (30, 10, 82, 72), (80, 10, 100, 72), (10, 10, 32, 150), (40, 70, 76, 150)
    assert find_exterior(c, np.array([room, room2, stub, fan]), 2, 0.3, 0.1).tolist() == [
        False, False, False, True]
    assert _outside_share(np.array(fan), _hull(np.array([room, room2, stub]))) < 0.5
    own = side_shares(c, stub, None, 2, 0.1, own=0)
    assert np.sort(own)[1] < 0.3 <= np.sort(own)[2]       # two sides of its own: enclosed, not walled


def test_without_an_enclosed_unit_nothing_is_exterior():
    """Free space everywhere (a map that shows its outside as free): no unit is enclosed, there
    is no footprint to be outside of, and no unit is flagged."""
    c = np.full((60, 90), FREE, np.uint8)
    rects = np.array([(0, 0, 30, 30), (0, 30, 30, 60), (0, 60, 30, 90), (30, 0, 60, 90)])
    assert not find_exterior(c, rects, 2, 0.3, 0.1).any()


def test_a_strip_closed_only_at_its_short_ends_does_not_shield_a_fan():
    """A thin unit inside the fan beyond the window, closed by obstacles at its two short ends and
    open along both long sides, passes the two-sides test on its own walls but encloses a fifth of
    its perimeter: it gives no cover and does not widen the footprint, so the fan is still
    flagged (it was not when such a strip counted as supported)."""
    from semmap_pp.derive.exterior import perimeter_share

    cls = np.ones((30, 30), np.uint8)
    cls[2:28, 2:14] = OCCUPIED
    cls[3:15, 3:13] = FREE
    cls[16:27, 3:13] = FREE
    cls[6:10, 13] = FREE
    cls[1:20, 14:28] = FREE
    cls[3, 20:22] = OCCUPIED
    cls[18, 20:22] = OCCUPIED
    strip = (3, 20, 19, 22)
    own = side_shares(cls, strip, None, 1, 0.1, own=0)
    assert np.sort(own)[2] >= 0.3 and perimeter_share(own, strip) < 0.3
    rects = np.array([[2, 2, 16, 14], [2, 13, 18, 28], [15, 2, 28, 14], strip])
    assert find_exterior(cls, rects, wall=1, max_share=0.3, seen_min=0.1).tolist() == \
        [False, True, False, False]


def l_building_with_corner_fan():
    """An L-shaped building: room A (upper left) with a 1 m window in its right wall, and a long
    room B below A reaching further right. The rays through the window fill the concave corner
    beyond A's right wall and above B's top wall, and leave it upwards and to the right."""
    c = np.full((100, 140), UNKNOWN, np.uint8)
    c[20:62, 10:52] = OCCUPIED                            # A and its walls
    c[22:60, 12:50] = FREE
    c[60:92, 10:130] = OCCUPIED                           # B and its walls
    c[62:90, 12:128] = FREE
    c[34:54, 50:52] = FREE                                # the window in A's right wall
    for row in range(-60, 60, 3):                         # rays beyond it, over B's roof line
        r = np.linspace(44, row, 90).round().astype(int)
        cols = np.arange(52, 142)
        ok = (r >= 0) & (r < 60) & (cols < 140)
        c[r[ok], cols[ok]] = FREE
        c[r[ok] + 1, cols[ok]] = FREE
    return c


A, B, CORNER = (20, 10, 62, 52), (60, 10, 92, 130), (16, 50, 62, 130)


def test_a_fan_in_the_concave_corner_of_the_building_is_exterior():
    """The corner fan has two enclosed sides (A's right wall and B's top wall, both drawn, with A
    and B across them) and lies inside the convex hull of A and B, so the three-open-sides test
    misses it; it lies outside their orthogonal hull (the L itself) and is flagged."""
    from semmap_pp.derive.exterior import ortho_hull

    c = l_building_with_corner_fan()
    shares = np.sort(side_shares(c, CORNER, None, 2, 0.1))
    assert shares[2] >= 0.3 > shares[1]                  # two enclosed sides, two open ones
    hull = ortho_hull(np.array([A, B]), c.shape)
    assert not hull[30, 100] and hull[30, 30] and hull[80, 120]
    flags = find_exterior(c, np.array([A, B, CORNER]), wall=2, max_share=0.3, seen_min=0.1)
    assert flags.tolist() == [False, False, True]


def test_a_room_glimpsed_through_its_door_with_one_wall_drawn_is_not_exterior():
    """Beyond a corridor's door, a room whose back and right walls the laser never hit: rays leave
    it through those two sides, but its drawn left wall has no building unit across it (the
    space beyond is unknown), so it is not a fan between two building walls."""
    c = np.full((100, 140), UNKNOWN, np.uint8)
    c[60:80, 0:140] = OCCUPIED                            # a corridor and its walls
    c[62:78, 0:140] = FREE
    c[20:62, 40:42] = OCCUPIED                            # the room's drawn left wall
    c[60:62, 60:80] = FREE                                # the door in the corridor's top wall
    for col in range(20, 160, 3):                         # rays through the door, into the room
        r = np.linspace(61, 10, 60).round().astype(int)
        cc = np.linspace(70, col, 60).round().astype(int)
        ok = (cc >= 42) & (cc < 140)
        c[r[ok], cc[ok]] = FREE
    corridor, room = (60, 0, 80, 140), (18, 40, 62, 110)
    shares = np.sort(side_shares(c, room, None, 2, 0.1))
    assert shares[2] >= 0.3 > shares[1]
    corridor2 = (80, 0, 100, 140)                         # a room below, enclosed too
    c[80:100, 0:140] = OCCUPIED
    c[82:98, 2:138] = FREE
    flags = find_exterior(c, np.array([corridor, room, corridor2]), wall=2, max_share=0.3,
                          seen_min=0.1)
    assert not flags[1]


def u_building(notch: str):
    """A U-shaped building: wings L and R (rooms enclosed by walls) and a base B below them. The
    notch between the wings holds either a fan of rays through a window in L's right wall
    (``"fan"``: rays stop at R's wall or leave the notch up and down, unknown between them) or a
    corridor seen whole, open at both ends (``"corridor"``)."""
    c = np.full((130, 120), UNKNOWN, np.uint8)
    for r0, c0, r1, c1 in ((10, 10, 90, 40), (10, 80, 90, 110), (88, 10, 120, 110)):
        c[r0:r1, c0:c1] = OCCUPIED
        c[r0 + 2:r1 - 2, c0 + 2:c1 - 2] = FREE
    if notch == "fan":
        c[40:50, 38:40] = FREE                            # the window
        for angle in np.linspace(-1.3, 1.3, 27):          # rays from it, stopped by R's wall
            for t in np.arange(0.0, 120.0, 0.5):
                r, col = int(round(45 + t * np.sin(angle))), int(round(40 + t * np.cos(angle)))
                if not (0 <= r < 88 and 40 <= col < 120) or c[r, col] == OCCUPIED:
                    break
                c[r, col] = FREE
    else:
        c[0:88, 40:80] = FREE
    return c


UL, UR, UB, NOTCH = (10, 10, 90, 40), (10, 80, 90, 110), (88, 10, 120, 110), (20, 38, 70, 82)


def test_a_fan_in_the_notch_of_a_u_is_exterior_but_a_corridor_there_is_not():
    """Both units lie inside the orthogonal hull (it fills the notch), both have two open sides
    and two drawn walls with a wing across each; the fan shows little of its interior, the
    corridor all of it."""
    from semmap_pp.derive.exterior import _seen_inside, ortho_hull

    rects = np.array([UL, UR, UB, NOTCH])
    assert ortho_hull(rects[:3], (130, 120))[30, 60]
    for notch, flagged in (("fan", True), ("corridor", False)):
        c = u_building(notch)
        shares = np.sort(side_shares(c, NOTCH, None, 2, 0.1))
        assert shares[2] >= 0.3 > shares[1], notch
        assert (_seen_inside(c, NOTCH, 2) < 0.7) == flagged
        flags = find_exterior(c, rects, wall=2, max_share=0.3, seen_min=0.1, fan_seen_max=0.7)
        assert flags.tolist() == [False, False, False, flagged], notch
        # without the seen-share rule neither is flagged: the orthogonal hull holds both
        assert not find_exterior(c, rects, wall=2, max_share=0.3, seen_min=0.1).any()


def test_a_fan_with_no_door_outside_the_outline_is_exterior_however_the_hulls_hold_it():
    """The U's notch fan when W* has no unit over the east wing: its two sides are the wings'
    drawn walls, but no enclosed unit lies across the east one, so the rules of the hulls keep
    it. It lies outside the outline (the notch is wider than the gap), shows little of its
    interior and has no door: with its own walls along less than ``outline_walls_max`` of its
    perimeter it is exterior; with a door (a room glimpsed through it), with walls along more, or
    with the rule off it is kept, and so is a corridor seen whole there. The west wing and the
    base, inside the outline, are never flagged."""
    from semmap_pp.derive.exterior import building_outline, perimeter_share

    rects = np.array([UL, UB, NOTCH])
    kw = dict(wall=2, max_share=0.3, seen_min=0.1, fan_seen_max=0.7, outline_gap=30)
    c = u_building("fan")
    assert not building_outline(c, 30)[30, 60] and building_outline(c, 30)[50, 25]
    assert not find_exterior(c, rects, **kw).any()
    per = perimeter_share(side_shares(c, NOTCH, None, 2, 0.1, own=0), NOTCH)
    assert 0.3 < per < 0.7
    no_doors = np.zeros(3, bool)
    assert find_exterior(c, rects, **kw, outline_walls_max=per + 0.01,
                         opened=no_doors).tolist() == [False, False, True]
    for walls_max, opened in ((per - 0.01, no_doors), (per + 0.01, np.ones(3, bool)),
                              (0.0, no_doors), (per + 0.01, None)):
        assert not find_exterior(c, rects, **kw, outline_walls_max=walls_max, opened=opened).any()
    assert not find_exterior(u_building("corridor"), rects, **kw, outline_walls_max=1.0,
                             opened=no_doors).any()


# ------------------------------------------------------------------ the building's own outline

def rotated_wing_building():
    """A building of two wings (0.05 m cells): a main wing of two rooms on the lattice, and east
    of it a 7 x 5 m hall rotated by 30 degrees, drawn into the grid with its own walls, joined to
    the main wing's upper room by a 1 m door. The hall has a 1 m window in its far wall with a
    fan of rays beyond it."""
    c = np.full((300, 380), UNKNOWN, np.uint8)
    rr, cc = np.mgrid[0:300, 0:380]
    theta = np.deg2rad(30.0)
    u = (cc - 205) * np.cos(theta) + (rr - 130) * np.sin(theta)    # along the hall
    v = -(cc - 205) * np.sin(theta) + (rr - 130) * np.cos(theta)   # across it
    c[(np.abs(u) <= 73) & (np.abs(v) <= 53)] = OCCUPIED
    c[(np.abs(u) <= 70) & (np.abs(v) <= 50)] = FREE
    c[60:200, 20:124] = OCCUPIED                          # the main wing: two rooms
    c[62:128, 22:120] = FREE
    c[132:198, 22:120] = FREE
    door = np.flatnonzero(c[:128, 124] == FREE)[-20:]     # rows where the hall meets the upper room
    c[door, 120:124] = FREE
    c[(u > 69) & (u < 75) & (np.abs(v) < 10)] = FREE      # the window in the hall's far wall
    for dv in np.linspace(-45, 45, 31):                   # rays through it, spreading out
        for t in np.arange(0.0, 70.0, 0.5):
            uu, vv = 74 + t, dv * t / 70.0
            r = int(round(130 + uu * np.sin(theta) + vv * np.cos(theta)))
            col = int(round(205 + uu * np.cos(theta) - vv * np.sin(theta)))
            if 0 <= r < 300 and 0 <= col < 380 and c[r, col] == UNKNOWN:
                c[r, col] = FREE
    return c


MAIN1, MAIN2, WING_FAN = (60, 20, 130, 124), (128, 20, 200, 124), (160, 262, 230, 330)
HALL_TILINGS = ([(95, 160, 165, 250)], [(70, 150, 130, 260), (128, 140, 190, 270)],
                [(80, 130, 180, 280)])


def test_a_wing_at_another_angle_is_inside_the_outline_and_never_exterior():
    """The lattice's rectangles do not fit the rotated hall: rays leave their sides through the
    hall's slanted walls and the hall lies outside the hulls of the main wing's rooms, so the
    hull rules alone call the hall's units exterior (issue 48). The building's walls enclose the
    hall: with the outline none of its units is flagged, and the fan beyond its window still is."""
    from semmap_pp.derive.exterior import building_outline

    c = rotated_wing_building()
    inside = building_outline(c, 30)                      # 1.5 m at 0.05 m per cell
    assert inside[130, 205] and inside[95, 70] and inside[170, 70]     # the hall, both rooms
    assert not inside[200, 300] and not inside[10, 10]                 # the fan, the outside
    for hall in HALL_TILINGS:
        rects = np.array([MAIN1, MAIN2, *hall, WING_FAN])
        before = find_exterior(c, rects, 2, 0.3, 0.1)
        assert before[2:-1].any(), hall                   # the hull rules alone: the hall is out
        flags = find_exterior(c, rects, 2, 0.3, 0.1, outline_gap=30)
        assert flags.tolist() == [False] * (len(rects) - 1) + [True], hall


def test_the_outline_bridges_gaps_up_to_its_width_and_no_wider():
    """A square building whose walls are dashed (0.75 m of wall, 1 m gaps: an outer wall drawn
    from a few scans, windows, exits) is enclosed at a 1.5 m outline gap; one gap of 2 m lets the
    disc in, and everything it reaches lies outside."""
    from semmap_pp.derive.exterior import building_outline

    c = np.full((200, 200), UNKNOWN, np.uint8)
    c[40:160, 40:160] = FREE
    for k in range(40, 160, 35):                          # 15 cells of wall, 20 of gap
        c[38:40, k:k + 15] = c[160:162, k:k + 15] = OCCUPIED
        c[k:k + 15, 38:40] = c[k:k + 15, 160:162] = OCCUPIED
    c[38:40, 150:162] = c[150:162, 160:162] = OCCUPIED    # the corners closed
    c[160:162, 150:162] = c[150:162, 38:40] = OCCUPIED
    c[38:40, 38:50] = c[38:50, 38:40] = c[160:162, 38:50] = OCCUPIED
    inside = building_outline(c, 30)
    assert inside[45:155, 45:155].all()                   # the disc bites a little way into gaps
    assert inside[40:160, 40:160].mean() > 0.98 and not inside[:30].any()
    assert not building_outline(c, 15)[100, 100]          # a 0.75 m gap: the disc passes 1 m ones
    c[38:40, 75:125] = FREE                               # a 2.5 m gap in the top wall
    assert not building_outline(c, 30)[100, 100]
    # the hull rules decide alone where the outline lets the outside in: the same flags as without
    cls = room_with_window()
    cls[10:12, 20:60] = FREE                              # a 2 m gap in the room's top wall
    for gap in (0, 30):
        assert find_exterior(cls, np.array([ROOM, FAN, ROOM2]), 2, 0.3, 0.1,
                             outline_gap=gap).tolist() == [False, True, False]


def test_the_outline_keeps_the_fans_outside_the_building():
    """Fans beyond a window, side by side, in the concave corner of an L and in the notch of a U
    (its mouth 2 m wide, wider than the 1.5 m gap): the outline leaves them outside, and each is
    flagged as without it; the corridor in the notch is not."""
    cases = [(room_with_window(), [ROOM, FAN, ROOM2], [False, True, False], 0.0),
             (room_with_window(), [ROOM, (20, 70, 54, 112), (20, 110, 54, 150), ROOM2],
              [False, True, True, False], 0.0),
             (l_building_with_corner_fan(), [A, B, CORNER], [False, False, True], 0.0),
             (u_building("fan"), [UL, UR, UB, NOTCH], [False, False, False, True], 0.7),
             (u_building("corridor"), [UL, UR, UB, NOTCH], [False, False, False, False], 0.7)]
    for c, rects, want, fan_seen_max in cases:
        for gap in (0, 30):
            got = find_exterior(c, np.array(rects), 2, 0.3, 0.1, fan_seen_max=fan_seen_max,
                                outline_gap=gap)
            assert got.tolist() == want, (rects, gap)


def test_obstacles_where_the_rays_end_outside_are_not_walls_of_the_outline():
    """Single occupied cells scattered over the fan (trees, cars, clutter where rays end: the
    synthetic floors' fans hold them) would hold the disc back and put the fan within the outline;
    components no longer than ``object_extent`` are objects, and the fan stays outside."""
    from semmap_pp.derive.exterior import building_outline

    c = room_with_window()
    rng = np.random.default_rng(0)
    beyond = np.zeros(c.shape, bool)
    beyond[:, 74:] = True
    c[beyond & (rng.random(c.shape) < 0.03)] = OCCUPIED
    rects = np.array([ROOM, FAN, ROOM2])
    assert building_outline(c, 30)[37, 110] and not building_outline(c, 30, 30)[37, 110]
    assert find_exterior(c, rects, 2, 0.3, 0.1, outline_gap=30).tolist() == [False, False, False]
    assert find_exterior(c, rects, 2, 0.3, 0.1, outline_gap=30, object_extent=30).tolist() == [
        False, True, False]


WINGS = Path(__file__).parents[1] / "data" / "wings"
# W*s of `semmap map` on the plans (seed 0, the model of CHANGELOG.md 2026-12-04; the lattice at
# 0 degrees): (the building's units, the units in the building the hull rules alone flag, the fans)
PLAN_WSTARS = {
    "wing30": ([(199, 79, 300, 160), (199, 159, 300, 240), (199, 239, 300, 320),
                (199, 319, 300, 400), (199, 399, 300, 480), (299, 79, 340, 549),
                (340, 79, 440, 160), (340, 159, 440, 240), (340, 239, 440, 320),
                (340, 319, 440, 400), (340, 399, 440, 480), (354, 805, 472, 883),
                (315, 547, 512, 630), (470, 805, 512, 846)],
               [(266, 628, 443, 706), (300, 704, 512, 807), (441, 628, 557, 706),
                (510, 704, 600, 816)],
               [(88, 165, 200, 235), (598, 652, 690, 739)]),
    "wing45": ([(199, 79, 300, 160), (199, 159, 300, 240), (199, 239, 300, 320),
                (199, 319, 300, 400), (199, 399, 300, 480), (299, 79, 340, 558),
                (335, 699, 372, 731), (303, 637, 472, 701), (340, 79, 440, 160),
                (340, 159, 440, 240), (340, 239, 440, 320), (340, 319, 440, 400),
                (340, 399, 440, 480), (338, 522, 546, 639), (447, 501, 490, 524),
                (462, 827, 518, 857), (427, 784, 559, 829)],
               [(370, 699, 630, 786), (470, 637, 656, 701), (544, 585, 594, 639)],
               [(86, 168, 200, 232), (635, 553, 729, 647)]),
    "pentagon": ([(141, 417, 207, 463), (160, 378, 232, 419), (160, 461, 232, 501),
                  (214, 703, 274, 734), (190, 153, 299, 221), (179, 651, 337, 705),
                  (271, 557, 304, 599), (275, 597, 337, 653), (297, 188, 331, 287),
                  (329, 217, 352, 247), (329, 155, 411, 219), (335, 642, 483, 725),
                  (408, 723, 483, 799), (409, 82, 503, 246), (538, 254, 586, 274),
                  (481, 619, 654, 774), (501, 110, 654, 256), (550, 594, 605, 621),
                  (584, 254, 642, 291), (603, 587, 642, 621), (640, 258, 681, 621),
                  (680, 320, 781, 401), (680, 399, 781, 481), (680, 479, 781, 561)],
                 [(102, 499, 273, 599), (98, 307, 279, 380), (143, 597, 277, 653),
                  (129, 219, 299, 309)],
                 [(50, 640, 152, 728)]),
}


def test_the_drawn_plans_with_wings_at_other_angles():
    """tests/data/wings (make_wings.py): a main wing on the image axes and a second wing at 30 or
    45 degrees, and a pentagonal ring of rooms at five angles, each with a fan of rays beyond a
    window. The lattice runs along the image axes; the hull rules call 4, 3 and 4 units inside
    the building exterior, with the model's outline only the fans are."""
    from semmap_pp.grid import load_map

    for name, (building, inside, fans) in PLAN_WSTARS.items():
        grid = load_map(WINGS / f"{name}.yaml")
        frame = build_frame(grid, MODEL)
        assert frame.theta == 0.0 and frame.crop is None, name
        c = frame.cells
        rects = np.array(building + inside + fans)
        args = (frame.classes, rects, c.wall, c.exterior_max_share, c.exterior_seen_min)
        kw = dict(across=c.adjacency_dilation, fan_seen_max=c.exterior_fan_seen_max)
        before = find_exterior(*args, **kw)
        assert np.flatnonzero(before).tolist() == list(range(len(building), len(rects))), name
        after = find_exterior(*args, **kw, outline_gap=c.exterior_outline_gap,
                              object_extent=c.object_max_extent)
        assert np.flatnonzero(after).tolist() == list(range(len(rects) - len(fans), len(rects))), name


def l_building(open_west: bool = False):
    """An L of two rooms (walls 2 cells): A along the top, B down the left side, a door between
    them; a window in A's bottom wall with a fan of rays beyond it into the L's open corner, which
    the convex hull of A and B spans. ``open_west``: B's outer wall has a 2.5 m gap (a glass front
    the laser did not draw), so the outline lets the outside into B."""
    c = np.full((240, 240), UNKNOWN, np.uint8)
    c[0:62, 0:220] = OCCUPIED
    c[2:60, 2:218] = FREE
    c[60:220, 0:62] = OCCUPIED
    c[62:218, 2:60] = FREE
    c[60:62, 20:40] = FREE                                # the door between A and B
    c[60:62, 120:140] = FREE                              # the window
    for col in range(-20, 281, 4):                        # rays beyond it, spreading out
        for t in np.linspace(0.0, 1.0, 300):
            r, cc = int(round(61 + 150 * t)), int(round(130 + (col - 130) * t))
            if not (0 <= r < 240 and 0 <= cc < 240) or c[r, cc] == OCCUPIED:
                break                                     # a ray stops at a wall
            c[r, cc] = FREE
    if open_west:
        c[100:150, 0:2] = FREE
    return c


L_A, L_B, L_FAN = (0, 0, 62, 220), (60, 0, 220, 62), (62, 100, 122, 160)


def test_a_fan_the_hull_spans_is_exterior_when_the_outline_holds_the_building():
    """The fan beyond the L's window opens on three sides and lies inside the hull of the two
    enclosed rooms, so the hull keeps it; it lies outside the building's outline, and the outline
    holds both rooms whole: with ``outline_trust`` it is exterior. Where the outline lets the
    outside into room B (an undrawn glass front), it holds less than ``outline_trust`` of the
    enclosed rooms' cells and the hull decides alone, as on a map explored in part."""
    from semmap_pp.derive.exterior import building_outline, outline_share
    rects = np.array([L_A, L_B, L_FAN])
    kw = dict(wall=2, max_share=0.3, seen_min=0.1, outline_gap=30)
    c = l_building()
    assert not building_outline(c, 30)[100, 130] and building_outline(c, 30)[30, 100]
    assert outline_share(c, rects, 2, 0.3, 0.1, 30) > 0.99    # the window's cells lie outside
    assert not find_exterior(c, rects, **kw).any()
    assert find_exterior(c, rects, **kw, outline_trust=0.8).tolist() == [False, False, True]
    leaky = l_building(open_west=True)
    share = outline_share(leaky, rects, 2, 0.3, 0.1, 30)
    assert 0.3 < share < 0.8
    assert not find_exterior(leaky, rects, **kw, outline_trust=0.8).any()
    assert find_exterior(leaky, rects, **kw, outline_trust=share - 0.01).tolist() == [False, False, True]
