"""``semmap edit MAP WORLD_JSON --out DIR [edits ...]``: a world.json changed by hand, by id and point.

The plan a person knows better than the search, said in the outputs' own terms: units by the id
world.json and overlay.png give them, places by points read off the map (map-frame metres, or
image pixels with ``--pixels``). The edits (``--drop``, ``--merge``, ``--cut``, ``--wall``,
``--add``; :mod:`semmap_pp.plans.edit`) apply in the order given; then every wall is set on the
lattice's best position within ``--snap`` metres (``ascent.snap_walls``; 0 keeps them as given),
the types are decided again under ``--rules``, and the result is written into DIR as ``semmap map``
writes a W*'s plan: world.json (for ``semmap map MAP --start``, ``semmap score`` and the next
edit), labels.png, regions.png, the types layer, world.geojson, graph.graphml, overlay.png and
graph.png; no trace, diagnostics or report (nothing was sampled). Both worlds' scores are
printed, as ``semmap score`` prints them. Nothing is written when an edit cannot be made.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from semmap_pp.cli.argtypes import non_negative_float
from semmap_pp.cli.options import add_map_options, add_target_options, target_inputs
from semmap_pp.cli.cmd_score import print_scores, score_world, scores_of
from semmap_pp.errors import OutputError
from semmap_pp.plans.edit import Edit
from semmap_pp.plans.places import unit_key


#: How far (metres) the edited units' walls may move to the map's best position: a point read off
#: a map is a few centimetres off the wall it means (10 cells at 0.05 m).
SNAP_M = 0.5


class _Edits(argparse.Action):
    """Collect every edit option into ``args.edits`` in command-line order."""

    def __call__(self, parser, namespace, values, option_string=None):
        edits = list(getattr(namespace, "edits", None) or [])
        edits.append(Edit(self.dest.removeprefix("edit_"), tuple(values)))
        namespace.edits = edits


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "edit", help="change a world.json by hand (drop, merge, cut, move a wall, add) and score it",
        description="Edit a world.json (a run's W*) by unit id and map point, in the order given; "
                    "walls are then set on the map's best positions nearby, the types decided again, "
                    "and the result written as a world.json for `semmap map --start` and `semmap "
                    "score`. Points are map-frame metres (as vertices_m), or image pixels "
                    "[x = column, y = row] with --pixels. Ids as world.json and overlay.png give "
                    "them: 7 or R7/C7/H7/E7; X2 for exterior unit 2.")
    p.add_argument("map", metavar="MAP", help="map_server YAML, a .png/.pgm/.npy image, or a bag (ROS 2 bag folder, .mcap, ROS 1 .bag)")
    p.add_argument("world", metavar="WORLD_JSON", type=Path, help="a world.json written for MAP")
    p.add_argument("--out", type=Path, required=True, metavar="DIR",
                   help="output directory: world.json, labels.png, overlay.png and the other files of "
                        "the plan (not WORLD_JSON's own directory)")
    p.add_argument("--force", action="store_true", help="write into a non-empty DIR")
    g = p.add_argument_group("edits (applied in the order given; each may be repeated)")
    g.add_argument("--drop", dest="edit_drop", nargs="+", action=_Edits, metavar="ID", default=argparse.SUPPRESS,
                   help="remove the units")
    g.add_argument("--merge", dest="edit_merge", nargs="+", action=_Edits, metavar="ID", default=argparse.SUPPRESS,
                   help="replace two or more units by their bounding box (the first one's id)")
    g.add_argument("--cut", dest="edit_cut", nargs=5, action=_Edits, metavar=("ID", "X0", "Y0", "X1", "Y1"),
                   default=argparse.SUPPRESS,
                   help="cut a unit in two by a wall along the line X0,Y0 - X1,Y1 (snapped to the lattice)")
    g.add_argument("--wall", dest="edit_wall", nargs=3, action=_Edits, metavar=("ID", "X", "Y"),
                   default=argparse.SUPPRESS, help="move the unit's side nearest to X,Y onto X,Y")
    g.add_argument("--add", dest="edit_add", nargs=4, action=_Edits, metavar=("X0", "Y0", "X1", "Y1"),
                   default=argparse.SUPPRESS, help="a new unit whose walls run through the two opposite corners")
    p.add_argument("--pixels", action="store_true",
                   help="points are image pixels [x = column, y = row from the top], not metres")
    p.add_argument("--snap", type=non_negative_float, default=SNAP_M, metavar="M",
                   help=f"move each wall of the edited units to its best position within M metres "
                        f"(default {SNAP_M}; 0 keeps the walls where the edits put them)")
    p.add_argument("--ids-from", type=Path, metavar="WORLD_JSON",
                   help="number the units as this world.json does where they are the same place (IoU >= "
                        "0.5), the others with ids it never used; give WORLD_JSON itself to keep its ids")
    add_target_options(p)
    p.add_argument("--json", action="store_true", help="print one JSON object instead of the table")
    add_map_options(p)
    p.set_defaults(func=run, edits=[])


def run(args) -> int:
    from semmap_pp.run.outdir import claimed

    if not args.edits:
        raise OutputError(args.out, "no edit given (--drop, --merge, --cut, --wall, --add); nothing written")
    with claimed(args.out, args.force):    # checked, and held until its files are written
        return _run(args)


def _run(args) -> int:
    from semmap_pp.sampler.ascent import snap_walls
    from semmap_pp.sampler.kernels import data_from_frame
    from semmap_pp.cells import TYPE_LETTER
    from semmap_pp.semantic.semantic_map import semantic_map
    from semmap_pp.semantic.world_json import world_dict, write_labels_png, write_world_json
    from semmap_pp.outputs.write import write_plan
    from semmap_pp.run.target_factory import run_target
    from semmap_pp.plans.edit import apply_edits, edit_origins, id_changes
    from semmap_pp.plans.world_file import pack_world, read_previous_ids, read_world_units, through_door_keys

    if args.out.is_dir() and args.world.parent.resolve() == args.out.resolve():
        raise OutputError(args.out, "is the directory of WORLD_JSON: its run's other files (trace.nc, "
                                    "report.html) would not match the edited world; write to another "
                                    "directory")
    previous = read_previous_ids(args.ids_from) if args.ids_from is not None else None
    rules, inputs = target_inputs(args)
    k_max = inputs.model.prior.k_max
    units = read_world_units(args.world, inputs.frame, inputs.grid)
    before = pack_world([r for _, r in units], k_max, args.world)
    edited = apply_edits(units, args.edits, inputs.frame, pixels=args.pixels, path=args.world)
    world = pack_world([r for _, r, _ in edited], k_max, args.world)
    post = run_target(inputs)
    reach = int(round(args.snap / inputs.frame.resolution))
    if reach > 0:
        settings = inputs.model.kernels
        world = snap_walls(post, world, data_from_frame(inputs.frame, settings),
                           [i for i, (_, _, changed) in enumerate(edited) if changed], reach=reach)
    terms = post.evaluate(world)
    flagged = through_door_keys(args.world)   # an edited unit is no longer the one added over a fan
    sm = semantic_map(inputs.grid, inputs.frame, post, world, roi=inputs.roi, terms=terms, previous=previous,
                      through_door=[i for i, (k, _, changed) in enumerate(edited) if k in flagged and not changed])
    rows = [{"world": str(args.world), **score_world(inputs, post, before)},
            {"world": str(args.out / "world.json"), **scores_of(sm, terms)}]
    doc = world_dict(sm, rules=rules.name, model=inputs.model.path.name, seed=None, roi_name=inputs.roi_name)
    ids = id_changes(edited, edit_origins(args.edits), sm.slot_ids, sm.exterior_ids,
                     {s: TYPE_LETTER[sm.type_of(u)] for s, u in sm.slot_ids.items()})
    if sm.id_record is not None:
        ids = carried_rows(ids, sm.id_record)
    doc["edited"] = {"from": str(args.world), "edits": [str(e) for e in args.edits], "snap_m": args.snap,
                     "ids": ids}
    args.out.mkdir(parents=True, exist_ok=True)
    write_world_json(args.out / "world.json", doc)
    write_labels_png(args.out / "labels.png", sm.labels_image)
    write_plan(args.out, sm, doc)
    print_scores(args, rules, inputs, rows, extra={"ids": ids})
    if not args.json:
        kept = {r["was"] for r in ids}
        print(ids_text(ids, args.out / "world.json", gone=[k for k, _ in units if k not in kept],
                       carried_from=args.ids_from))
    return 0


def carried_rows(ids: list[dict], record: dict) -> list[dict]:
    """:func:`~semmap_pp.plans.edit.id_changes` rows after ``--ids-from``: a unit an edit made
    that carried an id (the piece of a cut that is most of the unit it came from) continues that
    unit, so its ``was`` is the id (its ``by`` still names the edit).

    >>> carried_rows([{"was": None, "now": "C1", "by": "--cut 1 0 0 1 1"}, {"was": None, "now": "E21",
    ...               "by": "--cut 1 0 0 1 1"}, {"was": None, "now": "X1", "by": None}], {"carried": [1]})
    ... # doctest: +NORMALIZE_WHITESPACE
    [{'was': '1', 'now': 'C1', 'by': '--cut 1 0 0 1 1'}, {'was': None, 'now': 'E21', 'by': '--cut 1 0 0 1 1'},
     {'was': None, 'now': 'X1', 'by': None}]
    """
    carried = {str(i) for i in record["carried"]}
    out = []
    for r in ids:
        num = unit_key(r["now"])          # "C1" -> "1"; an exterior "X1" stays itself
        if r["was"] is None and num in carried:
            r = {**r, "was": num}
        out.append(r)
    return out


def ids_text(ids: list[dict], path, gone=(), carried_from=None) -> str:
    """The units of the written world.json whose id is not the one they had, the new ones with
    the edit that made them, and the ids ``gone`` (dropped, merged away or cut); ``semmap edit``
    prints it after the scores. ``carried_from``: the world.json the ids were carried from
    (``--ids-from``), named in the heading.

    >>> print(ids_text([{"was": None, "now": "R1", "by": "--add 1 2 3 4"}, {"was": "1", "now": "C2", "by": None},
    ...                 {"was": "3", "now": "R3", "by": None}], "w.json", gone=["2"]))
    ids in w.json (each world.json numbers its units afresh, in reading order):
      1 -> C2
      new R1: --add 1 2 3 4
      gone: 2
      every other unit keeps its id
    """
    how = ("each world.json numbers its units afresh, in reading order" if carried_from is None
           else f"ids carried from {carried_from} where a unit is the same place")
    lines = [f"ids in {path} ({how}):"]
    kept = [r for r in ids if r["was"] is not None]
    moved = [f"{r['was']} -> {r['now']}" for r in kept if r["was"] != unit_key(r["now"])]
    line = ""
    for item in moved:                       # items never split across lines
        if line and len(line) + 2 + len(item) > 98:
            lines.append("  " + line)
            line = ""
        line = f"{line}, {item}" if line else item
    if line:
        lines.append("  " + line)
    made: dict = {}
    for r in ids:
        if r["was"] is None:
            made.setdefault(r["by"], []).append(r["now"])
    lines += [f"  new {', '.join(now)}: {by}" for by, now in made.items()]
    if gone:
        lines.append(f"  gone: {', '.join(gone)}")
    if len(moved) < len(kept):
        lines.append("  every other unit keeps its id" if len(lines) > 1 else "  every unit keeps its id")
    return "\n".join(lines)
