"""The occupancy grid a SLAM system would have built: the plan rotated into the image, scanned by
a simulated laser from every scan position, and classified as map_server does.

Noise comes from the physics of mapping, not from painting: range noise and per-scan registration
error thicken and jitter walls; sparse rays at long range leave missing wall cells and streaks of
free cells through doors and windows into the outside; rays that return nothing end raggedly at
the laser's range; furniture casts unknown shadows; closed doors hide whole rooms. Isolated speckle
and dropped wall cells are then added on top.

Rotation: building-frame continuous cells ``(x, y)`` map to image continuous pixels
``(X, Y) = R (x, y) + t`` with ``R = [[cos a, sin a], [-sin a, cos a]]``: the floor turns
counter-clockwise by ``a`` *as displayed* (image rows grow downwards).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from semmap_pp.cells import FREE, OCCUPIED, UNKNOWN
from semmap_pp.synth.params import SynthParams
from semmap_pp.synth.raster import BuildingRasters


@dataclass(frozen=True)
class Placement:
    """Building frame -> image frame: ``(X, Y) = R(rotation_deg) (x, y) + (tx, ty)``."""

    rotation_deg: float
    tx: float
    ty: float

    def matrix(self) -> np.ndarray:
        a = np.deg2rad(self.rotation_deg)
        return np.array([[np.cos(a), np.sin(a)], [-np.sin(a), np.cos(a)]])

    def apply(self, xy: np.ndarray) -> np.ndarray:
        """Image ``(X, Y)`` of building ``(x, y)`` points, shape ``(N, 2)``."""
        return np.asarray(xy, dtype=float) @ self.matrix().T + np.array([self.tx, self.ty])

    def invert(self, XY: np.ndarray) -> np.ndarray:
        """Building ``(x, y)`` of image ``(X, Y)`` points."""
        return (np.asarray(XY, dtype=float) - np.array([self.tx, self.ty])) @ self.matrix()

    def shifted(self, dx: float, dy: float) -> "Placement":
        return Placement(self.rotation_deg, self.tx + dx, self.ty + dy)


def place_canvas(br: BuildingRasters, rotation_deg: float, margin: int):
    """The placement that puts the rotated building ``margin`` cells from the canvas edges, and the
    canvas shape ``(H, W)``."""
    ox, oy = br.offset
    hb, wb = br.solid.shape
    corners = np.array([[ox, oy], [ox + wb, oy], [ox + wb, oy + hb], [ox, oy + hb]], dtype=float)
    rot = Placement(rotation_deg, 0.0, 0.0).apply(corners)
    lo, hi = rot.min(axis=0), rot.max(axis=0)
    pl = Placement(rotation_deg, float(margin - np.floor(lo[0])), float(margin - np.floor(lo[1])))
    w = int(np.ceil(hi[0]) - np.floor(lo[0])) + 2 * margin
    h = int(np.ceil(hi[1]) - np.floor(lo[1])) + 2 * margin
    return pl, (h, w)


def lookup(br: BuildingRasters, pl: Placement, shape) -> np.ndarray:
    """For every image cell, the flat index of the building cell under its centre (-1: none)."""
    h, w = shape
    a = np.deg2rad(pl.rotation_deg)
    cos, sin = np.cos(a), np.sin(a)
    X = np.arange(w) + 0.5 - pl.tx
    Y = np.arange(h) + 0.5 - pl.ty
    ox, oy = br.offset
    hb, wb = br.solid.shape
    # (x, y) = (X, Y) @ R, written as outer sums (no (H*W, 2) temporaries)
    c = np.floor(cos * X[None, :] - sin * Y[:, None]).astype(np.int64) - ox
    r = np.floor(sin * X[None, :] + cos * Y[:, None]).astype(np.int64) - oy
    ok = (r >= 0) & (r < hb) & (c >= 0) & (c < wb)
    return np.where(ok, r * wb + c, -1)


def resample(building: np.ndarray, index: np.ndarray, fill=0) -> np.ndarray:
    """Nearest-neighbour image of a building raster through :func:`lookup`'s ``index``."""
    out = np.full(index.shape, fill, dtype=building.dtype)
    ok = index >= 0
    out[ok] = building.ravel()[index[ok]]
    return out


def scan_counts(rng: np.random.Generator, solid: np.ndarray, glass: np.ndarray, poses: np.ndarray,
                p: SynthParams, res: float, batch: int = 8):
    """Simulate laser scans from ``poses`` (image ``(X, Y)``) and count, per cell, the readings
    that ended in it (``hits``) and the rays that passed through it (``passes``)."""
    h, w = solid.shape
    hits = np.zeros(h * w, dtype=np.int64)
    passes = np.zeros(h * w, dtype=np.int64)
    step = 0.6
    rng_max = rng.uniform(p.laser_range_min, p.laser_range_max) / res
    dist = (np.arange(int(rng_max / step)) + 0.5) * step
    n_rays = p.laser_rays
    block = solid.ravel()
    pane = glass.ravel()
    sig_r = rng.uniform(p.range_sigma_min, p.range_sigma_max) / res
    depth = int(rng.integers(0, int(round(p.hit_depth_max / res)) + 1))
    sig_xy, sig_a = p.pose_sigma_xy / res, np.deg2rad(p.pose_sigma_deg)
    for k in range(0, len(poses), batch):
        pos = poses[k:k + batch]
        b = len(pos)
        phi = rng.uniform(0, 2 * np.pi, b)[:, None] + np.arange(n_rays)[None, :] * (2 * np.pi / n_rays)
        dx, dy = np.cos(phi)[..., None], np.sin(phi)[..., None]
        X = pos[:, 0, None, None] + dist * dx
        Y = pos[:, 1, None, None] + dist * dy
        idx = np.floor(Y).astype(np.int64) * w + np.floor(X).astype(np.int64)
        reflect = rng.random((b, n_rays)) < p.p_glass_reflects
        blocked = block[idx] | (pane[idx] & reflect[..., None])
        has_hit = blocked.any(axis=2)
        first = np.where(has_hit, blocked.argmax(axis=2), len(dist))
        hit_at = dist[np.minimum(first, len(dist) - 1)]
        measured = np.where(has_hit, hit_at + rng.normal(0, sig_r, (b, n_rays)), rng_max)
        valid = rng.random((b, n_rays)) >= p.p_ray_dropout
        # the SLAM pose of each scan is slightly off: readings land where the robot thinks
        ex = pos[:, 0] + rng.normal(0, sig_xy, b)
        ey = pos[:, 1] + rng.normal(0, sig_xy, b)
        phin = phi + rng.normal(0, sig_a, b)[:, None]
        ndx, ndy = np.cos(phin), np.sin(phin)
        Xn = ex[:, None, None] + dist * ndx[..., None]
        Yn = ey[:, None, None] + dist * ndy[..., None]
        nidx = np.floor(Yn).astype(np.int64) * w + np.floor(Xn).astype(np.int64)
        free = (dist[None, None, :] < measured[..., None] - 0.7) & valid[..., None]
        passes += np.bincount(nidx[free], minlength=h * w)
        end = has_hit & valid
        hx = np.floor(ex[:, None] + measured * ndx).astype(np.int64)
        hy = np.floor(ey[:, None] + measured * ndy).astype(np.int64)
        hits += np.bincount((hy * w + hx)[end], minlength=h * w)
        for e in range(1, depth + 1):  # the beam's footprint reaches a little into the wall
            hx = np.floor(ex[:, None] + (measured + e) * ndx).astype(np.int64)
            hy = np.floor(ey[:, None] + (measured + e) * ndy).astype(np.int64)
            hits += np.bincount((hy * w + hx)[end], minlength=h * w)
    return hits.reshape(h, w), passes.reshape(h, w), float(rng_max * res)


def classify(rng: np.random.Generator, hits: np.ndarray, passes: np.ndarray, p: SynthParams) -> np.ndarray:
    """Cell classes from hit / pass counts, with speckle and dropped wall cells on top."""
    ratio = hits / np.maximum(hits + passes, 1)
    classes = np.full(hits.shape, UNKNOWN, dtype=np.uint8)
    classes[(passes > 0) & (ratio <= p.free_ratio)] = FREE
    classes[(hits > 0) & (ratio >= p.occupied_ratio)] = OCCUPIED
    u = rng.random(hits.shape)
    occ, free = classes == OCCUPIED, classes == FREE
    classes[occ & (u < p.p_wall_dropout)] = UNKNOWN
    classes[free & (u < p.p_speckle_occupied)] = OCCUPIED
    classes[free & (u >= p.p_speckle_occupied) & (u < p.p_speckle_occupied + p.p_speckle_unknown)] = UNKNOWN
    return classes


def outside_clutter(rng: np.random.Generator, inside: np.ndarray, p: SynthParams, res: float) -> np.ndarray:
    """Sparse obstacles outside the building (trees, cars, other buildings) where leaking rays end."""
    away = ndimage.distance_transform_edt(~inside) > 1.0 / res
    return away & (rng.random(inside.shape) < p.outside_clutter)


def crop_box(classes: np.ndarray, inside: np.ndarray, rng: np.random.Generator, p: SynthParams,
             res: float):
    """``(r0, r1, c0, c1)``: the known part of the map near the building, the whole building, and
    a thin grey border."""
    rows_b, cols_b = np.nonzero(inside)
    near = ndimage.distance_transform_edt(~inside) <= p.max_outside / res
    rows_k, cols_k = np.nonzero((classes != UNKNOWN) & near)
    rows = np.concatenate([rows_b, rows_k])
    cols = np.concatenate([cols_b, cols_k])
    border = int(round(rng.uniform(p.map_margin_min, p.map_margin_max) / res))
    h, w = classes.shape
    r0, r1 = max(0, int(rows.min()) - border), min(h, int(rows.max()) + 1 + border)
    c0, c1 = max(0, int(cols.min()) - border), min(w, int(cols.max()) + 1 + border)
    return r0, r1, c0, c1
