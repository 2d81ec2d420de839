"""Building directions and zones (``semmap_pp.lattice.zones.building_zones``) against the truth.

``python bench/run.py zones --json``. Four parts:

* **wings**: synthetic floors with wings (``generate_floor(seed, units=9, wings=2,
  wing_angle_deg=30 | 45)`` and ``units=11, wings=3`` with the angles drawn from the seed; seeds
  ``--seeds``, default 0-9). Per kind: ``correct``, the share of the truth units' free pixels
  (``truth_labels.png`` on free cells) whose zone's angle is the unit's orientation within 3°
  modulo 90°; ``split_units``, the units with more than 10 % of their free pixels in a second
  zone; ``found``, the truth directions within 3° of a zone's angle; the largest angle error.
* **drawn**: the plans of tests/data/wings (wing30, wing45, pentagon): the zones' angles and
  shares, and the true rooms (``NAME_gt.png``) with more than 10 % of their free pixels in a
  second zone.
* **one_direction**: every map built along one direction that the project measures on: the 30
  synthetic floors, bench/data/real-gt, and from /work/shared/data the ten ipa plans, the five
  ipa-types maps and the four real maps (cartesium, intel, aces, freiburg-079; skipped when
  missing). Each should be one zone at θ0 (``lattice_orientation``); ``several`` lists those that
  are not, with their rooms split between zones when they have a room truth.
* **time**: the seconds of ``building_zones`` on the largest of those maps, and on a
  ``--composite`` x ``--composite`` map of the drawn plans tiled 3 x 3 (default 3000), with its
  peak of traced memory (``tracemalloc``).

``--tiny`` (one seed of one kind, one synthetic floor, a 600-cell composite) is the check of
tests/integration/test_bench_smoke.py that the benchmark runs, not a measurement.
"""

from __future__ import annotations

import math
import time
import tracemalloc
from pathlib import Path

import numpy as np
from PIL import Image

ROOT = Path(__file__).resolve().parents[1]
SHARED = Path("/work/shared/data")
IPA_FREE = dict(free_thresh=0.0197, occupied_thresh=0.0198)   # as bench_quality: grey >= 250 free
KINDS = {"30": dict(units=9, wings=2, wing_angle_deg=30.0), "45": dict(units=9, wings=2, wing_angle_deg=45.0),
         "3": dict(units=11, wings=3)}
TINY = {"seeds": "0", "kinds": ["30"], "synthetic": 1, "composite": 600}


def add_arguments(parser) -> None:
    parser.add_argument("--seeds", default="0-9", help="seeds of the wing floors: 0-9 or 0,3,5")
    parser.add_argument("--kinds", nargs="*", default=list(KINDS), choices=list(KINDS))
    parser.add_argument("--synthetic", type=int, default=30, help="one-direction synthetic floors (seeds 0..N-1)")
    parser.add_argument("--composite", type=int, default=3000, help="side of the timed composite map (0: none)")
    parser.add_argument("--tiny", action="store_true", help="a few maps: the smoke test")


def _seeds(text: str) -> list[int]:
    if "-" in text:
        a, b = text.split("-")
        return list(range(int(a), int(b) + 1))
    return [int(s) for s in text.split(",") if s]


def _gap_deg(a, b):
    return np.abs(np.remainder(np.asarray(a, float) - b + 45.0, 90.0) - 45.0)


def _zones(classes, resolution, params):
    from semmap_pp.lattice.frame import lattice_orientation
    from semmap_pp.lattice.zones import building_zones
    theta0 = lattice_orientation(classes, params)
    t = time.perf_counter()
    z = building_zones(classes, resolution, params, theta0)
    return z, time.perf_counter() - t, theta0


def _split(labels, free, truth_labels, ids, k) -> list:
    """The ids whose free pixels lie more than 10 % in a second zone."""
    out = []
    for i in ids:
        pix = free & (truth_labels == i)
        n = int(pix.sum())
        if n and k > 1 and np.sort(np.bincount(labels[pix], minlength=k))[-2] > 0.1 * n:
            out.append(int(i))
    return out


def wings(params, kind: str, seeds) -> dict:
    from semmap_pp.cells import FREE
    from semmap_pp.synth import generate_floor
    good = total = units = 0
    split, errors, found, floors = [], [], 0, []
    for s in seeds:
        f = generate_floor(s, **KINDS[kind])
        z, seconds, _ = _zones(f.classes, f.resolution, params)
        zone_deg = np.degrees(np.asarray(z.thetas))
        free = f.classes == FREE
        for u in f.truth["units"]:
            pix = free & (f.truth_labels == u["id"])
            good += int((_gap_deg(zone_deg[z.labels[pix]], -u["orientation_deg"]) <= 3.0).sum())
            total += int(pix.sum())
            units += 1
        split += [f"{s}:{i}" for i in _split(z.labels, free, f.truth_labels, [u["id"] for u in f.truth["units"]],
                                             len(z.thetas))]
        # an orientation counter-clockwise as displayed is -θ on the image (y down), modulo 90°
        truth = sorted({round(math.remainder(-u["orientation_deg"], 90.0), 1) for u in f.truth["units"]})
        err = [float(_gap_deg(zone_deg, t).min()) for t in truth]
        errors += err
        found += sum(e <= 3.0 for e in err)
        floors.append({"seed": s, "zones_deg": [round(a, 2) for a in zone_deg], "truth_deg": truth,
                       "shares": [round(v, 3) for v in z.shares], "seconds": round(seconds, 3)})
    return {"kind": kind, "correct": round(good / total, 4), "split_units": len(split), "units": units,
            "split": split, "directions_found": found, "directions": len(errors),
            "angle_error_max_deg": round(max(errors), 2), "floors": floors}


def drawn(params, names=("wing30", "wing45", "pentagon")) -> list:
    from semmap_pp.cells import FREE
    from semmap_pp.grid import load_map
    rows = []
    for name in names:
        grid = load_map(ROOT / "tests" / "data" / "wings" / f"{name}.yaml")
        truth = np.asarray(Image.open(ROOT / "tests" / "data" / "wings" / f"{name}_gt.png")).astype(np.int64)
        z, seconds, _ = _zones(grid.classes, grid.resolution, params)
        ids = [int(i) for i in np.unique(truth) if i > 0]
        rows.append({"map": name, "zones_deg": [round(math.degrees(t), 2) for t in z.thetas],
                     "shares": [round(v, 3) for v in z.shares], "rooms": len(ids),
                     "rooms_split": _split(z.labels, grid.classes == FREE, truth, ids, len(z.thetas)),
                     "seconds": round(seconds, 3)})
    return rows


def one_direction_maps(n_synthetic: int):
    """``(name, classes, resolution, room truth or None)`` of every one-direction map."""
    from semmap_pp.grid import load_map
    from semmap_pp.grid.outside import clear_outside
    from semmap_pp.model import load_model
    from semmap_pp.synth import generate_floor
    outside = load_model().outside
    for s in range(n_synthetic):
        f = generate_floor(s)
        yield f"synthetic-{s}", f.classes, f.resolution, None
    for folder in sorted((ROOT / "bench" / "data" / "real-gt").iterdir()):
        if (folder / "map.yaml").is_file():
            grid, _ = clear_outside(load_map(folder / "map.yaml"), outside)
            rgb = np.asarray(Image.open(folder / "gt.png").convert("RGB")).astype(np.int64)
            yield f"real-gt/{folder.name}", grid.classes, grid.resolution, (rgb[..., 0] << 16) | (rgb[..., 1] << 8) | rgb[..., 2]
    for path in sorted((SHARED / "ipa-segmentation").glob("*.yaml")):
        if not path.stem.endswith("_furnitures"):
            grid = load_map(path, **IPA_FREE)
            yield f"ipa/{path.stem}", grid.classes, grid.resolution, None
    for path in sorted((SHARED / "ipa-types").glob("*_original.png")):
        grid = load_map(path, resolution=0.05, **IPA_FREE)
        yield f"ipa-types/{path.stem}", grid.classes, grid.resolution, None
    for path in sorted((SHARED / "real").glob("*.yaml")):
        grid, _ = clear_outside(load_map(path), outside)
        yield f"real/{path.stem}", grid.classes, grid.resolution, None


def one_direction(params, n_synthetic: int) -> dict:
    from semmap_pp.cells import FREE
    several, count, slowest = [], 0, (0.0, "", 0)
    for name, classes, resolution, truth in one_direction_maps(n_synthetic):
        z, seconds, theta0 = _zones(classes, resolution, params)
        count += 1
        if classes.size > slowest[2]:
            slowest = (seconds, name, classes.size)
        if len(z.thetas) > 1 or z.thetas[0] != theta0:
            row = {"map": name, "zones_deg": [round(math.degrees(t), 2) for t in z.thetas],
                   "shares": [round(v, 3) for v in z.shares]}
            if truth is not None:
                ids = [int(i) for i in np.unique(truth) if i > 0 and (truth == i).sum() >= 100]
                row |= {"rooms": len(ids), "rooms_split": len(_split(z.labels, classes == FREE, truth, ids,
                                                                     len(z.thetas)))}
            several.append(row)
    return {"maps": count, "one_zone": count - len(several), "several": several,
            "largest": {"map": slowest[1], "cells": slowest[2], "seconds": round(slowest[0], 3)}}


def composite(params, side: int) -> dict:
    from semmap_pp.cells import UNKNOWN
    from semmap_pp.grid import load_map
    plans = [load_map(ROOT / "tests" / "data" / "wings" / f"{n}.yaml").classes for n in ("wing30", "pentagon", "wing45")]
    big = np.full((side, side), UNKNOWN, np.uint8)
    step = side // 3
    for i in range(3):
        for j in range(3):
            p = plans[(i + j) % 3][:step, :step]
            big[i * step:i * step + p.shape[0], j * step:j * step + p.shape[1]] = p
    tracemalloc.start()
    z, seconds, _ = _zones(big, 0.05, params)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    return {"side": side, "seconds": round(seconds, 3), "traced_peak_mb": round(peak / 1e6, 1),
            "zones_deg": [round(math.degrees(t), 2) for t in z.thetas]}


def run(args) -> dict:
    from semmap_pp.model import load_model
    if args.tiny:
        args.seeds, args.kinds, args.synthetic, args.composite = (TINY[k] for k in ("seeds", "kinds", "synthetic",
                                                                                  "composite"))
    params = load_model().lattice
    out = {"wings": [wings(params, k, _seeds(args.seeds)) for k in args.kinds],
           "drawn": drawn(params, ("pentagon",) if args.tiny else ("wing30", "wing45", "pentagon"))}
    if args.tiny:
        from semmap_pp.synth import generate_floor
        f = generate_floor(1)
        z, seconds, theta0 = _zones(f.classes, f.resolution, params)
        out["one_direction"] = {"maps": 1, "one_zone": int(z.thetas == (theta0,))}
    else:
        out["one_direction"] = one_direction(params, args.synthetic)
    if args.composite:
        out["composite"] = composite(params, args.composite)
    return out
