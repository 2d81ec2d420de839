"""Replica exchange (parallel tempering) of worlds: a ladder of tempered targets and swap moves.

A chain holds one world per rung of a ladder of likelihood exponents ``β_0 > β_1 > ... > β_K``
(``β_0`` the *cold* target, the one sampled; :func:`semmap_pp.target.tempering.tempered`). Every
replica is moved by the same MH–Green kernels (:func:`semmap_pp.sampler.mcmc.mh_green`) against
its own rung's target; a *swap* proposes to exchange the worlds of two neighbouring rungs ``i``
and ``j = i + 1`` and is accepted with probability

    min(1, exp((β_i − β_j)(ℓ(x_j) − ℓ(x_i)))),

``ℓ`` the log-likelihood (the tempered part; types and prior do not depend on the rung, so they
cancel). A rung may also have a *temperature* ``T_k >= 1`` (``[sampler] spread_temperature_ratio``):
its kernels then sample ``π_k^(1/T_k)`` (:func:`~semmap_pp.sampler.mcmc.mh_green` with that
temperature), so the prior and the knowledge terms are flattened too, not only the likelihood,
and the swap's log ratio is ``log π_i(x_j)/T_i + log π_j(x_i)/T_j − log π_i(x_i)/T_i −
log π_j(x_j)/T_j`` in full (the prior no longer cancels). :func:`swap_log_ratio` forms it as ``log π_i(x_j) + log π_j(x_i) − log π_i(x_i) −
log π_j(x_j)`` from the trackers' own likelihood tallies, which is the same number for any
tempered family. The product of the rungs' targets is invariant under each swap (detailed
balance: ``tests/unit/test_replicas.py`` enumerates it on tiny worlds), so the cold rung's worlds
are draws of the cold target. The pair is drawn uniformly among the ``K`` neighbours, so a round
of swaps is a mixture of reversible moves, itself reversible.

Trackers taking part need ``loglik``, ``logprior``, ``logp``, ``post``,
``loglik_under(post)`` and ``retarget(post)`` (:class:`semmap_pp.target.posterior.Tracker`).
"""

from __future__ import annotations

import math

from semmap_pp.target.tempering import tempered


def geometric_ladder(cold: float, rungs: int, ratio: float) -> tuple[float, ...]:
    """``(cold, cold·ratio, cold·ratio², ...)``: ``rungs`` likelihood exponents, the cold one first.

    Examples
    --------
    >>> geometric_ladder(0.02, 3, 0.5)
    (0.02, 0.01, 0.005)
    """
    if rungs < 1 or not (0.0 < ratio <= 1.0) or not (cold > 0.0):
        raise ValueError(f"a ladder needs rungs >= 1, 0 < ratio <= 1, cold > 0; got {rungs}, {ratio}, {cold}")
    return tuple(float(cold) * float(ratio) ** k for k in range(int(rungs)))


def geometric_temperatures(rungs: int, ratio: float) -> tuple[float, ...]:
    """``(1, ratio, ratio², ...)``: the rungs' temperatures, the cold one 1 (``ratio >= 1``).

    >>> geometric_temperatures(3, 2.0)
    (1.0, 2.0, 4.0)
    """
    if rungs < 1 or not ratio >= 1.0:
        raise ValueError(f"temperatures need rungs >= 1 and a ratio >= 1; got {rungs}, {ratio}")
    return tuple(float(ratio) ** k for k in range(int(rungs)))


def _log_target(tr, post, temperature: float) -> float:
    """``log π(x) / T`` of ``tr``'s world under the rung of target ``post`` at ``temperature``."""
    lp = tr.loglik_under(post) + tr.logprior
    return lp / temperature if lp > -math.inf else -math.inf


def swap_log_ratio(tr_i, tr_j, t_i: float = 1.0, t_j: float = 1.0) -> float:
    """Log acceptance ratio of exchanging the worlds of ``tr_i`` and ``tr_j`` between their
    targets (rungs at temperatures ``t_i`` and ``t_j``)."""
    if t_i != 1.0 or t_j != 1.0:
        before = _log_target(tr_i, tr_i.post, t_i) + _log_target(tr_j, tr_j.post, t_j)
        after = _log_target(tr_j, tr_i.post, t_i) + _log_target(tr_i, tr_j.post, t_j)
        if before == -math.inf:
            return math.inf if after > -math.inf or max(tr_i.logp, tr_j.logp) == -math.inf else 0.0
        return after - before
    mine = tr_i.loglik + tr_j.loglik
    if mine == -math.inf:
        return math.inf if max(tr_i.loglik, tr_j.loglik) == -math.inf else 0.0
    swapped = tr_j.loglik_under(tr_i.post) + tr_i.loglik_under(tr_j.post)
    return swapped - mine


def try_swap(rng, replicas: list, i: int, temperatures=None) -> bool:
    """Propose to exchange the worlds of rungs ``i`` and ``i + 1`` (in place: the trackers change
    places and targets; ``temperatures`` per rung, all 1 when None); MH with the uniform drawn
    first. Returns whether it was accepted."""
    a, b = replicas[i], replicas[i + 1]
    u = rng.random()
    log_u = math.log(u) if u > 0.0 else -math.inf
    t = temperatures
    ratio = swap_log_ratio(a, b) if t is None else swap_log_ratio(a, b, t[i], t[i + 1])
    if math.isnan(ratio) or not log_u < ratio:
        return False
    post_a, post_b = a.post, b.post
    a.retarget(post_b)
    b.retarget(post_a)
    replicas[i], replicas[i + 1] = b, a
    return True


def swap_round(rng, replicas: list, n_swaps: int, temperatures=None) -> tuple[int, int]:
    """``n_swaps`` swap proposals, each between a uniformly drawn pair of neighbouring rungs.
    Returns ``(attempted, accepted)``; nothing with fewer than two rungs."""
    if len(replicas) < 2:
        return 0, 0
    done = 0
    for _ in range(int(n_swaps)):
        i = int(rng.integers(len(replicas) - 1))
        done += try_swap(rng, replicas, i, temperatures)
    return int(n_swaps), done


class Ladder:
    """The rungs of one chain: their tempered targets (made once per process) and trackers.

    Parameters
    ----------
    exponents : sequence of float
        The likelihood exponents, the cold one first (``(1.0,)``: no replica exchange).
    """

    def __init__(self, exponents, temperatures=None):
        self.exponents = tuple(float(b) for b in exponents)
        if not self.exponents or any(not (b > 0.0) for b in self.exponents):
            raise ValueError(f"likelihood exponents must be positive, got {self.exponents}")
        self.temperatures = (tuple(float(t) for t in temperatures) if temperatures is not None
                             else (1.0,) * len(self.exponents))
        if len(self.temperatures) != len(self.exponents) or self.temperatures[0] != 1.0 \
                or any(not t >= 1.0 for t in self.temperatures):
            raise ValueError(f"one temperature >= 1 per rung, the cold one 1; got {self.temperatures}")
        self._posts = None
        self.replicas: list = []

    def __getstate__(self):
        return {"exponents": self.exponents, "temperatures": self.temperatures, "_posts": None,
                "replicas": []}

    @property
    def heated(self) -> bool:
        """Whether some rung has a temperature above 1 (swaps then use the full log ratio)."""
        return any(t != 1.0 for t in self.temperatures)

    def __len__(self) -> int:
        return len(self.exponents)

    def posts(self, target) -> list:
        """The rungs' targets: ``target`` tempered to each exponent (``target`` itself at 1)."""
        if self._posts is None:
            if set(self.exponents) == {1.0}:
                self._posts = [target] * len(self.exponents)
            else:
                self._posts = [tempered(target, b) for b in self.exponents]
        return self._posts

    def start(self, target, cold_tracker) -> None:
        """Every hotter rung starts at the cold tracker's world."""
        posts = self.posts(target)
        self.replicas = [cold_tracker] + [p.start(cold_tracker.world) for p in posts[1:]]

    def full_logp(self, tr, target) -> float:
        """The log posterior of ``tr``'s world under the untempered target."""
        if self.exponents[0] == 1.0 or not hasattr(tr, "loglik_under"):
            return float(tr.logp)
        return float(tr.logprior + tr.loglik_under(getattr(target, "base", target)))

    def hot(self) -> list:
        return self.replicas[1:]

