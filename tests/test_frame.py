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
    assert f.theta == 0.0 and f.classes.shape == (240, 240) and not f.outside.any()
    assert np.array_equal(f.classes, rooms())


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
