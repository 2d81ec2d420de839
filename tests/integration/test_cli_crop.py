"""Tests of `semmap crop MAP --box X0 Y0 X1 Y1 --out NAME.yaml`: the pixels of the box, classified
as `semmap map` reads them, with every cell at its old map-frame position."""

from __future__ import annotations

import numpy as np
import pytest

from semmap_pp.cells import FREE, OCCUPIED, UNKNOWN
from semmap_pp.cli import main
from semmap_pp.grid import load_map, write_map
from semmap_pp.grid.write import classes_to_image


@pytest.fixture
def rotated_map(tmp_path):
    """A 30 x 40 map of every class, its origin away from 0 and turned by 0.3 rad."""
    rng = np.random.default_rng(0)
    classes = rng.choice([FREE, UNKNOWN, OCCUPIED], size=(30, 40)).astype(np.uint8)
    return write_map(tmp_path / "m.yaml", classes_to_image(classes), 0.05, origin=(10.0, -20.0, 0.3)), classes


def test_the_crop_holds_the_box_and_keeps_every_cell_where_it_was(tmp_path, rotated_map, capsys):
    path, classes = rotated_map
    out = tmp_path / "wing.yaml"
    assert main(["crop", str(path), "--box", "7", "5", "31", "22", "--out", str(out)]) == 0
    assert capsys.readouterr().out.splitlines()[0] == str(out)
    whole, part = load_map(path), load_map(out)
    np.testing.assert_array_equal(part.classes, classes[5:22, 7:31])
    assert part.resolution == whole.resolution and part.origin[2] == whole.origin[2]
    rows, cols = np.mgrid[0:17, 0:24]
    for a, b in zip(part.cells_to_metres(rows, cols), whole.cells_to_metres(rows + 5, cols + 7)):
        np.testing.assert_allclose(a, b, atol=1e-9)


@pytest.mark.parametrize("box", [["0", "0", "41", "10"], ["5", "5", "5", "10"], ["0", "20", "10", "31"]])
def test_a_box_outside_the_map_is_one_line_naming_the_map_and_nothing_is_written(tmp_path, rotated_map,
                                                                                  capsys, box):
    path, _ = rotated_map
    out = tmp_path / "wing.yaml"
    assert main(["crop", str(path), "--box", *box, "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith(f"semmap: error: {path}: --box {' '.join(box)} is not a non-empty part of the "
                          f"40 x 30 pixel map") and "\n" not in err
    assert not out.exists() and not out.with_suffix(".pgm").exists()


def test_an_existing_crop_is_kept_unless_forced_and_the_out_must_be_a_yaml(tmp_path, rotated_map, capsys):
    path, _ = rotated_map
    out = tmp_path / "wing.yaml"
    args = ["crop", str(path), "--box", "0", "0", "10", "10", "--out", str(out)]
    assert main(args) == 0
    before = out.with_suffix(".pgm").read_bytes()
    assert main(["crop", str(path), "--box", "0", "0", "12", "10", "--out", str(out)]) == 2
    assert "exists (use --force to overwrite)" in capsys.readouterr().err
    assert out.with_suffix(".pgm").read_bytes() == before
    assert main(["crop", str(path), "--box", "0", "0", "12", "10", "--out", str(out), "--force"]) == 0
    assert load_map(out).classes.shape == (10, 12)
    assert main(["crop", str(path), "--box", "0", "0", "12", "10", "--out", str(tmp_path / "w.pgm")]) == 2
    assert "--out must name a .yaml file" in capsys.readouterr().err


def test_a_bare_image_is_cropped_with_the_resolution_loading_assumed_and_says_so(tmp_path, rotated_map, capsys):
    path, classes = rotated_map
    bare = path.with_suffix(".pgm")
    out = tmp_path / "part.yaml"
    assert main(["crop", str(bare), "--box", "0", "0", "10", "10", "--out", str(out)]) == 0
    err = capsys.readouterr().err
    assert err.startswith("note: ") and "0.05" in err
    part = load_map(out)
    assert part.resolution == 0.05 and part.origin == pytest.approx((0.0, 20 * 0.05, 0.0))
    np.testing.assert_array_equal(part.classes, classes[:10, :10])
