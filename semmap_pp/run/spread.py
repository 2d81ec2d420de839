"""The sample around W* (the paper's Fig. 7): every chain started at W*, under the full target,
after the search (opt-in, ``semmap map --tempered``: a tempered likelihood with replica exchange,
chains 2.. from the search's dispersed starts); and the typed worlds the spread figures and
world.json's posterior marginals are drawn from (:func:`posterior_worlds`)."""

from __future__ import annotations

import dataclasses
import math
import time

from semmap_pp import world as wm
from semmap_pp.errors import SemmapError
from semmap_pp.run.inputs import Inputs
from semmap_pp.run.lattice_cpr import LatticeCPR
from semmap_pp.run.results import (MapRun, RunSettings, SpreadSample, Tempering, collect_draws, figure_source,
                                   sampled_worlds, spread_chains, spread_first_draw)
from semmap_pp.run.target_factory import run_target
from semmap_pp.sampler.replicas import geometric_ladder, geometric_temperatures
from semmap_pp.sampler.sampling import sample_worlds
from semmap_pp.sampler.spread import typed_worlds
from semmap_pp.target.tempering import likelihood_exponent


def sample_around(run: MapRun, factory, data, mix, *, planned: bool, log, stop, budget) -> None:
    """Give ``run`` its sample around W* (:func:`sample_spread`) when ``planned`` and not
    interrupted first, and say on its report that the spread figures are drawn from it; otherwise a
    note says why there is none (the figures then use the search's draws)."""
    why = "sampling stopped early"
    if planned and stop is not None and stop():        # Ctrl-C while W* was polished
        run.stopped, why = "interrupted", "interrupted before it began"
    elif planned:
        try:
            run.spread = sample_spread(run.inputs, run.settings, run.world, run.semantic.log_posterior,
                                       factory, data, mix=mix, log=log, stop=stop, budget=budget,
                                       dispersed=run.starts[1:])
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


def sample_spread(inputs: Inputs, settings: RunSettings, wstar: wm.World, wstar_logp: float, factory,
                  data, *, mix, log=print, stop=None, budget: float | None = None,
                  dispersed=()) -> SpreadSample:
    """The sample around W* (paper Fig. 7, "starting the Markov chain from the world state W*"):
    ``settings.chains`` chains, each started at ``wstar``, record ``settings.spread_draws`` draws of
    ``settings.spread_n_inner`` kernels under the full target (no burn-in; knowledge on from the
    first draw when W* passes the coverage threshold, as it does once the search has switched it on).
    The seed is the run's plus one, so the sample's random draws are not the search's.

    Opt-in, with ``[sampler] spread_tempered`` (``semmap map --tempered``): the likelihood is
    raised to ``1 / A``, A the correlation area of W*'s residuals within
    ``spread_correlation_lag_m`` (:func:`~semmap_pp.target.tempering.likelihood_exponent`), and
    with ``spread_rungs > 1`` every chain exchanges worlds with hotter replicas
    (:mod:`semmap_pp.sampler.replicas`); chains 2.. then start from ``dispersed`` (the search's
    dispersed start worlds) instead of W*, so that their meeting is a test of convergence."""

    model = inputs.model
    p = model.sampler
    lag = p.spread_correlation_lag_m if p.spread_tempered else 0.0
    exponent, area = likelihood_exponent(run_target(inputs) if lag > 0 else None, wstar, lag)
    ladder = geometric_ladder(exponent, p.spread_rungs if p.spread_tempered else 1, p.spread_ladder_ratio)
    heat = geometric_temperatures(len(ladder), p.spread_temperature_ratio if p.spread_tempered else 1.0)
    starts = [wstar] + [w for w in dispersed if w.capacity == wstar.capacity] if len(ladder) > 1 else [wstar]
    dispersed_chains = len(ladder) > 1 and len(starts) > 1 and settings.chains > 1
    log(f"sampling around W*: {settings.chains} chains x {settings.spread_draws} draws x "
        f"{settings.spread_n_inner} kernels, " + ("chain 1 started at W*, the others at the search's "
                                                 "dispersed starts" if dispersed_chains
                                                 else "every chain started at W*"))
    if exponent != 1.0 or len(ladder) > 1:
        log(f"tempered (--tempered): likelihood to the power 1/{area:.1f} (the correlation area of W*'s "
            f"residuals, cells); {len(ladder)} replica(s) per chain, exponents "
            + ", ".join(f"{b:.3g}" for b in ladder)
            + (f"; {p.spread_swaps} swap(s) per draw" if len(ladder) > 1 else "")
            + ("; temperatures " + ", ".join(f"{t:.3g}" for t in heat) if heat[-1] != 1.0 else ""))
    t0 = time.perf_counter()
    result = sample_worlds(factory, data, starts, draws=settings.spread_draws, tune=0,
                           chains=settings.chains, cores=settings.cores, n_inner=settings.spread_n_inner,
                           seed=settings.seed + 1, anneal=1.0, mix=mix,
                           cpr_fn=LatticeCPR.from_roi(inputs.frame, inputs.roi),
                           resolution=inputs.frame.cells.resolution,
                           knowledge_threshold=model.knowledge.coverage_threshold if inputs.rules else None,
                           stop=stop, budget=budget, ladder=ladder, swaps=p.spread_swaps,
                           temperatures=heat if heat[-1] != 1.0 else None)
    seconds = time.perf_counter() - t0
    kept_chains, n_kept, summaries, sample_stats, report, samples, _ = collect_draws(
        result.records, model, draws_option="--spread-draws")
    made = sum(len(r.stats.get("logp", ())) for r in result.records)
    # the best world's log posterior, tracked at every kernel (a recorded draw is every n_inner-th)
    best = result.best_logp if result.best_world is not None else math.nan
    if len(ladder) > 1:
        report = dataclasses.replace(report, tempered=True)
    kernels = made * settings.spread_n_inner * len(ladder)      # every rung runs n_inner kernels
    spread = SpreadSample(settings.spread_draws, settings.spread_n_inner, summaries, sample_stats, report,
                          samples, seconds, kernels / seconds if seconds > 0 else 0.0,
                          float(wstar_logp), best, result.stopped, (tuple(kept_chains), n_kept),
                          result.best_world, Tempering(ladder, area, p.spread_swaps if len(ladder) > 1 else 0,
                                                       dispersed_chains, heat))
    log(spread.text())
    return spread


def posterior_worlds(run, n: int) -> list:
    """Up to ``n`` recorded worlds of the run's sample around W* (or, without one, of its own
    draws: :func:`figure_source`), from its chains in the best chain's mode
    (:func:`spread_chains`) after the draws in which they were still settling
    (:func:`spread_first_draw`), typed as the sampler typed them: what posterior.png,
    posterior_cells.png and world.json's posterior marginals are made of."""
    src = figure_source(run)
    post = run_target(run.inputs)
    return typed_worlds(post, sampled_worlds(src, n, spread_chains(src), spread_first_draw(src),
                                             knowledge=bool(post.knowledge_on)))
