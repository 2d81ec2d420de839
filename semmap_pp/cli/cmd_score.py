"""``semmap score MAP WORLD_JSON [WORLD_JSON ...]``: the log posterior of given worlds on a map.

Each world.json (an earlier run's W*, or one edited by hand) is read onto MAP's lattice as
``semmap map --start`` reads it, its types are decided again by the knowledge engine under
``--rules``, and the full target of a run (knowledge on) scores it: log posterior, its
log-likelihood and log-prior parts, CPR (the same region of interest as ``semmap map``), units per
type. The first world is the reference; every other line gives its log posterior's difference to
it. ``--polish`` also climbs from each world by W*'s polish (the greedy ascent that ends every
run, ``ascent.polish``) and scores where it stops. Nothing is written.

The use: telling a search miss from a model preference. A world that a person sees to be right,
drawn from a run's W* by moving or joining units: when it scores above W*, the target prefers it and
the search did not find it; when below, the target itself prefers W* (the likelihood, prior or
rules, not the search, are what to change). The same world scored under two rule files shows what
each set of rules makes of it.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

from semmap_pp.cells import UNIT_TYPES
from semmap_pp.cli.options import add_map_options, add_target_options, target_inputs


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "score", help="log posterior, CPR and types of given world.json files on a map",
        description="Score world.json files (a run's W*, or one edited by hand) under the full "
                    "target of MAP: log posterior and its parts, CPR, units per type; the first "
                    "file is the reference the others are compared with.")
    p.add_argument("map", metavar="MAP", help="map_server YAML, a .png/.pgm/.npy image, or a bag (ROS 2 bag folder, .mcap, ROS 1 .bag)")
    p.add_argument("worlds", metavar="WORLD_JSON", nargs="+", type=Path,
                   help="world.json files written for MAP (by `semmap map`, edited or not)")
    add_target_options(p)
    p.add_argument("--polish", action="store_true",
                   help="also climb from each world by W*'s polish (greedy ascent) and score the result")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    add_map_options(p)
    p.set_defaults(func=run)


def score_world(inputs, post, world) -> dict:
    """The scores of one world (types decided by ``post``) as a JSON-ready dict."""
    from semmap_pp.semantic.semantic_map import semantic_map

    terms = post.evaluate(world)
    return scores_of(semantic_map(inputs.grid, inputs.frame, post, world, roi=inputs.roi, terms=terms), terms)


def scores_of(sm, terms) -> dict:
    """:func:`score_world`'s dict from a world's semantic map and its evaluated terms."""
    types = [sm.type_of(uid) for uid in sm.unit_ids]
    return {"units": len(types), "exterior": len(sm.exterior_ids),
            "types": {t: types.count(t) for t in UNIT_TYPES},
            "cpr": None if math.isnan(sm.cpr) else round(sm.cpr, 6),
            "log_posterior": round(float(terms.total), 6),
            "log_likelihood": round(float(terms.loglik), 6),
            "log_prior": round(float(terms.logprior), 6)}


def _line(name: str, s: dict, ref: float | None) -> str:
    types = "/".join(str(s["types"][t]) for t in UNIT_TYPES)
    ext = f" +{s['exterior']}X" if s["exterior"] else ""
    units = f"{s['units']} ({types}){ext}"
    cpr = "-" if s["cpr"] is None else f"{s['cpr']:.4f}"
    delta = "-" if ref is None else f"{s['log_posterior'] - ref:+,.1f}"
    return (f"{name:<32} {units:<28} {cpr:>7} {s['log_posterior']:>16,.1f} {delta:>12} "
            f"{s['log_likelihood']:>16,.1f} {s['log_prior']:>10,.1f}")


def run(args) -> int:
    from semmap_pp.sampler.ascent import polish
    from semmap_pp.sampler.kernels import data_from_frame
    from semmap_pp.run.target_factory import run_target
    from semmap_pp.plans.world_file import read_start_world

    rules, inputs = target_inputs(args)
    worlds = [(p, read_start_world(p, inputs.frame, inputs.grid, inputs.model.prior.k_max))
              for p in args.worlds]          # every file checked before any scoring
    post = run_target(inputs)
    settings = inputs.model.kernels
    data = data_from_frame(inputs.frame, settings) if args.polish else None
    rounds = max(settings.polish_rounds, 1)     # the model's rounds; 0 (polish off) still polishes
    rows = []
    for path, world in worlds:
        row = {"world": str(path), **score_world(inputs, post, world)}
        if args.polish:
            row["polished"] = score_world(inputs, post, polish(post, world, data, rounds))
        rows.append(row)
    print_scores(args, rules, inputs, rows)
    return 0


def print_scores(args, rules: Path, inputs, rows: list[dict], extra: dict | None = None) -> None:
    """The rows as one JSON object (``args.json``; with the members of ``extra`` added) or as the
    table: the first row is the reference."""
    ref = rows[0]["log_posterior"]
    if args.json:
        print(json.dumps({"map": str(args.map), "rules": str(rules), "model": args.model or "default",
                          "roi": inputs.roi_name, "worlds": rows, **(extra or {})}, indent=1))
        return
    print(f"map {args.map}, rules {rules.name}, model {Path(args.model).name if args.model else 'default.toml'}, "
          f"ROI {inputs.roi_name}; types decided again by the rules (the files' types are not read)")
    print(f"{'world':<32} {'units (room/corr/hall/other)':<28} {'CPR':>7} {'log posterior':>16} "
          f"{'vs first':>12} {'log-likelihood':>16} {'log-prior':>10}")
    for i, row in enumerate(rows):
        print(_line(_short(row["world"]), row, None if i == 0 else ref))
        if "polished" in row:
            print(_line("  polished", row["polished"], ref))


def _short(name: str, width: int = 32) -> str:
    return name if len(name) <= width else "..." + name[-(width - 3):]
