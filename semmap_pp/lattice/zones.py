"""Building directions and zones: which wall directions a map has, and which direction every image
pixel belongs to (issue 48: units at their own orientation; docs/model.md, "Building directions
and zones").

A map built along one direction is one zone at θ0 (:func:`~semmap_pp.lattice.frame.lattice_orientation`).
A building with wings at other angles has one zone per direction that explains a part of the
building: its zone holds ``[lattice] zone_min_share`` of the wall faces (occupied cells next to
free ones) and walls along both of its axes. Four steps:

1. **Local wall direction** of every occupied cell, modulo 90°: the fourth-order structure tensor
   of the occupied mask (gradients at one cell, averaged over ``zone_wall_scale_m``), kept where it
   is coherent (``zone_min_coherence``): a wall and the wall at right angles to it vote alike, a
   corner does not cancel, clutter has no direction to speak of.
2. **Candidates**: θ0 first; then, greedily, the densest window of the local directions farther
   than ``off_axis_min_deg`` from every direction so far, its angle refined by the same scoring as
   θ0 on the cells near it; a candidate when the faces of the runs of cells nearest it stack
   ``off_axis_min_gain`` times sharper at it than at the nearest direction so far
   (:func:`~semmap_pp.lattice.frame.projection_sharpness`; clutter does not).
3. **Zones**: the free space is cut into room-like regions at its narrowings (free cells farther
   than ``zone_door_m / 2`` from every other cell, each component a seed, every cell given its
   nearest seed), each region takes the direction most of its walls vote for (at least
   ``zone_min_votes_m`` of them), and every other cell the zone of the nearest decided free cell.
   A boundary between zones so runs along walls and through doorways, not through a room.
4. **Parts**: a candidate whose zone holds less than ``zone_min_share`` of the wall faces, or
   whose walls there run along one of its axes only (one straight wall at an angle), is dropped,
   the weakest first, and the zones are made again.

Examples
--------
>>> import numpy as np
>>> from semmap_pp.model import load_model
>>> c = np.ones((200, 200), np.uint8); c[20:180:40, 10:190] = 2; c[10:190, 20:180:40] = 2
>>> z = building_zones(c, 0.05, load_model().lattice, 0.0)
>>> z.thetas, z.shares, z.labels.shape, int(z.labels.max())
((0.0,), (1.0,), (200, 200), 0)
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from semmap_pp.cells import FREE, OCCUPIED, UNKNOWN, mask_box
from semmap_pp.lattice.frame import BAND_ROWS, centred, projection_sharpness, sharpest_angle
from semmap_pp.model import LatticeParams

QUARTER = math.pi / 2
#: the labels are uint8: at most this many zones (a model file with a tiny ``zone_min_share`` and
#: ``off_axis_min_deg`` could ask for more directions)
MAX_ZONES = 256


@dataclass(frozen=True)
class Zones:
    """The building's directions and the zone of every image pixel (:func:`building_zones`)."""

    thetas: tuple[float, ...]   # radians, each in (-π/4, π/4]; thetas[0] is θ0 as given
    labels: np.ndarray          # (H, W) uint8, read-only: index into thetas of every image pixel
    shares: tuple[float, ...]   # share of the wall faces (occupied cells next to free ones) in each zone


def one_zone(shape: tuple[int, int], theta0: float) -> Zones:
    """Every pixel in one zone at ``theta0``."""
    labels = np.zeros(shape, np.uint8)
    labels.setflags(write=False)
    return Zones((theta0,), labels, (1.0,))


def building_zones(classes: np.ndarray, resolution: float, params: LatticeParams, theta0: float) -> Zones:
    """The building directions of a map and the zone of every pixel.

    Parameters
    ----------
    classes : (H, W) uint8
        Input classes (:mod:`semmap_pp.cells` codes).
    resolution : float
        Metres per cell.
    params : LatticeParams
        The ``zone_*`` and ``off_axis_*`` numbers of the model file.
    theta0 : float
        The single lattice's orientation (radians); it is ``thetas[0]``, unchanged.

    Returns
    -------
    Zones
        One zone (all labels 0, share 1.0) when no other direction explains a part of the
        building, when the map has no wall face, or when ``zone_min_share`` is 0.
    """
    classes = np.asarray(classes)
    if classes.ndim != 2:
        raise ValueError(f"expected a 2-D class image, got shape {classes.shape}")
    occupied = classes == OCCUPIED
    if params.zone_min_share <= 0 or not occupied.any():
        return one_zone(classes.shape, float(theta0))
    faces = occupied & ndimage.binary_dilation(classes == FREE, structure=np.ones((3, 3), bool))
    n = int(np.count_nonzero(faces))
    if n == 0:
        return one_zone(classes.shape, float(theta0))
    rows, cols, local = wall_directions(occupied, resolution, params)
    face = faces[rows, cols]
    thetas = directions(rows, cols, local, face, classes.shape, float(theta0), resolution, params)
    while len(thetas) > 1:
        labels = zone_labels(classes, rows, cols, local, thetas, resolution, params)
        shares = np.bincount(labels[faces], minlength=len(thetas)) / n
        weak = [d for d in range(1, len(thetas)) if shares[d] < params.zone_min_share
                or not _both_axes(rows, cols, local, labels, thetas, d, resolution, params)]
        if not weak:
            labels.setflags(write=False)
            return Zones(tuple(thetas), labels, tuple(float(s) for s in shares))
        del thetas[min(weak, key=lambda d: shares[d])]   # no part of the building of its own
    return one_zone(classes.shape, float(theta0))


def _both_axes(rows, cols, local, labels, thetas, d: int, resolution: float, params: LatticeParams) -> bool:
    """Whether the walls of zone ``d`` that vote for its direction run along both of its axes: one
    run of such cells (8-connected) reaches ``zone_min_votes_m`` along ``thetas[d]``, one along
    the axis at right angles. One straight wall at an angle (a wall across a corner, clutter beside
    it) is no part of a building built along that angle; a wing's rooms have both."""
    mine = (nearest_direction(local, thetas, math.radians(params.off_axis_min_deg)) == d) & \
        (labels[rows, cols] == d)
    if not mine.any():
        return False
    _, run = np.unique(_runs(rows[mine], cols[mine], labels.shape), return_inverse=True)
    c, s = math.cos(thetas[d]), math.sin(thetas[d])
    x, y = cols[mine].astype(np.float64), rows[mine].astype(np.float64)
    need = params.zone_min_votes_m / resolution
    for along in (c * x + s * y, -s * x + c * y):
        lo = np.full(run.max() + 1, np.inf)
        hi = np.full(run.max() + 1, -np.inf)
        np.minimum.at(lo, run, along)
        np.maximum.at(hi, run, along)
        if not (hi - lo >= need).any():
            return False
    return True


def wall_directions(occupied: np.ndarray, resolution: float, params: LatticeParams):
    """``(rows, cols, angle)`` of the occupied cells whose walls have a direction: the angle
    (radians, modulo 90° in (-π/4, π/4]) of the fourth-order structure tensor, where its coherence
    is at least ``zone_min_coherence``.

    The gradient ``g`` of the occupied mask (Gaussian derivatives at one cell: less smoothing
    leaves the staircase of a rasterised wall, whose steps point along the axes) gives each cell
    ``|g|^2 e^{4i arg g}``; averaged over ``zone_wall_scale_m`` (Gaussian), its argument over 4 is
    the wall direction modulo 90° and its modulus over the averaged ``|g|^2`` the coherence (1 on
    a straight wall or a right-angled corner, near 0 in clutter). Computed in bands of rows, so
    no float array of the image's size is made.
    """
    sigma = max(params.zone_wall_scale_m / resolution, 1.0)
    halo = int(math.ceil(4.0 * (sigma + 1.0))) + 1
    box = mask_box(occupied)
    h, w = occupied.shape
    r0, c0, r1, c1 = box
    c0, c1 = max(c0 - halo, 0), min(c1 + halo, w)
    out_r, out_c, out_a = [], [], []
    for b0 in range(r0, r1, BAND_ROWS):
        b1 = min(b0 + BAND_ROWS, r1)
        h0, h1 = max(b0 - halo, 0), min(b1 + halo, h)
        m = occupied[h0:h1, c0:c1].astype(np.float32)
        gx = ndimage.gaussian_filter(m, 1.0, order=(0, 1))
        gy = ndimage.gaussian_filter(m, 1.0, order=(1, 0))
        e = gx * gx + gy * gy
        a, b = gx * gx - gy * gy, 2.0 * gx * gy
        with np.errstate(invalid="ignore", divide="ignore"):
            zr = np.where(e > 0, (a * a - b * b) / e, 0.0).astype(np.float32)
            zi = np.where(e > 0, 2.0 * a * b / e, 0.0).astype(np.float32)
        inner = slice(b0 - h0, b1 - h0)
        rr, cc = np.nonzero(occupied[b0:b1, c0:c1])
        zr = ndimage.gaussian_filter(zr, sigma)[inner][rr, cc]
        zi = ndimage.gaussian_filter(zi, sigma)[inner][rr, cc]
        e = ndimage.gaussian_filter(e, sigma)[inner][rr, cc]
        keep = np.hypot(zr, zi) >= params.zone_min_coherence * np.maximum(e, 1e-12)
        out_r.append(rr[keep] + b0)
        out_c.append(cc[keep] + c0)
        out_a.append(_quarter(np.arctan2(zi[keep], zr[keep]).astype(np.float64) / 4.0))
    return (np.concatenate(out_r).astype(np.intp), np.concatenate(out_c).astype(np.intp),
            np.concatenate(out_a))


def _quarter(a):
    """Angles modulo 90° into (-π/4, π/4] (radians)."""
    a = np.remainder(np.asarray(a, dtype=np.float64) + QUARTER / 2, QUARTER) - QUARTER / 2
    return np.where(a <= -QUARTER / 2, a + QUARTER, a)


def _gap(a, b):
    """|a - b| modulo 90° (radians, in [0, π/4])."""
    return np.abs(_quarter(np.asarray(a) - b))


def nearest_direction(local: np.ndarray, thetas, tol: float) -> np.ndarray:
    """Index of the direction of ``thetas`` nearest each local angle (modulo 90°); -1 when none is
    within ``tol`` radians."""
    gaps = np.stack([_gap(local, t) for t in thetas])
    k = np.argmin(gaps, axis=0)
    return np.where(np.take_along_axis(gaps, k[None], 0)[0] <= tol, k, -1)


def directions(rows, cols, local, face, shape, theta0: float, resolution: float, params: LatticeParams) -> list[float]:
    """The candidate directions of the cells ``rows, cols`` with a local wall angle ``local``
    (``face``: those that are wall faces): θ0, then greedily the densest window of the local
    angles farther than ``off_axis_min_deg`` from every direction so far, its angle refined on the
    cells near it; it is a candidate when the cells nearest it hold a run of
    ``zone_min_votes_m`` whose faces stack ``off_axis_min_gain`` times sharper at it than at the
    nearest direction so far (:func:`_sharper`). No share of the cells is asked for here: whether
    a candidate is a zone is decided by the part of the building it explains
    (:func:`building_zones`)."""
    tol = math.radians(params.off_axis_min_deg)
    step = math.radians(params.angle_bin_deg)
    nbins = int(round(QUARTER / step))
    half = max(1, int(round(tol / 2 / step)))
    need = params.zone_min_votes_m / resolution
    thetas = [theta0]
    left = np.ones(local.shape, bool)
    while len(thetas) < MAX_ZONES:
        left &= np.min([_gap(local, t) for t in thetas], axis=0) > tol
        if np.count_nonzero(left) < need:
            return thetas
        hist = np.bincount(((local[left] + QUARTER / 2) / step).astype(np.intp) % nbins, minlength=nbins)
        window = sum(np.roll(hist, s) for s in range(-half, half + 1))
        centre = float(_quarter((int(np.argmax(window)) + 0.5) * step - QUARTER / 2))
        near = left & (_gap(local, centre) <= tol)
        x, y = centred(cols[near], rows[near])
        theta = _refined(x, y, centre, tol, params)
        nearest = min(thetas, key=lambda t: float(_gap(theta, t)))
        if float(_gap(theta, nearest)) > tol and _sharper(rows, cols, local, face, thetas, theta, nearest, shape,
                                                          need, params):
            thetas.append(theta)
        else:
            left &= ~near   # no direction of its own: clutter, or the tail of one found
    return thetas


def _sharper(rows, cols, local, face, thetas, theta, nearest, shape, need, params) -> bool:
    """Whether the cells nearest ``theta`` among ``thetas`` and it (within ``off_axis_min_deg``)
    hold a run of ``need`` cells and the wall faces (``face``) of such runs stack
    ``off_axis_min_gain`` times sharper at ``theta`` than at ``nearest``
    (:func:`~semmap_pp.lattice.frame.projection_sharpness`). Faces, not the whole runs: the
    coherent band behind a filled outside's wall is a metre thick, and stacks alike at angles near
    its own (lab_ipa's walls at 43.5°: 1.16 times sharper than at 0° with the band, 6.7 times on
    their faces)."""
    k = len(thetas)
    mine = nearest_direction(local, [*thetas, theta], math.radians(params.off_axis_min_deg)) == k
    if not mine.any():
        return False
    run = _runs(rows[mine], cols[mine], shape)
    keep = (np.bincount(run)[run] >= need) & face[mine]
    if not keep.any():
        return False
    x, y = centred(cols[mine][keep], rows[mine][keep])
    return projection_sharpness(x, y, theta) >= params.off_axis_min_gain * projection_sharpness(x, y, nearest)


def _runs(rows, cols, shape) -> np.ndarray:
    """The 8-connected run (label from 1) of each of the cells ``rows, cols``."""
    img = np.zeros(shape, bool)
    img[rows, cols] = True
    lab, _ = ndimage.label(img, structure=np.ones((3, 3), bool))
    return lab[rows, cols]


def _refined(x, y, centre: float, half: float, params: LatticeParams) -> float:
    """The angle within ``half`` of ``centre`` (radians) that stacks the points ``(x, y)`` sharpest:
    the scans of :func:`~semmap_pp.lattice.frame.estimate_orientation`
    (:func:`~semmap_pp.lattice.frame.sharpest_angle`), the coarse one over ``centre ± half`` only."""
    step = math.radians(params.angle_bin_deg)
    n = int(math.ceil(half / step))
    return float(_quarter(sharpest_angle(x, y, centre + step * np.arange(-n, n + 1), params)))


def zone_labels(classes: np.ndarray, rows, cols, local, thetas, resolution: float,
                params: LatticeParams) -> np.ndarray:
    """(H, W) uint8: the zone (index into ``thetas``) of every pixel, given the local wall angle
    ``local`` of the occupied cells ``rows, cols`` (:func:`wall_directions`).

    The free space is cut at its narrowings into regions (:func:`free_regions`). Each wall cell
    votes for the direction nearest its local angle (within ``off_axis_min_deg``), when it lies
    in a run of ``zone_min_votes_m`` of cells voting alike (a wall, not a speck of clutter), for
    the region of its nearest seed. A direction is present in a region with at least
    ``zone_min_votes_m`` of votes and ``zone_split_share`` of the votes of the region's strongest
    direction. A region with one direction present takes it; a region with several (a corridor
    bent at a wing's joint, a hall open to a link) gives each free cell the direction of its
    nearest voting wall cell, when that direction is present there. Every other pixel takes the
    zone of the nearest free cell of a decided region. Worked inside the box of the known cells;
    a pixel outside it takes the zone of the box's nearest pixel.
    """
    h, w = classes.shape
    r0, c0, r1, c1 = mask_box(classes != UNKNOWN)
    free = classes[r0:r1, c0:c1] == FREE
    region, n = free_regions(free, params.zone_door_m / 2 / resolution)
    labels = np.zeros((h, w), np.uint8)
    if n == 0:
        return labels
    k = len(thetas)
    rows, cols = rows - r0, cols - c0
    vote = nearest_direction(local, thetas, math.radians(params.off_axis_min_deg))
    need = params.zone_min_votes_m / resolution
    ok = (vote >= 0) & _long_runs(rows, cols, vote, k, free.shape, need)
    rows, cols, vote = rows[ok], cols[ok], vote[ok]
    own = region[rows, cols]
    counts = np.bincount(own * k + vote, minlength=(n + 1) * k).reshape(n + 1, k)
    present = (counts >= need) & (counts >= params.zone_split_share * counts.max(axis=1, keepdims=True))
    present[0] = False
    zone_of = np.where(present.any(axis=1), counts.argmax(axis=1), -1).astype(np.int16)
    zone = np.where(free, zone_of[region], np.int16(-1))
    mixed = present.sum(axis=1) > 1
    if mixed.any():
        _split_mixed(zone, region, mixed, present, (rows, cols, vote, own), free)
    del region
    undecided = zone < 0
    if undecided.all():
        return labels
    near = ndimage.distance_transform_edt(undecided, return_distances=False, return_indices=True)
    zone = zone[near[0], near[1]].astype(np.uint8)
    del near
    ri = np.clip(np.arange(h) - r0, 0, r1 - r0 - 1)
    ci = np.clip(np.arange(w) - c0, 0, c1 - c0 - 1)
    return zone[ri[:, None], ci[None, :]]


def free_regions(free: np.ndarray, radius: float) -> tuple[np.ndarray, int]:
    """``(region, n)``: the free space cut at its narrowings. The free cells farther than
    ``radius`` cells from every other cell are seeds (a doorway narrower than ``2 radius`` holds
    none), each 8-connected component of them a region ``1..n``, and every cell (free or not) in
    the region of its nearest seed; ``n == 0`` (and ``region`` None) when there is no seed.

    >>> f = np.zeros((9, 21), bool); f[1:8, 1:9] = f[1:8, 12:20] = f[4, 9:12] = True
    >>> region, n = free_regions(f, 1.5)
    >>> n, region[4, [2, 18, 9, 11]].tolist()
    (2, [1, 2, 1, 2])
    """
    seeds = ndimage.distance_transform_edt(free) > radius
    seed_labels, n = ndimage.label(seeds, structure=np.ones((3, 3), bool))
    if n == 0:
        return None, 0
    near = ndimage.distance_transform_edt(~seeds, return_distances=False, return_indices=True)
    return seed_labels[near[0], near[1]], n


def _split_mixed(zone, region, mixed, present, votes, free) -> None:
    """In place: the free cells of the ``mixed`` regions take the direction of their nearest
    voting wall cell of a mixed region (``votes``: its row, column, direction and region), when
    that direction is present in their region (:func:`zone_labels`)."""
    rows, cols, vote, own = votes
    r0, c0, r1, c1 = mask_box(mixed[region])       # the mixed regions with their walls
    keep = mixed[own] & present[own, vote] & (rows >= r0) & (rows < r1) & (cols >= c0) & (cols < c1)
    if not keep.any():
        return
    feat = np.ones((r1 - r0, c1 - c0), bool)
    feat[rows[keep] - r0, cols[keep] - c0] = False
    lab = np.zeros(feat.shape, np.int16)
    lab[rows[keep] - r0, cols[keep] - c0] = vote[keep]
    near = ndimage.distance_transform_edt(feat, return_distances=False, return_indices=True)
    got = lab[near[0], near[1]]
    del near
    reg = region[r0:r1, c0:c1]
    take = mixed[reg] & free[r0:r1, c0:c1] & present[reg, got]
    zone[r0:r1, c0:c1][take] = got[take]


def _long_runs(rows, cols, vote, k, shape, need):
    """Whether each voting cell lies in an 8-connected run of at least ``need`` cells voting alike."""
    keep = np.zeros(vote.shape, bool)
    img = np.zeros(shape, bool)
    for d in range(k):
        mine = vote == d
        if not mine.any():
            continue
        img[:] = False
        img[rows[mine], cols[mine]] = True
        lab, n = ndimage.label(img, structure=np.ones((3, 3), bool))
        size = np.bincount(lab[rows[mine], cols[mine]], minlength=n + 1)
        keep[mine] = size[lab[rows[mine], cols[mine]]] >= need
    return keep
