"""The real-gt floors at coarser cells (``bench/run.py quality --subset real-gt --pool K``): the
map pooled K x K as the program reads it back, in the same place, and the rooms found on it given
back to the floor's own cells."""

from pathlib import Path

import numpy as np
import pytest

import benchmod
from benchmod import bench_quality as bq

BENCH = Path(__file__).parents[2] / "bench"
REAL_GT = BENCH / "data" / "real-gt"


@pytest.fixture(scope="module")
def pooled_maps():
    return benchmod.load("pooled_maps")


def test_a_block_is_occupied_when_any_cell_is_free_when_half_are(pooled_maps):
    from semmap_pp.cells import FREE as F, OCCUPIED as O, UNKNOWN as U
    c = np.array([[F, F, F, U, U, U, F, F],
                  [F, O, F, U, U, F, U, U],
                  [F, F, U, U, U, U, F, F]], np.uint8)   # the last row: no whole block
    assert pooled_maps.pool_classes(c, 2).tolist() == [[O, F, U, F]]     # 4, 2, 1, 2 of 4 free
    assert pooled_maps.pool_classes(c, 3).tolist() == [[O, U]]


@pytest.mark.parametrize("name", ["freiburg_building52", "map17", "g4s_y2"])
def test_the_pooled_map_reads_back_as_its_pooled_classes_in_the_same_place(pooled_maps, tmp_path, name):
    """freiburg_building52 is saved with its own thresholds and greys (light ones beside its walls,
    which rooms.png counts as floor), map17 as map_server's, g4s_y2 with graded values (cells seen
    free a few times, which rooms.png counts as floor); each pooled
    map reads back (the program's own loader) as the pooled classes, at twice the cell size, the
    top-left corner of the building at the same map-frame point."""
    from semmap_pp.cells import FREE
    from semmap_pp.grid import load_map
    from semmap_pp.semantic.rooms import floor_cells
    folder = REAL_GT / name
    grid = load_map(folder / "map.yaml")
    floor = pooled_maps.write(folder, tmp_path, 2)
    assert np.array_equal(floor, floor_cells(grid))
    coarse = load_map(tmp_path / "map.yaml")
    assert np.array_equal(coarse.classes, pooled_maps.pool_classes(grid.classes, 2, floor))
    by_free = (pooled_maps.pool_classes(grid.classes, 2) == FREE).sum()
    if name == "g4s_y2":     # its graded floor is free at 0.1 m too
        assert (coarse.classes == FREE).sum() > 1.02 * by_free
    elif name == "map17":    # a trinary map: its floor is its free cells
        assert (coarse.classes == FREE).sum() == by_free
    else:                    # the light greys beside freiburg_building52's walls are floor
        assert by_free < (coarse.classes == FREE).sum() < 1.01 * by_free
    assert coarse.resolution == pytest.approx(2 * grid.resolution)
    # the corner of coarse cell (i, j) is the corner of fine cell (2i, 2j)
    for i, j in [(0, 0), (coarse.height - 1, coarse.width - 1), (7, 11)]:
        xc, yc = coarse.cells_to_metres(np.array([i]), np.array([j]))
        xf, yf = grid.cells_to_metres(np.array([2 * i]), np.array([2 * j]))
        step = grid.resolution / 2          # the centres: a coarse cell's lies half a fine cell on
        assert xc[0] == pytest.approx(xf[0] + step) and yc[0] == pytest.approx(yf[0] - step)


def test_rooms_go_back_to_the_cells_each_coarse_cell_pools(pooled_maps):
    labels = np.array([[1, 2, 0], [3, 3, 4]], np.int32)
    up = pooled_maps.upsampled(labels, 2, (5, 7))
    assert up.shape == (5, 7) and up.dtype == labels.dtype
    assert np.array_equal(up[:4, :6], np.kron(labels, np.ones((2, 2), np.int32)))
    assert not up[4].any() and not up[:, 6].any()
    assert pooled_maps.upsampled(labels, 2, (3, 3)).tolist() == [[1, 1, 2], [1, 1, 2], [3, 3, 3]]
    floor = np.ones((5, 7), bool)
    floor[0, 0] = floor[3, 5] = False
    cut = pooled_maps.scored(labels, 2, floor)
    assert cut[0, 0] == 0 and cut[3, 5] == 0 and np.array_equal(cut[floor], up[floor])


def test_pool_applies_to_real_gt_and_not_with_turn():
    import argparse
    parser = argparse.ArgumentParser()
    bq.add_arguments(parser)
    with pytest.raises(SystemExit, match="one at a time"):
        bq.run(parser.parse_args(["--subset", "real-gt", "--turn", "15", "--pool", "2"]))
    with pytest.raises(SystemExit, match="real-gt only"):
        bq.run(parser.parse_args(["--subset", "partial", "--pool", "2"]))
