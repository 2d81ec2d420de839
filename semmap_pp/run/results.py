"""What a run is set to do and what it returns: :class:`RunSettings`, :class:`MapRun` and the sample
around W* (:class:`SpreadSample`); the recorded draws as arrays, and the worlds the spread figures
are drawn from."""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field

import numpy as np

from semmap_pp import world as wm
from semmap_pp.model import Model
from semmap_pp.run.inputs import Inputs
from semmap_pp.sampler.diagnostics import SUMMARIES, ConvergenceReport, convergence
from semmap_pp.sampler.resume import keep_common_draws
from semmap_pp.semantic.semantic_map import SemanticMap


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


@dataclass(frozen=True)
class Tempering:
    """How the sample around W* was tempered (opt-in: ``semmap map --tempered``): the likelihood
    exponents of each chain's rungs, the cold one first (``(1.0,)``: the full likelihood, no
    replicas), the correlation area ``A`` the cold exponent ``1 / A`` came from, the swap proposals
    per draw, and whether chains 2.. started at the search's dispersed starts instead of W*."""

    ladder: tuple = (1.0,)
    area: float = 1.0
    swaps: int = 0
    dispersed: bool = False
    temperatures: tuple = (1.0,)    # per rung (the cold one 1): its kernels' temperature

    @property
    def on(self) -> bool:
        return self.ladder != (1.0,)

    def text(self) -> str:
        """What the sample's chains were, for its one-line summary ("" when untempered)."""
        if not self.on:
            return ""
        out = f"likelihood to the power 1/{self.area:.1f}"
        if len(self.ladder) > 1:
            out += (f", {len(self.ladder)} replicas per chain (exponents "
                    + ", ".join(f"{b:.3g}" for b in self.ladder) + f"), {self.swaps} swap(s) per draw")
            if any(t != 1.0 for t in self.temperatures):
                out += " at temperatures " + ", ".join(f"{t:.3g}" for t in self.temperatures)
        return out


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
    tempering: Tempering = Tempering()   # opt-in (--tempered): the ladder, exponent and starts

    def text(self) -> str:
        """One line: what was sampled, from where, how fast, and whether the chains rose above W*."""
        chains, n = self.kept
        t = self.tempering
        start = ("(chain 1 from W*, the others from the search's dispersed starts)" if t.dispersed
                 else "from W*")
        rungs = f" over {len(t.ladder)} rungs" if len(t.ladder) > 1 else ""
        text = (f"sample around W* (posterior.png, posterior_cells.png): {len(chains)} chain(s) x {n} "
                f"draws x {self.n_inner} kernels {start}, {self.seconds:.1f} s "
                f"({self.kernels_per_second:,.0f} kernels/s{rungs})")
        if t.on:
            text += "; " + t.text()
            swaps = self.sample_stats.get("swap_accept")
            if swaps is not None and np.isfinite(swaps).any():
                text += f", swaps accepted {float(np.nanmean(swaps)):.3f} of the time"
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


def collect_draws(records, model: Model, *, draws_option: str = "--draws"):
    """The draws every kept chain has (:func:`semmap_pp.sampler.resume.keep_common_draws`) as arrays:
    ``(kept chains, draws per chain, summaries, sample_stats, convergence report, samples, notes)``."""

    kept_chains, n_kept, recorded, notes = keep_common_draws(records)
    summaries = {"log_posterior": np.stack([records[c].stats["logp"][recorded[c]] for c in kept_chains])}
    for name in SUMMARIES[1:]:
        summaries[name] = np.stack([records[c].stats[name][recorded[c]] for c in kept_chains])
    first = records[kept_chains[0]].stats
    # beta and swap_accept only when the chains ran replicas or a tempered likelihood
    tempered = any(np.any(np.asarray(records[c].stats.get("beta", [1.0])) != 1.0)
                   or np.isfinite(np.asarray(records[c].stats.get("swap_accept", [np.nan]), float)).any()
                   for c in kept_chains)
    stat_names = [k for k in first if k.startswith("accept") or k in ("temperature", "knowledge", "best_logp")
                  or (tempered and k in ("beta", "swap_accept"))]
    sample_stats = {k: np.stack([records[c].stats[k][recorded[c]] for c in kept_chains]).astype(float)
                    for k in stat_names}
    report = convergence(summaries, rhat_max=model.diagnostics.rhat_max, ess_min=model.diagnostics.ess_min,
                         draws_option=draws_option)
    samples = {"rects": np.stack([records[c].rects[recorded[c]] for c in kept_chains]).astype(np.int32),
               "active": np.stack([records[c].active[recorded[c]] for c in kept_chains]).astype(bool)}
    if all(getattr(records[c], "types", None) is not None for c in kept_chains):   # (not from resume.npz)
        samples["types"] = np.stack([records[c].types[recorded[c]] for c in kept_chains]).astype(np.int8)
        samples["knowledge"] = np.stack([np.asarray(records[c].stats["knowledge"])[recorded[c]]
                                         for c in kept_chains]).astype(bool)
    return kept_chains, n_kept, summaries, sample_stats, report, samples, notes


def figure_source(run: MapRun):
    """What the spread figures are drawn from: the sample around W* when the run has one
    (:class:`SpreadSample`), else the run's own recorded draws. Both have ``samples`` and ``report``."""
    return run.spread if run.spread is not None else run


def sampled_worlds(run: MapRun | SpreadSample, n: int, chains=None, first: int = 0,
                   knowledge: bool | None = None) -> list[wm.World]:
    """Up to ``n`` recorded worlds, evenly thinned over the draws ``first..`` (from 0) of ``chains``
    (indices from 0 into the recorded chains; all of them when None). Types not assigned, but
    with ``knowledge`` (whether the target that would type them has its knowledge on) a world
    drawn under that same target keeps the types the sampler gave it (the MAP types, which
    :meth:`~semmap_pp.target.posterior.Posterior.typing` would give it again)."""
    names = ["rects", "active"] + (["types", "knowledge"] if knowledge is not None and "types" in run.samples else [])
    arrays = [run.samples[k][:, first:] for k in names]
    if chains is not None:
        idx = np.asarray(sorted(chains), dtype=int)
        arrays = [a[idx] for a in arrays]
    rects = arrays[0].reshape(-1, *arrays[0].shape[2:])
    active = arrays[1].reshape(-1, arrays[1].shape[-1])
    idx = np.unique(np.linspace(0, len(rects) - 1, num=min(n, len(rects))).round().astype(int))
    K = active.shape[1]
    untyped = np.full(K, wm.NO_TYPE)
    if len(arrays) == 2:
        return [wm.make(rects[i], active[i], untyped) for i in idx]
    types, known = arrays[2].reshape(-1, K), arrays[3].reshape(-1)
    return [wm.make(rects[i], active[i], types[i] if known[i] == knowledge else untyped) for i in idx]


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
