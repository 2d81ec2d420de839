"""Tests of semmap_pp.lattice.zones: the building's directions and the zone of every pixel."""

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

from semmap_pp.cells import FREE, OCCUPIED, UNKNOWN
from semmap_pp.grid import load_map
from scipy import ndimage

from semmap_pp.lattice.frame import lattice_orientation
from semmap_pp.lattice.zones import Zones, _both_axes, building_zones, free_regions, wall_directions
from semmap_pp.model import load_model
from semmap_pp.synth import generate_floor

pytestmark = pytest.mark.unit

PARAMS = load_model().lattice
RES = 0.05
T = 0.15            # wall thickness, metres
WINGS = Path(__file__).resolve().parents[1] / "data" / "wings"


def _uv(shape, origin, angle_deg):
    """(u, v) metres of every cell centre in the frame at ``origin`` turned by ``angle_deg``
    (image y down: the frame's u axis runs along (cos, sin) of the angle, as θ's lattice does)."""
    rows, cols = np.mgrid[0:shape[0], 0:shape[1]]
    x, y = (cols + 0.5) * RES - origin[0], (rows + 0.5) * RES - origin[1]
    a = math.radians(angle_deg)
    return x * math.cos(a) + y * math.sin(a), -x * math.sin(a) + y * math.cos(a)


def _box(uv, u0, v0, u1, v1):
    return (uv[0] >= u0) & (uv[0] < u1) & (uv[1] >= v0) & (uv[1] < v1)


def _building(uv, open_ends=()):
    """(walls, [floor of each space]) of a 14 m corridor (|v| <= 1) with three 4 x 4 m rooms on
    each side, a 1 m door into each; ``open_ends``: "w" / "e" leave that corridor end open."""
    spaces = [(0.0, -1.0, 14.0, 1.0)] + [(1.0 + 4 * i, s, 5.0 + 4 * i, s + 4.0)
                                         for i in range(3) for s in (-5.0, 1.0)]
    walls = np.zeros(uv[0].shape, bool)
    floors = []
    for u0, v0, u1, v1 in spaces:
        walls |= _box(uv, u0 - T / 2, v0 - T / 2, u1 + T / 2, v1 + T / 2)
    for i, (u0, v0, u1, v1) in enumerate(spaces):
        f = _box(uv, u0 + T / 2, v0 + T / 2, u1 - T / 2, v1 - T / 2)
        if i:   # the room's door on the corridor
            f |= _box(uv, u0 + 1.5, -1.0 - T if v0 < 0 else 1.0 - T, u0 + 2.5, -1.0 + T if v0 < 0 else 1.0 + T)
        floors.append(f)
    for end, u in (("w", 0.0), ("e", 14.0)):
        if end in open_ends:
            floors[0] |= _box(uv, u - T, -0.9, u + T, 0.9)
    return walls, floors


def two_wings(angle=30.0):
    """Two buildings of rooms (:func:`_building`), the second turned by ``angle`` degrees, joined by
    a 4 m link corridor from the first one's east end: ``(classes, floors of the first,
    floors of the second)``, each a list of one mask per space (the corridor first)."""
    shape = (int(34 / RES), int(42 / RES))
    a_uv = _uv(shape, (2.0, 12.0), 0.0)
    b_origin = (2.0 + 14.0 + 4.0, 12.0)
    b_uv = _uv(shape, b_origin, angle)
    wa, fa = _building(a_uv, "e")
    wb, fb = _building(b_uv, "w")
    link = _box(a_uv, 13.9, -0.9, 18.1, 0.9)
    c = np.full(shape, UNKNOWN, np.uint8)
    c[wa | wb | _box(a_uv, 14.0, -1.0 - T / 2, 18.0, 1.0 + T / 2)] = OCCUPIED
    for f in fa + fb + [link]:
        c[f] = FREE
    return c, [f & (c == FREE) for f in fa], [f & (c == FREE) for f in fb]


def _zone_angle_deg(z: Zones) -> np.ndarray:
    return np.degrees(np.asarray(z.thetas))[z.labels]


def _same_directions(thetas, want_deg, tol=1.0) -> bool:
    """Whether the directions ``thetas`` (radians) are ``want_deg`` (degrees), one each, modulo 90°."""
    got = [math.degrees(t) for t in thetas]
    gap = lambda a, b: abs(math.remainder(a - b, 90.0))
    return len(got) == len(want_deg) and all(min(gap(g, w) for g in got) <= tol for w in want_deg) \
        and all(min(gap(g, w) for w in want_deg) <= tol for g in got)


def _check_form(z: Zones, shape):
    assert isinstance(z.labels, np.ndarray) and z.labels.dtype == np.uint8 and z.labels.shape == shape
    assert not z.labels.flags.writeable
    assert len(z.shares) == len(z.thetas) and math.isclose(sum(z.shares), 1.0)
    assert int(z.labels.max()) < len(z.thetas)
    assert all(-math.pi / 4 < t <= math.pi / 4 for t in z.thetas)


@pytest.mark.parametrize("seed", [1, 6])
def test_a_manhattan_synthetic_floor_is_one_zone_at_theta0_exactly(seed):
    floor = generate_floor(seed)
    theta0 = lattice_orientation(floor.classes, PARAMS)
    z = building_zones(floor.classes, floor.resolution, PARAMS, theta0)
    _check_form(z, floor.classes.shape)
    assert z.thetas == (theta0,) and z.shares == (1.0,)
    assert not z.labels.any()


@pytest.mark.parametrize("angle", [30.0, -45.0, 12.0])
def test_two_wings_give_two_zones_at_their_angles_with_every_room_whole(angle):
    c, rooms_a, rooms_b = two_wings(angle)
    theta0 = lattice_orientation(c, PARAMS)
    z = building_zones(c, RES, PARAMS, theta0)
    _check_form(z, c.shape)
    assert len(z.thetas) == 2 and z.thetas[0] == theta0
    assert _same_directions(z.thetas, (0.0, angle)), z.thetas
    zone = _zone_angle_deg(z)
    for rooms, own in ((rooms_a, 0.0), (rooms_b, angle)):
        free = np.logical_or.reduce(rooms)
        right = np.abs(np.remainder(zone[free] - own + 45.0, 90.0) - 45.0) <= 1.0
        assert right.mean() >= 0.95
        for room in rooms[1:]:         # a room lies whole in one zone: no boundary through it
            assert np.bincount(z.labels[room]).max() >= 0.99 * room.sum()


def _faces(c):
    """The wall faces: occupied cells with a free cell among their eight neighbours."""
    return (c == OCCUPIED) & ndimage.binary_dilation(c == FREE, structure=np.ones((3, 3), bool))


def test_zone_shares_count_the_wall_faces():
    c, _, _ = two_wings()
    z = building_zones(c, RES, PARAMS, lattice_orientation(c, PARAMS))
    faces = _faces(c)
    want = np.bincount(z.labels[faces], minlength=len(z.thetas)) / faces.sum()
    assert np.allclose(z.shares, want)
    assert min(z.shares) >= PARAMS.zone_min_share


@pytest.mark.parametrize("angle", [45.0, 11.0, 6.0])
def test_a_filled_outside_does_not_hide_a_wing(angle):
    """A drawn plan whose outside is filled (ipa's): the occupied cells near the wing's direction
    are a small share of the occupied cells, but the wing's walls are half the building's faces."""
    c, rooms_a, rooms_b = two_wings(angle)
    c[c == UNKNOWN] = OCCUPIED
    occupied = c == OCCUPIED
    rows, cols, local = wall_directions(occupied, RES, PARAMS)
    near = np.abs(np.remainder(np.degrees(local) - angle + 45.0, 90.0) - 45.0) <= PARAMS.off_axis_min_deg
    assert near.sum() < PARAMS.zone_min_share * occupied.sum()      # no zone by the global share
    z = building_zones(c, RES, PARAMS, lattice_orientation(c, PARAMS))
    assert _same_directions(z.thetas, (0.0, angle), tol=0.5), z.thetas
    zone = _zone_angle_deg(z)
    free = np.logical_or.reduce(rooms_b)
    assert (np.abs(np.remainder(zone[free] - angle + 45.0, 90.0) - 45.0) <= 0.5).mean() >= 0.95


def test_a_zone_needs_walls_along_both_of_its_axes():
    """One straight wall at 30 degrees is no part of a building built along 30 degrees; with a
    wall at right angles to it, a room's corner, it is."""
    shape = (200, 200)
    uv = _uv(shape, (2.0, 2.0), 30.0)
    wall = _box(uv, 0.0, 0.0, 6.0, 0.1)
    labels = np.ones(shape, np.uint8)
    thetas = [0.0, math.radians(30.0)]

    def both(mask):
        rows, cols = np.nonzero(mask)
        return _both_axes(rows, cols, np.full(rows.shape, thetas[1]), labels, thetas, 1, RES, PARAMS)

    assert not both(wall)
    assert both(wall | _box(uv, 0.0, 0.0, 0.1, 2.0))
    assert not both(wall | _box(uv, 0.0, 0.0, 0.1, 0.6))             # shorter than zone_min_votes_m


def test_theta0_is_kept_as_given_and_no_share_means_one_zone():
    c, _, _ = two_wings()
    z = building_zones(c, RES, PARAMS, 0.0123)
    assert z.thetas[0] == 0.0123
    off = dataclasses.replace(PARAMS, zone_min_share=0.0)     # a model file without the keys
    z = building_zones(c, RES, off, 0.0)
    assert z.thetas == (0.0,) and not z.labels.any()


def test_a_few_walls_at_another_angle_are_no_zone():
    c, rooms_a, _ = two_wings()
    keep = np.zeros(c.shape, bool)
    keep[:, : int(19 / RES)] = True                  # the first building alone ...
    c = np.where(keep, c, UNKNOWN).astype(np.uint8)
    uv = _uv(c.shape, (3.0, 4.0), 30.0)              # ... and one 3 m wall at 30 degrees
    c[_box(uv, 0.0, 0.0, 3.0, T)] = OCCUPIED
    z = building_zones(c, RES, PARAMS, 0.0)
    assert z.thetas == (0.0,) and not z.labels.any()


@pytest.mark.parametrize("fill", [FREE, UNKNOWN])
def test_a_map_without_occupied_cells_is_one_zone(fill):
    c = np.full((60, 80), fill, np.uint8)
    z = building_zones(c, RES, PARAMS, 0.2)
    _check_form(z, c.shape)
    assert z.thetas == (0.2,) and z.shares == (1.0,)


def test_a_map_without_free_cells_is_one_zone():
    c, _, _ = two_wings()
    c[c == FREE] = UNKNOWN
    z = building_zones(c, RES, PARAMS, 0.0)
    assert z.thetas == (0.0,) and not z.labels.any()


def test_the_pentagon_has_its_five_directions():
    grid = load_map(WINGS / "pentagon.yaml")
    z = building_zones(grid.classes, grid.resolution, PARAMS, lattice_orientation(grid.classes, PARAMS))
    _check_form(z, grid.classes.shape)
    assert _same_directions(z.thetas, (0.0, 72.0, 144.0, 216.0, 288.0)), z.thetas
    assert min(z.shares) > 0.1


def test_free_regions_cut_at_a_doorway_and_not_at_a_wide_opening():
    f = np.zeros((30, 61), bool)
    f[2:28, 2:29] = f[2:28, 32:59] = True
    f[14:17, 29:32] = True                           # a doorway 3 cells wide
    _, n = free_regions(f, 2.0)
    assert n == 2
    f[5:25, 29:32] = True                            # an opening 20 cells wide
    _, n = free_regions(f, 2.0)
    assert n == 1
    assert free_regions(np.zeros((5, 5), bool), 1.0) == (None, 0)


def test_a_wrong_shape_is_refused():
    with pytest.raises(ValueError):
        building_zones(np.zeros((3, 4, 2), np.uint8), RES, PARAMS, 0.0)
