"""``semmap where WORLD X Y`` and ``semmap route WORLD FROM TO``: the unit at a map point, and the
doors and passages from one place to another (:mod:`semmap_pp.plans.places`).

WORLD is a world.json or a run's folder. Points are map-frame metres (as tf gives a robot's pose
in ``map``). FROM and TO are each a unit id as overlay.png shows it (``7``, ``R7``) or a point
``X,Y``. ``--json`` prints one JSON object instead of text. A point that no unit holds, or two
places no chain of openings joins, is said on stderr with exit status 1; a broken file is one line
naming it, exit 2.
"""

from __future__ import annotations

import json
import math
import sys

from semmap_pp.cli.argtypes import finite


def register(subparsers) -> None:
    where = subparsers.add_parser(
        "where", help="the unit of a world.json that holds a map point",
        description="Print the unit (room, corridor, hall, other) whose rectangle holds the map "
                    "point X Y (metres, the map frame), with its doors and passages. A point on "
                    "the wall two units share lies in both.")
    where.add_argument("world", help="a world.json, or a run's folder holding one")
    where.add_argument("x", type=finite, help="map-frame x (metres)")
    where.add_argument("y", type=finite, help="map-frame y (metres)")
    where.add_argument("--json", action="store_true", help="print one JSON object")
    where.set_defaults(func=run_where)

    route = subparsers.add_parser(
        "route", help="the doors and passages from one unit or point to another",
        description="Print the shortest route through doors and passages between two places of a "
                    "world.json: straight segments from opening centre to opening centre, each "
                    "inside one unit (furniture is not avoided). FROM and TO are unit ids (7, R7) "
                    "or map points X,Y in metres.")
    route.add_argument("world", help="a world.json, or a run's folder holding one")
    route.add_argument("start", metavar="FROM", help="unit id (7, R7) or map point X,Y (metres)")
    route.add_argument("goal", metavar="TO", help="unit id (7, R7) or map point X,Y (metres)")
    route.add_argument("--json", action="store_true", help="print one JSON object")
    route.set_defaults(func=run_route)


def _place(places, text: str):
    """A unit (by id) or a point ``X,Y`` as :meth:`Places.route` takes it."""
    from semmap_pp.errors import SemmapError

    if "," in text:
        parts = text.split(",")
        try:
            xy = tuple(float(v) for v in parts)
        except ValueError:
            xy = ()
        if len(xy) != 2 or not all(math.isfinite(v) for v in xy):
            raise SemmapError(places.path, f"{text!r} is not a map point X,Y (two numbers in metres)")
        return xy
    return places.unit(text)


def _unit_dict(places, u) -> dict:
    length, width = u.size_m
    out = {"id": u.key if u.exterior else int(u.key), "label": u.label, "type": u.type,
           "exterior": u.exterior, "size_m": [round(length, 4), round(width, 4)]}
    if not u.exterior:
        out["openings"] = [{"kind": o.kind, "id": o.id, "to": int(o.other(u.key)), "width_m": o.width_m,
                            "center_m": list(o.center)} for o in places.openings_of(u.key)]
    return out


def _unit_text(places, u) -> str:
    length, width = u.size_m
    if u.exterior:
        return f"{u.label}: exterior unit (free space seen outside the building), {length:.2f} x {width:.2f} m"
    by = {u2.key: u2 for u2 in places.units}
    ways = [f"{o.kind} {o.id} to {by[o.other(u.key)].label}" for o in places.openings_of(u.key)]
    return (f"{u.label}: {u.type}, {length:.2f} x {width:.2f} m; "
            + (", ".join(ways) if ways else "no door or passage"))


def _passages_note(places) -> str | None:
    if places.has_passages:
        return None
    return (f"note: {places.path} lists no passages (written before world.json held them): open "
            f"walls between units are not known, routes use doors only")


def run_where(args) -> int:
    from semmap_pp.plans.places import read_places

    places = read_places(args.world)
    found = places.units_at(args.x, args.y)
    if args.json:
        print(json.dumps({"point_m": [args.x, args.y], "units": [_unit_dict(places, u) for u in found]}))
    else:
        for u in found:
            print(_unit_text(places, u))
    note = _passages_note(places)
    if note and not args.json:
        print(note, file=sys.stderr)
    if not found:
        print(f"semmap: no unit of {places.path} holds the point {args.x:g} {args.y:g}", file=sys.stderr)
        return 1
    return 0


def run_route(args) -> int:
    from semmap_pp.plans.places import read_places

    places = read_places(args.world)
    start, goal = _place(places, args.start), _place(places, args.goal)
    route = places.route(start, goal)
    note = _passages_note(places)
    if note:
        print(note, file=sys.stderr)
    if route is None:
        print(f"semmap: no route from {args.start} to {args.goal} through the doors and passages of "
              f"{places.path} (they lie in parts of the map no opening joins)", file=sys.stderr)
        return 1
    print(json.dumps(route.to_dict()) if args.json else route.text())
    return 0
