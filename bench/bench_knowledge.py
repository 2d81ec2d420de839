"""Knowledge engine speed: exact marginals (grounding included), MC-SAT, cache hits, auto/LBP.

Floors are hand-built evidence of real layouts: a corridor with rooms on both sides, a grid of
corridors with rooms, a hall with rooms around it, at 20 and 40 units. "exact" times a cold
engine's first inference (templates warmed on a different floor of the same patterns, as in a
long MCMC run); "exact_cold" includes building the templates. "dense" floors (rows of rooms
between corridor rows, king-move adjacency on alternate cells, soft geometry) at 40 and 80 units
time ``method="auto"`` (which picks loopy BP there) and its error against exact marginals.
"rc2_hard" times the MAP of a captured intel evidence under ``rules/halls_to_corridors.lp``
(``bench/data/intel_halls_rc2_hard.lp``; RC2 on the summed-out tables, whatever ``--rules``).
``--tiny`` runs every row once on small floors (8 units, dense 12 units, one MC-SAT seed, few
cache hits): the check of tests/integration/test_bench_smoke.py that the benchmark runs, not a measurement.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from semmap_pp.knowledge import Evidence, KnowledgeEngine, load_rules
from semmap_pp.knowledge.evidence import evidence_from_facts
from semmap_pp.knowledge.exact import JunctionTree
from semmap_pp.knowledge.layouts import dense_floor
from semmap_pp.knowledge.lbp import pairwise_bp


def corridor_floor(n):
    """Unit 1 a corridor; rooms 2..n on both sides, side neighbours adjacent."""
    rooms = list(range(2, n + 1))
    left, right = rooms[0::2], rooms[1::2]
    adj = [(1, r) for r in rooms]
    adj += list(zip(left, left[1:])) + list(zip(right, right[1:]))
    return Evidence.build(range(1, n + 1), colike={1}, muldoor={1}, rolike=rooms, adj=adj)


def grid_floor(n):
    """Corridors in a grid (every 4th unit), rooms hanging off them."""
    n_corr = max(2, n // 4)
    side = int(np.ceil(np.sqrt(n_corr)))
    corr = list(range(1, n_corr + 1))
    adj = []
    for c in corr:
        r, k = divmod(c - 1, side)
        if k + 1 < side and c + 1 <= n_corr:
            adj.append((c, c + 1))
        if c + side <= n_corr:
            adj.append((c, c + side))
    rooms = list(range(n_corr + 1, n + 1))
    for i, room in enumerate(rooms):
        adj.append((corr[i % n_corr], room))
        if i % 3 and room - 1 in rooms:
            adj.append((room - 1, room))
    return Evidence.build(range(1, n + 1), colike=corr, muldoor=corr + rooms[::5],
                          rolike=rooms, adj=adj)


def hall_floor(n):
    """Unit 1 a hall, rooms around it in a ring, two corridors leaving it."""
    rooms = list(range(4, n + 1))
    adj = [(1, 2), (1, 3)] + [(1, r) for r in rooms] + list(zip(rooms, rooms[1:]))
    return Evidence.build(range(1, n + 1), halike={1}, colike=[2, 3], muldoor=[1, 2, 3],
                          rolike={r: (1.0 if r % 4 else 0.7) for r in rooms}, adj=adj)


FLOORS = {"corridor": corridor_floor, "grid": grid_floor, "hall": hall_floor}

#: the sizes of each part of the run, full and ``--tiny``: units of the hand-built floors, of the
#: floor MC-SAT runs on, of the dense floors of ``auto`` and of the clique rows; MC-SAT seeds of
#: the worst error; cache hits and evidence builds timed; best-of counts of the general path,
#: MC-SAT and the clique rows
SIZES = {"floors": (20, 40), "mcsat_floor": 20, "dense": (40, 80), "cliques": (12, 20, 25, 30, 42),
         "mcsat_seeds": 4, "hits": 20000, "builds": 2000, "best_of": (3, 3, 5)}
TINY = {"floors": (8,), "mcsat_floor": 8, "dense": (12,), "cliques": (12,), "mcsat_seeds": 1,
        "hits": 100, "builds": 10, "best_of": (1, 1, 1)}


def add_arguments(parser):
    parser.add_argument("--rules", default="rules/table3.lp")
    parser.add_argument("--repeat", type=int, default=20)
    parser.add_argument("--tiny", action="store_true",
                        help="every row once on small floors (a check that it runs, not a measurement)")


def _time(fn, repeat):
    best = float("inf")
    for _ in range(repeat):
        t = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t)
    return best


def run(args):
    rules = load_rules(args.rules)
    size = TINY if args.tiny else SIZES
    repeat = 1 if args.tiny else args.repeat
    generic_best, mcsat_best, clique_best = size["best_of"]
    out = {"rules": args.rules}
    warm = KnowledgeEngine(rules, method="exact")
    for name, make in FLOORS.items():
        for n in size["floors"]:
            ev = make(n)
            t = time.perf_counter()
            KnowledgeEngine(rules, method="exact").infer(ev)
            cold = time.perf_counter() - t
            warm.infer(ev)   # builds the templates of these patterns

            def fresh():
                warm._cache.clear()
                warm.infer(ev)
            out[f"exact_ms_{name}_{n}"] = round(1000 * _time(fresh, repeat), 3)
            out[f"exact_cold_ms_{name}_{n}"] = round(1000 * cold, 2)
            generic = KnowledgeEngine(rules, method="exact", fast=False)
            out[f"exact_generic_ms_{name}_{n}"] = round(
                1000 * _time(lambda: (generic._cache.clear(), generic.infer(ev)), generic_best), 2)
    # cache hits
    m = size["mcsat_floor"]
    ev = corridor_floor(m)
    warm.infer(ev)
    k = size["hits"]
    t = time.perf_counter()
    for _ in range(k):
        warm.infer(ev)
    out["cache_hit_us"] = round(1e6 * (time.perf_counter() - t) / k, 3)
    k = size["builds"]
    t = time.perf_counter()
    for _ in range(k):
        warm.infer(corridor_floor(m))
    out["build_evidence_and_hit_us"] = round(1e6 * (time.perf_counter() - t) / k, 2)
    # MC-SAT at default settings on 20 units, error against exact; "mcsat" has the templates
    # warm (as "exact"), "mcsat_cold" is the first call of a fresh engine
    seeds = size["mcsat_seeds"]
    for name in FLOORS:
        ev = FLOORS[name](m)
        exact = KnowledgeEngine(rules, method="exact").infer(ev)
        mc = KnowledgeEngine(rules, method="mcsat")
        t = time.perf_counter()
        mc.infer(ev)
        out[f"mcsat_cold_ms_{name}_{m}"] = round(1000 * (time.perf_counter() - t), 1)

        def fresh_mc():
            mc._cache.clear()
            mc.infer(ev)
        out[f"mcsat_ms_{name}_{m}"] = round(1000 * _time(fresh_mc, mcsat_best), 1)
        cpu = []                    # CPU time per call: less sensitive to a shared machine
        for _ in range(mcsat_best):
            c = time.process_time()
            fresh_mc()
            cpu.append(time.process_time() - c)
        out[f"mcsat_cpu_ms_{name}_{m}"] = round(1000 * min(cpu), 1)

        def error(r):
            return float(max(max(np.abs(r.types[u] - exact.types[u]).max() for u in ev.units),
                             max(abs(r.sale[pq] - exact.sale[pq]) for pq in ev.adj)))
        out[f"mcsat_max_abs_err_{name}_{m}"] = round(error(mc.infer(ev)), 4)
        # the worst over seeds 0..3 (the estimate's spread, not one draw of it)
        out[f"mcsat_worst_err_{seeds}seeds_{name}_{m}"] = round(max(
            error(KnowledgeEngine(rules, method="mcsat", seed=s).infer(ev)) for s in range(seeds)), 4)
    out.update(auto_rows(rules, repeat, size["dense"]))
    out.update(clique_rows(rules, size["cliques"], clique_best))
    out.update(rc2_hard_rows(1 if args.tiny else 3))
    return out


HERE = Path(__file__).resolve().parent


def rc2_hard_rows(best_of=3):
    """The MAP of an evidence whose RC2 instance was hard with one clause per table entry
    (best of ``best_of``, a fresh engine each: grounding, summing out and RC2)."""
    path = HERE / "data" / "intel_halls_rc2_hard.lp"
    ev = evidence_from_facts(path.read_text(), str(path))
    rules = load_rules(HERE.parent / "rules" / "halls_to_corridors.lp")
    ms = 1000 * _time(lambda: KnowledgeEngine(rules).map_types(ev), best_of)
    method = KnowledgeEngine(rules)._ground.ground_map(ev)[5]
    return {"rc2_hard_map_ms": round(ms, 1), "rc2_hard_map_method": method,
            "rc2_hard_units": len(ev.units)}


def clique_rows(rules, sizes=(12, 20, 25, 30, 42), best_of=5):
    """Exact vs LBP time by the largest junction-tree clique, on dense floors of 12..42 units
    (the measurement behind ``engine.AUTO_MAX_STATES``)."""
    out = {}
    exact = KnowledgeEngine(rules, method="exact")
    lbp = KnowledgeEngine(rules, method="lbp")
    for n in sizes:
        ev = dense_floor(n)
        tn = exact.local.type_network(ev)
        scopes = [(i,) for i in range(n)] + [(i, j) for i, j, _ in tn.sum_pairs]
        largest = JunctionTree(tn.card, scopes, max_states=1 << 40).largest
        times = []
        for eng in (exact, lbp):
            eng.infer(ev)

            def fresh(eng=eng):
                eng._cache.clear()
                eng.infer(ev)
            times.append(round(1000 * _time(fresh, best_of), 2))
        out[f"clique_log2_dense_{n}"] = int(np.log2(largest))
        out[f"exact_vs_lbp_ms_dense_{n}"] = times
    return out


def auto_rows(rules, repeat, sizes=(40, 80)):
    """``method="auto"`` on the dense floors: method picked, warm and cold time, error vs exact."""
    out = {}
    for n in sizes:
        ev = dense_floor(n)
        t = time.perf_counter()
        auto = KnowledgeEngine(rules)
        r = auto.infer(ev)
        out[f"auto_cold_ms_dense_{n}"] = round(1000 * (time.perf_counter() - t), 2)
        out[f"auto_method_dense_{n}"] = f"{r.method}/{r.map_method}"

        def fresh():
            auto._cache.clear()
            auto.infer(ev)
        out[f"auto_ms_dense_{n}"] = round(1000 * _time(fresh, repeat), 3)
        c = time.process_time()
        for _ in range(repeat):
            fresh()
        out[f"auto_cpu_ms_dense_{n}"] = round(1000 * (time.process_time() - c) / repeat, 3)
        tn = auto.local.type_network(ev)
        bp = pairwise_bp(tn.unary_sum, tn.sum_pairs, settings=auto.bp)
        out[f"lbp_iterations_dense_{n}"] = bp.iterations
        ex = KnowledgeEngine(rules, method="exact")
        t = time.perf_counter()
        e = ex.infer(ev)
        out[f"exact_ms_dense_{n}"] = round(1000 * (time.perf_counter() - t), 1)
        err = max(max(np.abs(r.types[u] - e.types[u]).max() for u in ev.units),
                  max(abs(r.sale[pq] - e.sale[pq]) for pq in ev.adj))
        out[f"auto_max_abs_err_dense_{n}"] = round(float(err), 4)
        out[f"auto_map_equals_exact_dense_{n}"] = r.map_types == e.map_types
    return out
