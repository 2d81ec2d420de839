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

import math
import os
import time
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from semmap_pp import world as wm
from semmap_pp.errors import MapError, ModelError, SemmapError
from semmap_pp.evaluate import closing_radius_cells, default_roi, load_roi
from semmap_pp.grid import MAX_CELLS, OccupancyGrid, load_map
from semmap_pp.grid.outside import clear_outside
from semmap_pp.knowledge import KnowledgeEngine, load_rules
from semmap_pp.lattice.frame import Frame, build_frame, off_axis_note
from semmap_pp.model import Model, load_model
from semmap_pp.resources import DEFAULT_RULES
from semmap_pp.sampler.ascent import polish, refine_world
from semmap_pp.sampler.diagnostics import SUMMARIES, ConvergenceReport, convergence
from semmap_pp.sampler.kernels import data_from_frame, default_mix
from semmap_pp.sampler.resume import keep_common_draws, merge_records
from semmap_pp.sampler.sampling import sample_worlds
from semmap_pp.sampler.spread import typed_worlds
from semmap_pp.sampler.start_worlds import dispersed_world, start_world
from semmap_pp.semantic.ids import carried_text
from semmap_pp.semantic.semantic_map import SemanticMap, semantic_map
from semmap_pp.target.likelihood import N_X, R_INTERIOR, R_OUT, R_WALL, X_FREE, X_OBJECTLIKE, X_UNKNOWN, X_WALLLIKE
from semmap_pp.target.posterior import Posterior
from semmap_pp.target.walls_inside import walls_inside


@dataclass(frozen=True)
class Inputs:
    """Everything read from disk, validated, before any sampling."""

    grid: OccupancyGrid
    model: Model
    rules: object | None      # knowledge.RuleSet, or None for no knowledge engine at all
    frame: Frame
    roi: np.ndarray           # (H, W) bool, image frame
    roi_name: str
    notes: tuple[str, ...] = ()  # what loading changed or found (the outside read as unknown, walls at
                                 # another angle), for the run's notes


def load_inputs(map_path, *, model_path=None, rules_path=DEFAULT_RULES, roi_path=None,
                map_options: dict | None = None) -> Inputs:
    """Read and validate the map, model, rules and region of interest (each error names its file)."""

    grid = load_map(map_path, **(map_options or {}))
    model = load_model(model_path)
    grid, outside_note = clear_outside(grid, model.outside)
    rules = load_rules(rules_path) if rules_path is not None else None
    check_model_for_map(grid, model, (map_options or {}).get("max_cells") or MAX_CELLS)
    frame = build_frame(grid, model)
    off_axis = off_axis_note(grid.classes, frame, model.lattice)
    if off_axis:   # world.json's map notes too, as the outside's
        grid = replace(grid, notes=tuple(grid.notes) + (off_axis,))
    if roi_path is not None:
        roi, roi_name = load_roi(roi_path, grid.shape), Path(roi_path).name
    else:
        roi = default_roi(grid.classes, closing_radius_cells(model.evaluate.roi_closing_m, grid.resolution))
        roi_name = "default"
    return Inputs(grid, model, rules, frame, roi, roi_name, tuple(n for n in (outside_note, off_axis) if n))


def check_model_for_map(grid: OccupancyGrid, model: Model, max_cells: int) -> None:
    """Refuse a model and map that cannot run together, before any work array is built.

    The model's lengths at the map's resolution must fit in cells (:meth:`Model.cells`), and the
    map padded by the longest of them (ROI closing, wall, door, object extent) must stay within
    the cell limit: a mistaken resolution of nanometres per cell would otherwise ask for exabytes.
    """
    try:
        c = model.cells(grid.resolution)
    except ModelError as exc:  # the map's resolution is the likelier culprit: name the map
        raise MapError(grid.source, f"{exc.message} (model {model.path})") from None
    pad = 1 + max(closing_radius_cells(model.evaluate.roi_closing_m, grid.resolution), c.wall,
                  c.adjacency_dilation, c.door_max, c.object_max_extent)
    h, w = grid.shape
    if (h + 2 * pad) * (w + 2 * pad) > max_cells:
        raise MapError(grid.source, f"at {grid.resolution:g} m/cell the model's lengths reach {pad} "
                                    f"cells: the {w}x{h} map padded by them exceeds the limit of "
                                    f"{max_cells} cells (is the resolution right?)")


@dataclass(frozen=True)
class TargetFactory:
    """Builds the target in each sampling process (the knowledge engine's solver state does not pickle)."""

    frame: Frame
    model: Model
    rules: object | None

    def __call__(self) -> Posterior:
        engine = None
        if self.rules is not None:
            engine = KnowledgeEngine(self.rules)
        return Posterior(self.frame, self.model, engine)


def run_target(inputs: Inputs) -> Posterior:
    """The full target of a run on ``inputs``, as W* is scored: knowledge on when it has rules."""
    post = TargetFactory(inputs.frame, inputs.model, inputs.rules)()
    post.knowledge_on = inputs.rules is not None
    return post


# Which (extended input code, region) pairs count as correctly explained (docs/evaluation.md, CPR): the sampler's
# cell categories are x + N_X * (region + 3 * corridor).
_CORRECT = np.zeros((N_X, 3), bool)
_CORRECT[X_UNKNOWN, R_OUT] = True
_CORRECT[[X_OBJECTLIKE, X_WALLLIKE], R_WALL] = True
_CORRECT[[X_FREE, X_UNKNOWN, X_OBJECTLIKE], R_INTERIOR] = True
CORRECT_CATEGORY = np.concatenate([_CORRECT.T.ravel()] * 2)  # corridor or not: same verdict


def category_hist(tracker) -> np.ndarray:
    """The tracker's (24,) category histogram of the current world."""
    hist = getattr(tracker, "hist", None)
    if hist is None:  # older trackers kept it on their likelihood cover
        hist = tracker.cover.hist
    return hist


@dataclass(frozen=True, eq=False)
class LatticeCPR:
    """Per-draw cell prediction rate from the likelihood's category tallies — O(1) per draw.

    The tracker keeps how many lattice cells fall in each (input code, region, corridor) category.
    Cells outside the ROI are unknown by construction (the default ROI contains every known cell),
    so as long as no unit reaches beyond the ROI each of them counts as correct (unknown, outside
    every unit), and ``CPR = (correct cells - cells outside the ROI) / ROI cells``. A unit reaching past
    the ROI makes this a slight under-estimate. It is a proxy for the convergence diagnostics; the
    reported CPR of W* is computed exactly on the input image by :func:`~semmap_pp.semantic.semantic_map.semantic_map`.
    """

    n_roi: int
    n_outside: int

    @classmethod
    def from_roi(cls, frame: Frame, roi_image: np.ndarray) -> "LatticeCPR":
        hl, wl = frame.shape
        n_roi = 0
        for b0, b1 in frame.bands():   # in bands of rows (memory of a band, not of the lattice)
            xi, yi, inside = frame.lattice_pixels(b0, b1)
            ok = inside & ~frame.outside[b0:b1]
            n_roi += int(np.count_nonzero(roi_image[yi[ok], xi[ok]]))
        return cls(n_roi, hl * wl - n_roi)

    def __call__(self, tracker) -> float:
        if self.n_roi == 0:
            return math.nan
        correct = int(np.dot(category_hist(tracker), CORRECT_CATEGORY))
        return (correct - self.n_outside) / self.n_roi


@dataclass(frozen=True)
class RunSettings:
    """How long and how wide to sample (defaults from the model file's [sampler] table)."""

    chains: int
    cores: int
    tune: int
    draws: int
    n_inner: int
    anneal: float
    seed: int
    spread_draws: int = 0           # the sample around W* (paper Fig. 7), draws per chain; 0: none
    spread_n_inner: int = 20        # its kernels per draw

    @classmethod
    def from_model(cls, model: Model, seed: int = 0, **overrides) -> "RunSettings":
        s = model.sampler
        values = dict(chains=s.chains, cores=s.cores, tune=s.tune, draws=s.draws, n_inner=s.n_inner,
                      anneal=s.anneal, seed=seed, spread_draws=s.spread_draws,
                      spread_n_inner=s.spread_n_inner)
        values.update({k: v for k, v in overrides.items() if v is not None})
        values["cores"] = max(1, min(values["cores"], values["chains"], os.cpu_count() or 1))
        return cls(**values)


@dataclass
class SpreadSample:
    """The sample around W* (the paper's Fig. 7): after the search, every chain started at W* and
    recorded ``draws`` draws of ``n_inner`` kernels under the same target, with no burn-in. The
    spread figures are drawn from it (:func:`figure_source`); it never changes W*."""

    draws: int
    n_inner: int
    summaries: dict                 # as MapRun's, over this sample's draws
    sample_stats: dict
    report: ConvergenceReport
    samples: dict
    seconds: float
    kernels_per_second: float
    start_logp: float               # W*'s log posterior, where every chain started
    best_logp: float                # the log posterior of best_world (NaN without one)
    stopped: str | None = None
    kept: tuple = ()
    best_world: wm.World | None = None   # the best world its chains visited (tracked at every
                                         # kernel, W* included); reported, never taken as W*

    def text(self) -> str:
        """One line: what was sampled, how fast, and whether the chains rose above W*."""
        chains, n = self.kept
        text = (f"sample around W* (posterior.png, posterior_cells.png): {len(chains)} chain(s) x {n} "
                f"draws x {self.n_inner} kernels from W*, {self.seconds:.1f} s "
                f"({self.kernels_per_second:,.0f} kernels/s)")
        rise = self.best_logp - self.start_logp
        if math.isfinite(rise) and rise > 0.05:
            text += (f"; its chains reached log posterior {rise:+.1f} above W* (W* is kept: the "
                     f"search's; docs/sampler.md)")
        return text


@dataclass
class MapRun:
    """The result of :func:`run_map`."""

    inputs: Inputs
    settings: RunSettings
    world: wm.World                 # W*, types assigned
    semantic: SemanticMap
    summaries: dict                 # name -> (chains, draws) label-invariant summaries (recorded draws)
    sample_stats: dict              # name -> (chains, draws) sampler statistics
    report: ConvergenceReport
    samples: dict                   # "rects" (chains, draws, K, 4), "active" (chains, draws, K): recorded worlds
    seconds: float
    kernels_per_second: float
    best_chain: int
    notes: list = field(default_factory=list)
    stopped: str | None = None      # "interrupted", "budget" or None (every planned draw made)
    records: list = field(default_factory=list)   # per chain: every real draw so far (resume.merge_records)
    starts: list = field(default_factory=list)    # the start world of each chain
    kept: tuple = ()                # (chain numbers, draws per chain) behind summaries and samples
    draw_seconds: tuple = ()        # per chain: seconds inside each draw's kernels in this run
    spread: SpreadSample | None = None   # the sample around W*, when settings.spread_draws > 0
    search_stopped: str | None = None    # how W*'s search ended early, if it did (``stopped`` may
                                         # also be set by a Ctrl-C after it: polish, sample around W*)

    @property
    def search_complete(self) -> bool:
        """Whether W*'s search made every planned draw."""
        return self.search_stopped is None

    def timing_text(self) -> str:
        """How long sampling took, and how fast the chains ran inside their draws.

        ``seconds`` is the wall time around ``pm.sample``: PyMC's set-up and worker processes, and on
        the first run after an install or a change of the code numba compiling the kernels on first
        use. Draws slower than :data:`SLOW_DRAW_FACTOR` times the median draw (and 0.1 s) are counted
        as compiling and left out of the rate inside the draws:

        >>> from types import SimpleNamespace as NS
        >>> run = NS(seconds=7.7, kernels_per_second=522.0, settings=NS(n_inner=50),
        ...          draw_seconds=([3.1] + [0.005] * 39, [3.5, 0.2, 2.9] + [0.008] * 37))
        >>> MapRun.timing_text(run)
        '7.7 s (522 kernels/s); inside the draws 5,572 kernels/s per chain, after 3 draws of 2.9-3.5 s that compiled code on first use'
        """
        text = f"{self.seconds:.1f} s ({self.kernels_per_second:,.0f} kernels/s)"
        times = [np.asarray(t, float) for t in self.draw_seconds if len(t)]
        if not times:
            return text
        every = np.concatenate(times)
        slow = every > max(0.1, SLOW_DRAW_FACTOR * float(np.median(every)))
        rest = every[~slow]
        if rest.sum() <= 0:
            return text
        rate = rest.size * self.settings.n_inner / rest.sum()
        text += f"; inside the draws {rate:,.0f} kernels/s per chain"
        if slow.any():
            lo, hi = every[slow].min(), every[slow].max()
            span = f"{hi:.1f}" if f"{lo:.1f}" == f"{hi:.1f}" else f"{lo:.1f}-{hi:.1f}"
            text += (f", after {int(slow.sum())} draw{'s' if slow.sum() > 1 else ''} of {span} s that "
                     f"compiled code on first use")
        return text


#: A draw this many times slower than the median draw (and over 0.1 s) was compiling code.
SLOW_DRAW_FACTOR = 50.0


def start_worlds(inputs: Inputs, chains: int, rng: np.random.Generator, base: wm.World | None = None,
                 data=None) -> list[wm.World]:
    """One start world per chain: the greedy data-driven world (:func:`data_start_world`, or
    ``base`` when given: it does not depend on the seed), then dispersed variants of it drawn
    with ``rng``."""
    clean = data_start_world(inputs, data) if base is None else base
    c = inputs.frame.cells
    worlds = [clean]
    for _ in range(1, chains):
        worlds.append(dispersed_world(rng, clean, inputs.frame.shape, min_side=c.min_side))
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


def run_map(inputs: Inputs, settings: RunSettings, *, log=print, callback=None, stop=None,
            budget: float | None = None, resume=None, starts: list | None = None,
            base_start: wm.World | None = None, previous_ids=None) -> MapRun:
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
    previous_ids : semmap_pp.plans.world_file.PreviousIds, optional
        The units of an earlier world.json whose ids W*'s units carry over where they are the
        same place (:mod:`semmap_pp.semantic.ids`); W* itself is the same as without.
    """

    model, frame = inputs.model, inputs.frame
    kernel_settings = model.kernels
    data = data_from_frame(frame, kernel_settings)
    factory = TargetFactory(frame, model, inputs.rules)
    head = (f"map {inputs.grid.source}: {inputs.grid.width}x{inputs.grid.height} cells, "
            f"orientation {math.degrees(frame.theta):.1f} deg")
    if resume is None:
        rng = np.random.default_rng(settings.seed)
        if starts is None:   # minutes on a large map: say so before, and how long after
            log(f"{head}; building the start worlds")
            t_start = time.perf_counter()
            starts = start_worlds(inputs, settings.chains, rng, base=base_start, data=data)
            made = "shared" if base_start is not None else f"{time.perf_counter() - t_start:.1f} s"
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
    kept_chains, n_kept, summaries, sample_stats, report, samples, notes = _collect(records, model)
    notes[:0] = inputs.notes

    post = run_target(inputs)
    best = result.best_world if result.best_world is not None else starts[0]
    best_chain = result.best_chain
    if resume is not None:   # W* of the earlier segments may still be the best
        best, best_chain = resume.better_best(best, result.best_logp, best_chain)
    polished = None
    if kernel_settings.polish_rounds:   # the nearest local maximum of the full target (ascent.py)
        log(f"polishing W* ({wm.n_units(best)} units) by greedy ascent of the full target")
        t_polish, before = time.perf_counter(), post.evaluate(best).total
        best = polish(post, best, data, kernel_settings.polish_rounds)
        polished = (before, time.perf_counter() - t_polish)
    sm = semantic_map(inputs.grid, frame, post, best, roi=inputs.roi, previous=previous_ids)
    if polished is not None:            # sm.log_posterior is W*'s, evaluated once
        log(f"W* polished by greedy ascent: log posterior {sm.log_posterior - polished[0]:+.1f} "
            f"in {polished[1]:.1f} s")
    if sm.id_record is not None:
        log(carried_text(sm.id_record))
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
        _sample_around(run, factory, data, default_mix(kernel_settings), planned=planned, log=log,
                       stop=stop, budget=left)
    return run


def _sample_around(run: MapRun, factory, data, mix, *, planned: bool, log, stop, budget) -> None:
    """Give ``run`` its sample around W* (:func:`sample_spread`) when ``planned`` and not
    interrupted first, and say on its report that the spread figures are drawn from it; otherwise a
    note says why there is none (the figures then use the search's draws)."""
    why = "sampling stopped early"
    if planned and stop is not None and stop():        # Ctrl-C while W* was polished
        run.stopped, why = "interrupted", "interrupted before it began"
    elif planned:
        try:
            run.spread = sample_spread(run.inputs, run.settings, run.world, run.semantic.log_posterior,
                                       factory, data, mix=mix, log=log, stop=stop, budget=budget)
        except SemmapError as exc:       # interrupted before any chain of it had 4 draws: keep W*
            why = exc.message
            if stop is not None and stop():
                run.stopped = "interrupted"
        else:
            if run.spread.stopped == "interrupted":
                run.stopped = "interrupted"
    if run.spread is None:
        run.notes.append(f"no sample around W*: {why}; the spread figures use the search's draws")
    else:
        run.report = run.report.with_figures(False)


def _collect(records, model: Model, *, draws_option: str = "--draws"):
    """The draws every kept chain has (:func:`semmap_pp.sampler.resume.keep_common_draws`) as arrays:
    ``(kept chains, draws per chain, summaries, sample_stats, convergence report, samples, notes)``."""

    kept_chains, n_kept, recorded, notes = keep_common_draws(records)
    summaries = {"log_posterior": np.stack([records[c].stats["logp"][recorded[c]] for c in kept_chains])}
    for name in SUMMARIES[1:]:
        summaries[name] = np.stack([records[c].stats[name][recorded[c]] for c in kept_chains])
    stat_names = [k for k in records[kept_chains[0]].stats
                  if k.startswith("accept") or k in ("temperature", "knowledge", "best_logp")]
    sample_stats = {k: np.stack([records[c].stats[k][recorded[c]] for c in kept_chains]).astype(float)
                    for k in stat_names}
    report = convergence(summaries, rhat_max=model.diagnostics.rhat_max, ess_min=model.diagnostics.ess_min,
                         draws_option=draws_option)
    samples = {"rects": np.stack([records[c].rects[recorded[c]] for c in kept_chains]).astype(np.int32),
               "active": np.stack([records[c].active[recorded[c]] for c in kept_chains]).astype(bool)}
    return kept_chains, n_kept, summaries, sample_stats, report, samples, notes


def sample_spread(inputs: Inputs, settings: RunSettings, wstar: wm.World, wstar_logp: float, factory,
                  data, *, mix, log=print, stop=None, budget: float | None = None) -> SpreadSample:
    """The sample around W* (paper Fig. 7, "starting the Markov chain from the world state W*"):
    ``settings.chains`` chains, each started at ``wstar``, record ``settings.spread_draws`` draws of
    ``settings.spread_n_inner`` kernels under the full target (no burn-in; knowledge on from the
    first draw when W* passes the coverage threshold, as it does once the search has switched it on).
    The seed is the run's plus one, so the sample's random draws are not the search's."""

    model = inputs.model
    log(f"sampling around W*: {settings.chains} chains x {settings.spread_draws} draws x "
        f"{settings.spread_n_inner} kernels, every chain started at W*")
    t0 = time.perf_counter()
    result = sample_worlds(factory, data, [wstar], draws=settings.spread_draws, tune=0,
                           chains=settings.chains, cores=settings.cores, n_inner=settings.spread_n_inner,
                           seed=settings.seed + 1, anneal=1.0, mix=mix,
                           cpr_fn=LatticeCPR.from_roi(inputs.frame, inputs.roi),
                           resolution=inputs.frame.cells.resolution,
                           knowledge_threshold=model.knowledge.coverage_threshold if inputs.rules else None,
                           stop=stop, budget=budget)
    seconds = time.perf_counter() - t0
    kept_chains, n_kept, summaries, sample_stats, report, samples, _ = _collect(
        result.records, model, draws_option="--spread-draws")
    made = sum(len(r.stats.get("logp", ())) for r in result.records)
    # the best world's log posterior, tracked at every kernel (a recorded draw is every n_inner-th)
    best = result.best_logp if result.best_world is not None else math.nan
    spread = SpreadSample(settings.spread_draws, settings.spread_n_inner, summaries, sample_stats, report,
                          samples, seconds, made * settings.spread_n_inner / seconds if seconds > 0 else 0.0,
                          float(wstar_logp), best, result.stopped, (tuple(kept_chains), n_kept),
                          result.best_world)
    log(spread.text())
    return spread


def figure_source(run: MapRun):
    """What the spread figures are drawn from: the sample around W* when the run has one
    (:class:`SpreadSample`), else the run's own recorded draws. Both have ``samples`` and ``report``."""
    return run.spread if run.spread is not None else run


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


def sampled_worlds(run: MapRun | SpreadSample, n: int, chains=None, first: int = 0) -> list[wm.World]:
    """Up to ``n`` recorded worlds, evenly thinned over the draws ``first..`` (from 0) of ``chains``
    (indices from 0 into the recorded chains; all of them when None), types not assigned."""
    rects, active = run.samples["rects"][:, first:], run.samples["active"][:, first:]
    if chains is not None:
        idx = np.asarray(sorted(chains), dtype=int)
        rects, active = rects[idx], active[idx]
    rects = rects.reshape(-1, *rects.shape[2:])
    active = active.reshape(-1, active.shape[-1])
    idx = np.unique(np.linspace(0, len(rects) - 1, num=min(n, len(rects))).round().astype(int))
    K = active.shape[1]
    return [wm.make(rects[i], active[i], np.full(K, wm.NO_TYPE)) for i in idx]


def spread_chains(run: MapRun | SpreadSample) -> list[int]:
    """The recorded chains (indices from 0) whose draws the posterior spread is drawn from: those in
    the best chain's mode (:meth:`ConvergenceReport.mode_chains`). A chain whose mean log posterior
    lies thousands of nats below the best chain's carries no posterior mass worth drawing (e^-1000
    of it); pooled, its worlds would show the spread between modes, not around W*."""
    return [c - 1 for c in run.report.mode_chains()]


def spread_first_draw(run: MapRun | SpreadSample) -> int:
    """The first recorded draw (from 0) the posterior spread uses: the draws before it, in which the
    chains of the best chain's mode were still settling, are left out
    (:func:`semmap_pp.sampler.diagnostics.warmup_draws`, :class:`~semmap_pp.sampler.diagnostics.ModeReport`)."""
    mode = run.report.within_mode
    return mode.first_draw if mode is not None else 0


def posterior_worlds(run, n: int) -> list:
    """Up to ``n`` recorded worlds of the run's sample around W* (or, without one, of its own
    draws: :func:`figure_source`), from its chains in the best chain's mode
    (:func:`spread_chains`) after the draws in which they were still settling
    (:func:`spread_first_draw`), typed as the sampler typed them."""
    src = figure_source(run)
    return typed_worlds(run_target(run.inputs),
                        sampled_worlds(src, n, spread_chains(src), spread_first_draw(src)))


def check_inputs_not_outputs(out: Path, inputs: Inputs, output_names) -> None:
    """Refuse a run whose outputs would overwrite one of its own input files (``--force`` into
    the folder that holds the map, its image or the ROI under an output's name)."""
    paths = [inputs.grid.source, inputs.grid.image_path]
    for p in paths:
        if p is None:
            continue
        p = Path(p)
        try:
            if p.resolve().parent == out.resolve() and p.name in output_names:
                raise SemmapError(p, f"is an input of this run, and --out {out} would overwrite it "
                                     f"with its own {p.name}; choose another --out")
        except OSError:
            continue
