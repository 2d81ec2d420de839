"""Tests of semmap_pp.frame: orientation estimate, lattice resampling, coordinate maps."""

import math

import numpy as np
import pytest
from scipy import ndimage

from semmap_pp.cells import FREE, OCCUPIED, UNKNOWN
from semmap_pp.frame import build_frame_from_classes, estimate_orientation
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
    r0, c0, r1, c1 = f.window if f.window is not None else (0, 0, 240, 240)   # the known cells + margin
    assert np.array_equal(f.classes, rooms()[r0:r1, c0:c1])
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


@pytest.mark.parametrize("deg", [0.0, 12.3])
def test_the_lattice_covers_the_known_cells_and_a_margin_not_the_whole_canvas(deg):
    """A map padded with unknown cells (a ROS canvas) gets the same lattice as the map itself once
    both have more than ``crop_margin_m`` of unknown around the known cells: the same cells, the
    same orientation, its image coordinates shifted by the padding."""
    base = np.pad(rooms(), 30, constant_values=UNKNOWN)           # 90 cells around the known ones
    pad = 400
    big = np.pad(base, pad, constant_values=UNKNOWN)
    theta = math.radians(deg)
    f = build_frame_from_classes(base, 0.05, MODEL, theta=theta)
    g = build_frame_from_classes(big, 0.05, MODEL, theta=theta)
    margin = round(MODEL.lattice.crop_margin_m / 0.05)
    assert g.window is not None and g.window[0] == pad + 90 - margin
    assert np.array_equal(f.classes, g.classes)
    assert not (g.outside & ~f.outside).any()    # outside the image: the canvas holds more of it
    rows, cols = np.array([0.0, 10.5, 77.0]), np.array([3.0, 50.25, 120.0])
    xf, yf = f.lattice_to_image(rows, cols)
    xg, yg = g.lattice_to_image(rows, cols)
    assert np.allclose(xg, xf + pad) and np.allclose(yg, yf + pad)
    lat = np.arange(f.classes.size, dtype=np.int32).reshape(f.classes.shape)
    img = g.to_image(lat, fill=-1)
    assert np.array_equal(img[pad:-pad, pad:-pad], f.to_image(lat, fill=-1))
    assert (img[:pad] == -1).all() and (img[-pad:] == -1).all()
    if deg == 0.0:
        assert np.array_equal(g.to_image(g.classes, fill=UNKNOWN), big)


def test_without_a_crop_margin_the_lattice_is_the_whole_image():
    import dataclasses

    model = dataclasses.replace(MODEL, lattice=dataclasses.replace(MODEL.lattice, crop_margin_m=0.0))
    big = np.pad(rooms(), 300, constant_values=UNKNOWN)
    f = build_frame_from_classes(big, 0.05, model, theta=0.0)
    assert f.window is None and f.classes.shape == big.shape
