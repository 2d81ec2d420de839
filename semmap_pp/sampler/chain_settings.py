"""The settings of the chains a :class:`~semmap_pp.sampler.step.WorldStep` runs, without importing
PyMC: how every draw runs (:class:`ChainSettings`) and when a chain stops (:class:`ChainLimits`)."""

from __future__ import annotations

import time
from dataclasses import dataclass


@dataclass(frozen=True)
class ChainSettings:
    """How every draw of a :class:`~semmap_pp.sampler.step.WorldStep` runs and what it reports.

    Attributes
    ----------
    mix : Mix, optional
        The kernel mix (default: :func:`semmap_pp.sampler.kernels.default_mix`).
    n_inner : int
        Kernels applied per PyMC draw.
    anneal : float
        Start temperature of the burn-in (1 = no annealing).
    knowledge_threshold : float, optional
        Knowledge phase (paper: knowledge is switched on once the world covers enough of the map).
        When given and the target has a knowledge engine, every chain starts with knowledge off; it
        is switched on during burn-in at the first draw whose coverage reaches the threshold, and at
        the first recorded draw at the latest, so every recorded draw has the same target.
    cpr_fn : callable(tracker) -> float, optional
        Cell prediction rate of the tracker's current world, recorded per draw (NaN without it).
    resolution : float
        Metres per lattice cell, for the ``wall_length`` summary (total unit perimeter).
    ladder : tuple of float
        Replica exchange: the likelihood exponents of the chain's rungs, the cold one (the target
        sampled and recorded) first (:mod:`semmap_pp.sampler.replicas`); ``(1.0,)``: one world,
        the target as it is.
    swaps : int
        Swap proposals between neighbouring rungs after every draw's kernels.
    temperatures : tuple of float, optional
        One temperature per rung of ``ladder`` (the cold one 1): a rung's kernels sample its
        target to the power ``1 / T``; None: every rung at 1.
    callback : callable(dict), optional
        Called after every draw with :func:`~semmap_pp.sampler.step.draw_info` of its stats, in the process that runs the
        chain (:func:`semmap_pp.sampler.sampling.sample_worlds` reports to the main process instead).
    """

    mix: object = None
    n_inner: int = 100
    anneal: float = 1.0
    knowledge_threshold: float | None = None
    cpr_fn: object = None
    resolution: float = 1.0
    callback: object = None
    ladder: tuple = (1.0,)
    swaps: int = 1
    temperatures: tuple | None = None


@dataclass(frozen=True)
class ChainLimits:
    """When the chains of a :class:`~semmap_pp.sampler.step.WorldStep` stop, and where they continue an earlier run.

    Attributes
    ----------
    stop : callable() -> bool, optional
        Checked before every kernel (e.g. a :class:`~semmap_pp.sampler.step.StopFlag` set by a SIGINT handler).
    deadline : float, optional
        ``time.time()`` after which every chain stops (a ``--budget``).
    chain_seconds : float, optional
        Each chain also stops this many seconds after it started (its share of the budget).
    schedule : (int, int), optional
        ``(burn-in draws, total draws)`` of every chain, counted from the chain's first draw ever;
        overrides what ``pm.sample`` passes (a resumed run calls it with the remaining draws).
    resume : mapping of int to ChainStart, optional
        Per chain number: where that chain continues an earlier run.
    min_draws : int
        A chain that has begun is not stopped (by ``stop`` or the deadline) before this many real
        draws; a chain stopped before its first draw makes none.
    """

    stop: object = None
    deadline: float | None = None
    chain_seconds: float | None = None
    schedule: tuple[int, int] | None = None
    resume: object = None
    min_draws: int = 4

    @classmethod
    def of_budget(cls, budget: float | None, cores: int, chains: int, **limits) -> "ChainLimits":
        """The limits of a run of ``budget`` seconds of wall time (None: none): every chain stops
        by then, and each also after its share ``budget * min(cores, chains) / chains`` from its
        own start (sequential chains share time)."""
        deadline = chain_seconds = None
        if budget is not None:
            deadline = time.time() + budget
            chain_seconds = budget * min(cores, chains) / chains
        return cls(deadline=deadline, chain_seconds=chain_seconds, **limits)
