"""The Metropolis–Hastings–Green acceptance, written once, and a plain-Python chain runner.

Every kernel returns ``Proposal(world, log_ratio, changed_slots)`` with
``log_ratio = log q(reverse) - log q(forward)``; on the discrete building lattice there is no
Jacobian, so the acceptance of a proposal ``W -> W'`` is

    log alpha = (log pi(W') - log pi(W)) / T + log_ratio,

with temperature ``T = 1`` for sampling (``T > 1`` only while annealing during burn-in).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np


def mh_green(rng, tracker, proposal, temperature: float = 1.0) -> bool:
    """Accept or reject ``proposal`` against ``tracker`` (commits it on acceptance).

    Parameters
    ----------
    rng : numpy.random.Generator
    tracker : object with ``logp``, ``propose(world, changed_slots)`` and ``accept(prop)``
        The incremental target of one chain (see :mod:`semmap_pp.target.posterior`).
    proposal : Proposal or None
        ``None`` (no valid move) is a rejection.
    temperature : float

    Returns
    -------
    bool
        Whether the proposal was accepted.
    """
    if proposal is None:
        return False
    # The uniform is drawn first, so the acceptance is "log pi(W') > floor" with
    # floor = log pi(W) + T (log u - log_ratio). A target that can bound log pi(W') cheaply
    # (``supports_floor``) skips the costly part (the knowledge engine) of proposals that cannot
    # reach the floor: still exact Metropolis-Hastings-Green, only less work.
    u = rng.random()
    log_u = math.log(u) if u > 0.0 else -math.inf
    old = tracker.logp
    floor = None if old == -math.inf else old + temperature * (log_u - proposal.log_ratio)
    if floor is not None and getattr(tracker, "supports_floor", False):
        prop = tracker.propose(proposal.world, proposal.changed_slots, floor=floor)
    else:
        prop = tracker.propose(proposal.world, proposal.changed_slots)
    new = prop.logp
    if new == -math.inf or math.isnan(new):
        return False
    if old == -math.inf or new > floor:  # leaving an impossible start is always accepted
        tracker.accept(prop)
        return True
    return False


class ChainStats(NamedTuple):
    """Per-kind counts of a run: ``attempted[i]``, ``accepted[i]``, ``impossible[i]`` (``None`` moves)."""

    kinds: tuple
    attempted: np.ndarray
    accepted: np.ndarray
    impossible: np.ndarray

    def acceptance(self) -> dict:
        return {k: (float(a) / n if n else math.nan)
                for k, a, n in zip(self.kinds, self.accepted, self.attempted)}


def run_chain(rng, tracker, kernels, n: int, data, temperature: float = 1.0, callback=None) -> ChainStats:
    """Apply ``n`` kernels drawn from the mix ``kernels`` with MH–Green acceptance.

    Parameters
    ----------
    rng : numpy.random.Generator
    tracker : Tracker
        Updated in place (it is the one stateful object of a chain).
    kernels : semmap_pp.sampler.kernels.Mix
    n : int
    data : KernelData
    temperature : float
    callback : callable(i, tracker, accepted), optional
        Called after every kernel (e.g. to record states in tests).
    """
    k = len(kernels)
    attempted, accepted, impossible = np.zeros(k, np.int64), np.zeros(k, np.int64), np.zeros(k, np.int64)
    for i in range(n):
        j, proposal = kernels(rng, tracker.world, data)
        attempted[j] += 1
        if proposal is None:
            impossible[j] += 1
            ok = False
        else:
            ok = mh_green(rng, tracker, proposal, temperature)
            accepted[j] += ok
        if callback is not None:
            callback(i, tracker, ok)
    return ChainStats(kernels.kinds, attempted, accepted, impossible)
