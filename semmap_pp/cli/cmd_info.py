"""``semmap info MAP [--json]``: what a map file holds and how its cells classify.

The map options (``--occupied-thresh``, ``--free-thresh``, ``--negate``, ``--resolution``,
``--mode``, ``--max-cells``, and a bag's ``--topic`` and ``--at``) are the shared ones of
:mod:`semmap_pp.cli.options`.
"""

from __future__ import annotations

import argparse
import json
import math

from semmap_pp.cells import INPUT_CLASSES, known_box
from semmap_pp.cli.options import add_map_options, map_options
from semmap_pp.grid import OccupancyGrid, load_map
from semmap_pp.grid.outside import border_open_share, seal_radius
from semmap_pp.model import OutsideParams


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "info", help="describe a map: size, resolution, origin, thresholds, cell counts",
        description="Load a map (map_server YAML, .png, .pgm, .npy or a bag's OccupancyGrid) and describe it.")
    parser.add_argument("map", help="map file: .yaml/.yml (map_server), .png, .pgm, .npy, or a bag "
                                    "(ROS 2 bag folder, .mcap, ROS 1 .bag)")
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    parser.add_argument("--orientation", action="store_true",
                        help="also the lattice's orientation θ0 and the walls at another angle, as "
                             "`semmap map` finds them (seconds on a large map)")
    parser.add_argument("--model", metavar="FILE",
                        help="model file for --orientation (default models/default.toml)")
    add_map_options(parser)
    parser.set_defaults(func=run)


def describe(grid: OccupancyGrid) -> dict:
    """The facts ``semmap info`` prints, as a JSON-ready dict."""
    counts = grid.counts()
    total = grid.classes.size
    width_m, height_m = grid.size_m
    return {
        "map": str(grid.source) if grid.source else None,
        "image": str(grid.image_path) if grid.image_path else None,
        "image_format": grid.image_format,
        "width": grid.width,
        "height": grid.height,
        "width_m": width_m,
        "height_m": height_m,
        "resolution": grid.resolution,
        "origin": list(grid.origin),
        "mode": grid.mode,
        "negate": int(grid.negate),
        "occupied_thresh": grid.occupied_thresh,
        "free_thresh": grid.free_thresh,
        "counts": counts,
        "fractions": {name: counts[name] / total for name in INPUT_CLASSES},
        # at the default model's [outside] border_open_min or above, `semmap map` reads the
        # outside as unknown (semmap_pp.grid.outside)
        "border_open": border_open_share(grid.classes,
                                         seal_radius(OutsideParams.seal_gap_m, grid.resolution)),
        # the known cells' bounding box: `semmap map` works on it and [lattice] crop_margin_m
        # around it when the rest is most of the image (docs/model.md)
        "known_box": list(box) if (box := known_box(grid.classes)) is not None else None,
        "notes": list(grid.notes),
        "topic": grid.topic,            # a bag's map: its topic, frame and header stamp
        "frame_id": grid.frame_id,
        "stamp_ns": grid.stamp_ns,
    }


def format_text(facts: dict) -> str:
    """Human-readable lines of :func:`describe`'s dict."""
    ox, oy, yaw = facts["origin"]
    lines = [
        f"map         {facts['map']}",
        f"image       {facts['image']} ({facts['image_format']})" if facts["image"] is not None else
        f"input       {facts['image_format']}",
        f"size        {facts['width']} x {facts['height']} cells, "
        f"{facts['width_m']:.2f} x {facts['height_m']:.2f} m",
        f"resolution  {facts['resolution']:g} m/cell",
        f"origin      x {ox:g} m, y {oy:g} m, yaw {yaw:g} rad",
        f"mode        {facts['mode']} (negate {facts['negate']})",
        f"thresholds  occupied > {facts['occupied_thresh']:g}, free < {facts['free_thresh']:g}",
    ]
    for name in INPUT_CLASSES:
        lines.append(f"{name:<11} {facts['counts'][name]:>10d} cells  "
                     f"{100.0 * facts['fractions'][name]:6.2f} %")
    lines.append(f"border      {100.0 * facts['border_open']:6.2f} % of the border cells open free space"
                 + (" (the outside is shown as free: see [outside] in the model file)"
                    if facts["border_open"] >= OutsideParams.border_open_min else ""))
    box = facts["known_box"]
    if box is not None:
        r0, c0, r1, c1 = box
        share = (r1 - r0) * (c1 - c0) / max(facts["width"] * facts["height"], 1)
        lines.append(f"known part  {c1 - c0} x {r1 - r0} cells from column {c0}, row {r0} "
                     f"({100.0 * share:.1f} % of the image)")
    if len(facts.get("orientations_deg", ())) > 1:
        shares = ", ".join(f"{a:.1f} deg ({100.0 * w:.0f} %)"
                           for a, w in zip(facts["orientations_deg"], facts["direction_shares"]))
        lines.append(f"directions  {shares} of the walls: a lattice each, every unit's walls "
                     f"run along or across its own")
    elif "orientation_deg" in facts:
        lines.append(f"orientation {facts['orientation_deg']:.1f} deg (the lattice's: every unit's walls "
                     f"run along it or across it)")
    if "orientation_deg" in facts and len(facts.get("orientations_deg", ())) <= 1:
        off = facts["off_axis"]
        if off["share"] > 0:
            x0, y0, x1, y1 = off["box_px"]
            lines.append(f"off axis    {100.0 * off['share']:.0f} % of the occupied cells run at about "
                         f"{off['angle_deg']:.0f} deg, within pixels x {x0}-{x1}, y {y0}-{y1}"
                         + (" (a note in `semmap map`: `semmap crop` cuts such a wing out)"
                            if off["note"] else ""))
        else:
            lines.append("off axis    no part of the map runs at another angle")
    if facts.get("topic"):
        lines.append(f"message     {facts['topic']}, frame {facts['frame_id']!r}, stamp "
                     f"{facts['stamp_ns'] // 10**9}.{facts['stamp_ns'] % 10**9:09d} s")
    lines += [f"note        {note}" for note in facts["notes"]]
    return "\n".join(lines)


def orientation(grid: OccupancyGrid, model) -> dict:
    """θ0 of the lattice ``semmap map`` would build (degrees), the building's directions and their
    shares of the walls (:func:`semmap_pp.lattice.zones.building_zones`, counted on the wall faces:
    a lattice each when there are several) and the walls at another angle
    (:func:`semmap_pp.lattice.frame.off_axis_walls`; ``note``: whether the run would say so)."""
    from semmap_pp.lattice.frame import lattice_orientation, off_axis_noted, off_axis_walls
    from semmap_pp.lattice.zones import building_zones

    params = model.lattice
    theta = lattice_orientation(grid.classes, params)
    off = off_axis_walls(grid.classes, theta, grid.resolution, params)
    share = float(off.share)
    zones = building_zones(grid.classes, grid.resolution, params, theta)
    return {"orientation_deg": math.degrees(theta),
            "orientations_deg": [math.degrees(t) for t in zones.thetas],
            "direction_shares": [float(w) for w in zones.shares],
            "off_axis": {"share": share, "angle_deg": None if off.blocks == 0 else off.angle_deg,
                         "box_px": None if off.box_px is None else list(off.box_px),
                         "note": off_axis_noted(share, params) and len(zones.thetas) == 1}}


def run(args: argparse.Namespace) -> int:
    grid = load_map(args.map, **map_options(args))
    facts = describe(grid)
    if args.orientation:
        from semmap_pp.model import load_model
        facts |= orientation(grid, load_model(args.model))
    print(json.dumps(facts) if args.json else format_text(facts))
    return 0
