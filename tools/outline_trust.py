"""How well does the building's outline hold a world's building? The share behind `exterior_outline_trust_min`.

    .venv/bin/python tools/outline_trust.py MAP WORLD_JSON [WORLD_JSON ...] [--model FILE] [--json]

For each world (a world.json of `semmap map`, or of `bench/run.py quality --save DIR`), read onto
MAP's lattice as `semmap score` reads it, and for each tile of the lattice (one on a map of one
direction): the share of the cells of its units enclosed by walls of their own on three sides
that lie within the building's outline (:func:`semmap_pp.derive.exterior.outline_share`). A map
whose walls close the building gives nearly 1; a map explored in part, whose rooms were seen only
through their doors, much less. `[world] exterior_outline_trust_min` of models/default.toml is
the least share at which the outline flags a fan that the hull of the enclosed units spans.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from semmap_pp.cli.options import add_map_options, add_target_options, target_inputs  # noqa: E402


def shares(inputs, world) -> list:
    """The outline share of each tile of ``inputs.frame`` under ``world`` (None: no such unit)."""
    from semmap_pp import world as wm
    from semmap_pp.derive import _tile_groups
    from semmap_pp.derive.exterior import outline_share
    frame = inputs.frame
    c = frame.cells
    rects = world.rects[wm.active_slots(world)]
    seen = getattr(frame, "seen_classes", frame.classes)
    out = []
    for group in _tile_groups(frame, rects):
        s = outline_share(seen, rects[group], c.wall, c.exterior_max_share, c.exterior_seen_min,
                          c.exterior_outline_gap, c.object_max_extent)
        out.append(None if s is None else round(s, 3))
    return out


def main(argv=None) -> int:
    from semmap_pp.plans.world_file import read_start_world
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("map")
    parser.add_argument("worlds", nargs="+", type=Path)
    add_target_options(parser)
    add_map_options(parser)
    parser.add_argument("--json", action="store_true", help="one JSON object instead of lines")
    args = parser.parse_args(argv)
    _rules, inputs = target_inputs(args)
    rows = {}
    for path in args.worlds:
        world = read_start_world(path, inputs.frame, inputs.grid, inputs.model.prior.k_max)
        rows[str(path)] = shares(inputs, world)
    if args.json:
        print(json.dumps({"map": args.map, "tiles": rows}))
    else:
        for path, values in rows.items():
            print(path, " ".join("-" if v is None else f"{v:.3f}" for v in values))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
