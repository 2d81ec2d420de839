"""Time per map against another version of the code, run alongside.

``python bench/run.py against --rev REV [--maps MAP ...] [--rounds N] --json``

The other version is checked out from this repository's git history into a temporary worktree
(``git worktree add --detach``, removed at the end). Each map is run by ``python -m semmap_pp map
MAP --out DIR --force --progress none`` (model defaults, this machine's cores) in a fresh process
with ``PYTHONPATH`` set to one checkout or the other, from a temporary folder so that each imports
its own package; both versions use this interpreter and its packages. Every map is run once by each
version first (their compiled-code caches filled, not timed), then ``--rounds`` times alternating,
the other version first: the machine's load falls on both alike, and the ratio of the means is the
figure (docs/benchmarks.md, "Time per map against the code of the table above, run alongside").
Whether the two world.json files of a map hold the same plan is reported too (the ``run`` and
``provenance`` fields left out).

``--tiny`` (:data:`TINY`: the 5 x 4 cell test map against ``HEAD``, one round, no warm-up run) is
the check of tests/integration/test_bench_smoke.py that the benchmark runs, not a measurement.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
MAPS = sorted((ROOT / "bench" / "data" / "real-gt").glob("*/map.yaml"))
#: ``--tiny``: the arguments it sets
TINY = {"maps": [ROOT / "tests" / "data" / "maps" / "tiny.yaml"], "rev": "HEAD", "rounds": 1}
#: world.json fields that name the run rather than the plan
RUN_FIELDS = ("run", "provenance", "timing", "created")


def add_arguments(parser) -> None:
    parser.add_argument("--rev", default=None, help="the other version: a commit, tag or branch (required)")
    parser.add_argument("--maps", type=Path, nargs="+", default=MAPS,
                        help="the maps (default: the five real-gt floors)")
    parser.add_argument("--rounds", type=int, default=3, help="timed runs of each version per map")
    parser.add_argument("--tiny", action="store_true", help="one small map against HEAD (a check that it runs)")


def _git(*argv: str) -> str:
    p = subprocess.run(["git", "-C", str(ROOT), *argv], capture_output=True, text=True)
    if p.returncode != 0:
        raise SystemExit(f"git {' '.join(argv)}: {p.stderr.strip() or p.stdout.strip()}")
    return p.stdout.strip()


def _run_map(checkout: Path, map_yaml: Path, out: Path, cwd: Path) -> float:
    env = dict(os.environ, PYTHONPATH=str(checkout))
    t0 = time.perf_counter()
    p = subprocess.run([sys.executable, "-m", "semmap_pp", "map", str(map_yaml.resolve()), "--out", str(out),
                        "--force", "--progress", "none"], capture_output=True, text=True, env=env, cwd=cwd)
    wall = time.perf_counter() - t0
    if p.returncode != 0:
        raise SystemExit(f"semmap map {map_yaml} ({checkout}) failed: {p.stderr.strip()[-500:]}")
    return wall


def _plan(out: Path) -> dict:
    doc = json.loads((out / "world.json").read_text())
    return {k: v for k, v in doc.items() if k not in RUN_FIELDS}


def _mean(xs) -> float:
    return sum(xs) / len(xs)


def run(args) -> dict:
    if args.tiny:
        for k, v in TINY.items():
            setattr(args, k, v)
    if not args.rev:
        raise SystemExit("--rev REV is required: the version to time against")
    if args.rounds < 1:
        raise SystemExit("--rounds must be at least 1")
    rev = _git("rev-parse", "--verify", f"{args.rev}^{{commit}}")
    here = _git("rev-parse", "HEAD")
    dirty = bool(_git("status", "--porcelain", "--untracked-files=no"))
    rows = []
    with tempfile.TemporaryDirectory(prefix="semmap-against-") as tmp:
        tmp = Path(tmp)
        other = tmp / "other"
        _git("worktree", "add", "--detach", str(other), rev)
        try:
            for m in args.maps:
                outs = {"other": tmp / "out-other", "this": tmp / "out-this"}
                sides = (("other", other), ("this", ROOT))
                if not args.tiny:          # a run of each first: caches filled, not timed
                    for name, checkout in sides:
                        _run_map(checkout, m, outs[name], tmp)
                times = {"other": [], "this": []}
                for _ in range(args.rounds):
                    for name, checkout in sides:
                        times[name].append(round(_run_map(checkout, m, outs[name], tmp), 2))
                ratio = _mean(times["this"]) / _mean(times["other"])
                rows.append({"map": str(m.relative_to(ROOT)) if m.is_relative_to(ROOT) else str(m),
                             "other_s": times["other"], "this_s": times["this"],
                             "ratio_of_means": round(ratio, 3),
                             "same_plan": _plan(outs["other"]) == _plan(outs["this"])})
        finally:
            _git("worktree", "remove", "--force", str(other))
    return {"rev": rev, "this": here + ("+uncommitted changes" if dirty else ""), "rounds": args.rounds,
            "rows": rows, "max_ratio": max(r["ratio_of_means"] for r in rows)}
