"""Drive chains of worlds through ``pm.sample`` with :class:`~semmap_pp.sampler.step.WorldStep`.

Examples
--------
A prior-free toy target (every valid world equally likely) on a small free lattice:

>>> import numpy as np
>>> from semmap_pp import world as wm
>>> from semmap_pp.sampler.kernels import build_data
>>> class Flat:
...     def start(self, world):
...         return _FlatTracker(world)
>>> data = build_data(np.zeros((12, 12), np.uint8), min_side=3, wall_cells=1)
>>> res = sample_worlds(Flat(), data, [wm.empty(3)] * 2, draws=5, tune=5, chains=2, cores=1,
...                     n_inner=10, seed=1)
>>> len(res.best_world.active), res.draws_per_chain
(3, 5)
"""

from __future__ import annotations

import logging
import math
import sys
import time
import warnings
from typing import NamedTuple

import numpy as np

from semmap_pp import world as wm
from semmap_pp.errors import SemmapError
from semmap_pp.sampler.chain_settings import ChainLimits, ChainSettings

#: How ``pm.sample`` starts the processes of parallel chains when the caller names none: "fork"
#: on Linux, the start method of Python 3.12 and 3.13 there, which the project's speed figures
#: were measured with (a forked chain inherits the imported modules and the compiled code; with
#: "forkserver", Python 3.14's default, each chain imports and loads them anew: ``semmap map
#: data/maps/ubremen-cartesium.yaml`` took 17.6 s instead of 6.0 s, the same W*; docs/sampler.md).
#: None elsewhere: PyMC's own choice (forkserver on Intel macOS, fork on Apple silicon).
DEFAULT_MP_CONTEXT = "fork" if sys.platform.startswith("linux") else None

#: the largest seed: numpy's generators take any, but trace.nc stores it as a 64-bit HDF5 integer
MAX_SEED = 2 ** 32 - 1
#: the most kernels per draw: the model's 50 runs in milliseconds; 10^6 in about a minute a draw
MAX_N_INNER = 1_000_000


class ChainRecord(NamedTuple):
    """The real draws (``stopped == 0``) of one chain, as the main process received them.

    Attributes
    ----------
    stats : dict of str to ndarray
        Every scalar stat of :class:`~semmap_pp.sampler.step.WorldStep`, one entry per real draw.
    rects : ndarray, (n, K, 4) int32
    active : ndarray, (n, K) bool
        The world after each real draw.
    last : ChainStart or None
        Where the chain would continue (None when it made no draw).
    types : ndarray, (n, K) int8, or None
        The types the sampler gave each world (None for draws read back from resume.npz).
    """

    stats: dict
    rects: np.ndarray
    active: np.ndarray
    last: object
    types: np.ndarray | None = None


class SampleResult(NamedTuple):
    """What :func:`sample_worlds` returns.

    Attributes
    ----------
    trace : pymc MultiTrace or None
        Draws of ``rects``, ``active``, ``types`` and the step's stats (tuning draws included, and
        the empty draws after a stop). None when a stop made ``pm.sample`` fail to return one.
    best_world : World
        The best world seen across all chains (``W*``), types not assigned.
    best_logp : float
    best_chain : int
    seconds : float
        Wall time of ``pm.sample``.
    draws_per_chain : int
    records : list of ChainRecord
        Per chain, the real draws (the trace without the empty draws after a stop).
    stopped : str or None
        ``"interrupted"`` (the stop flag), ``"budget"`` (a chain ran out of time) or None.
    """

    trace: object
    best_world: wm.World
    best_logp: float
    best_chain: int
    seconds: float
    draws_per_chain: int
    records: list = []
    stopped: str | None = None


_OBJECT_STATS = ("best_rects", "best_active", "rng_state")


class _Recorder:
    """``pm.sample``'s per-draw callback: keeps the real draws, reports progress, ends a stop.

    Runs in the main process for sequential and parallel chains alike. A KeyboardInterrupt raised
    here is PyMC's documented way to end sampling cleanly: with sequential chains it ends the
    current chain (PyMC goes on with the next), in parallel it ends them all. So a sequential chain
    that reports it stopped is ended at once (no empty draws), and when the stop flag is set the
    parallel chains are ended once those that have begun have their ``min_draws``. A parallel chain
    stopped by its budget while others still run makes empty draws (PyMC's cost per draw) instead.
    """

    def __init__(self, chains: int, callback, stop, min_draws: int, sequential: bool):
        self.draws = [[] for _ in range(chains)]
        self.callback, self.stop, self.min_draws = callback, stop, min_draws
        self.sequential = sequential

    def __call__(self, trace=None, draw=None):
        from semmap_pp.sampler.step import draw_info  # step imports PyMC (about 1 s): not at import

        stats = draw.stats[0]
        c = int(stats["chain"])
        if not stats["stopped"]:
            if self.draws[c]:   # keep the object stats (best world, random state) of the last draw only
                prev = self.draws[c][-1][0]
                self.draws[c][-1] = ({k: v for k, v in prev.items() if k not in _OBJECT_STATS},
                                     *self.draws[c][-1][1:])
            self.draws[c].append((stats, np.rint(draw.point["rects"]).astype(np.int32),
                                  np.asarray(draw.point["active"]) > 0,
                                  np.asarray(draw.point["types"]).astype(np.int8)))
        if self.callback is not None:
            self.callback(draw_info(stats))
        if stats["stopped"] and self.sequential:
            raise KeyboardInterrupt  # PyMC ends this chain (keeping what it recorded) and starts the next
        if self.stop is not None and self.stop():
            begun = [len(d) for d in self.draws if d]
            if stats["stopped"] or all(n >= self.min_draws for n in begun):
                raise KeyboardInterrupt  # PyMC ends the chain(s) and keeps what was recorded

    def records(self) -> list[ChainRecord]:
        from semmap_pp.sampler.step import ChainStart  # step imports PyMC (about 1 s): not at import

        out = []
        for rows in self.draws:
            if not rows:
                out.append(ChainRecord({}, np.zeros((0, 0, 4), np.int32), np.zeros((0, 0), bool), None))
                continue
            scalars = [k for k, v in rows[0][0].items() if np.ndim(v) == 0 and not isinstance(v, dict)]
            stats = {k: np.array([r[0][k] for r in rows]) for k in scalars}
            last = rows[-1][0]
            start = ChainStart(draw=int(last["draw_index"]) + 1, n_tune=int(last["n_tune"]),
                               rng_state=last["rng_state"],
                               knowledge_on=bool(last["knowledge"]), best_logp=float(last["best_logp"]),
                               best_rects=np.asarray(last["best_rects"]),
                               best_active=np.asarray(last["best_active"], bool))
            out.append(ChainRecord(stats, np.stack([r[1] for r in rows]), np.stack([r[2] for r in rows]),
                                   start, np.stack([r[3] for r in rows])))
        return out


def sample_worlds(target, data, starts, *, draws: int, tune: int = 0, chains: int = 4, cores: int = 1,
                  n_inner: int = 100, seed=None, anneal: float = 1.0, mix=None, cpr_fn=None,
                  resolution: float = 1.0, knowledge_threshold: float | None = None,
                  progressbar: bool = False, mp_ctx=None, callback=None, stop=None,
                  budget: float | None = None, resume=None, schedule: tuple[int, int] | None = None,
                  min_draws: int = 4, ladder: tuple = (1.0,), swaps: int = 1,
                  temperatures: tuple | None = None) -> SampleResult:
    """Run ``chains`` chains of ``tune + draws`` PyMC draws, ``n_inner`` kernels each.

    Parameters
    ----------
    target : Posterior or zero-argument callable returning one
    data : KernelData
    starts : sequence of World
        One start world per chain (repeated cyclically when shorter).
    draws, tune : int
        Recorded draws and burn-in draws per chain (burn-in annealed when ``anneal > 1``).
    chains, cores : int
        ``cores > 1`` samples chains in parallel processes (the step is pickled), started by
        ``mp_ctx`` (a multiprocessing start method or context; None: :data:`DEFAULT_MP_CONTEXT`).
    seed : int or None
        One seed; PyMC spawns the per-chain generators from it.
    callback : callable(dict), optional
        Called in this process after every draw of every chain with
        :func:`semmap_pp.sampler.step.draw_info` (chain, draw, phase, log posterior, units, CPR, ...).
    stop : callable() -> bool, optional
        A stop flag (:class:`semmap_pp.sampler.step.StopFlag`): once set, the chains stop after their
        current kernel (or after ``min_draws`` real draws) and ``pm.sample`` is ended cleanly.
    budget : float, optional
        Seconds of wall time: every chain stops by then, and each also after its share
        ``budget * min(cores, chains) / chains`` from its own start (sequential chains share time).
    resume : mapping of int to ChainStart, optional
        Chains that continue an earlier run (with ``schedule``, and ``starts`` their last worlds).
    schedule : (int, int), optional
        ``(burn-in, total draws)`` per chain, counted from each chain's first draw ever.
    ladder : tuple of float
        Replica exchange inside every chain (:mod:`semmap_pp.sampler.replicas`): the likelihood
        exponents of its rungs, the cold one (recorded) first; each rung runs ``n_inner`` kernels
        per draw, then ``swaps`` swaps are proposed. ``(1.0,)``: one world per chain, untempered.
    temperatures : tuple of float, optional
        A temperature per rung (the cold one 1), its kernels and swaps at it; None: all 1.

    Returns
    -------
    SampleResult
    """
    from semmap_pp.sampler.step import WorldStep, world_model, world_to_point  # imports PyMC

    starts = list(starts)
    if not starts:
        raise ValueError("sample_worlds needs at least one start world")
    capacity = starts[0].capacity
    model = world_model(capacity)
    initvals = [world_to_point(starts[i % len(starts)]) for i in range(chains)]
    logging.getLogger("pymc").setLevel(logging.ERROR)
    limits = ChainLimits.of_budget(budget, cores, chains, stop=stop, schedule=schedule,
                                   resume=resume, min_draws=min_draws)
    chain = ChainSettings(mix=mix, n_inner=n_inner, anneal=anneal, cpr_fn=cpr_fn,
                          resolution=resolution, knowledge_threshold=knowledge_threshold,
                          ladder=tuple(ladder), swaps=swaps,
                          temperatures=None if temperatures is None else tuple(temperatures))
    recorder = _Recorder(chains, callback, stop, min_draws, sequential=not (cores > 1 and chains > 1))
    with model, warnings.catch_warnings():
        # We want the MultiTrace with the burn-in kept (W* may be found while annealing).
        warnings.filterwarnings("ignore", message=".*return_inferencedata=False.*")
        warnings.filterwarnings("ignore", message="Tuning samples will be included.*")
        step = WorldStep(model.value_vars, target=target, data=data, chain=chain, limits=limits,
                         rng=seed)
        t0 = time.perf_counter()
        trace = _pm_sample(step, initvals, recorder, draws=draws, tune=tune, chains=chains,
                           cores=cores, seed=seed, progressbar=progressbar, mp_ctx=mp_ctx, stop=stop)
        seconds = time.perf_counter() - t0
    records = recorder.records()
    best = _best_world(records, resume, capacity)
    planned = schedule[1] if schedule is not None else tune + draws
    stopped = _stop_reason(records, resume, stop, budget, planned)
    return SampleResult(trace, best[2], best[0], best[1], seconds, draws, records, stopped)


def _pm_sample(step, initvals, recorder, *, draws, tune, chains, cores, seed, progressbar, mp_ctx,
               stop):
    """``pm.sample`` of the world model in context with ``step``: the MultiTrace, or None when a
    worker that saw the Ctrl-C closed its pipe first (what ``recorder`` received is kept); a
    project error in another process is raised as itself."""
    import pymc as pm  # PyMC takes about 1 s to import: only when chains are sampled
    from pymc.sampling.parallel import ParallelSamplingError

    trace = None
    try:
        trace = pm.sample(draws=draws, tune=tune, chains=chains, cores=cores, step=step,
                          initvals=initvals, random_seed=seed, compute_convergence_checks=False,
                          return_inferencedata=False, discard_tuned_samples=False,
                          progressbar=progressbar, callback=recorder,
                          mp_ctx=DEFAULT_MP_CONTEXT if mp_ctx is None else mp_ctx)
    except ParallelSamplingError as exc:
        # a chain in another process failed: the project's own error (a rule file too dense
        # for this map, say) is raised as itself, so the command prints its one line
        if isinstance(exc.__cause__, SemmapError):
            raise exc.__cause__ from None
        raise
    except (EOFError, BrokenPipeError, ConnectionError, RuntimeError):
        # A worker that saw the Ctrl-C itself can close its pipe before the main process ends
        # the run: what the recorder received is still complete and consistent.
        if stop is None or not stop():
            raise
    return trace


def _best_world(records, resume, capacity: int) -> tuple:
    """``(log p, chain, world)`` of the best world any chain reported (its last draw's, or where
    a resumed chain that made no draw stood), types left undecided; ``(-inf, 0, None)`` if none."""
    best = (-math.inf, 0, None)
    for c, rec in enumerate(records):
        start = rec.last if rec.last is not None else (resume or {}).get(c)
        if start is None or start.best_rects is None:
            continue
        if best[2] is None or start.best_logp > best[0]:
            r = np.asarray(start.best_rects).reshape(capacity, 4)
            a = np.asarray(start.best_active).reshape(capacity)
            best = (float(start.best_logp), c, wm.make(r, a, np.full(capacity, wm.NO_TYPE)))
    return best


def _stop_reason(records, resume, stop, budget, planned: int) -> str | None:
    """Why sampling ended early: the stop flag's reason, ``"budget"`` when a chain made fewer
    than its ``planned`` draws under a budget, or None."""
    if stop is not None and stop():
        return getattr(stop, "reason", None) or "interrupted"
    done = [rec.last.draw if rec.last is not None else (resume or {}).get(c, _NONE).draw
            for c, rec in enumerate(records)]
    return "budget" if budget is not None and min(done) < planned else None


class _NoStart(NamedTuple):
    draw: int = 0


_NONE = _NoStart()


class _FlatTracker:
    """A constant target (used by the example above and by quick smoke tests)."""

    def __init__(self, world):
        self.world, self.logp = world, 0.0

    def propose(self, world, changed_slots):
        return _FlatProp(world)

    def accept(self, prop):
        self.world = prop.world


class _FlatProp(NamedTuple):
    world: object
    logp: float = 0.0
