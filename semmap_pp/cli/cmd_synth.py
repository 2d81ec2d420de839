"""``semmap synth --seed N --out DIR [--units K] [--rotation DEG] [--wings W [--wing-angle DEG]]
[--force]``: a synthetic floor.

Writes ``map.yaml`` + ``map.pgm`` (the occupancy grid), ``truth.json`` and ``truth_labels.png``
(its ground truth, see ``docs/synthetic.md``). A new ``DIR`` appears complete or not at all (the
files are written into a temporary sibling folder that is then renamed); into an existing empty
``DIR`` (or a non-empty one with ``--force``) every file is written atomically.
"""

from __future__ import annotations

import argparse
import os
import shutil
import tempfile
from collections import Counter
from pathlib import Path

from semmap_pp.cli.argtypes import finite, integer, non_negative_int
from semmap_pp.errors import OutputError, SemmapError
from semmap_pp.synth import generate_floor, write_floor
from semmap_pp.synth.floor import MAX_UNITS
from semmap_pp.synth.wings import MAX_WINGS


def _units(text: str) -> int:
    value = integer(text)
    if not 2 <= value <= MAX_UNITS:
        raise argparse.ArgumentTypeError(f"must be between 2 and {MAX_UNITS}, got {value}")
    return value


def _resolution(text: str) -> float:
    value = finite(text)
    if not 0.01 <= value <= 0.2:
        raise argparse.ArgumentTypeError(f"must be within [0.01, 0.2] m, got {value:g}")
    return value


def _wings(text: str) -> int:
    value = integer(text)
    if not 1 <= value <= MAX_WINGS:
        raise argparse.ArgumentTypeError(f"must be between 1 and {MAX_WINGS}, got {value}")
    return value


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "synth", help="generate a synthetic floor (occupancy grid + ground truth)",
        description="Generate a realistic synthetic floor from a seed: map.yaml + map.pgm, "
                    "truth.json and truth_labels.png (see docs/synthetic.md).")
    parser.add_argument("--seed", type=non_negative_int, required=True, metavar="N",
                        help="seed; the same arguments always give the same bytes")
    parser.add_argument("--out", required=True, metavar="DIR", help="output folder")
    parser.add_argument("--units", type=_units, metavar="K",
                        help="number of space units (default: drawn from the seed)")
    parser.add_argument("--rotation", type=finite, metavar="DEG",
                        help="counter-clockwise rotation of the building as displayed "
                             "(default: drawn from the seed)")
    parser.add_argument("--resolution", type=_resolution, default=0.05, metavar="M",
                        help="metres per cell (default 0.05; the same seed is the same "
                             "building at every resolution)")
    parser.add_argument("--wings", type=_wings, default=1, metavar="W",
                        help=f"number of wings (1 to {MAX_WINGS}, default 1); from 2 on, each wing "
                             "is turned against the one before and joined to it by a link corridor")
    parser.add_argument("--wing-angle", type=finite, metavar="DEG",
                        help="counter-clockwise angle of each wing against the one before "
                             "(default: drawn per joint from the seed); needs --wings 2 or more")
    parser.add_argument("--force", action="store_true", help="write into a non-empty DIR")
    parser.set_defaults(func=run)


def _check_out(out: Path, force: bool) -> bool:
    """Whether ``out`` exists (as a usable folder); refuse what must not be written into."""
    if not out.exists():
        if out.is_symlink():
            raise OutputError(out, "is a dangling symbolic link")
        return False
    if not out.is_dir():
        raise OutputError(out, "exists and is not a directory")
    if any(out.iterdir()) and not force:
        raise OutputError(out, "directory is not empty (use --force to write into it)")
    return True


def run(args: argparse.Namespace) -> int:
    out = Path(args.out)
    if args.wing_angle is not None and args.wings < 2:
        raise SemmapError("--wing-angle", "needs --wings 2 or more")
    if args.wings > 1 and args.units is not None and args.units < 4 * args.wings - 1:
        raise SemmapError("--units", f"must be at least {4 * args.wings - 1} for --wings {args.wings}")
    exists = _check_out(out, args.force)
    floor = generate_floor(args.seed, units=args.units, rotation_deg=args.rotation,
                           resolution=args.resolution, wings=args.wings,
                           wing_angle_deg=args.wing_angle)
    if exists:
        paths = write_floor(floor, out)
    else:
        parent = out.absolute().parent
        try:
            parent.mkdir(parents=True, exist_ok=True)
            tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.", dir=parent))
            umask = os.umask(0o022)
            os.umask(umask)
            os.chmod(tmp, 0o777 & ~umask)  # mkdtemp's 0700 would hide the results from others
        except OSError as exc:
            raise OutputError(out, f"cannot create the output folder: {exc.strerror or exc}") from exc
        try:
            written = write_floor(floor, tmp)
            os.replace(tmp, out)
        except OSError as exc:
            raise OutputError(out, f"cannot create the output folder: {exc.strerror or exc}") from exc
        finally:
            if tmp.exists():
                shutil.rmtree(tmp, ignore_errors=True)
        paths = {k: out / Path(v).name for k, v in written.items()}
    t = floor.truth
    kinds = Counter(u["type"] for u in t["units"])
    print(f"synthetic floor: seed {t['seed']}, {t['layout']} layout, {len(t['units'])} units "
          f"({', '.join(f'{kinds[k]} {k}' for k in sorted(kinds))}), {len(t['doors'])} doors, "
          f"rotation {t['rotation_deg']:g} deg"
          + "".join(f", wing {w['wing']} at {w['orientation_deg']:g} deg" for w in t.get("wings", []))
          + f", {t['width']} x {t['height']} cells at "
          f"{t['resolution']:g} m")
    for key in ("map_yaml", "map_image", "truth", "truth_labels"):
        print(f"wrote {paths[key]}")
    return 0
