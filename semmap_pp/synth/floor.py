"""One synthetic floor from one seed: plan, furniture, robot path, laser scans, truth."""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from semmap_pp.grid import classes_to_image, write_map
from semmap_pp.synth import layout, render, topology, trajectory
from semmap_pp.synth.params import SynthParams
from semmap_pp.synth.raster import draw_plan, furnish
from semmap_pp.synth.truth import build_truth, write_truth

MAX_UNITS = 400
ATTEMPTS = 40
# The plan (rooms, walls, doors, windows, exits) is drawn in cells of this size and scaled to the
# map's resolution, so a seed gives the same building at every resolution; the furniture, the
# robot's path and the scans are drawn at the map's resolution.
PLAN_RESOLUTION = 0.05


@dataclass
class Floor:
    """A synthetic occupancy grid map with its ground truth.

    Attributes
    ----------
    image : np.ndarray of uint8, shape (H, W)
        map_server grey values: 254 free, 205 unknown, 0 occupied.
    classes : np.ndarray of uint8, shape (H, W)
        The same map as :mod:`semmap_pp.cells` codes.
    resolution : float
        Metres per cell.
    truth : dict
        The ``truth.json`` document (see ``docs/synthetic.md``).
    truth_labels : np.ndarray of uint16, shape (H, W)
        Unit id (>= 1) of every cell of a unit including its walls, 0 elsewhere.
    origin : tuple of float
        map_server origin ``(x, y, yaw)``.
    poses_px : np.ndarray, shape (N, 2)
        Where the simulated robot scanned, image ``[x, y]`` (for figures and checks).
    """

    image: np.ndarray
    classes: np.ndarray
    resolution: float
    truth: dict
    truth_labels: np.ndarray
    origin: tuple = (0.0, 0.0, 0.0)
    poses_px: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))


def _rotation(rng: np.random.Generator, p: SynthParams) -> float:
    u = rng.random()
    if u < p.p_axis_aligned:
        return 0.0
    if u < p.p_axis_aligned + p.p_right_angle:
        return float(90 * rng.integers(1, 4))
    return round(float(rng.uniform(0.0, 360.0)), 1)


def _plan(rng: np.random.Generator, n_units: int, p: SynthParams, res: float) -> topology.FloorPlan:
    best = None
    for attempt in range(ATTEMPTS):
        kind = layout.choose_layout(rng, p, n_units)
        draft = layout.GENERATORS[kind](rng, p, res, n_units + attempt // 3)
        keep = topology.prune(rng, draft, n_units, p, res)
        n = int(keep.sum())
        if best is None or abs(n - n_units) < abs(best[1].sum() - n_units):
            best = (draft, keep)
        if n == n_units:
            break
    draft, keep = best
    return topology.build_plan(rng, draft, keep, p, res)


def generate_floor(seed: int, *, units: int | None = None, rotation_deg: float | None = None,
                   resolution: float = 0.05, params: SynthParams | None = None) -> Floor:
    """A realistic synthetic floor and its ground truth, fully determined by the arguments.

    Parameters
    ----------
    seed : int
        Non-negative seed; the same arguments give a byte-identical floor.
    units : int, optional
        Number of space units (>= 2); drawn from the seed when omitted. The generator hits it
        exactly for all but unusual requests (then the nearest count it could build).
    rotation_deg : float, optional
        Counter-clockwise rotation of the building as displayed; drawn from the seed when omitted
        (often 0, sometimes a right angle, otherwise arbitrary).
    resolution : float
        Metres per cell.
    params : SynthParams, optional
        Generator configuration; defaults to :class:`SynthParams()`.

    Returns
    -------
    Floor

    Examples
    --------
    >>> f = generate_floor(3, units=3, rotation_deg=0.0)
    >>> len(f.truth["units"]), f.image.dtype.name, f.truth_labels.shape == f.image.shape
    (3, 'uint8', True)
    """
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ValueError(f"seed must be a non-negative integer, got {seed!r}")
    if units is not None and not (2 <= int(units) <= MAX_UNITS):
        raise ValueError(f"units must be between 2 and {MAX_UNITS}, got {units!r}")
    if rotation_deg is not None and not math.isfinite(float(rotation_deg)):
        raise ValueError(f"rotation_deg must be finite, got {rotation_deg!r}")
    if not (math.isfinite(float(resolution)) and 0.01 <= float(resolution) <= 0.2):
        raise ValueError(f"resolution must be within [0.01, 0.2] m, got {resolution!r}")
    p = params or SynthParams()
    res = float(resolution)
    rng_units, rng_rot, rng_layout, rng_plan, rng_furn, rng_path, rng_scan, rng_map = \
        np.random.default_rng(int(seed)).spawn(8)
    n_units = int(units) if units is not None else int(
        rng_units.integers(p.units_min_default, p.units_max_default + 1))
    rot = _rotation(rng_rot, p) if rotation_deg is None else float(rotation_deg) % 360.0

    plan = _plan(rng_layout, n_units, p, PLAN_RESOLUTION)
    plan = topology.rescale_plan(plan, PLAN_RESOLUTION / res)
    br = draw_plan(plan, p, res)
    solid_b = furnish(rng_furn, plan, br, p, res)
    poses_b = trajectory.scan_poses(rng_path, plan, br, solid_b, p, res)

    margin = int(math.ceil(p.laser_range_max / res)) + 4
    pl, shape = render.place_canvas(br, rot, margin)
    index = render.lookup(br, pl, shape)
    inside = render.resample(br.inside, index, fill=False)
    solid = render.resample(solid_b, index, fill=False)
    solid |= render.outside_clutter(rng_scan, inside, p, res)
    glass = render.resample(br.glass, index, fill=False)
    poses = pl.apply(poses_b) if len(poses_b) else np.zeros((0, 2))
    hits, passes, laser_range = render.scan_counts(rng_scan, solid, glass, poses, p, res)
    classes = render.classify(rng_map, hits, passes, p)
    r0, r1, c0, c1 = render.crop_box(classes, inside, rng_map, p, res)
    classes = np.ascontiguousarray(classes[r0:r1, c0:c1])
    labels = render.resample(br.labels, index, fill=0)[r0:r1, c0:c1]
    final = pl.shifted(-c0, -r0)
    truth = build_truth(plan, final, seed=int(seed), resolution=res, width=classes.shape[1],
                        height=classes.shape[0], laser_range_m=laser_range)
    return Floor(image=classes_to_image(classes), classes=classes, resolution=res, truth=truth,
                 truth_labels=np.ascontiguousarray(labels, dtype=np.uint16),
                 poses_px=poses - np.array([c0, r0]) if len(poses) else poses)


def write_floor(floor: Floor, out_dir: str | os.PathLike) -> dict:
    """Write ``map.yaml``, ``map.pgm``, ``truth.json`` and ``truth_labels.png`` into ``out_dir``.

    Every file is written atomically. Returns ``{"map_yaml", "map_image", "truth",
    "truth_labels"}`` -> path.
    """
    out = Path(out_dir)
    yaml_path = write_map(out / "map.yaml", floor.image, floor.resolution, floor.origin)
    paths = {"map_yaml": Path(yaml_path), "map_image": Path(yaml_path).with_suffix(".pgm")}
    paths.update(write_truth(out, floor.truth, floor.truth_labels))
    return paths


__all__ = ["Floor", "generate_floor", "write_floor"]
