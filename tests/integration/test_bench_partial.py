"""The partial subset's held-out explorations (``bench/run.py quality --subset partial --held-out``):
the same shares of rooms entered as the first explorations, other seeds, other partial maps."""

from pathlib import Path

import numpy as np

from benchmod import bench_quality as bq

BENCH = Path(__file__).parents[2] / "bench"


def test_held_out_explorations_enter_the_same_shares_with_other_seeds_and_see_other_cells(monkeypatch):
    monkeypatch.syspath_prepend(str(BENCH))
    import partial_maps
    from semmap_pp.evaluate import read_segmentation_truth
    first, held = bq.partial_explorations(False), bq.partial_explorations(True)
    assert [e for e, _, _ in first] == [e for e, _, _ in held]
    assert not {s for _, s, _ in first} & {s for _, s, _ in held}
    assert all(s >= bq.HELD_OUT_FIRST for _, s, _ in held)
    assert [x for _, _, x in first] == ["", ""] and len({x for _, _, x in held}) == 2
    folder = BENCH / "data" / "real-gt" / "freiburg_building52"
    truth = read_segmentation_truth(folder / "gt.png", "rose2")
    (e, s, _), (_, s2, _) = first[0], held[0]
    a, _, ta = partial_maps.explore(folder, e, s, truth)
    b, _, tb = partial_maps.explore(folder, e, s2, truth)
    assert (a != 205).any() and (b != 205).any()
    assert not np.array_equal(a != 205, b != 205)            # another part of the floor seen
    again, _, _ = partial_maps.explore(folder, e, s2, truth)
    assert np.array_equal(again, b)                          # and always the same one
