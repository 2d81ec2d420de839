"""Longer fuzzing of the map, rule and model loaders: ``python bench/fuzz.py --seconds 600``.

Runs the fuzz targets of tests/unit/test_fuzz.py (random bytes and mutations of valid PNG, PGM, .npy,
YAML, rules/*.lp and models/default.toml) with hypothesis, round after round with fresh random
seeds, until the time is up. A case may only end normally or with the project's own SemmapError; a
case that runs longer than ``--case-timeout`` seconds counts as a hang. Every failure is printed with
the input hypothesis shrank it to, and the run goes on. The last line is one JSON object: cases run
per target, failures, seconds. Exit status 1 if anything failed.
"""

from __future__ import annotations

import argparse
import json
import signal
import sys
import time
import traceback
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests" / "unit"))
sys.path.insert(0, str(ROOT))

from hypothesis import HealthCheck, given, settings  # noqa: E402

import test_fuzz  # noqa: E402


class Hang(Exception):
    """A fuzz case ran past its time limit."""


def _alarm(signum, frame):
    raise Hang("case ran past its time limit")


def run_target(name: str, examples: int, case_timeout: float) -> str | None:
    """One hypothesis run of ``examples`` cases of target ``name``; the failure text or None."""
    strategy, target = test_fuzz.TARGETS[name]

    @settings(max_examples=examples, deadline=None, database=None, derandomize=False,
              suppress_health_check=list(HealthCheck))
    @given(strategy)
    def case(args):
        # the alarm repeats every second after the limit: a Hang raised where Python ignores
        # exceptions (a gc callback during clingo's grounding did) is raised again
        signal.setitimer(signal.ITIMER_REAL, case_timeout, 1.0)
        try:
            target(*args)
        finally:
            signal.setitimer(signal.ITIMER_REAL, 0)

    try:
        case()
    except Exception:  # the shrunk failing case, as hypothesis reports it
        return traceback.format_exc(limit=3)
    return None


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=60.0, help="total fuzzing time")
    parser.add_argument("--examples", type=int, default=200, help="cases per hypothesis run")
    parser.add_argument("--case-timeout", type=float, default=10.0, help="seconds before a case is a hang")
    parser.add_argument("--targets", nargs="*", default=sorted(test_fuzz.TARGETS),
                        choices=sorted(test_fuzz.TARGETS))
    args = parser.parse_args(argv)
    signal.signal(signal.SIGALRM, _alarm)
    cases = {name: 0 for name in args.targets}
    failures: list[dict] = []
    start = time.monotonic()
    rounds = 0
    while time.monotonic() - start < args.seconds:
        for name in args.targets:
            before = test_fuzz.COUNT["cases"]
            failure = run_target(name, args.examples, args.case_timeout)
            cases[name] += test_fuzz.COUNT["cases"] - before
            if failure is not None:
                failures.append({"target": name, "error": failure})
                print(f"FAILURE in {name}:\n{failure}", file=sys.stderr, flush=True)
            if time.monotonic() - start >= args.seconds:
                break
        rounds += 1
        print(f"round {rounds}: {sum(cases.values())} cases, {len(failures)} failures, "
              f"{time.monotonic() - start:.0f} s", file=sys.stderr, flush=True)
    result = {"benchmark": "fuzz", "command": "python bench/fuzz.py " + " ".join(sys.argv[1:]),
              "seconds": round(time.monotonic() - start, 1), "rounds": rounds,
              "cases": cases, "total_cases": sum(cases.values()),
              "failures": len(failures), "failed_targets": sorted({f["target"] for f in failures})}
    print(json.dumps(result))
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
