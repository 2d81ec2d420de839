"""Readers of ground-truth and prediction files (semmap_pp.evaluate.io)."""

from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from semmap_pp.errors import MapError
from semmap_pp.evaluate.io import (ipa_gt_labels, read_ipa_gt, read_json, read_label_image)

DATA = Path(__file__).parents[1] / "data" / "ipa"
SHARED_IPA = Path("/work/shared/data/ipa-segmentation")


def test_gt_rooms_are_8_connected_and_larger_than_the_minimum():
    img = np.zeros((4, 6), np.uint8)
    img[0:2, 0:2] = 255      # 4 cells
    img[2:4, 2:4] = 255      # 4 cells touching the first block only at a corner -> same room
    img[0:3, 5] = 255        # 3 cells, a separate room
    labels = ipa_gt_labels(img, min_room_cells=0)
    assert labels.max() == 2
    assert labels[0, 0] == labels[3, 3] != labels[0, 5]
    # min_room_cells = 3 keeps the 8-cell room and drops the 3-cell one (it needs > 3)
    kept = ipa_gt_labels(img, min_room_cells=3)
    assert kept.max() == 1 and kept[0, 5] == 0 and kept[3, 3] == 1


def test_gt_white_means_mean_of_rgb_above_250_and_alpha_is_ignored(tmp_path):
    rgba = np.zeros((1, 3, 4), np.uint8)
    rgba[0, 0] = (240, 255, 255, 255)    # mean 250.0 -> not white (luminance would say 250.5)
    rgba[0, 1] = (246, 255, 255, 0)      # mean 252.0 -> white, although fully transparent
    rgba[0, 2] = (251, 251, 251, 255)    # mean 251 -> white
    Image.fromarray(rgba, "RGBA").save(tmp_path / "gt.png")
    labels = read_ipa_gt(tmp_path / "gt.png", min_room_cells=0)
    assert labels.tolist() == [[0, 1, 1]]


def test_gt_without_rooms_is_a_map_error(tmp_path):
    Image.fromarray(np.zeros((5, 5), np.uint8)).save(tmp_path / "black.png")
    with pytest.raises(MapError, match="black.png: no white"):
        read_ipa_gt(tmp_path / "black.png")


def neighbour_pairs(arr, dy, dx):
    """Views (arr[y, x], arr[y + dy, x + dx]) over every position where both exist (dy >= 0)."""
    h, w = arr.shape
    x0, x1 = max(0, -dx), w - max(0, dx)
    return arr[0:h - dy, x0:x1], arr[dy:h, x0 + dx:x1 + dx]


def test_bundled_office_a_ground_truth():
    labels = read_ipa_gt(DATA / "office_a_gt_segmentation.png")
    assert labels.shape == (685, 1194)
    # 27 rooms (measured once with this reader; the checks below make the count meaningful)
    assert labels.max() == 27
    sizes = np.bincount(labels.ravel())[1:]
    assert (sizes > 100).all()
    # The labels are a maximal 8-connected partition of the white cells: two white 8-neighbours
    # of which one is in a room carry the same label.
    img = np.asarray(Image.open(DATA / "office_a_gt_segmentation.png"))
    white = img[..., :3].astype(float).mean(axis=2) > 250
    for dy, dx in ((0, 1), (1, 0), (1, 1), (1, -1)):
        a, b = neighbour_pairs(labels, dy, dx)
        wa, wb = neighbour_pairs(white, dy, dx)
        both = wa & wb & ((a > 0) | (b > 0))
        assert (a[both] == b[both]).all()
    # White cells outside every room are only those of components of <= 100 cells.
    assert white[labels > 0].all()


@pytest.mark.skipif(not SHARED_IPA.is_dir(), reason="shared ipa data not present")
def test_every_shared_ipa_ground_truth_reads():
    files = sorted(SHARED_IPA.glob("*_gt_segmentation.png"))
    assert files
    for f in files:
        labels = read_ipa_gt(f)
        assert labels.max() >= 5, f.name          # every benchmark floor has several rooms


def test_label_images_8_and_16_bit(tmp_path):
    a16 = np.array([[0, 1, 300], [65535, 2, 0]], dtype=np.uint16)
    Image.fromarray(a16).save(tmp_path / "l16.png")
    assert read_label_image(tmp_path / "l16.png").tolist() == a16.astype(int).tolist()
    a8 = np.array([[0, 3], [9, 255]], dtype=np.uint8)
    Image.fromarray(a8).save(tmp_path / "l8.png")
    out = read_label_image(tmp_path / "l8.png")
    assert out.dtype == np.int32 and out.tolist() == [[0, 3], [9, 255]]


def test_colour_label_image_is_a_map_error(tmp_path):
    Image.fromarray(np.zeros((2, 2, 3), np.uint8)).save(tmp_path / "rgb.png")
    with pytest.raises(MapError, match="one channel"):
        read_label_image(tmp_path / "rgb.png")


def test_read_json_errors_name_the_file_and_position(tmp_path):
    (tmp_path / "bad.json").write_text('{"units": [\n  1,\n  ]\n}')
    # Python 3.12's json points at the bracket after the trailing comma (3:3), 3.13's at the comma (2:4)
    with pytest.raises(MapError, match=r"bad.json:(3:3|2:4): not valid JSON"):
        read_json(tmp_path / "bad.json")
    (tmp_path / "bad2.json").write_text('{"units":\n\n   x}')
    with pytest.raises(MapError, match=r"bad2.json:3:4: not valid JSON"):
        read_json(tmp_path / "bad2.json")
    (tmp_path / "list.json").write_text("[]")
    with pytest.raises(MapError, match="top level must be a JSON object"):
        read_json(tmp_path / "list.json")
    with pytest.raises(MapError, match="no such file"):
        read_json(tmp_path / "missing.json")
    (tmp_path / "ok.json").write_text('{"units": []}')
    assert read_json(tmp_path / "ok.json") == {"units": []}
