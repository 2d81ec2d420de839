"""Several searches of one map, for the commands that compare them (``semmap compare``,
``semmap stability``): in a row under one Ctrl-C handler, or ``--jobs N`` at a time, each in a
process of its own; either way nothing is written when Ctrl-C stops them."""

from __future__ import annotations

import signal
import sys
import time


def add_jobs_option(p) -> None:
    """``--jobs N``: how many runs at a time (:func:`run_each`'s ``workers``)."""
    from semmap_pp.cli.argtypes import positive_int

    p.add_argument("--jobs", type=positive_int, default=1, metavar="N",
                   help="runs at a time, each in a process of its own (default 1); each run's chains "
                        "use --cores processes besides")


def log(msg: str) -> None:
    """A progress or log line, on stderr (results go to stdout)."""
    print(msg, file=sys.stderr, flush=True)


def general_path_note(rules, shown) -> str | None:
    """The note for a rule set (:class:`~semmap_pp.knowledge.dialect.RuleSet`, shown as
    ``shown``) that is not pairwise-local: its runs take the knowledge engine's general path."""
    from semmap_pp.knowledge.local import is_pairwise
    if rules is None or is_pairwise(rules):
        return None
    return (f"note: {shown} is not pairwise-local: the knowledge engine grounds every new evidence "
            "whole, which takes several times longer than unit and pair templates (`semmap rules "
            f"check {shown}` says which statement)")


def run_each(command: str, inputs, jobs, workers: int = 1) -> list | None:
    """``run_map`` once per ``(title, inputs, settings)`` of ``jobs`` after printing the notes of
    ``inputs`` (what loading changed) once: ``[(run, seconds), ...]`` in the order of ``jobs``, or
    None when Ctrl-C stopped them (the caller then writes nothing and exits 130).

    The jobs share one map and model, so chain 1's data-driven start world, which depends on
    neither the seed nor the rules (:func:`semmap_pp.run.pipeline.data_start_world`), is built once
    and handed to every run (``base_start``): the same runs, built once. With ``workers`` > 1
    the runs go ``workers`` at a time, each in a process of its own (:func:`_run_parallel`);
    the results are the same as in a row."""
    from semmap_pp.errors import SemmapError
    from semmap_pp.run.pipeline import run_map
    from semmap_pp.sampler.step import StopFlag

    for note in inputs.notes:
        log(f"note: {note}")
    noted = set()
    for _title, job_inputs, _settings in jobs:
        rules = job_inputs.rules
        if rules is not None and rules.digest not in noted:
            noted.add(rules.digest)
            note = general_path_note(rules, rules.path)
            if note:
                log(note)
    if workers > 1 and len(jobs) > 1:
        return _run_parallel(command, inputs, jobs, min(workers, len(jobs)))
    stop = StopFlag()

    def on_sigint(signum, frame):
        stop.set("interrupted")
        log(f"semmap {command}: interrupted: stopping; nothing will be written")

    previous = signal.signal(signal.SIGINT, on_sigint)
    runs, base = [], None
    try:
        for title, job_inputs, settings in jobs:
            log(f"--- {title} ---")
            t0 = time.perf_counter()
            try:
                run = run_map(job_inputs, settings, log=log, stop=stop, base_start=base)
            except SemmapError:
                if stop():      # interrupted before any chain had 4 draws
                    return None
                raise
            if stop():
                return None
            runs.append((run, time.perf_counter() - t0))
            base = run.starts[0] if base is None and run.starts else base
    finally:
        signal.signal(signal.SIGINT, previous)
    return runs


def _ignore_sigint() -> None:
    """A worker's initializer: Ctrl-C is the parent's to handle (it stops the workers)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def _run_one(title: str, inputs, settings, base):
    """One run of :func:`_run_parallel`, in a worker process; its log lines carry ``title``."""
    from semmap_pp.run.pipeline import run_map

    t0 = time.perf_counter()
    run = run_map(inputs, settings, log=lambda msg: log(f"[{title}] {msg}"), base_start=base)
    return run, time.perf_counter() - t0


def _stop_workers(pool) -> None:
    """End ``pool``'s worker processes now (the runs they hold are not wanted any more)."""
    for proc in list((getattr(pool, "_processes", None) or {}).values()):
        if proc.is_alive():
            proc.terminate()
    pool.shutdown(wait=True, cancel_futures=True)


def _run_parallel(command: str, inputs, jobs, workers: int) -> list | None:
    """:func:`run_each` with ``workers`` runs at a time, each in a spawned process (a clean
    interpreter: no threads of this one forked). The start world they share is built here first.
    An error in a run (a :class:`~semmap_pp.errors.SemmapError` reaches this process as itself)
    stops the others and is raised; Ctrl-C stops them all and returns None."""
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    from semmap_pp.run.pipeline import data_start_world

    log(f"--- {len(jobs)} runs, {workers} at a time (--jobs), each in a process of its own ---")
    pool = None
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)   # Ctrl-C: KeyboardInterrupt here
    try:
        t0 = time.perf_counter()
        base = data_start_world(inputs)
        log(f"shared start world: {int(base.active.sum())} units ({time.perf_counter() - t0:.1f} s)")
        pool = ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context("spawn"),
                                   initializer=_ignore_sigint)
        futures = [pool.submit(_run_one, title, job_inputs, settings, base)
                   for title, job_inputs, settings in jobs]
        runs = []
        for (title, _inputs, _settings), future in zip(jobs, futures):
            runs.append(future.result())
            log(f"--- {title}: done, {runs[-1][1]:.1f} s ---")
        pool.shutdown()
        return runs
    except KeyboardInterrupt:
        log(f"semmap {command}: interrupted: stopping; nothing will be written")
        if pool is not None:
            _stop_workers(pool)
        return None
    except BaseException:
        if pool is not None:
            _stop_workers(pool)
        raise
    finally:
        signal.signal(signal.SIGINT, previous)
