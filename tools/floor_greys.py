"""Which grey cells of a graded map are floor? The hand-drawn truth's answer, by occupancy and by distance from a wall.

    .venv/bin/python tools/floor_greys.py bench/data/real-gt/g4s_y2 [FOLDER ...] [--json]

FOLDER holds a real-gt floor: ``map.yaml`` (with its image) and ``gt.png``. Among the cells the
map's thresholds call unknown, those lighter than the map's own unknown value (the occupancy most
unknown cells hold) are counted by their occupancy and by their distance from the nearest
occupied cell, apart for the cells inside a hand-drawn room and those outside every room. The
number ``[rooms] wall_floor_max`` of models/default.toml reads off this table: beside a wall
(within one cell of an occupied one, ``wall_blur_m``) the cells in the rooms are lighter than the
ones outside them (a wall's blur).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np
from scipy import ndimage

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from semmap_pp.cells import OCCUPIED, UNKNOWN  # noqa: E402
from semmap_pp.evaluate import read_segmentation_truth  # noqa: E402
from semmap_pp.grid import load_map  # noqa: E402

#: occupancy bins (upper edges) and distance bands (cells from the nearest occupied cell)
P_EDGES = (0.02, 0.04, 0.06, 0.08, 0.10, 0.12, 0.15, 0.20, 0.30, 1.0)
BANDS = (("beside a wall (<= 1.5 cells)", 0.0, 1.5), ("farther", 1.5, np.inf))


def table(folder: Path) -> dict:
    """``{band: {"in rooms": counts, "outside rooms": counts}}`` over :data:`P_EDGES`'s bins."""
    grid = load_map(folder / "map.yaml")
    truth = read_segmentation_truth(folder / "gt.png", "rose2")
    classes, occ = grid.classes, grid.occupancy
    unknown = (classes == UNKNOWN) & np.isfinite(occ)
    values, counts = np.unique(occ[unknown], return_counts=True)
    grey = unknown & (occ < float(values[counts.argmax()]))
    dist = ndimage.distance_transform_edt(classes != OCCUPIED)
    edges = (0.0,) + P_EDGES
    out = {}
    for name, lo, hi in BANDS:
        band = grey & (dist > lo) & (dist <= hi)
        out[name] = {"in rooms": np.histogram(occ[band & (truth > 0)], edges)[0].tolist(),
                     "outside rooms": np.histogram(occ[band & (truth == 0)], edges)[0].tolist()}
    return out


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("folders", type=Path, nargs="+")
    parser.add_argument("--json", action="store_true", help="one JSON object instead of the table")
    args = parser.parse_args(argv)
    result = {str(f): table(f) for f in args.folders}
    if args.json:
        print(json.dumps({"occupancy_upper_edges": P_EDGES, "floors": result}))
        return 0
    print("occupancy at most: " + " ".join(f"{e:>6}" for e in P_EDGES))
    for folder, bands in result.items():
        print(folder)
        for band, rows in bands.items():
            for kind, row in rows.items():
                print(f"  {band:28s} {kind:14s}" + " ".join(f"{n:>6d}" for n in row))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
