"""The main job: an occupancy grid in, the most probable semantic world W* and its diagnostics out.

::

    load_inputs ─► Inputs(grid, model, rules, frame) ─► run_map ─► MapRun(W*, semantic map, summaries)

:func:`run_map` builds the target (:class:`~semmap_pp.target.posterior.Posterior` with the knowledge engine),
one data-driven start world per chain (the first deterministic, the others dispersed), samples the
chains through PyMC with :class:`~semmap_pp.sampler.step.WorldStep`, keeps the best world seen across chains
under the full target, and derives its semantic map. Knowledge is switched on during burn-in once
the world covers ``knowledge.coverage_threshold`` of the free cells (paper: 80 %), so every recorded
draw has the same target. Before that, types come from the geometry class alone.

Rules are read once, at the start: a rule file edited while a run is going does not change the run.
"""

from __future__ import annotations

import functools
import time
from typing import NamedTuple

import numpy as np

from semmap_pp import world as wm
from semmap_pp.lattice.tiles import directions_text, rect_spans
from semmap_pp.run.inputs import Inputs
from semmap_pp.run.lattice_cpr import LatticeCPR
from semmap_pp.run.memory import trim_heap
from semmap_pp.run.results import MapRun, RunSettings, collect_draws
from semmap_pp.run.shared import share, share_fields, shared_folder
from semmap_pp.run.spread import sample_around
from semmap_pp.run.target_factory import TargetFactory, run_target
from semmap_pp.sampler.ascent import add_units, polish, refine_world
from semmap_pp.sampler.kernels import data_from_frame, default_mix
from semmap_pp.sampler.resume import merge_records
from semmap_pp.sampler.sampling import sample_worlds
from semmap_pp.sampler.start_worlds import dispersed_world, start_world
from semmap_pp.semantic.ids import carried_text
from semmap_pp.semantic.rooms import through_door_boxes
from semmap_pp.semantic.semantic_map import semantic_map
from semmap_pp.target.likelihood import prepare, remember
from semmap_pp.target.posterior import Posterior
from semmap_pp.target.walls_inside import walls_inside


#: The kernel data's and the likelihood's lattice-sized arrays (:func:`shared_tables`).
KERNEL_TABLES = ("hcum", "vcum", "free_up", "free_down", "free_left", "free_right")
LIKELIHOOD_TABLES = ("xcode", "xsum")


def start_worlds(inputs: Inputs, chains: int, rng: np.random.Generator, base: wm.World | None = None,
                 data=None) -> list[wm.World]:
    """One start world per chain: the greedy data-driven world (:func:`data_start_world`, or
    ``base`` when given: it does not depend on the seed), then dispersed variants of it drawn
    with ``rng``."""
    clean = data_start_world(inputs, data) if base is None else base
    c = inputs.frame.cells
    worlds = [clean]
    for _ in range(1, chains):
        worlds.append(dispersed_world(rng, clean, inputs.frame.shape, min_side=c.min_side,
                                      spans=rect_spans(inputs.frame)))
    return worlds


def data_start_world(inputs: Inputs, data=None) -> wm.World:
    """The greedy data-driven start world of chain 1, refined by the knowledge-free ascent
    (deterministic: the same for every seed).

    The greedy cover has ``[prior] k_max`` slots (its smallest pieces are left out when they do not
    fit); the start ascent doubles the world's capacity when a split or a birth finds no empty slot
    (:meth:`semmap_pp.sampler.ascent._Ascent.free`: a building with more units than k_max), and W*'s
    polish does the same."""
    frame, model = inputs.frame, inputs.model
    c = frame.cells
    base = start_world(frame.classes, model.prior.k_max, min_side=c.min_side, wall_cells=c.wall,
                       factor=model.sampler.start_factor)
    # keep the start inside the prior's support (sides within [min_side, max_side])
    ok = [s for s in wm.active_slots(base)
          if np.all(np.diff(base.rects[s].reshape(2, 2), axis=0) <= c.max_side)]
    clean = wm.empty(base.capacity)
    for i, s in enumerate(ok):
        clean = wm.add(clean, i, base.rects[s])
    ks = model.kernels
    if ks.start_rounds:  # greedy ascent of the knowledge-free target (semmap_pp/sampler/ascent.py)
        if data is None:   # the caller's kernel data of the same frame and settings, else made here
            data = data_from_frame(frame, ks)
        clean = refine_world(Posterior(frame, model, None), clean, data, rounds=ks.start_rounds)
    return clean


class Started(NamedTuple):
    """What :func:`timed_start_world` makes: the start world, the seconds it took and, when it was
    given the run's shared folder, the run's tables (:func:`make_tables`) it was made with."""

    world: wm.World
    seconds: float
    tables: tuple | None = None


def timed_start_world(inputs: Inputs, folder=None) -> Started:
    """:func:`data_start_world` of ``inputs`` and the seconds it took: what ``semmap map`` hands
    :func:`run_map` as ``start_job``, made in a forked process. With the run's shared ``folder``
    the run's tables are made first, into it (:func:`make_tables`), the start world is made with
    them and they are handed back too (mapped arrays travel as their files' paths), so that the
    run does not make them again; without, the start world has kernel data of its own."""
    tables = make_tables(inputs, folder) if folder is not None else None
    t0 = time.perf_counter()
    world = data_start_world(inputs, None if tables is None else tables[0])
    return Started(world, time.perf_counter() - t0, tables)


#: What the first line of a run's log says it does next (after :func:`map_head`).
BUILDING_STARTS = "building the start worlds"


def map_head(inputs: Inputs) -> str:
    """The head of a run's first log line: the map, its size and its building directions."""
    return (f"map {inputs.grid.source}: {inputs.grid.width}x{inputs.grid.height} cells, "
            f"{directions_text(inputs.frame)}")


def _chain_plan(inputs: Inputs, settings: RunSettings, *, log, resume, starts, base_start, data=None,
                started: Started | None = None):
    """Where the chains start and how long they run, said in the log: ``(first start worlds,
    start worlds, burn-in and draws pm.sample is asked for, schedule, chain starts, history)``,
    for a new run (data-driven or given start worlds) or one that resumes an earlier run; ``data``
    is the run's kernel data, which the start worlds' ascent reuses; ``started``: the data-driven
    start world made elsewhere (:func:`run_map`'s ``start_job``)."""
    head = map_head(inputs)
    if resume is None:
        rng = np.random.default_rng(settings.seed)
        if starts is None:   # minutes on a large map: say so before, and how long after
            if started is None:       # else the caller said it when it began the job
                log(f"{head}; {BUILDING_STARTS}")
            t_start, made = time.perf_counter(), "shared" if base_start is not None else None
            if base_start is None and started is not None:
                base_start, made = started.world, f"{started.seconds:.1f} s"
            starts = start_worlds(inputs, settings.chains, rng, base=base_start, data=data)
            made = made or f"{time.perf_counter() - t_start:.1f} s"
            log(f"start world: {wm.n_units(starts[0])} units ({made})")
        else:
            starts = [starts[i % len(starts)] for i in range(settings.chains)]
            log(f"{head}; start world: {wm.n_units(starts[0])} units (given)")
        first = starts
        pm_tune, pm_draws, schedule, chain_starts = settings.tune, settings.draws, None, None
        history = [None] * settings.chains
    else:
        first, starts = resume.starts, resume.last_worlds()
        schedule = (settings.tune, resume.total_draws)
        chain_starts = resume.chain_starts()
        pm_tune, pm_draws = 0, max(1, resume.remaining())
        history = resume.history
        log(f"{head}; chain 1 resumes from {wm.n_units(starts[0])} units")
    if resume is None:
        log(f"sampling: {settings.chains} chains on {settings.cores} core(s), {settings.tune} burn-in + "
            f"{settings.draws} draws x {settings.n_inner} kernels")
    else:
        log(f"resuming: {settings.chains} chains on {settings.cores} core(s), up to {pm_draws} more draws "
            f"per chain (to {resume.total_draws} in all, {settings.tune} of them burn-in) "
            f"x {settings.n_inner} kernels")
    return first, starts, pm_tune, pm_draws, schedule, chain_starts, history


def _wstar_map(inputs: Inputs, post, best: wm.World, data, *, log, previous_ids, fork: bool = False):
    """The semantic map of W*: ``best`` polished by greedy ascent of the full target ``post``
    (when ``[kernels] polish_rounds``; ``fork``: on two cores, :func:`polish`'s), then given a unit
    over each room that rooms.png finds seen through its door where the target gains by it
    (:func:`_through_door_units`), its units' ids carried over from ``previous_ids``."""
    kernel_settings = inputs.model.kernels
    polished = None
    if kernel_settings.polish_rounds:   # the nearest local maximum of the full target (ascent.py)
        log(f"polishing W* ({wm.n_units(best)} units) by greedy ascent of the full target")
        t_polish, before = time.perf_counter(), post.evaluate(best).total
        best = polish(post, best, data, kernel_settings.polish_rounds, fork=fork)
        polished = (before, time.perf_counter() - t_polish)
    sm = semantic_map(inputs.grid, inputs.frame, post, best, roi=inputs.roi, previous=previous_ids)
    if polished is not None:            # sm.log_posterior is W*'s, evaluated once
        log(f"W* polished by greedy ascent: log posterior {sm.log_posterior - polished[0]:+.1f} "
            f"in {polished[1]:.1f} s")
        sm = _through_door_units(inputs, post, sm, data, log=log, previous_ids=previous_ids)
    if sm.id_record is not None:
        log(carried_text(sm.id_record))
    return sm


def _through_door_units(inputs: Inputs, post, sm, data, *, log, previous_ids):
    """``sm`` with a unit added over each room seen only through its door that no unit covers
    (:func:`~semmap_pp.semantic.rooms.through_door_boxes`), where the target gains by it
    (:func:`~semmap_pp.sampler.ascent.add_units`): a fan of rays into a room is free space the
    kernels' birth table has no box for. The added units are rooms of their own in rooms.png
    (``SemanticMap.through_door``). ``sm`` itself when there is none or none is kept."""
    boxes = through_door_boxes(sm)
    if not boxes:
        return sm
    world, born = add_units(post, sm.world, data, boxes)
    log(f"rooms seen through their door: {len(born)} of {len(boxes)} added to W* as units")
    if not born:
        return sm
    return semantic_map(inputs.grid, inputs.frame, post, world, roi=inputs.roi, previous=previous_ids,
                        through_door=born)


def run_map(inputs: Inputs, settings: RunSettings, *, log=print, callback=None, stop=None,
            budget: float | None = None, resume=None, starts: list | None = None,
            base_start: wm.World | None = None, start_job=None, previous_ids=None, folder=None) -> MapRun:
    """Sample worlds for ``inputs`` and return W*, its semantic map and the convergence report.

    Parameters
    ----------
    callback : callable(dict), optional
        Progress of every draw (:func:`semmap_pp.sampler.step.draw_info`), in this process.
    stop : StopFlag, optional
        Set (by a SIGINT handler) to end sampling early; the draws so far are kept.
    budget : float, optional
        Seconds of sampling wall time (see :func:`semmap_pp.sampler.sampling.sample_worlds`).
    resume : semmap_pp.sampler.resume.ResumeState, optional
        Continue an earlier run: its chains go on from their last worlds and random states, and
        the new draws are appended to the old ones (``settings`` must be the stored ones).
    starts : list of World, optional
        Start worlds of the chains (repeated cyclically) instead of the data-driven ones, e.g. the
        W* of an earlier run, as the paper's Fig. 7 does; not with ``resume``.
    base_start : World, optional
        :func:`data_start_world` of ``inputs``, made earlier (it does not depend on the seed:
        ``semmap stability`` makes it once for all its seeds); the run is the same as without.
    start_job : object with ``result() -> Started``, optional
        :func:`timed_start_world` of ``inputs`` being made elsewhere (``semmap map`` forks a process
        for it before it imports PyMC, ArviZ and matplotlib), with the run's tables when it was
        given ``folder``; asked for before the run makes its tables, and unused with ``resume``,
        ``starts`` or ``base_start``. The run is the same as without; its log leaves out the first
        line (:func:`map_head`, "building the start worlds"), which the caller says when it
        begins the job.
    previous_ids : semmap_pp.plans.world_file.PreviousIds, optional
        The units of an earlier world.json whose ids W*'s units carry over where they are the
        same place (:mod:`semmap_pp.semantic.ids`); W* itself is the same as without.
    folder : path, optional
        The folder of the run's shared tables (:func:`~semmap_pp.run.shared.shared_folder`), made
        by the caller, which gave it to ``start_job`` too; by default one is made for the run.
        Either way it is removed when the run ends.
    """

    with shared_folder(folder) as folder:   # the lattice tables the chains' processes map, not copy
        run = _run_map(inputs, settings, folder, log=log, callback=callback, stop=stop, budget=budget,
                       resume=resume, starts=starts, base_start=base_start, start_job=start_job,
                       previous_ids=previous_ids)
    trim_heap()   # what the search freed, given back before the outputs' images are made
    return run


def make_tables(inputs: Inputs, folder) -> tuple:
    """The run's kernel data and likelihood data, their lattice-sized tables mapped from files of
    ``folder`` (:mod:`semmap_pp.run.shared`): the same values, held once for all processes; the
    likelihood data is what :func:`~semmap_pp.target.likelihood.prepare` gives from now on in
    this process."""
    frame, model = inputs.frame, inputs.model
    data = share_fields(data_from_frame(frame, model.kernels, store=functools.partial(share, folder=folder)),
                        KERNEL_TABLES, folder)
    likelihood = share_fields(prepare(frame, model), LIKELIHOOD_TABLES, folder)
    remember(frame, model, likelihood)
    return data, likelihood


def shared_tables(inputs: Inputs, folder, made: tuple | None = None) -> tuple:
    """The run's kernel data and target factory: :func:`make_tables`, or the tables ``made``
    already (by :func:`timed_start_world` in another process, into the same ``folder``)."""
    if made is None:
        data, likelihood = make_tables(inputs, folder)
    else:
        data, likelihood = made
        remember(inputs.frame, inputs.model, likelihood)
    return data, TargetFactory(inputs.frame, inputs.model, inputs.rules, likelihood)


def _run_map(inputs: Inputs, settings: RunSettings, folder, *, log, callback, stop, budget, resume, starts,
             base_start, start_job, previous_ids) -> MapRun:
    """:func:`run_map` with the shared tables' ``folder``."""
    model, frame = inputs.model, inputs.frame
    kernel_settings = model.kernels
    started = None
    if start_job is not None and resume is None and starts is None and base_start is None:
        started = start_job.result()
    data, factory = shared_tables(inputs, folder, None if started is None else started.tables)
    first, starts, pm_tune, pm_draws, schedule, chain_starts, history = _chain_plan(
        inputs, settings, log=log, resume=resume, starts=starts, base_start=base_start, data=data,
        started=started)
    t0 = time.perf_counter()
    result = sample_worlds(factory, data, starts, draws=pm_draws, tune=pm_tune,
                           chains=settings.chains, cores=settings.cores, n_inner=settings.n_inner,
                           seed=settings.seed, anneal=settings.anneal, mix=default_mix(kernel_settings),
                           cpr_fn=LatticeCPR.from_roi(frame, inputs.roi), resolution=frame.cells.resolution,
                           knowledge_threshold=model.knowledge.coverage_threshold if inputs.rules else None,
                           callback=callback, stop=stop, budget=budget, resume=chain_starts,
                           schedule=schedule)
    seconds = time.perf_counter() - t0
    draw_seconds = tuple(np.asarray(r.stats.get("seconds", ()), float) for r in result.records)
    new_draws = sum(len(r.stats.get("logp", ())) for r in result.records)
    total_kernels = new_draws * settings.n_inner
    records = merge_records(history, result.records)
    kept_chains, n_kept, summaries, sample_stats, report, samples, notes = collect_draws(records, model)
    notes[:0] = inputs.notes

    post = run_target(inputs)
    best = result.best_world if result.best_world is not None else starts[0]
    best_chain = result.best_chain
    if resume is not None:   # W* of the earlier segments may still be the best
        best, best_chain = resume.better_best(best, result.best_logp, best_chain)
    sm = _wstar_map(inputs, post, best, data, log=log, previous_ids=previous_ids,
                    fork=settings.cores > 1)
    rate = total_kernels / seconds if seconds > 0 else 0.0
    swallowed = _walls_inside_note(sm, post, model)
    if swallowed:
        notes.append(swallowed)   # semmap map logs the notes ("note: ...") and report.html lists them
    if result.stopped:
        notes.insert(0, f"{result.stopped}: sampling stopped early after {seconds:.1f} s; kept "
                        f"{len(kept_chains)} chain(s) x {n_kept} draws")
    run = MapRun(inputs, settings, sm.world, sm, summaries, sample_stats, report, samples, seconds,
                 rate, best_chain, notes, result.stopped, records, list(first),
                 (tuple(kept_chains), n_kept), draw_seconds, search_stopped=result.stopped)
    log(f"W*: {sm.units_text()}, log posterior {sm.log_posterior:.1f}, CPR {sm.cpr:.3f} "
        f"(ROI {inputs.roi_name}); sampling {run.timing_text()}")
    if settings.spread_draws > 0:
        # the sample around W* follows unless sampling was stopped early
        planned = not result.stopped and (budget is None or budget > seconds)
        left = None if budget is None else max(budget - (time.perf_counter() - t0), 1.0)
        sample_around(run, factory, data, default_mix(kernel_settings), planned=planned, log=log,
                      stop=stop, budget=left)
    return run


def _walls_inside_note(sm, post, model) -> str | None:
    """A note when a unit of W* holds ``[diagnostics] walls_inside_max`` or more of the map's
    wall-like cells inside its walls (:mod:`semmap_pp.target.walls_inside`), else None."""
    slots = sorted(sm.slot_ids) + sorted(sm.exterior_ids)
    if not slots:
        return None
    share = walls_inside(post.data.xcode, sm.world.rects[slots], post.cells.wall)
    k = int(np.argmax(share))
    if share[k] < model.diagnostics.walls_inside_max or model.diagnostics.walls_inside_max >= 1.0:
        return None                      # 1.0: the note is off
    s = slots[k]
    name = f"unit {sm.slot_ids[s]}" if s in sm.slot_ids else f"exterior unit X{sm.exterior_ids[s]}"
    return (f"{name} holds {100 * share[k]:.0f} % of the map's wall-like cells inside its walls: the "
            f"map probably shows the outside of the building as free space (one unit over everything "
            f"explains it best); mark the outside unknown or crop the map to the building")
