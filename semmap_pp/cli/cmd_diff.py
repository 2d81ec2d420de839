"""``semmap diff OLD NEW``: what changed between two world.json files (:mod:`semmap_pp.plans.diff`).

OLD and NEW are each a world.json or a run's folder. Units are paired by where they are, not by id;
the command lists the units retyped, moved, removed and added, and the doors and passages removed
or added. Exit status as diff(1): 0 when both hold the same plan, 1 when they differ, 2 for a file
that cannot be read (one line naming it).
"""

from __future__ import annotations

import json
from pathlib import Path

from semmap_pp.cli.argtypes import non_negative_float


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "diff", help="what changed between two world.json files (units, types, doors)",
        description="Pair the units of two world.json files by where they are (intersection over "
                    "union of their rectangles in map metres, at least 0.5) and list the units "
                    "retyped, moved, removed and added, and the doors and passages removed or added: "
                    "after the map grew, a rule file or the model changed, or a hand edit. Exit "
                    "status 0 when both hold the same plan, 1 when they differ.")
    p.add_argument("old", metavar="OLD", help="a world.json, or a run's folder holding one")
    p.add_argument("new", metavar="NEW", help="a world.json, or a run's folder holding one")
    p.add_argument("--tolerance", type=non_negative_float, default=None, metavar="METRES",
                   help="a unit is moved when a corner shifts farther than this (default 0.1)")
    p.add_argument("--all", action="store_true", help="list the unchanged units too")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument("--png", type=Path, metavar="FILE",
                   help="also draw both plans, coloured by change, in map metres (a PNG file)")
    p.set_defaults(func=run)


def run(args) -> int:
    from semmap_pp.plans.places import read_places
    from semmap_pp.plans.diff import TOLERANCE_M, diff_worlds

    tolerance = TOLERANCE_M if args.tolerance is None else args.tolerance
    diff = diff_worlds(read_places(args.old), read_places(args.new), tolerance_m=tolerance)
    if args.png is not None:      # written first: a figure that cannot be written prints nothing
        from semmap_pp import atomic
        from semmap_pp.errors import OutputError
        from semmap_pp.outputs.figures import diff_png

        try:
            atomic.write_bytes(args.png, diff_png(diff))
        except OSError as exc:
            raise OutputError(args.png, f"cannot write the figure: {exc.strerror or exc}") from None
    print(json.dumps(diff.to_dict()) if args.json else diff.text(all_units=args.all))
    if args.png is not None and not args.json:
        print(args.png)
    return 0 if diff.same else 1
