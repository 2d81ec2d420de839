"""Knowledge against no knowledge on one map: the paper's Fig. 6 (defects) and Fig. 7 (spread).

Run (from the repository root; on cartesium with the defaults about 1.5 min of CPU, 2-3 min wall on
the shared 2-core machine)::

    .venv/bin/python docs/figures/make_knowledge_figures.py

For each rule set (``rules/table3.lp``, ``rules/none.lp``), with the same map, model (read now, from
``--model``, default ``models/default.toml``) and seed:

1. **find W*** — ``run_map`` with the model file's ``[sampler]`` run lengths (what ``semmap map`` does);
2. **sample from W*** — as the paper's Fig. 7 ("Starting the Markov chain from the world state W*"):
   ``run_map(..., starts=[W*])`` with no burn-in and ``--draws`` recorded draws of ``--n-inner`` kernels
   per chain, under the same rule set. ``--start own`` (default) starts each rule set from its own W*,
   ``--start table3`` starts both from the W* of table3 (the paper starts both from its W*).

It writes, into ``--out`` (default ``docs/figures``):

* ``knowledge_fig6.png`` — W* of each rule set side by side; every topological defect (adjacent rooms
  whose connecting walls differ by more than ``[diagnostics] defect_tolerance_m``) has its two
  connecting walls drawn in orange and a magenta dashed circle (the paper's Fig. 6);
* ``knowledge_fig7.png`` — up to ``--worlds`` sampled worlds (default 1000, evenly thinned over chains
  and draws) drawn with thin lines over the map, one panel per rule set (``outputs.figures.compare_png``);
* ``knowledge_table.md`` / ``knowledge_table.json`` — per rule set: W* (units, CPR, log posterior,
  defects) and the sampled worlds (defects, spread measures, R-hat, ESS), see docs/knowledge_comparison.md.

``--study SEEDS`` skips the figures and prints only the spread / defect numbers for several seeds
(one JSON line per seed and rule set), for the measurements in docs/knowledge_comparison.md.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import platform
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from semmap_pp import atomic  # noqa: E402
from semmap_pp import world as wm  # noqa: E402
from semmap_pp.outputs.figures import compare_png  # noqa: E402
from semmap_pp.studies.compare import (compare_dict, mean_wall_sd_m, summarise,  # noqa: E402
                                       typed_sampled_worlds)
from semmap_pp.target.defects import ROOM, count_defects, topological_defects  # noqa: E402
from semmap_pp.knowledge import load_rules  # noqa: E402
from semmap_pp.run.inputs import load_inputs  # noqa: E402
from semmap_pp.run.pipeline import run_map  # noqa: E402
from semmap_pp.run.results import RunSettings  # noqa: E402
from semmap_pp.run.target_factory import TargetFactory, run_target  # noqa: E402

RULES = {"table3": ROOT / "rules" / "table3.lp", "none": ROOT / "rules" / "none.lp"}
ORANGE = "#ff8c00"


def _quiet(msg: str) -> None:
    print("  " + msg, file=sys.stderr, flush=True)


def find_wstar(inputs, model, seed: int):
    """Phase 1: ``run_map`` with the model file's run lengths; returns the run (its W* is ``run.world``)."""
    # this script samples around W* itself (phase 2, with its own run lengths)
    return run_map(inputs, RunSettings.from_model(model, seed=seed, spread_draws=0), log=_quiet)


def sample_from(inputs, model, seed: int, start, draws: int, n_inner: int, chains: int):
    """Phase 2: chains started at ``start`` (a W*), no burn-in, ``draws`` recorded draws each."""
    settings = RunSettings.from_model(model, seed=seed, tune=0, draws=draws, n_inner=n_inner, chains=chains,
                                      spread_draws=0)
    return run_map(inputs, settings, log=_quiet, starts=[start])


def all_rooms(world):
    """``world`` with every active unit typed room: defects of the geometry alone, whatever the typing."""
    return wm.with_types(world, np.full(world.capacity, ROOM))


def reference_target(inputs):
    """The table3 target, knowledge on: types every world the same way, whichever rule set sampled it."""
    post = TargetFactory(inputs.frame, inputs.model, load_rules(RULES["table3"]))()
    post.knowledge_on = True
    return post


def spread_numbers(run, worlds, reference) -> dict:
    """The spread and defect measures of sampled ``worlds`` of ``run`` (see docs/knowledge_comparison.md).

    ``reference`` is :func:`reference_target`: defects are also counted with table3's typing for both
    rule sets (none.lp types every unit room, so its own typing counts every adjacent pair).
    """
    from semmap_pp.studies.compare import wall_spread
    from semmap_pp.sampler.spread import cell_probabilities, typed_worlds, wall_disagreement_m2

    frame, model = run.inputs.frame, run.inputs.model
    c = frame.cells
    tol = model.diagnostics.defect_tolerance_m
    p_wall, _ = cell_probabilities(frame.shape, worlds, c.wall)
    units = np.array([wm.n_units(w) for w in worlds])
    geo = count_defects([all_rooms(w) for w in worlds], c.resolution, c.wall, c.adjacency_dilation, tol)
    typed = count_defects(worlds, c.resolution, c.wall, c.adjacency_dilation, tol)
    ref = count_defects(typed_worlds(reference, worlds), c.resolution, c.wall, c.adjacency_dilation, tol)
    return {"n_worlds": len(worlds),
            "wall_spread_mean_ever_wall": wall_spread(worlds, frame.shape, c.wall),
            "cells_ever_wall": int(np.count_nonzero(p_wall > 0)),
            "wall_disagreement_m2": wall_disagreement_m2(p_wall, c.resolution),
            "units_mean": float(units.mean()), "units_sd": float(units.std()),
            "defects_rooms_mean": float(typed.mean()),
            "defects_table3_typing_mean": float(ref.mean()),
            "defects_all_adjacent_mean": float(geo.mean()),
            "accept_rate": float(np.mean(run.sample_stats["accept"])) if "accept" in run.sample_stats
            else math.nan}


def _connecting_walls(frame, rp, rq) -> list[np.ndarray]:
    """The two facing sides (as ``[[x, y], [x, y]]`` in the image) whose lengths the SaLe factor compares."""
    vp, vq = frame.rect_vertices_px(rp), frame.rect_vertices_px(rq)   # corners (r0,c0) (r0,c1) (r1,c1) (r1,c0)
    col_gap = max(rp[1], rq[1]) - min(rp[3], rq[3])
    row_gap = max(rp[0], rq[0]) - min(rp[2], rq[2])
    if col_gap >= row_gap:      # side by side along the columns: vertical walls facing each other
        left_p = rp[1] <= rq[1]
        sp = vp[[1, 2]] if left_p else vp[[3, 0]]
        sq = vq[[3, 0]] if left_p else vq[[1, 2]]
    else:                       # one above the other: horizontal walls
        top_p = rp[0] <= rq[0]
        sp = vp[[3, 2]] if top_p else vp[[0, 1]]
        sq = vq[[0, 1]] if top_p else vq[[3, 2]]
    return [sp, sq]


def fig6_png(runs: list, names: list[str]) -> bytes:
    """W* of each run side by side, types at unit centres, defects' connecting walls in orange."""
    from matplotlib.collections import LineCollection
    from matplotlib.lines import Line2D
    from matplotlib.patches import Circle

    from semmap_pp.outputs.figures import MAGENTA, classified_rgb, png, side_by_side, world_outlines
    from semmap_pp.outputs.graphml import TYPE_LETTER

    fig, axes, (y0, y1, x0, x1) = side_by_side([r.semantic for r in runs], extra_h=0.9)
    for ax, run, name in zip(axes, runs, names):
        sm, frame, model = run.semantic, run.inputs.frame, run.inputs.model
        c = frame.cells
        world = run.world
        ax.imshow(classified_rgb(sm.grid.classes, light=True)[y0:y1, x0:x1], extent=(x0, x1, y1, y0),
                  interpolation="nearest")
        ax.add_collection(LineCollection(world_outlines(frame, [world]), colors="tab:blue", linewidths=1.2))
        for s in wm.active_slots(world):
            x, y = frame.rect_vertices_px(world.rects[s]).mean(axis=0)
            t = int(world.types[s])
            letter = TYPE_LETTER[("room", "corridor", "hall", "other")[t]] if t >= 0 else "?"
            ax.text(x, y, letter, ha="center", va="center", fontsize=8, fontweight="bold",
                    bbox=dict(boxstyle="round,pad=0.1", fc="white", ec="none", alpha=0.8))
        defects = topological_defects(world, c.resolution, c.wall, c.adjacency_dilation,
                                      model.diagnostics.defect_tolerance_m)
        segs = []
        for d in defects:
            rp, rq = (np.asarray(world.rects[k], float) for k in (d.p, d.q))
            pair = _connecting_walls(frame, rp, rq)
            segs += pair
            mid = np.concatenate(pair).mean(axis=0)
            radius = 0.025 * max(y1 - y0, x1 - x0)
            ax.add_patch(Circle(mid, radius, fill=False, ec=MAGENTA, ls="--", lw=1.2))
        if segs:
            ax.add_collection(LineCollection(segs, colors=ORANGE, linewidths=3.0))
        ax.set_xlim(x0, x1)
        ax.set_ylim(y1, y0)
        ax.set_aspect("equal")
        ax.set_xticks([])
        ax.set_yticks([])
        ax.set_title(f"{name}: W* with {wm.n_units(world)} units, CPR {sm.cpr:.3f}, "
                     f"{len(defects)} topological defect(s)", fontsize=9)
    handles = [Line2D([], [], color="tab:blue", label="unit of W*"),
               Line2D([], [], color=ORANGE, lw=3, label="connecting walls of a defect (adjacent rooms, "
                      f"lengths differ > {runs[0].inputs.model.diagnostics.defect_tolerance_m:g} m)"),
               Line2D([], [], color=MAGENTA, ls="--", label="defect")]
    fig.legend(handles=handles, loc="lower center", ncol=3, frameon=False, fontsize=8)
    fig.subplots_adjust(0.01, 0.45 / fig.get_figheight(), 0.99, 1 - 0.35 / fig.get_figheight(), wspace=0.03)
    return png(fig)


def run_rule_sets(map_path, model_path, seed, draws, n_inner, chains, n_worlds, start_mode):
    from semmap_pp.sampler.spread import typed_worlds

    base = load_inputs(map_path, model_path=model_path, rules_path=RULES["table3"])
    model = base.model
    out = {}
    reference = reference_target(base)
    for name, path in RULES.items():
        inputs = dataclasses.replace(base, rules=load_rules(path))
        print(f"--- {name}: finding W* (seed {seed}) ---", file=sys.stderr, flush=True)
        t0 = time.process_time()
        a = find_wstar(inputs, model, seed)
        out[name] = {"inputs": inputs, "find": a, "cpu_find": time.process_time() - t0}
    for name in RULES:
        inputs = out[name]["inputs"]
        start = out["table3" if start_mode == "table3" else name]["find"].world
        print(f"--- {name}: {chains} chains x {draws} draws x {n_inner} kernels from W* ---",
              file=sys.stderr, flush=True)
        b = sample_from(inputs, model, seed, start, draws, n_inner, chains)
        ws = typed_sampled_worlds(b, n_worlds)
        out[name].update(sample=b, worlds=ws, numbers=spread_numbers(b, ws, reference))
        out[name]["wstar_table3_typing"] = typed_worlds(reference, [out[name]["find"].world])[0]
        # the conditional wall spread of one world, table3's W*, under each rule set's target
        out[name]["numbers"]["wall_sd_table3_wstar_m"] = mean_wall_sd_m(run_target(inputs),
                                                                      out["table3"]["find"].world)
    return model, out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--map", default=str(ROOT / "data" / "maps" / "ubremen-cartesium.yaml"))
    ap.add_argument("--model", default=None, help="model file (default models/default.toml), read at run time")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--chains", type=int, default=2)
    ap.add_argument("--draws", type=int, default=1000, help="recorded draws per chain from W* (default 1000)")
    ap.add_argument("--n-inner", type=int, default=40, help="kernels per draw from W* (default 40)")
    ap.add_argument("--worlds", type=int, default=1000, help="sampled worlds drawn and measured (default 1000)")
    ap.add_argument("--start", choices=("own", "table3"), default="own",
                    help="start each rule set from its own W* (default) or both from table3's W*")
    ap.add_argument("--out", type=Path, default=ROOT / "docs" / "figures")
    ap.add_argument("--study", type=int, nargs="+", metavar="SEED",
                    help="no figures: print the spread / defect numbers for these seeds (JSON lines)")
    args = ap.parse_args(argv)

    if args.study:
        for seed in args.study:
            _, out = run_rule_sets(args.map, args.model, seed, args.draws, args.n_inner, args.chains,
                                   args.worlds, args.start)
            for name, o in out.items():
                s = summarise(o["sample"], name, RULES[name].name, o["worlds"])
                print(json.dumps({"seed": seed, "rules": name, "draws": args.draws, "n_inner": args.n_inner,
                                  "start": args.start, "wstar_cpr": round(float(o["find"].semantic.cpr), 4),
                                  "wstar_units": wm.n_units(o["find"].world),
                                  "wstar_defects": len(topological_defects(
                                      o["find"].world, *_defect_args(o["find"]))),
                                  "wstar_defects_table3_typing": len(topological_defects(
                                      o["wstar_table3_typing"], *_defect_args(o["find"]))),
                                  "converged": s.converged, "wall_sd_m": _round(s.wall_sd_m),
                                  **{k: _round(v) for k, v in o["numbers"].items()}}),
                      flush=True)
        return 0

    t_start = time.time()
    model, out = run_rule_sets(args.map, args.model, args.seed, args.draws, args.n_inner, args.chains,
                               args.worlds, args.start)
    names = list(RULES)
    finds = [out[n]["find"] for n in names]
    samples = [out[n]["sample"] for n in names]
    worlds = [out[n]["worlds"] for n in names]
    rows = [summarise(out[n]["sample"], n, RULES[n].name, out[n]["worlds"]) for n in names]
    args.out.mkdir(parents=True, exist_ok=True)
    atomic.write_bytes(args.out / "knowledge_fig6.png", fig6_png(finds, names))
    atomic.write_bytes(args.out / "knowledge_fig7.png", compare_png(samples, worlds, rows))

    wstar = {n: {"units": wm.n_units(out[n]["find"].world), "cpr": round(float(out[n]["find"].semantic.cpr), 4),
                 "log_posterior": round(float(out[n]["find"].semantic.log_posterior), 1),
                 "defects": len(topological_defects(out[n]["find"].world, *_defect_args(out[n]["find"]))),
                 "defects_all_adjacent": len(topological_defects(all_rooms(out[n]["find"].world),
                                                                 *_defect_args(out[n]["find"]))),
                 "defects_table3_typing": len(topological_defects(out[n]["wstar_table3_typing"],
                                                                  *_defect_args(out[n]["find"])))}
             for n in names}
    settings = {"map": str(Path(args.map).relative_to(ROOT)) if Path(args.map).is_relative_to(ROOT) else args.map,
                "model": str(model.path), "seed": args.seed, "find_wstar": "model [sampler] run lengths "
                f"({model.sampler.chains} chains x ({model.sampler.tune} + {model.sampler.draws}) x "
                f"{model.sampler.n_inner})", "from_wstar": f"{args.chains} chains x (0 + {args.draws}) x "
                f"{args.n_inner} kernels", "start": args.start, "worlds": args.worlds,
                "machine": _machine(),
                "wall_seconds": round(time.time() - t_start, 1)}
    doc = compare_dict(rows, map_path=settings["map"], settings=settings)
    doc["wstar"] = wstar
    doc["spread"] = {n: {k: _round(v) for k, v in out[n]["numbers"].items()} for n in names}
    atomic.write_text(args.out / "knowledge_table.json", json.dumps(doc, indent=1) + "\n")
    atomic.write_text(args.out / "knowledge_table.md", _markdown(names, wstar, doc["spread"], rows, settings))
    for f in ("knowledge_fig6.png", "knowledge_fig7.png", "knowledge_table.md", "knowledge_table.json"):
        print(args.out / f)
    return 0


def _machine() -> str:
    """CPU model and count, OS and Python, for the table."""
    import os

    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return f"{os.cpu_count()} x {cpu}, {platform.system()}, Python {platform.python_version()}"


def _defect_args(run):
    c = run.inputs.frame.cells
    return c.resolution, c.wall, c.adjacency_dilation, run.inputs.model.diagnostics.defect_tolerance_m


def _round(v):
    return round(v, 5) if isinstance(v, float) else v


def _markdown(names, wstar, spread, rows, settings) -> str:
    lines = ["# Knowledge (table3) against none on " + settings["map"], "",
             f"Model `{Path(settings['model']).name}`, seed {settings['seed']}. W*: {settings['find_wstar']}. "
             f"Sampled worlds: {settings['from_wstar']} started from "
             + ("each rule set's own W*" if settings["start"] == "own" else "table3's W*")
             + f", {spread[names[0]]['n_worlds']} worlds evenly thinned. {settings['wall_seconds']} s wall "
             f"on {settings['machine']}.", "",
             "| quantity | " + " | ".join(names) + " |", "|---|" + "---:|" * len(names)]

    def add(label, vals):
        lines.append(f"| {label} | " + " | ".join(str(v) for v in vals) + " |")

    add("units in W*", [wstar[n]["units"] for n in names])
    add("CPR of W*", [f"{wstar[n]['cpr']:.4f}" for n in names])
    add("log posterior of W* (own target)", [f"{wstar[n]['log_posterior']:.1f}" for n in names])
    add("topological defects in W* (rooms)", [wstar[n]["defects"] for n in names])
    add("defects in W*, rooms as table3 types them", [wstar[n]["defects_table3_typing"] for n in names])
    add("defects in W*, every adjacent pair", [wstar[n]["defects_all_adjacent"] for n in names])
    add("defects, mean over sampled worlds (rooms)", [f"{spread[n]['defects_rooms_mean']:.2f}" for n in names])
    add("defects, mean over sampled worlds (rooms as table3 types them)",
        [f"{spread[n]['defects_table3_typing_mean']:.2f}" for n in names])
    add("defects, mean over sampled worlds (every adjacent pair)",
        [f"{spread[n]['defects_all_adjacent_mean']:.2f}" for n in names])
    add("sampled worlds drawn from (draw of each chain; before it still settling, MSER)",
        [r.spread_first_draw for r in rows])
    add("units, mean ± sd over sampled worlds", [f"{spread[n]['units_mean']:.1f} ± {spread[n]['units_sd']:.1f}"
                                                for n in names])
    add("wall spread, mean p(1-p) over cells ever wall (compare.py)",
        [f"{spread[n]['wall_spread_mean_ever_wall']:.4f}" for n in names])
    add("cells ever wall", [spread[n]["cells_ever_wall"] for n in names])
    add("wall disagreement, m² (Σ 2p(1-p) · cell area)", [f"{spread[n]['wall_disagreement_m2']:.2f}" for n in names])
    add("wall sd given the rest of W*, mean over its walls, m (compare.conditional_wall_sd)",
        [f"{r.wall_sd_m:.4f}" for r in rows])
    add("the same on table3's W* (one world, each rule set's target), m",
        [f"{spread[n]['wall_sd_table3_wstar_m']:.4f}" for n in names])
    add("acceptance rate (kernels)", [f"{spread[n]['accept_rate']:.3f}" for n in names])
    add("converged", ["yes" if r.converged else "no" for r in rows])
    for q in rows[0].rhat:
        add(f"R-hat {q}", [f"{r.rhat[q]:.3f}" for r in rows])
    for q in rows[0].rhat:
        add(f"ESS bulk / tail {q}", [f"{r.ess_bulk[q]:.0f} / {r.ess_tail[q]:.0f}" for r in rows])
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    sys.exit(main())
