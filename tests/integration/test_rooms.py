"""rooms.png and world.json's rooms (semmap_pp.semantic.rooms), the ROSE2 / ipa segmentation
protocol (semmap_pp.evaluate.protocol_scores) and `semmap eval DIR --segmentation GT`."""

import json
from collections import deque
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st
from PIL import Image
from scipy import ndimage as ndi

from semmap_pp.cli import main
from semmap_pp.cells import FREE
from semmap_pp.errors import ModelError
from semmap_pp.evaluate import (colour_room_labels, colour_segment_labels, protocol_scores,
                                read_segmentation, read_segmentation_truth)
from semmap_pp.model import RoomParams, load_model
from semmap_pp.semantic.rooms import floor_cells, geodesic_flood, room_labels, seen_share

ROOT = Path(__file__).resolve().parents[2]
REAL_GT = ROOT / "bench" / "data" / "real-gt"
INTEL = ROOT / "tests" / "data" / "maps" / "intel_corner.yaml"
TINY = ["--chains", "2", "--cores", "1", "--tune", "2", "--draws", "4", "--n-inner", "5",
        "--spread-draws", "0", "--progress", "none"]
#: ROSE2's published recall on its five maps (Luperto et al. 2022; bench/data/real-gt/README.md)
PUBLISHED_RECALL = {"freiburg_building52": 0.967, "freiburg_building101": 0.908, "g4s_y2": 0.943,
                    "map17": 0.913, "map23": 0.977}


# --- the flood ---------------------------------------------------------------------------------

def bfs_distance(passable: np.ndarray, sources: np.ndarray, walls: np.ndarray) -> np.ndarray:
    """Path length from ``sources`` through passable cells (inf where unreachable): steps to the 4
    neighbours, and to the diagonal ones unless both cells beside the step are ``walls``."""
    h, w = passable.shape
    dist = np.full((h, w), np.inf)
    q = deque()
    for i, j in zip(*np.nonzero(sources)):
        dist[i, j] = 0
        q.append((i, j))
    while q:
        i, j = q.popleft()
        for di, dj in ((1, 0), (-1, 0), (0, 1), (0, -1), (1, 1), (1, -1), (-1, 1), (-1, -1)):
            ii, jj = i + di, j + dj
            if not (0 <= ii < h and 0 <= jj < w) or not passable[ii, jj] or dist[ii, jj] < np.inf:
                continue
            if di and dj and walls[ii, j] and walls[i, jj]:
                continue
            dist[ii, jj] = dist[i, j] + 1
            q.append((ii, jj))
    return dist


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 2 ** 31 - 1), st.booleans())
def test_the_flood_gives_each_cell_a_nearest_seed_along_the_floor(seed, some_walls):
    rng = np.random.default_rng(seed)
    passable = rng.random((12, 15)) < 0.75
    seeds = np.zeros((12, 15), np.int32)
    for label in (1, 2, 3):
        i, j = rng.integers(0, 12), rng.integers(0, 15)
        seeds[i, j] = label
        passable[i, j] = True
    # every non-passable cell a wall, or only some of them (the others unseen cells)
    walls = ~passable & (rng.random(passable.shape) < 0.5) if some_walls else ~passable
    out = geodesic_flood(seeds, passable, walls=walls)
    dists = {k: bfs_distance(passable, seeds == k, walls) for k in (1, 2, 3)}
    nearest = np.min(np.stack(list(dists.values())), axis=0)
    for i, j in np.ndindex(out.shape):
        if seeds[i, j]:
            assert out[i, j] == seeds[i, j]
        elif not passable[i, j] or nearest[i, j] == np.inf:
            assert out[i, j] == 0
        else:
            assert dists[int(out[i, j])][i, j] == nearest[i, j]


# --- room_labels on drawn floors --------------------------------------------------------------

def corridor_and_room(door_width: int):
    """A corridor (rows 0..9, a unit's interior) and, behind a wall (rows 10..11) with a doorway of
    ``door_width`` cells, a 20 x 20 room that no unit covers; 0.1 m cells."""
    free = np.zeros((32, 40), bool)
    free[0:10, :] = True
    free[12:32, 10:30] = True
    free[10:12, 20 - door_width // 2:20 + (door_width + 1) // 2] = True
    seeds = np.zeros(free.shape, np.int32)
    seeds[1:9, 1:39] = 1
    return free, seeds


def test_the_cells_of_a_ray_that_touch_at_their_corners_join_its_room_but_a_staircase_wall_holds():
    """A room (a unit's interior) with a ray leaving it across unseen cells, its cells touching
    only at their corners: the ray is the room's. Below the room's floor, a second room behind a
    wall drawn as a staircase of occupied cells (rows 18 and 19 in turn): the flood does not cut
    through the staircase's corners."""
    free = np.zeros((30, 30), bool)
    free[2:12, 2:12] = True                                   # room 1
    for k in range(12, 20):
        free[k, k] = True                                     # a diagonal ray out of its corner
    free[12:28, 2:10] = True                                  # its floor going on, then room 2 ...
    occupied = np.zeros_like(free)
    for k in range(8):
        occupied[19 - k % 2, 2 + k] = True                    # ... under a staircase wall
    occupied[1, 1:13] = occupied[1:29, 1] = True              # the rooms' outer walls
    free &= ~occupied
    seeds = np.zeros(free.shape, np.int32)
    seeds[3:11, 3:11] = 1
    seeds[22:27, 3:9] = 2
    lab, _ = room_labels(free, seeds, np.zeros_like(free), 0.1, RoomParams(min_room_m2=100.0),
                         occupied=occupied)
    assert (lab[12:20, 12:20].diagonal() == 1).all()
    rows = np.arange(30)[:, None]
    below = free & (rows >= 19) & (np.arange(30)[None, :] < 10)
    below &= ~((rows == 19) & (np.arange(30)[None, :] % 2 == 0))    # (19, odd) cells are above it
    assert (lab[below & (rows >= 20)] == 2).all()
    assert (lab[free & (rows >= 12) & (rows <= 17) & (np.arange(30)[None, :] < 10)] == 1).all()
    # without the corner rule (every non-free cell a wall, as unseen cells are) the ray is cut off
    lab4, _ = room_labels(free, seeds, np.zeros_like(free), 0.1, RoomParams(min_room_m2=100.0))
    assert (lab4[12:20, 12:20].diagonal()[1:] == 0).all()


def test_a_room_seen_through_its_door_is_a_room_of_its_own():
    free, seeds = corridor_and_room(door_width=8)          # 0.8 m
    labels, rooms = room_labels(free, seeds, np.zeros_like(free), 0.1)
    assert [(k, region) for k, region, _ in rooms] == [(1, 1), (2, 0)]
    assert (labels[12:32, 10:30] == 2).all()
    assert (labels[0:10] == 1).all()                        # the corridor's own strips joined it


def test_rays_into_the_open_through_a_window_are_no_room():
    """The same piece beyond a door-wide opening, once with walls around it (a room seen through its
    door) and once ending in unknown cells (rays through a window into the open)."""
    free, seeds = corridor_and_room(door_width=8)
    walls = ~free
    walls[12:32, 10:30] = False
    walls[10:12, :] = True
    walls[10:12, 16:24] = False
    labels, rooms = room_labels(free, seeds, np.zeros_like(free), 0.1, occupied=walls)
    assert [(k, region) for k, region, _ in rooms] == [(1, 1), (2, 0)]
    free, seeds = (np.pad(a, ((0, 6), (0, 0))) for a in (free, seeds))   # unknown beyond the fan
    open_air = np.zeros_like(free)
    open_air[10:12, :] = True                               # the corridor's wall, a window in it,
    open_air[10:12, 16:24] = False                          # nothing beyond
    labels, rooms = room_labels(free, seeds, np.zeros_like(free), 0.1, occupied=open_air)
    assert [(k, region) for k, region, _ in rooms] == [(1, 1)]
    assert (labels[13:32, 10:30] == 0).all()                # not flooded into the corridor either


def test_a_small_unit_in_rays_into_the_open_keeps_no_room_there():
    """A unit too small for a room keeps its cells' room where no room reaches them (``fallback``:
    a closet behind its door), but not in rays into the open: those are no room."""
    free, seeds = corridor_and_room(door_width=8)
    free, seeds = (np.pad(a, ((0, 6), (0, 0))) for a in (free, seeds))
    open_air = np.zeros_like(free)
    open_air[10:12, :] = True
    open_air[10:12, 16:24] = False
    fallback = np.zeros_like(seeds)
    fallback[20:24, 15:19] = 2                       # a small unit's interior out in the fan
    labels, rooms = room_labels(free, seeds, np.zeros_like(free), 0.1, occupied=open_air, fallback=fallback)
    assert [(k, region) for k, region, _ in rooms] == [(1, 1)]
    assert (labels[13:32, 10:30] == 0).all()
    closet = np.zeros_like(free)                     # the same piece walled all round: a room
    closet[10:12, :] = closet[32, :] = closet[:, 9] = closet[:, 30] = True
    closet[10:12, 16:24] = False
    labels, rooms = room_labels(free, seeds, np.zeros_like(free), 0.1, occupied=closet, fallback=fallback)
    assert [(k, region) for k, region, _ in rooms] == [(1, 1), (2, 0)]


def fan_beyond_a_door(far_wall: bool):
    """A corridor (rows 0..9) with a wall (rows 10..11) and a 0.8 m door, and beyond the door a fan
    of rays widening into a room the robot never entered: its sides unseen (unknown cells), and,
    with ``far_wall``, the room's far wall (row 34) behind a one-cell margin of blur (row 33, neither
    free nor occupied); without it the rays end in unknown cells. 0.1 m cells."""
    free = np.zeros((40, 60), bool)
    occupied = np.zeros_like(free)
    free[0:10, :] = True
    occupied[10:12, :] = True
    occupied[10:12, 26:34] = False
    free[10:12, 26:34] = True
    for r in range(12, 33):
        half = 4 + (r - 12) // 2
        free[r, 30 - half:30 + half] = True
    if far_wall:
        occupied[34, 10:50] = True
    seeds = np.zeros(free.shape, np.int32)
    seeds[1:9, 1:59] = 1
    return free, seeds, occupied


def test_a_fan_into_a_room_seen_through_its_door_is_a_room_and_one_into_the_open_is_not():
    """The fan's sides are unseen, so most non-free cells around it are unknown whatever lies
    beyond; what tells a room from the open is its far wall, read through the map's blur
    (``wall_blur_m``): without the wall, or without the blur, too few cells around it are walls."""
    free, seeds, occupied = fan_beyond_a_door(far_wall=True)
    ring = ndi.binary_dilation(free[12:], np.ones((3, 3), bool)) & ~free[12:]
    assert (ring & occupied[12:]).sum() < 0.2 * ring.sum()          # occupied cells alone: too few
    blur = RoomParams(wall_blur_m=0.1)                               # one 0.1 m cell
    labels, rooms = room_labels(free, seeds, np.zeros_like(free), 0.1, blur, occupied=occupied)
    assert [(k, region) for k, region, _ in rooms] == [(1, 1), (2, 0)]
    assert (labels[13:33][free[13:33]] == 2).all()
    labels, rooms = room_labels(free, seeds, np.zeros_like(free), 0.1,
                                RoomParams(wall_blur_m=0.0), occupied=occupied)
    assert [(k, region) for k, region, _ in rooms] == [(1, 1)]         # the blur hides the wall
    free, seeds, occupied = fan_beyond_a_door(far_wall=False)
    labels, rooms = room_labels(free, seeds, np.zeros_like(free), 0.1, blur, occupied=occupied)
    assert [(k, region) for k, region, _ in rooms] == [(1, 1)]
    assert (labels[13:33] == 0).all()


def test_a_unit_over_rays_into_the_open_keeps_no_room_and_one_over_a_room_never_entered_does():
    """W* may cover a fan of rays with a unit of its own. Its room is dropped when walls enclose
    less of the unit's own floor than a room seen through its door needs (``walled_min``) and less
    of all its floor than rays through an exit have (``exit_fan_walled_max``): rays into the open,
    no room, and not flooded into the corridor either. A room never entered keeps its room when
    either holds: its far wall seen whole, or only a few cells of it (more walls around than the
    open has). The corridor, walled along its side, keeps its room."""
    blur = RoomParams(wall_blur_m=0.1)
    for seen, kept in ((20, True), (4, True), (0, False)):          # cells of the far wall seen
        free, seeds, occupied = fan_beyond_a_door(far_wall=seen == 20)
        occupied[34, 30 - seen // 2:30 + seen // 2] = True
        seeds[14:32, 18:42] = 2                      # a unit's interior over the fan
        fan = np.zeros_like(free)
        fan[16:33] = free[16:33]
        labels, rooms = room_labels(free, seeds, np.zeros_like(free), 0.1, blur, occupied=occupied)
        assert (labels[0:10] == 1).all()
        if kept:
            assert [(k, region) for k, region, _ in rooms] == [(1, 1), (2, 2)]
            assert (labels[fan] == 2).all()
        else:
            assert [(k, region) for k, region, _ in rooms] == [(1, 1)]
            assert (labels[12:33][free[12:33]] != 1).all() and (labels[fan] == 0).all()
    off = RoomParams(wall_blur_m=0.1, walled_min=0.0)
    labels, rooms = room_labels(free, seeds, np.zeros_like(free), 0.1, off, occupied=occupied)
    assert [(k, region) for k, region, _ in rooms] == [(1, 1), (2, 2)] and (labels[fan] == 2).all()


def test_a_unit_over_a_room_and_rays_beyond_it_keeps_the_room():
    """One unit W* drew over a walled room and over rays into the open beside it, the two walled
    apart (a room per core, step 1): the room is kept, the rays are no room. Rooms are judged
    each on its own floor, not the unit on all of them."""
    free = np.zeros((40, 70), bool)
    occupied = np.zeros_like(free)
    free[0:10, :] = True                             # a corridor, walled below
    occupied[10:12, :] = True
    occupied[10:12, 14:20] = occupied[10:12, 46:52] = False
    free[10:12, 14:20] = free[10:12, 46:52] = True   # a door into the room, an exit into the open
    free[12:30, 4:30] = True                         # the room, walled all round
    occupied[12:31, 3] = occupied[12:31, 30] = occupied[30, 3:31] = True
    for r in range(12, 40):                          # rays into the open beyond the exit
        half = 3 + (r - 12) // 2
        free[r, max(49 - half, 32):min(49 + half, 70)] = True
    seeds = np.zeros(free.shape, np.int32)
    seeds[1:9, 1:69] = 1
    seeds[14:28, 6:28] = 2                           # one unit over the room ...
    seeds[14:38, 33:66] = 2                          # ... and the rays (its interior on both sides)
    labels, rooms = room_labels(free, seeds, np.zeros_like(free), 0.1, RoomParams(wall_blur_m=0.1),
                                occupied=occupied, walls_apart=occupied.copy())
    room, rays = np.zeros_like(free), np.zeros_like(free)
    room[13:29, 5:29] = True
    rays[16:40, 32:70] = free[16:40, 32:70]
    assert (labels[room] == 2).all() and (labels[rays] == 0).all() and (labels[0:10] == 1).all()


def test_a_walled_room_with_rays_out_through_its_exit_keeps_its_room():
    """A room walled all round but for an exit wider than a door, and rays beyond the exit joined
    to it (the open side of the room in front, step 3): its whole floor is as open as rays into the
    open, its own floor is walled, so it keeps its room, rays and all."""
    free = np.zeros((64, 84), bool)
    occupied = np.zeros_like(free)
    free[1:20, 21:60] = True                         # the room ...
    occupied[0, 20:61] = occupied[20, 20:61] = occupied[0:21, 20] = occupied[0:21, 60] = True
    occupied[20, 28:52] = False                      # ... and its exit, 2.4 m wide
    free[20, 28:52] = True
    free[21:24, 28:52] = True                        # the floor just beyond the exit, then
    for a in np.radians(np.linspace(-60, 60, 15)):   # single rays into the open
        for t in range(1, 42):
            free[int(round(20 + t * np.cos(a))), int(round(40 + t * np.sin(a)))] = True
    seeds = np.zeros(free.shape, np.int32)
    seeds[2:19, 22:59] = 1
    rays = np.zeros_like(free)
    rays[24:] = free[24:]
    labels, rooms = room_labels(free, seeds, np.zeros_like(free), 0.1, RoomParams(wall_blur_m=0.1),
                                occupied=occupied)
    assert [(k, region) for k, region, _ in rooms] == [(1, 1)]
    assert (labels[1:20, 21:60] == 1).all() and (labels[rays] == 1).mean() > 0.9


def fan_beyond_an_exit(far_wall: bool):
    """:func:`fan_beyond_a_door` through an exit 2.4 m wide (wider than a double door): the rays
    beyond it meet the corridor's strip through an opening wider than ``door_max_m``."""
    free, seeds, occupied = fan_beyond_a_door(far_wall)
    occupied[10:12, 18:42] = False
    free[10:12, 18:42] = True
    for r in range(12, 33):
        half = 12 + (r - 12) // 2
        free[r, 30 - half:30 + half] = True
    return free, seeds, occupied


def test_rays_into_the_open_through_an_exit_where_w_star_has_an_exterior_unit_are_no_room():
    """A fan beyond an opening wider than a door joins the room in front (the open side of one
    space), unless W* put an exterior unit over most of it (``exit_fan_exterior_min``) and hardly any
    walls lie around it (``exit_fan_walled_max``): rays into the open through an exit. A fan
    into a room never entered, part of its far wall seen, stays the room's (the walls around it
    are fewer than a room of its own needs, ``walled_min``, but more than the open's), and so
    does one the exterior unit covers less, and an open-plan bay walled all round."""
    free, seeds, occupied = fan_beyond_an_exit(far_wall=False)
    blur = RoomParams(wall_blur_m=0.1)
    fan = np.zeros_like(free)
    fan[14:33] = free[14:33]
    outside = np.zeros_like(free)
    outside[16:40, :] = True                         # the exterior unit: most of the fan
    labels, rooms = room_labels(free, seeds, np.zeros_like(free), 0.1, blur, occupied=occupied)
    assert [(k, region) for k, region, _ in rooms] == [(1, 1)] and (labels[fan] == 1).all()
    labels, rooms = room_labels(free, seeds, np.zeros_like(free), 0.1, blur, occupied=occupied,
                                outside=outside)
    assert [(k, region) for k, region, _ in rooms] == [(1, 1)] and (labels[fan] == 0).all()
    assert (labels[0:10] == 1).all()
    off = RoomParams(wall_blur_m=0.1, exit_fan_exterior_min=0.0)
    labels, _ = room_labels(free, seeds, np.zeros_like(free), 0.1, off, occupied=occupied, outside=outside)
    assert (labels[fan] == 1).all()                  # the rule off: flooded as before
    little = np.zeros_like(free)
    little[30:40, :] = True                          # an exterior unit over its far end only
    labels, _ = room_labels(free, seeds, np.zeros_like(free), 0.1, blur, occupied=occupied, outside=little)
    assert (labels[fan] == 1).all()
    for half, kept in ((1, False), (5, True)):       # 2 or 10 cells of its far wall seen
        free, seeds, occupied = fan_beyond_an_exit(far_wall=False)
        occupied[34, 30 - half:30 + half] = True
        labels, _ = room_labels(free, seeds, np.zeros_like(free), 0.1, blur, occupied=occupied, outside=outside)
        assert (labels[fan] == 1).all() if kept else (labels[fan] == 0).all()
    free, seeds, occupied = fan_beyond_an_exit(far_wall=True)
    occupied[12:34, 5] = occupied[12:34, 54] = True  # walls on its sides too: an open-plan bay
    labels, _ = room_labels(free, seeds, np.zeros_like(free), 0.1, blur, occupied=occupied, outside=outside)
    assert (labels[fan] == 1).all()


def test_an_opening_wider_than_a_door_joins_the_unit_in_front():
    free, seeds = corridor_and_room(door_width=20)         # 2.0 m > door_max_m 1.6
    labels, rooms = room_labels(free, seeds, np.zeros_like(free), 0.1)
    assert [(k, region) for k, region, _ in rooms] == [(1, 1)]
    assert (labels[free] == 1).all()


def test_a_piece_smaller_than_a_room_joins_its_neighbour():
    free, seeds = corridor_and_room(door_width=8)
    labels, rooms = room_labels(free, seeds, np.zeros_like(free), 0.1, RoomParams(min_room_m2=5.0))
    assert len(rooms) == 1 and (labels[free] == 1).all()     # 4 m^2 behind the door


def test_doors_separate_rooms_and_belong_to_none():
    free, seeds = corridor_and_room(door_width=8)
    seeds[13:31, 11:29] = 2                                 # the room is a unit too
    doors = np.zeros_like(free)
    doors[10:12, 16:24] = True
    labels, rooms = room_labels(free, seeds, doors, 0.1)
    assert [(k, region) for k, region, _ in rooms] == [(1, 1), (2, 2)]
    assert (labels[doors] == 0).all() and (labels[free & ~doors] > 0).all()
    assert sum(n for *_, n in rooms) == int((free & ~doors).sum())


def test_free_cells_no_room_reaches_are_none():
    free, seeds = corridor_and_room(door_width=8)
    free[30:32, 0:4] = True                                 # a speck beyond the wall
    labels, _ = room_labels(free, seeds, np.zeros_like(free), 0.1)
    assert (labels[30:32, 0:4] == 0).all()


def test_seen_share_of_a_full_and_of_a_fan_shaped_room():
    assert seen_share(np.ones((5, 7), bool)) == 1.0
    fan = np.zeros((30, 30), bool)
    for k in range(0, 30, 9):                               # four thin rays from one corner
        rr = np.linspace(0, 29, 60).astype(int)
        cc = np.clip((rr * k / 29).astype(int), 0, 29)
        fan[rr, cc] = True
    assert seen_share(fan) < 0.4


@settings(max_examples=200, deadline=None)
@given(st.integers(0, 2 ** 31 - 1))
def test_seen_share_equals_the_hull_of_every_cells_corners(seed):
    from scipy.spatial import ConvexHull, QhullError
    rng = np.random.default_rng(seed)
    mask = rng.random((rng.integers(1, 10), rng.integers(1, 10))) < 0.4
    if not mask.any():
        assert seen_share(mask) == 0.0
        return
    r, c = np.nonzero(mask)
    corners = np.unique(np.concatenate([np.stack([r + a, c + b], 1) for a in (0, 1) for b in (0, 1)]), axis=0)
    try:
        expected = min(1.0, mask.sum() / ConvexHull(corners).volume)
    except QhullError:
        expected = 1.0
    assert seen_share(mask) == pytest.approx(expected, abs=1e-12)


# --- the floor: the cells rooms.png labels -----------------------------------------------------

def graded_room():
    """A room of free cells (p 0.004) in a map whose unknown grey is p 0.4 (the freiburg floors'),
    walls p 1 around it; inside, a patch seen free only a few times (p 0.06), a patch nearer the
    grey (p 0.25); along the west wall a darker grey (p 0.15: the wall's blur), along the east
    wall cells seen free a few times (p 0.06)."""
    from semmap_pp.cells import OCCUPIED, UNKNOWN
    from semmap_pp.grid.occupancy import OccupancyGrid
    classes = np.full((30, 40), UNKNOWN, np.uint8)
    occ = np.full((30, 40), 0.4, np.float32)
    classes[5:25, 5:35], occ[5:25, 5:35] = OCCUPIED, 1.0
    classes[6:24, 6:34], occ[6:24, 6:34] = FREE, 0.004
    classes[10:14, 10:16], occ[10:14, 10:16] = UNKNOWN, 0.06       # seen free a few times
    classes[16:20, 10:16], occ[16:20, 10:16] = UNKNOWN, 0.25       # nearer the unknown grey
    classes[6:24, 6], occ[6:24, 6] = UNKNOWN, 0.15                 # the west wall's blur
    classes[6:24, 33], occ[6:24, 33] = UNKNOWN, 0.06               # seen free along the east wall
    occ[0, 0] = np.nan                                             # unknown by the image itself
    return OccupancyGrid(classes, occ, 0.05)


def test_the_floor_holds_cells_seen_free_but_not_the_grey_nor_a_walls_blur():
    g = graded_room()
    floor = floor_cells(g, RoomParams(wall_blur_m=0.05, wall_floor_max=0.1))
    assert floor[10:14, 10:16].all()                       # nearer to free than to the grey
    assert not floor[16:20, 10:16].any()                   # nearer to the grey
    assert not floor[7:23, 6].any()                        # beside the wall, darker than 0.1: its blur
    assert floor[6:24, 33].all()                           # beside the wall, seen free
    rows, cols = np.arange(30)[:, None], np.arange(40)[None]
    patch = (rows >= 10) & (rows < 14) & (cols >= 10) & (cols < 16)
    east = (rows >= 6) & (rows < 24) & (cols == 33)
    assert (floor == ((g.classes == FREE) | patch | east)).all()
    # without a blur margin the west wall's grey is floor too (nearer to free than to the grey)
    assert floor_cells(g, RoomParams(wall_blur_m=0.0))[7:23, 6].all()
    # and with no grey at all allowed beside a wall, neither wall's cells are
    none = floor_cells(g, RoomParams(wall_blur_m=0.05, wall_floor_max=0.0))
    assert not none[7:23, 6].any() and not none[7:23, 33].any()


def test_a_trinary_map_s_floor_is_its_free_cells():
    from semmap_pp.grid import load_map
    g = load_map(INTEL)
    assert (floor_cells(g, load_model().rooms) == (g.classes == FREE)).all()


def test_the_cells_seen_free_of_a_graded_slam_map_are_in_its_hand_drawn_rooms():
    """g4s_y2 is saved with graded values: cells lighter than its unknown grey (205) but above
    its free_thresh. The hand-drawn truth counts most of them as floor."""
    from semmap_pp.grid import load_map
    g = load_map(REAL_GT / "g4s_y2" / "map.yaml")
    added = floor_cells(g, load_model().rooms) & (g.classes != FREE)
    gt = read_segmentation_truth(REAL_GT / "g4s_y2" / "gt.png", "rose2")
    assert added.sum() > 0.02 * (gt > 0).sum()
    assert (gt[added] > 0).mean() > 0.9


@pytest.mark.parametrize("name", ["g4s_y2", "freiburg_building101", "freiburg_building52"])
def test_beside_a_wall_the_hand_drawn_rooms_hold_the_light_greys_and_not_the_darker_ones(name):
    """tools/floor_greys.py on the three graded real-gt floors: within a cell of a wall, the grey
    cells inside the hand-drawn rooms are nearly all at most ``wall_floor_max`` (p 0.1), those
    outside every room nearly all above it (a wall's blur); the model's value splits them."""
    import importlib.util
    spec = importlib.util.spec_from_file_location("floor_greys", ROOT / "tools" / "floor_greys.py")
    tool = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(tool)
    band = tool.table(REAL_GT / name)["beside a wall (<= 1.5 cells)"]
    k = tool.P_EDGES.index(load_model().rooms.wall_floor_max) + 1      # bins at most the value
    inside, outside = np.array(band["in rooms"]), np.array(band["outside rooms"])
    assert inside[:k].sum() > 0.99 * inside.sum() and inside.sum() > 1000
    assert outside[k:].sum() > 0.9 * outside.sum()


def test_the_model_file_rooms_table_is_read_and_checked(tmp_path):
    text = (ROOT / "models" / "default.toml").read_text()
    assert load_model().rooms == RoomParams(**{k: getattr(load_model().rooms, k)
                                               for k in ("min_room_m2", "door_max_m", "open_share_min",
                                                         "band_m", "walled_min", "wall_blur_m",
                                                         "split_core_m", "split_min_m2", "split_unknown_m2")})
    bad = tmp_path / "bad.toml"
    bad.write_text(text.replace("open_share_min = 0.6", "open_share_min = 1.5"))
    with pytest.raises(ModelError, match="rooms.open_share_min"):
        load_model(bad)
    for old, new in (("split_core_m = 0.45", "split_core_m = -1"), ("split_min_m2 = 1.5", "split_min_m2 = 0"),
                     ("split_unknown_m2 = 4.0", 'split_unknown_m2 = "big"')):
        bad.write_text(text.replace(old, new))
        with pytest.raises(ModelError, match=f"rooms.{old.split()[0]}"):
            load_model(bad)
    off = tmp_path / "off.toml"
    off.write_text(text.replace("split_core_m = 0.45", "split_core_m = 0"))
    assert load_model(off).rooms.split_core_m == 0.0
    without = tmp_path / "old.toml"
    start = text.index("[rooms]")
    end = text.index("\n[", start + 1)
    without.write_text(text[:start] + text[end + 1:])
    assert load_model(without).rooms == RoomParams()


# --- the protocol ------------------------------------------------------------------------------

def test_colour_truth_rooms_are_connected_regions_of_one_colour():
    img = np.zeros((30, 50, 3), np.uint8)
    img[:, :20] = (10, 200, 10)
    img[:, 25:] = (10, 200, 10)                             # the same colour again: another room
    img[0:2, 22:24] = (90, 90, 90)                          # 4 cells: too small to be a room
    labels = colour_room_labels(img)
    assert sorted(np.unique(labels).tolist()) == [0, 1, 2]
    assert colour_segment_labels(img).max() == 2            # one segment per colour


@pytest.mark.parametrize("name", sorted(PUBLISHED_RECALL))
def test_rose2s_own_output_scores_its_published_recall(name):
    """The scoring code reproduces ROSE2's published recall on each of its five maps (its
    precision figures depend on how their code treats small regions: README of real-gt)."""
    gt = read_segmentation_truth(REAL_GT / name / "gt.png", "rose2")
    s = protocol_scores(gt, read_segmentation(REAL_GT / name / "rose2.png"))
    assert s.recall == pytest.approx(PUBLISHED_RECALL[name], abs=0.0015)
    assert 0.8 < s.precision <= 1.0


def test_a_merged_segment_lowers_precision_and_a_split_room_recall():
    gt = np.zeros((20, 40), int)
    gt[:, :20], gt[:, 20:] = 1, 2
    perfect = protocol_scores(gt, gt)
    assert (perfect.precision, perfect.recall) == (1.0, 1.0)
    merged = protocol_scores(gt, np.ones_like(gt))
    assert merged.precision == 0.5 and merged.recall == 1.0
    split = gt.copy()
    split[:, 30:] = 3
    s = protocol_scores(gt, split)
    assert s.precision == 1.0 and s.recall == 0.75


# --- a run -------------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
    out = tmp_path_factory.mktemp("rooms") / "run"
    assert main(["map", str(INTEL), "--out", str(out), *TINY]) == 0
    return out


def test_a_run_writes_rooms_png_and_world_json_rooms_that_agree(run_dir):
    rooms = np.asarray(Image.open(run_dir / "rooms.png"))
    doc = json.loads((run_dir / "world.json").read_text())
    assert rooms.dtype == np.uint16
    assert rooms.shape == np.asarray(Image.open(run_dir / "labels.png")).shape
    ids, counts = np.unique(rooms[rooms > 0], return_counts=True)
    assert [r["id"] for r in doc["rooms"]] == ids.tolist()
    assert [r["cells"] for r in doc["rooms"]] == counts.tolist()
    units = {u["id"] for u in doc["units"]}
    for r in doc["rooms"]:
        flagged = {u["id"] for u in doc["units"] if u["seen_through_door"]}
        assert set(r["units"]) <= units
        assert r["seen_through_door"] == (not r["units"] or set(r["units"]) <= flagged)
        assert 0 < r["seen_share"] <= 1
    owned = [u for r in doc["rooms"] for u in r["units"]]
    assert len(owned) == len(set(owned))                    # a unit grows one room at most


def test_rooms_cover_only_free_cells_on_a_trinary_map(run_dir):
    from semmap_pp.cells import FREE
    from semmap_pp.grid import load_map
    rooms = np.asarray(Image.open(run_dir / "rooms.png"))
    classes = load_map(INTEL).classes
    assert (classes[rooms > 0] == FREE).all()
    assert (rooms > 0).sum() > 0.8 * (classes == FREE).sum()


def test_eval_segmentation_scores_rooms_png(run_dir, tmp_path, capsys):
    rooms = np.asarray(Image.open(run_dir / "rooms.png"))
    rng = np.random.default_rng(0)
    palette = rng.integers(30, 255, (int(rooms.max()) + 1, 3)).astype(np.uint8)
    palette[0] = 0
    gt = tmp_path / "gt.png"
    Image.fromarray(palette[rooms]).save(gt)                # the run's own rooms as the truth
    assert main(["eval", str(run_dir), "--segmentation", str(gt), "--json"]) == 0
    s = json.loads(capsys.readouterr().out)["scores"]
    # every true room (a one-colour region) lies in one room of rooms.png; a room whose cells
    # fall apart is two true rooms, so precision may stay below 1
    assert s["recall"] == 1.0 and s["precision"] > 0.9
    assert main(["eval", str(run_dir), "--segmentation", str(gt), "--of", "labels.png", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["scores"]["precision"] < s["precision"]


def test_eval_segmentation_errors_are_one_line(run_dir, tmp_path, capsys):
    wrong = tmp_path / "wrong.png"
    Image.fromarray(np.zeros((10, 10, 3), np.uint8)).save(wrong)
    assert main(["eval", str(run_dir), "--segmentation", str(wrong)]) != 0
    err = capsys.readouterr().err.strip()
    assert "wrong.png" in err and "no region of one colour" in err and "\n" not in err
    gt = tmp_path / "gt.png"
    Image.fromarray(np.full((20, 30, 3), 200, np.uint8)).save(gt)
    assert main(["eval", str(run_dir), "--segmentation", str(gt)]) != 0
    err = capsys.readouterr().err.strip()
    assert "not the same map" in err and "\n" not in err
    assert main(["eval", str(tmp_path), "--segmentation", str(gt)]) != 0
    assert "rooms.png" in capsys.readouterr().err


def test_eval_segmentation_refuses_a_fifo_without_reading_it(run_dir, tmp_path):
    import os
    import subprocess
    import sys
    fifo = tmp_path / "gt.png"
    os.mkfifo(fifo)
    for args in (["--segmentation", str(fifo)], ["--segmentation", str(REAL_GT / "map17" / "gt.png"),
                                                 "--of", str(fifo)]):
        p = subprocess.run([sys.executable, "-m", "semmap_pp", "eval", str(run_dir), *args],
                           capture_output=True, text=True, timeout=120)
        assert p.returncode == 2
        assert "gt.png" in p.stderr and "not a regular file" in p.stderr
        assert len(p.stderr.strip().splitlines()) == 1


# --- units one room across a wide gap ------------------------------------------------------------

def two_units_with_a_partition(gap_cells: int, clutter: bool = False):
    """Two 40 x 40-cell units side by side (0.05 m cells, 2-cell wall bands) sharing a wall down
    columns 38-41 that stops ``gap_cells`` short of the bottom wall; ``clutter`` puts a cupboard
    row across the floor in front of the gap."""
    from semmap_pp.cells import FREE, OCCUPIED
    classes = np.full((44, 84), OCCUPIED, np.uint8)
    classes[2:42, 2:82] = FREE
    classes[2:42 - gap_cells, 38:42] = OCCUPIED
    if clutter:
        classes[42 - gap_cells - 2:42, 30:36] = OCCUPIED
    return classes, (0, 0, 44, 42), (0, 38, 44, 84)


@pytest.mark.parametrize("gap_cells, joined", [(40, True), (36, True), (30, False), (16, False)])
def test_a_gap_wider_than_a_double_door_is_one_floor(gap_cells, joined):
    from semmap_pp.cells import FREE
    from semmap_pp.semantic.rooms import wide_opening
    classes, rp, rq = two_units_with_a_partition(gap_cells)
    width = RoomParams().door_max_m / 0.05                       # 32 cells
    assert wide_opening(classes == FREE, rp, rq, 2, width) is joined
    assert wide_opening(classes == FREE, rq, rp, 2, width) is joined     # symmetric


def test_clutter_in_front_of_a_wide_gap_narrows_it_to_a_door():
    from semmap_pp.cells import FREE
    from semmap_pp.semantic.rooms import wide_opening
    classes, rp, rq = two_units_with_a_partition(36)
    assert wide_opening(classes == FREE, rp, rq, 2, 32.0)
    classes, rp, rq = two_units_with_a_partition(36, clutter=True)
    assert not wide_opening(classes == FREE, rp, rq, 2, 32.0)


class _FakeMap:
    """The parts of a SemanticMap that room_joins reads: two units with one door between them."""

    def __init__(self, classes, rp, rq, types):
        from types import SimpleNamespace
        from semmap_pp.derive.doors import Door
        self.slot_ids = {0: 1, 1: 2}
        self.world = SimpleNamespace(rects=[rp, rq])
        self.frame = SimpleNamespace(door_classes=classes, cells=SimpleNamespace(wall=2),
                                     resolution=0.05)
        self.derived = SimpleNamespace(doors=[Door(0, 1, (30, 38, 42, 42), True, 12)], passages=[])
        self._types = dict(zip((1, 2), types))
        self.through_door = frozenset()

    def type_of(self, uid):
        return self._types[uid]


@pytest.mark.parametrize("types, gap_cells, one_room", [
    (("room", "room"), 36, True), (("room", "other"), 36, True),
    (("room", "room"), 16, False),                    # a door
    (("corridor", "room"), 36, False), (("room", "hall"), 36, False)])   # a corridor's side
def test_room_joins_takes_a_wide_gap_between_rooms_but_not_a_corridors(types, gap_cells, one_room):
    from semmap_pp.semantic.rooms import room_joins
    classes, rp, rq = two_units_with_a_partition(gap_cells)
    pairs, doors = room_joins(_FakeMap(classes, rp, rq, types), RoomParams(open_share_min=1.0))
    assert (pairs == [(1, 2)]) is one_room
    assert len(doors) == (0 if one_room else 1)


# --- a room seen through its door becomes a unit -------------------------------------------------

def corridor_and_fan_room(tmp_path: Path) -> Path:
    """A map_server map (0.05 m cells) of a corridor the robot drove and, below it, a room seen only
    through its 0.9 m door: 720 rays cast from one scan position in the corridor end on the first
    occupied cell (the corridor's walls, the room's walls); cells no ray reached are unknown. The
    room's rays fan out from its door; between the fan and the room's side walls it is unknown."""
    H, W = 170, 240
    occ = np.zeros((H, W), bool)
    occ[20:22, 20:220] = occ[58:60, 20:220] = True          # the corridor's walls
    occ[20:60, 20:22] = occ[20:60, 218:220] = True
    occ[60:152, 68:70] = occ[60:152, 170:172] = True         # the room's side walls
    occ[150:152, 68:172] = True                              # its far wall
    occ[58:60, 110:128] = False                              # the door
    seen = np.zeros((H, W), bool)
    seen[22:58, 22:218] = True
    y0, x0 = 40.5, 119.5
    for a in np.linspace(0, 2 * np.pi, 720, endpoint=False):
        for t in np.arange(0, 160, 0.5):
            iy, ix = int(y0 + t * np.sin(a)), int(x0 + t * np.cos(a))
            if not (0 <= iy < H and 0 <= ix < W):
                break
            seen[iy, ix] = True
            if occ[iy, ix]:
                break
    img = np.full((H, W), 205, np.uint8)
    img[seen] = 254
    img[seen & occ] = 0
    Image.fromarray(img).save(tmp_path / "fan.pgm")
    (tmp_path / "fan.yaml").write_text("image: fan.pgm\nresolution: 0.05\norigin: [0.0, 0.0, 0.0]\n"
                                       "negate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.196\n")
    return tmp_path / "fan.yaml"


@pytest.fixture(scope="module")
def fan_world(tmp_path_factory):
    """The fan map's inputs, full target and kernel data, and the semantic map of a W* that holds
    the corridor only (the unit the data-driven start world gives it)."""
    from semmap_pp import world as wm
    from semmap_pp.resources import DEFAULT_RULES
    from semmap_pp.run import pipeline
    from semmap_pp.run.inputs import load_inputs
    from semmap_pp.run.target_factory import run_target
    from semmap_pp.sampler.kernels import data_from_frame
    from semmap_pp.semantic.semantic_map import semantic_map
    inputs = load_inputs(corridor_and_fan_room(tmp_path_factory.mktemp("fan")), rules_path=DEFAULT_RULES)
    post = run_target(inputs)
    start = pipeline.data_start_world(inputs)
    corridor = [tuple(int(v) for v in start.rects[s]) for s in wm.active_slots(start)
                if start.rects[s][2] <= 62]
    assert len(corridor) == 1
    world = wm.add(wm.empty(8), 0, corridor[0])
    sm = semantic_map(inputs.grid, inputs.frame, post, world, roi=inputs.roi)
    return inputs, post, data_from_frame(inputs.frame, inputs.model.kernels), sm


def test_a_room_seen_through_its_door_becomes_a_unit_of_w_star_and_a_room_of_its_own(fan_world):
    from semmap_pp.run.pipeline import _through_door_units
    from semmap_pp.semantic.world_json import world_dict
    inputs, post, data, sm = fan_world
    fan = (inputs.grid.classes == FREE) & (np.arange(inputs.grid.height)[:, None] >= 62)
    before = [r for r in sm.rooms.rooms if r.seen_through_door]
    assert len(before) == 1 and before[0].units == ()              # rooms.png finds it, no unit covers it
    out = _through_door_units(inputs, post, sm, data, log=lambda m: None, previous_ids=None)
    assert out.log_posterior > sm.log_posterior                     # kept because the target gains
    assert len(out.through_door) == 1
    slot = next(iter(out.through_door))
    uid = out.slot_ids[slot]
    covered = out.labels_image == uid
    assert covered[fan].mean() > 0.9                                # the unit lies over the fan
    room = [r for r in out.rooms.rooms if uid in r.units]
    assert len(room) == 1 and room[0].units == (uid,) and room[0].seen_through_door
    doc = world_dict(out)
    assert [u["seen_through_door"] for u in doc["units"]] == [u["id"] == uid for u in doc["units"]]
    assert [r["seen_through_door"] for r in doc["rooms"]] == [uid in r["units"] for r in doc["rooms"]]


def test_a_unit_added_over_a_room_seen_through_its_door_joins_no_other(fan_world):
    """The same W* with the fan's unit: unflagged, the wide door between it and the corridor can
    make them one room; flagged, never (its room is the fan's)."""
    from semmap_pp.run.pipeline import _through_door_units
    from semmap_pp.semantic.rooms import room_joins
    inputs, post, data, sm = fan_world
    out = _through_door_units(inputs, post, sm, data, log=lambda m: None, previous_ids=None)
    uid = out.slot_ids[next(iter(out.through_door))]
    pairs, _ = room_joins(out, out.room_params)
    assert all(uid not in p for p in pairs)


def test_a_box_the_target_does_not_gain_by_is_not_added(fan_world):
    """Once the fan's room has its unit, a box over the unknown beside it gains nothing wherever
    its walls move: the world is returned as it was."""
    from semmap_pp.run.pipeline import _through_door_units
    from semmap_pp.sampler.ascent import add_units
    inputs, post, data, sm = fan_world
    full = _through_door_units(inputs, post, sm, data, log=lambda m: None, previous_ids=None).world
    world, born = add_units(post, full, data, [(100, 180, 160, 236)])
    assert born == [] and world is full


def test_semmap_edit_keeps_the_flag_of_an_unedited_unit_over_a_room_seen_through_its_door(fan_world, tmp_path):
    from semmap_pp.run.pipeline import _through_door_units
    from semmap_pp.semantic.world_json import dumps, world_dict
    inputs, post, data, sm = fan_world
    out = _through_door_units(inputs, post, sm, data, log=lambda m: None, previous_ids=None)
    doc = world_dict(out)
    flagged = [u["id"] for u in doc["units"] if u["seen_through_door"]]
    others = [u["id"] for u in doc["units"] if not u["seen_through_door"]]
    assert len(flagged) == 1 and others
    (tmp_path / "world.json").write_text(dumps(doc))
    assert main(["edit", str(inputs.grid.source), str(tmp_path / "world.json"), "--out", str(tmp_path / "e"),
                 "--drop", *map(str, others)]) == 0
    edited = json.loads((tmp_path / "e" / "world.json").read_text())
    assert [u["seen_through_door"] for u in edited["units"]] == [True]
    assert [r["seen_through_door"] for r in edited["rooms"] if r["units"]] == [True]


@pytest.mark.parametrize("types, one_room", [
    (("room", "room"), True), (("room", "other"), True), (("corridor", "corridor"), True),
    (("corridor", "hall"), True), (("corridor", "other"), True),
    (("corridor", "room"), False), (("room", "hall"), False)])
def test_a_door_taking_most_of_a_wall_joins_two_units_but_never_a_corridor_and_a_room(types, one_room):
    """The wall stops 36 cells short of the bottom: the door takes 36 of its 40 lines, the open
    side of one space W* cut in two; but a room open to the corridor along it is a room."""
    from semmap_pp.semantic.rooms import opening_share, room_joins
    classes, rp, rq = two_units_with_a_partition(36)
    params = RoomParams(open_share_min=0.6, door_max_m=100.0)     # no gap is wide: the share decides
    assert opening_share(classes, rp, rq, 2) >= 0.6
    pairs, doors = room_joins(_FakeMap(classes, rp, rq, types), params)
    assert (pairs == [(1, 2)]) is one_room
    assert len(doors) == (0 if one_room else 1)


from types import SimpleNamespace as _NS
_CELLS = _NS(wall=2, object_max_extent=30, wall_line_tolerance=1, wall_line_gap=1)


def test_a_door_with_a_wall_line_beside_it_stays_a_door():
    """A door that takes most of a narrow wall (the end of a corridor, a link between two wings)
    stands in a wall the map draws: the wall line runs on past the two units, so the wall's
    closed lines are a wall line's cells and the opening stays a door. The same opening beside a
    stub that is no wall line (a unit's corner, furniture) is a passage."""
    from semmap_pp.cells import FREE, OCCUPIED
    from semmap_pp.derive import Derived
    from semmap_pp.derive.doors import Door
    from semmap_pp.semantic.rooms import open_walls
    for long_wall, passage in ((True, False), (False, True)):
        classes = np.full((120, 84), FREE, np.uint8)
        classes[0:2, :] = OCCUPIED
        classes[2:8, 38:42] = OCCUPIED                      # the jamb above the 28-line opening
        classes[36:44, 38:42] = OCCUPIED                    # and below it ...
        if long_wall:
            classes[36:110, 38:42] = OCCUPIED               # ... a wall line running on past the units
        rp, rq = (0, 0, 44, 42), (0, 38, 44, 84)
        door = Door(0, 1, (8, 38, 36, 42), True, 28)
        derived = Derived(np.array([0, 1]), None, [door], [], np.ones((2, 2), bool), [], [], [], [])
        world = _NS(rects=[rp, rq], types=np.array([0, 0]))
        frame = _NS(door_classes=classes, classes=classes, cells=_CELLS)
        out = open_walls(derived, world, frame, (), RoomParams(open_share_min=0.6))
        assert (out.passages == [door]) is passage and (out.doors == [door]) is not passage


@pytest.mark.parametrize("types, gap_cells, through_door, passage", [
    (("room", "room"), 34, (), True), (("room", "other"), 34, (), True),
    (("corridor", "corridor"), 34, (), True),
    (("room", "room"), 16, (), False),                                   # a door in a wall
    (("corridor", "room"), 34, (), False), (("room", "hall"), 34, (), False),   # a corridor's side
    (("room", "room"), 34, (1,), False)])                  # a room seen through its door keeps it
def test_a_door_taking_most_of_a_wall_is_listed_as_a_passage(types, gap_cells, through_door, passage):
    """world.json's doors and passages read the wall as rooms.png does: an opening that takes
    ``open_share_min`` of the wall two units share, beside a stub that is no wall line, is the
    open side of one space (a passage), unless a corridor or a hall meets a room there or a unit
    was added over a room seen through its door; the passage joins the two units in rooms.png as
    the door did."""
    from types import SimpleNamespace
    from semmap_pp.cells import UNIT_TYPES
    from semmap_pp.derive import Derived
    from semmap_pp.derive.doors import Door
    from semmap_pp.semantic.rooms import open_walls, room_joins
    classes, rp, rq = two_units_with_a_partition(gap_cells)
    door = Door(0, 1, (42 - gap_cells, 38, 42, 42), True, gap_cells)
    derived = Derived(np.array([0, 1]), None, [door], [], np.ones((2, 2), bool), [], [], [], [])
    world = SimpleNamespace(rects=[rp, rq], types=np.array([UNIT_TYPES.index(t) for t in types]))
    frame = SimpleNamespace(door_classes=classes, classes=classes, cells=_CELLS)
    params = RoomParams(open_share_min=0.6)
    out = open_walls(derived, world, frame, through_door, params)
    assert (out.passages == [door], out.doors == []) == ((passage, passage) if passage else (False, False))
    assert len(out.doors) + len(out.passages) == 1
    fake = _FakeMap(classes, rp, rq, types)
    fake.derived = out
    fake.through_door = frozenset(through_door)
    pairs, doors = room_joins(fake, RoomParams(open_share_min=0.6, door_max_m=100.0))
    assert doors == out.doors                          # rooms.png: the same rooms either way
    if passage:
        assert pairs == [(1, 2)]


def test_on_a_lattice_of_several_directions_every_door_stays_a_door():
    """A wall at another angle than its tile's is no wall line of that lattice, so what stands
    beside an opening cannot be read there: the opening that is a passage on one lattice stays a
    door on a tiled one."""
    from types import SimpleNamespace
    from semmap_pp.derive import Derived
    from semmap_pp.derive.doors import Door
    from semmap_pp.lattice.tiles import TiledFrame
    from semmap_pp.semantic.rooms import open_walls
    classes, rp, rq = two_units_with_a_partition(34)
    door = Door(0, 1, (8, 38, 42, 42), True, 34)
    derived = Derived(np.array([0, 1]), None, [door], [], np.ones((2, 2), bool), [], [], [], [])
    world = SimpleNamespace(rects=[rp, rq], types=np.array([0, 0]))
    plain = SimpleNamespace(door_classes=classes, classes=classes, cells=_CELLS)
    assert open_walls(derived, world, plain, (), RoomParams(open_share_min=0.6)).passages == [door]
    tiled = TiledFrame.__new__(TiledFrame)
    one = SimpleNamespace(shape=(44, 84))
    for key, value in (("tiles", (one, one)), ("cols", (0, 100)), ("door_classes", classes),
                       ("classes", classes), ("cells", _CELLS)):
        object.__setattr__(tiled, key, value)
    out = open_walls(derived, world, tiled, (), RoomParams(open_share_min=0.6))
    assert out.doors == [door] and out.passages == []


def semantic_map_of(tmp_path: Path, img: np.ndarray, boxes):
    """The semantic map of a world of units over ``img`` (a map_server image, 0.05 m cells, saved
    with its YAML in ``tmp_path``): one unit per pixel box ``(x0, y0, x1, y1)``, in order."""
    from semmap_pp import world as wm
    from semmap_pp.resources import DEFAULT_RULES
    from semmap_pp.run.inputs import load_inputs
    from semmap_pp.run.target_factory import run_target
    from semmap_pp.semantic.semantic_map import semantic_map
    Image.fromarray(img).save(tmp_path / "units.pgm")
    (tmp_path / "units.yaml").write_text("image: units.pgm\nresolution: 0.05\norigin: [0.0, 0.0, 0.0]\n"
                                         "negate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.196\n")
    inputs = load_inputs(tmp_path / "units.yaml", rules_path=DEFAULT_RULES)
    frame, world = inputs.frame, wm.empty(8)
    for i, (x0, y0, x1, y1) in enumerate(boxes):
        rect, _ = frame.rect_from_vertices_px([[x0, y0], [x1, y0], [x1, y1], [x0, y1]])
        world = wm.add(world, i, rect)
    return semantic_map(inputs.grid, frame, run_target(inputs), world, roi=inputs.roi)


def two_rooms_and_a_small_unit_across_their_wall(tmp_path: Path, gap: bool):
    """A map (0.05 m cells) of two rooms, one above the other, and the world of three units: one
    over each room, and between them a small one (1.4 x 1.7 m, less than ``min_room_m2`` inside its
    wall band) drawn across the wall that parts the rooms, so that its top edge opens onto the
    upper room's floor and its bottom edge onto the lower room's. ``gap``: the wall has a 0.8 m
    opening inside the small unit."""
    img = np.full((130, 100), 205, np.uint8)
    img[10:118, 10:90] = 254
    occ = np.zeros(img.shape, bool)
    occ[8:10, 8:92] = occ[118:120, 8:92] = occ[8:120, 8:10] = occ[8:120, 90:92] = True
    occ[62:64, 8:92] = True                                  # the wall between the two rooms
    if gap:
        occ[62:64, 14:30] = False
    img[occ] = 0
    return semantic_map_of(tmp_path, img, [(8, 8, 92, 46), (8, 46, 36, 80), (8, 80, 92, 120)])


@pytest.mark.parametrize("gap", [False, True])
def test_a_small_unit_across_a_wall_joins_the_rooms_only_where_the_floor_crosses_it(tmp_path, gap):
    """Passages join the small unit to both rooms' units. Where the wall holds no opening inside
    it, the rooms stay two and each takes the small unit's floor on its side of the wall; where
    the floor crosses the unit through an opening, the three units are one region, whose two
    rooms the wall holds apart (split_cores; without that split, one room)."""
    from semmap_pp.semantic.regions import passage_pairs
    from semmap_pp.semantic.rooms import rooms_of
    sm = two_rooms_and_a_small_unit_across_their_wall(tmp_path, gap)
    assert passage_pairs(sm) == [(1, 2), (2, 3)]
    for rooms, one_region in ((sm.rooms, False), (rooms_of(sm, RoomParams(split_core_m=0.0)), True)):
        labels = rooms.labels
        upper, lower = np.unique(labels[12:60, 12:88]), np.unique(labels[66:116, 12:88])
        assert len(upper) == 1 and len(lower) == 1 and upper[0] > 0 and lower[0] > 0
        if gap and one_region:
            assert upper[0] == lower[0]
            assert [r.units for r in rooms.rooms] == [(1, 2, 3)]
        elif gap:
            assert upper[0] != lower[0]
            assert [r.units for r in rooms.rooms] == [(1, 2, 3), (1, 2, 3)]
        else:
            assert upper[0] != lower[0]
            assert sorted(r.units for r in rooms.rooms) == [(1, 2), (3,)]


def test_a_small_unit_seeds_no_room_of_its_own(tmp_path):
    """A room and, beyond its outer wall, floor seen through a window (rays outside), with a
    small unit (under ``min_room_m2`` inside its band) drawn across the wall: most of its floor
    lies outside, the window beside it. Its passage to the room's unit does not join (the wall
    parts its main piece from the room inside it); it seeds no room, so the floor outside joins
    the room through the window and rooms.png holds the one room, the small unit in none."""
    from semmap_pp.semantic.regions import passage_pairs
    img = np.full((100, 100), 205, np.uint8)
    img[10:60, 10:90] = 254                                  # the room
    img[64:98, 28:80] = 254                                  # rays outside, through the window
    img[60:64, 62:76] = 254
    occ = np.zeros(img.shape, bool)
    occ[8:10, 8:92] = occ[8:62, 8:10] = occ[8:62, 90:92] = True
    occ[60:62, 8:92] = True                                  # the outer wall ...
    occ[60:62, 62:76] = False                                # ... and its window, beside the unit
    img[occ] = 0
    sm = semantic_map_of(tmp_path, img, [(8, 8, 92, 50), (28, 50, 52, 88)])
    assert passage_pairs(sm) == [(1, 2)]
    labels = sm.rooms.labels
    assert [r.units for r in sm.rooms.rooms] == [(1,)]
    room = sm.rooms.rooms[0].id
    assert (labels[12:58, 12:88] == room).all()              # the room ...
    assert (labels[66:96, 30:78] == room).all()              # ... and the floor beyond the window


# --- rooms walled apart under one unit -----------------------------------------------------------

def two_rooms_and_desks(tmp_path: Path) -> Path:
    """A map_server map (0.05 m cells) of two rooms side by side, 3.5 x 3.5 m each, a 0.9 m door
    in the wall between them (beside the far wall: the wall's 2.5 m are a wall line, longer than
    ``object_max_extent``), and in the left room a row of three 0.6 m desks across it with 0.5 m
    passages between them and the walls."""
    img = np.full((80, 160), 205, np.uint8)
    img[5:75, 5:155] = 254
    img[3:5, 3:157] = img[75:77, 3:157] = img[3:77, 3:5] = img[3:77, 155:157] = 0
    img[5:75, 79:81] = 0                   # the wall between the rooms
    img[57:75, 79:81] = 254                # its door
    for c0 in (15, 37, 59):                # the desks, 10-cell passages between them
        img[34:46, c0:c0 + 12] = 0
    Image.fromarray(img).save(tmp_path / "two.pgm")
    (tmp_path / "two.yaml").write_text("image: two.pgm\nresolution: 0.05\norigin: [0.0, 0.0, 0.0]\n"
                                       "negate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.196\n")
    return tmp_path / "two.yaml"


def test_one_unit_over_two_rooms_walled_apart_seeds_two_rooms_but_desks_hold_none_apart(tmp_path):
    """A region (one unit of W*) over two rooms with a door between them seeds a room in each
    (split_cores); the map's walls hold them apart (walls_apart), the desks do not: the room
    with desks across it keeps one core, where taking every non-free cell for a wall cuts it."""
    from types import SimpleNamespace
    from semmap_pp.run.inputs import load_inputs
    from semmap_pp.semantic.rooms import split_cores, walls_apart
    inputs = load_inputs(two_rooms_and_desks(tmp_path))
    sm = SimpleNamespace(frame=inputs.frame, grid=inputs.grid)
    walls = walls_apart(sm)
    assert walls[20, 80] and walls[4, 40] and not walls[40, 20]        # walls, not the desks
    assert not walls[65, 80]                                            # nor the door
    free = inputs.grid.classes == FREE
    seeds = np.where(free, 1, 0)
    split, parent = split_cores(seeds, walls, 0.05, RoomParams())
    assert parent == {2: 1}
    assert split[20, 40] == 1 and split[60, 40] == 1 and split[40, 120] == 2    # above and below the desks
    _, parent_all = split_cores(seeds, ~free, 0.05, RoomParams())
    assert len(parent_all) == 2             # the desks taken for walls: three cores
    assert split_cores(seeds, walls, 0.05, RoomParams(split_core_m=0.0))[1] == {}
    assert split_cores(seeds, walls, 0.05, RoomParams(split_min_m2=50.0))[1] == {}   # cores too small
    labels, rooms = room_labels(free, seeds, np.zeros_like(free), 0.05, RoomParams(), walls_apart=walls)
    assert [r[1] for r in rooms] == [1, 1]                              # two rooms of region 1
    assert labels[40, 20] != labels[40, 120] and labels[65, 80] in (labels[40, 20], labels[40, 120])
    assert (labels[free] > 0).all()
    labels1, rooms1 = room_labels(free, seeds, np.zeros_like(free), 0.05, RoomParams())
    assert len(rooms1) == 1


def test_the_likelihoods_wall_like_cells_are_the_wall_lines_open_walls_reads():
    """semantic_map hands open_walls the likelihood's wall-like cells (made once per map) instead of
    finding the wall lines again: the two are the same cells."""
    from semmap_pp.cells import OCCUPIED
    from semmap_pp.lattice.frame import build_frame_from_classes
    from semmap_pp.synth import generate_floor
    from semmap_pp.target.likelihood import X_WALLLIKE, prepare, wall_like
    model = load_model()
    frame = build_frame_from_classes(generate_floor(3, resolution=0.05).classes, 0.05, model)
    c = frame.cells
    found = wall_like(frame.classes == OCCUPIED, c.object_max_extent, c.wall_line_tolerance, c.wall_line_gap)
    assert found.any()
    assert np.array_equal(prepare(frame, model).xcode == X_WALLLIKE, found)
