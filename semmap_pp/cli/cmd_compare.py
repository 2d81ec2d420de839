"""``semmap compare MAP --rules A --rules B [--seeds N N ...] [--out DIR]``: knowledge sets on one map.

Runs ``semmap map``'s sampling once per rule file with the same map, model, seed and run lengths,
then prints a Markdown table (CPR, log posterior, R-hat and ESS of the summaries, posterior wall
spread, topological defects; see :mod:`semmap_pp.studies.compare`). With ``--seeds`` it does so for each
seed and first prints every quantity's mean, sd and range over the seeds, with how far each rule
set's W*s agree between seeds (:class:`semmap_pp.studies.compare.AcrossSeeds`). With ``--out DIR`` it also
writes ``compare.md``, ``compare.json`` and ``compare.png`` (the sampled worlds of each run drawn
thin, side by side; of the first seed), each atomically. Ctrl-C stops and writes nothing (exit 130).
"""

from __future__ import annotations

import dataclasses
import json
import sys
from pathlib import Path

from semmap_pp.cli.argtypes import non_negative_int as _non_negative_int
from semmap_pp.cli.argtypes import positive_int as _positive_int
from semmap_pp.cli.argtypes import seed as seed_type
from semmap_pp.cli.options import add_map_options, add_run_length_options, map_options
from semmap_pp.cli.runs import add_jobs_option
from semmap_pp.model import SPREAD_DRAWS_RULE, spread_draws_ok


def register(subparsers) -> None:
    p = subparsers.add_parser("compare", help="compare knowledge sets (rule files) on one map",
                              description=__doc__.splitlines()[0])
    p.add_argument("map", metavar="MAP", help="map_server YAML, a .png/.pgm/.npy image, or a bag (ROS 2 bag folder, .mcap, ROS 1 .bag)")
    p.add_argument("--rules", action="append", required=True, metavar="FILE",
                   help="a rule file; give it twice or more (e.g. rules/table3.lp and rules/none.lp)")
    p.add_argument("--out", type=Path, metavar="DIR", help="also write compare.md, compare.json, compare.png")
    p.add_argument("--model", metavar="FILE", default=None, help="model file (default models/default.toml)")
    p.add_argument("--roi", metavar="MASK", default=None, help="region-of-interest mask for the CPR")
    seeds = p.add_mutually_exclusive_group()
    seeds.add_argument("--seed", type=seed_type, default=None, help="random seed (default 0)")
    seeds.add_argument("--seeds", type=seed_type, nargs="+", default=None, metavar="N",
                       help="several seeds: every rule set is run with each, and a table over the seeds "
                            "(mean, sd, range; how far the seeds' W*s agree) comes first")
    add_run_length_options(p)
    p.add_argument("--spread-draws", type=_non_negative_int, default=None, metavar="N",
                   help="draws per chain of each rule set's sample around its W* (paper Fig. 7; model "
                        "file default; 0: the spread from the search's draws)")
    p.add_argument("--n-worlds", type=_positive_int, default=200,
                   help="sampled worlds for the spread, the defects and compare.png (default 200)")
    add_jobs_option(p)
    p.add_argument("--force", action="store_true", help="write into a non-empty DIR")
    add_map_options(p)
    p.set_defaults(func=run)


def _names(paths: list[Path]) -> list[str]:
    names, seen = [], {}
    for p in paths:
        seen[p.stem] = seen.get(p.stem, 0) + 1
        names.append(p.stem if seen[p.stem] == 1 else f"{p.stem}#{seen[p.stem]}")
    return names


def run(args) -> int:
    from semmap_pp.run.outdir import claimed

    with claimed(args.out, args.force):    # checked and held before any sampling
        return _run(args)


def _run(args) -> int:
    from semmap_pp.studies.compare import (AcrossSeeds, across_table, compare_table, diffs_section,
                                           summarise, typed_sampled_worlds, wstar_diffs)
    from semmap_pp.cli.runs import run_each
    from semmap_pp.knowledge import load_rules
    from semmap_pp.run.inputs import load_inputs
    from semmap_pp.run.results import RunSettings
    from semmap_pp.studies.stability import SeedPlan

    if len(args.rules) < 2:
        print("semmap compare: error: give --rules at least twice (the knowledge sets to compare)",
              file=sys.stderr)
        return 2
    seeds = list(dict.fromkeys(args.seeds)) if args.seeds else [0 if args.seed is None else args.seed]
    paths = [Path(r) for r in args.rules]
    rule_sets = [load_rules(p) for p in paths]          # every rule file is checked before sampling
    inputs = load_inputs(args.map, model_path=args.model, rules_path=paths[0], roi_path=args.roi,
                         map_options=map_options(args))
    settings = RunSettings.from_model(inputs.model, seed=seeds[0], chains=args.chains, cores=args.cores,
                                      tune=args.tune, draws=args.draws, n_inner=args.n_inner,
                                      spread_draws=args.spread_draws)
    if settings.draws < 4:
        print("semmap compare: error: --draws must be at least 4 (R-hat and ESS need them)", file=sys.stderr)
        return 2
    if not spread_draws_ok(settings.spread_draws):
        print(f"semmap compare: error: --spread-draws {SPREAD_DRAWS_RULE}", file=sys.stderr)
        return 2

    several = len(seeds) > 1
    names = _names(paths)
    jobs = [(f"rules {path}" + (f", seed {seed}" if several else ""), dataclasses.replace(inputs, rules=rs),
             dataclasses.replace(settings, seed=seed))
            for seed in seeds for path, rs in zip(paths, rule_sets)]
    done = run_each("compare", inputs, jobs, workers=args.jobs)
    if done is None:
        return 130
    n = len(paths)
    per_seed = []        # per seed: (runs, sampled worlds, rows), rule sets in the order given
    for k in range(len(seeds)):
        runs, worlds, rows = [], [], []
        for name, path, (r, _seconds) in zip(names, paths, done[k * n:(k + 1) * n]):
            ws = typed_sampled_worlds(r, args.n_worlds)
            runs.append(r)
            worlds.append(ws)
            rows.append(summarise(r, name, path.name, ws))
        per_seed.append((runs, worlds, rows))
    tables = [compare_table(rows) for _runs, _worlds, rows in per_seed]
    cols = []
    if several:
        cols = [AcrossSeeds.of(seeds, [rows[j] for _r, _w, rows in per_seed],
                               [SeedPlan.from_semantic(seed, runs[j].semantic, runs[j].seconds)
                                for seed, (runs, _w, _rows) in zip(seeds, per_seed)])
                for j in range(n)]
        text = "\n\n".join([f"## Across seeds\n\n{across_table(cols)}"]
                            + [f"## Seed {seed}\n\n{t}" for seed, t in zip(seeds, tables)])
    else:
        text = tables[0]
    diffs = wstar_diffs(per_seed[0][0], names)
    text += "\n\n" + diffs_section(diffs, seeds[0] if several else None)
    print(text)
    if args.out is not None:
        _write(args.out, inputs, settings, seeds, per_seed, cols, text, diffs)
    return 0


def _write(out: Path, inputs, settings, seeds, per_seed, cols, text: str, diffs) -> None:
    """compare.md, compare.json and compare.png into ``out``, each path printed."""
    from semmap_pp import atomic
    from semmap_pp.outputs.figures import compare_png
    from semmap_pp.studies.compare import across_dict, compare_dict

    several = len(seeds) > 1
    out.mkdir(parents=True, exist_ok=True)
    shared = {k: getattr(settings, k) for k in ("chains", "tune", "draws", "n_inner", "anneal", "seed")}
    which = (f"seeds {', '.join(map(str, seeds))}" if several else f"seed {settings.seed}")
    head = (f"# Knowledge sets compared on {inputs.grid.source}\n\nSame map, model "
            f"({inputs.model.path.name}), {which}; {settings.chains} chains x "
            f"({settings.tune} burn-in + {settings.draws} draws) x {settings.n_inner} kernels. "
            "Log posteriors are values of different targets; CPR, spread and defects compare "
            "directly.\n\n")
    atomic.write_text(out / "compare.md", head + text + "\n")
    runs, worlds, rows = per_seed[0]
    doc = compare_dict(rows, map_path=str(inputs.grid.source), settings=shared)
    doc["wstar_diffs"] = [d.to_dict() for d in diffs]
    if several:
        doc["seeds"] = seeds
        doc["per_seed"] = [{"seed": seed, "rule_sets": compare_dict(r, map_path=doc["map"],
                                                                   settings=shared)["rule_sets"]}
                           for seed, (_r, _w, r) in zip(seeds, per_seed)]
        doc["across_seeds"] = across_dict(cols)
    atomic.write_text(out / "compare.json", json.dumps(doc, indent=1) + "\n")
    atomic.write_bytes(out / "compare.png", compare_png(runs, worlds, rows))
    for name in ("compare.md", "compare.json", "compare.png"):
        print(out / name)
