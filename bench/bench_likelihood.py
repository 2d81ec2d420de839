"""Likelihood/posterior speed on a real map: incremental single-unit edits and full evaluations.

``python bench/run.py likelihood --json``. On the cartesium lattice (as the sampler sees it: the
known cells and a margin, :func:`semmap_pp.lattice.frame.build_frame_from_classes`) a seeded 20-unit
world of room-sized rectangles is placed over the known part of the map; a *typical single-unit
edit* moves one wall of one unit by 1..5 cells (the SHRINK/DILATE kernel), half of the proposals
are accepted. The same world and the same edits run on a map of four times the area (that lattice
tiled 2x2), interleaved edit by edit with the 1x map, to show that the cost follows the edit, not
the map. The world must lie in the prior's support and edits must be evaluated, or the run stops
with a message (it would time nothing real). ``--tiny`` (:data:`TINY`: 3 units, 50 edits on
tests/data/maps/intel_corner.yaml) is the check of tests/integration/test_bench_smoke.py that it runs.
"""

from __future__ import annotations

import statistics
import time
from pathlib import Path

import numpy as np

from semmap_pp import world as wm
from semmap_pp.lattice.frame import build_frame, build_frame_from_classes
from semmap_pp.grid import load_map
from semmap_pp.model import load_model
from semmap_pp.target.posterior import Posterior

ROOT = Path(__file__).resolve().parents[1]
#: ``--tiny``: the arguments it sets
TINY = {"map": str(ROOT / "tests/data/maps/intel_corner.yaml"), "units": 3, "edits": 50, "full": 2}


def add_arguments(parser) -> None:
    parser.add_argument("--map", default=str(ROOT / "data/maps/ubremen-cartesium.yaml"))
    parser.add_argument("--units", type=int, default=20)
    parser.add_argument("--edits", type=int, default=5000)
    parser.add_argument("--full", type=int, default=30, help="number of full evaluations")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--tiny", action="store_true", help="a few edits on a small map (a check that it runs)")


def random_world(rng, classes, n, capacity, min_side, max_side=200):
    """``n`` rectangles inside the bounding box of the known cells, sides from ``max(min_side,
    40)`` up to ``max_side`` (or the box, when it is smaller)."""
    rows, cols = np.nonzero(classes != 1)
    r_lo, r_hi, c_lo, c_hi = rows.min(), rows.max(), cols.min(), cols.max()
    lo = max(min_side, 40)
    h_max, w_max = min(max_side, max(int(r_hi - r_lo), lo + 1)), min(max_side, max(int(c_hi - c_lo), lo + 1))
    w = wm.empty(capacity)
    for s in range(n):
        h = int(rng.integers(lo, h_max))
        wd = int(rng.integers(lo, w_max))
        r0 = int(rng.integers(r_lo, max(r_lo + 1, r_hi - h)))
        c0 = int(rng.integers(c_lo, max(c_lo + 1, c_hi - wd)))
        w = wm.add(w, s, (r0, c0, r0 + h, c0 + wd))
    return w


def edit_sequence(rng, world, n_edits, min_side):
    """Pre-drawn (slot, side, step, accept) one-wall moves that keep every side >= min_side."""
    out = []
    slots = wm.active_slots(world)
    for _ in range(n_edits):
        out.append((int(rng.choice(slots)), int(rng.integers(4)),
                    int(rng.choice([-5, -4, -3, -2, -1, 1, 2, 3, 4, 5])), bool(rng.random() < 0.5)))
    return out


def time_edits(posts, world, edits, min_side):
    """Time the same edits on several posteriors, interleaved edit by edit so that machine load
    affects all of them alike (the 4x/1x ratio is a paired comparison)."""
    trackers = [p.start(world) for p in posts]
    times = [[] for _ in posts]
    type_changes = 0
    h, w = posts[0].frame.shape
    for slot, side, step, accept in edits:
        r = list(trackers[0].world.rects[slot])
        r[side] += step
        if (r[2] - r[0] < min_side or r[3] - r[1] < min_side or r[0] < 0 or r[1] < 0
                or r[2] > h or r[3] > w):
            continue
        for k, tr in enumerate(trackers):
            nw = wm.replace(tr.world, slot, r)
            t0 = time.perf_counter()
            prop = tr.propose(nw, [slot])
            times[k].append(time.perf_counter() - t0)
            if k == 0:
                type_changes += int(np.any(prop.world.types != tr.world.types))
            if accept:
                tr.accept(prop)
    # the incremental value after all edits agrees with a full evaluation
    errs = []
    for p, tr in zip(posts, trackers):
        full = p.evaluate(tr.world).total
        errs.append(abs(tr.logp - full) / abs(full))
    return times, type_changes, errs


def run(args) -> dict:
    if args.tiny:
        for key, value in TINY.items():
            setattr(args, key, value)
    model = load_model()
    grid = load_map(args.map)
    frame0 = build_frame(grid, model)
    lattice = np.asarray(frame0.classes)
    rng = np.random.default_rng(args.seed)
    frame1 = build_frame_from_classes(lattice, grid.resolution, model, theta=0.0)
    # 4x: the 1x lattice tiled (too few cells are unknown around it to crop it again)
    frame4 = build_frame_from_classes(np.tile(np.asarray(frame1.classes), (2, 2)), grid.resolution,
                                      model, theta=0.0)
    c = frame1.cells
    world = random_world(rng, np.asarray(frame1.classes), args.units, model.prior.k_max, c.min_side)
    edits = edit_sequence(rng, world, args.edits, c.min_side)

    out = {"map": Path(args.map).name, "lattice": list(lattice.shape),
           "theta_deg": round(float(np.degrees(frame0.theta)), 3), "units": args.units}
    posts = {}
    for name, frame in (("1x", frame1), ("4x", frame4)):
        t0 = time.perf_counter()
        posts[name] = Posterior(frame, model)
        prep = time.perf_counter() - t0
        if not np.isfinite(posts[name].evaluate(world).logprior):
            raise SystemExit(f"bench likelihood: the {args.units}-unit world is outside the prior's "
                             f"support on the {name} lattice {list(frame.shape)}")
        full = []
        for _ in range(args.full):
            t0 = time.perf_counter()
            posts[name].evaluate(world)
            full.append(time.perf_counter() - t0)
        out[name] = {"lattice": list(frame.shape), "prepare_s": round(prep, 3),
                     "full_eval_ms_median": round(1e3 * statistics.median(full), 3)}
    times, type_changes, errs = time_edits([posts["1x"], posts["4x"]], world, edits, c.min_side)
    if not times[0]:
        raise SystemExit(f"bench likelihood: none of the {len(edits)} edits kept the world inside "
                         f"the {list(frame1.shape)} lattice: nothing was timed")
    for name, t, err in zip(("1x", "4x"), times, errs):
        out[name].update({
            "edit_us_median": round(1e6 * statistics.median(t), 2),
            "edit_us_p90": round(1e6 * float(np.percentile(t, 90)), 2),
            "edits_timed": len(t),
            "edits_with_type_change": type_changes,
            "incremental_vs_full_rel_err": err,
        })
    out["edit_ratio_4x_over_1x"] = round(out["4x"]["edit_us_median"] / out["1x"]["edit_us_median"], 3)
    out["targets"] = {"edit_us_median<=100": out["1x"]["edit_us_median"] <= 100,
                      "full_eval_ms<=20": out["1x"]["full_eval_ms_median"] <= 20,
                      "ratio_4x<=1.3": out["edit_ratio_4x_over_1x"] <= 1.3}
    return out
