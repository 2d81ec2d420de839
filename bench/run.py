"""Benchmark runner: ``python bench/run.py NAME [--json] [...]``.

Each benchmark is a module ``bench/bench_<name>.py`` with ``add_arguments(parser)`` and
``run(args) -> dict``. The runner prints a human summary and, with ``--json``, the result as one
JSON object on the last line (machine and command included), so results can be pasted into
docs/benchmarks.md and compared as ratios within one run.
"""

from __future__ import annotations

import argparse
import importlib
import json
import os
import platform
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent))


def machine() -> dict:
    info = {"python": platform.python_version(), "platform": platform.platform(),
            "cpus": os.cpu_count()}
    try:
        with open("/proc/cpuinfo") as fh:
            for line in fh:
                if line.startswith("model name"):
                    info["cpu"] = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    return info


def main(argv: list[str] | None = None) -> int:
    names = sorted(p.stem[len("bench_"):] for p in HERE.glob("bench_*.py"))
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("name", choices=names)
    parser.add_argument("--json", action="store_true", help="print the result as JSON on the last line")
    argv = sys.argv[1:] if argv is None else argv
    pre, _ = parser.parse_known_args(argv)
    module = importlib.import_module(f"bench_{pre.name}")
    module.add_arguments(parser)
    args = parser.parse_args(argv)
    t0 = time.perf_counter()
    result = module.run(args)
    result = {"benchmark": pre.name, "command": "python bench/run.py " + " ".join(argv),
              "machine": machine(), "wall_s": round(time.perf_counter() - t0, 3), **result}
    if args.json:
        print(json.dumps(result, sort_keys=False))
    else:
        for k, v in result.items():
            print(f"{k}: {v}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
