"""``semmap crop MAP --box X0 Y0 X1 Y1 --out NAME.yaml [--force]``: a part of a map, as a map.

Writes ``NAME.yaml`` + ``NAME.pgm`` (map_server, trinary) holding the pixels ``X0 <= x < X1``,
``Y0 <= y < Y1`` of MAP (x the column, y the row from the top, as every pixel coordinate the
project writes), classified as ``semmap map`` reads them. The origin is moved so that every cell
keeps its map-frame position: the units of a run on the crop have the same ``vertices_m`` as they
would on the whole map, so the runs of several crops can be put side by side. The use: a building
with a wing at another angle than the rest (the run's note names the pixels of that part;
docs/robustness.md), each part mapped on its own lattice.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

from semmap_pp.cli.argtypes import non_negative_int
from semmap_pp.cli.options import add_map_options, map_options
from semmap_pp.errors import MapError, OutputError
from semmap_pp.grid import load_map
from semmap_pp.grid.write import classes_to_image, write_map


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "crop", help="write a part of a map as a map (the map frame kept)",
        description="Write the pixels X0 <= x < X1, Y0 <= y < Y1 of MAP as a map_server map whose "
                    "origin keeps every cell's map-frame position (e.g. one wing of a building "
                    "built at another angle, which the run's note locates).")
    parser.add_argument("map", help="map file: .yaml/.yml (map_server), .png, .pgm, .npy, or a bag")
    parser.add_argument("--box", type=non_negative_int, nargs=4, required=True,
                        metavar=("X0", "Y0", "X1", "Y1"),
                        help="pixel columns X0..X1-1 and rows Y0..Y1-1 (row 0 at the top)")
    parser.add_argument("--out", type=Path, required=True, metavar="NAME.yaml",
                        help="the YAML to write; the image goes beside it as NAME.pgm")
    parser.add_argument("--force", action="store_true", help="overwrite NAME.yaml and NAME.pgm")
    add_map_options(parser)
    parser.set_defaults(func=run)


def crop_origin(grid, x0: int, y1: int) -> tuple[float, float, float]:
    """The map-frame origin of the crop whose left column is ``x0`` and whose bottom row is
    ``y1 - 1``: the whole map's origin moved by ``(x0, H - y1)`` cells along the image's axes
    (rotated by the origin's yaw, as ROS places the image)."""
    ox, oy, yaw = grid.origin
    du, dv = x0 * grid.resolution, (grid.height - y1) * grid.resolution
    c, s = math.cos(yaw), math.sin(yaw)
    return ox + c * du - s * dv, oy + s * du + c * dv, yaw


def run(args) -> int:
    out: Path = args.out
    if out.suffix.lower() not in (".yaml", ".yml"):
        raise OutputError(out, "--out must name a .yaml file (the image is written beside it as .pgm)")
    grid = load_map(args.map, **map_options(args))
    x0, y0, x1, y1 = args.box
    if not (x0 < x1 <= grid.width and y0 < y1 <= grid.height):
        raise MapError(grid.source or args.map,
                       f"--box {x0} {y0} {x1} {y1} is not a non-empty part of the "
                       f"{grid.width} x {grid.height} pixel map (need X0 < X1 <= {grid.width}, "
                       f"Y0 < Y1 <= {grid.height})")
    if not args.force:
        for p in (out, out.with_suffix(".pgm")):
            if p.exists():
                raise OutputError(p, "exists (use --force to overwrite)")
    image = classes_to_image(grid.classes[y0:y1, x0:x1])
    try:
        written = write_map(out, image, grid.resolution, crop_origin(grid, x0, y1))
    except ValueError as exc:    # a path write_map refuses
        raise OutputError(out, str(exc)) from None
    for note in grid.notes:    # what loading assumed (a bare image's resolution): now in the YAML
        print(f"note: {note}", file=sys.stderr)
    print(written)
    print(f"{x1 - x0} x {y1 - y0} cells; pixel (x, y) of the crop is pixel (x + {x0}, y + {y0}) of "
          f"{args.map}, at the same map-frame position")
    return 0
