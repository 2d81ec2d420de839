"""The PyMC step method that runs the reversible-jump kernels (the only module that imports PyMC).

PyMC's ``pm.Model`` is only a container here: it holds three fixed-shape variables of the world
(``rects`` (K, 4) ``pm.Flat``, ``active`` (K,) and ``types`` (K,) discrete, none transformed) so that
``pm.sample`` can drive chains, traces and multiprocessing. :class:`WorldStep` owns all three: each
PyMC draw applies ``n_inner`` kernels with the MH–Green acceptance against the incremental target
(:mod:`semmap_pp.target.posterior`), so PyMC's per-draw cost is shared by many kernels.

Chains: PyMC calls :meth:`WorldStep.setup_chain` before each chain (sequential chains share one step
object, parallel ones get an unpickled copy), which drops the target's caches; the first
:meth:`~WorldStep.step` of the chain rebuilds them from the chain's start point. A start with
``log p = -inf`` falls back to the empty world. During tuning (burn-in) the target can be annealed:
``log alpha = Δ log p / T + log_ratio`` with ``T`` falling geometrically from ``anneal`` to 1.
The best world seen (its ``log p``, rectangles and activity) is reported in the stats of every draw,
so the MAP world ``W*`` can be taken across chains even when they ran in other processes.

Stopping early (docs/cli.md, ``--budget`` and Ctrl-C): the step checks a ``stop`` flag (set by the
main process's signal handler) before every kernel and a per-chain deadline (``--budget``). Once it
stops, every further draw is *empty*: no kernel runs, the point is returned unchanged and the stat
``stopped`` is 1, so ``pm.sample`` ends normally, in one process or many, and the caller keeps the
draws with ``stopped == 0``. A chain that has begun is not stopped before ``min_draws`` real draws
(R-hat and ESS need four); one that has not begun makes none. A deadline reached during burn-in ends the burn-in there (temperature 1, knowledge on) and
the chain records ``min_draws`` draws before it stops. A chain can continue an earlier run
(:class:`ChainStart`): its draw index, random state, knowledge phase and best world are restored.
"""

from __future__ import annotations

import math
import multiprocessing
import signal
import time
from typing import NamedTuple

import numpy as np
import pymc as pm
from pymc.step_methods.compound import BlockedStep, Competence

from semmap_pp import world as wm
from semmap_pp.cells import UNIT_TYPES
from semmap_pp.sampler.chain_settings import ChainLimits, ChainSettings
from semmap_pp.sampler.kernels import KIND_NAMES, default_mix
from semmap_pp.sampler.mcmc import mh_green
from semmap_pp.sampler.replicas import Ladder, swap_round

VAR_NAMES = ("rects", "active", "types")


def world_model(capacity: int) -> pm.Model:
    """A ``pm.Model`` holding the world variables of ``capacity`` slots (flat, untransformed)."""
    with pm.Model() as model:
        pm.Flat("rects", shape=(capacity, 4))
        pm.DiscreteUniform("active", 0, 1, shape=capacity)
        pm.DiscreteUniform("types", wm.NO_TYPE, len(UNIT_TYPES) - 1, shape=capacity)
    return model


def world_to_point(world: wm.World) -> dict:
    """The PyMC point (``initvals`` entry) of a world."""
    return {"rects": world.rects.astype(np.float64), "active": world.active.astype(np.int64),
            "types": world.types.astype(np.int64)}


def point_to_world(point: dict) -> wm.World:
    """The world of a PyMC point (rectangles rounded to the lattice)."""
    return wm.make(np.rint(point["rects"]).astype(np.int32), np.asarray(point["active"]) > 0,
                   np.asarray(point["types"]))


class ChainStart(NamedTuple):
    """Where a chain continues an earlier run (``--resume``).

    Attributes
    ----------
    draw : int
        Real draws the chain has made (burn-in included): the absolute index of its next draw.
    n_tune : int
        The chain's burn-in length (shorter than planned when a budget cut it).
    rng_state : dict
        ``rng.bit_generator.state`` after the chain's last draw.
    knowledge_on : bool
        Knowledge phase of the chain's last draw.
    best_logp : float
    best_rects, best_active : ndarray
        The chain's best world so far.
    """

    draw: int
    n_tune: int
    rng_state: dict
    knowledge_on: bool
    best_logp: float
    best_rects: np.ndarray
    best_active: np.ndarray


class StopFlag:
    """A flag set by a signal handler and read by the step between kernels.

    A pickled copy (the step sent to a worker process) is a new, unset flag: workers are stopped
    by the main process (``pm.sample`` aborts them), never by their own copy.
    """

    def __init__(self):
        self.reason: str | None = None

    def set(self, reason: str = "interrupted") -> None:
        if self.reason is None:
            self.reason = reason

    def __call__(self) -> bool:
        return self.reason is not None

    def __reduce__(self):
        return (StopFlag, ())


def chain_index(rng) -> int | None:
    """The chain number PyMC gave ``rng`` (``pm.sample`` spawns one generator per chain), or None."""
    try:
        key = rng.bit_generator.seed_seq.spawn_key
    except AttributeError:
        return None
    return int(key[-1]) if key else None


def draw_info(stats: dict) -> dict:
    """The progress record of one draw (what ``callback`` receives) from the step's stats."""
    return {"chain": int(stats["chain"]), "draw": int(stats["draw_index"]),
            "total": int(stats["total_draws"]), "n_tune": int(stats["n_tune"]),
            "phase": "burn-in" if stats["burn_in"] else "sampling", "stopped": bool(stats["stopped"]),
            "logp": float(stats["logp"]), "best_logp": float(stats["best_logp"]),
            "n_units": int(stats["n_units"]), "cpr": float(stats["cpr"]),
            "temperature": float(stats["temperature"]), "accept": float(stats["accept"]),
            "seconds": float(stats.get("seconds", 0.0))}


def _scalar_stats() -> dict:
    stats = {"logp": (np.float64, []), "n_units": (np.int64, []), "cpr": (np.float64, []),
             "chain": (np.int64, []), "draw_index": (np.int64, []), "burn_in": (np.int64, []),
             "stopped": (np.int64, []), "n_tune": (np.int64, []), "total_draws": (np.int64, []),
             "wall_length": (np.float64, []), "knowledge": (np.int64, []),
             "accept": (np.float64, []), "temperature": (np.float64, []), "best_logp": (np.float64, []),
             "seconds": (np.float64, []), "beta": (np.float64, []), "swap_accept": (np.float64, [])}
    stats.update({f"accept_{k}": (np.float64, []) for k in KIND_NAMES})
    stats.update({f"n_{t}": (np.int64, []) for t in UNIT_TYPES})
    return stats


class WorldStep(BlockedStep):
    """Reversible-jump MCMC over worlds as a PyMC ``BlockedStep``.

    Parameters
    ----------
    vars : list
        The model's ``rects``, ``active`` and ``types`` value variables (see :func:`world_model`).
    target : Posterior or callable
        The target (``start(world) -> tracker``) or a zero-argument callable returning it (use a
        callable when the target itself does not pickle; it is called once per process).
    data : KernelData
    chain : ChainSettings
        How every draw runs and what it reports.
    limits : ChainLimits
        When a chain stops, and where it continues an earlier run.
    """

    name = "semmap_world"
    stats_dtypes_shapes = _scalar_stats()

    def __init__(self, vars=None, target=None, data=None, *, chain: ChainSettings = ChainSettings(),
                 limits: ChainLimits = ChainLimits(), model=None, blocked: bool = True, rng=None):
        model = pm.modelcontext(model)
        self.vars = [model.rvs_to_values.get(v, v) for v in (vars or model.value_vars)]
        names = sorted(v.name for v in self.vars)
        if names != sorted(VAR_NAMES):
            raise ValueError(f"WorldStep owns exactly the variables {VAR_NAMES}, got {names}")
        if target is None or data is None:
            raise ValueError("WorldStep needs a target and the kernel data")
        if chain.n_inner < 1 or chain.anneal < 1.0:
            raise ValueError("n_inner must be >= 1 and anneal >= 1")
        self.capacity = int(model.initial_point()["active"].shape[0])
        # The best world and the random state travel as object stats (PyMC's ndarray trace stores
        # scalar stats only).
        self.stats_dtypes_shapes = dict(_scalar_stats(), best_rects=(object, None),
                                        best_active=(object, None), rng_state=(object, None))
        self.stats_dtypes = [{k: d for k, (d, _) in self.stats_dtypes_shapes.items()}]
        self._target = target
        self.data = data
        self.mix = chain.mix if chain.mix is not None else default_mix(data.settings)
        self._kind_index = np.array([KIND_NAMES.index(k) for k in self.mix.kinds])
        self.n_inner = int(chain.n_inner)
        self.anneal = float(chain.anneal)
        self.cpr_fn = chain.cpr_fn
        self.resolution = float(chain.resolution)
        self.knowledge_threshold = chain.knowledge_threshold
        self.callback = chain.callback
        self.ladder = Ladder(chain.ladder, chain.temperatures)
        self.swaps = int(chain.swaps)
        self.stop = limits.stop
        self.deadline = limits.deadline
        self.chain_seconds = limits.chain_seconds
        self.schedule = limits.schedule
        self.resume = dict(limits.resume or {})
        self.min_draws = int(limits.min_draws)
        self.rng = np.random.default_rng(rng)
        self.tune = False
        self._chains_set_up = 0
        self._chain = 0
        self._reset_chain(0, None)

    # -------------------------------------------------------------- chain set-up
    def _phased(self) -> bool:
        return self.knowledge_threshold is not None and getattr(self.target, "knowledge", None) is not None

    def _reset_chain(self, tune: int, draws: int | None) -> None:
        self._tracker = None
        if self._phased():
            self.target.knowledge_on = False  # sequential chains share the target: each starts off
        self._n_tune = int(tune)
        self._total = None if draws is None else int(tune) + int(draws)
        self._draw = 0
        self._best = (-math.inf, None, None)
        self._stopped = False
        self._chain_deadline = self.deadline

    def setup_chain(self, rng, tune: int, draws: int) -> None:
        """Called by PyMC before each chain: new RNG, caches dropped (rebuilt from the start point)."""
        super().setup_chain(rng, tune, draws)
        index = chain_index(self.rng)
        self._chain = index if index is not None else self._chains_set_up
        self._chains_set_up += 1
        if self.schedule is not None:
            self._reset_chain(self.schedule[0], self.schedule[1] - self.schedule[0])
        else:
            self._reset_chain(tune, draws)
        start = self.resume.get(self._chain)
        if start is not None:
            self._draw, self._n_tune = int(start.draw), int(start.n_tune)
            self.rng.bit_generator.state = start.rng_state
            if self._phased():
                self.target.knowledge_on = bool(start.knowledge_on)
            if start.best_rects is not None:
                self._best = (float(start.best_logp), np.asarray(start.best_rects).copy(),
                              np.asarray(start.best_active, bool).copy())
        if self.chain_seconds is not None:
            own = time.time() + self.chain_seconds
            self._chain_deadline = own if self.deadline is None else min(own, self.deadline)
        if multiprocessing.parent_process() is not None:
            # A worker: Ctrl-C reaches the whole process group, but only the main process decides
            # (it aborts the workers through pm.sample); a KeyboardInterrupt here would kill the pipe.
            try:
                signal.signal(signal.SIGINT, signal.SIG_IGN)
            except ValueError:  # not the main thread of the worker: nothing to protect
                pass

    def __getstate__(self):
        state = self.__dict__.copy()
        state["_tracker"] = None  # caches are per process and per chain
        return state

    @property
    def target(self):
        if callable(self._target) and not hasattr(self._target, "start"):
            self._target = self._target()
        return self._target

    def _sync(self, point):
        world = point_to_world(point)
        tr = self._tracker
        if tr is not None and np.array_equal(tr.world.rects, world.rects) \
                and np.array_equal(tr.world.active, world.active):
            return tr
        cold = self.ladder.posts(self.target)[0]
        tr = cold.start(world)
        if tr.logp == -math.inf:  # guard an impossible start: begin from the empty world instead
            empty = cold.start(wm.empty(world.capacity))
            if empty.logp > -math.inf:
                tr = empty
        self._tracker = tr
        self.ladder.start(self.target, tr)
        self._remember(tr)
        return tr

    def _full_logp(self, tr) -> float:
        """``tr``'s log posterior under the untempered target (the cold rung's own when it is)."""
        return self.ladder.full_logp(tr, self.target)

    def _remember(self, tr) -> None:
        logp = self._full_logp(tr)
        if logp > self._best[0]:
            self._best = (logp, tr.world.rects.copy(), tr.world.active.copy())

    def temperature(self) -> float:
        """Temperature of the current draw: geometric from ``anneal`` to 1 over the burn-in draws."""
        if self._n_tune <= 0 or self.anneal == 1.0 or self._draw >= self._n_tune:
            return 1.0
        return self.anneal ** (1.0 - self._draw / self._n_tune)

    # -------------------------------------------------------------- stopping
    def _must_stop(self) -> bool:
        """Whether the chain stops now (after its ``min_draws``); a late budget ends burn-in first."""
        if self._stopped:
            return True
        if self._total is not None and self._draw >= self._total:
            self._stopped = True
            return True
        if 0 < self._draw < self.min_draws:
            return False  # a chain that has begun makes its min_draws; one that has not stays empty
        if self.stop is not None and self.stop():
            self._stopped = True
        elif self._chain_deadline is not None and time.time() >= self._chain_deadline:
            if self._draw < self._n_tune:
                # the budget ran out in burn-in: end it here and record min_draws draws at T = 1
                self._n_tune = self._draw
                self._total = self._draw + self.min_draws
                self._chain_deadline = None
            else:
                self._stopped = True
        return self._stopped

    # -------------------------------------------------------------- one draw
    def _switch_knowledge(self, tr) -> None:
        """Turn knowledge on once coverage reaches the threshold, or when recording starts."""
        if not self._phased() or self.target.knowledge_on:
            return
        recording = self._draw >= self._n_tune
        if recording or tr.coverage() >= self.knowledge_threshold:
            self.target.knowledge_on = True
            tr.resync()
            for hot in self.ladder.hot():
                hot.resync()
            self._best = (-math.inf, None, None)  # W* is judged under the full target only
            self._remember(tr)

    def step(self, point):
        tr = self._sync(point)
        if self._must_stop():
            return self._emit(tr, math.nan, None, None, stopped=True)
        self._switch_knowledge(tr)
        temp = self.temperature()
        k = len(self.mix)
        attempted, accepted = np.zeros(k, np.int64), np.zeros(k, np.int64)
        t0 = time.perf_counter()
        self._kernels(tr, temp, attempted, accepted, cold=True)
        swapped = math.nan
        if len(self.ladder) > 1:
            heat = self.ladder.temperatures
            for t_k, hot in zip(heat[1:], self.ladder.hot()):
                self._kernels(hot, temp * t_k, np.zeros(k, np.int64), np.zeros(k, np.int64), cold=False)
            tried, done = swap_round(self.rng, self.ladder.replicas, self.swaps,
                                     heat if self.ladder.heated else None)
            swapped = done / tried if tried else math.nan
            if self.ladder.replicas[0] is not tr:
                tr = self._tracker = self.ladder.replicas[0]
                self._remember(tr)
        self._draw += 1
        return self._emit(tr, temp, attempted, accepted, stopped=False,
                          seconds=time.perf_counter() - t0, swapped=swapped)

    def _kernels(self, tr, temp, attempted, accepted, *, cold: bool) -> None:
        """``n_inner`` kernels of the mix on one rung's tracker (the cold one keeps the best world)."""
        rng, mix, data = self.rng, self.mix, self.data
        # the best world is judged under the untempered target: a tempered cold rung checks it at
        # every accepted move, the untempered one when its log posterior passes the best so far
        every = self.ladder.exponents[0] != 1.0
        best = self._best[0]
        stop = self.stop if self._draw >= self.min_draws else None
        for _ in range(self.n_inner):
            if stop is not None and stop():
                break  # a partial draw is still a valid state of the chain
            j, proposal = mix(rng, tr.world, data)
            attempted[j] += 1
            if proposal is not None and mh_green(rng, tr, proposal, temp):
                accepted[j] += 1
                if cold and (every or tr.logp > best):
                    self._remember(tr)
                    best = tr.logp

    def _emit(self, tr, temp, attempted, accepted, *, stopped: bool, seconds: float = 0.0,
              swapped: float = math.nan):
        world = tr.world
        n_done = max(int(attempted.sum()), 1) if attempted is not None else 1
        stats = {"logp": self._full_logp(tr), "n_units": wm.n_units(world), "temperature": temp,
                 "cpr": float(self.cpr_fn(tr)) if self.cpr_fn is not None else math.nan,
                 "wall_length": float(2 * np.sum((world.rects[:, 2] - world.rects[:, 0])
                                                 + (world.rects[:, 3] - world.rects[:, 1]))) * self.resolution,
                 "knowledge": int(bool(getattr(self.target, "knowledge_on", False))),
                 "accept": float(accepted.sum()) / n_done if accepted is not None else math.nan,
                 "best_logp": float(self._best[0]), "chain": self._chain,
                 "draw_index": self._draw - (0 if stopped else 1),
                 "burn_in": int(not stopped and self._draw - 1 < self._n_tune), "stopped": int(stopped),
                 "n_tune": self._n_tune, "total_draws": -1 if self._total is None else self._total,
                 "seconds": float(seconds), "beta": self.ladder.exponents[0],
                 "swap_accept": float(swapped)}
        for kind in KIND_NAMES:
            stats[f"accept_{kind}"] = math.nan
        if attempted is not None:
            for kind, a, n in zip(self.mix.kinds, accepted, attempted):
                stats[f"accept_{kind}"] = float(a) / n if n else math.nan
        typed = world.types[world.active].astype(np.int64)
        counts = np.bincount(typed[typed >= 0], minlength=len(UNIT_TYPES))
        for t, c in zip(UNIT_TYPES, counts):
            stats[f"n_{t}"] = int(c)
        _, b_rects, b_active = self._best
        stats["best_rects"] = b_rects.astype(np.int64)
        stats["best_active"] = b_active.astype(bool)
        stats["rng_state"] = self.rng.bit_generator.state
        if self.callback is not None:
            self.callback(draw_info(stats))
        return world_to_point(world), [stats]

    @staticmethod
    def competence(var, has_grad):
        return Competence.INCOMPATIBLE  # only ever assigned explicitly
