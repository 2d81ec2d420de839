"""tools/move_costs.py's term-by-term account adds up to the target's own change of log posterior.

The diagnosis of issue 49 (docs/model.md, "What a unit more or less costs at `1 / A`") reads a
move's log acceptance as tempered likelihood + the prior's number and slots + rectangles + SaLe +
the proposal's log ratio; here the terms of a death, a split and a bounding box are checked
against the tempered target's full evaluation on a small map.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

from semmap_pp import world as wm
from semmap_pp.lattice.frame import build_frame_from_classes
from semmap_pp.model import load_model
from semmap_pp.sampler.kernels import data_from_frame
from semmap_pp.target.posterior import Posterior
from semmap_pp.target.tempering import tempered

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "tools"))
import move_costs  # noqa: E402


@pytest.fixture(scope="module")
def small():
    classes = np.full((60, 90), 1, np.uint8)       # unknown around
    classes[5:55, 5:85] = 0                        # free floor
    classes[5:55, 44:46] = 2                       # a wall between two rooms
    classes[5:7, 5:85] = classes[53:55, 5:85] = 2
    classes[5:55, 5:7] = classes[5:55, 83:85] = 2
    model = load_model()
    frame = build_frame_from_classes(classes, 0.05, model, theta=0.0)
    post = Posterior(frame, model)
    w = wm.add(wm.add(wm.empty(8), 0, (5, 5, 55, 46)), 1, (5, 44, 55, 85))
    return post, w, data_from_frame(frame, model.kernels)


@pytest.mark.parametrize("lam", [1.0, 0.05])
def test_the_terms_add_up_to_the_tempered_targets_change(small, lam):
    post, w, data = small
    cold = tempered(post, lam)
    for after, ratio in ((wm.remove(w, 1), -1.5), (wm.add(w, 2, (20, 20, 40, 40)), 0.25),
                         (wm.replace(wm.remove(w, 1), 0, (5, 5, 55, 85)), 0.0)):
        d = move_costs.delta(post, lam, w, after, ratio)
        change = cold.evaluate(after).total - cold.evaluate(w).total
        assert d["tempered_loglik"] + d["n_slots"] + d["rects"] + d["sale"] == pytest.approx(change, abs=1e-6)
        assert d["log_alpha"] == pytest.approx(change + ratio, abs=1e-6)
        assert d["rects"] == pytest.approx(post.log_rect * (after.active.sum() - w.active.sum()))


def test_a_split_reports_its_kernels_log_ratio_and_a_box_merge_its_pair(small):
    post, w, data = small
    split = move_costs.best_split(post, 0.1, w, 0, data)
    assert split is not None and split["rects"] == pytest.approx(post.log_rect)
    boxes = move_costs.box_merges(post, 0.1, w, data.max_side)
    assert [b["pair"] for b in boxes] == [[0, 1]]
    assert boxes[0]["loglik"] < 0          # the box spans the wall between the two rooms
    assert move_costs.box_merges(post, 0.1, w, data.max_side, slack=-0.5) == []
