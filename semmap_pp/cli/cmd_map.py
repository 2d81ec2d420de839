"""``semmap map MAP --out DIR``: the semantic map of an occupancy grid.

Writes ``world.json`` (schema: docs/world.schema.json), ``labels.png`` (16-bit unit ids, the input
image's frame), ``trace.nc`` (ArviZ: label-invariant summaries and sampler statistics per chain and
draw) and ``diagnostics.txt`` (R-hat, ESS and the verdict). Every file is written atomically; a
non-empty DIR is refused without ``--force``. The same inputs and seed give the same world.json.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from semmap_pp.cli.cmd_info import add_map_options, map_options


def _positive_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not an integer: {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be >= 1, got {value}")
    return value


def _non_negative_int(text: str) -> int:
    value = _positive_int(text) if text.strip() != "0" else 0
    return value


def register(subparsers) -> None:
    p = subparsers.add_parser("map", help="build the semantic map of an occupancy grid",
                              description=__doc__.splitlines()[0])
    p.add_argument("map", metavar="MAP", help="map_server YAML, or a .png/.pgm/.npy image")
    p.add_argument("--out", required=True, type=Path, metavar="DIR", help="output directory")
    p.add_argument("--rules", metavar="FILE", default=None,
                   help="rule file (default rules/table3.lp; rules/none.lp = no knowledge)")
    p.add_argument("--model", metavar="FILE", default=None, help="model file (default models/default.toml)")
    p.add_argument("--roi", metavar="MASK", default=None,
                   help="region-of-interest mask image for the CPR (default: the known part, closed)")
    p.add_argument("--seed", type=_non_negative_int, default=0, help="random seed (default 0)")
    p.add_argument("--chains", type=_positive_int, default=None, help="chains (model file default)")
    p.add_argument("--cores", type=_positive_int, default=None, help="processes (model file default)")
    p.add_argument("--tune", type=_non_negative_int, default=None, help="burn-in draws per chain")
    p.add_argument("--draws", type=_positive_int, default=None, help="recorded draws per chain")
    p.add_argument("--n-inner", type=_positive_int, default=None, help="kernels per draw")
    p.add_argument("--force", action="store_true", help="write into a non-empty DIR")
    add_map_options(p)
    p.set_defaults(func=run)


def run(args) -> int:
    from semmap_pp import atomic
    from semmap_pp.diagnostics import to_datatree, write_trace
    from semmap_pp.outputs import world_dict, write_labels_png, write_world_json
    from semmap_pp.pipeline import DEFAULT_RULES, RunSettings, check_out_dir, load_inputs, run_map

    out: Path = args.out
    check_out_dir(out, args.force)
    rules = Path(args.rules) if args.rules else DEFAULT_RULES
    inputs = load_inputs(args.map, model_path=args.model, rules_path=rules, roi_path=args.roi,
                         map_options=map_options(args))
    settings = RunSettings.from_model(inputs.model, seed=args.seed, chains=args.chains, cores=args.cores,
                                      tune=args.tune, draws=args.draws, n_inner=args.n_inner)
    if settings.draws < 4:
        raise SystemExit("semmap: error: --draws must be at least 4 (R-hat and ESS need them)")

    def log(msg: str) -> None:
        print(msg, file=sys.stderr, flush=True)

    result = run_map(inputs, settings, log=log)
    out.mkdir(parents=True, exist_ok=True)
    doc = world_dict(result.semantic, rules=rules.name, model=inputs.model.path.name, seed=settings.seed,
                     roi_name=inputs.roi_name)
    written = [write_world_json(out / "world.json", doc),
               write_labels_png(out / "labels.png", result.semantic.labels_image)]
    tree = to_datatree(result.summaries, sample_stats=result.sample_stats,
                       attrs={"map": str(inputs.grid.source), "rules": rules.name, "seed": settings.seed,
                              "chains": settings.chains, "tune": settings.tune, "draws": settings.draws,
                              "n_inner": settings.n_inner})
    written.append(write_trace(tree, out / "trace.nc"))
    text = (f"map: {inputs.grid.source}\nrules: {rules}\nmodel: {inputs.model.path}\n"
            f"seed: {settings.seed}; sampling took {result.seconds:.1f} s "
            f"({result.kernels_per_second:.0f} kernels/s)\n"
            f"W*: {len(result.semantic.unit_ids)} units, log posterior {result.semantic.log_posterior:.2f}, "
            f"CPR {result.semantic.cpr:.4f} (ROI {inputs.roi_name})\n\n{result.report.to_text()}\n")
    atomic.write_text(out / "diagnostics.txt", text)
    written.append(out / "diagnostics.txt")
    for path in written:
        print(path)
    return 0
