"""The greedy ascent (ascent.refine_world) and the door candidates it relies on."""

from types import SimpleNamespace

import numpy as np
import pytest

from semmap_pp import world as wm
from semmap_pp.cells import FREE, OCCUPIED, UNKNOWN
from semmap_pp.lattice.frame import build_frame
from semmap_pp.grid import OccupancyGrid
from semmap_pp.sampler.ascent import align_walls, refine_world
from semmap_pp.sampler.kernels import build_data, data_from_frame
from semmap_pp.model import load_model
from semmap_pp.target.posterior import Posterior, below_floor


def two_rooms() -> np.ndarray:
    """Two 3 m x 3 m rooms (0.05 m cells) side by side, 2-cell walls, a 0.8 m door between them."""
    m = np.full((84, 144), UNKNOWN, np.uint8)
    m[2:82, 2:142] = OCCUPIED
    m[4:80, 4:70] = FREE
    m[4:80, 72:140] = FREE
    m[34:50, 70:72] = FREE          # the door in the shared wall
    return m


def knowledge_free(m: np.ndarray):
    """The knowledge-free target and the kernels' data of lattice map ``m`` (0.05 m cells, no
    rotation): ``(posterior, data)``."""
    frame = build_frame(OccupancyGrid(m, np.zeros(m.shape, np.float32), 0.05), load_model())
    assert frame.theta == 0.0
    return Posterior(frame, load_model(), None), data_from_frame(frame)


def test_refine_reaches_the_walls_and_swallows_the_fragment():
    model = load_model()
    grid = OccupancyGrid(two_rooms(), np.zeros((84, 144), np.float32), 0.05)
    frame = build_frame(grid, model)
    assert frame.theta == 0.0                                # the lattice is the image
    post = Posterior(frame, model, None)
    start = wm.empty(8)
    start = wm.add(start, 0, (2, 2, 82, 50))                # left room stops 20 cells short of its wall
    start = wm.add(start, 1, (4, 50, 80, 70))               # a strip between it and the wall
    start = wm.add(start, 2, (2, 70, 82, 142))              # the right room, right as it is
    out = refine_world(post, start, data_from_frame(frame))
    assert post.evaluate(out).total > post.evaluate(start).total
    rects = sorted(tuple(int(v) for v in out.rects[s]) for s in wm.active_slots(out))
    assert len(rects) == 2                                  # the strip was absorbed, nothing born
    left, right = rects
    assert abs(left[3] - 72) <= 2 and left[:3] == (2, 2, 82)  # its wall band now sits on the shared wall
    assert right == (2, 70, 82, 142)


def test_align_walls_moves_walls_only():
    """Rectangles a few cells off their walls are set on them; no unit is added, removed, merged
    or cut, even where refine_world would (a fragment-free world of two misplaced rooms)."""
    post, data = knowledge_free(two_rooms())
    start = wm.add(wm.add(wm.empty(8), 3, (4, 1, 79, 69)), 5, (1, 73, 84, 140))
    out = align_walls(post, start, data)
    assert wm.active_slots(out).tolist() == [3, 5]
    assert post.evaluate(out).total > post.evaluate(start).total
    assert tuple(int(v) for v in out.rects[3]) == (2, 2, 82, 72)
    assert tuple(int(v) for v in out.rects[5]) == (2, 70, 82, 142)
    assert np.array_equal(start.rects[3], (4, 1, 79, 69))      # the input is not edited


def hall_with_window() -> np.ndarray:
    """A 4.8 m x 4 m hall (2-cell walls) with a 0.45 m window in its top wall and free space seen
    through it above (outside the building)."""
    m = np.full((140, 120), UNKNOWN, np.uint8)
    m[40:120, 2:102] = OCCUPIED
    m[42:118, 4:100] = FREE
    m[10:40, 60:95] = FREE
    m[40:42, 74:83] = FREE
    return m


def test_a_merge_trims_the_unit_that_blocks_its_box(monkeypatch):
    """The hall in two pieces (a strip along its right wall) and a third unit over the space seen
    through the window and the hall's top right corner: merging the two pieces is only a gain
    when the third unit is cut back to the hall's top wall (a wall line), which the merge does."""
    from semmap_pp.sampler import ascent

    post, data = knowledge_free(hall_with_window())
    start = wm.add(wm.add(wm.add(wm.empty(8), 0, (40, 2, 120, 72)), 1, (60, 70, 120, 102)),
                   2, (8, 70, 62, 102))
    asc = ascent._Ascent(post, start, data)
    assert asc.merges()
    rects = sorted(tuple(int(v) for v in asc.world.rects[s]) for s in wm.active_slots(asc.world))
    assert (40, 2, 120, 102) in rects                        # the hall is one unit
    (fan,) = [r for r in rects if r != (40, 2, 120, 102)]
    assert fan[0] < 40 and fan[2] <= 42                       # the third one ends at the hall's top wall
    assert asc.tr.logp > post.evaluate(start).total
    assert abs(asc.tr.logp - post.evaluate(asc.world).total) < 1e-6 * abs(asc.tr.logp)

    # without the trim the two pieces cannot be merged (the box would overlap the third unit)
    monkeypatch.setattr(ascent._Ascent, "cut_back", lambda self, world, a, box: (world, []))
    old = ascent._Ascent(post, start, data)
    old.merges()
    assert (40, 2, 120, 102) not in {tuple(int(v) for v in old.world.rects[s])
                                     for s in wm.active_slots(old.world)}


def test_a_merge_swallows_a_third_piece_that_lies_inside_its_box(monkeypatch):
    """The hall in three pieces, a strip along its right wall cut in two: the box of the hall's
    main piece and either strip piece holds the other strip piece whole, so the merge drops it
    (before, a unit the box swallowed blocked the merge and the hall stayed in pieces: synthetic
    floor 7, docs/quality.md)."""
    from semmap_pp.sampler import ascent

    post, data = knowledge_free(hall_with_window())
    start = wm.add(wm.add(wm.add(wm.empty(8), 0, (40, 2, 120, 72)), 1, (40, 70, 100, 102)),
                   2, (98, 70, 120, 102))
    asc = ascent._Ascent(post, start, data)
    assert asc.merges()
    rects = [tuple(int(v) for v in asc.world.rects[s]) for s in wm.active_slots(asc.world)]
    assert rects == [(40, 2, 120, 102)]
    assert asc.tr.logp > post.evaluate(start).total
    assert abs(asc.tr.logp - post.evaluate(asc.world).total) < 1e-6 * abs(asc.tr.logp)

    # what the merge does with the third piece: no part of a unit side is left beside the box
    box = (40, 2, 120, 102)
    swallowed, cut = asc.cut_back(wm.replace(wm.remove(start, 1), 0, box), 0, box)
    assert cut == [2] and not swallowed.active[2]


def test_a_merge_trims_a_unit_only_along_a_wall_line():
    """Two rooms; the left one in two pieces, the second reaching across the shared wall into the
    right room. Their box would cut the right room back at a column of open floor (no wall line
    there), so the merge is refused, although the target would take it (intel's rooms and
    corridor ends were merged into one hall that way; docs/sampler.md)."""
    from semmap_pp.sampler import ascent

    post, data = knowledge_free(two_rooms())
    start = wm.add(wm.add(wm.add(wm.empty(8), 0, (2, 2, 82, 60)), 1, (2, 58, 82, 100)),
                   2, (2, 70, 82, 142))
    asc = ascent._Ascent(post, start, data)
    box = (2, 2, 82, 100)
    trimmed, cut = asc.cut_back(wm.replace(wm.remove(start, 1), 0, box), 0, box)
    assert cut == [2] and tuple(int(v) for v in trimmed.rects[2]) == (2, 98, 82, 142)
    assert asc.boundary_lines(box, trimmed.rects[2]) < asc.trim_line_min    # open floor at column 98
    assert not asc.merges()
    assert np.array_equal(asc.world.rects, start.rects)
    # the other guard: a unit left with less than half its area is not trimmed but kept whole
    keep = ascent._Ascent(post, start, data, merge_keep=0.7, trim_line_min=0.0)
    assert not keep.merges()                                  # 44 of 72 columns kept: 0.61 < 0.7
    loose = ascent._Ascent(post, start, data, merge_keep=0.5, trim_line_min=0.0)
    assert loose.merges()                                     # without both guards the merge is taken


def corridor_over_room() -> np.ndarray:
    """A 0.9 m x 9.8 m corridor (2-cell walls) and a 3 m x 3 m room below its middle, joined by a
    0.8 m door."""
    m = np.full((126, 206), UNKNOWN, np.uint8)
    m[38:122, 2:202] = OCCUPIED
    m[40:58, 4:200] = FREE
    m[60:120, 100:160] = FREE
    m[58:60, 120:136] = FREE
    return m


def test_a_merge_trims_a_unit_by_a_wall_band_without_asking_for_a_wall_line():
    """The corridor in two pieces, the right one a row lower, so the pair's box reaches a row
    into the room's top band: trimming the room by that row only sets the two bands on one line,
    and the merge needs no wall line there (synthetic floor 4's corridor stayed in two pieces,
    its door into a room leaving less than half the wall a line; docs/quality.md). A box that
    would trim the room deeper still needs the line."""
    from semmap_pp.sampler import ascent

    post, data = knowledge_free(corridor_over_room())
    room = (58, 98, 122, 162)
    for lower, merged in ((1, True), (4, False)):
        start = wm.add(wm.add(wm.add(wm.empty(8), 0, (38, 2, 60, 100)),
                              1, (38 + lower, 98, 60 + lower, 202)), 2, room)
        asc = ascent._Ascent(post, start, data, trim_line_min=1.01)   # no line is ever enough
        box = (38, 2, 60 + lower, 202)
        trimmed, cut = asc.cut_back(wm.replace(wm.remove(start, 1), 0, box), 0, box)
        assert cut == [2] and asc.trimmed_by(trimmed, 2) == lower      # rows taken off its top
        assert asc.merges() == merged
        n = wm.n_units(asc.world)
        assert n == (2 if merged else 3)
        if merged:
            assert asc.tr.logp > post.evaluate(start).total
            assert abs(asc.tr.logp - post.evaluate(asc.world).total) < 1e-6 * abs(asc.tr.logp)


def room_and_alcove_room() -> np.ndarray:
    """A tall room (rows 2..92, columns 62..122) and a shorter room beside its lower part (rows
    22..92, columns 2..60), 2-cell walls, a 0.8 m door between them."""
    m = np.full((96, 126), UNKNOWN, np.uint8)
    m[0:94, 60:124] = OCCUPIED
    m[20:94, 0:62] = OCCUPIED
    m[2:92, 62:122] = FREE
    m[22:92, 2:60] = FREE
    m[60:76, 60:62] = FREE
    return m


def test_an_l_shaped_pair_is_cut_the_other_way_along_a_wall_when_that_raises_log_p(monkeypatch):
    """The two rooms split the wrong way round (the tall room's top as one unit; the short room
    and the tall room's bottom as the other, the wall between them inside it): the recut makes
    the tall room one unit and the short room the other; from there no recut helps, and a recut
    whose new cut crosses open floor is not tried."""
    from semmap_pp.sampler import ascent

    post, data = knowledge_free(room_and_alcove_room())
    wrong = wm.add(wm.add(wm.empty(8), 0, (0, 60, 22, 124)), 1, (20, 0, 94, 124))
    asc = ascent._Ascent(post, wrong, data)
    assert asc.recuts()
    rects = sorted(tuple(int(v) for v in asc.world.rects[s]) for s in wm.active_slots(asc.world))
    assert rects == [(0, 60, 94, 124), (20, 0, 94, 62)]
    assert asc.tr.logp > post.evaluate(wrong).total
    assert abs(asc.tr.logp - post.evaluate(asc.world).total) < 1e-6 * abs(asc.tr.logp)
    assert not ascent._Ascent(post, asc.world, data).recuts()           # the right cut is kept
    polished = refine_world(post, wrong, data, rounds=1, recuts=True)   # W*'s polish takes it too
    assert sorted(tuple(int(v) for v in polished.rects[s]) for s in wm.active_slots(polished)) == rects
    # the same pair with no wall along the other cut (the wall between the rooms taken away: an
    # opening of 3.5 m, wider than a door)
    m = room_and_alcove_room()
    m[22:92, 60:62] = FREE
    open_post, open_data = knowledge_free(m)
    tried = []
    monkeypatch.setattr(ascent._Ascent, "tentative", lambda self, new, changed, polish: tried.append(1))
    ascent._Ascent(open_post, wrong, open_data).recuts()
    assert tried == []


def test_door_candidates_are_gaps_in_wall_lines_not_corridor_rows():
    m = np.full((30, 40), FREE, np.uint8)
    m[:, 5] = m[:, 16] = OCCUPIED     # a corridor 10 cells wide between two walls (columns 6..15)
    m[20, 16:] = OCCUPIED             # a wall along row 20 right of the corridor ...
    m[20, 26:31] = FREE               # ... with a 5-cell gap in it
    data = build_data(m, min_side=4, wall_cells=1, door_min=3, door_max=12)
    doors = {tuple(int(v) for v in d) for d in data.door_candidates}
    assert (0, 20, 26, 31) in doors                         # axis 0 = along a row: row 20, cols 26..30
    assert not any(d[0] == 0 and d[2] == 6 and d[3] == 16 for d in doors)  # no corridor row is a door


def corridor_and_room() -> np.ndarray:
    """A 1 m x 14.8 m corridor (0.05 m cells) and a room below its middle; the wall between them
    has three doors, so its pieces are shorter than ``object_max_extent`` (objects, not walls)."""
    m = np.full((130, 300), UNKNOWN, np.uint8)
    m[38:62, 0:300] = OCCUPIED
    m[40:60, 2:298] = FREE
    m[60:124, 98:202] = OCCUPIED
    m[62:122, 100:200] = FREE
    for c0 in (112, 150, 176):
        m[60:62, c0:c0 + 14] = FREE
    return m


def test_bridges_join_a_corridor_across_the_unit_that_spans_it_and_a_room():
    """Two corridor pieces and one unit over the rest of the corridor and the room: no removal,
    wall move, merge or split raises log p, but joining the pieces across that unit (cut back to
    the room) does."""
    from semmap_pp.sampler.ascent import _Ascent

    model = load_model()
    grid = OccupancyGrid(corridor_and_room(), np.zeros((130, 300), np.float32), 0.05)
    frame = build_frame(grid, model)
    assert frame.theta == 0.0
    post = Posterior(frame, model, None)
    start = wm.add(wm.add(wm.add(wm.empty(8), 0, (38, 0, 62, 100)), 1, (38, 200, 62, 300)),
                   2, (38, 98, 124, 202))
    asc = _Ascent(post, start, data_from_frame(frame))
    before = asc.tr.logp
    assert not asc.removals() and not asc.merges() and not asc.splits()
    assert not any(asc.wall_moves(s) for s in wm.active_slots(asc.world).tolist())
    assert asc.tr.logp == before
    assert asc.bridges()
    rects = sorted(tuple(int(v) for v in asc.world.rects[s]) for s in wm.active_slots(asc.world))
    assert rects == [(38, 0, 62, 300), (60, 98, 124, 202)]
    assert asc.tr.logp > before + 100
    assert abs(asc.tr.logp - post.evaluate(asc.world).total) < 1e-6      # the tracker agrees


def corridor_and_two_rooms(crossing_wall: bool) -> np.ndarray:
    """A 1 m x 30 m corridor (0.05 m cells) and two 5 m rooms below its middle, each with three
    doors to it (wall pieces shorter than ``object_max_extent``); with ``crossing_wall`` the wall
    between the rooms runs on across the corridor."""
    m = np.full((130, 600), UNKNOWN, np.uint8)
    m[38:62, 0:600] = OCCUPIED
    m[40:60, 2:598] = FREE
    m[60:124, 198:402] = OCCUPIED
    m[62:122, 200:299] = FREE
    m[62:122, 301:400] = FREE
    for c0 in (212, 250, 276, 312, 350, 376):
        m[60:62, c0:c0 + 14] = FREE
    if crossing_wall:
        m[40:60, 299:301] = OCCUPIED
    return m


def _two_rooms_ascent(crossing_wall: bool):
    from semmap_pp.sampler.ascent import _Ascent

    model = load_model()
    m = corridor_and_two_rooms(crossing_wall)
    frame = build_frame(OccupancyGrid(m, np.zeros(m.shape, np.float32), 0.05), model)
    assert frame.theta == 0.0
    post = Posterior(frame, model, None)
    start = wm.empty(8)
    for s, r in enumerate([(38, 0, 62, 200), (38, 400, 62, 600), (38, 198, 124, 301),
                           (38, 299, 124, 402)]):
        start = wm.add(start, s, r)
    return post, _Ascent(post, start, data_from_frame(frame))


def test_bridges_span_two_rooms_wide_gaps_but_not_a_wall_across_the_corridor():
    """The corridor's pieces are 10 m apart (two units over corridor + room between them): joined.
    With a wall across the corridor in the gap, two corridors meet at a wall: not joined."""
    post, asc = _two_rooms_ascent(crossing_wall=False)
    before = asc.tr.logp
    assert asc.bridges()
    rects = sorted(tuple(int(v) for v in asc.world.rects[s]) for s in wm.active_slots(asc.world))
    assert rects[0] == (38, 0, 62, 600)
    assert [r[0] for r in rects[1:]] == [60, 60] and len(rects) == 3   # rooms cut back below it
    assert asc.tr.logp > before + 100
    assert abs(asc.tr.logp - post.evaluate(asc.world).total) < 1e-6

    post, asc = _two_rooms_ascent(crossing_wall=True)
    a, b = [int(v) for v in asc.world.rects[0]], [int(v) for v in asc.world.rects[1]]
    assert asc.crossing_line(1, a, b) >= asc.merge_line_max
    before = asc.tr.logp
    assert not asc.bridges()
    assert asc.tr.logp == before


def test_ascent_floors_skip_inferences_and_change_nothing(monkeypatch):
    """With knowledge on, the ascent tries a move's candidates in the order of their type-free
    bounds and passes the best log p so far to the tracker as a floor, so candidates whose bound is
    below it skip the knowledge engine; the moves taken, the world and its log p are those of the
    ascent without floors, which evaluates every candidate."""
    from pathlib import Path

    from semmap_pp.sampler.ascent import _Ascent
    from semmap_pp.knowledge import load_rules
    from semmap_pp.run.target_factory import TargetFactory
    from semmap_pp.target.posterior import Tracker

    model = load_model()
    m = corridor_and_two_rooms(crossing_wall=False)
    frame = build_frame(OccupancyGrid(m, np.zeros(m.shape, np.float32), 0.05), model)
    rules = load_rules(Path(__file__).resolve().parents[2] / "rules" / "table3.lp")
    start = wm.empty(8)
    for s, r in enumerate([(36, 0, 60, 205), (39, 393, 64, 600), (35, 196, 120, 304),
                           (40, 297, 126, 398)]):     # walls off their lines: moves to take
        start = wm.add(start, s, r)

    evaluated = []
    propose = Tracker.propose

    def counting(self, new_world, changed_slots, floor=None, bound=None):
        out = propose(self, new_world, changed_slots, floor, bound)
        evaluated[-1] += not out.bounded
        return out

    monkeypatch.setattr(Tracker, "propose", counting)

    def ascend():
        evaluated.append(0)
        post = TargetFactory(frame, model, rules)()
        post.knowledge_on = True
        asc = _Ascent(post, start, data_from_frame(frame))
        for s in wm.active_slots(asc.world).tolist():
            asc.wall_moves(s)
        asc.bridges()
        return asc

    with_floors = ascend()
    monkeypatch.setattr(Tracker, "supports_floor", False)
    without = ascend()
    assert sum(without.tr.skipped) == 0
    assert evaluated[0] < 0.5 * evaluated[1]
    assert not np.array_equal(with_floors.world.rects, start.rects)      # moves were taken
    assert np.array_equal(with_floors.world.active, without.world.active)
    assert np.array_equal(with_floors.world.rects, without.world.rects)
    assert with_floors.tr.logp == without.tr.logp


def l_of_walls(T=50, V=80, H=40, O=45) -> np.ndarray:
    """One space whose lower-left room is closed off by an L of walls (a horizontal wall ``H``
    cells long under ``T`` rows of open floor, then a vertical one ``V`` cells long with a 0.8 m
    door); right of the L an ``O``-cell strip stays open to the space above (floor 10's corner)."""
    rows, cols = 4 + T + 2 + V + 2, 4 + H + 2 + O + 2
    m = np.full((rows + 2, cols + 2), UNKNOWN, np.uint8)
    m[2:rows, 2:cols] = OCCUPIED
    m[4:rows - 2, 4:cols - 2] = FREE
    hw, vw = 4 + T, 4 + H
    m[hw:hw + 2, 4:vw + 2] = OCCUPIED
    m[hw:rows - 2, vw:vw + 2] = OCCUPIED
    door = hw + 2 + V // 2 - 8
    m[door:door + 16, vw:vw + 2] = FREE
    return m


def test_a_room_in_an_l_of_walls_is_cut_out_by_two_cuts_when_no_single_cut_helps():
    from semmap_pp.sampler.ascent import _Ascent

    m = l_of_walls()
    model = load_model()
    frame = build_frame(OccupancyGrid(m, np.zeros(m.shape, np.float32), 0.05), model)
    post = Posterior(frame, model, None)
    start = wm.add(wm.empty(8), 0, (2, 2, m.shape[0] - 2, m.shape[1] - 2))
    asc = _Ascent(post, start, data_from_frame(frame))
    before = asc.tr.logp
    singles = [wm.add(wm.replace(start, 0, a), 1, b) for a, b in asc.cuts(start.rects[0])]
    assert singles and max(post.evaluate(w).total for w in singles) < before   # no cut alone helps
    assert asc.splits()
    rects = sorted(tuple(int(v) for v in asc.world.rects[s]) for s in wm.active_slots(asc.world))
    assert len(rects) == 3 and (54, 2, 138, 46) in rects      # the room inside the L, on its walls
    assert asc.tr.logp > before + 100
    assert abs(asc.tr.logp - post.evaluate(asc.world).total) < 1e-6


def row_of_rooms(n: int) -> np.ndarray:
    """``n`` 3 m x 2.5 m rooms in a row (0.05 m cells, 2-cell walls), a 0.8 m door near the top
    of each shared wall."""
    w = 52
    m = np.full((66, 2 + n * w + 4), UNKNOWN, np.uint8)
    m[2:64, 2:2 + n * w + 2] = OCCUPIED
    for i in range(n):
        c0 = 4 + i * w
        m[4:62, c0:c0 + w - 2] = FREE
        if i:
            m[8:24, c0 - 2:c0] = FREE
    return m


def test_the_ascent_grows_a_full_world_to_split_every_room():
    """A world of 2 slots over a row of 6 rooms: each split needs an empty slot, so the ascent
    doubles the capacity (2 -> 4 -> 8) and cuts every room out, its log p tracked exactly."""
    m = row_of_rooms(6)
    post, data = knowledge_free(m)
    start = wm.add(wm.empty(2), 0, (2, 2, 64, m.shape[1] - 2))
    out = refine_world(post, start, data, rounds=6)
    assert out.capacity == 8 and wm.n_units(out) == 6
    widths = sorted(int(out.rects[s][3] - out.rects[s][1]) for s in wm.active_slots(out))
    assert widths == [54] * 6                                  # each room on its own walls
    assert post.evaluate(out).total > post.evaluate(wm.grow(start, 8)).total + 500


def test_start_worlds_have_room_for_a_building_larger_than_k_max():
    """k_max = 4 and 6 rooms: the greedy cover fills its 4 slots, the start ascent doubles the
    capacity to add and cut what is left: the start world is the six rooms (with k_max = 64 the
    capacity stays 64)."""
    import dataclasses

    from semmap_pp.evaluate import default_roi
    from semmap_pp.run.inputs import Inputs
    from semmap_pp.run.pipeline import start_worlds

    m = row_of_rooms(6)
    grid = OccupancyGrid(m, np.zeros(m.shape, np.float32), 0.05)
    found = {}
    for k_max, capacity in ((4, 8), (64, 64)):
        model = load_model()
        model = dataclasses.replace(model, prior=dataclasses.replace(model.prior, k_max=k_max))
        inputs = Inputs(grid, model, None, build_frame(grid, model), default_roi(m, 20), "default")
        worlds = start_worlds(inputs, 2, np.random.default_rng(0))
        assert [w.capacity for w in worlds] == [capacity, capacity]
        found[k_max] = sorted(tuple(int(v) for v in worlds[0].rects[s]) for s in wm.active_slots(worlds[0]))
    assert found[4] == [(2, 2 + 52 * i, 64, 56 + 52 * i) for i in range(6)]
    assert len(found[64]) >= 6


def test_the_ascents_validity_test_equals_its_definition():
    """``_Ascent.valid``'s test (the prior's compiled ``all_valid``) against ``world.is_valid``
    plus the longest side, on random worlds (rectangles past the lattice, inverted, too small,
    too long, inactive)."""
    from semmap_pp.target.prior import all_valid
    rng = np.random.default_rng(0)
    seen = set()
    for _ in range(3000):
        k = int(rng.integers(1, 8))
        lo, hi = int(rng.integers(1, 6)), int(rng.integers(5, 40))
        r0, c0 = rng.integers(-3, 50, k), rng.integers(-3, 60, k)
        rects = np.stack([r0, c0, r0 + rng.integers(-2, 45, k), c0 + rng.integers(-2, 45, k)], 1)
        world = wm.make(rects, rng.random(k) < 0.7, np.full(k, wm.NO_TYPE))
        r = world.rects[world.active]
        want = wm.is_valid(world, (50, 60), lo) and bool(np.all(r[:, 2:] - r[:, :2] <= hi))
        assert all_valid(world.rects, world.active, (50, 60), lo, hi) == want
        seen.add(want)
    assert seen == {True, False}


def test_the_fragments_a_grown_unit_swallows_equal_their_definition():
    """``_Ascent.absorb``'s compiled selection against its definition (the thin units other than
    the grown one with at least ``share`` of their area inside it) on random worlds."""
    from semmap_pp.sampler.ascent_walls import _swallowed
    rng = np.random.default_rng(1)
    found = 0
    for _ in range(3000):
        k = int(rng.integers(1, 10))
        r0, c0 = rng.integers(0, 40, k), rng.integers(0, 40, k)
        rects = np.stack([r0, c0, r0 + rng.integers(1, 30, k), c0 + rng.integers(1, 30, k)], 1)
        world = wm.make(rects, rng.random(k) < 0.8, np.full(k, wm.NO_TYPE))
        slot, min_side = int(rng.integers(0, k)), int(rng.integers(1, 8))
        r, o = world.rects[slot], world.rects
        inter = (np.clip(np.minimum(o[:, 2], r[2]) - np.maximum(o[:, 0], r[0]), 0, None)
                 * np.clip(np.minimum(o[:, 3], r[3]) - np.maximum(o[:, 1], r[1]), 0, None))
        area = (o[:, 2] - o[:, 0]) * (o[:, 3] - o[:, 1])
        thin = np.minimum(o[:, 2] - o[:, 0], o[:, 3] - o[:, 1]) < 2 * min_side
        want = world.active & (np.arange(k) != slot) & thin & (inter >= 0.8 * area)
        got = _swallowed(world.rects, world.active, slot, 2 * min_side, 0.8)
        assert np.array_equal(got, want)
        found += int(want.any())
    assert found > 100


def test_a_wall_off_its_line_moves_with_both_its_edges():
    """Both rooms' edges on the shared wall 8 cells right of it: each edge alone cannot move (it
    opens a gap of free space or runs into the other room), the wall moved as a whole can, and
    W*'s polish (``shared_walls=True``) takes it."""
    from semmap_pp.sampler import ascent

    post, data = knowledge_free(two_rooms())
    right = [(2, 2, 82, 72), (2, 70, 82, 142)]
    wrong = wm.add(wm.add(wm.empty(8), 0, (2, 2, 82, 80)), 1, (2, 78, 82, 142))
    rects = lambda w: sorted(tuple(int(v) for v in w.rects[s]) for s in wm.active_slots(w))  # noqa: E731
    stuck = ascent._Ascent(post, wrong, data)
    assert not stuck.all_wall_moves()                        # one edge at a time: stuck
    asc = ascent._Ascent(post, wrong, data)
    assert sorted(asc.wall_group(0, 3)) == [(0, 3), (1, 1)]  # the two edges on the shared wall
    assert sorted(asc.wall_group(0, 0)) == [(0, 0), (1, 0)]  # the two top edges, collinear
    assert asc.shared_wall_moves()
    assert rects(asc.world) == right
    assert abs(asc.tr.logp - post.evaluate(asc.world).total) < 1e-6 * abs(asc.tr.logp)
    assert not ascent._Ascent(post, asc.world, data).shared_wall_moves()   # a local maximum
    assert rects(refine_world(post, wrong, data, rounds=1, recuts=True, shared_walls=True)) == right


def test_a_birth_that_does_not_pay_leaves_the_world_as_it_was(monkeypatch):
    """A tentative birth is polished by wall moves, which may swallow units; when the whole does
    not raise log p the world before the birth comes back, swallowed units included (the undo
    used to remove the new unit only, so a failed birth could lower log p)."""
    from semmap_pp.sampler import ascent

    post, data = knowledge_free(two_rooms())
    start = wm.add(wm.add(wm.empty(8), 0, (2, 2, 82, 72)), 1, (2, 70, 82, 142))
    asc = ascent._Ascent(post, start, data)
    asc.data = data._replace(birth_rects=np.array([[10, 20, 40, 50]]))   # a box inside room 0
    before = asc.tr.logp
    born = []

    def swallow_right_room(self, slot):      # the polish of the new unit drops the right room
        born.append(slot)
        self.tr.accept(self.tr.propose(wm.remove(self.world, 1), (1,)))
        return True

    monkeypatch.setattr(ascent._Ascent, "wall_moves", swallow_right_room)
    assert not asc.births(covered_frac=1.0)  # every box counts as uncovered
    assert born == [2]                       # the box was born in the first free slot
    assert asc.tr.logp == before
    assert sorted(tuple(int(v) for v in asc.world.rects[s]) for s in wm.active_slots(asc.world)) \
        == [(2, 2, 82, 72), (2, 70, 82, 142)]
    assert abs(asc.tr.logp - post.evaluate(asc.world).total) < 1e-6 * abs(before)


def test_a_focused_pass_visits_the_focus_only():
    """Wall moves ``within`` a set of slots visit only those units; ``near`` adds the units
    within two wall bands."""
    from semmap_pp.sampler import ascent

    post, data = knowledge_free(two_rooms())
    off = wm.add(wm.add(wm.empty(8), 0, (2, 5, 82, 72)), 1, (2, 70, 82, 139))   # outer walls 3 cells in
    asc = ascent._Ascent(post, off, data)
    assert asc.near({0}) == {0, 1} and asc.near({1}) == {0, 1}
    apart = wm.add(wm.add(wm.empty(8), 0, (2, 2, 82, 40)), 1, (2, 100, 82, 142))
    far = ascent._Ascent(post, apart, data)
    assert far.near({0}) == {0}
    assert asc.units({1}) == [1]
    assert asc.all_wall_moves({1})
    assert tuple(int(v) for v in asc.world.rects[0]) == (2, 5, 82, 72)       # not visited
    assert tuple(int(v) for v in asc.world.rects[1]) == (2, 70, 82, 142)     # onto its wall
    assert asc.units() == [0, 1] and asc.all_wall_moves()
    assert tuple(int(v) for v in asc.world.rects[0]) == (2, 2, 82, 72)


def test_a_wall_move_reaches_as_many_walls_on_a_finer_map():
    """At 0.025 m a thick wall is drawn as two lines of cells, each line a plateau of the line
    evidence as wide as the wall band (4 cells), so a wall fills 8 of the peaks: the 8 peaks of
    0.05 m reach 1 wall of the row, the 16 of ``ascent_peaks(8, 0.025)`` reach 2 (CHANGELOG.md, quality
    change 30)."""
    from semmap_pp.sampler.ascent import _Ascent, ascent_peaks
    from semmap_pp.lattice.frame import build_frame_from_classes

    model = load_model()
    m = np.full((60, 760), FREE, np.uint8)
    walls = [60 + 80 * k for k in range(8)]
    for x in walls:
        m[:, x] = m[:, x + 5] = OCCUPIED        # a 0.15 m wall: two lines, its core unknown
        m[:, x + 1:x + 5] = UNKNOWN
    frame = build_frame_from_classes(m, 0.025, model)
    post, data = Posterior(frame, model, None), data_from_frame(frame)
    world = wm.add(wm.empty(4), 0, (0, 0, 60, 50))

    def walls_reached(asc) -> int:
        cand = asc.positions([0, 0, 60, 50], 3)     # the unit's right wall
        return sum(any(x + 1 <= c <= x + 9 for c in cand) for x in walls)

    fine = _Ascent(post, world, data)
    assert ascent_peaks(8, 0.025) == fine.peaks == 16 and ascent_peaks(8, 0.05) == 8
    assert walls_reached(fine) == 2
    assert walls_reached(_Ascent(post, world, data, peaks=8)) == 1


def test_after_whole_walls_moved_the_joining_moves_run_again(monkeypatch):
    """W*'s polish alternates its phases: once whole walls have moved, the moves that join units
    (merges among them) run again, since a moved wall may open a merge, but no split; when no
    whole wall moves, one pass is all. From a local maximum, with the whole-wall phase made to
    report a move once: two passes of the merges instead of one, one of the splits."""
    from semmap_pp.sampler import ascent

    post, data = knowledge_free(two_rooms())
    wrong = wm.add(wm.add(wm.empty(8), 0, (2, 2, 82, 80)), 1, (2, 78, 82, 142))
    polished = refine_world(post, wrong, data, rounds=2, recuts=True, shared_walls=True)
    calls, cuts = [], []
    merges, splits = ascent._Ascent.merges, ascent._Ascent.splits
    monkeypatch.setattr(ascent._Ascent, "merges", lambda self: calls.append(1) or merges(self))
    monkeypatch.setattr(ascent._Ascent, "splits", lambda self, *a: cuts.append(1) or splits(self, *a))
    refine_world(post, polished, data, rounds=2, recuts=True, shared_walls=True)
    assert len(calls) == len(cuts) == 1          # a local maximum: nothing moves, one pass
    reported = []
    shared = ascent._Ascent.shared_wall_moves

    def once(self):
        moved = shared(self)
        if not reported:
            reported.append(1)
            return moved | {0}
        return moved
    monkeypatch.setattr(ascent._Ascent, "shared_wall_moves", once)
    calls.clear()
    cuts.clear()
    out = refine_world(post, polished, data, rounds=2, recuts=True, shared_walls=True)
    assert len(calls) == 2          # the merges again after the (reported) wall move ...
    assert len(cuts) == 1           # ... but not the splits
    assert post.evaluate(out).total >= post.evaluate(polished).total - 1e-6


def test_w_stars_polish_leaves_the_double_cuts_to_the_start_ascent():
    """The room inside an L of walls needs two cuts at once: the start ascent (refine_world, as
    the pipeline's knowledge-free start runs it) makes them, W*'s polish does not try them
    (ascent.polish; CHANGELOG.md, quality change 35) and keeps what single moves give."""
    from semmap_pp.sampler.ascent import polish

    m = l_of_walls()
    model = load_model()
    frame = build_frame(OccupancyGrid(m, np.zeros(m.shape, np.float32), 0.05), model)
    post, data = Posterior(frame, model, None), data_from_frame(frame)
    start = wm.add(wm.empty(8), 0, (2, 2, m.shape[0] - 2, m.shape[1] - 2))

    def rects(w):
        return sorted(tuple(int(v) for v in w.rects[s]) for s in wm.active_slots(w))

    assert (54, 2, 138, 46) in rects(refine_world(post, start, data, rounds=1))
    polished = polish(post, start, data, rounds=1)
    assert (54, 2, 138, 46) not in rects(polished)
    assert post.evaluate(polished).total >= post.evaluate(start).total


def test_w_stars_polish_leaves_the_births_to_the_start_ascent(monkeypatch):
    """The start ascent (refine_world) tries births, the boxes of the birth table over free space
    no unit covers; W*'s polish does not (ascent.polish; CHANGELOG.md, quality change 36)."""
    from semmap_pp.sampler import ascent

    post, data = knowledge_free(two_rooms())
    left_only = wm.add(wm.empty(8), 0, (2, 2, 82, 72))      # the left room on its walls
    tried = []
    births = ascent._Ascent.births
    monkeypatch.setattr(ascent._Ascent, "births",
                        lambda self, *a, **k: tried.append(1) or births(self, *a, **k))
    refine_world(post, left_only, data, rounds=1)
    assert tried
    tried.clear()
    polished = ascent.polish(post, left_only, data, rounds=1)
    assert not tried
    assert post.evaluate(polished).total >= post.evaluate(left_only).total


def room_over_corridor(width: int = 100) -> np.ndarray:
    """A room (rows 10..90) over a corridor (rows 92..124), ``width`` cells wide, the 2-cell wall
    between them with two doors, and a cupboard 30 cells wide and 12 deep against the wall's room
    side in the middle: its gaps to the side walls are of door width, so every line across the
    cupboard and the wall is wall or door cells over the whole span (a plateau of line evidence)."""
    m = np.full((140, width + 20), OCCUPIED, np.uint8)
    m[10:90, 10:10 + width] = FREE
    m[92:124, 10:10 + width] = FREE
    m[90:92, 16:32] = FREE
    m[90:92, width - 12:width + 4] = FREE
    c0 = 10 + (width - 30) // 2
    m[78:90, c0:c0 + 30] = OCCUPIED
    return m


def test_w_stars_polish_cuts_all_along_a_plateau_of_line_evidence():
    """One unit over a room and the corridor below it, their wall behind a cupboard: the three
    strongest line peaks are neighbouring lines at the cupboard's top, where no cut helps, so the
    narrow cuts leave the unit whole; W*'s polish tries every line of the plateau and a few past
    it (ascent_cuts._wall_runs) and cuts the unit at the wall (lab_d_furnitures' room over its
    corridor)."""
    from semmap_pp.sampler.ascent import _Ascent, polish

    post, data = knowledge_free(room_over_corridor())
    start = wm.add(wm.empty(8), 0, (8, 8, 126, 112))
    before = post.evaluate(start).total
    narrow = [a[2] for a, b in _Ascent(post, start, data).cuts(start.rects[0]) if a[3] == 112]
    assert narrow == [80, 81, 82]                  # three lines of one plateau, the cupboard's top
    assert wm.n_units(refine_world(post, start, data, rounds=1, births=False,
                                   double_cuts=False)) == 1
    out = polish(post, start, data, rounds=1)
    rects = sorted(tuple(int(v) for v in out.rects[s]) for s in wm.active_slots(out))
    assert len(rects) == 2
    assert abs(rects[0][2] - 92) <= 2 and abs(rects[1][0] - 90) <= 2   # cut at the wall (rows 90..92)
    assert post.evaluate(out).total > before + 100



def offices_with_a_deeper_one() -> np.ndarray:
    """Three offices over a corridor, 2-cell walls, a door each: the outer two 150 cells wide
    (rows 10..70), the middle one 80 wide and deeper (rows 10..84, its wall to the corridor at
    rows 84..86), so the corridor's wall jogs down under it and back up."""
    m = np.full((154, 406), OCCUPIED, np.uint8)
    m[10:70, 10:160] = FREE
    m[10:84, 162:242] = FREE                    # the deeper office
    m[10:70, 244:394] = FREE
    m[72:134, 10:160] = FREE                    # the corridor under the first office ...
    m[86:134, 160:244] = FREE                   # ... under the deeper one ...
    m[72:134, 244:394] = FREE                   # ... and under the third
    m[70:72, 30:46] = FREE                      # the doors
    m[84:86, 202:218] = FREE
    m[70:72, 264:280] = FREE
    return m


def test_w_stars_polish_cuts_a_corridor_where_its_wall_jogs_and_moves_the_wall_with_the_office():
    """The corridor as one rectangle reaches into the deeper office, whose unit stops at the
    other offices' line: the office's wall lies inside the corridor, and their border, on open
    floor, reads as a passage. No single move mends it, nor does moving the whole wall; a jog
    (ascent_cuts.jogs) cuts the corridor's piece under the office off and moves its wall and
    the office's together."""
    from semmap_pp.sampler.ascent import polish

    post, data = knowledge_free(offices_with_a_deeper_one())
    start = wm.empty(12)
    for slot, rect in enumerate([(8, 8, 72, 162), (8, 160, 72, 244), (8, 242, 72, 396),
                                 (70, 8, 136, 396)]):
        start = wm.add(start, slot, rect)

    def rects(world):
        return sorted(tuple(int(v) for v in world.rects[s]) for s in wm.active_slots(world))

    kept = refine_world(post, start, data, rounds=2, recuts=True, shared_walls=True,
                        double_cuts=False, births=False, wide_cuts=True, jogs=False)
    assert rects(kept) == rects(start)                  # nothing else moves the office's wall
    out = polish(post, start, data, rounds=2)
    assert rects(out) == [(8, 8, 72, 162), (8, 160, 86, 244), (8, 242, 72, 396),
                          (70, 8, 136, 162), (70, 242, 136, 396), (84, 160, 136, 244)]
    assert post.evaluate(out).total > post.evaluate(start).total + 100


class FakeTracker:
    """A tracker of candidates 0..n-1 with log p ``logps[i]`` and upper bound ``bounds[i]``; with
    ``floors`` it skips (log p -inf) a proposal whose bound lies below its floor, by the real
    tracker's test, and counts the proposals it evaluates in full."""

    def __init__(self, logp, logps, bounds, floors):
        self.logp, self.logps, self.bounds, self.evaluated = logp, logps, bounds, 0
        self.supports_floor = floors

    def upper_bound(self, world, changed):
        return self.bounds[world]

    def propose(self, world, changed, floor=None, bound=None):
        # the bound the ascent hands over is the one it was given
        assert bound is None or bound == self.bounds[world] or np.isnan([bound, self.bounds[world]]).all()
        if floor is not None and below_floor(self.bounds[world], floor):   # the tracker's test
            return SimpleNamespace(logp=-np.inf, bounded=True)
        self.evaluated += 1
        return SimpleNamespace(logp=self.logps[world], bounded=False, world=world)


def test_best_proposal_tried_by_bound_chooses_as_trying_all_in_order():
    """:meth:`Climb.best_proposal` tries candidates by their upper bounds, highest first, and
    stops at the first bound below the best log p so far; on random candidates (ties, bounds
    equal to the log p, infinite and NaN bounds, starts at and around 0, trackers without floors)
    it picks what trying every candidate in list order picks (the first of the best), and it
    evaluates fewer of them."""
    from semmap_pp.sampler.ascent_walls import Climb

    rng = np.random.default_rng(3)
    fewer = 0
    for trial in range(2000):
        n = int(rng.integers(0, 12))
        logps = rng.integers(-6, 4, n).astype(float)      # small integers: many ties
        slack = rng.choice([0.0, 0.5, 3.0, 20.0, np.inf, np.nan], n, p=[.4, .2, .15, .1, .1, .05])
        start = float(rng.choice([-2.0, -0.5, 0.0, 1.0]))
        climb = Climb.__new__(Climb)
        climb.tr = FakeTracker(start, logps, logps + slack, bool(rng.random() < 0.85))
        got = climb.best_proposal([(i, (0,)) for i in range(n)])
        above = np.flatnonzero(logps > start + 1e-9)
        want = None if above.size == 0 else int(above[np.argmax(logps[above])])
        assert (got is None and want is None) or (got is not None and got.world == want), \
            (start, logps, slack)
        fewer += climb.tr.evaluated < n
    assert fewer > 400


def test_best_few_tried_by_bound_chooses_as_scoring_every_candidate():
    """:meth:`Climb.best_few` (the crosses' choice of the ``k`` to try) tries candidates by their
    upper bounds and stops at the first below the ``k``-th best log p so far; on random
    candidates (ties, bounds equal to the log p, infinite and NaN bounds, trackers without
    floors, k from 1 to 4) it returns what scoring all of them gives: the ``k`` of highest log p,
    the earlier first on a tie, and it scores fewer of them in full."""
    from semmap_pp.sampler.ascent_walls import Climb

    rng = np.random.default_rng(5)
    fewer = 0
    for trial in range(2000):
        n, k = int(rng.integers(0, 12)), int(rng.integers(1, 5))
        logps = rng.integers(-6, 4, n).astype(float)      # small integers: many ties
        slack = rng.choice([0.0, 0.5, 3.0, 20.0, np.inf, np.nan], n, p=[.4, .2, .15, .1, .1, .05])
        climb = Climb.__new__(Climb)
        climb.tr = FakeTracker(0.0, logps, logps + slack, bool(rng.random() < 0.85))
        got = climb.best_few([(i, (0,)) for i in range(n)], k)
        want = sorted(range(n), key=lambda i: (-logps[i], i))[:k]
        assert got == want, (k, logps, slack)
        fewer += climb.tr.evaluated < n
    assert fewer > 300


def test_a_tentative_move_that_fails_its_test_is_undone():
    """``tentative(..., keep=test)``: the left room's wall move swallows the strip beside it (log
    p rises); kept as a plain tentative move, undone when the test asks every polished unit to
    remain."""
    from semmap_pp.sampler.ascent import _Ascent

    post, data = knowledge_free(two_rooms())
    start = wm.add(wm.add(wm.empty(8), 0, (2, 2, 82, 50)), 2, (2, 70, 82, 142))
    new = wm.add(start, 1, (4, 50, 80, 70))                 # a strip between the room and its wall
    for keep, kept in ((None, True), (lambda w: bool(w.active[[0, 1]].all()), False)):
        asc = _Ascent(post, start, data)
        before = asc.tr.logp
        assert asc.tentative(new, (1,), (0, 1), keep=keep) is kept
        if kept:
            assert not asc.world.active[1] and asc.tr.logp > before   # swallowed, and a gain
        else:
            assert asc.world.active.tolist() == start.active.tolist()       # as it was
            assert np.array_equal(asc.world.rects[start.active], start.rects[start.active])
            assert abs(asc.tr.logp - before) < 1e-6


def four_rooms() -> np.ndarray:
    """Four 3 m x 3 m rooms in two rows and two columns (0.05 m cells, 2-cell walls meeting in a
    cross), a 0.8 m door in each arm of the cross."""
    m = np.full((130, 130), UNKNOWN, np.uint8)
    m[2:128, 2:128] = OCCUPIED
    for r0 in (4, 66):
        for c0 in (4, 66):
            m[r0:r0 + 60, c0:c0 + 60] = FREE
    m[20:36, 64:66] = FREE          # the doors in the cross's four arms
    m[90:106, 64:66] = FREE
    m[64:66, 20:36] = FREE
    m[64:66, 90:106] = FREE
    return m


def test_a_cross_cuts_a_unit_into_four_pieces_that_share_their_wall_bands():
    """One unit over four rooms whose walls meet in a cross: :meth:`crosses` cuts it along both
    axes at once, each piece on its room's walls and the four sharing the cross's wall bands, and
    tracks log p exactly; with ``[kernels] cross_tries = 0`` it cuts nothing."""
    from semmap_pp.sampler.ascent import _Ascent

    m = four_rooms()
    model = load_model()
    frame = build_frame(OccupancyGrid(m, np.zeros(m.shape, np.float32), 0.05), model)
    post = Posterior(frame, model, None)
    start = wm.add(wm.empty(8), 0, (2, 2, 128, 128))
    off = _Ascent(post, start, data_from_frame(frame, model.kernels._replace(cross_tries=0)))
    assert not off.crosses() and wm.n_units(off.world) == 1
    asc = _Ascent(post, start, data_from_frame(frame, model.kernels))
    before = asc.tr.logp
    assert asc.crosses()
    rects = sorted(tuple(int(v) for v in asc.world.rects[s]) for s in wm.active_slots(asc.world))
    assert rects == [(2, 2, 66, 66), (2, 64, 66, 128), (64, 2, 128, 66), (64, 64, 128, 128)]
    assert asc.tr.logp > before + 100
    assert abs(asc.tr.logp - post.evaluate(asc.world).total) < 1e-6
    # pieces shorter both ways than twice the smallest unit side are no spaces: not cut
    small = _Ascent(post, start, data_from_frame(frame, model.kernels)._replace(min_side=33))
    assert not small.crosses() and wm.n_units(small.world) == 1


def test_a_cross_whose_piece_a_wall_move_absorbs_is_undone():
    """The four rooms' unit cut in four, but the first piece's wall move grows it over its
    neighbour (stood in for here: the top-left piece takes the top-right's place): log p still
    rises above the one unit (the cross's other wall stays a band), yet three pieces are a
    carving, not four spaces, so the cross is undone."""
    from semmap_pp.sampler.ascent import _Ascent

    m = four_rooms()
    model = load_model()
    frame = build_frame(OccupancyGrid(m, np.zeros(m.shape, np.float32), 0.05), model)
    post = Posterior(frame, model, None)
    start = wm.add(wm.empty(8), 0, (2, 2, 128, 128))
    asc = _Ascent(post, start, data_from_frame(frame, model.kernels))
    before, seen = asc.tr.logp, []

    def absorbing(slot):          # the cross's first piece is slot 0, the next one slot 1
        if slot == 0 and asc.world.active[1]:
            top = [int(v) for v in asc.world.rects[0]]
            top[3] = int(asc.world.rects[1][3])
            grown = wm.remove(wm.replace(asc.world, 0, top), 1)
            asc.tr.accept(asc.tr.propose(grown, (0, 1)))
            seen.append(asc.tr.logp)
        return False

    asc.wall_moves = absorbing
    assert not asc.crosses()
    assert seen and max(seen) > before                       # a gain, refused all the same
    assert wm.n_units(asc.world) == 1 and abs(asc.tr.logp - before) < 1e-6


def test_w_stars_polish_cuts_a_unit_over_four_spaces_along_both_axes():
    """A piece of a real floor (map17 of bench/data/real-gt turned by 30 degrees, read onto its
    lattice; tests/data/README.md): a corridor, the clutter beside it and two rooms behind a
    broken wall under one hall-sized unit, as W* had it. Every cut alone makes long strips that
    are typed as corridors, whose clutter the corridor's sensor row makes dear, so single cuts and
    wall moves leave the hall whole; cut along both axes at once, the four pieces wall-moved, the
    rooms and the clutter come apart (log p up by thousands of nats)."""
    from pathlib import Path
    from semmap_pp.run.inputs import load_inputs
    from semmap_pp.run.target_factory import run_target
    from semmap_pp.sampler.ascent import polish

    inputs = load_inputs(Path(__file__).parents[1] / "data" / "map17_turned" / "map17_30deg_crop.yaml")
    post = run_target(inputs)
    hall = wm.add(wm.empty(8), 0, (20, 21, 234, 452))

    def units_over(w, *cells):
        return [s for s in wm.active_slots(w)
                if all(w.rects[s][0] <= r < w.rects[s][2] and w.rects[s][1] <= c < w.rects[s][3]
                       for r, c in cells)]

    kernels = inputs.model.kernels
    whole = polish(post, hall, data_from_frame(inputs.frame, kernels._replace(cross_tries=0)), 3)
    assert units_over(whole, (60, 100), (180, 100), (180, 350))      # still one unit over all three
    cut = polish(post, hall, data_from_frame(inputs.frame, kernels), 3)
    assert post.evaluate(cut).total > post.evaluate(whole).total + 1000
    assert not units_over(cut, (180, 100), (180, 350))               # the two rooms apart
    assert not units_over(cut, (60, 300), (180, 350))                # the clutter and a room apart
    assert not units_over(cut, (60, 100), (180, 100))


def test_tentative_stops_its_wall_moves_once_a_unit_it_needs_is_gone(monkeypatch):
    """:meth:`WallMoves.tentative` with ``alive``: a candidate whose wall moves drop one of those
    units is undone, as without ``alive`` when ``keep`` asks for every one of them; the units
    after the drop are not wall-moved, and the world and log p are the ones before."""
    from semmap_pp.sampler.ascent import _Ascent

    post, asc = _two_rooms_ascent(crossing_wall=False)
    start, before = asc.world, asc.tr.logp
    moved = []

    def wall_moves(self, slot):       # the first wall move swallows unit 3
        moved.append(slot)
        if self.world.active[3]:
            self.tr.accept(self.tr.propose(wm.remove(self.world, 3), (3,)))
        return True

    monkeypatch.setattr(_Ascent, "wall_moves", wall_moves)
    cut = wm.replace(asc.world, 0, (38, 0, 62, 190))
    kept = asc.tentative(cut, (0,), (0, 1, 2), keep=lambda w: bool(w.active[[0, 3]].all()), alive=(0, 3))
    assert not kept and moved == [0]
    assert np.array_equal(asc.world.rects, start.rects) and np.array_equal(asc.world.active, start.active)
    assert asc.tr.logp == before

    moved.clear()
    post, asc = _two_rooms_ascent(crossing_wall=False)     # without alive: every unit wall-moved
    assert not asc.tentative(cut, (0,), (0, 1, 2), keep=lambda w: bool(w.active[[0, 3]].all()))
    assert moved == [0, 1, 2] and asc.tr.logp == before


def test_crosses_are_not_tried_again_on_a_unit_whose_neighbourhood_kept_its_rectangles(monkeypatch):
    """After a call of :meth:`CutMoves.crosses` that kept none, the next call tries only the
    units whose rectangle, or the rectangle of a unit near them, changed since; after a call
    that kept one, every unit again."""
    from semmap_pp.sampler.ascent import _Ascent

    post, asc = _two_rooms_ascent(crossing_wall=False)
    tried, keep = [], set()

    def cross(self, s, tries):
        tried.append(s)
        return s in keep

    monkeypatch.setattr(_Ascent, "_cross", cross)
    asc.tries = {}                          # as W*'s polish keeps them (refine_world's memo)
    assert not asc.crosses() and tried == [0, 1, 2, 3]
    tried.clear()
    assert not asc.crosses() and tried == []
    near = asc.near((1,))
    assert near == {1, 3}                   # the room at the corridor's right end, not the others
    asc.tr.accept(asc.tr.propose(wm.replace(asc.world, 1, (38, 402, 62, 600)), (1,)))
    assert not asc.crosses() and tried == [1, 3]
    tried.clear()
    keep.add(3)
    asc.tr.accept(asc.tr.propose(wm.replace(asc.world, 1, (38, 400, 62, 600)), (1,)))
    assert asc.crosses() and tried == [1, 3]     # (the fake keeps 3 but leaves the world as it is)
    tried.clear()
    keep.clear()
    assert not asc.crosses() and tried == [0, 1, 2, 3]


def test_a_bridge_that_failed_is_tried_again_only_once_the_units_around_it_changed(monkeypatch):
    """With failed tries kept (W*'s polish), a bridge whose try changed nothing is not tried in
    the next call while every unit within two wall bands of its box keeps its rectangle; once one
    moves, or after a call that kept a move, it is tried again. Without them, every call tries it."""
    from semmap_pp.sampler.ascent import _Ascent

    post, asc = _two_rooms_ascent(crossing_wall=False)
    tried, keep = [], [False]

    def tentative(self, new, changed, polish, keep_=None, alive=()):
        tried.append(tuple(changed[:2]))
        return keep[0]

    monkeypatch.setattr(_Ascent, "tentative", tentative)
    assert not asc.bridges() and not asc.bridges() and tried == [(0, 1), (0, 1)]   # not kept
    asc.tries = {}
    tried.clear()
    assert not asc.bridges() and tried == [(0, 1)]
    assert not asc.bridges() and tried == [(0, 1)]                 # the same units around it
    asc.tr.accept(asc.tr.propose(wm.replace(asc.world, 3, (38, 299, 124, 404)), (3,)))
    assert not asc.bridges() and tried == [(0, 1)] * 2             # a room beside it moved
    keep[0] = True
    asc.tr.accept(asc.tr.propose(wm.replace(asc.world, 3, (38, 299, 124, 402)), (3,)))
    assert asc.bridges() and tried == [(0, 1)] * 3                 # (kept: the fake leaves the world)
    keep[0] = False
    assert not asc.bridges() and tried == [(0, 1)] * 4             # after a call that kept one


class _Tally:
    """A stand-in for an ascent's state for :meth:`Climb.each`: a list of the items taken; an
    item is taken when ``rule(taken, item)`` holds (a deterministic test of the state)."""

    def __init__(self, rule):
        self.taken, self.rule = [], rule

    def attempt(self, x) -> bool:
        if self.rule(self.taken, x):
            self.taken.append(x)
            return True
        return False


@pytest.mark.parametrize("forks", ["fork", "no process"])
def test_each_with_a_forked_half_takes_what_trying_in_turn_takes(forks, monkeypatch):
    """:meth:`Climb.each` with ``fork``: on random rules (none, one, several or every item
    taken, each decision depending on the items taken before), the items taken, their order and
    the answer are those of trying every item in turn here; also when no process can be forked
    (the forked half's answer is then made here)."""
    import semmap_pp.forked
    from semmap_pp.sampler import ascent_walls
    from semmap_pp.sampler.ascent_walls import Climb

    if forks == "no process":
        monkeypatch.setattr(semmap_pp.forked, "_one_thread", lambda: False)
    started = []
    start = semmap_pp.forked.Forked._start
    monkeypatch.setattr(semmap_pp.forked.Forked, "_start", lambda self: started.append(1) or start(self))
    rng = np.random.default_rng(5)
    for trial in range(40 if forks == "fork" else 200):
        n = int(rng.integers(0, 3 * ascent_walls.FORK_MIN_ITEMS))
        p = float(rng.choice([0.0, 0.05, 0.3, 1.0]))
        salt = int(rng.integers(1 << 30))

        def rule(taken, x, p=p, salt=salt):     # deterministic in (the state, the item)
            return np.random.default_rng([salt, len(taken), sum(taken), x]).random() < p

        results = []
        for fork in (False, True):
            state = _Tally(rule)
            climb = object.__new__(Climb)
            climb.fork = fork
            results.append((climb.each(range(n), state.attempt), state.taken))
        assert results[0] == results[1], (trial, n, p)
    assert (len(started) > 20) if forks == "fork" else not started
