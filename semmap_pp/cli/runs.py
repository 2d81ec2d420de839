"""Several searches of one map in a row, for the commands that compare them (``semmap compare``,
``semmap stability``): one Ctrl-C handler over all of them, and nothing written when it fires."""

from __future__ import annotations

import signal
import sys
import time


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


def run_each(command: str, inputs, jobs) -> list | None:
    """``run_map`` once per ``(title, inputs, settings)`` of ``jobs``, in order, after printing
    the notes of ``inputs`` (what loading changed) once: ``[(run, seconds), ...]``, or None when
    Ctrl-C stopped them (the caller then writes nothing and exits 130).

    The jobs share one map and model, so chain 1's data-driven start world, which depends on
    neither the seed nor the rules (:func:`semmap_pp.pipeline.data_start_world`), is built by
    the first run and handed to the others (``base_start``): the same runs, built once."""
    from semmap_pp.errors import SemmapError
    from semmap_pp.pipeline import run_map
    from semmap_pp.step import StopFlag

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
