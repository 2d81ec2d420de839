"""``semmap batch MAP... --out DIR``: many maps, seeds and rule sets as tasks of a Dask cluster.

One task per map, rule file and seed, each a ``semmap map`` run writing
``DIR/<map>[/<rules>][/seed-<s>]/`` exactly as ``semmap map`` does (:mod:`semmap_pp.run.batch`). MAP is
a map file, a folder of them or a glob pattern. Without ``--scheduler`` a local cluster of
``--workers`` worker processes (default: one per core) runs them; ``--scheduler ADDRESS`` sends them
to a running Dask scheduler (docs/cli.md). A task that fails (a bad map, ``--timeout``, a worker that
dies) is recorded with its one-line error and the others go on; the exit status is 1 when any
failed. A rerun skips the tasks whose folder holds a whole run (``--force`` redoes them).
``DIR/summary.json``, ``DIR/summary.csv`` and ``DIR/index.html`` are rewritten as tasks end.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

from semmap_pp.cli.argtypes import non_negative_int, positive_int, seconds
from semmap_pp.cli.argtypes import seed as seed_type
from semmap_pp.cli.options import add_map_options, add_run_length_options, map_options
from semmap_pp.errors import MapError, SemmapError

#: the options of ``semmap map`` a batch hands to every task: (dest, flag)
PASSED = (("model", "--model"), ("roi", "--roi"), ("chains", "--chains"), ("cores", "--cores"),
          ("tune", "--tune"), ("draws", "--draws"), ("n_inner", "--n-inner"),
          ("spread_draws", "--spread-draws"), ("budget", "--budget"),
          ("occupied_thresh", "--occupied-thresh"), ("free_thresh", "--free-thresh"),
          ("negate", "--negate"), ("resolution", "--resolution"), ("mode", "--mode"),
          ("max_cells", "--max-cells"), ("topic", "--topic"), ("at", "--at"))


def register(subparsers) -> None:
    p = subparsers.add_parser("batch", help="many maps, seeds and rule sets on a Dask cluster",
                              description=__doc__.splitlines()[0])
    p.add_argument("maps", metavar="MAP", nargs="+", help="map files, folders of maps, or glob patterns")
    p.add_argument("--out", type=Path, required=True, metavar="DIR", help="the batch folder")
    p.add_argument("--scheduler", metavar="ADDRESS", default=None,
                   help="a running Dask scheduler (tcp://host:8786); default: a local cluster")
    p.add_argument("--workers", type=positive_int, default=None, metavar="N",
                   help="worker processes of the local cluster (default: one per core)")
    p.add_argument("--seeds", type=seed_type, nargs="+", default=None, metavar="S",
                   help="run every map with each seed (DIR/<map>/seed-<s>/)")
    p.add_argument("--rules", action="append", default=None, metavar="FILE",
                   help="a rule file; give it twice or more to run every map under each (DIR/<map>/<rules>/)")
    p.add_argument("--model", metavar="FILE", default=None, help="model file (default models/default.toml)")
    p.add_argument("--roi", metavar="MASK", default=None, help="region-of-interest mask for the CPR")
    add_run_length_options(p)
    p.add_argument("--spread-draws", type=non_negative_int, default=None, metavar="N",
                   help="draws per chain of the sample around W* (model file default)")
    p.add_argument("--budget", type=seconds, default=None, metavar="SECONDS",
                   help="each run: stop sampling after SECONDS and keep the draws made")
    p.add_argument("--timeout", type=seconds, default=None, metavar="SECONDS",
                   help="a task still running after SECONDS fails (its process is killed)")
    p.add_argument("--force", action="store_true", help="redo tasks whose output is complete")
    p.add_argument("--progress", choices=("auto", "rich", "plain", "none"), default="auto",
                   help="progress on stderr (auto: rich on a terminal, plain lines otherwise)")
    add_map_options(p)
    p.set_defaults(func=run)


def map_args(args) -> list[str]:
    """The ``semmap map`` arguments every task gets. Each task's chains run on one core unless
    ``--cores`` says otherwise: the workers share the machine (the result does not depend on it)."""
    out = []
    for dest, flag in PASSED:
        v = getattr(args, dest, None)
        if dest == "cores" and v is None:
            v = 1
        if dest == "max_cells" and v is not None:
            from semmap_pp.grid import MAX_CELLS
            if v == MAX_CELLS:
                continue
        if v is not None:
            out += [flag, str(v)]
    if args.allow_outside:
        out.append("--allow-outside")
    return out


def _check_inputs(args) -> None:
    """Rule and model files are the whole batch's: a bad one stops it before any task runs."""
    from semmap_pp.knowledge import load_rules
    from semmap_pp.model import load_model
    load_model(args.model)
    for r in args.rules or ():
        load_rules(r)


def _client(args):
    from distributed import Client, LocalCluster
    if args.scheduler:
        try:
            return Client(args.scheduler, timeout="10s"), None
        except (OSError, TimeoutError) as exc:
            raise MapError(None, f"cannot reach the Dask scheduler at {args.scheduler}: {exc}") from None
    dashboard = ":0" if _has_bokeh() else None
    n = args.workers or os.cpu_count() or 1
    cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True,
                           dashboard_address=dashboard, silence_logs=50)
    return Client(cluster), cluster


class _Progress:
    """Tasks done, failed and running: a rich bar on a terminal, plain lines otherwise."""

    def __init__(self, mode: str, total: int):
        self.mode = "rich" if mode == "auto" and sys.stderr.isatty() else ("plain" if mode == "auto" else mode)
        self.total, self.done, self.failed = total, 0, 0
        self.bar = None
        if self.mode == "rich":
            from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn
            self.bar = Progress(TextColumn("batch"), BarColumn(), MofNCompleteColumn(),
                                TextColumn("{task.fields[note]}"), TimeElapsedColumn(), transient=False)
            self.bar.start()
            self.tid = self.bar.add_task("batch", total=total, note="")

    def update(self, result: dict | None, label: str = "", running: int | None = None) -> None:
        if result is not None:
            self.done += 1
            self.failed += result["status"] == "failed"
        note = f"{self.failed} failed" + ("" if running is None else f", {running} running")
        if self.bar is not None:
            self.bar.update(self.tid, completed=self.done, note=note)
        elif self.mode == "plain" and result is not None:
            err = f": {result['error']}" if result.get("error") else ""
            print(f"batch: {self.done}/{self.total} done, {label} {result['status']}{err} ({note})",
                  file=sys.stderr, flush=True)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.stop()


def run(args) -> int:
    from semmap_pp.run import batch as B

    maps = B.expand_maps(args.maps)
    _check_inputs(args)
    out = args.out
    if out.exists() and not out.is_dir():
        raise MapError(out, "not a folder")
    try:
        out.mkdir(parents=True, exist_ok=True)
        probe = out / ".semmap-batch-write-test"
        probe.write_bytes(b"")
        probe.unlink()
    except OSError as exc:
        raise MapError(out, f"cannot write there: {exc.strerror or exc}") from None
    from semmap_pp.run.outdir import check_free_space, lock_out_dir, needed_bytes
    check_free_space(out, needed_bytes())
    with lock_out_dir(out):      # one batch at a time in DIR (each task's run locks its own folder)
        return _run_tasks(args, B, maps, out)


def _run_tasks(args, B, maps, out: Path) -> int:
    """The tasks of a batch into ``out``, which the caller holds the lock of; the exit status."""
    tasks = B.plan_tasks(maps, out.resolve(), args.rules, args.seeds)
    extra = map_args(args)
    results: dict[str, dict] = {}
    todo = []
    for t in tasks:
        if not args.force and B.complete(t.out):
            results[t.out] = {**B.Result(t.map, t.rules, t.seed, t.out, "skipped").__dict__,
                              **B.world_facts(t.out)}
        else:
            todo.append(t)
    order = [t.out for t in tasks]

    def summary() -> None:
        B.write_summary(out, [results[k] for k in order if k in results])

    progress = _Progress(args.progress, len(tasks))
    for _ in results:
        progress.update({"status": "skipped"})
    client = cluster = None
    interrupted = False
    try:
        if todo:
            client, cluster = _client(args)
            link = client.dashboard_link if cluster is None or _has_bokeh() else None
            if link:
                print(f"batch: Dask dashboard at {link}", file=sys.stderr)
            before = set(results)
            todo, cost = _refuse_up_front(B, todo, args, client, results)
            for k in results:
                if k not in before:
                    progress.update(results[k], k)
            summary()
            futures = {}
            # the largest maps first, so that the last tasks to end are short ones (fewer idle workers)
            for t in todo:
                f = client.submit(B.run_task, t, extra, args.timeout, pure=False,
                                  key=f"semmap-{t.label}-{id(t)}", priority=int(cost.get(t.map, 0) // 1e6))
                futures[f] = t
            from distributed import as_completed
            for f in as_completed(list(futures)):
                t = futures[f]
                res = _task_result(B, f, t)
                results[t.out] = res
                try:
                    running = sum(len(v) for v in client.processing().values())
                except Exception:  # noqa: BLE001 - a scheduler going away: no count
                    running = None
                progress.update(res, t.label, running)
                summary()
    except KeyboardInterrupt:
        interrupted = True
    finally:
        progress.close()
        summary()
        _close(client, cluster)
    if interrupted:
        raise KeyboardInterrupt
    failed = [r for r in results.values() if r["status"] == "failed"]
    ok = sum(r["status"] == "ok" for r in results.values())
    skipped = sum(r["status"] == "skipped" for r in results.values())
    print(f"batch: {ok} run, {skipped} skipped (complete), {len(failed)} failed; {out / 'summary.csv'}")
    for r in failed:
        print(f"  failed: {r['out']}: {r['error']}", file=sys.stderr)
    return 1 if failed else 0


def _task_result(B, future, t) -> dict:
    """The result row of task ``t`` from its finished ``future``: a failed row when a worker died
    with it (KilledWorker) or the task raised."""
    try:
        return future.result()
    except Exception as exc:      # a worker died with it (KilledWorker) or the task raised
        name = type(exc).__name__
        why = "a worker died while running it" if name == "KilledWorker" else str(exc) or name
        return {**B.Result(t.map, t.rules, t.seed, t.out, "failed").__dict__,
                "error": f"{why} ({name})"}


def _close(client, cluster) -> None:
    """Close the Dask client and the local cluster, if any, whatever state they are in."""
    if client is not None:
        try:
            client.close()
        except Exception:  # noqa: BLE001 - closing a cluster that is going away
            pass
    if cluster is not None:
        try:
            cluster.close()
        except Exception:  # noqa: BLE001
            pass


def _has_bokeh() -> bool:
    """Whether Dask can serve its dashboard (it needs bokeh)."""
    try:
        import bokeh  # noqa: F401
        return True
    except ImportError:
        return False


def _refuse_up_front(B, todo, args, client, results):
    """Tasks whose map cannot be read, or whose estimated peak exceeds every worker's memory
    limit, fail before anything runs; the rest go on. Returns them and each map's estimated peak
    (bytes), which also orders them: the largest first."""
    limits = [w.get("memory_limit") or 0 for w in client.scheduler_info().get("workers", {}).values()]
    limit = max(limits) if limits and all(limits) else None
    checked: dict[str, str | None] = {}
    cost: dict[str, float] = {}
    keep = []
    opts = map_options(args)
    for t in todo:
        if t.map not in checked:
            why = None
            try:
                peak = cost[t.map] = B.estimated_peak_bytes(t.map, opts)
                if limit and peak > limit:
                    why = (f"{t.map}: estimated peak {peak / 1e9:.1f} GB exceeds the workers' memory "
                           f"limit of {limit / 1e9:.1f} GB")
            except SemmapError as exc:
                why = str(exc)
            checked[t.map] = why
        if checked[t.map] is None:
            keep.append(t)
        else:
            results[t.out] = {**B.Result(t.map, t.rules, t.seed, t.out, "failed").__dict__,
                              "error": checked[t.map]}
    return keep, cost
