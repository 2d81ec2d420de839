"""Posterior marginals of W*'s units and doors over sampled worlds (semmap_pp.sampler.marginals)
and their place in world.json (semantic.world_json.with_posterior): counts checked against
hand-made lists of sampled worlds whose answers are known."""

from types import SimpleNamespace as NS

import numpy as np
import pytest

from semmap_pp import world as wm
from semmap_pp.cells import UNIT_TYPES
from semmap_pp.derive.doors import Door
from semmap_pp.sampler.marginals import (MATCH_IOU, best_match, door_marginals, iou, unit_marginals,
                                         world_doors)
from semmap_pp.semantic.world_json import with_posterior

ROOM, CORRIDOR, HALL, OTHER = (UNIT_TYPES.index(t) for t in ("room", "corridor", "hall", "other"))


def world(*units, k=6):
    """A world of ``(slot, rect, type)`` units."""
    w = wm.empty(k)
    for slot, rect, t in units:
        w = wm.add(w, slot, rect, type_index=t)
    return w


WSTAR = world((0, (0, 0, 10, 10), ROOM), (1, (0, 10, 10, 30), CORRIDOR), (2, (20, 0, 30, 10), HALL))


def test_iou_by_hand():
    assert iou((0, 0, 10, 10), (0, 0, 10, 10)) == 1.0
    assert iou((0, 0, 10, 10), (0, 5, 10, 15)) == pytest.approx(50 / 150)
    assert iou((0, 0, 10, 10), (10, 0, 20, 10)) == 0.0


def test_unit_exists_and_type_counts_over_a_hand_made_sample():
    """Unit 0: matched in worlds a, b, c (types room, room, other), not in d (IoU 0.4): 3/4, types
    2/3 room, 1/3 other. Unit 1: matched in a (corridor) and d (hall; in another slot): 2/4.
    Unit 2: never matched: 0, type None."""
    a = world((0, (0, 0, 10, 10), ROOM), (1, (0, 10, 10, 30), CORRIDOR))
    b = world((3, (0, 0, 10, 9), ROOM))                                   # IoU 0.9
    c = world((5, (0, 0, 10, 10), OTHER))
    d = world((0, (0, 0, 10, 4), ROOM), (4, (0, 12, 10, 30), HALL))      # IoU 0.4; unit 1: 0.9
    m = unit_marginals(WSTAR, [a, b, c, d])
    assert set(m) == {0, 1, 2}
    assert m[0].exists == 0.75 and m[0].n == 4
    assert m[0].types == pytest.approx((2 / 3, 0.0, 0.0, 1 / 3))
    assert m[1].exists == 0.5
    assert m[1].types[CORRIDOR] == 0.5 and m[1].types[HALL] == 0.5
    assert m[2].exists == 0.0 and m[2].types is None


def test_a_repeated_world_counts_once_per_draw():
    same = WSTAR
    other = world((0, (0, 0, 10, 10), OTHER))
    m = unit_marginals(WSTAR, [same, same, same, other])
    assert m[0].exists == 1.0 and m[0].types[ROOM] == 0.75 and m[0].types[OTHER] == 0.25
    assert m[1].exists == 0.75


def test_the_iou_threshold_is_inclusive_and_the_best_match_wins():
    half = (0, 0, 10, 5)                              # IoU exactly 0.5 with (0, 0, 10, 10)
    assert iou((0, 0, 10, 10), half) == MATCH_IOU
    assert best_match((0, 0, 10, 10), world((2, half, ROOM))) == 2
    assert best_match((0, 0, 10, 10), world((2, (0, 0, 10, 4), ROOM))) is None
    # two overlapping candidates: the larger IoU, not the lower slot
    w = world((0, (0, 0, 10, 6), ROOM), (1, (0, 0, 10, 9), HALL))
    assert best_match((0, 0, 10, 10), w) == 1
    assert unit_marginals(world((0, (0, 0, 10, 10), ROOM)), [w])[0].types[HALL] == 1.0


def test_unit_marginals_are_best_match_per_unit_over_random_worlds():
    """The marginals, found for all units at once, equal best_match unit by unit: random
    overlapping worlds with ties, empty worlds and IoU exactly at the threshold among them."""
    rng = np.random.default_rng(3)

    def random_world(k):
        w = wm.empty(8)
        for slot in rng.choice(8, size=k, replace=False):
            r0, c0 = (int(v) for v in rng.integers(0, 12, 2))
            w = wm.add(w, int(slot), (r0, c0, r0 + int(rng.integers(1, 8)), c0 + int(rng.integers(1, 8))),
                       type_index=int(rng.integers(0, len(UNIT_TYPES))))
        return w

    for _ in range(40):
        wstar = random_world(int(rng.integers(1, 7)))
        worlds = [random_world(int(rng.integers(0, 7))) for _ in range(12)] + [wstar]
        got = unit_marginals(wstar, worlds)
        for s in wm.active_slots(wstar):
            matches = [(w, best_match(tuple(int(v) for v in wstar.rects[s]), w)) for w in worlds]
            typed = [int(w.types[m]) for w, m in matches if m is not None]
            assert got[int(s)].exists == sum(m is not None for _, m in matches) / len(worlds)
            want = tuple(typed.count(t) / len(typed) for t in range(len(UNIT_TYPES))) if typed else None
            assert got[int(s)].types == want


def test_door_marginals_count_worlds_with_a_door_at_the_place():
    """Two doors of W*; worlds give their own door lists (doors_of): door 0 is in worlds 1 and 2
    (world 2's a cell off, within the wall band), door 1 in world 3 only; world 4 none."""
    frame = NS(cells=NS(wall=1))
    d0, d1 = Door(0, 1, (9, 3, 11, 7), False, 4), Door(1, 2, (3, 19, 7, 21), True, 4)
    lists = [[Door(0, 1, (9, 3, 11, 7), False, 4)], [Door(3, 1, (11, 3, 12, 7), False, 4)],
             [Door(1, 2, (3, 19, 7, 21), True, 4)], []]
    worlds = [world((0, (0, 0, 10 + i, 10), ROOM)) for i in range(4)]        # four distinct worlds
    by_world = {w.rects.tobytes() + w.active.tobytes(): doors for w, doors in zip(worlds, lists)}
    p = door_marginals(frame, [d0, d1], worlds, doors_of=lambda f, w: by_world[w.rects.tobytes() + w.active.tobytes()])
    assert p == [0.5, 0.25]
    far = [[Door(0, 1, (13, 3, 14, 7), False, 4)]] * 4                       # two cells off: not there
    assert door_marginals(frame, [d0], worlds, doors_of=lambda f, w: far[0]) == [0.0]
    assert door_marginals(frame, [d0], [], doors_of=lambda f, w: []) == [pytest.approx(np.nan, nan_ok=True)]


def test_world_doors_finds_the_door_of_two_rooms():
    """On a real lattice: two rooms sharing a wall with a door gap; W*'s door is there in W* itself
    and not in a world with one room only."""
    from semmap_pp.lattice.frame import build_frame_from_classes
    from semmap_pp.model import load_model

    from semmap_pp.cells import FREE, OCCUPIED, UNKNOWN

    classes = np.full((40, 70), UNKNOWN, np.uint8)
    classes[4:36, 4:66] = OCCUPIED                     # walls (2 cells: 0.1 m at 0.05 m/cell) ...
    classes[6:34, 6:34] = FREE                         # ... around two free rooms
    classes[6:34, 36:64] = FREE
    classes[16:30, 34:36] = FREE                       # a door in the shared wall, 0.7 m wide
    frame = build_frame_from_classes(classes, 0.05, load_model(), theta=0.0)
    w = wm.empty(4)
    w = wm.add(w, 0, (4, 4, 36, 36), type_index=ROOM)
    w = wm.add(w, 1, (4, 34, 36, 66), type_index=ROOM)
    doors = world_doors(frame, w)
    assert len(doors) == 1
    alone = wm.remove(w, 1)
    assert door_marginals(frame, doors, [w, w, alone]) == [pytest.approx(2 / 3)]


def test_world_doors_with_a_pair_cache_equal_those_found_anew():
    """The doors of worlds that share pairs of units, found with one pair cache (as
    door_marginals does), equal those found for each world alone, slots included."""
    from semmap_pp.lattice.frame import build_frame_from_classes
    from semmap_pp.model import load_model

    from semmap_pp.cells import FREE, OCCUPIED, UNKNOWN

    classes = np.full((40, 100), UNKNOWN, np.uint8)
    classes[4:36, 4:96] = OCCUPIED
    for c0 in (6, 36, 66):                             # three rooms in a row ...
        classes[6:34, c0:c0 + 28] = FREE
    classes[16:30, 34:36] = FREE                       # ... a door between the first two
    classes[10:24, 64:66] = FREE                       # ... and one between the last two
    frame = build_frame_from_classes(classes, 0.05, load_model(), theta=0.0)
    rooms = [(4, 4, 36, 36), (4, 34, 36, 66), (4, 64, 36, 96)]
    worlds = []
    for order in ((0, 1, 2), (2, 0, 1), (1, 2, 0)):    # the same pairs in other slots
        w = wm.empty(5)
        for slot, k in enumerate(order):
            w = wm.add(w, slot + 1, rooms[k], type_index=ROOM)
        worlds += [w, wm.remove(w, 2)]
    cache = {}
    for w in worlds:
        assert world_doors(frame, w, cache) == world_doors(frame, w)
    assert len(cache) >= 2 and sum(len(world_doors(frame, w)) for w in worlds) >= 6


def test_world_json_gets_them_on_the_right_unit_and_door_ids():
    """with_posterior puts each slot's marginals on its unit id and each door's on the id
    world.json gave it (doors ordered by their units' ids, then box)."""
    ids = {0: 2, 1: 1, 2: 3}                           # slot -> unit id
    da, db = Door(0, 2, (5, 5, 6, 8), False, 3), Door(0, 1, (0, 9, 3, 10), True, 3)
    sm = NS(slot_ids=ids, slot_of={v: k for k, v in ids.items()}.__getitem__, derived=NS(doors=[da, db]))
    doc = {"units": [{"id": 1, "type": "corridor"}, {"id": 2, "type": "room"}, {"id": 3, "type": "hall"}],
           "doors": [{"id": 1, "units": [1, 2]}, {"id": 2, "units": [2, 3]}]}
    a = world((0, (0, 0, 10, 10), ROOM), (1, (0, 10, 10, 30), CORRIDOR))
    marg = unit_marginals(WSTAR, [a, WSTAR])
    out = with_posterior(doc, sm, marg, {da: 0.25, db: 1.0}, worlds=2, source="the sample around W*")
    by_id = {u["id"]: u for u in out["units"]}
    assert by_id[2]["posterior_exists"] == 1.0 and by_id[2]["posterior_type"]["room"] == 1.0  # slot 0
    assert by_id[3]["posterior_exists"] == 0.5 and by_id[3]["posterior_type"]["hall"] == 1.0  # slot 2
    assert by_id[1]["posterior_type"]["corridor"] == 1.0
    # door id 1 joins units 1 and 2 (slots 1, 0): db; id 2 joins units 2 and 3: da
    assert [d["posterior_exists"] for d in out["doors"]] == [1.0, 0.25]
    assert out["posterior_marginals"]["worlds"] == 2
    assert "posterior_exists" not in doc["units"][0]          # the input left as it was
