"""bench_quality.pooled_floor: the synthetic floors as maps of coarser cells (the 0.1 m rows of
docs/quality.md come from it)."""

import numpy as np

from semmap_pp.cells import FREE, OCCUPIED, UNKNOWN
from semmap_pp.evaluate import polygon_mask
from semmap_pp.synth import generate_floor

from benchmod import bench_quality as bq


def test_a_pooled_floor_is_the_same_floor_in_coarser_cells():
    f = generate_floor(3)
    g = bq.pooled_floor(f, 2)
    h, w = f.classes.shape[0] // 2, f.classes.shape[1] // 2
    assert g.classes.shape == (h, w) and g.resolution == 2 * f.resolution
    assert g.truth["resolution"] == g.resolution and (g.truth["height"], g.truth["width"]) == (h, w)
    blocks = [f.classes[i:2 * h:2, j:2 * w:2] for i in (0, 1) for j in (0, 1)]
    occ = np.any([b == OCCUPIED for b in blocks], axis=0)
    n_free = np.sum([b == FREE for b in blocks], axis=0)
    np.testing.assert_array_equal(g.classes == OCCUPIED, occ)
    np.testing.assert_array_equal(g.classes == FREE, ~occ & (n_free >= 2))
    np.testing.assert_array_equal(g.classes == UNKNOWN, ~occ & (n_free < 2))
    # the truth's pixel coordinates halve: each unit covers the same part of the floor
    for u, v in zip(f.truth["units"], g.truth["units"]):
        assert np.allclose(np.asarray(v["corners_px"]) * 2, u["corners_px"])
        assert v["size_m"] == u["size_m"] and v["explored"] == u["explored"]
        fine = polygon_mask(u["corners_px"], f.classes.shape)[:2 * h, :2 * w]
        coarse = polygon_mask(v["corners_px"], (h, w))
        corners = np.asarray(u["corners_px"], float)
        perimeter = np.linalg.norm(np.roll(corners, -1, axis=0) - corners, axis=1).sum()
        assert abs(int(coarse.sum()) * 4 - int(fine.sum())) <= 2 * perimeter   # cells along the edges
    for d, e in zip(f.truth["doors"], g.truth["doors"]):
        assert np.allclose(np.asarray(e["center_px"]) * 2, d["center_px"]) and e["width_m"] == d["width_m"]
    assert f.truth["units"][0]["corners_px"] != g.truth["units"][0]["corners_px"]   # f untouched
    assert bq.pooled_floor(f, 1) is f


def test_a_floor_scanned_at_another_resolution_is_the_same_building():
    """``--resolution 0.1``: the generator scans the same seed's building onto 0.1 m cells."""
    from semmap_pp.knowledge import load_rules
    from semmap_pp.model import load_model
    from semmap_pp.resources import DEFAULT_RULES

    floor, grid, inputs = bq._floor(3, load_model(), load_rules(DEFAULT_RULES), resolution=0.1)
    fine = generate_floor(3)
    assert floor.resolution == grid.resolution == 0.1 and inputs.frame.cells.wall == 2
    assert len(floor.truth["units"]) == len(fine.truth["units"])
    for u, v in zip(fine.truth["units"], floor.truth["units"]):
        assert u["type"] == v["type"] and np.allclose(u["size_m"], v["size_m"], atol=0.1)


def test_bench_stability_counts_every_unit_of_the_best_wstar_once():
    """bench quality --subset stability on one small floor with short runs: the best W*'s units
    are split into those every seed agrees on and the others, each with its matches to the truth."""
    import argparse

    from semmap_pp.knowledge import load_rules
    from semmap_pp.model import load_model
    from semmap_pp.resources import DEFAULT_RULES

    parser = argparse.ArgumentParser()
    bq.add_arguments(parser)
    args = parser.parse_args(["--subset", "stability", "--floors", "1", "--first-floor", "1", "--seeds", "0,1",
                              "--chains", "1", "--cores", "1", "--tune", "2", "--draws", "4", "--n-inner", "10",
                              "--quiet"])
    out = bq.bench_stability(args, load_model(), load_rules(DEFAULT_RULES))
    (row,) = out["rows"]
    assert out["seeds"] == [0, 1] and len(row["units"]) == 2
    best = row["units"][int(np.argmax(row["log_posterior"]))]
    units = out["units"]
    assert units["stable"]["units"] + units["unstable"]["units"] == best
    assert units["stable"]["units"] == row["stable_units"]
    assert all(0 <= v["match_truth"] <= v["units"] for v in units.values())
    assert out["floors_one_plan"] == int(row["mean_unit_f1"] == 1.0)
