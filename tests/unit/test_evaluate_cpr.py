"""Cell prediction rate and its region of interest (semmap_pp.evaluate.cpr)."""

import math

import numpy as np
import pytest
from PIL import Image

from semmap_pp.cells import FREE, OCCUPIED, UNKNOWN, W_FREE, W_OBJECT, W_UNKNOWN, W_WALL
from semmap_pp.errors import MapError
from semmap_pp.evaluate.cpr import (closing_radius_cells, cpr, default_roi, disk, load_roi)

F, U, O = int(FREE), int(UNKNOWN), int(OCCUPIED)


def test_cpr_full_table_has_exactly_the_five_design_pairs():
    # Every (input class, world state) pair once: a 3 x 4 grid, rows = input, cols = state.
    inputs = np.repeat(np.array([F, U, O], dtype=np.uint8)[:, None], 4, axis=1)
    states = np.tile(np.array([W_WALL, W_FREE, W_OBJECT, W_UNKNOWN], dtype=np.uint8), (3, 1))
    rate, n = cpr(inputs, states)
    # correct: (F,FREE), (U,OBJECT), (U,UNKNOWN), (O,WALL), (O,OBJECT) -> 5 of 12
    assert n == 12
    assert rate == pytest.approx(5 / 12)
    # Cell by cell, through a one-cell ROI each time.
    expected = {(F, W_FREE), (O, W_WALL), (O, W_OBJECT), (U, W_OBJECT), (U, W_UNKNOWN)}
    for r in range(3):
        for c in range(4):
            roi = np.zeros((3, 4), bool)
            roi[r, c] = True
            one, n1 = cpr(inputs, states, roi)
            assert n1 == 1
            assert one == (1.0 if (int(inputs[r, c]), int(states[r, c])) in expected else 0.0)


def test_cpr_roi_restricts_the_count():
    c = np.array([[F, F, O, U]], dtype=np.uint8)
    w = np.array([[W_FREE, W_WALL, W_WALL, W_FREE]], dtype=np.uint8)
    # whole map: correct F/FREE and O/WALL -> 2/4
    assert cpr(c, w) == (0.5, 4)
    # ROI = last three cells: F/WALL wrong, O/WALL right, U/FREE wrong -> 1/3
    rate, n = cpr(c, w, np.array([[False, True, True, True]]))
    assert n == 3 and rate == pytest.approx(1 / 3)


def test_cpr_empty_roi_is_nan_with_zero_cells():
    c = np.zeros((2, 2), np.uint8)
    rate, n = cpr(c, np.ones((2, 2), np.uint8), np.zeros((2, 2), bool))
    assert n == 0 and math.isnan(rate)


@pytest.mark.parametrize("world, roi", [
    (np.zeros((2, 3), np.uint8), None),                       # shape mismatch with (2, 2)
    (np.full((2, 2), 4, np.uint8), None),                     # world state code 4 does not exist
    (np.zeros((2, 2), np.uint8), np.ones((3, 3), bool)),      # ROI shape mismatch
])
def test_cpr_rejects_inconsistent_inputs(world, roi):
    with pytest.raises(MapError):
        cpr(np.zeros((2, 2), np.uint8), world, roi)


def test_cpr_rejects_unknown_input_code():
    with pytest.raises(MapError):
        cpr(np.full((1, 1), 3, np.uint8), np.zeros((1, 1), np.uint8))


def test_disk_radius_two():
    # x^2 + y^2 <= 4: 13 cells (the 5x5 square minus 12 cells beyond radius 2)
    d = disk(2)
    assert d.shape == (5, 5) and d.sum() == 13
    assert not d[0, 0] and d[0, 2] and d[2, 2]


def test_closing_radius_cells_rounds():
    assert closing_radius_cells(1.0, 0.05) == 20
    assert closing_radius_cells(0.12, 0.05) == 2     # 2.4 -> 2
    with pytest.raises(ValueError):
        closing_radius_cells(1.0, 0.0)


def test_default_roi_keeps_known_cells_at_the_map_border():
    # A map known everywhere: closing must not erode the border (scipy's closing without padding
    # would drop every cell within the radius of the border).
    c = np.full((6, 7), F, np.uint8)
    assert default_roi(c, 2).all()


def test_default_roi_fills_holes_and_bridges_narrow_gaps():
    c = np.full((9, 13), U, np.uint8)
    c[1:8, 1:5] = O
    c[1:8, 8:12] = O          # two known blocks, columns 5, 6, 7 unknown between them
    c[4, 2] = U               # an unknown cell enclosed by known cells: a hole
    r0 = default_roi(c, 0)
    assert r0[4, 2]           # holes are filled even without closing
    assert not r0[4, 5:8].any()
    # Closing with a disk of radius r bridges gaps of up to 2r cells: radius 1 leaves the
    # 3-cell gap open, radius 2 closes it in the inner rows.
    assert not default_roi(c, 1)[4, 5:8].any()
    r2 = default_roi(c, 2)
    assert r2[3:6, 5:8].all()
    # The unknown frame around the blocks stays outside; every known cell is inside.
    assert not r2[0].any() and not r2[:, 0].any() and not r2[:, -1].any()
    assert r2[c != U].all()


def test_default_roi_of_an_unknown_map_is_empty():
    assert not default_roi(np.full((4, 4), U, np.uint8), 3).any()


def test_load_roi_reads_nonzero_as_inside(tmp_path):
    mask = np.array([[0, 255, 0], [7, 0, 0]], dtype=np.uint8)
    Image.fromarray(mask).save(tmp_path / "roi.png")
    assert load_roi(tmp_path / "roi.png", (2, 3)).tolist() == [[False, True, False],
                                                                [True, False, False]]


def test_load_roi_ignores_alpha(tmp_path):
    rgba = np.zeros((1, 2, 4), dtype=np.uint8)
    rgba[..., 3] = 255            # opaque black: outside
    rgba[0, 1, 0] = 9             # a red pixel: inside
    Image.fromarray(rgba, "RGBA").save(tmp_path / "roi.png")
    assert load_roi(tmp_path / "roi.png", (1, 2)).tolist() == [[False, True]]


def test_load_roi_shape_mismatch_and_missing_file_are_map_errors(tmp_path):
    Image.fromarray(np.zeros((2, 3), np.uint8)).save(tmp_path / "roi.png")
    with pytest.raises(MapError, match="roi.png: ROI mask is 3x2 pixels but the map is 4x2"):
        load_roi(tmp_path / "roi.png", (2, 4))
    with pytest.raises(MapError, match="no such file"):
        load_roi(tmp_path / "none.png", (2, 3))
    (tmp_path / "junk.png").write_bytes(b"not an image")
    with pytest.raises(MapError, match="cannot read image"):
        load_roi(tmp_path / "junk.png", (2, 3))


def test_closing_by_distance_transforms_equals_scipys_closing_with_the_disk():
    """closing_disk (linear time) = scipy.ndimage.binary_closing with disk(r) on padded masks."""
    from scipy import ndimage as ndi

    from semmap_pp.evaluate.cpr import closing_disk, disk

    rng = np.random.default_rng(7)
    for _ in range(150):
        h, w = rng.integers(3, 50, 2)
        r = int(rng.integers(1, 9))
        m = np.pad(rng.random((h, w)) < rng.uniform(0.02, 0.6), r + 1)
        inner = (slice(r + 1, -(r + 1)), slice(r + 1, -(r + 1)))
        assert np.array_equal(closing_disk(m, r)[inner], ndi.binary_closing(m, structure=disk(r))[inner])
    assert not closing_disk(np.zeros((5, 5), bool), 2).any()


def test_default_roi_is_the_closing_of_the_whole_map_however_much_unknown_surrounds_it():
    """default_roi works on the known cells' bounding box; the reference closes the whole map,
    padded, with scipy's binary closing and the disk, then fills its holes."""
    from scipy import ndimage as ndi

    rng = np.random.default_rng(11)
    for _ in range(120):
        h, w = rng.integers(5, 70, 2)
        c = np.full((h, w), U, np.uint8)
        for _ in range(int(rng.integers(0, 4))):
            a, b = int(rng.integers(0, h)), int(rng.integers(0, w))
            blob = rng.random((int(rng.integers(1, 15)), int(rng.integers(1, 15)))) < rng.uniform(0.1, 1.0)
            part = c[a:a + blob.shape[0], b:b + blob.shape[1]]
            part[blob[:part.shape[0], :part.shape[1]]] = rng.choice([F, O])
        r = int(rng.integers(0, 6))
        known = c != U
        if r:
            closed = ndi.binary_closing(np.pad(known, r + 1), structure=disk(r))[r + 1:-(r + 1), r + 1:-(r + 1)]
            known = known | closed
        assert np.array_equal(default_roi(c, r), ndi.binary_fill_holes(known))
