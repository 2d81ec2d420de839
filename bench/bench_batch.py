"""``semmap batch`` throughput: one worker against two, and what a task costs the scheduler.

``python bench/run.py batch --json [--draws N] [--spread-draws N]``

* **throughput**: the same eight maps (the two bundled paper maps, the five real-gt floors, the
  test corner of intel) run by ``semmap batch`` with ``--workers 1``, then ``--workers 2``, each
  into a fresh folder, in one run of this benchmark; the ratio of the walls is the speed-up.
* **overhead**: 200 no-op tasks on a two-worker LocalCluster: the scheduler's cost per task,
  against a map's seconds; and the bytes a task ships (its arguments and its result, pickled).
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


def add_arguments(parser) -> None:
    parser.add_argument("--draws", type=int, default=None, help="semmap map --draws (model default)")
    parser.add_argument("--spread-draws", type=int, default=None, help="semmap map --spread-draws")


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

    from semmap_pp import batch as B

    extra = []
    if args.draws is not None:
        extra += ["--draws", str(args.draws)]
    if args.spread_draws is not None:
        extra += ["--spread-draws", str(args.spread_draws)]
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        links = MAPS            # the real-gt floors, all map.yaml, are named by their folders
        # compiled code cached before the clock starts (a first run after an install compiles)
        subprocess.run([sys.executable, "-m", "semmap_pp", "map", str(MAPS[-1]), "--out", str(tmp / "warm"),
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
            client.gather(client.map(abs, range(200), pure=False))
            per_task = (time.perf_counter() - t0) / 200
        cluster.close()
        task = B.plan_tasks([links[0]], tmp / "w2", None, None)[0]
        shipped = len(pickle.dumps((B.run_task, task, ["--cores", "1", *extra], None)))
        result_bytes = len(pickle.dumps(B.Result(str(links[0]), None, None, task.out, "ok").__dict__ |
                                        {"units": {"room": 10, "corridor": 2, "hall": 0, "other": 3},
                                         "doors": 12, "cpr": 0.9, "log_posterior": -1e6, "wall_s": 12.3}))
    return {"maps": [str(m.relative_to(ROOT)) for m in MAPS], "extra": extra,
            "one_worker_s": round(one, 1), "two_workers_s": round(two, 1), "speedup": round(one / two, 3),
            "target_speedup": 1.7, "per_task_overhead_ms": round(per_task * 1e3, 2),
            "mean_map_s_one_worker": round(one / len(MAPS), 1), "task_bytes": shipped,
            "result_bytes": result_bytes, "task_wall_s_one_worker": walls}
