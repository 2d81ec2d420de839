"""Sampler speed on a real map: kernel applications per second, plain Python and through ``pm.sample``.

``python bench/run.py sampler --json``. On the cartesium lattice the chain is first burnt in from the
empty world with the plain loop (``--burn`` kernels) so that it holds units; then it measures

* ``kernels_alone_us``: each kernel pair's CPU cost without the target (proposal and exact ratio);
* ``loop_kernels_per_s``: :func:`semmap_pp.sampler.mcmc.run_chain` with the project's Posterior;
* ``pymc_kernels_per_s``: one chain through ``pm.sample`` with :class:`semmap_pp.sampler.step.WorldStep`
  (``--draws`` draws of ``--n-inner`` kernels, timed around ``pm.sample``, set-up included);
* ``pymc_overhead_us_per_draw``: ``pm.sample`` with a constant target and one kernel per draw, minus
  the same kernels in the plain loop: what PyMC adds per draw;
* ``knowledge_kernels_per_cpu_s``: the burnt-in chain with the knowledge engine on
  (``--rules``, a fresh engine), ``--knowledge-warm`` kernels after the switch, then
  ``--knowledge-kernels`` kernels timed (CPU time) in the plain loop;
  ``knowledge_first_kernels_per_cpu_s`` is the rate of the warm-up kernels (the fresh engine's
  templates are built there, as in every ``semmap map`` process), and ``knowledge_counts`` what
  the target did in the timed kernels (proposals evaluated, skipped by the floor bound, evidence
  unchanged, engine cache hits and misses); ``knowledge_template_groundings`` counts the clingo
  groundings of the fresh engine (0 once the template store holds them, as in every later
  ``semmap map`` process; ``SEMMAP_TEMPLATE_CACHE=off`` measures a process without the store);
* ``knowledge_pymc_kernels_per_s``: the same start world with knowledge on through ``pm.sample``,
  one chain (``--knowledge-pymc-draws`` draws of ``--n-inner`` kernels, a fresh engine and
  posterior, ``SampleResult.seconds``: wall time around ``pm.sample``, PyMC's set-up included;
  ``..._per_cpu_s`` the process CPU time around ``sample_worlds``).

``--only knowledge`` runs the burn-in and the knowledge measurement alone. ``--tiny`` runs every
part once at a few kernels on tests/data/maps/intel_corner.yaml (:data:`TINY`): the check of
tests/integration/test_bench_smoke.py that the benchmark runs, not a measurement.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from semmap_pp import world as wm
from semmap_pp.lattice.frame import build_frame
from semmap_pp.grid import load_map
from semmap_pp.sampler.kernels import data_from_frame, default_mix
from semmap_pp.sampler.mcmc import run_chain
from semmap_pp.model import load_model
from semmap_pp.target.posterior import Posterior
from semmap_pp.sampler.sampling import _FlatTracker, sample_worlds

ROOT = Path(__file__).resolve().parents[1]
#: ``--tiny``: the arguments it sets
TINY = {"map": str(ROOT / "tests/data/maps/intel_corner.yaml"), "burn": 50, "kernels": 50, "draws": 2,
        "n_inner": 5, "knowledge_warm": 10, "knowledge_kernels": 20, "knowledge_pymc_draws": 2,
        "flat_draws": 20}


def add_arguments(parser) -> None:
    parser.add_argument("--map", default=str(ROOT / "data/maps/ubremen-cartesium.yaml"))
    parser.add_argument("--burn", type=int, default=3000, help="plain-loop kernels before timing")
    parser.add_argument("--kernels", type=int, default=5000, help="kernels in the timed plain loop")
    parser.add_argument("--draws", type=int, default=200)
    parser.add_argument("--n-inner", type=int, default=100)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--rules", default=str(ROOT / "rules/table3.lp"))
    parser.add_argument("--knowledge-start", choices=("refined", "burnt"), default="refined",
                        help="knowledge chain starts from semmap map's start world (refined) or "
                        "from the burnt-in chain")
    parser.add_argument("--knowledge-warm", type=int, default=300)
    parser.add_argument("--knowledge-kernels", type=int, default=1500)
    parser.add_argument("--knowledge-pymc-draws", type=int, default=60,
                        help="draws of --n-inner kernels through pm.sample with knowledge on "
                        "(0: skip)")
    parser.add_argument("--flat-draws", type=int, default=2000,
                        help="draws of one kernel through pm.sample with a constant target (PyMC's cost)")
    parser.add_argument("--only", choices=("all", "knowledge"), default="all")
    parser.add_argument("--tiny", action="store_true",
                        help="every part once at a few kernels on a small map (a check that it runs)")


class _Flat:
    def start(self, world):
        return _FlatTracker(world)


def knowledge_rate(args, frame, model, data, start) -> dict:
    """Kernels per CPU-s of the chain at ``start`` with the knowledge engine on (plain loop)."""
    from semmap_pp.knowledge import KnowledgeEngine

    engine = KnowledgeEngine.from_file(args.rules)
    post = Posterior(frame, model, engine)
    mix = default_mix(data.settings)
    rng = np.random.default_rng(args.seed + 1)
    tracker = post.start(start)
    post.knowledge_on = True
    tracker.resync()
    counts = {"proposals": 0, "bounded": 0}
    propose = tracker.propose

    def counted(world, changed, floor=None):
        prop = propose(world, changed, floor=floor)
        counts["proposals"] += 1
        counts["bounded"] += bool(prop.bounded)
        return prop

    tracker.propose = counted
    c0 = time.process_time()
    run_chain(rng, tracker, mix, args.knowledge_warm, data)
    c_warm = time.process_time() - c0
    counts.update(proposals=0, bounded=0)
    hits0, misses0 = engine.hits, engine.misses
    c0 = time.process_time()
    stats = run_chain(rng, tracker, mix, args.knowledge_kernels, data)
    c_timed = time.process_time() - c0
    counts.update(engine_hits=engine.hits - hits0, engine_misses=engine.misses - misses0,
                  accepted=int(stats.accepted.sum()))
    full = post.evaluate(tracker.world).total
    out = {
        "knowledge_rules": Path(args.rules).name, "knowledge_start": args.knowledge_start,
        "knowledge_units": wm.n_units(tracker.world),
        "knowledge_first_kernels_per_cpu_s": round(args.knowledge_warm / max(c_warm, 1e-9), 1),
        "knowledge_kernels_per_cpu_s": round(args.knowledge_kernels / max(c_timed, 1e-9), 1),
        "knowledge_counts": counts,
        "knowledge_template_groundings": engine.local.groundings if engine.local else None,
        "knowledge_tracker_error": abs(tracker.logp - full) / max(abs(full), 1.0),
    }
    if args.knowledge_pymc_draws > 0:
        post = Posterior(frame, model, KnowledgeEngine.from_file(args.rules))
        post.knowledge_on = True
        c0 = time.process_time()
        res = sample_worlds(post, data, [start], draws=args.knowledge_pymc_draws, tune=0,
                            chains=1, cores=1, n_inner=args.n_inner, seed=args.seed + 2)
        c_pymc = time.process_time() - c0
        n = args.knowledge_pymc_draws * args.n_inner
        out.update(knowledge_pymc_kernels=n,
                   knowledge_pymc_kernels_per_s=round(n / res.seconds, 1),
                   knowledge_pymc_kernels_per_cpu_s=round(n / c_pymc, 1))
    return out


def run(args) -> dict:
    if args.tiny:
        for key, value in TINY.items():
            setattr(args, key, value)
    model = load_model()
    frame = build_frame(load_map(args.map), model)
    t0 = time.perf_counter()
    data = data_from_frame(frame)
    t_data = time.perf_counter() - t0
    post = Posterior(frame, model)
    capacity = model.prior.k_max
    mix = default_mix(data.settings)
    rng = np.random.default_rng(args.seed)

    tracker = post.start(wm.empty(capacity))
    run_chain(rng, tracker, mix, args.burn, data)
    start = tracker.world
    kstart = start
    if args.knowledge_start == "refined":   # the start world of semmap map's first chain
        from semmap_pp.run.inputs import load_inputs
        from semmap_pp.run.pipeline import start_worlds
        kstart = start_worlds(load_inputs(args.map, rules_path=args.rules), 1,
                              np.random.default_rng(args.seed))[0]
    knowledge = knowledge_rate(args, frame, model, data, kstart)
    if args.only == "knowledge":
        return {"map": args.map, "units_at_start": wm.n_units(start), **knowledge}

    alone = {}   # CPU time: robust when other processes share the cores
    for kernel in mix.kernels:
        c0 = time.process_time()
        for _ in range(1000):
            kernel(rng, start, data)
        alone[kernel.kind] = round((time.process_time() - c0) / 1000 * 1e6, 1)

    t0, c0 = time.perf_counter(), time.process_time()
    stats = run_chain(rng, tracker, mix, args.kernels, data)
    t_loop, c_loop = time.perf_counter() - t0, time.process_time() - c0

    c0 = time.process_time()
    res = sample_worlds(post, data, [start], draws=args.draws, tune=0, chains=1, cores=1,
                        n_inner=args.n_inner, seed=args.seed)
    c_pymc = time.process_time() - c0
    n_pymc = args.draws * args.n_inner

    # PyMC's own cost per draw: constant target, one kernel per draw, against the same in a loop
    n_flat = args.flat_draws
    flat = sample_worlds(_Flat(), data, [start], draws=n_flat, tune=0, chains=1, cores=1, n_inner=1,
                         seed=args.seed)
    tr = _FlatTracker(start)
    t0 = time.perf_counter()
    run_chain(np.random.default_rng(args.seed), tr, mix, n_flat, data)
    t_flat_loop = time.perf_counter() - t0
    return {
        "map": args.map, "lattice": list(frame.shape), "capacity": capacity,
        "units_at_start": wm.n_units(start), "data_build_s": round(t_data, 3),
        "birth_candidates": int(len(data.birth_rects)),
        "kernels_alone_us": alone,
        "loop_kernels_per_s": round(args.kernels / t_loop, 1),
        "loop_kernels_per_cpu_s": round(args.kernels / c_loop, 1),
        "loop_acceptance": {k: round(v, 4) for k, v in stats.acceptance().items()},
        "pymc_kernels_per_s": round(n_pymc / res.seconds, 1),
        "pymc_kernels_per_cpu_s": round(n_pymc / c_pymc, 1),
        "pymc_draws": args.draws, "pymc_n_inner": args.n_inner,
        "pymc_overhead_us_per_draw": round((flat.seconds - t_flat_loop) / n_flat * 1e6, 1),
        "units_at_end": wm.n_units(tracker.world),
        **knowledge,
    }
