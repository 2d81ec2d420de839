"""``semmap map MAP --out DIR``: the semantic map of an occupancy grid.

Writes ``world.json`` (schema: docs/world.schema.json), ``labels.png`` (16-bit unit ids, the input
image's frame), ``trace.nc`` (ArviZ: label-invariant summaries and sampler statistics per chain and
draw), ``diagnostics.txt`` (R-hat, ESS and the verdict) and the other outputs of
:func:`semmap_pp.outputs.write.write_all`, after ``resume.npz`` (what ``--resume`` needs), which
comes first. Every file is written atomically; a non-empty DIR is refused without ``--force``, and
a DIR another run is writing into is refused (:mod:`semmap_pp.run.outdir`). The same inputs and seed
give the same world.json, unless ``--budget`` (or Ctrl-C) ends sampling early: then the run's
length depends on the machine. Ctrl-C stops sampling cleanly, writes what was done and exits 130;
a Ctrl-C while the files are written stops the writing once resume.npz is complete (exit 130).
docs/cli.md has every option.
"""

from __future__ import annotations

import argparse
import signal
import sys
from pathlib import Path

from semmap_pp.cli import quiet_finalizers
from semmap_pp.cli.argtypes import seed as seed_type
from semmap_pp.cli.argtypes import non_negative_int as _non_negative_int
from semmap_pp.cli.argtypes import positive_int as _positive_int
from semmap_pp.cli.argtypes import seconds as _seconds
from semmap_pp.cli.options import (add_map_options, add_run_length_options, add_target_options, map_options,
                                   target_inputs)
from semmap_pp.model import SPREAD_DRAWS_RULE, spread_draws_ok


#: Options a resumed run takes from the resume file (giving them with --resume is an error).
FIXED_WHEN_RESUMING = ("chains", "tune", "n_inner", "seed", "rules", "model", "roi")


def register(subparsers) -> None:
    p = subparsers.add_parser("map", help="build the semantic map of an occupancy grid",
                              description=__doc__.splitlines()[0])
    p.add_argument("map", metavar="MAP", nargs="?", help="map_server YAML, a .png/.pgm/.npy image, or a bag (ROS 2 bag folder, .mcap, ROS 1 .bag)")
    p.add_argument("--out", type=Path, metavar="DIR",
                   help="output directory (required, except with --resume: default the resumed DIR)")
    add_target_options(p)
    p.add_argument("--seed", type=seed_type, default=None, help="random seed (default 0)")
    add_run_length_options(p, draws_help="recorded draws per chain (with --resume: this many more per chain)")
    p.add_argument("--spread-draws", type=_non_negative_int, default=None, metavar="N",
                   help="draws per chain of the sample around W* that the spread figures are drawn from "
                        "(paper Fig. 7; model file default 1000; 0: none, the figures use the search's draws)")
    p.add_argument("--tempered", action="store_true",
                   help="opt-in: the sample around W* under the likelihood raised to 1/A (A the correlation "
                        "area of W*'s residuals) with replica exchange ([sampler] spread_rungs rungs; "
                        "docs/sampler.md, \"Replica exchange\"); slower, and measured not to converge either")
    p.add_argument("--rungs", type=_positive_int, default=None, metavar="N",
                   help="rungs of the replica exchange per chain (implies --tempered; 1: the tempered "
                        "likelihood without replicas; default the model file's spread_rungs)")
    p.add_argument("--force", action="store_true", help="write into a non-empty DIR")
    p.add_argument("--max-memory", type=_memory_size, metavar="SIZE", default=None,
                   help="refuse a map whose run is estimated to need more memory at its peak than SIZE "
                        "(e.g. 2G, 800M; default: the machine's memory)")
    p.add_argument("--budget", type=_seconds, metavar="SECONDS",
                   help="stop sampling after SECONDS of wall time and keep the draws made "
                        "(the result then depends on the machine's speed)")
    p.add_argument("--start", type=Path, metavar="WORLD_JSON",
                   help="start every chain from this world.json (an earlier run's W*, edited or not; "
                        "with --tune 0 the paper's Fig. 7)")
    p.add_argument("--resume", type=Path, metavar="DIR",
                   help="continue the run in DIR (its resume.npz): the chains go on and draws are appended")
    p.add_argument("--ids-from", type=Path, metavar="WORLD_JSON",
                   help="number W*'s units as this earlier world.json does where they are the same place "
                        "(rectangles overlapping by IoU >= 0.5 in map-frame metres; the map may have grown "
                        "since), the other units with ids it never used; or an earlier run's folder (also with --resume)")
    p.add_argument("--progress", choices=("auto", "rich", "plain", "none"), default="auto",
                   help="live progress on stderr (auto: rich on a terminal, plain lines otherwise)")
    p.add_argument("--progress-every", type=_seconds, default=5.0, metavar="SECONDS",
                   help="seconds between plain progress lines (default 5)")
    add_map_options(p)
    p.set_defaults(func=run)


def _memory_size(text: str) -> int:
    from semmap_pp.run.memory import parse_size
    try:
        n = parse_size(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    if n <= 0:
        raise argparse.ArgumentTypeError(f"must be positive, got {text!r}")
    return n


def _usage(message: str) -> int:
    print(f"semmap map: error: {message}", file=sys.stderr)
    return 2


def _resume_inputs(args):
    """Inputs, settings and resume state of ``--resume DIR``."""
    from semmap_pp.errors import SemmapError
    from semmap_pp.run.inputs import load_inputs
    from semmap_pp.run.results import RunSettings
    from semmap_pp.sampler.resume import read_resume

    state = read_resume(args.resume, extra_draws=args.draws)
    m = state.meta["inputs"]
    inputs = load_inputs(m["map"], model_path=m["model"],
                         rules_path=Path(m["rules"]) if m["rules"] else None, roi_path=m["roi"],
                         map_options=m["map_options"])
    lattice = m.get("lattice")   # absent from older files; the worlds are in its cells
    if lattice is not None and tuple(lattice) != tuple(inputs.frame.shape):
        raise SemmapError(Path(args.resume) / "resume.npz",
                          f"written for a lattice of {lattice[0]} x {lattice[1]} cells, but the map and "
                          f"model now give {inputs.frame.shape[0]} x {inputs.frame.shape[1]} (the map, "
                          "the model file or this version changed): run `semmap map` again")
    values = dict(state.meta["settings"])
    if args.cores is not None:
        values["cores"] = args.cores
    if args.spread_draws is not None:
        values["spread_draws"] = args.spread_draws
    values["cores"] = max(1, min(values["cores"], values["chains"]))
    return inputs, RunSettings(**values), state, Path(m["rules"]) if m["rules"] else None


def _places_or_none(doc: dict, path):
    """A world.json's content (read from ``path``) as :func:`semmap_pp.plans.places.places_from_doc`
    reads it, or None: a file too old or odd for ``semmap diff`` still gives its ids."""
    from semmap_pp.errors import SemmapError
    from semmap_pp.plans.places import places_from_doc

    try:
        return places_from_doc(doc, Path(path))
    except SemmapError:
        return None


def _changes_since(previous, path: Path, name: str | None = None) -> str | None:
    """One line on how the world.json just written to ``path`` differs from ``previous`` (called
    ``name`` in it, else by its path)."""
    from semmap_pp.errors import SemmapError
    from semmap_pp.plans.places import read_places
    from semmap_pp.plans.diff import diff_worlds

    try:
        now = read_places(path)
    except SemmapError:
        return None
    return diff_worlds(previous, now).summary(name)


def carried_ids_source(run_dir: Path) -> Path | None:
    """``run_dir``'s world.json when its unit ids were carried from an earlier one (it has an
    ``ids`` object): what ``--resume run_dir`` carries them from, so that the resumed run keeps
    them; None otherwise (a file that cannot be read is left to the resume's own checks)."""
    from semmap_pp.errors import SemmapError
    from semmap_pp.plans.world_file import read_world_doc

    path = Path(run_dir) / "world.json"
    try:
        doc = read_world_doc(path)     # bounded as every world.json read is
    except SemmapError:
        return None
    return path if isinstance(doc, dict) and isinstance(doc.get("ids"), dict) else None


def _install_sigint(stop):
    """Ctrl-C sets ``stop`` (sampling ends cleanly); a second Ctrl-C restores the default."""

    def handler(signum, frame):
        if stop():
            print("semmap: stopping; press Ctrl-C again to quit without writing", file=sys.stderr, flush=True)
            signal.signal(signal.SIGINT, signal.default_int_handler)
            return
        stop.set("interrupted")
        print("semmap: interrupted: stopping the chains, then writing the results so far",
              file=sys.stderr, flush=True)

    return signal.signal(signal.SIGINT, handler)


def run(args) -> int:
    from semmap_pp.run.memory import check_memory, young_heap
    from semmap_pp.run.outdir import check_free_space, lock_out_dir, needed_bytes
    from semmap_pp.run.shared import shared_folder
    from semmap_pp.outputs.report import FILES as OUTPUT_FILES
    from semmap_pp.run.outdir import check_out_dir
    from semmap_pp.run.inputs import check_inputs_not_outputs
    from semmap_pp.run.results import RunSettings
    from semmap_pp.sampler.resume import FILE_NAME as RESUME_FILE
    from semmap_pp.plans.world_file import previous_ids_from_doc, read_run_world

    state, starts = None, None
    if not spread_draws_ok(args.spread_draws or 0):
        return _usage(f"--spread-draws {SPREAD_DRAWS_RULE}")
    if args.resume is not None:
        fixed = FIXED_WHEN_RESUMING + ("occupied_thresh", "free_thresh", "negate", "resolution", "mode",
                                       "topic", "at")
        given = [f"--{k.replace('_', '-')}" for k in fixed + ("start",) if getattr(args, k) is not None]
        if given or args.map is not None:
            what = ", ".join(given + (["MAP"] if args.map is not None else []))
            return _usage(f"{what} cannot be given with --resume (the run keeps its own; "
                          "--draws, --cores, --budget and --out can)")
        inputs, settings, state, rules = _resume_inputs(args)
        out: Path = args.out if args.out is not None else args.resume
        if out.resolve() != args.resume.resolve():
            check_out_dir(out, args.force)
    else:
        if args.map is None or args.out is None:
            return _usage("MAP and --out DIR are required (or --resume DIR)")
        out = args.out
        check_out_dir(out, args.force)
        rules, inputs = target_inputs(args)
        check_inputs_not_outputs(out, inputs, set(OUTPUT_FILES) | {RESUME_FILE})
        settings = RunSettings.from_model(inputs.model, seed=args.seed or 0, chains=args.chains,
                                          cores=args.cores, tune=args.tune, draws=args.draws,
                                          n_inner=args.n_inner, spread_draws=args.spread_draws)
        if settings.draws < 4:
            return _usage("--draws must be at least 4 (R-hat and ESS need them)")
        if args.start is not None:
            from semmap_pp.plans.world_file import read_start_world
            starts = [read_start_world(args.start, inputs.frame, inputs.grid, inputs.model.prior.k_max)]

    inputs = _tempering(inputs, args)
    ids_from = args.ids_from
    if ids_from is None and state is not None:   # a resumed run keeps the ids its world.json carried
        ids_from = carried_ids_source(args.resume)
    # read before sampling: a bad file costs no run
    previous_ids = previous_places = None
    if ids_from is not None:
        ids_from, doc = read_run_world(ids_from)   # the file itself, when given a run's folder
        previous_ids = previous_ids_from_doc(doc, ids_from)
        previous_places = _places_or_none(doc, ids_from)   # what the new plan is compared with

    h, w = inputs.grid.shape
    check_memory(inputs, args.max_memory)   # the estimated peak, before any sampling
    check_free_space(out, needed_bytes(h * w))
    # the lock is held until every file is written: one run at a time in a folder; the sampling
    # and the outputs collect only what they make
    with lock_out_dir(out), young_heap(), shared_folder() as folder:
        if state is None or out.resolve() != args.resume.resolve():
            check_out_dir(out, args.force)     # again under the lock: a run that ended meanwhile may have filled it
        job = _start_job(inputs, settings, folder) if state is None and starts is None else None
        if job is not None:     # said now: the imports below take a second or two
            from semmap_pp.run.pipeline import BUILDING_STARTS, map_head
            print(f"{map_head(inputs)}; {BUILDING_STARTS}", file=sys.stderr, flush=True)
        try:
            _import_the_rest()
            return _sample_and_write(args, out, inputs, settings, state, rules, starts, previous_ids,
                                     previous_places, ids_from, job, folder)
        finally:
            if job is not None:
                job.close()


def _start_job(inputs, settings, folder=None):
    """With two cores or more, the data-driven start world made in a forked process
    (:func:`semmap_pp.run.pipeline.timed_start_world`, one core for 1-2 s on a real floor) while
    this one imports the rest of the program (:func:`_import_the_rest`), which the run then
    waits for; with the run's shared ``folder`` the process makes the run's tables too, into it.
    None with one core: the run makes it itself, as it would."""
    if settings.cores < 2:
        return None
    import functools

    from semmap_pp.forked import Forked
    from semmap_pp.run.pipeline import timed_start_world

    return Forked(functools.partial(timed_start_world, inputs, folder), fork=True)


def _import_the_rest() -> None:
    """Import the modules that the chains and the outputs import later (PyMC, ArviZ, matplotlib,
    dask, the ROS 2 message types: about 1.8 s), here, while :func:`_start_job`'s process makes
    the start world."""
    import arviz_base  # noqa: F401  (sampler.diagnostics imports ArviZ when it judges the draws)
    import arviz_stats  # noqa: F401
    import dask.base  # noqa: F401  (xarray asks dask for its scheduler when it writes trace.nc)
    import distributed  # noqa: F401
    import h5netcdf  # noqa: F401
    from rosbags.typesys import Stores, get_typestore

    from semmap_pp.outputs import write  # noqa: F401  (matplotlib)
    from semmap_pp.sampler import step  # noqa: F401  (PyMC)

    get_typestore(Stores.ROS2_JAZZY)   # imports the message types the ROS 2 bag is written with


def _sample_and_write(args, out: Path, inputs, settings, state, rules, starts, previous_ids,
                      previous_places, ids_from, start_job=None, folder=None) -> int:
    """Sample (:func:`semmap_pp.run.pipeline.run_map`) and write every output into ``out``, which
    the caller holds the lock of; the exit status. ``start_job``: :func:`_start_job`'s; ``folder``:
    the run's shared folder (:func:`~semmap_pp.run.shared.shared_folder`) it was given."""
    from semmap_pp.cli.progress import Progress
    from semmap_pp.cli.runs import general_path_note
    from semmap_pp.errors import SemmapError
    from semmap_pp.run.pipeline import run_map
    from semmap_pp.sampler.resume import FILE_NAME as RESUME_FILE
    from semmap_pp.sampler.step import StopFlag

    def log(msg: str) -> None:
        print(msg, file=sys.stderr, flush=True)

    note = general_path_note(inputs.rules, rules)
    if note:
        log(note)
    if state is None:
        left = settings.chains * (settings.tune + settings.draws)
    else:
        left = sum(max(state.total_draws - d, 0) for d in state.done())
    stop = StopFlag()
    previous = _install_sigint(stop)
    try:
        with Progress(settings.chains, left, budget=args.budget, mode=args.progress,
                      every=args.progress_every, parallel=min(settings.cores, settings.chains)) as progress:
            result = run_map(inputs, settings, log=log, callback=progress if args.progress != "none" else None,
                             stop=stop, budget=args.budget, resume=state, starts=starts,
                             start_job=start_job, previous_ids=previous_ids, folder=folder)
    except BaseException as exc:
        signal.signal(signal.SIGINT, previous)
        if isinstance(exc, SemmapError) and stop():
            log(f"semmap: interrupted: nothing written ({exc.message})")
            return 130
        raise
    try:   # the sampling's handler stays until _write_outputs installs its own: no Ctrl-C loses the run
        if starts is not None:
            from semmap_pp.world import n_units
            result.notes.insert(0, f"every chain started from {args.start} ({n_units(starts[0])} units)")
        for note in result.notes:
            log(f"note: {note}")
        written, interrupted = _write_outputs(out, result, rules, _run_meta(args, inputs, state, rules))
    finally:
        signal.signal(signal.SIGINT, previous)
    for path in written:
        print(path)
    if interrupted:
        more = " --draws N" if result.search_complete else ""
        log(f"semmap: interrupted while writing the outputs: the search is saved in {out / RESUME_FILE}; "
            f"`semmap map --resume {out}{more}` continues it and writes every file again")
        return 130
    if previous_places is not None:
        resumed = Path(ids_from).resolve() == (out / "world.json").resolve()    # now overwritten
        changes = _changes_since(previous_places, out / "world.json",
                                 "the world.json this run overwrote" if resumed else None)
        if changes:
            log(changes if resumed else f"{changes} (`semmap diff {ids_from} {out}` lists them)")
    _log_convergence(log, result, out)
    kept_chains, kept_draws = result.kept
    if result.stopped == "interrupted" and result.search_complete:   # after W*'s search had ended
        what = (f"the sample around W* ({len(result.spread.kept[0])} chain(s) x {result.spread.kept[1]} draws)"
                if result.spread is not None else "the search's draws for the spread figures")
        log(f"semmap: interrupted after W*'s search had ended: wrote W* and {what} to {out}")
        return 130
    if result.stopped == "interrupted":
        log(f"semmap: interrupted: wrote partial results ({len(kept_chains)} chain(s) x {kept_draws} draws) "
            f"to {out}; continue with `semmap map --resume {out}`")
        return 130
    if result.stopped == "budget":
        log(f"semmap: budget of {args.budget:g} s reached: kept {len(kept_chains)} chain(s) x {kept_draws} "
            f"draws; continue with `semmap map --resume {out}`")
    return 0


def _tempering(inputs, args):
    """``inputs`` with the model's ``[sampler] spread_tempered`` switched on by ``--tempered`` or
    ``--rungs N`` (which also sets ``spread_rungs``); unchanged without them."""
    if not args.tempered and args.rungs is None:
        return inputs
    import dataclasses

    s = inputs.model.sampler
    s = dataclasses.replace(s, spread_tempered=True,
                            spread_rungs=args.rungs if args.rungs is not None else s.spread_rungs)
    return dataclasses.replace(inputs, model=dataclasses.replace(inputs.model, sampler=s))


def _run_meta(args, inputs, state, rules) -> dict:
    """The inputs of the run as resume.npz and world.json record them (absolute paths)."""
    return {"map": str(Path(inputs.grid.source).resolve()) if inputs.grid.source else None,
            "model": str(Path(inputs.model.path).resolve()),
            "rules": str(Path(rules).resolve()) if rules is not None else None,
            "roi": None if state is None and args.roi is None else
            (state.meta["inputs"]["roi"] if state is not None else str(Path(args.roi).resolve())),
            "map_options": state.meta["inputs"]["map_options"] if state is not None else map_options(args),
            "lattice": [int(v) for v in inputs.frame.shape]}


def _log_convergence(log, result, out: Path) -> None:
    """Whether the chains (and the sample around W*) converged, and where to read more."""
    rep = result.report
    log(f"chains: {'converged' if rep.ok else 'NOT converged'} ({rep.n_chains} x {rep.n_draws} draws; "
        f"R-hat and ESS: `semmap diagnose {out}`"
        + ("" if rep.ok else f"; whether other seeds find the same plan: "
           f"`semmap stability {result.inputs.grid.source}`") + ")")
    if not rep.ok:
        log(f"  failed: {rep.failed()}\n  to fix: {rep.remedy()}")
    note = rep.separation_note()
    if note:
        log(note)
    if result.spread is not None:   # the spread figures' draws: the sample around W*
        rep = result.spread.report
        log(f"sample around W*: {'converged' if rep.ok else 'NOT converged'} ({rep.n_chains} x "
            f"{rep.n_draws} draws; `semmap diagnose {out / 'spread.nc'}`)")
        if not rep.ok:
            log(f"  failed: {rep.failed()}\n  to fix: {rep.remedy()}")
    if rep.shows_mode():
        log(f"{rep.within_mode.heading(rep.n_chains)}: {rep.within_mode.verdict()}")


def _write_outputs(out: Path, run, rules, meta: dict) -> tuple[list[Path], bool]:
    """Write ``resume.npz`` first, then every other output (:func:`semmap_pp.outputs.write.write_all`);
    return the paths written and whether Ctrl-C stopped the writing.

    A Ctrl-C while resume.npz is written lets it finish, then stops; a Ctrl-C after it stops at
    once, or, where its KeyboardInterrupt landed in a library object's ``__del__`` (which Python
    swallows), before the next file (:data:`semmap_pp.atomic.before_write`). Either way the
    search is saved, and every file written is complete (each is renamed whole onto its name; the
    one being written is dropped). The caller puts its SIGINT handler back."""
    from semmap_pp import atomic
    from semmap_pp.forked import Forked
    from semmap_pp.outputs.write import N_SAMPLED_WORLDS, posterior_pngs, write_posterior, write_wstar
    from semmap_pp.run.memory import young_heap
    from semmap_pp.run.spread import posterior_worlds
    from semmap_pp.sampler.resume import FILE_NAME as RESUME_FILE
    from semmap_pp.sampler.resume import write_resume

    pressed, saving = [], [True]

    def handler(signum, frame):
        pressed.append(signum)
        if not saving[0]:
            raise KeyboardInterrupt
        print(f"semmap: interrupted: finishing {RESUME_FILE}, then stopping", file=sys.stderr, flush=True)

    def check():
        if pressed and not saving[0]:
            raise KeyboardInterrupt

    previous = sys.unraisablehook

    def unraisable(u):          # a Ctrl-C a finalizer swallowed: `check` stops at the next file
        if u.exc_type is None or not issubclass(u.exc_type, KeyboardInterrupt):
            previous(u)

    signal.signal(signal.SIGINT, handler)
    atomic.before_write, sys.unraisablehook = check, unraisable
    written = []
    try:
        written.append(write_resume(out, run, meta))
        saving[0] = False
        if pressed:
            raise KeyboardInterrupt
        # typed before world.json, which holds the posterior marginals over them
        worlds = posterior_worlds(run, N_SAMPLED_WORLDS)
        with young_heap():
            # with two cores, report.html's figures that need no other file are drawn meanwhile
            # (graph.png among them: the figures' process has time to spare, this one has none)
            figures = Forked(lambda: posterior_pngs(run, worlds, graph=True), fork=run.settings.cores > 1)
            try:
                wstar = write_wstar(out, run, rules_name=rules.name, rules_path=rules, worlds=worlds,
                                    figures=("overlay",))
                written += write_posterior(out, run, worlds, wstar, rules_name=rules.name,
                                           other_files=(RESUME_FILE,), figures=figures.result)
            finally:
                figures.close()
    except KeyboardInterrupt:
        quiet_finalizers()
        return written, True
    finally:
        atomic.before_write = None
        if sys.unraisablehook is unraisable:       # (quiet_finalizers keeps its own)
            sys.unraisablehook = previous
    return written, False
