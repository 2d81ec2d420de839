"""``semmap batch``: many maps, seeds and rule sets as tasks of a Dask cluster.

Each task is one ``semmap map`` run, started as a process of its own by a Dask worker
(:func:`run_task`), so a task writes exactly the files ``semmap map`` writes, and a task that
crashes, hangs past its timeout or exhausts memory takes only itself down. The cluster is a
``distributed.LocalCluster`` of one worker process per core, or the scheduler at ``--scheduler
ADDRESS`` (docs/cli.md, ``semmap batch``). Tasks ship their arguments (a few hundred bytes) and
return a small dict; the maps are read, and the outputs written, on a file system the workers share.

The batch folder holds one folder per task, ``DIR/<map>[/<rules>][/seed-<s>]``, and, rewritten as
tasks end, ``summary.json``, ``summary.csv`` and ``index.html`` (:func:`write_summary`).
"""

from __future__ import annotations

import csv
import ctypes
import glob as globmod
import html
import io
import json
import os
import signal
import subprocess
import sys
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

from semmap_pp import atomic
from semmap_pp.cells import known_box
from semmap_pp.errors import MapError
from semmap_pp.grid import load_map
from semmap_pp.grid.rosbag import BAG_SUFFIXES, is_bag

#: the file ``semmap map`` writes last (after resume.npz, which it writes first): a task whose
#: folder holds both is complete
DONE_FILE = "report.html"
MAP_SUFFIXES = (".yaml", ".yml", ".png", ".pgm", ".npy")
#: peak memory of a run, estimated from the cells of the map's known box (``semmap map`` works on
#: the known part and 2 m around it): a fixed part and bytes per cell, an upper bound of the peaks
#: measured (RSS by /usr/bin/time, docs/benchmarks.md, "semmap batch"), not a model of them.
PEAK_BASE_BYTES = 0.6e9
PEAK_BYTES_PER_CELL = 300.0


@dataclass(frozen=True)
class Task:
    """One run of a batch: a map, a rule file (None: the default), a seed (None: the default)."""

    map: str
    out: str
    rules: str | None = None
    seed: int | None = None
    label: str = ""


@dataclass
class Result:
    """What a task left: ``status`` is ok, failed or skipped (its output was complete)."""

    map: str
    rules: str | None
    seed: int | None
    out: str
    status: str
    wall_s: float = 0.0
    error: str | None = None
    units: dict = field(default_factory=dict)
    doors: int | None = None
    cpr: float | None = None
    log_posterior: float | None = None


def expand_maps(items: list[str]) -> list[Path]:
    """The map files ``items`` name: files, bags, folders (their map files: ``*.yaml`` when it
    holds any, else images; and the bags in it, files or ROS 2 bag folders) and glob patterns, in
    order, each once. A ROS 2 bag folder named itself is one map."""

    out: list[Path] = []

    def add(p: Path) -> None:
        try:      # a name found in a folder or by a pattern, as semmap map checks its arguments
            str(p).encode("utf-8")
        except UnicodeEncodeError:
            raise MapError(p, "not UTF-8 text (a name of other bytes, shown as \\xNN); semmap writes "
                              "the names it is given into its outputs as UTF-8: rename it") from None
        if p not in out:
            out.append(p)

    for item in items:
        p = Path(item)
        if p.is_dir() and is_bag(p):
            add(p)
        elif p.is_dir():
            yamls = sorted(q for q in p.iterdir() if q.suffix.lower() in (".yaml", ".yml") and q.is_file())
            found = yamls or sorted(q for q in p.iterdir() if q.suffix.lower() in MAP_SUFFIXES and q.is_file())
            found += sorted(q for q in p.iterdir() if (q.is_file() and q.suffix.lower() in BAG_SUFFIXES)
                            or (q.is_dir() and (q / "metadata.yaml").is_file()))
            if not found:
                raise MapError(p, "folder holds no map (.yaml, .png, .pgm, .npy, a bag)")
            for q in found:
                add(q)
        elif p.exists():
            if not p.is_file():
                raise MapError(p, "not a regular file")
            add(p)
        elif any(ch in item for ch in "*?["):
            hits = sorted(Path(h) for h in globmod.glob(item, recursive=True)
                          if Path(h).is_file() or (Path(h) / "metadata.yaml").is_file())
            if not hits:
                raise MapError(p, "the pattern matches no file")
            for q in hits:
                add(q)
        else:
            raise MapError(p, "no such file")
    return out


def _unique_names(paths: list[Path], by_folder: bool = False) -> list[str]:
    """A folder name per path: its stem; with ``by_folder``, maps that share a stem (a folder per
    floor, each with its map.yaml) are named by their folder; what still repeats gets -2, -3, ..."""
    stems = [p.stem if p.suffix else p.name for p in paths]
    if by_folder:
        stems = [p.parent.name if stems.count(st) > 1 and p.parent.name else st
                 for p, st in zip(paths, stems)]
    names, seen = [], {}
    for st in stems:
        seen[st] = seen.get(st, 0) + 1
        names.append(st if seen[st] == 1 else f"{st}-{seen[st]}")
    return names


def plan_tasks(maps: list[Path], out: Path, rules: list[str] | None, seeds: list[int] | None) -> list[Task]:
    """One task per map, rule file and seed: ``out/<map>[/<rules>][/seed-<s>]`` (the rules level
    only with two or more rule files, the seed level only with ``--seeds``)."""
    rule_list = rules or [None]
    rule_names = _unique_names([Path(r) for r in rules]) if rules else [None]
    seed_list = seeds if seeds else [None]
    tasks = []
    for m, mname in zip(maps, _unique_names(maps, by_folder=True)):
        for r, rname in zip(rule_list, rule_names):
            for s in seed_list:
                d = out / mname
                if rules and len(rules) > 1:
                    d = d / rname
                if seeds:
                    d = d / f"seed-{s}"
                label = "/".join(str(x) for x in (mname, rname if rules and len(rules) > 1 else None,
                                                  None if s is None else f"seed-{s}") if x is not None)
                tasks.append(Task(str(m), str(d), r, s, label))
    return tasks


def task_command(task: Task, map_args: list[str]) -> list[str]:
    """The ``semmap map`` command line of a task."""
    cmd = [sys.executable, "-m", "semmap_pp", "map", task.map, "--out", task.out, "--force",
           "--progress", "none"]
    if task.rules is not None:
        cmd += ["--rules", task.rules]
    if task.seed is not None:
        cmd += ["--seed", str(task.seed)]
    return cmd + list(map_args)


def complete(out: str | os.PathLike) -> bool:
    """Whether a task's folder holds a whole run: ``semmap map`` writes resume.npz first and
    :data:`DONE_FILE` last, so a run stopped while writing (Ctrl-C, a full disk, a kill) lacks
    one of them."""
    d = Path(out)
    return all((d / name).is_file() for name in ("resume.npz", "world.json", DONE_FILE))


def _last_error(stderr: str) -> str:
    lines = [ln.strip() for ln in stderr.strip().splitlines() if ln.strip()]
    for ln in reversed(lines):
        if ln.startswith("semmap:"):
            return ln
    return lines[-1] if lines else "no message"


def world_facts(out: str | os.PathLike) -> dict:
    """Units by type, doors, CPR and log posterior from a task's world.json (empty if unreadable)."""
    try:
        doc = json.loads((Path(out) / "world.json").read_text(encoding="utf-8"))
        units = {t: 0 for t in ("room", "corridor", "hall", "other")}
        for u in doc.get("units", []):
            units[u.get("type")] = units.get(u.get("type"), 0) + 1
        return {"units": units, "doors": len(doc.get("doors", [])), "cpr": doc.get("cpr"),
                "log_posterior": doc.get("log_posterior")}
    except (OSError, ValueError, AttributeError, TypeError, RecursionError):
        return {}


def _die_with_parent() -> None:  # pragma: no cover - runs in the child before exec
    """Linux: the run is killed when the worker that started it dies (a killed worker leaves no
    run behind writing into the folder its retry writes)."""
    try:
        ctypes.CDLL(None).prctl(1, 9)          # PR_SET_PDEATHSIG, SIGKILL
    except (OSError, AttributeError):
        pass


def _kill_group(p: subprocess.Popen) -> None:
    try:
        os.killpg(p.pid, signal.SIGKILL)
    except (ProcessLookupError, PermissionError):
        pass
    p.wait()


def run_task(task: Task, map_args: list[str], timeout: float | None = None) -> dict:
    """Run one task as a process of its own; its :class:`Result` as a dict. Runs on a worker."""
    t0 = time.perf_counter()
    Path(task.out).mkdir(parents=True, exist_ok=True)
    res = Result(task.map, task.rules, task.seed, task.out, "ok")
    p = subprocess.Popen(task_command(task, map_args), stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                         stdin=subprocess.DEVNULL, text=True, start_new_session=True,
                         preexec_fn=_die_with_parent)
    try:
        _, err = p.communicate(timeout=timeout)
        if p.returncode != 0:
            res.status, res.error = "failed", _last_error(err)
    except subprocess.TimeoutExpired:
        _kill_group(p)
        res.status, res.error = "failed", f"timed out after {timeout:g} s"
    except BaseException:          # the worker is being stopped: the run goes with it
        _kill_group(p)
        raise
    res.wall_s = round(time.perf_counter() - t0, 2)
    if res.status == "ok":
        facts = world_facts(task.out)
        for k, v in facts.items():
            setattr(res, k, v)
    return asdict(res)


def estimated_peak_bytes(map_path: str, map_options: dict | None = None) -> float:
    """A run's estimated peak memory (:data:`PEAK_BASE_BYTES` + :data:`PEAK_BYTES_PER_CELL` per
    cell of the map's known box)."""

    grid = load_map(map_path, **(map_options or {}))
    box = known_box(grid.classes)
    cells = 0 if box is None else (box[2] - box[0]) * (box[3] - box[1])
    return PEAK_BASE_BYTES + PEAK_BYTES_PER_CELL * cells


SUMMARY_FIELDS = ("map", "rules", "seed", "status", "room", "corridor", "hall", "other", "doors",
                  "cpr", "log_posterior", "wall_s", "error", "out")


def summary_rows(results: list[dict]) -> list[dict]:
    rows = []
    for r in results:
        units = r.get("units") or {}
        rows.append({"map": r["map"], "rules": r.get("rules"), "seed": r.get("seed"), "status": r["status"],
                     **{t: units.get(t) if units else None for t in ("room", "corridor", "hall", "other")},
                     "doors": r.get("doors"), "cpr": r.get("cpr"), "log_posterior": r.get("log_posterior"),
                     "wall_s": r.get("wall_s"), "error": r.get("error"), "out": r["out"]})
    return rows


def index_html(out: Path, rows: list[dict]) -> str:
    """index.html: a row per task, its report.html linked with its overlay as a thumbnail."""
    def rel(p: str, name: str) -> str:
        try:
            return html.escape(str((Path(p) / name).relative_to(out)), quote=True)
        except ValueError:
            return html.escape(str(Path(p) / name), quote=True)

    body = []
    for r in rows:
        ok = r["status"] in ("ok", "skipped")
        thumb = (f'<a href="{rel(r["out"], "report.html")}"><img src="{rel(r["out"], "overlay.png")}" '
                 f'width="240" alt="overlay"></a>' if ok else "")
        units = " / ".join("" if r[t] is None else str(r[t]) for t in ("room", "corridor", "hall", "other"))
        body.append("<tr>" + "".join(f"<td>{html.escape('' if v is None else str(v))}</td>" for v in
                                     (r["map"], r["rules"] or "default", r["seed"] if r["seed"] is not None
                                      else "default", r["status"], units, r["doors"], r["cpr"],
                                      r["wall_s"], r["error"] or ""))
                    + f"<td>{thumb}</td></tr>")
    head = "".join(f"<th>{h}</th>" for h in ("map", "rules", "seed", "status", "units R / C / H / O",
                                             "doors", "CPR", "wall s", "error", "W*"))
    return ("<!DOCTYPE html><html><head><meta charset=\"utf-8\"><title>semmap batch</title>"
            "<style>body{font-family:sans-serif}td,th{border:1px solid #ccc;padding:3px 6px}"
            "table{border-collapse:collapse}</style></head><body><h1>semmap batch</h1>"
            f"<table><tr>{head}</tr>{''.join(body)}</table></body></html>\n")


def write_summary(out: Path, results: list[dict]) -> None:
    """summary.json, summary.csv and index.html of the results so far (each atomically)."""
    rows = summary_rows(results)
    atomic.write_text(out / "summary.json", json.dumps({"tasks": rows}, indent=1) + "\n")
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=SUMMARY_FIELDS, lineterminator="\n")
    w.writeheader()
    w.writerows(rows)
    atomic.write_text(out / "summary.csv", buf.getvalue())
    atomic.write_text(out / "index.html", index_html(out, rows))


__all__ = ["Task", "Result", "expand_maps", "plan_tasks", "task_command", "complete", "run_task",
           "estimated_peak_bytes", "write_summary", "summary_rows", "index_html", "DONE_FILE"]
