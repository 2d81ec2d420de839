import dataclasses

import numpy as np
import pytest

from semmap_pp import world as wm
from semmap_pp.cells import FREE, OCCUPIED, UNKNOWN
from semmap_pp.evaluate import closing_radius_cells, default_roi
from semmap_pp.lattice.frame import build_frame
from semmap_pp.grid import OccupancyGrid
from semmap_pp.sampler.kernels import data_from_frame
from semmap_pp.model import load_model
from semmap_pp.semantic.semantic_map import semantic_map
from semmap_pp.resources import DEFAULT_RULES
from semmap_pp.run.lattice_cpr import LatticeCPR
from semmap_pp.run.target_factory import run_target, TargetFactory
from semmap_pp.target.posterior import Posterior

MODEL = load_model()


def rooms_grid(door=False):
    c = np.full((60, 120), UNKNOWN, np.uint8)
    c[6:54, 6:114] = OCCUPIED
    c[8:52, 8:58] = FREE
    c[8:52, 60:112] = FREE
    if door:
        c[20:40, 58:60] = FREE
    return OccupancyGrid(classes=c, occupancy=np.zeros(c.shape, np.float32), resolution=0.05,
                         origin=(0.0, 0.0, 0.0), source=None, image_path=None)


@pytest.mark.parametrize("rects", [
    [(6, 6, 54, 60), (6, 58, 54, 114)],       # the true world
    [(6, 6, 54, 60)],                          # one room missing
    [(10, 10, 40, 50), (6, 58, 54, 114)],      # one room too small
    [],
])
def test_tally_cpr_equals_image_cpr_without_doors(rects):
    g = rooms_grid()
    f = build_frame(g, MODEL)
    post = Posterior(f, MODEL)
    world = wm.empty(4)
    for i, r in enumerate(rects):
        world = wm.add(world, i, r)
    roi = default_roi(g.classes, closing_radius_cells(MODEL.evaluate.roi_closing_m, g.resolution))
    exact = semantic_map(g, f, post, world, roi=roi).cpr
    proxy = LatticeCPR.from_roi(f, roi)(post.start(world))
    assert proxy == pytest.approx(exact, abs=1e-12)


def test_knowledge_switches_on_in_burn_in_and_stays_on_for_recorded_draws():
    from semmap_pp.knowledge import load_rules
    from semmap_pp.sampler.sampling import sample_worlds

    g = rooms_grid(door=True)
    f = build_frame(g, MODEL)
    factory = TargetFactory(f, MODEL, load_rules(DEFAULT_RULES))
    start = wm.add(wm.empty(4), 0, (6, 6, 54, 60))    # covers about half of the free cells
    data = data_from_frame(f)

    def knowledge_flags(threshold):
        res = sample_worlds(factory, data, [start], draws=4, tune=6, chains=1, cores=1, n_inner=5,
                            seed=3, knowledge_threshold=threshold)
        return np.asarray(res.trace.get_sampler_stats("knowledge", chains=0))

    never = knowledge_flags(1.01)              # coverage can never reach it: on from the first recorded draw
    assert never[:6].tolist() == [0] * 6 and never[6:].tolist() == [1] * 4
    always = knowledge_flags(0.0)
    assert always.tolist() == [1] * 10


def test_run_map_keeps_recorded_worlds():
    from semmap_pp.run.inputs import Inputs
    from semmap_pp.run.pipeline import run_map
    from semmap_pp.run.results import RunSettings, sampled_worlds

    g = rooms_grid(door=True)
    f = build_frame(g, MODEL)
    roi = default_roi(g.classes, closing_radius_cells(MODEL.evaluate.roi_closing_m, g.resolution))
    inputs = Inputs(g, MODEL, None, f, roi, "default")
    run = run_map(inputs, RunSettings.from_model(MODEL, seed=2, chains=2, cores=1, tune=3, draws=5,
                                                 n_inner=10), log=lambda m: None)
    assert run.samples["rects"].shape == (2, 5, MODEL.prior.k_max, 4)
    assert run.summaries["n_units"].shape == (2, 5)
    # the recorded unit counts are those of the recorded worlds
    assert (run.samples["active"].sum(axis=2) == run.summaries["n_units"]).all()
    worlds = sampled_worlds(run, 4)
    assert len(worlds) == 4 and all(wm.is_valid(w, f.shape, f.cells.min_side) for w in worlds)
    # time inside each draw's kernels: one entry per draw (burn-in too), within the wall time
    assert [len(t) for t in run.draw_seconds] == [8, 8]
    inside = np.concatenate(run.draw_seconds)
    assert np.all(inside >= 0) and inside.sum() <= run.seconds
    assert " kernels/s per chain" in run.timing_text()


def test_sampled_worlds_keep_the_types_the_sampler_gave_them():
    """With the rules on, the recorded worlds carry the sampler's types: those that
    Posterior.typing gives each world from scratch (what posterior.png and the posterior
    marginals use). Worlds drawn before the knowledge was on, or asked for a target without
    it, come back untyped, and typed_worlds types them."""
    from semmap_pp.knowledge import load_rules
    from semmap_pp.resources import DEFAULT_RULES
    from semmap_pp.run.inputs import Inputs
    from semmap_pp.run.pipeline import run_map
    from semmap_pp.run.results import RunSettings, sampled_worlds
    from semmap_pp.run.target_factory import run_target
    from semmap_pp.sampler.spread import typed_worlds

    g = rooms_grid(door=True)
    f = build_frame(g, MODEL)
    roi = default_roi(g.classes, closing_radius_cells(MODEL.evaluate.roi_closing_m, g.resolution))
    inputs = Inputs(g, MODEL, load_rules(DEFAULT_RULES), f, roi, "default")
    run = run_map(inputs, RunSettings.from_model(MODEL, seed=2, chains=2, cores=1, tune=3, draws=8,
                                                 n_inner=10), log=lambda m: None)
    post = run_target(inputs)
    assert post.knowledge_on and run.samples["knowledge"].any()
    worlds = sampled_worlds(run, 100, knowledge=True)
    known = run.samples["knowledge"].reshape(-1)
    assert len(worlds) == known.size
    for w, k in zip(worlds, known):
        typed = np.asarray(post.typing(w).world.types)
        if k:
            assert np.array_equal(np.asarray(w.types), typed)
        else:
            assert (np.asarray(w.types) == wm.NO_TYPE).all()
        assert np.array_equal(np.asarray(typed_worlds(post, [w])[0].types), typed)
    # asked for a target without knowledge: only the draws made without it keep their types
    for w, k in zip(sampled_worlds(run, 100, knowledge=False), known):
        assert k == (np.asarray(w.types)[np.asarray(w.active)] == wm.NO_TYPE).all()


def test_timing_text_leaves_compiling_draws_out_of_the_rate():
    from types import SimpleNamespace as NS

    from semmap_pp.run.results import MapRun

    def text(*chains):
        return MapRun.timing_text(NS(seconds=2.0, kernels_per_second=1000.0, settings=NS(n_inner=10),
                                     draw_seconds=chains))

    assert text() == "2.0 s (1,000 kernels/s)"                    # no draws timed (an older run)
    assert text([0.01] * 20) == "2.0 s (1,000 kernels/s); inside the draws 1,000 kernels/s per chain"
    one_slow = text([0.01] * 19 + [1.5])
    assert one_slow.endswith("1,000 kernels/s per chain, after 1 draw of 1.5 s that compiled code on first use")
    # a draw under 0.1 s is never counted as compiling, however slow beside the others
    assert "compiled" not in text([0.0001] * 19 + [0.09])
    assert "after 1 draw of 0.1 s" in text([0.0001] * 19 + [0.11])


def test_run_map_starts_every_chain_from_the_given_world():
    from semmap_pp.run.inputs import Inputs
    from semmap_pp.run.pipeline import run_map
    from semmap_pp.run.results import RunSettings

    g = rooms_grid(door=True)
    f = build_frame(g, MODEL)
    roi = default_roi(g.classes, closing_radius_cells(MODEL.evaluate.roi_closing_m, g.resolution))
    inputs = Inputs(g, MODEL, None, f, roi, "default")
    start = wm.add(wm.add(wm.empty(MODEL.prior.k_max), 0, (6, 6, 54, 60)), 1, (6, 58, 54, 114))
    run = run_map(inputs, RunSettings.from_model(MODEL, seed=2, chains=2, cores=1, tune=0, draws=4,
                                                 n_inner=1), log=lambda m: None, starts=[start])
    assert len(run.starts) == 2
    for s in run.starts:
        assert np.array_equal(s.active, start.active) and np.array_equal(s.rects, start.rects)
    # one kernel per draw: the first recorded world is the start or one edit away from it
    first = run.samples["active"][:, 0].sum(axis=1)
    assert np.all(np.abs(first - 2) <= 1)


def test_w_star_is_polished_by_greedy_ascent_of_the_full_target():
    """A chain that barely moves (one kernel a draw) from a room cut 8 cells short of its walls: with
    ``polish_rounds`` the reported W* is the local maximum the ascent reaches (the room grown to
    its walls), never worse than the best sampled world; with 0 it is the sampled world."""
    import dataclasses

    from semmap_pp.knowledge import load_rules
    from semmap_pp.run.inputs import Inputs
    from semmap_pp.run.pipeline import run_map
    from semmap_pp.run.results import RunSettings

    g = rooms_grid(door=True)
    rules = load_rules(DEFAULT_RULES)
    start = wm.add(wm.add(wm.empty(MODEL.prior.k_max), 0, (6, 6, 46, 60)), 1, (6, 58, 54, 114))
    out = {}
    for rounds in (0, 3):
        model = dataclasses.replace(MODEL, kernels=MODEL.kernels._replace(polish_rounds=rounds))
        f = build_frame(g, model)
        roi = default_roi(g.classes, closing_radius_cells(model.evaluate.roi_closing_m, g.resolution))
        logs = []
        run = run_map(Inputs(g, model, rules, f, roi, "default"),
                      RunSettings.from_model(model, seed=3, chains=1, cores=1, tune=0, draws=4,
                                             n_inner=1), log=logs.append, starts=[start])
        out[rounds] = (run.semantic.log_posterior, run.world, logs)
    (lp0, _, logs0), (lp3, w3, logs3) = out[0], out[3]
    assert lp3 > lp0 + 10
    assert any("W* polished" in m for m in logs3) and not any("W* polished" in m for m in logs0)
    rects = sorted(tuple(int(v) for v in w3.rects[s]) for s in wm.active_slots(w3))
    assert rects == [(6, 6, 54, 60), (6, 58, 54, 114)]


def test_a_unit_over_the_building_and_its_free_surroundings_gets_a_note():
    """The map shows the space around two rooms as free (as a rendering that marks every crossed
    cell free would): one unit over everything holds the rooms' walls inside it, and W* gets a
    note saying what is wrong with the map; the two rooms as units get none."""
    from semmap_pp.run.pipeline import _walls_inside_note

    c = rooms_grid().classes.copy()
    c[c == UNKNOWN] = FREE
    g = OccupancyGrid(classes=c, occupancy=np.zeros(c.shape, np.float32), resolution=0.05,
                      origin=(0.0, 0.0, 0.0), source=None, image_path=None)
    f = build_frame(g, MODEL)
    post = Posterior(f, MODEL)
    roi = default_roi(g.classes, closing_radius_cells(MODEL.evaluate.roi_closing_m, g.resolution))
    everything = wm.add(wm.empty(8), 0, (0, 0, 60, 120))
    note = _walls_inside_note(semantic_map(g, f, post, everything, roi=roi), post, MODEL)
    assert note is not None and note.startswith("unit 1 holds ") and "outside of the building as free" in note
    rooms = wm.add(wm.add(wm.empty(8), 0, (6, 6, 54, 60)), 1, (6, 58, 54, 114))
    assert _walls_inside_note(semantic_map(g, f, post, rooms, roi=roi), post, MODEL) is None
    import dataclasses
    off = dataclasses.replace(MODEL, diagnostics=dataclasses.replace(MODEL.diagnostics, walls_inside_max=1.0))
    assert " holds 100 % " in note        # every wall of the building lies inside it
    assert _walls_inside_note(semantic_map(g, f, post, everything, roi=roi), post, off) is None


def test_the_posterior_spread_is_drawn_from_the_chains_in_the_best_chains_mode():
    """A chain started with one room missing stays thousands of nats below the other (n_inner=1, a
    few draws): the spread figures' worlds come from the other chain only, and sampled_worlds
    draws from the chains it is given."""
    from semmap_pp.run.spread import posterior_worlds
    from semmap_pp.run.inputs import Inputs
    from semmap_pp.run.pipeline import run_map
    from semmap_pp.run.results import RunSettings, sampled_worlds, spread_chains

    g = rooms_grid(door=True)
    f = build_frame(g, MODEL)
    roi = default_roi(g.classes, closing_radius_cells(MODEL.evaluate.roi_closing_m, g.resolution))
    inputs = Inputs(g, MODEL, None, f, roi, "default")
    good = wm.add(wm.add(wm.empty(MODEL.prior.k_max), 0, (6, 6, 54, 60)), 1, (6, 58, 54, 114))
    bad = wm.add(wm.empty(MODEL.prior.k_max), 0, (6, 6, 54, 60))
    run = run_map(inputs, RunSettings.from_model(MODEL, seed=2, chains=2, cores=1, tune=0, draws=6,
                                                 n_inner=1, spread_draws=0), log=lambda m: None,
                  starts=[good, bad])
    lp = run.summaries["log_posterior"]
    assert lp[0].min() - lp[1].max() > 1000          # chain 2 far below: another mode
    assert run.report.mode_chains() == [1] and spread_chains(run) == [0]
    def key(rects, active):
        return str(np.asarray(rects)[np.asarray(active)].tolist())

    chain = [{key(r, a) for r, a in zip(run.samples["rects"][c], run.samples["active"][c])} for c in (0, 1)]
    assert chain[0].isdisjoint(chain[1])
    for c in (0, 1):
        assert {key(w.rects, w.active) for w in sampled_worlds(run, 6, [c])} == chain[c]
    assert len(sampled_worlds(run, 100)) == 12          # all chains by default
    spread = posterior_worlds(run, 100)
    first = run.report.within_mode.first_draw                  # draws in which chain 1 still climbed
    after = {key(r, a) for r, a in zip(run.samples["rects"][0, first:], run.samples["active"][0, first:])}
    assert len(spread) == 6 - first and {key(w.rects, w.active) for w in spread} == after
    # a later first draw: the spread figures' worlds start there
    mode = dataclasses.replace(run.report.within_mode, first_draw=4)
    late = dataclasses.replace(run, report=dataclasses.replace(run.report, within_mode=mode))
    assert [key(w.rects, w.active) for w in posterior_worlds(late, 100)] == \
        [key(r, a) for r, a in zip(run.samples["rects"][0, 4:], run.samples["active"][0, 4:])]
    assert len(sampled_worlds(run, 100, None, 5)) == 2        # draw 6 of each chain


def test_a_map_in_a_larger_unknown_canvas_gives_the_same_world_shifted():
    """A ROS canvas: the same map padded with unknown cells. The lattice covers the known cells and
    the model's crop margin, so the run sees the same lattice: the same W*, log posterior and CPR,
    its pixel coordinates shifted by the padding, and labels.png as big as the input."""
    from semmap_pp.semantic.world_json import world_dict
    from semmap_pp.run.inputs import Inputs
    from semmap_pp.run.pipeline import run_map
    from semmap_pp.run.results import RunSettings

    def run(pad):
        g = rooms_grid(door=True)
        c = np.pad(g.classes, pad, constant_values=UNKNOWN)
        g = OccupancyGrid(classes=c, occupancy=np.zeros(c.shape, np.float32), resolution=0.05,
                          origin=(0.0, 0.0, 0.0), source=None, image_path=None)
        roi = default_roi(g.classes, closing_radius_cells(MODEL.evaluate.roi_closing_m, g.resolution))
        inputs = Inputs(g, MODEL, None, build_frame(g, MODEL), roi, "default")
        r = run_map(inputs, RunSettings.from_model(MODEL, seed=5, chains=1, cores=1, tune=2, draws=4,
                                                   n_inner=5), log=lambda m: None)
        return r, world_dict(r.semantic)

    (a, da), (b, db) = run(100), run(600)
    assert a.semantic.frame.crop is not None and b.semantic.frame.crop is not None
    assert np.array_equal(a.world.rects[a.world.active], b.world.rects[b.world.active])
    assert a.semantic.log_posterior == pytest.approx(b.semantic.log_posterior, abs=1e-6)
    assert a.semantic.cpr == pytest.approx(b.semantic.cpr, abs=1e-12)
    assert len(da["units"]) == len(db["units"]) > 0
    for u, v in zip(da["units"], db["units"]):
        assert np.allclose(np.asarray(v["vertices_px"]), np.asarray(u["vertices_px"]) + 500)
    assert b.semantic.labels_image.shape == (60 + 2 * 600, 120 + 2 * 600)
    assert np.array_equal(b.semantic.labels_image[500:-500, 500:-500], a.semantic.labels_image)


def test_the_sample_around_wstar_starts_there_draws_the_figures_and_never_changes_wstar():
    """With spread_draws > 0, run_map samples again after the search; with one rung (no replica
    exchange) every chain starts at W* (paper Fig. 7). W*, its log posterior and the search's
    draws are those of the run without the sample; the spread figures' worlds come from the
    sample; a run stopped early has none."""
    from semmap_pp.run.spread import posterior_worlds
    from semmap_pp.run.inputs import Inputs
    from semmap_pp.run.pipeline import run_map
    from semmap_pp.run.results import figure_source, RunSettings

    g = rooms_grid(door=True)
    f = build_frame(g, MODEL)
    roi = default_roi(g.classes, closing_radius_cells(MODEL.evaluate.roi_closing_m, g.resolution))
    one_rung = dataclasses.replace(MODEL, sampler=dataclasses.replace(MODEL.sampler, spread_rungs=1))
    inputs = Inputs(g, one_rung, None, f, roi, "default")
    base = dict(seed=3, chains=2, cores=1, tune=2, draws=4, n_inner=10)
    plain = run_map(inputs, RunSettings.from_model(MODEL, **base, spread_draws=0), log=lambda m: None)
    logged = []
    run = run_map(inputs, RunSettings.from_model(MODEL, **base, spread_draws=6, spread_n_inner=5),
                  log=logged.append)
    assert plain.spread is None and figure_source(plain) is plain
    sp = run.spread
    assert figure_source(run) is sp
    # W* and the search are untouched by the sample that follows them
    assert wm.canonical_key(run.world) == wm.canonical_key(plain.world)
    assert run.semantic.log_posterior == plain.semantic.log_posterior
    np.testing.assert_array_equal(run.summaries["log_posterior"], plain.summaries["log_posterior"])
    # every chain of the sample started at W*: its first draw, 5 kernels on, differs from W* in
    # at most the units 5 accepted kernels can change
    assert sp.start_logp == run.semantic.log_posterior
    assert sp.samples["rects"].shape[:2] == (2, 6) and sp.kept == ((0, 1), 6)
    assert sp.summaries["log_posterior"].shape == (2, 6) and sp.report.n_draws == 6
    assert sp.best_logp >= sp.summaries["log_posterior"].max() - 1e-6
    assert sp.best_logp >= sp.start_logp - 1e-6                 # W*, where they started, counts
    # the best world its chains visited is kept (bench --spread-best), and best_logp is its
    # log posterior (tracked at every kernel, not only at the recorded draws)
    assert sp.best_world is not None
    assert run_target(inputs).evaluate(sp.best_world).total == pytest.approx(sp.best_logp, abs=1e-6)
    # bench quality --spread-best scores that world, polished, in W*'s place when it is higher
    from benchmod import bench_quality as bq
    assert bq.spread_best(plain) is plain
    assert bq.spread_best(run) is run or sp.best_logp > sp.start_logp
    # a run whose W* lies below a world its sample visited (here: W* with a unit taken out, and
    # the real W* as the sample's best) gets that world, polished: at least as high
    post = run_target(inputs)
    worse = wm.remove(run.world, int(np.flatnonzero(run.world.active)[0]))
    low = post.evaluate(worse).total
    assert low < run.semantic.log_posterior
    climbed = dataclasses.replace(run, world=worse, semantic=semantic_map(g, f, post, worse, roi=roi),
                                  spread=dataclasses.replace(sp, start_logp=low, best_world=run.world,
                                                             best_logp=run.semantic.log_posterior))
    taken = bq.spread_best(climbed)
    assert taken is not climbed and taken.semantic.log_posterior >= run.semantic.log_posterior - 1e-6
    assert climbed.semantic.log_posterior == low                           # the run given is not changed
    wstar = set(map(tuple, run.world.rects[run.world.active].tolist()))
    for c in range(2):
        first = set(map(tuple, sp.samples["rects"][c, 0][sp.samples["active"][c, 0]].tolist()))
        assert len(first ^ wstar) <= 2 * 5        # at most 5 accepted kernels, each changing a unit or two
    assert any(m.startswith("sample around W* (posterior.png") for m in logged)
    # the spread figures' worlds are the sample's draws after its warm-up cut
    key = lambda rects, active: str(np.asarray(rects)[np.asarray(active)].tolist())   # noqa: E731
    cut = sp.report.within_mode.first_draw
    drawn = {key(w.rects, w.active) for w in posterior_worlds(run, 100)}
    chains = [c - 1 for c in sp.report.mode_chains()]
    assert drawn == {key(r, a) for c in chains for r, a in zip(sp.samples["rects"][c, cut:],
                                                                sp.samples["active"][c, cut:])}
    # a run stopped early keeps the search's draws for the figures and says so
    early = run_map(inputs, RunSettings.from_model(MODEL, **(base | dict(draws=50)), spread_draws=6),
                    log=lambda m: None, budget=1e-6)        # each chain stops after 4 draws
    assert early.stopped == "budget" and early.spread is None and figure_source(early) is early
    # Ctrl-C as the sample around W* begins (or while W* is polished): W* is kept, the run counts
    # as interrupted, and the figures use the search's draws
    from semmap_pp.sampler.step import StopFlag
    for when in ("polishing W*", "sampling around W*"):
        stop = StopFlag()

        def log(msg, when=when, stop=stop):
            if msg.startswith(when):
                stop.set("interrupted")

        cut = run_map(inputs, RunSettings.from_model(MODEL, **base, spread_draws=50), log=log, stop=stop)
        assert cut.spread is None and cut.stopped == "interrupted" and figure_source(cut) is cut
        assert cut.search_complete and not early.search_complete and run.search_complete
        assert cut.report.within_mode.figures and not run.report.within_mode.figures
        assert wm.canonical_key(cut.world) == wm.canonical_key(plain.world)
        assert any(n.startswith("no sample around W*: ") for n in cut.notes)
    assert any(n.startswith("no sample around W*: sampling stopped early") for n in early.notes)
