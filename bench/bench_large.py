"""Time and peak memory of reading a large map and building what a run needs, per map size.

``python bench/run.py large --json``. For each size (default 1,000^2, 2,500^2 and 5,000^2 cells) a
synthetic floor is written as a PGM (a grid of rooms with doors, corridors, clutter, an unknown
outside; rotated by ``--angle`` degrees so that the lattice is resampled as for a real, rotated map).
A fresh subprocess then measures, phase by phase: ``load_map`` (decode + classify), ``build_frame``
(orientation estimate and lattice), the default region of interest, the likelihood data
(``likelihood.prepare``) and the kernel data (``kernels.data_from_frame``). Peak memory is the
process's peak resident set size (``resource.getrusage(RUSAGE_SELF).ru_maxrss``) after each phase,
less the resident size after imports; times are wall-clock seconds. The result holds each size's
numbers, bytes per cell at the peak, and the ratios between sizes (time per cell relative to the
smallest size: 1.0 means linear). With ``--canvas N`` (default 4000; 0 skips it) a
``--canvas-floor`` floor pasted into an N x N canvas of unknown cells, as gmapping writes maps, is
measured with the model's lattice crop and without (``crop_margin_m = 0``): the ratios of the two.

Whole runs (``--floors``, default ``intel campus``; ``--floors`` with no name skips them): each
floor of :data:`FLOORS` is written by :func:`campus_floor` (a rectangular corridor loop with a row
of rooms along its outside, rotated by ``--floor-angle``, unknown around and inside the loop), and
``semmap map FLOOR.yaml --out DIR`` (model defaults, or ``--map-args``) runs in a subprocess of a
fresh interpreter that measures it: wall time and the peak resident set size of the largest
process of the run (``getrusage(RUSAGE_CHILDREN).ru_maxrss``, what ``/usr/bin/time -v`` reports)
and ``tree_pss_mib``, the largest proportional set size of the run's processes together (the
chains' worker processes included, shared pages counted once; polled every 0.5 s).
``intel`` is a floor of intel's size (0.28 M known cells, a 0.76 M-cell canvas), ``mid`` one
between (1.0 M known cells in a 6.2 M-cell canvas), ``campus`` one shaped like the MIT infinite
corridor (a 0.9 km loop: 2.05 M known cells in a 23.9 M-cell canvas). ``--plot PNG`` draws time
and peak against known cells on log-log axes (docs/figures/large_runs.png). The result gives time and peak against the known cells and, for each floor against the
first, the ratios of known cells, time and peak (``time_over_known``: the time ratio over the
known-cell ratio; issue 54 asks for at most 1.5 on the campus floor).

``--tiny`` (:data:`TINY`: sizes 200 and 300, a 600-cell canvas, the two floors shrunk and short
runs) is the check of tests/integration/test_bench_smoke.py that the benchmark runs, not a
measurement.
"""

from __future__ import annotations

import json
import math
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
#: ``--tiny``: the arguments it sets
TINY = {"sizes": [200, 300], "canvas": 600, "canvas_floor": 200, "floor_scale": 0.15, "floors": ["intel", "campus"],
        "map_args": "--chains 1 --cores 1 --tune 2 --draws 4 --n-inner 5 --spread-draws 0"}

#: The whole-run floors (:func:`campus_floor`): the loop's outer sides along the building's axes, m.
FLOORS = {"intel": {"side_u_m": 40.0, "side_v_m": 30.0},
          "mid": {"side_u_m": 120.0, "side_v_m": 100.0},
          "campus": {"side_u_m": 225.0, "side_v_m": 215.0}}

WHOLE_CHILD = r"""
import json, os, resource, subprocess, sys, threading, time

def tree_pss_kib(root):
    # proportional set size of root and its descendants (shared pages split between them), KiB
    kids = {}
    for d in os.listdir("/proc"):
        if d.isdigit():
            try:
                with open(f"/proc/{d}/stat") as fh:
                    kids.setdefault(int(fh.read().rsplit(")", 1)[1].split()[1]), []).append(int(d))
            except OSError:
                pass
    total, todo = 0, [root]
    while todo:
        pid = todo.pop()
        todo.extend(kids.get(pid, []))
        try:
            with open(f"/proc/{pid}/smaps_rollup") as fh:
                total += sum(int(ln.split()[1]) for ln in fh if ln.startswith("Pss:"))
        except OSError:
            pass
    return total

t = time.perf_counter()
proc = subprocess.Popen(sys.argv[1:], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
peak_tree = [0]
def poll():
    while proc.poll() is None:
        peak_tree[0] = max(peak_tree[0], tree_pss_kib(proc.pid))
        time.sleep(0.5)
threading.Thread(target=poll, daemon=True).start()
_, err = proc.communicate()
wall = time.perf_counter() - t
peak = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
print(json.dumps({"rc": proc.returncode, "wall_s": round(wall, 2), "peak_mib": round(peak / 1024, 1),
                  "tree_pss_mib": round(peak_tree[0] / 1024, 1), "stderr": err[-3000:]}))
"""

CHILD = r"""
import json, math, resource, sys, time
t0 = time.perf_counter()
from semmap_pp.evaluate import closing_radius_cells, default_roi
from semmap_pp.lattice.frame import build_frame
from semmap_pp.grid import load_map
from semmap_pp.sampler.kernels import data_from_frame
from semmap_pp.target.likelihood import prepare
from semmap_pp.model import load_model

def rss_kib():
    with open("/proc/self/status") as fh:
        for line in fh:
            if line.startswith("VmRSS:"):
                return int(line.split()[1])

def peak_kib():
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss

model = load_model(sys.argv[3] if len(sys.argv) > 3 else None)
base = rss_kib()
out = {"import_s": round(time.perf_counter() - t0, 3), "base_rss_mib": round(base / 1024, 1), "phases": {}}
def phase(name, fn):
    t = time.perf_counter()
    value = fn()
    out["phases"][name] = {"s": round(time.perf_counter() - t, 3),
                           "peak_mib": round((peak_kib() - base) / 1024, 1)}
    return value
grid = phase("load_map", lambda: load_map(sys.argv[1], max_cells=int(sys.argv[2])))
frame = phase("build_frame", lambda: build_frame(grid, model))
phase("default_roi", lambda: default_roi(grid.classes, closing_radius_cells(
    model.evaluate.roi_closing_m, grid.resolution)))
phase("likelihood", lambda: prepare(frame, model))
phase("kernel_data", lambda: data_from_frame(frame, model.kernels))
out["lattice"] = list(frame.shape)
out["theta_deg"] = round(math.degrees(frame.theta), 2)
out["total_s"] = round(sum(p["s"] for p in out["phases"].values()), 3)
out["peak_mib"] = max(p["peak_mib"] for p in out["phases"].values())
print(json.dumps(out))
"""


def add_arguments(parser) -> None:
    parser.add_argument("--sizes", type=int, nargs="+", default=[1000, 2500, 5000],
                        help="side lengths of the square maps, cells")
    parser.add_argument("--angle", type=float, default=20.0, help="rotation of the synthetic building, degrees")
    parser.add_argument("--resolution", type=float, default=0.05)
    parser.add_argument("--room", type=float, default=6.0, help="room pitch, metres")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--canvas", type=int, default=4000,
                        help="also a --canvas-floor floor in a canvas of this many cells a side, unknown around it "
                             "(gmapping's default map: 4000), with the model's lattice crop and without; 0: skip")
    parser.add_argument("--canvas-floor", type=int, default=1000, help="side of the floor in the canvas, cells")
    parser.add_argument("--floors", nargs="*", default=list(FLOORS), choices=list(FLOORS),
                        help="whole runs of `semmap map` on these floors (campus_floor); none: skip")
    parser.add_argument("--floor-angle", type=float, default=5.0, help="rotation of the whole-run floors, degrees")
    parser.add_argument("--floor-scale", type=float, default=1.0, help="the whole-run floors' sides times this")
    parser.add_argument("--map-args", default="", help="more arguments of the whole runs' `semmap map`")
    parser.add_argument("--plot", type=Path, default=None, help="a log-log PNG of time and peak against known cells")
    parser.add_argument("--tiny", action="store_true", help="small maps (a check that it runs)")


def synthetic_floor(n: int, angle_deg: float, resolution: float, room_m: float,
                    rng: np.random.Generator) -> np.ndarray:
    """``n x n`` map_server grey image: rotated rooms with doors, clutter, unknown outside.

    Walls are 0.1 m thick on a ``room_m`` pitch, every wall has a 1 m door in the middle of each
    room side, one row of rooms in five is a corridor (no cross walls), 0.5 % of the free cells are
    clutter, and everything outside a disc of 0.48 n cells is unknown.
    """
    image = np.empty((n, n), np.uint8)
    c, s = math.cos(math.radians(angle_deg)), math.sin(math.radians(angle_deg))
    pitch, wall, door = room_m / resolution, max(1.0, 0.1 / resolution), 1.0 / resolution
    cols = np.arange(n, dtype=np.float32) - n / 2
    for r0 in range(0, n, 500):  # in bands, to keep the generator's memory small
        rows = np.arange(r0, min(r0 + 500, n), dtype=np.float32)[:, None] - n / 2
        u = c * cols[None, :] + s * rows + 1e4 * pitch
        v = -s * cols[None, :] + c * rows + 1e4 * pitch
        fu, fv = np.mod(u, pitch), np.mod(v, pitch)
        corridor = (np.floor_divide(v, pitch).astype(np.int64) % 5) == 0
        wall_u = (fu < wall) & ~corridor & (np.abs(fv - pitch / 2) > door / 2)
        wall_v = (fv < wall) & (np.abs(fu - pitch / 2) > door / 2)
        band = np.where(wall_u | wall_v, 0, 254).astype(np.uint8)
        clutter = rng.random(band.shape) < 0.005
        band[clutter] = 0
        outside = rows ** 2 + cols[None, :] ** 2 > (0.48 * n) ** 2
        band[outside] = 205
        image[r0:r0 + len(rows)] = band
    return image


def campus_floor(side_u_m: float, side_v_m: float, angle_deg: float, resolution: float,
                 rng: np.random.Generator, *, room_depth_m: float = 3.5, corridor_m: float = 2.2,
                 pitch_m: float = 4.0, margin_m: float = 3.0) -> np.ndarray:
    """map_server grey image of a corridor loop with rooms: a campus floor, known in a thin band.

    The loop's outer walls form a ``side_u_m`` x ``side_v_m`` rectangle rotated by ``angle_deg``;
    inwards from its outer wall (0.15 m walls) lie a row of rooms ``room_depth_m`` deep on a
    ``pitch_m`` pitch, each with a 1 m door in the middle of its corridor wall, then the corridor
    (``corridor_m`` wide) and the loop's inner wall. 0.5 % of the free cells are clutter; the
    courtyard inside the loop and everything outside it are unknown. The canvas is the rotated
    rectangle's bounding box and ``margin_m`` around it. Generated in bands of rows.

    >>> im = campus_floor(20.0, 15.0, 5.0, 0.05, np.random.default_rng(0))
    >>> im.shape, sorted(np.unique(im).tolist())
    ((454, 545), [0, 205, 254])
    """
    wall, door = 0.15, 1.0
    band = room_depth_m + corridor_m + 2 * wall
    c, s = math.cos(math.radians(angle_deg)), math.sin(math.radians(angle_deg))
    w_m = side_u_m * abs(c) + side_v_m * abs(s) + 2 * margin_m
    h_m = side_u_m * abs(s) + side_v_m * abs(c) + 2 * margin_m
    w, h = int(math.ceil(w_m / resolution)), int(math.ceil(h_m / resolution))
    image = np.empty((h, w), np.uint8)
    xs = (np.arange(w, dtype=np.float32) + 0.5) * resolution - w_m / 2
    for r0 in range(0, h, 256):
        ys = ((np.arange(r0, min(r0 + 256, h), dtype=np.float32) + 0.5) * resolution - h_m / 2)[:, None]
        u = c * xs[None, :] + s * ys
        v = -s * xs[None, :] + c * ys
        tu, tv = side_u_m / 2 - np.abs(u), side_v_m / 2 - np.abs(v)  # depth from the outer wall
        t = np.minimum(tu, tv)
        along = np.mod(np.where(tu < tv, v, u) + 1e4 * pitch_m, pitch_m)
        rooms = t < wall + room_depth_m
        mid = (t >= wall + room_depth_m) & (t < 2 * wall + room_depth_m)
        doorway = np.abs(along - pitch_m / 2) < door / 2
        walls = (t < wall) | (t >= band - wall) | (mid & ~doorway) | (rooms & (along < wall))
        out = np.where(walls, 0, 254).astype(np.uint8)
        out[(out == 254) & (rng.random(out.shape) < 0.005)] = 0
        out[(t < 0) | (t >= band)] = 205
        image[r0:r0 + len(ys)] = out
    return image


def measure_whole(yaml_path: Path, out_dir: Path, map_args: str) -> dict:
    """``semmap map`` on ``yaml_path`` in a fresh interpreter's subprocess: wall time, peak RSS."""
    cmd = [sys.executable, "-m", "semmap_pp", "map", str(yaml_path), "--out", str(out_dir),
           "--progress", "plain", *map_args.split()]
    result = subprocess.run([sys.executable, "-c", WHOLE_CHILD, *cmd], capture_output=True, text=True,
                            cwd=ROOT, timeout=7200)
    if result.returncode != 0:
        raise RuntimeError(result.stderr[-2000:])
    m = json.loads(result.stdout.strip().splitlines()[-1])
    if m["rc"] != 0:
        raise RuntimeError(f"semmap map {yaml_path} failed:\n{m['stderr']}")
    doc = json.loads((out_dir / "world.json").read_text())
    lines = [ln for ln in m.pop("stderr").splitlines() if ln.startswith(("start world", "W*"))]
    m["units"] = len(doc.get("units", []))
    m["log"] = lines
    return m


def measure_floors(args, d: Path) -> dict:
    """The whole runs of ``args.floors`` (see the module docstring), one after the other."""
    from semmap_pp.grid import write_map

    rows = []
    for name in args.floors:
        sides = {k: v * args.floor_scale for k, v in FLOORS[name].items()}
        rng = np.random.default_rng((args.seed, list(FLOORS).index(name)))   # each floor its own clutter
        image = campus_floor(sides["side_u_m"], sides["side_v_m"], args.floor_angle, args.resolution, rng)
        canvas, known = image.size, int(np.count_nonzero(image != 205))
        path = write_map(d / f"{name}.yaml", image, args.resolution)
        del image
        m = measure_whole(path, d / f"out_{name}", args.map_args)
        row = {"floor": name, **sides, "canvas_cells": canvas, "known_cells": known, **m,
               "s_per_m_known": round(m["wall_s"] / (known / 1e6), 2),
               "mib_per_m_known": round(m["peak_mib"] / (known / 1e6), 1)}
        rows.append(row)
        print(f"whole run {name}: {canvas / 1e6:.2f} M canvas, {known / 1e6:.2f} M known cells: "
              f"{m['wall_s']} s, peak {m['peak_mib']} MiB (all processes {m['tree_pss_mib']} MiB), "
              f"{m['units']} units", file=sys.stderr, flush=True)
    for row in rows[1:]:
        first = rows[0]
        k = row["known_cells"] / first["known_cells"]
        row["vs_" + first["floor"]] = {
            "known_ratio": round(k, 2), "canvas_ratio": round(row["canvas_cells"] / first["canvas_cells"], 2),
            "time_ratio": round(row["wall_s"] / first["wall_s"], 2),
            "peak_ratio": round(row["peak_mib"] / first["peak_mib"], 2),
            "tree_pss_ratio": round(row["tree_pss_mib"] / max(first["tree_pss_mib"], 1e-9), 2),
            "time_over_known": round(row["wall_s"] / first["wall_s"] / k, 2)}
    out = {"angle_deg": args.floor_angle, "map_args": args.map_args, "floors": rows}
    if args.plot is not None:
        plot_floors(out, args.plot)
    return out


def plot_floors(whole: dict, path: Path) -> None:
    """Wall time and peak RSS of the whole runs against their known cells, log-log, with the line
    of proportion through the first floor."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    rows = whole["floors"]
    known = np.array([r["known_cells"] for r in rows], float) / 1e6
    fig = Figure(figsize=(9, 3.8), dpi=100)
    FigureCanvasAgg(fig)
    for ax, key, unit in zip(fig.subplots(1, 2), ("wall_s", "peak_mib"), ("wall time, s", "peak RSS, MiB")):
        y = np.array([r[key] for r in rows], float)
        ax.loglog(known, y, "o-", label="semmap map")
        ax.loglog(known, y[0] * known / known[0], "--", color="grey", label="proportional to known cells")
        for r, k, v in zip(rows, known, y):
            ax.annotate(f"{r['floor']} ({r['canvas_cells'] / 1e6:.1f} M canvas)", (k, v), fontsize=8,
                        xytext=(4, -10), textcoords="offset points")
        ax.set_xticks(known, [f"{k:.2f}" for k in known], minor=False)
        ax.set_xticks([], minor=True)
        ax.set_xlim(known[0] / 1.3, known[-1] * 2.5)
        ax.set_xlabel("known cells, millions")
        ax.set_ylabel(unit)
        ax.grid(True, which="both", alpha=0.3)
    fig.axes[0].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path)


def measure(path: Path, cells: int, model: Path | None = None) -> dict:
    extra = [str(model)] if model is not None else []
    result = subprocess.run([sys.executable, "-c", CHILD, str(path), str(max(cells, 1)), *extra],
                            capture_output=True, text=True, cwd=ROOT, timeout=3600)
    if result.returncode != 0:
        raise RuntimeError(result.stderr[-2000:])
    return json.loads(result.stdout.strip().splitlines()[-1])


def run(args) -> dict:
    from semmap_pp.grid import write_map

    if args.tiny:
        for key, value in TINY.items():
            setattr(args, key, value)
    rng = np.random.default_rng(args.seed)
    rows = []
    with tempfile.TemporaryDirectory() as d:
        for n in args.sizes:
            image = synthetic_floor(n, args.angle, args.resolution, args.room, rng)
            path = write_map(Path(d) / f"floor{n}.yaml", image, args.resolution)
            del image
            m = measure(path, n * n)
            m["cells"] = n * n
            m["bytes_per_cell"] = round(m["peak_mib"] * 2**20 / (n * n), 1)
            rows.append(m)
            print(f"{n}x{n}: load {m['phases']['load_map']['s']} s, all phases {m['total_s']} s, "
                  f"peak {m['peak_mib']} MiB over {m['base_rss_mib']} MiB", file=sys.stderr, flush=True)
        canvas = measure_canvas(args, rng, Path(d)) if args.canvas else None
        whole = measure_floors(args, Path(d)) if args.floors else None
    small = rows[0]
    for m in rows:
        scale = m["cells"] / small["cells"]
        m["time_per_cell_ratio"] = round(m["total_s"] / small["total_s"] / scale, 2)
        m["load_time_per_cell_ratio"] = round(
            m["phases"]["load_map"]["s"] / small["phases"]["load_map"]["s"] / scale, 2)
        m["peak_per_cell_ratio"] = round(m["peak_mib"] / max(small["peak_mib"], 1e-9) / scale, 2)
    return {"angle_deg": args.angle, "resolution": args.resolution, "sizes": rows, "canvas": canvas,
            "whole": whole}


def measure_canvas(args, rng, d: Path) -> dict:
    """A ``--canvas-floor`` floor pasted off-centre into a ``--canvas`` canvas of unknown cells (a ROS
    map as gmapping writes it), measured with the model's lattice crop and with a copy of the model
    whose ``crop_margin_m`` is 0 (the lattice over the whole canvas), one after the other."""
    import re

    from semmap_pp.grid import write_map
    from semmap_pp.model import DEFAULT_MODEL

    n, f = args.canvas, args.canvas_floor
    image = np.full((n, n), 205, np.uint8)
    r0, c0 = n // 3, n // 4
    image[r0:r0 + f, c0:c0 + f] = synthetic_floor(f, args.angle, args.resolution, args.room, rng)
    path = write_map(d / f"canvas{n}.yaml", image, args.resolution)
    del image
    text = Path(DEFAULT_MODEL).read_text()
    whole = d / "whole_canvas.toml"
    whole.write_text(re.sub(r"(?m)^crop_margin_m = .*$", "crop_margin_m = 0.0", text))
    out = {"canvas": n, "floor": f, "at": [r0, c0]}
    for name, model in (("crop", None), ("whole", whole)):
        m = measure(path, n * n, model)
        out[name] = m
        print(f"canvas {n}x{n} ({name}): lattice {m['lattice']}, all phases {m['total_s']} s, "
              f"peak {m['peak_mib']} MiB", file=sys.stderr, flush=True)
    out["time_ratio_whole_to_crop"] = round(out["whole"]["total_s"] / out["crop"]["total_s"], 1)
    out["peak_ratio_whole_to_crop"] = round(out["whole"]["peak_mib"] / max(out["crop"]["peak_mib"], 1e-9), 1)
    return out
