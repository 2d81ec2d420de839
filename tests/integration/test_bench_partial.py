"""The partial subset's held-out explorations (``bench/run.py quality --subset partial --held-out``):
the same shares of rooms entered as the first explorations, other seeds, other partial maps."""

from pathlib import Path

import numpy as np
from PIL import Image

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
    img = np.asarray(Image.open(folder / "map.png").convert("L"))
    canvas = 153                                             # freiburg's unknown grey, not 205
    assert np.all((a == img) | (a == canvas)) and (a != canvas).any() and (b != canvas).any()
    assert not np.array_equal(a != canvas, b != canvas)      # another part of the floor seen
    again, _, _ = partial_maps.explore(folder, e, s2, truth)
    assert np.array_equal(again, b)                          # and always the same one


def test_rays_stop_where_the_full_map_never_saw(monkeypatch, tmp_path):
    """A floor whose unknown grey is 153 (the freiburg floors' thresholds): a ray from the room
    stops at the unseen band, and the room beyond it, which the full map shows, stays unseen."""
    monkeypatch.syspath_prepend(str(BENCH))
    import partial_maps
    import yaml
    img = np.full((60, 120), 153, np.uint8)
    img[10:50, 5:115] = 255                  # one free hall ...
    img[10:50, 58:62] = 153                  # ... cut by a band the full map never saw
    img[9, 5:115] = img[50, 5:115] = 0
    Image.fromarray(img).save(tmp_path / "map.png")
    meta = {"image": "map.png", "resolution": 0.05, "origin": [0.0, 0.0, 0.0], "negate": 0,
            "occupied_thresh": 0.45, "free_thresh": 0.03, "mode": "trinary"}
    (tmp_path / "map.yaml").write_text(yaml.safe_dump(meta))
    truth = np.zeros(img.shape, np.int32)
    truth[10:50, 5:58] = 1
    truth[10:50, 62:115] = 2
    part, _, labels = partial_maps.explore(tmp_path, 0.0, 0, truth)
    assert (part[10:50, 10:50] == 255).all()                 # the room the robot drove through
    assert (part[10:50, 63:115] == 153).all() and not (labels == 2).any()
