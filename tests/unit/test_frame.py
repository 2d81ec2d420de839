"""Tests of semmap_pp.lattice.frame: orientation estimate, lattice resampling, coordinate maps."""

import dataclasses
import math

import numpy as np
import pytest
from scipy import ndimage

from semmap_pp.cells import FREE, OCCUPIED, UNKNOWN
from semmap_pp.lattice.frame import build_frame_from_classes, estimate_orientation, off_axis_note, off_axis_walls
from semmap_pp.model import load_model

MODEL = load_model()


def rooms(size=240):
    """Two rooms side by side with 3-cell walls and sparse clutter, axis-aligned."""
    c = np.full((size, size), UNKNOWN, np.uint8)
    c[60:180, 40:200] = FREE
    for r0, c0, r1, c1 in [(60, 40, 180, 200), (60, 40, 180, 120)]:
        c[r0:r0 + 3, c0:c1] = OCCUPIED
        c[r1 - 3:r1, c0:c1] = OCCUPIED
        c[r0:r1, c0:c0 + 3] = OCCUPIED
        c[r0:r1, c1 - 3:c1] = OCCUPIED
    rng = np.random.default_rng(0)
    c[(rng.random(c.shape) < 0.01) & (c == FREE)] = OCCUPIED
    return c


@pytest.mark.parametrize("deg", [0.0, 2.0, -7.0, 12.3, 20.0, -33.0, 44.0])
def test_orientation_of_rotated_rooms_within_half_a_degree(deg):
    # ndimage.rotate turns the picture counter-clockwise on screen (y down): walls at -deg
    img = ndimage.rotate(rooms(), deg, order=0, reshape=True, cval=UNKNOWN, mode="constant")
    theta = math.degrees(estimate_orientation(img, MODEL.lattice))
    assert abs(math.remainder(theta + deg, 90.0)) < 0.5


def test_small_angle_gives_identity_frame():
    f = build_frame_from_classes(rooms(), 0.05, MODEL)
    assert f.theta == 0.0 and not f.outside.any()
    r0, c0 = f.crop[:2] if f.crop is not None else (0, 0)    # the known cells + margin
    assert np.array_equal(f.classes, rooms()[r0:r0 + f.classes.shape[0], c0:c0 + f.classes.shape[1]])
    assert np.array_equal(f.to_image(f.classes, fill=UNKNOWN), rooms())


def test_rotated_lattice_is_axis_aligned_and_round_trips():
    img = ndimage.rotate(rooms(), 20.0, order=0, reshape=True, cval=UNKNOWN, mode="constant")
    f = build_frame_from_classes(img, 0.05, MODEL)
    assert abs(math.degrees(f.theta) + 20.0) < 0.5
    # walls become rows of the lattice: some lattice row is mostly occupied
    occ_rows = (f.classes == OCCUPIED).sum(axis=1)
    assert occ_rows.max() > 0.8 * 160
    # coordinate maps are inverse to each other
    r, c = np.array([3.0, 10.5, 100.0]), np.array([7.0, 0.0, 55.25])
    x, y = f.lattice_to_image(r, c)
    r2, c2 = f.image_to_lattice(x, y)
    assert np.allclose(r, r2) and np.allclose(c, c2)
    # cells outside the image are UNKNOWN and flagged; the four corners are outside
    assert f.outside[0, 0] and f.outside[-1, -1]
    assert np.all(f.classes[f.outside] == UNKNOWN)


def test_to_image_resamples_back():
    img = ndimage.rotate(rooms(), 20.0, order=0, reshape=True, cval=UNKNOWN, mode="constant")
    f = build_frame_from_classes(img, 0.05, MODEL)
    back = f.to_image(f.classes, fill=UNKNOWN)
    assert back.shape == img.shape
    # nearest neighbour twice moves a cell by at most one: most cells come back unchanged
    assert np.mean(back == img) > 0.97


def thin_wall(deg: float, size: int = 200, door: int = 0) -> np.ndarray:
    """Free floor cut in two by a wall one pixel thick through the centre at ``deg`` degrees (an
    8-connected line of pixels, as a laser scan draws it), with a doorway ``door`` pixels wide in
    its middle."""
    c = np.full((size, size), FREE, np.uint8)
    t = math.radians(deg)
    s = np.linspace(-size, size, 4 * size)
    s = s[np.abs(s) >= door / 2]
    x = np.rint(size / 2 + s * math.cos(t)).astype(int)
    y = np.rint(size / 2 + s * math.sin(t)).astype(int)
    ok = (x >= 0) & (x < size) & (y >= 0) & (y < size)
    c[y[ok], x[ok]] = OCCUPIED
    return c


def free_sides(frame) -> int:
    """How many 4-connected parts of free floor larger than a few cells the lattice shows."""
    labels, n = ndimage.label(frame.classes == FREE)
    return int(np.count_nonzero(np.bincount(labels.ravel())[1:] > 100))


CENTRES = dataclasses.replace(MODEL, lattice=dataclasses.replace(MODEL.lattice, wall_samples=1))


@pytest.mark.parametrize("deg", [3.0, 7.0, 15.0, 30.0, 37.0])
def test_a_thin_wall_at_the_lattice_angle_stays_closed(deg):
    """Resampled at its own angle, a wall one pixel thick keeps the floor on its two sides apart
    (the default ``wall_samples`` 2), and leaks through holes when cells read their centres alone."""
    img = thin_wall(deg)
    f = build_frame_from_classes(img, 0.05, MODEL, theta=math.radians(deg))
    assert MODEL.lattice.wall_samples == 2 and f.wall_samples == 2
    assert free_sides(f) == 2
    assert free_sides(build_frame_from_classes(img, 0.05, CENTRES, theta=math.radians(deg))) == 1


@pytest.mark.parametrize("deg", [7.0, 30.0])
def test_closing_the_gaps_leaves_doorways_and_thick_walls_as_they_are(deg):
    """Only cells joining two pieces of a wall are added: a doorway 20 pixels wide keeps its free
    cells (the rooms stay joined), and 3-pixel walls (rooms(), turned) come out as their centres
    read them, but for a few cells where specks lie close."""
    img = thin_wall(deg, door=20)
    a = build_frame_from_classes(img, 0.05, CENTRES, theta=math.radians(deg))
    b = build_frame_from_classes(img, 0.05, MODEL, theta=math.radians(deg))
    assert free_sides(b) == 1
    changed = a.classes != b.classes
    assert changed.any() and np.all(b.classes[changed] == OCCUPIED) and np.array_equal(a.outside, b.outside)
    mid = np.zeros(b.shape, bool)
    r, c = np.rint(b.image_to_lattice(np.array([100.0]), np.array([100.0]))).astype(int).ravel()
    mid[r - 3:r + 4, c - 8:c + 9] = True                        # the doorway: 17 of its 20 cells
    assert not (mid & (b.classes == OCCUPIED)).any()
    walls = ndimage.rotate(rooms(), deg, order=0, reshape=True, cval=UNKNOWN, mode="constant")
    a = build_frame_from_classes(walls, 0.05, CENTRES, theta=-math.radians(deg))
    b = build_frame_from_classes(walls, 0.05, MODEL, theta=-math.radians(deg))
    changed = a.classes != b.classes
    assert np.all(b.classes[changed] == OCCUPIED)
    assert changed.sum() < 0.01 * (a.classes == OCCUPIED).sum()
    z = build_frame_from_classes(rooms(), 0.05, MODEL, theta=0.0)
    assert np.array_equal(z.classes, rooms())                   # the identity frame reads no sub-cell


@pytest.mark.parametrize("deg", [15.0, 30.0])
def test_no_cell_is_added_where_the_image_shows_no_wall_with_floor_on_both_sides(deg):
    """Clutter (scattered specks), a dotted line the image leaves open, and the edge of furniture
    with unknown behind it (floor on one side only) come out as the centres read them."""
    rng = np.random.default_rng(3)
    specks = np.full((200, 200), FREE, np.uint8)       # one in two cells of a 3-pixel grid
    specks[::3, ::3][rng.random((67, 67)) < 0.5] = OCCUPIED
    dotted = thin_wall(deg)
    dotted[:, ::2] = np.where(dotted[:, ::2] == OCCUPIED, FREE, dotted[:, ::2])
    edge = thin_wall(deg)
    below = np.add.outer(np.arange(200) - 100.0, -(np.arange(200) - 100.0) * math.tan(math.radians(deg))) > 0
    edge[below & (edge == FREE)] = UNKNOWN
    for img in (specks, dotted, edge):
        a = build_frame_from_classes(img, 0.05, CENTRES, theta=math.radians(deg))
        b = build_frame_from_classes(img, 0.05, MODEL, theta=math.radians(deg))
        assert np.array_equal(a.classes, b.classes)
    whole = thin_wall(deg)          # the same wall drawn whole, floor on both sides: closed
    a = build_frame_from_classes(whole, 0.05, CENTRES, theta=math.radians(deg))
    b = build_frame_from_classes(whole, 0.05, MODEL, theta=math.radians(deg))
    assert free_sides(a) == 1 and free_sides(b) == 2


def test_rect_vertices_follow_the_rotation():
    f = build_frame_from_classes(np.zeros((10, 20), np.uint8), 0.05, MODEL, theta=0.0)
    v = f.rect_vertices_px((2, 3, 5, 9))
    # continuous pixel frame: the cell box of rows 2..4, cols 3..8 spans x in [3, 9), y in [2, 5)
    assert v.tolist() == [[3.0, 2.0], [9.0, 2.0], [9.0, 5.0], [3.0, 5.0]]
    g = build_frame_from_classes(np.zeros((10, 20), np.uint8), 0.05, MODEL, theta=math.radians(30))
    v = g.rect_vertices_px((2, 3, 5, 9))
    top = v[1] - v[0]                       # the rectangle's top edge runs at +30° in the image
    assert math.isclose(math.degrees(math.atan2(top[1], top[0])), 30.0, abs_tol=1e-9)
    assert math.isclose(np.hypot(*top), 6.0)


def test_metres_follow_map_server():
    f = build_frame_from_classes(np.zeros((4, 3), np.uint8), 0.5, MODEL, origin=(10.0, 20.0, 0.0))
    x, y = f.image_to_metres(0.5, 3.5)   # bottom-left pixel centre (pixel frame: c + 0.5, r + 0.5)
    assert (float(x), float(y)) == (10.25, 20.25)
    x, y = f.image_to_metres(0, 4)       # bottom-left image corner = the map origin
    assert (float(x), float(y)) == (10.0, 20.0)


@pytest.mark.parametrize("deg", [0.0, 12.3, -33.0])
def test_the_lattice_covers_the_known_cells_and_a_margin_not_the_whole_canvas(deg):
    """A map in a large unknown canvas (a ROS map) gets the part of the whole image's lattice that
    covers its known cells and ``crop_margin_m``: the same cells, the same coordinates, a fraction
    of the size; outputs resampled to the image are the same as with the whole lattice."""
    import dataclasses

    whole = dataclasses.replace(MODEL, lattice=dataclasses.replace(MODEL.lattice, crop_margin_m=0.0))
    big = np.pad(rooms(), 400, constant_values=UNKNOWN)
    theta = math.radians(deg)
    f = build_frame_from_classes(big, 0.05, whole, theta=theta)
    g = build_frame_from_classes(big, 0.05, MODEL, theta=theta)
    assert f.crop is None and g.crop is not None and g.crop[2:] == f.classes.shape
    i0, j0 = g.crop[:2]
    hl, wl = g.classes.shape
    assert hl * wl < 0.2 * f.classes.size
    assert np.array_equal(g.classes, f.classes[i0:i0 + hl, j0:j0 + wl])
    assert (f.classes != UNKNOWN).sum() == (g.classes != UNKNOWN).sum()    # every known cell kept
    rows, cols = np.array([0.0, 10.5, 77.0]), np.array([3.0, 50.25, 120.0])
    assert np.allclose(g.lattice_to_image(rows, cols), f.lattice_to_image(rows + i0, cols + j0))
    assert np.allclose(g.rect_vertices_px((5, 7, 60, 90)), f.rect_vertices_px((5 + i0, 7 + j0, 60 + i0, 90 + j0)))
    lat = np.arange(g.classes.size, dtype=np.int32).reshape(g.classes.shape)
    whole_lat = np.full(f.classes.shape, -1, np.int32)
    whole_lat[i0:i0 + hl, j0:j0 + wl] = lat
    assert np.array_equal(g.to_image(lat, fill=-1), f.to_image(whole_lat, fill=-1))
    if deg == 0.0:
        assert np.array_equal(g.to_image(g.classes, fill=UNKNOWN), big)


def test_without_a_crop_margin_the_lattice_is_the_whole_image():
    import dataclasses

    model = dataclasses.replace(MODEL, lattice=dataclasses.replace(MODEL.lattice, crop_margin_m=0.0))
    big = np.pad(rooms(), 300, constant_values=UNKNOWN)
    f = build_frame_from_classes(big, 0.05, model, theta=0.0)
    assert f.crop is None and f.classes.shape == big.shape


def test_a_crop_that_would_keep_most_of_the_lattice_is_not_made():
    from semmap_pp.lattice.frame import CROP_MAX_SHARE, known_window

    c = rooms()                                   # 40-60 unknown cells around the known ones
    win = known_window(c, round(MODEL.lattice.crop_margin_m / 0.05))
    assert win is not None and (win[2] - win[0]) * (win[3] - win[1]) > CROP_MAX_SHARE * c.size
    for deg in (0.0, 12.3):
        f = build_frame_from_classes(c, 0.05, MODEL, theta=math.radians(deg))
        assert f.crop is None


# ------------------------------------------------------------------ walls at another angle

def _side_by_side(*floors):
    """Synthetic floors' classes pasted side by side on unknown cells (one map, several wings)."""
    h = max(f.shape[0] for f in floors)
    out = np.full((h, sum(f.shape[1] for f in floors)), UNKNOWN, np.uint8)
    c0 = 0
    for f in floors:
        out[:f.shape[0], c0:c0 + f.shape[1]] = f
        c0 += f.shape[1]
    return out


@pytest.fixture(scope="module")
def square_wing():
    from semmap_pp.synth import generate_floor
    return generate_floor(3, units=8, rotation_deg=0.0).classes


@pytest.mark.parametrize("deg", [10.0, 30.0, 45.0])
def test_a_wing_at_another_angle_is_found_with_its_angle(square_wing, deg):
    from semmap_pp.synth import generate_floor
    wing = generate_floor(5, units=8, rotation_deg=deg).classes
    both = _side_by_side(square_wing, wing)
    theta = estimate_orientation(both, MODEL.lattice)
    assert abs(math.degrees(theta)) < 0.5                      # the larger wall mass: the square wing
    found = off_axis_walls(both, theta, 0.05, MODEL.lattice)
    assert found.share > 0.25 and found.blocks >= 3
    # where: the blocks lie over the turned wing (the right-hand part), give or take a block
    block = round(MODEL.lattice.off_axis_block_m / 0.05)
    x0, y0, x1, y1 = found.box_px
    assert square_wing.shape[1] - block <= x0 < x1 <= both.shape[1] and 0 <= y0 < y1 <= both.shape[0]
    own = math.degrees(estimate_orientation(wing, MODEL.lattice))
    assert abs(math.remainder(found.angle_deg - own, 90.0)) < 1.0
    # the wing alone has one orientation: nothing off axis
    assert off_axis_walls(wing, math.radians(own), 0.05, MODEL.lattice).share == 0.0


@pytest.mark.slow
@pytest.mark.parametrize("seed, deg", [(0, None), (6, None), (11, None), (4, 20.0)])
def test_a_building_of_one_orientation_has_no_walls_off_axis(seed, deg):
    """Rotated floors and the axis-aligned rooms: no block is off axis, so no note."""
    from semmap_pp.synth import generate_floor
    c = generate_floor(seed, units=10, rotation_deg=deg).classes
    f = build_frame_from_classes(c, 0.05, MODEL)
    assert off_axis_walls(c, f.theta, 0.05, MODEL.lattice).share < 0.05
    assert off_axis_note(c, f, MODEL.lattice) is None
    assert off_axis_walls(rooms(), 0.0, 0.05, MODEL.lattice).share == 0.0


def test_the_note_names_the_share_and_both_angles_and_can_be_switched_off(square_wing):
    from semmap_pp.synth import generate_floor
    both = _side_by_side(square_wing, generate_floor(5, units=8, rotation_deg=30.0).classes)
    f = build_frame_from_classes(both, 0.05, MODEL)
    note = off_axis_note(both, f, MODEL.lattice)
    share = off_axis_walls(both, f.theta, 0.05, MODEL.lattice).share
    x0, y0, x1, y1 = off_axis_walls(both, f.theta, 0.05, MODEL.lattice).box_px
    assert note.startswith(f"{100 * share:.0f} % of the occupied cells lie where the walls run at about -30 deg, "
                           f"not along the lattice's 0.0 deg (a wing built at another angle?), within pixels "
                           f"x {x0}-{x1}, y {y0}-{y1} of the image")
    off = dataclasses.replace(MODEL.lattice, off_axis_note_share=0.0)
    assert off_axis_note(both, f, off) is None
    high = dataclasses.replace(MODEL.lattice, off_axis_note_share=min(1.0, share + 0.01))
    assert off_axis_note(both, f, high) is None


def test_the_run_gets_the_note_and_world_json_s_map_notes_too(tmp_path, square_wing):
    """Two floors at 30 degrees from each other: a lattice each, and no note; with the zones off
    (``zone_min_share = 0``), one lattice and the note, in world.json's map notes too."""
    from semmap_pp.grid import write_map
    from semmap_pp.lattice.tiles import rect_spans
    from semmap_pp.model import DEFAULT_MODEL
    from semmap_pp.run.inputs import load_inputs
    from semmap_pp.synth import generate_floor
    both = _side_by_side(square_wing, generate_floor(5, units=8, rotation_deg=30.0).classes)
    image = np.where(both == FREE, 254, np.where(both == OCCUPIED, 0, 205)).astype(np.uint8)
    wings = write_map(tmp_path / "wings.yaml", image, 0.05)
    tiled = load_inputs(wings)
    assert len(rect_spans(tiled.frame)) == 2 and not [n for n in tiled.notes if "another angle" in n]
    model = tmp_path / "no_zones.toml"
    text = DEFAULT_MODEL.read_text()
    assert "zone_min_share = 0.07\n" in text
    model.write_text(text.replace("zone_min_share = 0.07\n", "zone_min_share = 0.0\n"))
    inputs = load_inputs(wings, model_path=model)
    assert not rect_spans(inputs.frame)
    notes = [n for n in inputs.notes if "another angle" in n]
    assert len(notes) == 1 and notes[0] in inputs.grid.notes      # world.json's map.notes are grid.notes
    one = write_map(tmp_path / "one.yaml", np.where(square_wing == FREE, 254, np.where(
        square_wing == OCCUPIED, 0, 205)).astype(np.uint8), 0.05)
    assert not [n for n in load_inputs(one).notes if "another angle" in n]


@pytest.mark.parametrize("fill", ["occupied", "noise", "empty", "tiny"])
def test_degenerate_maps_have_nothing_off_axis(fill):
    """All occupied (a solid block stacks no sharper at any angle that matters), 30 % random
    clutter, no occupied cell, a map smaller than a block: share 0, no error."""
    rng = np.random.default_rng(0)
    c = {"occupied": np.full((400, 400), OCCUPIED, np.uint8),
         "noise": np.where(rng.random((400, 400)) < 0.3, OCCUPIED, FREE).astype(np.uint8),
         "empty": np.full((400, 400), UNKNOWN, np.uint8),
         "tiny": np.full((10, 10), OCCUPIED, np.uint8)}[fill]
    found = off_axis_walls(c, 0.0, 0.05, MODEL.lattice)
    assert found.share == 0.0 and found.blocks == 0 and math.isnan(found.angle_deg) and found.box_px is None
