"""The real-gt floors turned (``bench/run.py quality --subset real-gt --turn``): each floor's map and
truth rotated together, the new canvas the map's own unknown grey."""

from pathlib import Path

import numpy as np
import pytest
from PIL import Image

import benchmod
from benchmod import bench_quality as bq

BENCH = Path(__file__).parents[2] / "bench"
REAL_GT = BENCH / "data" / "real-gt"


@pytest.fixture(scope="module")
def turned_maps():
    return benchmod.load("turned_maps")


@pytest.mark.parametrize("name, grey", [("freiburg_building52", 153), ("map17", 205)])
def test_the_new_corners_are_the_maps_own_unknown_grey(turned_maps, name, grey):
    """The freiburg floors' unknown is 153, which a 205 canvas would not be (their thresholds call
    205 free-ish grey); map17's is 205."""
    folder = REAL_GT / name
    img = np.asarray(Image.open(folder / "map.png").convert("L"))
    assert turned_maps.unknown_grey(folder, img) == grey
    out, _, _ = turned_maps.turn(folder, 30.0, np.zeros(img.shape, np.int32))
    assert out[0, 0] == out[-1, -1] == grey
    assert set(np.unique(out)) <= set(np.unique(img))          # no new grey values


def test_map_and_truth_turn_together_and_a_quarter_turn_is_exact(turned_maps):
    from semmap_pp.evaluate import read_segmentation_truth
    folder = REAL_GT / "freiburg_building52"
    truth = read_segmentation_truth(folder / "gt.png", "rose2")
    img = np.asarray(Image.open(folder / "map.png").convert("L"))
    quarter, _, tq = turned_maps.turn(folder, 90.0, truth)
    assert np.array_equal(quarter, np.rot90(img)) and np.array_equal(tq, np.rot90(truth))
    out, meta, labels = turned_maps.turn(folder, 30.0, truth)
    assert meta["image"] == "map.png" and out.shape == labels.shape and out.shape != img.shape
    free = img == 255
    # each room keeps its cells, and they stay on the floor the map saw
    for k in np.unique(truth[truth > 0])[:5]:
        n0, n1 = (truth == k).sum(), (labels == k).sum()
        assert abs(n1 - n0) <= 0.05 * n0
        assert abs((out[labels == k] == 255).mean() - free[truth == k].mean()) < 0.03
    again, _, _ = turned_maps.turn(folder, 30.0, truth)
    assert np.array_equal(again, out)


def test_turn_is_for_the_real_gt_subset_only(capsys):
    import argparse
    parser = argparse.ArgumentParser()
    bq.add_arguments(parser)
    assert parser.parse_args(["--subset", "real-gt", "--turn", "default"]).turn == (15.0, 30.0, 45.0)
    assert parser.parse_args(["--subset", "real-gt", "--turn", "20,-7.5"]).turn == (20.0, -7.5)
    with pytest.raises(SystemExit):
        parser.parse_args(["--subset", "real-gt", "--turn", "twenty"])
    with pytest.raises(SystemExit, match="real-gt only"):
        bq.run(parser.parse_args(["--subset", "partial", "--turn", "15"]))
