"""``semmap batch`` throughput: one worker against two, and what a task costs the scheduler.

``python bench/run.py batch --json [--draws N] [--spread-draws N]``

* **throughput**: the same eight maps (the two bundled paper maps, the five real-gt floors, the
  test corner of intel) run by ``semmap batch`` with ``--workers 1``, then ``--workers 2``, each
  into a fresh folder, in one run of this benchmark; the ratio of the walls is the speed-up.
* **overhead**: 200 no-op tasks on a two-worker LocalCluster: the scheduler's cost per task,
  against a map's seconds; and the bytes a task ships (its arguments and its result, pickled).

``--maps`` and ``--tasks`` replace the eight maps (the last one also warms the compiled code) and
the 200 tasks; ``--tiny`` (:data:`TINY`: the 5 x 4 cell test map alone, one chain of 2 + 4 draws,
20 tasks) is the check of tests/integration/test_bench_smoke.py that the benchmark runs, not a measurement.
"""

from __future__ import annotations

import json
import pickle
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
MAPS = ([ROOT / "data" / "maps" / "ubremen-cartesium.yaml", ROOT / "data" / "maps" / "intel-lab.yaml"]
        + sorted((ROOT / "bench" / "data" / "real-gt").glob("*/map.yaml"))
        + [ROOT / "tests" / "data" / "maps" / "intel_corner.yaml"])
#: ``--tiny``: the arguments it sets
TINY = {"maps": [ROOT / "tests" / "data" / "maps" / "tiny.yaml"], "tasks": 20, "chains": 1, "tune": 2, "draws": 4, "n_inner": 10,
        "spread_draws": 0}


def add_arguments(parser) -> None:
    parser.add_argument("--maps", type=Path, nargs="+", default=MAPS, help="the maps (default: the eight above)")
    parser.add_argument("--tasks", type=int, default=200, help="no-op tasks timed on the cluster")
    parser.add_argument("--chains", type=int, default=None, help="semmap map --chains (model default)")
    parser.add_argument("--tune", type=int, default=None, help="semmap map --tune (model default)")
    parser.add_argument("--draws", type=int, default=None, help="semmap map --draws (model default)")
    parser.add_argument("--n-inner", type=int, default=None, help="semmap map --n-inner (model default)")
    parser.add_argument("--spread-draws", type=int, default=None, help="semmap map --spread-draws")
    parser.add_argument("--tiny", action="store_true", help="one small map, short runs (a check that it runs)")


def _batch(maps, out: Path, workers: int, extra: list[str]) -> float:
    t0 = time.perf_counter()
    p = subprocess.run([sys.executable, "-m", "semmap_pp", "batch", *map(str, maps), "--out", str(out),
                        "--workers", str(workers), "--progress", "none", *extra],
                       capture_output=True, text=True)
    wall = time.perf_counter() - t0
    if p.returncode != 0:
        raise SystemExit(f"semmap batch failed: {p.stderr.strip()[-500:]}")
    return wall


def run(args) -> dict:
    from distributed import Client, LocalCluster

    from semmap_pp.run import batch as B

    if args.tiny:
        for key, value in TINY.items():
            setattr(args, key, value)
    extra = []
    for option in ("chains", "tune", "draws", "n_inner", "spread_draws"):
        if getattr(args, option) is not None:
            extra += ["--" + option.replace("_", "-"), str(getattr(args, option))]
    maps = [Path(m).resolve() for m in args.maps]
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        links = maps            # the real-gt floors, all map.yaml, are named by their folders
        # compiled code cached before the clock starts (a first run after an install compiles;
        # --tiny, which times nothing, leaves it out)
        if not args.tiny:
            subprocess.run([sys.executable, "-m", "semmap_pp", "map", str(maps[-1]), "--out", str(tmp / "warm"),
                            "--progress", "none", "--draws", "4", "--tune", "2", "--spread-draws", "0"],
                           capture_output=True, check=True)
        one = _batch(links, tmp / "w1", 1, extra)
        two = _batch(links, tmp / "w2", 2, extra)
        walls = {Path(r["out"]).name: r["wall_s"]
                 for r in json.loads((tmp / "w1" / "summary.json").read_text())["tasks"]}

        cluster = LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None,
                               silence_logs=50)
        with Client(cluster) as client:
            client.gather(client.map(abs, range(20)))            # warm
            t0 = time.perf_counter()
            client.gather(client.map(abs, range(args.tasks), pure=False))
            per_task = (time.perf_counter() - t0) / args.tasks
        cluster.close()
        task = B.plan_tasks([links[0]], tmp / "w2", None, None)[0]
        shipped = len(pickle.dumps((B.run_task, task, ["--cores", "1", *extra], None)))
        result_bytes = len(pickle.dumps(B.Result(str(links[0]), None, None, task.out, "ok").__dict__ |
                                        {"units": {"room": 10, "corridor": 2, "hall": 0, "other": 3},
                                         "doors": 12, "cpr": 0.9, "log_posterior": -1e6, "wall_s": 12.3}))
    return {"maps": [str(m.relative_to(ROOT)) if m.is_relative_to(ROOT) else str(m) for m in maps],
            "extra": extra,
            "one_worker_s": round(one, 1), "two_workers_s": round(two, 1), "speedup": round(one / two, 3),
            "target_speedup": 1.7, "per_task_overhead_ms": round(per_task * 1e3, 2),
            "mean_map_s_one_worker": round(one / len(maps), 1), "task_bytes": shipped,
            "result_bytes": result_bytes, "task_wall_s_one_worker": walls}
