"""Tests of semmap_pp.grid: the pixel rule, every image format and mode, conventions, writing."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from PIL import Image

from semmap_pp.cells import FREE, OCCUPIED, UNKNOWN
from semmap_pp.grid import (OccupancyGrid, classes_to_image, classify, load_map,
                            occupancy_from_grey, ros_values, save_grid, write_map)

F, U, O = int(FREE), int(UNKNOWN), int(OCCUPIED)
DATA = Path(__file__).parents[1] / "data" / "maps"
REAL = Path(__file__).parents[2] / "data" / "maps"


def write_yaml(path: Path, image: str, **keys) -> Path:
    doc = {"image": image, "resolution": 0.05, "origin": "[0.0, 0.0, 0.0]", "negate": 0,
           "occupied_thresh": 0.65, "free_thresh": 0.196}
    doc.update(keys)
    path.write_text("".join(f"{k}: {v}\n" for k, v in doc.items()))
    return path


def pgm_p5(width: int, height: int, maxval: int, samples) -> bytes:
    dtype = ">u2" if maxval > 255 else np.uint8
    return (f"P5\n{width} {height}\n{maxval}\n".encode()
            + np.asarray(samples, dtype=dtype).tobytes())


# --- the pixel rule -----------------------------------------------------------------------------

def test_grey_levels_classify_like_map_server_defaults():
    # 254 (p=0.004) free; 205 (p=0.196078 > 0.196) unknown; 89 (p=0.651) occupied;
    # 90 (p=0.647) unknown; 206 (p=0.192) free.
    grey = np.array([[254.0, 205.0, 89.0, 90.0, 206.0]])
    p = occupancy_from_grey(grey, dtype=np.float64)
    assert classify(p, 0.65, 0.196).tolist() == [[F, U, O, U, F]]


def test_thresholds_are_strict_comparisons():
    # grey 204 gives p = 51/255 = 0.2 exactly: neither "> 0.2" nor "< 0.2".
    p = occupancy_from_grey(np.array([[204.0]]), dtype=np.float64)
    assert p[0, 0] == 0.2
    assert classify(p, 0.2, 0.1).tolist() == [[U]]
    assert classify(p, 0.3, 0.2).tolist() == [[U]]
    assert classify(p, 0.19, 0.1).tolist() == [[O]]


def test_negate_swaps_dark_and_light():
    grey = np.array([[0.0, 255.0]])
    normal = classify(occupancy_from_grey(grey), 0.65, 0.196)
    negated = classify(occupancy_from_grey(grey, negate=True), 0.65, 0.196)
    assert normal.tolist() == [[O, F]]
    assert negated.tolist() == [[F, O]]


def test_transparent_pixels_are_unknown_except_in_raw_mode():
    grey = np.array([[0.0, 0.0, 255.0]])
    alpha = np.array([[255, 0, 0]], dtype=np.uint8)
    for mode in ("trinary", "scale"):
        p = occupancy_from_grey(grey, alpha, mode=mode)
        assert np.isnan(p[0, 1:]).all() and p[0, 0] == 1.0
        assert classify(p, 0.65, 0.196).tolist() == [[O, U, U]]
    # raw ignores alpha: grey 0 is 0 % (free) and 255 is ROS's -1 (unknown).
    p = occupancy_from_grey(grey, alpha, mode="raw")
    assert classify(p, 0.65, 0.196).tolist() == [[F, F, U]]


def test_raw_values_are_percentages():
    grey = np.array([[0.0, 30.0, 50.0, 70.0, 100.0, 101.0, 255.0]])
    p = occupancy_from_grey(grey, mode="raw", dtype=np.float64)
    np.testing.assert_allclose(p[0, :5], [0.0, 0.3, 0.5, 0.7, 1.0])
    assert np.isnan(p[0, 5:]).all()
    assert classify(p, 0.65, 0.196).tolist() == [[F, U, U, O, O, U, U]]
    assert ros_values(p, mode="raw", occupied_thresh=0.65, free_thresh=0.196).tolist() == [
        [0, 30, 50, 70, 100, -1, -1]]


def test_scale_mode_keeps_the_in_between_value():
    # thresholds 0.25 / 0.75: p = 0.5 is half way, map_server gives 1 + 98 * 0.5 = 50;
    # p = 0.25 exactly (grey 191.25) is not "< free_thresh", so it is the lowest scaled value 1.
    grey = np.array([[255.0, 127.5, 0.0, 191.25]])
    p = occupancy_from_grey(grey, mode="scale", dtype=np.float64)
    assert classify(p, 0.75, 0.25).tolist() == [[F, U, O, U]]
    values = ros_values(p, mode="scale", occupied_thresh=0.75, free_thresh=0.25)
    assert values.tolist() == [[0, 50, 100, 1]]
    trinary = ros_values(p, mode="trinary", occupied_thresh=0.75, free_thresh=0.25)
    assert trinary.tolist() == [[0, -1, 100, -1]]


# --- image formats ------------------------------------------------------------------------------

def test_bundled_tiny_yaml_p2_map():
    grid = load_map(DATA / "tiny.yaml")
    assert grid.shape == (4, 5)
    assert grid.classes.tolist() == [
        [F, F, U, U, O],
        [F, F, U, U, O],
        [O, O, O, O, O],
        [U, U, U, U, U],
    ]
    assert grid.resolution == 0.5 and grid.origin == (-1.0, 2.0, 0.0)
    assert grid.image_path == DATA / "tiny.pgm" and grid.source == DATA / "tiny.yaml"
    assert grid.counts() == {"free": 4, "unknown": 9, "occupied": 7}
    assert grid.notes == ()


def test_bundled_rgba_png_uses_colour_mean_and_alpha():
    grid = load_map(DATA / "tiny_rgba.png")
    # white, black, transparent white / grey 205, yellow (mean 170: unknown; a luminance
    # conversion would call it 226 and free), transparent black.
    assert grid.classes.tolist() == [[F, O, U], [U, U, U]]
    assert np.isnan(grid.occupancy[0, 2]) and np.isnan(grid.occupancy[1, 2])
    assert grid.occupancy[1, 1] == pytest.approx(1 / 3, abs=1e-6)
    assert grid.notes and "0.05" in grid.notes[0]


@pytest.mark.parametrize("maxval, samples, expected", [
    (255, [255, 0, 205, 254], [[F, O], [U, F]]),
    (15, [15, 0, 12, 3], [[F, O], [U, O]]),           # 12/15*255 = 204 -> p = 0.2: unknown
])
def test_pgm_p2(tmp_path, maxval, samples, expected):
    text = f"P2\n# comment line\n2 2 # trailing comment\n{maxval}\n" + " ".join(map(str, samples))
    (tmp_path / "m.pgm").write_text(text)
    assert load_map(tmp_path / "m.pgm").classes.tolist() == expected


def test_pgm_p5_8_bit(tmp_path):
    (tmp_path / "m.pgm").write_bytes(pgm_p5(3, 1, 255, [254, 205, 0]))
    grid = load_map(tmp_path / "m.pgm")
    assert grid.classes.tolist() == [[F, U, O]]
    assert grid.image_format == "PGM P5 8-bit (maxval 255)"


def test_pgm_p5_16_bit_scaled_by_maxval(tmp_path):
    # maxval 1000: 1000 is white, 0 black, 800 -> v = 204 -> p = 0.2 (unknown at 0.65/0.196).
    (tmp_path / "m.pgm").write_bytes(pgm_p5(4, 1, 1000, [1000, 0, 800, 990]))
    grid = load_map(tmp_path / "m.pgm")
    assert grid.classes.tolist() == [[F, O, U, F]]
    assert grid.occupancy[0, 2] == pytest.approx(0.2)
    # maxval 65535, big-endian: 0x0100 = 256 is nearly black.
    (tmp_path / "n.pgm").write_bytes(pgm_p5(2, 1, 65535, [65535, 256]))
    assert load_map(tmp_path / "n.pgm").classes.tolist() == [[F, O]]


def test_png_mode_l(tmp_path):
    Image.fromarray(np.array([[254, 205, 0]], np.uint8), "L").save(tmp_path / "m.png")
    assert load_map(tmp_path / "m.png").classes.tolist() == [[F, U, O]]


def test_png_16_bit(tmp_path):
    a = np.array([[65535, 0, 52428]], dtype=np.uint16)   # 52428 -> v = 204 -> p = 0.2
    Image.fromarray(a).save(tmp_path / "m.png")
    grid = load_map(tmp_path / "m.png")
    assert grid.image_format.endswith("16-bit")
    assert grid.classes.tolist() == [[F, O, U]]
    assert grid.occupancy[0, 2] == pytest.approx(0.2, abs=1e-5)


def test_png_mode_la(tmp_path):
    a = np.array([[[255, 255], [0, 255], [0, 0]]], np.uint8)
    Image.fromarray(a, "LA").save(tmp_path / "m.png")
    assert load_map(tmp_path / "m.png").classes.tolist() == [[F, O, U]]


def test_png_mode_rgb(tmp_path):
    a = np.array([[[255, 255, 255], [0, 0, 255], [255, 255, 0]]], np.uint8)
    Image.fromarray(a, "RGB").save(tmp_path / "m.png")
    # blue: mean 85, p = 0.667 > 0.65 occupied; yellow: mean 170, unknown.
    assert load_map(tmp_path / "m.png").classes.tolist() == [[F, O, U]]


def test_png_mode_p_uses_palette_colours_and_transparency(tmp_path):
    im = Image.fromarray(np.array([[0, 1, 2]], np.uint8), "P")
    im.putpalette([0, 0, 0, 255, 255, 255, 255, 255, 255] + [0] * (256 * 3 - 9))
    im.save(tmp_path / "m.png")                      # index 0 black, 1 white: colours, not indices
    assert load_map(tmp_path / "m.png").classes.tolist() == [[O, F, F]]
    im.save(tmp_path / "t.png", transparency=2)      # index 2 transparent -> unknown
    assert load_map(tmp_path / "t.png").classes.tolist() == [[O, F, U]]


def test_yaml_naming_a_png_with_mode_and_negate(tmp_path):
    Image.fromarray(np.array([[0, 255, 128]], np.uint8), "L").save(tmp_path / "m.png")
    write_yaml(tmp_path / "m.yaml", "m.png", negate=1, mode="scale")
    grid = load_map(tmp_path / "m.yaml")
    assert grid.classes.tolist() == [[F, O, U]] and grid.mode == "scale" and grid.negate


def test_raw_mode_through_yaml(tmp_path):
    (tmp_path / "m.pgm").write_bytes(pgm_p5(4, 1, 255, [0, 100, 50, 255]))
    write_yaml(tmp_path / "m.yaml", "m.pgm", mode="raw")
    grid = load_map(tmp_path / "m.yaml")
    assert grid.classes.tolist() == [[F, O, U, U]]
    assert np.isnan(grid.occupancy[0, 3]) and grid.occupancy[0, 1] == 1.0


def test_keywords_override_the_yaml(tmp_path):
    write_yaml(tmp_path / "m.yaml", "m.pgm")
    (tmp_path / "m.pgm").write_bytes(pgm_p5(1, 1, 255, [128]))   # p = 0.498
    assert load_map(tmp_path / "m.yaml").classes.tolist() == [[U]]
    grid = load_map(tmp_path / "m.yaml", occupied_thresh=0.4, resolution=0.2)
    assert grid.classes.tolist() == [[O]] and grid.resolution == 0.2


def test_missing_optional_yaml_keys_take_defaults_with_notes(tmp_path):
    (tmp_path / "m.pgm").write_bytes(pgm_p5(1, 1, 255, [205]))
    (tmp_path / "m.yaml").write_text("image: m.pgm\nresolution: 0.1\n")
    grid = load_map(tmp_path / "m.yaml")
    assert (grid.occupied_thresh, grid.free_thresh, grid.origin) == (0.65, 0.196, (0, 0, 0))
    assert len(grid.notes) == 3


@pytest.mark.parametrize("array, expected", [
    (np.array([[254, 205, 0]], np.uint8), [[F, U, O]]),
    (np.array([[65535, 0]], np.uint16), [[F, O]]),
    (np.array([[0.0, 0.5, 1.0, np.nan]], np.float32), [[F, U, O, U]]),
    (np.array([[False, True]]), [[F, O]]),
])
def test_npy_arrays(tmp_path, array, expected):
    np.save(tmp_path / "m.npy", array)
    assert load_map(tmp_path / "m.npy").classes.tolist() == expected


@pytest.mark.parametrize("array", [
    np.full((3, 4), 205, np.uint8),      # all unknown
    np.full((3, 4), 254, np.uint8),      # all free
    np.zeros((1, 1), np.uint8),          # a single occupied cell
])
def test_degenerate_maps_load(tmp_path, array):
    write_map(tmp_path / "d.yaml", array, 0.05)
    grid = load_map(tmp_path / "d.yaml")
    assert grid.shape == array.shape
    assert sum(grid.counts().values()) == array.size


def test_grid_arrays_are_read_only_copies():
    classes = np.array([[0, 1]], np.uint8)
    grid = OccupancyGrid(classes, np.zeros((1, 2)), 0.1)
    classes[0, 0] = 2
    assert grid.classes[0, 0] == F
    with pytest.raises(ValueError):
        grid.classes[0, 0] = 2
    with pytest.raises(ValueError):
        grid.occupancy[0, 0] = 1.0


# --- cells <-> metres ---------------------------------------------------------------------------

def test_cells_to_metres_by_hand():
    # 4 rows x 3 cols, 0.5 m cells, origin (10, 20): the bottom-left corner of the bottom-left
    # pixel (row 3, col 0) is at (10, 20), so that pixel's centre is at (10.25, 20.25).
    grid = OccupancyGrid(np.zeros((4, 3), np.uint8), np.zeros((4, 3)), 0.5, (10.0, 20.0, 0.0))
    x, y = grid.cells_to_metres([3, 0, -0.5], [0, 2, -0.5])
    np.testing.assert_allclose(x, [10.25, 11.25, 10.0])
    np.testing.assert_allclose(y, [20.25, 21.75, 22.0])     # row -0.5 is the image's top edge
    rows, cols = grid.metres_to_cells([10.25, 11.25], [20.25, 21.75])
    np.testing.assert_allclose(rows, [3, 0])
    np.testing.assert_allclose(cols, [0, 2])


def test_cells_to_metres_with_yaw():
    # Yaw 90 degrees: the image's x axis points along the map's y axis.
    grid = OccupancyGrid(np.zeros((1, 1), np.uint8), np.zeros((1, 1)), 1.0, (0.0, 0.0, math.pi / 2))
    x, y = grid.cells_to_metres(0, 0)
    assert (float(x), float(y)) == pytest.approx((-0.5, 0.5))


@settings(max_examples=50, deadline=None)
@given(st.floats(-50, 50), st.floats(-50, 50), st.floats(-math.pi, math.pi),
       st.floats(0.01, 2.0), st.floats(-5, 30), st.floats(-5, 30))
def test_metres_to_cells_inverts_cells_to_metres(ox, oy, yaw, res, row, col):
    grid = OccupancyGrid(np.zeros((7, 9), np.uint8), np.zeros((7, 9)), res, (ox, oy, yaw))
    r, c = grid.metres_to_cells(*grid.cells_to_metres(row, col))
    assert float(r) == pytest.approx(row, abs=1e-6) and float(c) == pytest.approx(col, abs=1e-6)


# --- writing ------------------------------------------------------------------------------------

def test_classes_to_image_levels():
    out = classes_to_image(np.array([[F, U], [O, F]], np.uint8))
    assert out.dtype == np.uint8 and out.tolist() == [[254, 205], [0, 254]]
    with pytest.raises(ValueError):
        classes_to_image(np.array([[3]], np.uint8))


def test_write_map_files(tmp_path):
    out = write_map(tmp_path / "sub" / "m.yaml", np.array([[254, 0]], np.uint8), 0.1,
                    origin=(1.0, -2.0, 0.5))
    assert out == tmp_path / "sub" / "m.yaml"
    pgm = (tmp_path / "sub" / "m.pgm").read_bytes()
    assert pgm.startswith(b"P5\n") and pgm.endswith(b"\n2 1\n255\n\xfe\x00")
    text = out.read_text()
    assert "image: m.pgm\n" in text and "origin: [1.0, -2.0, 0.5]" in text
    assert sorted(p.name for p in (tmp_path / "sub").iterdir()) == ["m.pgm", "m.yaml"]
    with pytest.raises(ValueError):
        write_map(tmp_path / "x.yaml", np.zeros((2, 2), np.int32), 0.1)


def test_save_grid_round_trip_keeps_classes_whatever_the_thresholds(tmp_path):
    # Loaded with thresholds 0.15 / 0.05, the map_saver grey 205 (p = 0.196) would be occupied;
    # save_grid writes thresholds that read its own grey levels back to the same classes.
    rng = np.random.default_rng(7)
    classes = rng.integers(0, 3, size=(13, 17)).astype(np.uint8)
    grid = OccupancyGrid(classes, np.zeros(classes.shape), 0.05, (3.0, 4.0, 0.1),
                         occupied_thresh=0.15, free_thresh=0.05)
    again = load_map(save_grid(grid, tmp_path / "g.yaml"))
    np.testing.assert_array_equal(again.classes, classes)
    assert again.origin == pytest.approx(grid.origin) and again.resolution == 0.05


def test_save_grid_round_trip_of_a_real_map(tmp_path):
    grid = load_map(REAL / "intel-lab.yaml")
    again = load_map(save_grid(grid, tmp_path / "intel.yaml"))
    np.testing.assert_array_equal(again.classes, grid.classes)


# --- the bundled real maps ----------------------------------------------------------------------

def test_cartesium_map():
    grid = load_map(REAL / "ubremen-cartesium.yaml")
    assert grid.shape == (672, 1237)
    counts = grid.counts()
    # Measured 182992 / 622982 / 25290; the picture shows white rooms, red walls, grey outside.
    assert 160_000 < counts["free"] < 210_000
    assert 580_000 < counts["unknown"] < 660_000
    assert 20_000 < counts["occupied"] < 32_000
    # The rotated building leaves the image corners unexplored.
    assert {int(grid.classes[r, c]) for r in (0, 671) for c in (0, 1236)} == {U}


def test_intel_lab_map():
    grid = load_map(REAL / "intel-lab.yaml")
    assert grid.shape == (587, 586)
    counts = grid.counts()
    # Measured 193628 / 121799 / 28555.
    assert 170_000 < counts["free"] < 215_000
    assert 100_000 < counts["unknown"] < 145_000
    assert 22_000 < counts["occupied"] < 35_000
    assert grid.classes[300, 300] == U          # the unexplored courtyard in the middle
    assert (grid.classes[498:503, 195:206] == F).all()   # the long corridor along the bottom
