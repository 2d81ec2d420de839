"""The knowledge-set comparison: spread, defects and the table, on literal worlds and a tiny run."""

import dataclasses
import json
import math

import numpy as np
import pytest

from semmap_pp import world as wm
from semmap_pp.cells import FREE, OCCUPIED, UNIT_TYPES, UNKNOWN
from semmap_pp.studies.compare import (ACROSS_QUANTITIES, AcrossSeeds, RuleSetSummary, across_dict, across_table,
                               compare_dict, compare_table, spread_of, summarise, wall_disagreement,
                               wall_spread)
from semmap_pp.evaluate import closing_radius_cells, default_roi
from semmap_pp.lattice.frame import build_frame
from semmap_pp.grid import OccupancyGrid
from semmap_pp.model import load_model

ROOM = UNIT_TYPES.index("room")
MODEL = load_model()


def test_identical_worlds_have_no_spread():
    w = wm.add(wm.empty(2), 0, (0, 0, 6, 6), ROOM)
    assert wall_spread([w, w, w], (10, 10), wall=1) == 0.0


def test_spread_of_two_worlds_differing_in_one_wall():
    a = wm.add(wm.empty(2), 0, (0, 0, 4, 4), ROOM)
    b = wm.add(wm.empty(2), 0, (0, 0, 4, 6), ROOM)
    # a's wall cells: 12 of the 4x4 box; b's: 16 of the 4x6 box. Cells wall in both (p=1): rows 0 and
    # 3 of columns 0..3 and column 0 (10 cells); wall in one only (p=1/2): column 3 rows 1-2 (a), columns
    # 4, 5 of rows 0 and 3 and column 5 rows 1-2 (b) -> 8 cells. Mean p(1-p) = 8 * 0.25 / 18.
    assert wall_spread([a, b], (10, 10), wall=1) == pytest.approx(8 * 0.25 / 18)


def test_wall_disagreement_is_the_area_two_worlds_disagree_on():
    a = wm.add(wm.empty(2), 0, (0, 0, 4, 4), ROOM)
    b = wm.add(wm.empty(2), 0, (0, 0, 4, 6), ROOM)
    assert wall_disagreement([a, a], (10, 10), wall=1, resolution=0.1) == 0.0
    # the 8 cells walled in one world of two (see above): p = 1/2, 2p(1-p) = 1/2, 0.01 m² each
    assert wall_disagreement([a, b], (10, 10), wall=1, resolution=0.1) == pytest.approx(8 * 0.5 * 0.01)


def test_a_rare_excursion_lowers_the_mean_spread_but_raises_the_disagreement():
    # 19 identical worlds and one with a far-away extra room: the excursion adds 12 cells at
    # p = 1/20 to the "ever wall" cells, so the mean over them falls although the worlds agree less.
    a = wm.add(wm.empty(2), 0, (0, 0, 4, 4), ROOM)
    b = wm.add(wm.empty(2), 0, (0, 0, 4, 6), ROOM)
    far = wm.add(a, 1, (20, 20, 24, 24), ROOM)
    base = [a, b] * 10
    shape = (30, 30)
    excursion = base[:-1] + [far]
    assert wall_spread(excursion, shape, 1) < wall_spread(base, shape, 1)
    assert wall_disagreement(excursion, shape, 1, 0.1) > wall_disagreement(base, shape, 1, 0.1)
    # the area counts the new cells: 12 cells at p = 1/20 add 12 * 2 * (1/20) * (19/20) * 0.01 m²
    # (replacing one b by far also moves b's 8 cells from p = 1/2 to 9/20: 8 * 2 * (9/20) * (11/20) * 0.01)
    expected = (12 * 2 * (1 / 20) * (19 / 20) + 8 * 2 * (9 / 20) * (11 / 20)) * 0.01
    assert wall_disagreement(excursion, shape, 1, 0.1) == pytest.approx(expected)


def row(name, defects_best, cpr=0.9, rhat=1.01):
    return RuleSetSummary(name, f"{name}.lp", 5, cpr, -10.0, rhat < 1.05, {"log_posterior": rhat},
                          {"log_posterior": 200.0}, {"log_posterior": math.nan}, 0.1, 20, defects_best,
                          defects_best + 0.5, 1.0)


def test_table_has_one_column_per_rule_set_and_the_defects():
    text = compare_table([row("a", 0), row("b", 3, cpr=0.8, rhat=1.2)])
    lines = text.splitlines()
    assert lines[0] == "| quantity | a | b |"
    assert "| topological defects in W* | 0 | 3 |" in lines
    assert "| CPR of W* | 0.9000 | 0.8000 |" in lines
    assert "| converged | yes | no |" in lines
    assert "| ESS bulk / tail log_posterior | 200 / nan | 200 / nan |" in lines


def test_json_turns_nan_into_null():
    doc = compare_dict([row("a", 1)], map_path="m.yaml", settings={"seed": 3})
    text = json.dumps(doc, allow_nan=False)          # would raise on a NaN
    back = json.loads(text)
    assert back["rule_sets"][0]["ess_tail"]["log_posterior"] is None
    assert back["rule_sets"][0]["defects_best"] == 1 and back["settings"] == {"seed": 3}


def test_spread_of_is_mean_sample_sd_and_range_of_the_finite_values():
    got = spread_of([1.0, 2.0, math.nan, 6.0])
    assert got == {"mean": 3.0, "sd": pytest.approx(math.sqrt(7.0)), "min": 1.0, "max": 6.0, "n": 3}
    one = spread_of([4])
    assert one["mean"] == 4.0 and math.isnan(one["sd"]) and one["n"] == 1
    none = spread_of([math.nan, math.inf])
    assert none["n"] == 0 and all(math.isnan(none[k]) for k in ("mean", "sd", "min", "max"))


def _plan(seed, logp, rects):
    from semmap_pp.studies.stability import SeedPlan
    return SeedPlan(seed, tuple(range(1, len(rects) + 1)), tuple(rects), ("room",) * len(rects), logp, 0.9, 1.0)


def test_across_seeds_sums_up_each_quantity_and_the_agreement_of_the_wstars():
    a, b, c = (0, 0, 10, 10), (0, 10, 10, 20), (10, 0, 20, 20)
    rows = [dataclasses.replace(row("t", d, cpr=p), seconds=s, converged=k)
            for d, p, s, k in ((1, 0.90, 2.0, True), (3, 0.92, 4.0, False), (2, 0.94, math.nan, False))]
    plans = [_plan(7, -10.0, [a, b, c]), _plan(8, -12.0, [a, b]), _plan(9, -11.0, [a, b, c])]
    col = AcrossSeeds.of([7, 8, 9], rows, plans)
    assert col.name == "t" and col.rules == "t.lp" and col.seeds == (7, 8, 9) and col.converged == 1
    assert col.spread("defects_best") == {"mean": 2.0, "sd": 1.0, "min": 1.0, "max": 3.0, "n": 3}
    assert col.spread("cpr")["mean"] == pytest.approx(0.92) and col.spread("seconds")["n"] == 2
    # seed 7's W* is the best; seed 8's lacks unit c: pairwise F1 0.8, 1.0, 0.8
    assert col.reference_seed == 7 and col.reference_units == 3 and col.stable_units == 2
    assert col.mean_unit_f1 == pytest.approx((0.8 + 1.0 + 0.8) / 3)
    text = across_table([col, col])
    lines = text.splitlines()
    assert lines[0] == "| quantity (seeds 7, 8, 9: mean ± sd (min – max)) | t | t |"
    assert "| topological defects in W* | 2.00 ± 1.00 (1.00 – 3.00) | 2.00 ± 1.00 (1.00 – 3.00) |" in lines
    assert "| sampling seconds | 3.0 ± 1.4 (2.0 – 4.0) | 3.0 ± 1.4 (2.0 – 4.0) |" in lines
    assert "| converged | 1 of 3 seeds | 1 of 3 seeds |" in lines
    assert "| units of the best W* found with their type in every other seed's | 2 of 3 (seed 7) | 2 of 3 (seed 7) |" in lines
    assert len(lines) == 2 + 1 + len(ACROSS_QUANTITIES) + 3
    doc = json.loads(json.dumps(across_dict([col]), allow_nan=False))[0]
    assert doc["quantities"]["cpr"]["max"] == pytest.approx(0.94) and doc["stable_units"] == 2
    assert set(doc["quantities"]) == {f for f, _l, _s in ACROSS_QUANTITIES}
    with pytest.raises(ValueError):
        AcrossSeeds.of([7], rows[:1], plans[:1])


def two_rooms_grid():
    c = np.full((60, 120), UNKNOWN, np.uint8)
    c[6:54, 6:114] = OCCUPIED
    c[8:52, 8:58] = FREE
    c[8:52, 60:112] = FREE
    c[20:40, 58:60] = FREE
    return OccupancyGrid(classes=c, occupancy=np.zeros(c.shape, np.float32), resolution=0.05,
                         origin=(0.0, 0.0, 0.0), source=None, image_path=None)


def test_summarise_a_tiny_run():
    from semmap_pp.studies.compare import typed_sampled_worlds
    from semmap_pp.run.inputs import Inputs
    from semmap_pp.run.pipeline import run_map
    from semmap_pp.run.results import RunSettings

    g = two_rooms_grid()
    f = build_frame(g, MODEL)
    roi = default_roi(g.classes, closing_radius_cells(MODEL.evaluate.roi_closing_m, g.resolution))
    inputs = Inputs(g, MODEL, None, f, roi, "default")
    run = run_map(inputs, RunSettings.from_model(MODEL, seed=1, chains=2, cores=1, tune=2, draws=4,
                                                 n_inner=10, spread_draws=0), log=lambda m: None)
    worlds = typed_sampled_worlds(run, 5)
    s = summarise(run, "none", "none.lp", worlds)
    kept = len(run.report.mode_chains()) * (4 - run.report.within_mode.first_draw)  # climbing draws out
    assert s.n_worlds == len(worlds) == min(5, kept)
    assert s.cpr == pytest.approx(run.semantic.cpr) and s.n_units == len(run.semantic.unit_ids)
    assert set(s.rhat) == {q.name for q in run.report.quantities}
    assert 0.0 <= s.wall_spread <= 0.25 and s.defects_best >= 0 and s.defects_mean >= 0
    assert 0.0 <= s.wall_sd_m <= 0.25    # the conditional spread over +- 0.25 m
    assert all((w.types[w.active] >= 0).all() for w in worlds)   # typed as the sampler typed them


def test_conditional_wall_sd_is_the_exact_gibbs_conditional_of_each_wall():
    """Against a brute force over full evaluations: each side of each unit moved by -k..k cells,
    the offsets weighed by exp(log π) (invalid worlds by 0), the standard deviation taken."""
    from semmap_pp.studies.compare import conditional_wall_sd
    from semmap_pp.target.posterior import Posterior

    post = Posterior(build_frame(two_rooms_grid(), MODEL), MODEL, None)
    # a map this clear pins every wall to one position (sd 0); with the evidence per cell scaled
    # down the conditionals spread over several offsets, so that the comparison has content
    post.data = dataclasses.replace(post.data, gain=post.data.gain * 1e-3)
    world = wm.add(wm.add(wm.empty(4), 0, (6, 6, 54, 60)), 1, (6, 58, 54, 114))
    k = 3
    got = conditional_wall_sd(post, world, k)
    offsets = np.arange(-k, k + 1)
    want = []
    for s in (0, 1):
        for side in range(4):
            lp = []
            for o in offsets:
                r = [int(v) for v in world.rects[s]]
                r[side] += int(o)
                lp.append(post.evaluate(wm.replace(world, s, tuple(r))).total)
            p = np.exp(np.array(lp) - max(lp))
            p /= p.sum()
            mean = (p * offsets).sum()
            want.append(math.sqrt((p * (offsets - mean) ** 2).sum()))
    assert got == pytest.approx(np.array(want), abs=1e-9)
    assert got.shape == (8,) and (got >= 0).all() and (got <= k).all()
