"""``semmap stability MAP [--seeds N N ...] [--out DIR]``: is W* the same plan whatever the seed?

Runs ``semmap map``'s search once per seed (default 0 1 2) with the same map, model, rules and run
lengths, without the sample around W* (it never changes W*), and compares the W*s
(:mod:`semmap_pp.studies.stability`): the unit F1 between every two of them, and for each unit of the
best one (highest log posterior) in how many of the others it is found (IoU >= 0.5) and with which
type. Prints a Markdown table; with ``--out DIR`` also writes ``stability.md``, ``stability.json``
and ``stability.png`` (the best W*'s units coloured by agreement), each atomically. Ctrl-C stops
and writes nothing (exit 130).
"""

from __future__ import annotations

import dataclasses
import json
import sys
from pathlib import Path

from semmap_pp.cli.argtypes import seed as seed_type
from semmap_pp.cli.options import add_map_options, add_run_length_options, add_target_options, target_inputs
from semmap_pp.cli.runs import add_jobs_option


def register(subparsers) -> None:
    p = subparsers.add_parser("stability", help="search one map with several seeds and compare the W*s",
                              description=__doc__.splitlines()[0])
    p.add_argument("map", metavar="MAP", help="map_server YAML, a .png/.pgm/.npy image, or a bag (ROS 2 bag folder, .mcap, ROS 1 .bag)")
    p.add_argument("--seeds", type=seed_type, nargs="+", default=[0, 1, 2], metavar="N",
                   help="the seeds, at least two different ones (default 0 1 2)")
    p.add_argument("--out", type=Path, metavar="DIR",
                   help="also write stability.md, stability.json, stability.png")
    add_target_options(p)
    add_run_length_options(p)
    add_jobs_option(p)
    p.add_argument("--force", action="store_true", help="write into a non-empty DIR")
    p.add_argument("--json", action="store_true",
                   help="print stability.json's object (one line) instead of the table")
    add_map_options(p)
    p.set_defaults(func=run)


def run(args) -> int:
    from semmap_pp.run.outdir import claimed

    with claimed(args.out, args.force):    # checked and held before any sampling
        return _run(args)


def _run(args) -> int:
    from semmap_pp import atomic
    from semmap_pp.cli.runs import run_each
    from semmap_pp.outputs.figures import stability_png
    from semmap_pp.run.results import RunSettings
    from semmap_pp.studies.stability import SeedPlan, Stability

    seeds = list(dict.fromkeys(args.seeds))
    if len(seeds) < 2:
        print("semmap stability: error: give at least two different --seeds", file=sys.stderr)
        return 2
    rules, inputs = target_inputs(args)
    settings = RunSettings.from_model(inputs.model, seed=seeds[0], chains=args.chains, cores=args.cores,
                                      tune=args.tune, draws=args.draws, n_inner=args.n_inner,
                                      spread_draws=0)
    if settings.draws < 4:
        print("semmap stability: error: --draws must be at least 4 (R-hat and ESS need them)",
              file=sys.stderr)
        return 2

    done = run_each("stability", inputs, [(f"seed {seed}", inputs, dataclasses.replace(settings, seed=seed))
                                          for seed in seeds], workers=args.jobs)
    if done is None:
        return 130
    plans = [SeedPlan.from_semantic(seed, r.semantic, seconds) for seed, (r, seconds) in zip(seeds, done)]
    semantic = [r.semantic for r, _ in done]
    result = Stability.of(plans)
    table = result.table()
    doc = result.to_dict()
    doc.update(map=str(inputs.grid.source), model=str(inputs.model.path), rules=str(rules),
               settings={k: getattr(settings, k) for k in ("chains", "tune", "draws", "n_inner", "anneal")})
    print(json.dumps(doc) if args.json else table)
    if args.out is not None:
        out = args.out
        out.mkdir(parents=True, exist_ok=True)
        head = (f"# W* of {inputs.grid.source} with {len(seeds)} seeds\n\nSame map, model "
                f"({inputs.model.path.name}) and rules ({rules.name}); "
                f"{settings.chains} chains x ({settings.tune} burn-in + {settings.draws} draws) x "
                f"{settings.n_inner} kernels per seed, no sample around W*.\n\n")
        order = [p.seed for p in (result.reference, *result.others)]
        atomic.write_text(out / "stability.md", head + table + "\n")
        atomic.write_text(out / "stability.json", json.dumps(doc, indent=1) + "\n")
        atomic.write_bytes(out / "stability.png", stability_png(semantic[result.ref], result.units, order))
        for n in ("stability.md", "stability.json", "stability.png"):
            print(out / n)
    return 0
