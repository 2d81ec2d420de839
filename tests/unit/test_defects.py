"""Topological defects on literal worlds: adjacent rooms with equal or different connecting walls."""

import numpy as np
import pytest

from semmap_pp import world as wm
from semmap_pp.cells import UNIT_TYPES
from semmap_pp.target.defects import count_defects, topological_defects
from semmap_pp.model import load_model

ROOM, CORRIDOR = UNIT_TYPES.index("room"), UNIT_TYPES.index("corridor")
RES, WALL, DIL = 0.1, 1, 1      # 10 cm cells, walls 1 cell thick, adjacency dilation 1 cell


def pair(left, right, t_left=ROOM, t_right=ROOM):
    return wm.add(wm.add(wm.empty(4), 0, left, t_left), 2, right, t_right)


def test_side_by_side_rooms_with_equal_walls_are_no_defect():
    w = pair((0, 0, 20, 10), (0, 9, 20, 30))          # both 20 cells high, sharing column 9
    assert topological_defects(w, RES, WALL, DIL, 0.05) == []


def test_side_by_side_rooms_with_different_walls_are_a_defect():
    w = pair((0, 0, 20, 10), (0, 9, 14, 30))          # 20 vs 14 cells high: 0.6 m apart
    (d,) = topological_defects(w, RES, WALL, DIL, 0.5)
    assert (d.p, d.q) == (0, 2) and d.difference_m == pytest.approx(0.6)
    assert topological_defects(w, RES, WALL, DIL, 0.6) == []        # strictly more than the tolerance


def test_stacked_rooms_compare_widths():
    w = pair((0, 0, 10, 20), (9, 0, 30, 12))          # one above the other: widths 20 vs 12
    (d,) = topological_defects(w, RES, WALL, DIL, 0.5)
    assert d.difference_m == pytest.approx(0.8)


def test_only_room_pairs_count():
    w = pair((0, 0, 20, 10), (0, 9, 14, 30), t_right=CORRIDOR)
    assert topological_defects(w, RES, WALL, DIL, 0.1) == []
    untyped = pair((0, 0, 20, 10), (0, 9, 14, 30), t_left=wm.NO_TYPE)
    assert topological_defects(untyped, RES, WALL, DIL, 0.1) == []


def test_rooms_that_do_not_touch_are_no_defect():
    w = pair((0, 0, 20, 10), (0, 15, 14, 30))         # 5 cells of gap > 2 dilations
    assert topological_defects(w, RES, WALL, DIL, 0.1) == []


def test_count_over_worlds():
    good = pair((0, 0, 20, 10), (0, 9, 20, 30))
    bad = pair((0, 0, 20, 10), (0, 9, 14, 30))
    three = wm.add(bad, 3, (19, 0, 40, 10), ROOM)      # below the left room, same width: no new defect
    assert count_defects([good, bad, three], RES, WALL, DIL, 0.5).tolist() == [0, 1, 1]


def test_model_tolerance_is_twice_the_sale_sigma():
    m = load_model()
    assert m.diagnostics.defect_tolerance_m == pytest.approx(2 * m.prior.sale_sigma_m)


def _model_without_tolerance(tmp_path):
    from semmap_pp import model as M
    text = M.load_model().path.read_text().replace("defect_tolerance_m = 1.0\n", "")
    text = text.replace("sale_sigma_m = 0.5", "sale_sigma_m = 0.3")
    p = tmp_path / "m.toml"
    p.write_text(text)
    return M.load_model(p)


def test_tolerance_defaults_to_twice_sigma_without_the_key(tmp_path):
    m = _model_without_tolerance(tmp_path)
    assert m.diagnostics.defect_tolerance_m == pytest.approx(0.6)
    assert np.isfinite(m.diagnostics.rhat_max)
