"""Drive chains of worlds through ``pm.sample`` with :class:`~semmap_pp.step.WorldStep`.

Examples
--------
A prior-free toy target (every valid world equally likely) on a small free lattice:

>>> import numpy as np
>>> from semmap_pp import world as wm
>>> from semmap_pp.kernels import build_data
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
import time
import warnings
from typing import NamedTuple

import numpy as np

from semmap_pp import world as wm


class SampleResult(NamedTuple):
    """What :func:`sample_worlds` returns.

    Attributes
    ----------
    trace : pymc MultiTrace
        Draws of ``rects``, ``active``, ``types`` and the step's stats (tuning draws included).
    best_world : World
        The best world seen across all chains (``W*``), types not assigned.
    best_logp : float
    best_chain : int
    seconds : float
        Wall time of ``pm.sample``.
    draws_per_chain : int
    """

    trace: object
    best_world: wm.World
    best_logp: float
    best_chain: int
    seconds: float
    draws_per_chain: int


def sample_worlds(target, data, starts, *, draws: int, tune: int = 0, chains: int = 4, cores: int = 1,
                  n_inner: int = 100, seed=None, anneal: float = 1.0, mix=None, cpr_fn=None,
                  resolution: float = 1.0, knowledge_threshold: float | None = None,
                  progressbar: bool = False, mp_ctx=None) -> SampleResult:
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
        ``cores > 1`` samples chains in parallel processes (the step is pickled).
    seed : int or None
        One seed; PyMC spawns the per-chain generators from it.

    Returns
    -------
    SampleResult
    """
    import pymc as pm

    from semmap_pp.step import WorldStep, world_model, world_to_point

    starts = list(starts)
    if not starts:
        raise ValueError("sample_worlds needs at least one start world")
    capacity = starts[0].capacity
    model = world_model(capacity)
    initvals = [world_to_point(starts[i % len(starts)]) for i in range(chains)]
    logging.getLogger("pymc").setLevel(logging.ERROR)
    with model, warnings.catch_warnings():
        # We want the MultiTrace with the burn-in kept (W* may be found while annealing).
        warnings.filterwarnings("ignore", message=".*return_inferencedata=False.*")
        warnings.filterwarnings("ignore", message="Tuning samples will be included.*")
        step = WorldStep(model.value_vars, target=target, data=data, mix=mix, n_inner=n_inner,
                         anneal=anneal, cpr_fn=cpr_fn, resolution=resolution,
                         knowledge_threshold=knowledge_threshold, rng=seed)
        t0 = time.perf_counter()
        trace = pm.sample(draws=draws, tune=tune, chains=chains, cores=cores, step=step,
                          initvals=initvals, random_seed=seed, compute_convergence_checks=False,
                          return_inferencedata=False, discard_tuned_samples=False,
                          progressbar=progressbar, mp_ctx=mp_ctx)
        seconds = time.perf_counter() - t0
    best = (-math.inf, 0, None)
    for c in range(trace.nchains):
        lp = trace.get_sampler_stats("best_logp", chains=c)
        if best[2] is None or lp[-1] > best[0]:
            # PyMC stacks object stats of all draws: take the last draw's K slots
            last_r = np.asarray(trace.get_sampler_stats("best_rects", chains=c)).reshape(-1, capacity, 4)[-1]
            last_a = np.asarray(trace.get_sampler_stats("best_active", chains=c)).reshape(-1, capacity)[-1]
            best = (float(lp[-1]), c, wm.make(last_r, last_a, np.full(capacity, wm.NO_TYPE)))
    return SampleResult(trace, best[2], best[0], best[1], seconds, draws)


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
