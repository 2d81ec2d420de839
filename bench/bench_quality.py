"""Quality of the whole pipeline: synthetic truth, real-map CPR, ipa segmentation and typing.

``python bench/run.py quality --json [--subset synthetic|synthetic-wings|truth|surgery|real|ipa|types|stability|targets|all] [--floors N] [--budget B]``

Every map goes through :func:`semmap_pp.run.pipeline.run_map` with the model file's defaults (``--budget
model``), a shorter run (``--budget quick``) or the model's run capped at a number of seconds of
sampling per map (``--budget 30``: ``run_map(budget=...)``); per-map rows, the means and the published figures
(/work/shared/data/README.md) are printed, the JSON summary on the last line.

* **synthetic**: floors ``semmap_pp.synth.generate_floor(seed)`` for seeds ``0..N-1`` (rotations
  drawn by the generator), scored with :func:`semmap_pp.evaluate.score_world` against the floor's
  truth; CPR on the floor's map with the default ROI and with the building as ROI
  (:func:`building_roi`). Exterior units (world.json ``exterior``: free space seen outside the
  building) are not predictions of the building's units; ``unit_f1_with_exterior`` scores them as
  if they were. ``*_observed`` scores against the units the simulated robot saw
  (:func:`observed_truth`); ``*_either_l`` with each of the truth's L-shaped spaces cut whichever
  way W* cut it (:func:`semmap_pp.evaluate.score_world_either_l`; ``l_shapes_recut`` counts them);
  ``*_visible`` against what the map shows (:func:`visible_truth`: seen units, open doors, either
  cut of each L); ``errors`` is :func:`error_breakdown` (where unit F1 is lost), ``door_errors``
  :func:`door_breakdown` (where door F1 is lost); ``seen_shares`` the medians of world.json's
  ``seen_share`` and ``walls_seen_share`` by what the units match (:func:`seen_by_class`).
  ``--pool K`` runs the floors as maps of K times coarser cells (:func:`pooled_floor`);
  ``--resolution R`` has the generator render them at R metres per cell (the same seeds and
  buildings, scanned onto coarser or finer cells).
* **synthetic-wings**: floors of wings (``generate_floor(seed, wings=, wing_angle_deg=)``): two
  wings at 30 and at 45 degrees, three wings at angles drawn from the seed, beside the one-wing
  floors of the same seeds, each scored as the synthetic subset scores its floors (unit F1, door
  F1, types, CPR, rooms.png P/R by the ROSE2 protocol); ``groups`` holds each group's means and
  their difference from the Manhattan floors (:func:`bench_synthetic_wings`). ``--held-out`` runs
  the seeds from :data:`HELD_OUT_FIRST` on, which no setting was tuned on; ``--maps`` keeps groups.
* **truth**: the ceiling of the synthetic targets: the same floors with the seen true units as the
  world (:func:`truth_world`, walls aligned by :func:`semmap_pp.sampler.ascent.align_walls`), derived and
  scored as W* is (:func:`bench_truth`); ``--outside-from DIR`` adds the units outside the building
  of the W*s a synthetic run saved in DIR, to compare log posteriors inside the building.
* **surgery**: which of W*'s errors the target prefers (:func:`bench_surgery`; ``--wstars DIR``, the
  W*s of ``--subset synthetic --save DIR``): each missed or pieced seen true unit put in W*'s place,
  the walls aligned, the log posterior compared with W*'s aligned the same way.
* **targets**: synthetic, truth and real in one run, ending with issue 5's quality targets under every
  reading the benchmark measures (:func:`target_report`: the literal one, the floor's whole truth and
  the default ROI, then against what the map shows; the truth's own score beside each synthetic
  reading as its ceiling; printed as a table and in the JSON's ``target_report``). Any subset
  prints the rows it measured.
* **real**: ``data/maps/*.yaml`` of the repository (cartesium, intel), CPR with the default ROI, and
  the time to W*.
* **ipa**: the ten plans of ``/work/shared/data/ipa-segmentation`` (with ``--furniture`` their
  ``NAME_furnitures`` versions, furniture drawn in, scored against the same truth), loaded with the benchmark's own
  pixel rule (grey >= 250 free, anything else obstacle: ``free_thresh=0.0197``,
  ``occupied_thresh=0.0198``; the YAML's 0.65 / 0.03 would make grey obstacles unknown). Segments are
  *regions*: regions.png's, units joined where their connecting wall holds an open passage (one
  space cut in two units), see :func:`regions_of`. Precision / recall micro, published protocol and restricted.
* **real-gt**: the five real SLAM floors of ``bench/data/real-gt`` (ROSE2's evaluation maps, MIT
  licence: LICENSE-ROSE2 there) with their hand-drawn room truth. rooms.png is scored by the ROSE2
  protocol (:func:`semmap_pp.evaluate.protocol_scores`), and so, with the same code, are ROSE2's own
  published output (``rose2.png``) and regions.png cut to the map's free cells; per map and as means.
  ``--turn 15,30,45`` (or ``default``) runs the floors turned by those angles with their truth
  instead (``bench/turned_maps.py``: a map frame at another angle to the building), held out.
  ``--pool K`` runs them as maps of K times coarser cells (``bench/pooled_maps.py``: 0.1 m for
  K = 2), rooms.png scored at the floors' own cells against their own truth, held out.
* **partial**: two partial explorations of each real-gt floor (``bench/partial_maps.py``: the robot
  drove through the corridors and 30 % or 60 % of the rooms and saw the others only through their
  doors), rooms.png scored by the ROSE2 protocol on the cells the partial map saw. ROSE2's
  output exists for the full floors only. ``--held-out`` runs explorations of other seeds
  (:data:`HELD_OUT_FIRST` + 1 and + 2: other rooms entered), which no setting was tuned on.
* **types**: the five maps of ``/work/shared/data/ipa-types`` (same pixel rule), per-cell room vs
  corridor accuracy (:func:`semmap_pp.evaluate.type_accuracy`).

``--spread-best`` (any subset that runs the pipeline) scores, instead of W*, the best world of the
sample around W* (``[sampler] spread_draws``, off otherwise), polished as W* is, when it is higher
(:func:`spread_best`): what taking the sample's climb as W* would give; ``semmap map`` does not.

Missing data directories are skipped with a note. A map on which the pipeline fails with the
knowledge engine is run again without it (``knowledge`` in its row says so); a map that fails both
ways gets a row with its error message and is left out of the means. **Time to W\\*** is the wall time from the start of
sampling until the best chain's ``best_logp`` first reached its final value, clocked per draw through
``run_map``'s ``callback`` (start worlds and the final semantic map are not included).

``--tiny`` (:data:`TINY`: one synthetic floor, one chain of 2 + 4 draws of 10 kernels; the
synthetic subset unless ``--subset`` names another) is the check of tests/integration/test_bench_smoke.py
that the benchmark runs, not a measurement.
"""

from __future__ import annotations

import argparse
import dataclasses
import itertools
import json
import math
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
SHARED = Path("/work/shared/data")
IPA_FREE = dict(free_thresh=0.0197, occupied_thresh=0.0198)  # grey >= 250 free, else obstacle
PUBLISHED = {
    "cpr": {"ubremen-cartesium": 0.868, "intel-lab": 0.914},
    "rose2_real": {"ubremen-cartesium": (0.878, 0.896), "intel-lab": (0.866, 0.926),
                   "average_11_maps": (0.890, 0.939)},
    "bormann_real_average": {"morphological": (0.850, 0.823), "distance": (0.883, 0.798),
                             "voronoi": (0.859, 0.719)},
    "paper_minutes_per_map": 20,
}
TARGETS = {"synthetic_cpr": 0.95, "unit_f1": 0.9, "type_accuracy": 0.9, "door_f1": 0.85,
           "cartesium_cpr": 0.90, "intel_cpr": 0.93, "time_to_wstar_s": 60.0}
BUDGETS = {"model": {}, "quick": dict(chains=2, tune=10, draws=10, n_inner=50)}
# Every reading of a target that the benchmark measures, the literal one first (the floor's whole
# truth, the default ROI), then against what the map shows: (target key, reading, subset, key).
# The real maps' keys name a row (``map:key``); the synthetic ones a mean, whose ceiling is the
# truth subset's mean of the same key (the seen true units scored as W* is).
READINGS = (
    ("synthetic_cpr", "default ROI (the known map, closed)", "synthetic", "cpr"),
    ("synthetic_cpr", "the building as ROI (true units + 0.25 m)", "synthetic", "cpr_building"),
    ("unit_f1", "every true unit", "synthetic", "unit_f1"),
    ("unit_f1", "every true unit, either cut of each L", "synthetic", "unit_f1_either_l"),
    ("unit_f1", "the seen true units", "synthetic", "unit_f1_observed"),
    ("unit_f1", "what the map shows (seen units, either cut of each L)", "synthetic", "unit_f1_visible"),
    ("type_accuracy", "matched units", "synthetic", "type_accuracy"),
    ("door_f1", "every true door", "synthetic", "door_f1"),
    ("door_f1", "every true door, either cut of each L", "synthetic", "door_f1_either_l"),
    ("door_f1", "the doors of seen true units", "synthetic", "door_f1_observed"),
    ("door_f1", "what the map shows (open doors between seen units)", "synthetic", "door_f1_visible"),
    ("cartesium_cpr", "default ROI", "real", "ubremen-cartesium:cpr"),
    ("intel_cpr", "default ROI", "real", "intel-lab:cpr"),
    ("time_to_wstar_s", "cartesium, polish included", "real", "ubremen-cartesium:time_to_wstar_s"),
)
AT_MOST = {"time_to_wstar_s"}      # targets that are upper bounds
#: ``--tiny``: the arguments it sets
TINY = {"floors": 1, "first_floor": 1, "chains": 1, "cores": 1, "tune": 2, "draws": 4, "n_inner": 10,
        "quiet": True}


def _budget(text: str) -> str | float:
    """A preset name of :data:`BUDGETS` or seconds of sampling per map."""
    if text in BUDGETS:
        return text
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a preset {sorted(BUDGETS)} nor seconds: {text!r}") from None
    if not value > 0:
        raise argparse.ArgumentTypeError(f"seconds must be > 0, got {text!r}")
    return value


def _angles(text: str) -> tuple[float, ...]:
    """``--turn``'s angles: comma-separated degrees, or ``default`` (:data:`turned_maps.ANGLES`)."""
    if text.strip() == "default":
        import turned_maps
        return tuple(turned_maps.ANGLES)
    try:
        return tuple(float(t) for t in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"angles must be comma-separated degrees, got {text!r}") from None


def add_arguments(parser) -> None:
    parser.add_argument("--subset", default="all",
                        choices=["synthetic", "synthetic-wings", "truth", "surgery", "real", "real-gt", "partial", "wings", "ipa", "types", "stability",
                                 "targets", "all"])
    parser.add_argument("--floors", type=int, default=30, help="synthetic floors (seeds 0..N-1)")
    parser.add_argument("--seeds", default="0,1,2",
                        help="sampler seeds of --subset stability, comma-separated (default 0,1,2)")
    parser.add_argument("--first-floor", type=int, default=0, help="first synthetic seed")
    parser.add_argument("--held-out", action="store_true",
                        help=f"synthetic-wings: the held-out seeds ({HELD_OUT_FIRST} + --first-floor on); "
                             f"partial: explorations of seeds {HELD_OUT_FIRST} + 1, + 2")
    parser.add_argument("--turn", type=_angles, default=None, metavar="DEG[,DEG...]",
                        help="real-gt: the floors turned by these angles (degrees; turned_maps) "
                             "instead of as they are; 'default' for 15,30,45")
    parser.add_argument("--furniture", action="store_true",
                        help="ipa: the plans with furniture drawn in (NAME_furnitures.png), same truth")
    parser.add_argument("--resolution", type=float, default=0.05,
                        help="synthetic floors rendered at this many metres per cell (generate_floor)")
    parser.add_argument("--pool", type=int, default=1,
                        help="synthetic floors as maps of K times coarser cells (pooled_floor); real-gt: "
                             "the floors so (pooled_maps), rooms.png scored at their own cells")
    parser.add_argument("--budget", default="model", type=_budget,
                        help="run lengths: 'model' ([sampler]), 'quick', or seconds of sampling per map")
    parser.add_argument("--seed", type=int, default=0, help="sampler seed")
    parser.add_argument("--over-seeds", default=None,
                        help="run the subset once per sampler seed (comma-separated, e.g. 0,1,2): rows "
                             "carry it as sampler_seed, 'means' is the mean over the seeds of each seed's means, "
                             "'seed_sd' their standard deviation; one search's W* depends on its seed")
    for name in ("chains", "cores", "tune", "draws", "n-inner"):
        parser.add_argument(f"--{name}", type=int, default=None, help=f"override {name}")
    parser.add_argument("--anneal", type=float, default=None, help="override the burn-in temperature")
    parser.add_argument("--maps", default=None, help="comma-separated map names to keep (real/ipa/types)")
    parser.add_argument("--save", type=Path, default=None, help="write each W*'s world.json, labels.png and rooms.png here (DIR/MAP/)")
    parser.add_argument("--outside-from", type=Path, default=None,
                        help="truth subset: add the units lying mostly outside the building of the W*s "
                             "saved here (--subset synthetic --save DIR) to the seen truth")
    parser.add_argument("--wstars", type=Path, default=None,
                        help="surgery subset: the W*s saved here (--subset synthetic --save DIR)")
    parser.add_argument("--spread-best", action="store_true",
                        help="score the best world of the sample around W* ([sampler] spread_draws), "
                             "polished as W* is, instead of W* when it is higher (docs/sampler.md)")
    parser.add_argument("--calibration", action="store_true",
                        help="synthetic subsets: keep the sample around W* and score the posterior "
                             "marginals of W*'s units, types and doors against the truth (reliability "
                             "table, expected calibration error)")
    parser.add_argument("--quiet", action="store_true")
    parser.add_argument("--model", type=Path, default=None, help="model file (default models/default.toml)")
    parser.add_argument("--rules", type=Path, default=None, help="rule file (default rules/table3.lp)")
    parser.add_argument("--tiny", action="store_true",
                        help="one synthetic floor, very short runs (a check that it runs)")


# ------------------------------------------------------------------ helpers

def _settings(model, args):
    from semmap_pp.run.results import RunSettings
    over = dict(BUDGETS[args.budget]) if isinstance(args.budget, str) else {}
    for key in ("chains", "cores", "tune", "draws", "n_inner", "anneal"):
        v = getattr(args, key)
        if v is not None:
            over[key] = v
    if not (getattr(args, "spread_best", False) or getattr(args, "calibration", False)):
        over["spread_draws"] = 0    # W* is scored: the sample around it (the spread figures) is not needed
    return RunSettings.from_model(model, seed=args.seed, **over)


def _inputs_from_grid(grid, model, rules):
    from semmap_pp.evaluate import closing_radius_cells, default_roi
    from semmap_pp.lattice.tiles import building_frame
    from semmap_pp.run.inputs import Inputs
    frame = building_frame(grid, model)
    roi = default_roi(grid.classes, closing_radius_cells(model.evaluate.roi_closing_m, grid.resolution))
    return Inputs(grid, model, rules, frame, roi, "default")


def _run_or_record(args, inputs, settings, rows: list, row: dict, label: str):
    """``_run``'s ``(run, clock)``; or, when the run fails, ``row`` with the error appended to
    ``rows``, the failure logged under ``label``, and None."""
    try:
        return _run(inputs, settings, args.quiet, best=getattr(args, "spread_best", False))
    except MapFailed as exc:
        rows.append({**row, "error": str(exc)})
        _log(args, f"{label}: FAILED {exc}")
        return None


def time_to_best(run, clock) -> dict:
    """When W* was found (seconds from the call of ``run_map``).

    ``clock`` is ``[(seconds, chain, best_logp), ...]``, one entry per draw as the main process received
    it (the pipeline's per-draw ``callback``), and a last entry ``(seconds, None, log posterior of
    W*)`` when ``run_map`` returned. The sampled best is the best chain's last ``best_logp``; when W*'s
    polish (``[kernels] polish_rounds``) raised the log posterior above it, W* was found only when
    ``run_map`` returned, and that time is reported (``"polished": True``).
    """
    c = run.best_chain
    mine = [(t, lp) for t, ch, lp in clock if ch == c and lp == lp]
    if not mine:
        return {"seconds": None, "draw": None}
    final = max(lp for _, lp in mine)
    done = [(t, lp) for t, ch, lp in clock if ch is None]
    if done and done[-1][1] > final + 1e-6:
        return {"seconds": round(done[-1][0], 1), "draw": len(mine), "of": len(mine),
                "run_s": round(run.seconds, 1), "polished": True}
    for k, (t, lp) in enumerate(mine):
        if lp >= final - 1e-9:
            return {"seconds": round(t, 1), "draw": k, "of": len(mine), "run_s": round(run.seconds, 1),
                    "polished": False}
    return {"seconds": None, "draw": None}


SECONDS: list = [None]   # sampling budget in seconds per map (``--budget N``), set by :func:`run`


def _run(inputs, settings, quiet, best: bool = False):
    """``run_map`` and the per-draw clock ``[(seconds since the call, chain, best_logp)]``.

    The clock starts before ``run_map`` (start worlds included). A sampling failure is re-raised as
    :class:`MapFailed` so one map does not end the benchmark.
    """
    from semmap_pp.run import pipeline
    clock = []
    t0 = time.perf_counter()

    def tick(info):
        clock.append((time.perf_counter() - t0, info["chain"], info["best_logp"]))

    log = (lambda m: None) if quiet else (lambda m: print("   ", m, file=sys.stderr, flush=True))
    try:
        run = pipeline.run_map(inputs, settings, callback=tick, log=log, budget=SECONDS[0])
        run.notes.insert(0, "knowledge: on")
    except Exception as exc:  # noqa: BLE001 - a benchmark row, not a crash
        if inputs.rules is None:
            raise MapFailed(f"{type(exc).__name__}: {exc}") from exc
        # The knowledge engine failed on some world (see docs/quality.md): the map is run again
        # without knowledge (types from the geometry class), and the row says so.
        log(f"pipeline failed with knowledge ({type(exc).__name__}: {exc}); again without knowledge")
        clock.clear()
        t0 = time.perf_counter()
        try:
            run = pipeline.run_map(dataclasses.replace(inputs, rules=None), settings, callback=tick, log=log,
                                   budget=SECONDS[0])
        except Exception as exc2:  # noqa: BLE001
            raise MapFailed(f"{type(exc2).__name__}: {exc2}") from exc2
        run.notes.insert(0, f"knowledge: off (engine failed: {type(exc).__name__}: {str(exc)[:120]})")
    if best and settings.spread_draws > 0:    # --spread-best
        run = spread_best(run)
    clock.append((time.perf_counter() - t0, None, run.semantic.log_posterior))
    return run, clock


def spread_best(run):
    """``run`` with the best world of its sample around W* (``run.spread.best_world``), polished as
    W* is (``[kernels] polish_rounds`` of the ascent), in place of W* when that world is higher;
    otherwise ``run`` itself. ``semmap map`` never does this (W* is the search's, docs/sampler.md):
    the benchmark measures what taking it would give (``--spread-best``)."""
    from semmap_pp.sampler.ascent import polish
    from semmap_pp.sampler.kernels import data_from_frame
    from semmap_pp.semantic.semantic_map import semantic_map
    from semmap_pp.run.target_factory import run_target
    sp = run.spread
    if sp is None or sp.best_world is None or not sp.best_logp > sp.start_logp:
        return run
    inputs = run.inputs
    ks = inputs.model.kernels
    post = run_target(inputs)
    world = polish(post, sp.best_world, data_from_frame(inputs.frame, ks), ks.polish_rounds)
    sm = semantic_map(inputs.grid, inputs.frame, post, world, roi=inputs.roi)
    return dataclasses.replace(run, world=sm.world, semantic=sm)


class MapFailed(RuntimeError):
    """The pipeline failed on one map (the row records the message)."""


def regions_of(sm) -> tuple[np.ndarray, dict]:
    """Image-frame region labels and ``unit id -> region id``: regions.png's regions
    (:mod:`semmap_pp.semantic.regions`: units joined where their connecting wall holds an open
    passage, one space cut into two rectangles)."""
    from semmap_pp.semantic.regions import regions_image, unit_regions
    unit_region = unit_regions(sm)
    return regions_image(sm, unit_region).astype(np.int32), unit_region


def _mean(rows, key):
    vals = [r[key] for r in rows if r.get(key) is not None and not (isinstance(r[key], float) and math.isnan(r[key]))]
    return round(float(np.mean(vals)), 4) if vals else None


def _keep(name, args):
    return args.maps is None or any(k in name for k in args.maps.split(","))


def _log(args, msg):
    if not args.quiet:
        print(msg, file=sys.stderr, flush=True)


def _save(args, name, sm, extra=None):
    if args.save is None:
        return
    from semmap_pp.semantic.world_json import world_dict, write_labels_png, write_world_json
    out = args.save / name
    out.mkdir(parents=True, exist_ok=True)
    write_world_json(out / "world.json", world_dict(sm))
    write_labels_png(out / "labels.png", sm.labels_image)
    write_labels_png(out / "rooms.png", sm.rooms.labels)


def _r4(v):
    return round(float(v), 4) if v == v else None


def _door_f1(sc) -> float:
    dp, dr = sc.door_precision, sc.door_recall
    if dp == dp and dr == dr:
        return 2 * dp * dr / (dp + dr) if dp + dr > 0 else 0.0
    return 0.0 if dp == dp or dr == dr else math.nan


def observed_truth(truth: dict) -> dict:
    """The truth without the units the simulated robot never saw (``explored`` false: behind closed
    doors, every cell unknown in the map), and without their doors and adjacencies. No mapper can
    find such a unit; scoring against them caps recall (46 of the 453 units of floors 0..29)."""
    keep = {u["id"] for u in truth["units"] if u.get("explored", True)}
    out = dict(truth)
    out["units"] = [u for u in truth["units"] if u["id"] in keep]
    out["doors"] = [d for d in truth.get("doors", []) if set(d["units"]) <= keep]
    out["adjacency"] = [a for a in truth.get("adjacency", []) if set(a) <= keep]
    return out


def visible_truth(truth: dict) -> dict:
    """What the map shows of the truth: :func:`observed_truth` without the closed doors (the
    generator draws a closed door as wall, so the map holds nothing to find: 47 of the 412 doors
    of floors 0..29, 7 of them between seen units). Scored with either cut of each L
    (:func:`semmap_pp.evaluate.score_world_either_l`) as ``*_visible``."""
    out = observed_truth(truth)
    out["doors"] = [d for d in out["doors"] if d.get("open", True)]
    return out


def _overlaps(pred: dict, truth: dict, shape):
    """Cell counts of the predicted and true units' polygons: ``(inter, pred sizes, true sizes,
    IoU, outside)``, ``inter[i, j]`` the cells predicted unit ``i`` shares with true unit ``j`` and
    ``outside[i]`` whether unit ``i`` lies mostly outside the true units (:func:`_mostly_outside`)."""
    from semmap_pp.evaluate.truth import polygon_mask
    T = [polygon_mask(u["corners_px"], shape) for u in truth["units"]]
    P = [polygon_mask(u["vertices_px"], shape) for u in pred["units"]]
    union = np.any(T, axis=0) if T else np.zeros(shape, bool)
    inter = np.array([[np.count_nonzero(p & t) for t in T] for p in P], dtype=np.int64).reshape(len(P), len(T))
    ps = np.array([p.sum() for p in P], dtype=np.int64)
    ts = np.array([t.sum() for t in T], dtype=np.int64)
    iou = inter / np.maximum(1, ps[:, None] + ts[None, :] - inter)
    outside = [_mostly_outside(p, union) for p in P]
    return inter, ps, ts, iou, outside


def unit_classes(pred: dict, truth: dict, shape, iou_min: float = 0.5):
    """The error class of every predicted and every true unit (``None`` when matched), as
    :func:`error_breakdown` counts them: ``(pred classes, true classes, inter, pred sizes, true
    sizes)`` with :func:`_overlaps`' counts."""
    inter, ps, ts, iou, outside = _overlaps(pred, truth, shape)
    n_p, n_t = inter.shape
    matched_p = iou.max(axis=1) >= iou_min if n_t else np.zeros(n_p, bool)
    matched_t = iou.max(axis=0) >= iou_min if n_p else np.zeros(n_t, bool)
    pc: list = [None] * n_p
    for i in range(n_p):
        if matched_p[i]:
            continue
        holds = np.flatnonzero(inter[i] > 0.3 * ts)
        inside = np.flatnonzero(inter[i] > 0.7 * ps[i])
        if outside[i]:
            pc[i] = "outside_building"
        elif len(holds) >= 2:
            pc[i] = "spans"
        elif len(inside):
            pc[i] = "piece_of_matched" if matched_t[inside[0]] else "piece_of_missed"
        else:
            pc[i] = "other"
    tc: list = [None] * n_t
    for j in range(n_t):
        if matched_t[j]:
            continue
        i = int(inter[:, j].argmax()) if n_p else -1
        if not truth["units"][j].get("explored", True):
            tc[j] = "unseen"
        elif np.count_nonzero((inter[:, j] > 0.2 * ps) & (inter[:, j] > 0.1 * ts[j])) >= 2:
            tc[j] = "cut"
        elif i >= 0 and inter[i, j] > 0.5 * ts[j] and np.any(np.delete(inter[i] > 0.3 * ts, j)):
            tc[j] = "merged"
        elif i >= 0 and inter[i, j] > 0.8 * ps[i]:
            tc[j] = "partial"
        else:
            tc[j] = "other"
    return pc, tc, inter, ps, ts


def error_breakdown(pred: dict, truth: dict, shape, iou_min: float = 0.5) -> dict:
    """Where unit F1 is lost, each unmatched unit in exactly one class (:func:`unit_classes`).

    Predicted units matching no true unit (IoU < ``iou_min`` with every one), ``pred_unmatched``:

    * ``pred_outside_building``: lying mostly (> half their cells) outside the building (ray fans
      seen through windows and exits);
    * ``pred_spans``: holding > 30 % of each of two or more true units (rooms merged);
    * ``pred_piece_of_matched``: > 70 % inside one true unit that another predicted unit matches
      (a room or corridor in pieces, one of which matches: a cut at furniture, a stepped wall);
    * ``pred_piece_of_missed``: > 70 % inside one true unit that no predicted unit matches (the
      pieces of a cut room, the seen part of a partly seen one);
    * ``pred_other``: the rest (straddling a wall).

    True units matched by none, ``true_missed``:

    * ``true_missed_unseen``: never seen (``explored`` false);
    * ``true_missed_cut``: cut into pieces (>= 2 predicted units each holding > 20 % of their own
      cells and > 10 % of the true unit's);
    * ``true_missed_merged``: most of it (> half) lies in one predicted unit that also holds > 30 %
      of another true unit;
    * ``true_missed_partial``: the predicted unit holding most of it lies > 80 % inside it but
      covers less than half of it (a room seen only through its door, covered where it was seen);
    * ``true_missed_other``: the rest.
    """
    pc, tc, *_ = unit_classes(pred, truth, shape, iou_min)
    out = {"pred_unmatched": sum(c is not None for c in pc)}
    out |= {f"pred_{k}": pc.count(k) for k in ("outside_building", "spans", "piece_of_matched",
                                               "piece_of_missed", "other")}
    out["true_missed"] = sum(c is not None for c in tc)
    out |= {f"true_missed_{k}": tc.count(k) for k in ("unseen", "cut", "merged", "partial", "other")}
    return out


def door_breakdown(pred: dict, truth: dict, score) -> dict:
    """Where door F1 is lost, given ``score`` (:func:`semmap_pp.evaluate.score_world` of ``pred``
    against ``truth``): the predicted doors that match none (``door_fp``) split into those touching
    a unit that matches no true unit (``door_fp_unmatched_unit``) and those between two matched
    units (``door_fp_matched_pair``: no true door there, or too far from it); the true doors
    found by none (``door_fn``) into those touching a true unit no unit matches
    (``door_fn_unmatched_unit``, of which ``..._closed`` the generator drew closed: wall in the
    map) and those between two matched units (``door_fn_matched_pair``);
    ``door_closed_between_matched`` counts the closed true doors between two matched units (no
    detector finds them)."""
    pred_doors, true_doors = pred.get("doors", []), truth.get("doors", [])
    tp = int(round(score.door_recall * len(true_doors))) if true_doors else 0
    matched_true = set(score.matches.values())
    fp_unmatched = sum(any(u not in score.matches for u in d["units"]) for d in pred_doors)
    fn_unmatched = [d for d in true_doors if any(u not in matched_true for u in d["units"])]
    fn_unmatched_closed = sum(not d.get("open", True) for d in fn_unmatched)
    pair_closed = sum(not d.get("open", True) for d in true_doors
                      if all(u in matched_true for u in d["units"]))
    out = {"door_tp": tp, "door_fp": len(pred_doors) - tp, "door_fp_unmatched_unit": fp_unmatched,
           "door_fp_matched_pair": len(pred_doors) - tp - fp_unmatched,
           "door_fn": len(true_doors) - tp, "door_fn_unmatched_unit": len(fn_unmatched),
           "door_fn_unmatched_unit_closed": fn_unmatched_closed,
           "door_fn_matched_pair": len(true_doors) - tp - len(fn_unmatched),
           "door_closed_between_matched": pair_closed}
    return out


def route_agreement(pred: dict, truth: dict, matches: dict, resolution: float) -> dict:
    """Whether W*'s doors and passages lead where the building's do (what a planner asks of the
    map): for every two true units that both match a unit of W* (``matches``: W* id -> true id),
    the shortest route between the two true units' centres through the truth's open doors and open
    walls (``open_boundaries``), and the shortest between the matched units' centres through W*'s
    doors and passages (:meth:`semmap_pp.plans.places.Places.route`; both in the image's pixel frame,
    scaled to metres). ``route_pairs`` counts the pairs the truth joins, ``route_found`` those W*
    joins too (their ratio is ``route_recall``), ``route_extra`` the pairs W* joins and the truth
    does not, and ``route_ratios`` W*'s length over the truth's, per pair both join."""
    from semmap_pp.plans.places import places_from_doc

    def doc(units, doors, passages):
        return {"units": units, "doors": doors, "passages": passages}

    def unit(uid, kind, corners):
        return {"id": uid, "type": kind, "vertices_m": (np.asarray(corners, float) * resolution).tolist()}

    def opening(k, a, b, centre):
        return {"id": k, "units": [a, b], "center_m": (np.asarray(centre, float) * resolution).tolist(),
                "width_m": 1.0}

    p = places_from_doc(doc([unit(u["id"], u["type"], u["vertices_px"]) for u in pred["units"]],
                            [opening(d["id"], *d["units"], d["center_px"]) for d in pred["doors"]],
                            [opening(d["id"], *d["units"], d["center_px"]) for d in pred.get("passages", [])]))
    true_units = {u["id"]: u for u in truth["units"]}
    open_walls = []
    for k, (a, b) in enumerate(truth.get("open_boundaries", []), 1):   # the centre of the shared edge
        ca, cb = np.asarray(true_units[a]["corners_px"], float), np.asarray(true_units[b]["corners_px"], float)
        lo, hi = np.maximum(ca.min(axis=0), cb.min(axis=0)), np.minimum(ca.max(axis=0), cb.max(axis=0))
        open_walls.append(opening(k, a, b, (lo + hi) / 2))
    t = places_from_doc(doc([unit(u["id"], u["type"], u["corners_px"]) for u in truth["units"]],
                            [opening(k, *d["units"], d["center_px"])
                             for k, d in enumerate(truth.get("doors", []), 1) if d.get("open", True)],
                            open_walls))
    pairs = found = extra = 0
    ratios = []
    matched = sorted(matches.items(), key=lambda m: m[1])
    for (pa, ta), (pb, tb) in itertools.combinations(matched, 2):
        rt = t.route(t.unit(str(ta)), t.unit(str(tb)))
        rp = p.route(p.unit(str(pa)), p.unit(str(pb)))
        pairs += rt is not None
        found += rt is not None and rp is not None
        extra += rt is None and rp is not None
        if rt is not None and rp is not None and rt.length_m > 0:
            ratios.append(rp.length_m / rt.length_m)
    return {"route_pairs": pairs, "route_found": found, "route_extra": extra, "route_ratios": ratios}


def building_roi(truth: dict, shape, default: np.ndarray, resolution: float, margin_m: float = 0.25):
    """The building as region of interest: the union of the true units (every one, seen or not),
    grown by ``margin_m`` to hold their walls, within the default ROI. The analogue of the paper's
    hand-drawn ROI around the building: ray fans seen through windows and exits lie outside it."""
    from scipy import ndimage

    from semmap_pp.evaluate.truth import polygon_mask
    inside = np.zeros(shape, bool)
    for u in truth["units"]:
        inside |= polygon_mask(u["corners_px"], shape)
    r = max(1, int(round(margin_m / resolution)))
    return ndimage.binary_dilation(inside, structure=np.ones((2 * r + 1, 2 * r + 1), bool)) & default


# ------------------------------------------------------------------ subsets

def _scaled_px(value, k: int):
    """``value`` (a truth document or part of it) with every ``*_px`` coordinate divided by ``k``."""
    if isinstance(value, dict):
        return {key: (np.divide(v, k).tolist() if key.endswith("_px") else _scaled_px(v, k))
                for key, v in value.items()}
    if isinstance(value, list):
        return [_scaled_px(v, k) for v in value]
    return value


def pooled_floor(floor, k: int):
    """``floor`` as a map of ``k`` times coarser cells: each k x k block of its classes is one cell,
    occupied when any of the block is, free when at least half of it is, else unknown (a coarser
    occupancy grid of the same scans); its truth's pixel coordinates divided by ``k``, its width,
    height and resolution changed to match. ``k = 1`` returns ``floor``.

    >>> import numpy as np, dataclasses
    >>> from semmap_pp.synth import Floor
    >>> c = np.array([[0, 0, 2, 1], [0, 1, 1, 1]], np.uint8)
    >>> f = Floor(image=c, classes=c, resolution=0.05, truth={"units": [{"corners_px": [[2, 0]]}]},
    ...           truth_labels=c.astype(np.uint16), origin=(0, 0, 0), poses_px=np.zeros((0, 2)))
    >>> g = pooled_floor(f, 2)
    >>> g.classes.tolist(), g.resolution, g.truth["units"][0]["corners_px"]
    ([[0, 2]], 0.1, [[1.0, 0.0]])
    """
    if k == 1:
        return floor
    import pooled_maps
    classes = pooled_maps.pool_classes(floor.classes, k)
    h, w = classes.shape
    truth = _scaled_px(floor.truth, k) | {"resolution": floor.resolution * k, "width": w, "height": h}
    return dataclasses.replace(floor, classes=classes, image=floor.image[:h * k:k, :w * k:k],
                               truth_labels=floor.truth_labels[:h * k:k, :w * k:k],
                               resolution=floor.resolution * k, truth=truth, poses_px=floor.poses_px / k)


def _floor(seed: int, model, rules, pool: int = 1, resolution: float = 0.05, **kind):
    """Synthetic floor ``seed`` rendered at ``resolution`` (then pooled ``pool`` x ``pool``), its
    grid and the pipeline's inputs for it (default ROI); ``kind``: more arguments of
    ``generate_floor`` (``wings``, ``wing_angle_deg``)."""
    from semmap_pp.grid import OccupancyGrid
    from semmap_pp.synth import generate_floor
    floor = pooled_floor(generate_floor(seed, resolution=resolution, **kind), pool)
    grid = OccupancyGrid(floor.classes, np.zeros(floor.classes.shape, np.float32), floor.resolution,
                         source=Path(f"synth-{seed}"))
    return floor, grid, _inputs_from_grid(grid, model, rules)


def _floor_scores(floor, sm, pred: dict):
    """The scores W* and the truth ceiling share: ``(row fields, score against the truth, score
    against the seen truth)``."""
    from semmap_pp.evaluate import cpr, score_world, score_world_either_l
    se, sc, recut = score_world_either_l(pred, floor.truth, shape=floor.classes.shape,
                                         resolution=floor.resolution)      # sc: the strict score
    so = score_world(pred, observed_truth(floor.truth), shape=floor.classes.shape,
                     resolution=floor.resolution)
    sv = score_world_either_l(pred, visible_truth(floor.truth), shape=floor.classes.shape,
                              resolution=floor.resolution)[0]
    cpr_building = cpr(floor.classes, sm.states_image, building_roi(floor.truth, floor.classes.shape,
                                                                   sm.roi, floor.resolution))[0]
    fields = {"cpr": round(sm.cpr, 4), "cpr_building": _r4(cpr_building), "unit_f1": round(sc.unit_f1, 4),
              "unit_f1_observed": round(so.unit_f1, 4), "door_f1_observed": _r4(_door_f1(so)),
              "unit_f1_either_l": round(se.unit_f1, 4), "type_accuracy_either_l": _r4(se.type_accuracy),
              "door_f1_either_l": _r4(_door_f1(se)), "l_shapes": len(floor.truth.get("l_shapes", [])),
              "l_shapes_recut": len(recut), "unit_f1_visible": round(sv.unit_f1, 4),
              "type_accuracy_visible": _r4(sv.type_accuracy), "door_f1_visible": _r4(_door_f1(sv))}
    return fields, sc, so


def seen_by_class(pred: dict, truth: dict, matches: dict) -> dict:
    """``(seen_share, walls_seen_share)`` of W*'s units (world.json) by what they match: a true
    room the robot drove into or only glimpsed ("entered room", "glimpsed room", likewise for the
    other types), "unmatched", and "exterior" for the exterior units."""
    true = {u["id"]: u for u in truth["units"]}
    out: dict = {}
    for u in pred["units"]:
        t = true.get(matches.get(u["id"]))
        key = "unmatched" if t is None else f"{'entered' if t.get('entered') else 'glimpsed'} {t['type']}"
        out.setdefault(key, []).append((u["seen_share"], u["walls_seen_share"]))
    for e in pred.get("exterior", []):
        out.setdefault("exterior", []).append((e["seen_share"], e["walls_seen_share"]))
    return out


def room_truth(truth_labels, l_shapes=()) -> np.ndarray:
    """The synthetic truth's rooms: its units' labels, the two rectangles of each L-shaped room
    (``truth.json``'s ``l_shapes``, pairs of unit ids) one room under the first one's id. The
    generator draws an L room as two units with no wall between them; a room segmentation, as a
    person draws it, has one room there.

    >>> room_truth(np.array([[1, 2, 3]]), [[1, 2]]).tolist()
    [[1, 1, 3]]
    """
    truth = np.asarray(truth_labels).astype(np.int64)
    lut = np.arange(int(truth.max(initial=0)) + 1)
    for a, b in l_shapes:
        if max(a, b) < lut.size:
            lut[lut == lut[b]] = lut[a]
    return lut[truth]


def _rooms_vs_truth(sm, truth_labels, l_shapes=()) -> dict:
    """rooms.png against the synthetic truth's rooms (:func:`room_truth`: its units, an L-shaped
    room's two one room; its free cells; the ROSE2 protocol), and its rooms seen through a door
    that lie mostly outside every true unit (fans outside the building taken for rooms)."""
    from semmap_pp.cells import FREE
    from semmap_pp.evaluate import protocol_scores
    truth = room_truth(truth_labels, l_shapes)
    if truth.shape != sm.grid.classes.shape:
        return {}
    lab = sm.rooms.labels
    sc = protocol_scores(np.where(sm.grid.classes == FREE, truth, 0), lab)
    outside = sum(1 for r in sm.rooms.rooms if r.seen_through_door and (truth[lab == r.id] > 0).mean() <= 0.5)
    return {"rooms_precision": round(sc.precision, 4), "rooms_recall": round(sc.recall, 4),
            "rooms_outside": outside}


def _recall_by_wing(truth: dict, matches: dict) -> dict:
    """A floor of wings' unit recall wing by wing (``"0"``: the link corridors); ``{}`` for a
    one-wing floor."""
    if "wings" not in truth:
        return {}
    found = set(matches.values())
    out = {}
    for u in truth["units"]:
        n, k = out.get(str(u["wing"]), (0, 0))
        out[str(u["wing"])] = (n + 1, k + (u["id"] in found))
    return {"unit_recall_by_wing": {w: round(k / n, 4) for w, (n, k) in sorted(out.items())}}


def _calibration_claims(run, pred: dict, floor) -> dict:
    """The posterior's claims about W* on a synthetic floor and whether the truth bears them out
    (:func:`semmap_pp.evaluate.calibration.posterior_claims`), from the sample around W* as
    ``semmap map`` writes them into world.json."""
    from semmap_pp.evaluate import score_world
    from semmap_pp.evaluate.calibration import posterior_claims
    from semmap_pp.outputs.write import N_SAMPLED_WORLDS, posterior_doc
    from semmap_pp.run.spread import posterior_worlds
    doc = posterior_doc(pred, run, posterior_worlds(run, N_SAMPLED_WORLDS))
    sc = score_world(doc, floor.truth, shape=floor.classes.shape, resolution=floor.resolution)
    return posterior_claims(doc, floor.truth, sc)


def bench_synthetic(args, model, rules, floors=None) -> dict:
    """The synthetic subset; ``floors``: ``[(group, seed, generate_floor arguments)]`` instead of
    the one-wing floors of seeds ``first_floor ..`` (rows then carry their ``group``)."""
    from semmap_pp.evaluate.calibration import calibration_summary
    from semmap_pp.evaluate import score_world
    from semmap_pp.semantic.world_json import world_dict
    rows, claims = [], []
    seen = {}   # class of unit -> [(seen_share, walls_seen_share)]
    skipped = []     # floors of a group that the generator cannot lay out
    if floors is None:
        floors = [(None, s, {}) for s in range(args.first_floor, args.first_floor + args.floors)]
    for group, seed, kind in floors:
        t0 = time.perf_counter()
        try:
            floor, grid, inputs = _floor(seed, model, rules, args.pool, args.resolution, **kind)
        except RuntimeError as exc:      # wings that would collide at that angle: no such floor
            if group is None:
                raise
            skipped.append({"group": group, "seed": seed, "reason": str(exc)})
            _log(args, f"{group} {seed:3d}: skipped, {exc}")
            continue
        settings = _settings(model, args)
        label = f"synth {seed:3d}" if group is None else f"{group} {seed:3d}"
        ran = _run_or_record(args, inputs, settings, rows, {"seed": seed} | (
            {} if group is None else {"group": group}), label)
        if ran is None:
            continue
        run, clock = ran
        sm = run.semantic
        pred = world_dict(sm)
        shared, sc, so = _floor_scores(floor, sm, pred)
        door_f1 = _door_f1(sc)
        # exterior units counted as predicted units too (what unit F1 would be without the flag)
        with_ext = dict(pred, units=pred["units"] + [
            {"id": 100000 + e["id"], "type": "other", "vertices_px": e["vertices_px"]}
            for e in pred.get("exterior", [])])
        sx = score_world(with_ext, floor.truth, shape=floor.classes.shape, resolution=floor.resolution)
        dp, dr = sc.door_precision, sc.door_recall
        row = {"seed": seed, **({} if group is None else {"group": group}), "rotation": round(float(floor.truth.get("rotation_deg", math.nan)), 1)
               if isinstance(floor.truth.get("rotation_deg"), (int, float)) else None,
               "shape": list(floor.classes.shape), "true_units": len(floor.truth["units"]),
               "units": len(sm.unit_ids), "exterior": len(sm.exterior_ids),
               "log_posterior": round(float(sm.log_posterior), 1),
               **shared,
               "type_accuracy": round(sc.type_accuracy, 4) if sc.type_accuracy == sc.type_accuracy else None,
               "door_f1": round(door_f1, 4) if door_f1 == door_f1 else None,
               "door_p": round(dp, 4) if dp == dp else None, "door_r": round(dr, 4) if dr == dr else None,
               "unit_f1_with_exterior": round(sx.unit_f1, 4),
               **_rooms_vs_truth(sm, floor.truth_labels, floor.truth.get("l_shapes", ())),
               **_recall_by_wing(floor.truth, sc.matches),
               "observed_units": len(observed_truth(floor.truth)["units"]),
               "type_accuracy_observed": _r4(so.type_accuracy),
               "errors": error_breakdown(pred, floor.truth, floor.classes.shape),
               "door_errors": door_breakdown(pred, floor.truth, sc),
               "routes": route_agreement(pred, floor.truth, sc.matches, floor.resolution),
               "seconds": round(time.perf_counter() - t0, 1), "knowledge": run.notes[0]}
        rows.append(row)
        if getattr(args, "calibration", False):
            claims.append(_calibration_claims(run, pred, floor))
        for k, v in seen_by_class(pred, floor.truth, sc.matches).items():
            seen.setdefault(k, []).extend(v)
        _save(args, f"synth-{seed}" if group is None else f"{group}-{seed}", sm)
        _log(args, f"{label}: {row['units']:3d}/{row['true_units']:3d} units  CPR {row['cpr']:.3f} (building {row['cpr_building']})  "
                   f"F1 {row['unit_f1']:.3f} (seen {row['unit_f1_observed']:.3f}, either L {row['unit_f1_either_l']:.3f}, visible {row['unit_f1_visible']:.3f})  types {row['type_accuracy']}  "
                   f"doors {row['door_f1']} (seen {row['door_f1_observed']}, visible {row['door_f1_visible']})  "
                   f"{row['seconds']} s")
    means = {k: _mean(rows, k) for k in ("cpr", "cpr_building", "unit_f1", "unit_f1_with_exterior",
                                         "type_accuracy", "door_f1", "unit_f1_observed",
                                         "type_accuracy_observed", "door_f1_observed", "unit_f1_either_l",
                                         "type_accuracy_either_l", "door_f1_either_l", "unit_f1_visible",
                                         "type_accuracy_visible", "door_f1_visible", "rooms_precision",
                                         "rooms_recall", "seconds")}
    errors = {k: sum(r["errors"][k] for r in rows if "errors" in r)
              for k in next((r["errors"] for r in rows if "errors" in r), {})}
    door_errors = {k: sum(r["door_errors"][k] for r in rows if "door_errors" in r)
                   for k in next((r["door_errors"] for r in rows if "door_errors" in r), {})}
    errors |= {"pred_units": sum(r["units"] for r in rows if "units" in r),
               "pred_exterior": sum(r.get("exterior", 0) for r in rows),
               "rooms_outside": sum(r.get("rooms_outside", 0) for r in rows),
               "true_units": sum(r["true_units"] for r in rows if "true_units" in r)}
    routes = [r["routes"] for r in rows if "routes" in r]
    ratios = np.concatenate([r["route_ratios"] for r in routes]) if routes else np.zeros(0)
    for r in routes:
        r["route_ratios"] = len(r["route_ratios"])      # the rows keep the count, the summary the spread
    route_pairs, route_found = sum(r["route_pairs"] for r in routes), sum(r["route_found"] for r in routes)
    route_summary = {"pairs": route_pairs, "found": route_found,
                     "recall": round(route_found / route_pairs, 4) if route_pairs else None,
                     "extra": sum(r["route_extra"] for r in routes),
                     "length_ratio_median": round(float(np.median(ratios)), 4) if ratios.size else None,
                     "length_ratio_p90": round(float(np.percentile(ratios, 90)), 4) if ratios.size else None,
                     "length_ratio_over_1_5": int((ratios > 1.5).sum())}
    seen_shares = {k: {"units": len(v), "interior_median": round(float(np.median([a for a, _ in v])), 2),
                       "walls_median": round(float(np.median([b for _, b in v])), 2)}
                   for k, v in sorted(seen.items())}
    return {"rows": rows, "means": means, "errors": errors, "door_errors": door_errors,
            **({"calibration": calibration_summary(claims)} if claims else {}),
            "routes": route_summary, "seen_shares": seen_shares, **({"skipped": skipped} if skipped else {}),
            "targets": {k: TARGETS[k] for k in ("unit_f1", "type_accuracy", "door_f1")} | {
                "cpr": TARGETS["synthetic_cpr"]}}


def lattice_rect(frame, corners_px) -> tuple:
    """The lattice cell box enclosing a polygon given in the pixel frame (the inverse of
    :meth:`semmap_pp.lattice.frame.Frame.rect_vertices_px`, rounded: :meth:`~semmap_pp.lattice.frame.Frame.rect_from_vertices_px`)."""
    return frame.rect_from_vertices_px(corners_px)[0]


def polygons_world(frame, polygons, capacity: int):
    """The polygons (pixel frame) as a world of ``capacity`` slots on ``frame``'s lattice, each as
    :func:`lattice_rect`."""
    from semmap_pp import world as wm
    if len(polygons) > capacity:
        raise ValueError(f"{len(polygons)} units, world capacity {capacity}")
    w = wm.empty(capacity)
    for slot, corners in enumerate(polygons):
        w = wm.add(w, slot, lattice_rect(frame, corners))
    return w


def truth_world(frame, truth: dict, capacity: int, extra=()):
    """The seen true units of a synthetic floor as a world on ``frame``'s lattice (units the robot
    never saw left out), plus the polygons ``extra`` (pixel frame), each as :func:`lattice_rect`."""
    return polygons_world(frame, [u["corners_px"] for u in observed_truth(truth)["units"]] + list(extra),
                          capacity)


def kernel_data(inputs, model):
    """The kernels' data of ``inputs``' lattice with the model's ``[kernels]`` settings (what
    :func:`semmap_pp.sampler.ascent.align_walls` needs)."""
    from semmap_pp.sampler.kernels import data_from_frame
    return data_from_frame(inputs.frame, model.kernels)


def outside_units(pred: dict, truth: dict, shape) -> list:
    """The polygons (pixel frame) of the predicted units and exterior units of ``pred`` lying mostly
    (more than half their cells) outside every true unit: W*'s cover of the space seen outside
    the building."""
    from semmap_pp.evaluate.truth import polygon_mask
    inside = np.zeros(shape, bool)
    for u in truth["units"]:
        inside |= polygon_mask(u["corners_px"], shape)
    out = []
    for u in pred["units"] + pred.get("exterior", []):
        if _mostly_outside(polygon_mask(u["vertices_px"], shape), inside):
            out.append(u["vertices_px"])
    return out


def _mostly_outside(mask: np.ndarray, inside: np.ndarray) -> bool:
    """More than half the cells of ``mask`` lie outside ``inside`` (the true units' union)."""
    return bool(np.count_nonzero(mask & ~inside) > 0.5 * np.count_nonzero(mask))


def bench_truth(args, model, rules) -> dict:
    """The ceiling of the synthetic targets: each floor's seen true units as the world, their walls
    set on the lattice's best positions by the ascent's wall moves (:func:`semmap_pp.sampler.ascent.align_walls`,
    no unit added, removed, merged or cut), types assigned by the full target, and everything
    derived and scored exactly as W* is in :func:`bench_synthetic`. What a mapper that found every
    seen unit would score: unit recall is capped by the units never seen, and CPR by what the
    building's units leave unexplained (free space seen outside the building through windows
    and exits lies in the default ROI). ``log_posterior`` is the aligned truth's, to compare with
    W*'s (a higher W* means the target prefers W* to the truth). With ``--outside-from DIR`` (the
    saved W*s of ``--subset synthetic --save DIR``) W*'s units over the space outside the building
    (:func:`outside_units`) join the seen truth before the walls are aligned, so that the two log
    posteriors differ only inside the building; rows then carry W*'s log posterior too."""
    from semmap_pp.sampler.ascent import align_walls
    from semmap_pp.semantic.world_json import world_dict
    from semmap_pp.semantic.semantic_map import semantic_map
    from semmap_pp.run.target_factory import run_target
    rows = []
    for seed in range(args.first_floor, args.first_floor + args.floors):
        t0 = time.perf_counter()
        floor, grid, inputs = _floor(seed, model, rules, args.pool, args.resolution)
        post = run_target(inputs)
        data = kernel_data(inputs, model)
        wstar = (json.loads((args.outside_from / f"synth-{seed}" / "world.json").read_text())
                 if args.outside_from else None)
        extra = outside_units(wstar, floor.truth, floor.classes.shape) if wstar else []
        start = truth_world(inputs.frame, floor.truth, model.prior.k_max, extra)
        world = align_walls(post, start, data)
        sm = semantic_map(grid, inputs.frame, post, world, roi=inputs.roi)
        shared, sc, _ = _floor_scores(floor, sm, world_dict(sm))
        row = {"seed": seed, "true_units": len(floor.truth["units"]), "units": len(sm.unit_ids),
               "exterior": len(sm.exterior_ids), "log_posterior": round(float(sm.log_posterior), 1),
               **shared, "type_accuracy": _r4(sc.type_accuracy), "door_f1": _r4(_door_f1(sc)),
               "seconds": round(time.perf_counter() - t0, 1)}
        if wstar:
            row |= {"outside_units": len(extra), "wstar_log_posterior": wstar["log_posterior"]}
        rows.append(row)
        _save(args, f"truth-{seed}", sm)
        _log(args, f"truth {seed:3d}: {row['units']:3d}/{row['true_units']:3d} units  CPR {row['cpr']:.3f} "
                   f"(building {row['cpr_building']})  F1 {row['unit_f1']:.3f} (seen {row['unit_f1_observed']})  "
                   f"types {row['type_accuracy']}  doors {row['door_f1']} (seen {row['door_f1_observed']})  "
                   f"log p {row['log_posterior']}")
    keys = ("cpr", "cpr_building", "unit_f1", "unit_f1_observed", "type_accuracy", "door_f1",
            "door_f1_observed", "unit_f1_either_l", "type_accuracy_either_l", "door_f1_either_l",
            "unit_f1_visible", "type_accuracy_visible", "door_f1_visible", "seconds")
    out = {"rows": rows, "means": {k: _mean(rows, k) for k in keys}}
    if args.outside_from:
        diff = [r["log_posterior"] - r["wstar_log_posterior"] for r in rows if "wstar_log_posterior" in r]
        out["truth_minus_wstar"] = {"higher": sum(d > 0.05 for d in diff), "equal": sum(abs(d) <= 0.05 for d in diff),
                                    "lower": sum(d < -0.05 for d in diff)}
    return out


def surgery_clusters(pred: dict, truth: dict, shape, iou_min: float = 0.5) -> list:
    """The local repairs :func:`bench_surgery` scores: for each seen true unit that no predicted
    unit matches, and each one holding an unmatched piece (:func:`unit_classes`), ``(true unit,
    its class, predicted units to remove, true units to add)`` (indices into ``pred["units"]`` and
    ``truth["units"]``). Removed: the predicted units with > 20 % of their cells in the true unit;
    added: it and every other seen true unit one of those holds > 30 % of (a merged neighbour);
    then also removed every predicted unit lying mostly (> 50 %) in an added one."""
    pc, tc, inter, ps, ts = unit_classes(pred, truth, shape, iou_min)
    seen = [u.get("explored", True) for u in truth["units"]]
    targets = [(j, c) for j, c in enumerate(tc) if c not in (None, "unseen")]
    for i, c in enumerate(pc):
        if c == "piece_of_matched":
            j = int(inter[i].argmax())
            if all(j != t for t, _ in targets):
                targets.append((j, "holds_piece"))
    out = []
    for j, c in targets:
        remove = {i for i in range(len(ps)) if inter[i, j] > 0.2 * ps[i]}
        add = {j} | {k for i in remove for k in range(len(ts)) if seen[k] and inter[i, k] > 0.3 * ts[k]}
        remove |= {i for i in range(len(ps)) for k in add if inter[i, k] > 0.5 * ps[i]}
        out.append((j, c, sorted(remove), sorted(add)))
    return out


def bench_surgery(args, model, rules) -> dict:
    """Which of W*'s errors the target prefers (``--wstars DIR``: the W*s of ``--subset synthetic
    --save DIR``). For each repair of :func:`surgery_clusters`, W* with its units over a missed or
    pieced true unit replaced by the true units there, every wall then moved to its best position
    (:func:`semmap_pp.sampler.ascent.align_walls`, the full target), against W* aligned the same way:
    ``delta`` > 0 (the truth scores higher: a search miss), < 0 (the target's own choice) or 0
    (the walls moved back to W*'s: a room seen in part shrinks to its seen part again)."""
    from semmap_pp.sampler.ascent import align_walls
    from semmap_pp.run.target_factory import run_target
    if args.wstars is None:
        raise SystemExit("--subset surgery needs --wstars DIR (the W*s of --subset synthetic --save DIR)")
    rows = []
    for seed in range(args.first_floor, args.first_floor + args.floors):
        path = args.wstars / f"synth-{seed}" / "world.json"
        if not path.exists():
            _log(args, f"surgery {seed:3d}: no {path}, skipped")
            continue
        t0 = time.perf_counter()
        floor, grid, inputs = _floor(seed, model, rules, args.pool, args.resolution)
        post = run_target(inputs)
        data = kernel_data(inputs, model)
        pred = json.loads(path.read_text())
        units = [u["vertices_px"] for u in pred["units"]]
        extra = [u["vertices_px"] for u in pred.get("exterior", [])]

        def aligned_logp(polygons):
            w = polygons_world(inputs.frame, polygons, max(model.prior.k_max, len(polygons)))
            return float(post.evaluate(align_walls(post, w, data)).total)

        base = aligned_logp(units + extra)
        repairs = []
        for j, cls, remove, add in surgery_clusters(pred, floor.truth, floor.classes.shape):
            kept = [u for i, u in enumerate(units) if i not in remove]
            lp = aligned_logp(kept + [floor.truth["units"][k]["corners_px"] for k in add] + extra)
            repairs.append({"true_unit": floor.truth["units"][j]["id"], "class": cls,
                            "removed": len(remove), "added": len(add), "delta": round(lp - base, 1)})
        rows.append({"seed": seed, "wstar_aligned_log_posterior": round(base, 1), "repairs": repairs,
                     "seconds": round(time.perf_counter() - t0, 1)})
        _log(args, f"surgery {seed:3d}: " + ", ".join(f"T{r['true_unit']} {r['class']} {r['delta']:+.1f}"
                                                      for r in repairs))
    by_class: dict = {}
    for r in (r for row in rows for r in row["repairs"]):
        c = by_class.setdefault(r["class"], {"repairs": 0, "truth_higher": 0, "equal": 0, "truth_lower": 0})
        c["repairs"] += 1
        c["truth_higher" if r["delta"] > 0.05 else "truth_lower" if r["delta"] < -0.05 else "equal"] += 1
    return {"rows": rows, "by_class": by_class}


def bench_stability(args, model, rules) -> dict:
    """The synthetic floors searched with each of ``--seeds`` (``semmap stability``'s comparison,
    :mod:`semmap_pp.studies.stability`), and whether seed agreement tells right from wrong: the best W*'s
    units found with their type under every seed, and the others, each counted with how many of
    them match a true unit (IoU >= 0.5, as the synthetic subset scores them)."""
    from semmap_pp.semantic.world_json import world_dict
    from semmap_pp.studies.stability import SeedPlan, Stability
    seeds = [int(v) for v in str(args.seeds).split(",") if v.strip()]
    if len(set(seeds)) < 2:
        raise SystemExit("--seeds needs at least two different seeds")
    rows = []
    tally = {"stable": [0, 0], "unstable": [0, 0]}     # [units, of them matching a true unit]
    for f in range(args.first_floor, args.first_floor + args.floors):
        floor, _grid, inputs = _floor(f, model, rules, args.pool, args.resolution)
        plans, sms = [], []
        for seed in dict.fromkeys(seeds):
            settings = dataclasses.replace(_settings(model, args), seed=seed)
            try:
                run, clock = _run(inputs, settings, args.quiet, best=getattr(args, "spread_best", False))
            except MapFailed as exc:
                _log(args, f"synth {f:3d} seed {seed}: FAILED {exc}")
                break
            plans.append(SeedPlan.from_semantic(seed, run.semantic, clock[-1][0]))
            sms.append(run.semantic)
        if len(plans) < len(set(seeds)):
            rows.append({"floor": f, "error": "a seed failed"})
            continue
        res = Stability.of(plans)
        pred = world_dict(sms[res.ref])
        pc = unit_classes(pred, floor.truth, floor.classes.shape)[0]
        right = {u["id"]: c is None for u, c in zip(pred["units"], pc)}
        for u in res.units:
            t = tally["stable" if u.agreed else "unstable"]
            t[0] += 1
            t[1] += right[u.id]
        rows.append({"floor": f, "reference_seed": res.reference.seed, "units": [len(p.ids) for p in plans],
                     "log_posterior": [round(p.log_posterior, 1) for p in plans],
                     "mean_unit_f1": round(res.mean_f1(), 4), "stable_units": res.stable_units()})
        _log(args, f"synth {f:3d}: units {rows[-1]['units']}, F1 between seeds {res.mean_f1():.3f}, "
                   f"{res.stable_units()}/{len(res.units)} stable")
    ok = [r for r in rows if "error" not in r]
    return {"seeds": seeds, "rows": rows,
            "floors_one_plan": sum(r["mean_unit_f1"] == 1.0 for r in ok),
            "mean_unit_f1": round(float(np.mean([r["mean_unit_f1"] for r in ok])), 4) if ok else None,
            "units": {k: {"units": v[0], "match_truth": v[1],
                          "share": round(v[1] / v[0], 4) if v[0] else None} for k, v in tally.items()}}


def real_maps(bundled: Path, shared: Path) -> list[tuple[Path, bool]]:
    """The real maps of ``--subset real``: ``(yaml path, bundled)``, the maps bundled in ``bundled``
    (the paper's two, with CPR targets) first, then those of ``shared`` that are not bundled (the
    other Radish floors, aces and freiburg-079: no ground truth, no target, scored so that a change
    that breaks them shows), each by name; the shared folder may be absent."""
    own = sorted(bundled.glob("*.yaml"))
    names = {p.stem for p in own}
    more = sorted(p for p in shared.glob("*.yaml") if p.stem not in names) if shared.is_dir() else []
    return [(p, True) for p in own] + [(p, False) for p in more]


def bench_real(args, model, rules) -> dict:
    from semmap_pp.resources import DEFAULT_RULES
    from semmap_pp.run.inputs import load_inputs
    rows = []
    for path, bundled in real_maps(ROOT / "data" / "maps", SHARED / "real"):
        if not _keep(path.stem, args):
            continue
        inputs = load_inputs(path, model_path=args.model, rules_path=args.rules or DEFAULT_RULES)
        settings = _settings(model, args)
        ran = _run_or_record(args, inputs, settings, rows, {"map": path.stem}, f"real {path.stem}")
        if ran is None:
            continue
        run, clock = ran
        sm = run.semantic
        ttb = time_to_best(run, clock)
        row = {"map": path.stem, "bundled": bundled, "units": len(sm.unit_ids), "exterior": len(sm.exterior_ids),
               "cpr": round(sm.cpr, 4),
               "paper_cpr": PUBLISHED["cpr"].get(path.stem), "log_posterior": round(sm.log_posterior, 1),
               "run_s": round(run.seconds, 1), "time_to_wstar_s": ttb.get("seconds"),
               "wstar_draw": ttb.get("draw"), "draws_per_chain": ttb.get("of"),
               "wstar_polished": ttb.get("polished"),
               "knowledge": run.notes[0], "types": {t: sum(1 for u in sm.unit_ids if sm.type_of(u) == t)
                         for t in ("room", "corridor", "hall", "other")}}
        rows.append(row)
        _save(args, path.stem, sm)
        _log(args, f"real {path.stem}: CPR {row['cpr']:.3f} (paper {row['paper_cpr']}), {row['units']} units, "
                   f"run {row['run_s']} s, W* at {row['time_to_wstar_s']} s")
    return {"rows": rows, "targets": {"ubremen-cartesium": TARGETS["cartesium_cpr"],
                                      "intel-lab": TARGETS["intel_cpr"],
                                      "time_to_wstar_s": TARGETS["time_to_wstar_s"]}}


def bench_ipa(args, model, rules) -> dict:
    from semmap_pp.cells import FREE
    from semmap_pp.evaluate import read_ipa_gt, segmentation_scores
    from semmap_pp.grid import load_map
    base = SHARED / "ipa-segmentation"
    if not base.is_dir():
        return {"skipped": f"{base} not found"}
    rows = []
    for gt_path in sorted(base.glob("*_gt_segmentation.png")):
        name = gt_path.name[:-len("_gt_segmentation.png")]
        if not _keep(name, args):
            continue
        map_path = base / (f"{name}_furnitures.yaml" if args.furniture else f"{name}.yaml")
        if not map_path.exists():
            rows.append({"map": name, "error": f"{map_path.name} not found"})
            continue
        grid = load_map(map_path, **IPA_FREE)
        inputs = _inputs_from_grid(grid, model, rules)
        ran = _run_or_record(args, inputs, _settings(model, args), rows, {"map": name}, f"ipa {name}")
        if ran is None:
            continue
        run, clock = ran
        sm = run.semantic
        gt = read_ipa_gt(gt_path)
        seg, _ = regions_of(sm)
        pub = segmentation_scores(gt, seg, restrict_to_gt=False)
        res = segmentation_scores(gt, seg, restrict_to_gt=True)
        # the published protocol on segments of the map's free cells only, as ipa's and ROSE2's
        # methods label them (regions.png labels wall cells too); no ground truth used for it
        free = segmentation_scores(gt, np.where(grid.classes == FREE, seg, 0), restrict_to_gt=False)
        units = segmentation_scores(gt, sm.labels_image.astype(np.int64), restrict_to_gt=False)
        rooms = segmentation_scores(gt, sm.rooms.labels, restrict_to_gt=False)
        row = {"map": name, "rooms_precision": round(rooms.precision, 4), "rooms_recall": round(rooms.recall, 4), "units": len(sm.unit_ids), "regions": int(len(np.unique(seg)) - (seg == 0).any()),
               "precision": round(pub.precision, 4), "recall": round(pub.recall, 4),
               "precision_restricted": round(res.precision, 4), "recall_restricted": round(res.recall, 4),
               "precision_free": round(free.precision, 4), "recall_free": round(free.recall, 4),
               "precision_units": round(units.precision, 4), "recall_units": round(units.recall, 4),
               "log_posterior": round(float(sm.log_posterior), 1),
               "run_s": round(run.seconds, 1), "knowledge": run.notes[0]}
        rows.append(row)
        _save(args, name, sm)
        _log(args, f"ipa {name}: rooms P {row['rooms_precision']:.3f} R {row['rooms_recall']:.3f}; "
                   f"regions P {row['precision']:.3f} R {row['recall']:.3f} (restricted "
                   f"{row['precision_restricted']:.3f}/{row['recall_restricted']:.3f}), {row['units']} units")
    keys = ("rooms_precision", "rooms_recall", "precision", "recall", "precision_restricted",
            "recall_restricted", "precision_free", "recall_free", "precision_units", "recall_units")
    return {"rows": rows, "means": {k: _mean(rows, k) for k in keys},
            "published_real_maps": {"rose2_average_11": PUBLISHED["rose2_real"]["average_11_maps"],
                                    **PUBLISHED["bormann_real_average"]},
            "pixel_rule": "grey >= 250 free, else obstacle (free_thresh=0.0197, occupied_thresh=0.0198)"}


REAL_GT = ROOT / "bench" / "data" / "real-gt"


def bench_real_gt(args, model, rules) -> dict:
    """rooms.png on the real-gt floors beside ROSE2's own output; with ``--turn`` the floors turned
    by those angles instead (:mod:`turned_maps`: ROSE2's output exists for the floors as they are)."""
    import tempfile
    rows = []
    with tempfile.TemporaryDirectory(prefix="semmap-turned-") as tmp:
        for folder in sorted(p for p in REAL_GT.iterdir() if (p / "map.yaml").is_file()):
            for degrees in args.turn or (None,):
                name = folder.name if degrees is None else f"{folder.name}@{degrees:g}deg"
                if args.pool > 1:
                    name = f"{folder.name}@{args.pool}x"
                if _keep(folder.name, args):
                    _real_gt_row(args, model, folder, name, degrees, Path(tmp), rows)
    keys = ("precision", "recall", "regions_free_precision", "regions_free_recall", "run_s")
    if not args.turn and args.pool == 1:
        keys += ("rose2_precision", "rose2_recall")
    return {"rows": rows, "means": {k: _mean(rows, k) for k in keys}, "turned": list(args.turn or ()),
            "pooled": args.pool,
            "protocol": "ROSE2: truth rooms = one-colour regions > 200 cells, segments whole"}


def _real_gt_row(args, model, folder: Path, name: str, degrees, tmp: Path, rows: list) -> None:
    """Run and score one real-gt floor (turned by ``degrees`` unless None) into ``rows``."""
    import turned_maps
    from semmap_pp.cells import FREE
    from semmap_pp.evaluate import protocol_scores, read_segmentation, read_segmentation_truth
    from semmap_pp.resources import DEFAULT_RULES
    from semmap_pp.run.inputs import load_inputs
    import pooled_maps
    gt = read_segmentation_truth(folder / "gt.png", "rose2")
    map_yaml = folder / "map.yaml"
    if degrees is not None:
        gt = turned_maps.write(folder, tmp / name, degrees, gt)
        map_yaml = tmp / name / "map.yaml"
    elif args.pool > 1:                 # scored at the floor's own cells, against its own truth
        floor = pooled_maps.write(folder, tmp / name, args.pool)
        map_yaml = tmp / name / "map.yaml"
    inputs = load_inputs(map_yaml, model_path=args.model, rules_path=args.rules or DEFAULT_RULES)
    ran = _run_or_record(args, inputs, _settings(model, args), rows, {"map": name}, f"real-gt {name}")
    if ran is None:
        return
    run, clock = ran
    sm = run.semantic
    seg, _ = regions_of(sm)
    seg, labels = np.where(inputs.grid.classes == FREE, seg, 0), sm.rooms.labels
    if args.pool > 1:                   # never with --turn (run() refuses the two together)
        seg, labels = (pooled_maps.scored(a, args.pool, floor) for a in (seg, labels))
    rooms = protocol_scores(gt, labels)
    regions = protocol_scores(gt, seg)
    row = {"map": name, "units": len(sm.unit_ids), "rooms": len(sm.rooms.rooms),
           "rooms_seen_through_door": sum(r.seen_through_door for r in sm.rooms.rooms),
           "true_rooms": rooms.n_rooms,
           "precision": round(rooms.precision, 4), "recall": round(rooms.recall, 4),
           "regions_free_precision": round(regions.precision, 4),
           "regions_free_recall": round(regions.recall, 4),
           "cpr": round(sm.cpr, 4), "theta_deg": round(math.degrees(sm.frame.theta), 2),
           "run_s": round(run.seconds, 1)}
    if degrees is None and args.pool == 1:
        rose2 = protocol_scores(gt, read_segmentation(folder / "rose2.png"))
        row |= {"rose2_precision": round(rose2.precision, 4), "rose2_recall": round(rose2.recall, 4)}
    rows.append(row)
    _save(args, name.replace("@", "_"), sm)
    ref = (f" | ROSE2 {row['rose2_precision']:.3f} / {row['rose2_recall']:.3f}" if "rose2_precision" in row else "")
    _log(args, f"real-gt {name}: rooms P {row['precision']:.3f} R {row['recall']:.3f}{ref} | regions "
               f"cut to free {row['regions_free_precision']:.3f} / {row['regions_free_recall']:.3f}; "
               f"{row['rooms']} rooms, run {row['run_s']} s")


def partial_explorations(held_out: bool) -> list[tuple[float, int, str]]:
    """``(share of rooms entered, exploration seed, suffix of the map's name)`` of the partial
    subset: :data:`partial_maps.EXPLORATIONS`, or with ``held_out`` the same shares explored with
    seeds :data:`HELD_OUT_FIRST` on (named by their seed).

    >>> partial_explorations(True)
    [(0.3, 1001, '-seed1001'), (0.6, 1002, '-seed1002')]
    """
    import partial_maps
    if not held_out:
        return [(e, s, "") for e, s in partial_maps.EXPLORATIONS]
    return [(e, HELD_OUT_FIRST + s, f"-seed{HELD_OUT_FIRST + s}") for e, s in partial_maps.EXPLORATIONS]


def bench_partial(args, model, rules) -> dict:
    """rooms.png on partial explorations of the real-gt floors (:mod:`partial_maps`)."""
    import tempfile
    import partial_maps
    from semmap_pp.evaluate import protocol_scores, read_segmentation_truth
    from semmap_pp.resources import DEFAULT_RULES
    from semmap_pp.run.inputs import load_inputs
    rows = []
    with tempfile.TemporaryDirectory(prefix="semmap-partial-") as tmp:
        for folder in sorted(p for p in REAL_GT.iterdir() if (p / "map.yaml").is_file()):
            truth = read_segmentation_truth(folder / "gt.png", "rose2")
            for explored, seed, suffix in partial_explorations(args.held_out):
                name = f"{folder.name}@{explored:g}{suffix}"
                if not _keep(name, args):
                    continue
                out = Path(tmp) / f"{folder.name}-{seed}"
                gt = partial_maps.write(folder, out, explored, seed, truth)
                inputs = load_inputs(out / "map.yaml", model_path=args.model,
                                     rules_path=args.rules or DEFAULT_RULES)
                ran = _run_or_record(args, inputs, _settings(model, args), rows, {"map": name},
                                     f"partial {name}")
                if ran is None:
                    continue
                sm = ran[0].semantic
                sc = protocol_scores(gt, sm.rooms.labels)
                row = {"map": name, "explored": explored, "units": len(sm.unit_ids),
                       "exterior_units": len(sm.exterior_ids), "rooms": len(sm.rooms.rooms),
                       "rooms_seen_through_door": sum(r.seen_through_door for r in sm.rooms.rooms),
                       "true_rooms": sc.n_rooms, "precision": round(sc.precision, 4),
                       "recall": round(sc.recall, 4), "run_s": round(ran[0].seconds, 1)}
                rows.append(row)
                _save(args, name.replace("@", "_"), sm)
                _log(args, f"partial {name}: rooms P {row['precision']:.3f} R {row['recall']:.3f}; "
                           f"{row['rooms']} rooms ({row['rooms_seen_through_door']} seen through their door)")
    return {"rows": rows, "means": {k: _mean(rows, k) for k in ("precision", "recall", "run_s")},
            "held_out": bool(args.held_out),
            "protocol": "ROSE2 on the cells the partial map saw: truth rooms = regions > 200 cells"}


WINGS = ROOT / "tests" / "data" / "wings"


def bench_wings(args, model, rules) -> dict:
    """rooms.png on the drawn plans with wings at other angles (tests/data/wings: a second wing at
    30 and 45 degrees, a pentagonal ring), against their room truth (``NAME_gt.png``, ROSE2's
    protocol), and the exterior units lying mostly inside the building's rooms."""
    from PIL import Image
    from semmap_pp.cells import FREE
    from semmap_pp.evaluate import protocol_scores
    from semmap_pp.resources import DEFAULT_RULES
    from semmap_pp.run.inputs import load_inputs
    rows = []
    for map_path in sorted(WINGS.glob("*.yaml")):
        name = map_path.stem
        if not _keep(name, args):
            continue
        inputs = load_inputs(map_path, model_path=args.model, rules_path=args.rules or DEFAULT_RULES)
        ran = _run_or_record(args, inputs, _settings(model, args), rows, {"map": name}, f"wings {name}")
        if ran is None:
            continue
        sm = ran[0].semantic
        truth = np.asarray(Image.open(WINGS / f"{name}_gt.png")).astype(np.int64)
        sc = protocol_scores(truth, sm.rooms.labels)
        inside = 0
        for slot in sm.exterior_ids:
            r0, c0, r1, c1 = (int(v) for v in sm.world.rects[slot])
            cells = np.zeros(sm.frame.shape, bool)
            cells[max(r0, 0):r1, max(c0, 0):c1] = True
            img = sm.frame.to_image(cells, fill=False) & (sm.grid.classes == FREE)
            if img.any() and (truth[img] > 0).mean() > 0.5:
                inside += 1
        row = {"map": name, "units": len(sm.unit_ids), "exterior_units": len(sm.exterior_ids),
               "exterior_inside": inside, "rooms": len(sm.rooms.rooms), "true_rooms": sc.n_rooms,
               "precision": round(sc.precision, 4), "recall": round(sc.recall, 4),
               "run_s": round(ran[0].seconds, 1)}
        rows.append(row)
        _save(args, name, sm)
        _log(args, f"wings {name}: rooms P {row['precision']:.3f} R {row['recall']:.3f}; {row['units']} units "
                   f"+ {row['exterior_units']} exterior ({inside} inside the building)")
    return {"rows": rows, "means": {k: _mean(rows, k) for k in ("precision", "recall", "exterior_inside", "run_s")},
            "protocol": "ROSE2 on the plan's free cells: truth rooms = labels > 200 cells"}


#: the groups of ``--subset synthetic-wings``: name -> ``generate_floor`` arguments. ``wings2-0``
#: and ``wings3-0`` are the controls: the same plans, links and robot as the turned groups of
#: their number of wings, every joint at 0 degrees (Manhattan floors of several wings)
WING_GROUPS = {"manhattan": {}, "wings2-0": {"wings": 2, "wing_angle_deg": 0.0},
               "wings2-30": {"wings": 2, "wing_angle_deg": 30.0},
               "wings2-45": {"wings": 2, "wing_angle_deg": 45.0},
               "wings3-0": {"wings": 3, "wing_angle_deg": 0.0}, "wings3-drawn": {"wings": 3}}
#: each turned group's control: its floors with every joint at 0 degrees
WING_CONTROLS = {"wings2-30": "wings2-0", "wings2-45": "wings2-0", "wings3-drawn": "wings3-0"}
#: seeds from here on are held out: no setting of the model or the generator was tuned on them
HELD_OUT_FIRST = 1000
WING_KEYS = ("unit_f1", "door_f1", "type_accuracy", "cpr", "cpr_building", "unit_f1_visible",
             "rooms_precision", "rooms_recall", "seconds")


def bench_synthetic_wings(args, model, rules) -> dict:
    """Floors of wings (:data:`WING_GROUPS`: two wings at 30 and at 45 degrees, three at angles
    drawn from the seed, and the same floors with every joint at 0 degrees) beside the one-wing
    floors of the same seeds, scored as the synthetic subset scores its floors; means per group,
    each group's difference from the one-wing floors (``minus_manhattan``) and each turned
    group's from its control (``minus_control``, :data:`WING_CONTROLS`): what the angles cost.
    ``--held-out`` takes the seeds from :data:`HELD_OUT_FIRST` on."""
    first = HELD_OUT_FIRST + args.first_floor if args.held_out else args.first_floor
    floors = [(g, seed, kind) for g, kind in WING_GROUPS.items() if _keep(g, args)
              for seed in range(first, first + args.floors)]
    out = bench_synthetic(args, model, rules, floors)
    groups = {}
    for g in WING_GROUPS:
        rows = [r for r in out["rows"] if r.get("group") == g]
        if rows:
            groups[g] = {"floors": len(rows), **{k: _mean(rows, k) for k in WING_KEYS}}
            by_wing = [r["unit_recall_by_wing"] for r in rows if "unit_recall_by_wing" in r]
            for w in sorted({w for b in by_wing for w in b}):
                groups[g][f"unit_recall_wing_{w}"] = _mean([b for b in by_wing if w in b], w)
    for g, m in groups.items():
        if g == "manhattan":
            continue
        for key, other in (("minus_manhattan", "manhattan"), ("minus_control", WING_CONTROLS.get(g))):
            diff = _group_difference(out["rows"], g, other)
            if diff is not None:
                m[key] = diff
        _log(args, f"{g}: {m['floors']} floors  unit F1 {m['unit_f1']}  door F1 {m['door_f1']}  "
                   f"types {m['type_accuracy']}  CPR {m['cpr']}  rooms P {m['rooms_precision']} "
                   f"R {m['rooms_recall']}")
    out["groups"] = groups
    out["seeds"] = [first, first + args.floors - 1]
    out["held_out"] = bool(args.held_out)
    return out


def _group_difference(rows: list, group: str, other: str | None) -> dict | None:
    """The means of ``group``'s rows less ``other``'s over the seeds both hold (a seed the
    generator could not lay out in one group is left out of both), per key of :data:`WING_KEYS`
    but the time; None when they share no seed."""
    by = {g: {r["seed"]: r for r in rows if r.get("group") == g and "unit_f1" in r} for g in (group, other)}
    seeds = sorted(set(by[group]) & set(by[other])) if other is not None else []
    if not seeds:
        return None
    out = {}
    for k in WING_KEYS[:-1]:
        a, b = _mean([by[group][s] for s in seeds], k), _mean([by[other][s] for s in seeds], k)
        if a is not None and b is not None:
            out[k] = round(a - b, 4)
    return out


TYPE_MAPS = [("Fr52_original.png", "training_Fr52.png"), ("NLB_original.png", "training_NLB_furniture.png"),
             ("lab_c_furnitures_original.png", "training_lab_c_furnitures.png"),
             ("lab_d_furnitures_original.png", "training_lab_d_furniture.png"),
             ("lab_ipa_original.png", "training_lab_ipa.png")]


def bench_types(args, model, rules) -> dict:
    from semmap_pp.evaluate import read_ipa_types, type_accuracy, type_map_from_labels
    from semmap_pp.grid import load_map
    base = SHARED / "ipa-types"
    if not base.is_dir():
        return {"skipped": f"{base} not found"}
    rows = []
    for map_name, truth_name in TYPE_MAPS:
        if not (base / map_name).exists() or not _keep(map_name, args):
            continue
        grid = load_map(base / map_name, resolution=0.05, **IPA_FREE)
        inputs = _inputs_from_grid(grid, model, rules)
        ran = _run_or_record(args, inputs, _settings(model, args), rows, {"map": map_name}, f"types {map_name}")
        if ran is None:
            continue
        run, clock = ran
        sm = run.semantic
        types = {uid: sm.type_of(uid) for uid in sm.unit_ids}
        pred = type_map_from_labels(sm.labels_image, types)
        sc = type_accuracy(pred, read_ipa_types(base / truth_name))
        row = {"map": map_name[:-len("_original.png")], "accuracy": round(sc.accuracy, 4),
               "balanced_accuracy": round(sc.balanced_accuracy, 4), "recall_room": round(sc.recall_room, 4),
               "recall_corridor": round(sc.recall_corridor, 4), "coverage": round(sc.coverage, 4),
               "accuracy_covered": round(sc.accuracy_covered, 4), "units": len(sm.unit_ids),
               "log_posterior": round(float(sm.log_posterior), 1),
               "run_s": round(run.seconds, 1), "knowledge": run.notes[0]}
        rows.append(row)
        _save(args, row["map"], sm)
        _log(args, f"types {row['map']}: acc {row['accuracy']:.3f} balanced {row['balanced_accuracy']:.3f} "
                   f"coverage {row['coverage']:.3f}")
    keys = ("accuracy", "balanced_accuracy", "recall_room", "recall_corridor", "coverage", "accuracy_covered")
    return {"rows": rows, "means": {k: _mean(rows, k) for k in keys},
            "pixel_rule": "grey >= 250 free, else obstacle; resolution 0.05 m assumed"}


def run(args) -> dict:
    from semmap_pp.knowledge import load_rules
    from semmap_pp.model import load_model
    from semmap_pp.resources import DEFAULT_RULES
    if args.tiny:
        for key, value in TINY.items():
            setattr(args, key, value)
        if args.subset == "all":
            args.subset = "synthetic"
    if args.pool < 1 or (args.pool > 1 and args.subset not in ("synthetic", "truth", "surgery", "real-gt")):
        raise SystemExit("--pool K (K >= 1) applies to --subset synthetic, truth, surgery and real-gt only")
    if args.resolution != 0.05 and args.subset not in ("synthetic", "truth", "surgery"):
        raise SystemExit("--resolution applies to --subset synthetic, truth and surgery only")
    if args.turn and args.subset != "real-gt":
        raise SystemExit("--turn applies to --subset real-gt only")
    if args.turn and args.pool > 1:
        raise SystemExit("--turn and --pool: one at a time")
    model = load_model(args.model)
    rules = load_rules(args.rules or DEFAULT_RULES)
    SECONDS[0] = None if isinstance(args.budget, str) else float(args.budget)
    s = _settings(model, args)
    out = {"settings": {k: getattr(s, k) for k in ("chains", "cores", "tune", "draws", "n_inner", "anneal",
                                                   "spread_draws", "spread_n_inner")}
           | {"spread_best": args.spread_best, "budget": args.budget, "pool": args.pool,
              "resolution": args.resolution, "furniture": args.furniture},
           "published": PUBLISHED, "targets": TARGETS}
    subsets = {"all": ["synthetic", "real", "ipa", "types"],
               "targets": ["synthetic", "truth", "real"]}.get(args.subset, [args.subset])
    fns = {"synthetic": bench_synthetic, "synthetic-wings": bench_synthetic_wings, "truth": bench_truth, "surgery": bench_surgery,
           "real": bench_real, "real-gt": bench_real_gt, "partial": bench_partial, "wings": bench_wings, "ipa": bench_ipa, "types": bench_types, "stability": bench_stability}
    for name in subsets:
        t0 = time.perf_counter()
        out[name] = over_seeds(fns[name], args, model, rules)
        out[name]["wall_s"] = round(time.perf_counter() - t0, 1)
        off = knowledge_off(out[name])
        if off:    # said at the top of the subset: its rows measured the geometry's fixed types
            out[name]["knowledge_off"] = off
            _log(args, f"{name}: knowledge off (engine failed) on {len(off)} row(s): {', '.join(off)}")
    out["target_report"] = target_report(out)
    for line in report_lines(out["target_report"]) if out["target_report"] else ():
        _log(args, line)
    return out


def parse_seeds(text) -> list[int]:
    """``--over-seeds`` as a list of seeds (empty for None).

    >>> parse_seeds("0, 1,2"), parse_seeds(None)
    ([0, 1, 2], [])
    """
    if text is None:
        return []
    try:
        seeds = [int(v) for v in str(text).split(",") if v.strip()]
    except ValueError:
        raise SystemExit(f"--over-seeds: comma-separated integers expected, got {text!r}") from None
    if not seeds or min(seeds) < 0 or len(set(seeds)) != len(seeds):
        raise SystemExit(f"--over-seeds: distinct seeds >= 0 expected, got {text!r}")
    return seeds


def combine_seeds(parts: dict) -> dict:
    """One subset's results under several seeds (``{seed: result}``) as one result: every row
    with its ``sampler_seed``, the means over the seeds of each seed's means, their standard deviation
    (``seed_sd``, 0 for one seed) and each seed's means (``means_by_seed``).

    >>> r = combine_seeds({0: {"rows": [{"map": "a", "p": 0.9}], "means": {"p": 0.9}},
    ...                    1: {"rows": [{"map": "a", "p": 0.8}], "means": {"p": 0.8}}})
    >>> r["means"], r["seed_sd"], [row["sampler_seed"] for row in r["rows"]]
    ({'p': 0.85}, {'p': 0.05}, [0, 1])
    """
    rows, by_seed = [], {}
    for seed, part in parts.items():
        rows += [{**row, "sampler_seed": seed} for row in part.get("rows", [])]
        by_seed[seed] = part.get("means", {})
    keys = [k for k in next(iter(by_seed.values()), {})
            if all(isinstance(m.get(k), (int, float)) for m in by_seed.values())]
    first = next(iter(parts.values()))
    return {**{k: v for k, v in first.items() if k not in ("rows", "means")}, "rows": rows,
            "means": {k: round(float(np.mean([m[k] for m in by_seed.values()])), 4) for k in keys},
            "seed_sd": {k: round(float(np.std([m[k] for m in by_seed.values()])), 4) for k in keys},
            "means_by_seed": {str(s): m for s, m in by_seed.items()}}


def over_seeds(fn, args, model, rules) -> dict:
    """``fn(args, model, rules)``, once per ``--over-seeds`` seed (:func:`combine_seeds`), or once."""
    seeds = parse_seeds(getattr(args, "over_seeds", None))
    if not seeds:
        return fn(args, model, rules)
    keep, parts = args.seed, {}
    try:
        for seed in seeds:
            args.seed = seed
            _log(args, f"-- seed {seed}")
            parts[seed] = fn(args, model, rules)
    finally:
        args.seed = keep
    if any("rows" not in p for p in parts.values()):     # a skipped subset: as it came
        return next(iter(parts.values()))
    return combine_seeds(parts)


def _measured(result: dict, subset: str, key: str):
    """One reading's value in ``result``: a mean of the subset, or ``map:key`` of a real map's row."""
    part = result.get(subset)
    if not isinstance(part, dict):
        return None
    if ":" in key:
        name, field = key.split(":", 1)
        return next((r.get(field) for r in part.get("rows", []) if r.get("map") == name), None)
    return part.get("means", {}).get(key)


def target_report(result: dict) -> list[dict]:
    """Each target of :data:`TARGETS` under each reading of :data:`READINGS` that ``result``
    measured: the bound, the value, whether it is met, and (synthetic means, when the truth subset
    ran) the ceiling, the seen true units scored as W* is. Nothing is chosen: every reading is a row.

    >>> rows = target_report({"synthetic": {"means": {"cpr": 0.93, "cpr_building": 0.951}},
    ...                       "truth": {"means": {"cpr": 0.89}}})
    >>> [(r["reading"][:11], r["value"], r["met"], r["ceiling"]) for r in rows]
    [('default ROI', 0.93, False, 0.89), ('the buildin', 0.951, True, None)]
    """
    rows = []
    for target, reading, subset, key in READINGS:
        value = _measured(result, subset, key)
        if value is None:
            continue
        bound = TARGETS[target]
        met = value <= bound if target in AT_MOST else value >= bound
        ceiling = result.get("truth", {}).get("means", {}).get(key) if subset == "synthetic" else None
        rows.append({"target": target, "reading": reading, "bound": bound,
                     "at_most": target in AT_MOST, "value": value, "met": bool(met), "ceiling": ceiling})
    return rows


def report_lines(rows: list[dict]) -> list[str]:
    """:func:`target_report`'s rows as a text table (one line per reading)."""
    lines = [f"{'target':<16} {'reading':<56} {'bound':>8} {'value':>8} {'ceiling':>8}  met"]
    for r in rows:
        bound = ("<= " if r["at_most"] else ">= ") + f"{r['bound']:g}"
        ceiling = "" if r["ceiling"] is None else f"{r['ceiling']:.4f}"
        lines.append(f"{r['target']:<16} {r['reading']:<56} {bound:>8} {r['value']:>8.4g} {ceiling:>8}  "
                     f"{'yes' if r['met'] else 'no'}")
    return lines


def knowledge_off(result: dict) -> list[str]:
    """The rows of a subset's result that ran without knowledge because the engine failed
    (:func:`_run`'s fallback), by map name or seed.

    >>> knowledge_off({"rows": [{"map": "a", "knowledge": "knowledge: on"},
    ...                         {"seed": 3, "knowledge": "knowledge: off (engine failed: ...)"}]})
    ['3']
    """
    return [str(r.get("map", r.get("seed"))) for r in result.get("rows", [])
            if isinstance(r, dict) and str(r.get("knowledge", "")).startswith("knowledge: off")]
