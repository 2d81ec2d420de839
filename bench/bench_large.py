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
``--tiny`` (:data:`TINY`: sizes 200 and 300, a 600-cell canvas) is the check of
tests/integration/test_bench_smoke.py that the benchmark runs, not a measurement.
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
TINY = {"sizes": [200, 300], "canvas": 600, "canvas_floor": 200}

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
    small = rows[0]
    for m in rows:
        scale = m["cells"] / small["cells"]
        m["time_per_cell_ratio"] = round(m["total_s"] / small["total_s"] / scale, 2)
        m["load_time_per_cell_ratio"] = round(
            m["phases"]["load_map"]["s"] / small["phases"]["load_map"]["s"] / scale, 2)
        m["peak_per_cell_ratio"] = round(m["peak_mib"] / max(small["peak_mib"], 1e-9) / scale, 2)
    return {"angle_deg": args.angle, "resolution": args.resolution, "sizes": rows, "canvas": canvas}


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
