"""One synthetic floor from one seed: plan, furniture, robot path, laser scans, truth."""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from semmap_pp.grid import classes_to_image, write_map
from semmap_pp.synth import layout, render, topology, trajectory, wings as wings_mod
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
                   resolution: float = 0.05, params: SynthParams | None = None, wings: int = 1,
                   wing_angle_deg: float | None = None) -> Floor:
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
    wings : int
        Number of wings (1 to 4). From 2 on, each wing is a plan of its own turned by
        ``wing_angle_deg`` against the wing before it and joined to it by a link corridor;
        ``units`` counts every unit, links included.
    wing_angle_deg : float, optional
        Counter-clockwise angle of each wing against the one before; drawn per joint from
        [``wing_angle_min``, ``wing_angle_max``] when omitted. Only with ``wings >= 2``.

    Returns
    -------
    Floor

    Examples
    --------
    >>> f = generate_floor(3, units=3, rotation_deg=0.0)
    >>> len(f.truth["units"]), f.image.dtype.name, f.truth_labels.shape == f.image.shape
    (3, 'uint8', True)
    """
    _check_args(seed, units, rotation_deg, resolution)
    n_wings = _check_wings(wings, wing_angle_deg, units)
    p = params or SynthParams()
    res = float(resolution)
    # a ninth stream for the wings leaves the first eight (and every one-wing floor) as they were
    rng_units, rng_rot, rng_layout, rng_plan, rng_furn, rng_path, rng_scan, rng_map, rng_wings = \
        np.random.default_rng(int(seed)).spawn(9)
    n_units = int(units) if units is not None else int(
        rng_units.integers(p.units_min_default, p.units_max_default + 1))
    rot = _rotation(rng_rot, p) if rotation_deg is None else float(rotation_deg) % 360.0
    if n_wings > 1:
        return _wing_floor(int(seed), max(n_units, 4 * n_wings - 1), rot, res, p, n_wings,
                           wing_angle_deg, (rng_wings, rng_scan, rng_map))

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


def _check_args(seed, units, rotation_deg, resolution) -> None:
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ValueError(f"seed must be a non-negative integer, got {seed!r}")
    if units is not None and not (2 <= int(units) <= MAX_UNITS):
        raise ValueError(f"units must be between 2 and {MAX_UNITS}, got {units!r}")
    if rotation_deg is not None and not math.isfinite(float(rotation_deg)):
        raise ValueError(f"rotation_deg must be finite, got {rotation_deg!r}")
    if not (math.isfinite(float(resolution)) and 0.01 <= float(resolution) <= 0.2):
        raise ValueError(f"resolution must be within [0.01, 0.2] m, got {resolution!r}")


def _check_wings(wings, wing_angle_deg, units) -> int:
    if isinstance(wings, bool) or not isinstance(wings, (int, np.integer)) or \
            not 1 <= wings <= wings_mod.MAX_WINGS:
        raise ValueError(f"wings must be an integer from 1 to {wings_mod.MAX_WINGS}, got {wings!r}")
    if wing_angle_deg is not None:
        if wings < 2:
            raise ValueError("wing_angle_deg needs wings >= 2")
        if not math.isfinite(float(wing_angle_deg)):
            raise ValueError(f"wing_angle_deg must be finite, got {wing_angle_deg!r}")
    if wings > 1 and units is not None and int(units) < 4 * wings - 1:
        raise ValueError(f"units must be at least {4 * wings - 1} for {wings} wings "
                         f"(3 per wing and a link between two), got {units!r}")
    return int(wings)


def _wing_parts(rngs, n_units: int, p: SynthParams, res: float, n_wings: int, alphas: list) -> list:
    """The wings' plans placed one after the other, each joined to the one before by a link."""
    per = [(n_units - (n_wings - 1)) // n_wings] * n_wings
    per[0] += n_units - (n_wings - 1) - sum(per)
    parts, placed = [], []
    for k in range(n_wings):
        got = None
        for _ in range(ATTEMPTS):
            plan = topology.rescale_plan(_plan(rngs[5 * k], per[k], p, PLAN_RESOLUTION),
                                         PLAN_RESOLUTION / res)
            if k == 0:
                got = (wings_mod.Part(plan, 0.0, (0.0, 0.0), "wing", 1), None)
                break
            got = wings_mod.join(rngs[-2], parts[-1], plan, alphas[k - 1], placed, p, res, k + 1)
            if got is not None:
                break
        if got is None:
            raise RuntimeError(f"could not join wing {k + 1} to wing {k}")
        wing, link = got
        if link is not None:
            parts.append(link)
            placed.append(link.site(link.polygon))
        parts.append(wing)
        placed += [wing.site(wings_mod.polygon_of(r)) for r in plan.rects.tolist()]
    return parts


def _wing_floor(seed: int, n_units: int, rot: float, res: float, p: SynthParams, n_wings: int,
                wing_angle_deg, streams) -> Floor:
    """:func:`generate_floor` with ``wings >= 2`` (see ``docs/synthetic.md``, "Wings")."""
    rng_wings, rng_scan, rng_map = streams
    rngs = rng_wings.spawn(5 * n_wings + 2)
    alphas = [float(wing_angle_deg) if wing_angle_deg is not None else
              round(float(rngs[-1].uniform(p.wing_angle_min, p.wing_angle_max)), 1)
              for _ in range(n_wings - 1)]
    parts = _wing_parts(rngs, n_units, p, res, n_wings, alphas)
    rasters, poses_b = [], []
    for k, part in enumerate(parts):
        stream = 5 * (part.wing - 1) + (3 if part.kind == "link" else 1)
        br = draw_plan(part.drawn(), p, res)
        if part.kind == "link":
            wings_mod.clip_link(part, br.labels, br.solid, br.glass, br.offset)
            br.inside = br.labels > 0
        solid_b = furnish(rngs[stream], part.plan, br, p, res)
        rasters.append((br, solid_b))
        poses_b.append(trajectory.scan_poses(rngs[stream + 1], part.plan, br, solid_b, p, res))
    margin = int(math.ceil(p.laser_range_max / res)) + 4
    placements, shape, layer = wings_mod.compose(parts, rasters, rot, margin)
    poses = np.concatenate([pl.apply(q) for pl, q in zip(placements, poses_b) if len(q)])
    inside, solid = layer["inside"], layer["solid"]
    col, row = np.floor(poses[:, 0]).astype(int), np.floor(poses[:, 1]).astype(int)
    poses = poses[inside[row, col] & ~solid[row, col]]
    solid = solid | render.outside_clutter(rng_scan, inside, p, res)
    hits, passes, laser_range = render.scan_counts(rng_scan, solid, layer["glass"], poses, p, res)
    classes = render.classify(rng_map, hits, passes, p)
    r0, r1, c0, c1 = render.crop_box(classes, inside, rng_map, p, res)
    classes = np.ascontiguousarray(classes[r0:r1, c0:c1])
    offsets = wings_mod.unit_ids(parts)
    labels = np.where(layer["owner"] >= 0, layer["labels"].astype(np.int64)
                      + np.asarray(offsets)[layer["owner"]], 0)[r0:r1, c0:c1]
    final = [pl.shifted(-c0, -r0) for pl in placements]
    h, w = classes.shape
    docs = [build_truth(q.plan, final[k], seed=seed, resolution=res, width=w, height=h,
                        laser_range_m=laser_range) if q.kind == "wing" else None
            for k, q in enumerate(parts)]
    base = dict(docs[0])
    base["layout"] = "+".join(d["layout"] for d in docs if d is not None)
    truth = wings_mod.wings_truth(parts, final, alphas, base, docs)
    return Floor(image=classes_to_image(classes), classes=classes, resolution=res, truth=truth,
                 truth_labels=np.ascontiguousarray(labels, dtype=np.uint16),
                 poses_px=poses - np.array([c0, r0]))


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
