"""The building lattice: the map's dominant orientation θ0 and the map resampled onto a grid rotated
by θ0 (see docs/architecture.md, "The building lattice").

Two coordinate frames, kept apart on purpose. Inside this module (``lattice_to_image``,
``image_to_lattice``) fractional cell *indices* are used: index ``(col, row)`` is the centre of that
cell, and a lattice rectangle ``(r0, c0, r1, c1)`` spans ``[r0 - 0.5, r1 - 0.5] x [c0 - 0.5, c1 - 0.5]``.
Everything this module hands to the outside world in pixels (``rect_vertices_px``, and the input of
``image_to_metres``) is in the project's continuous pixel frame of :mod:`semmap_pp.cells`: pixel
``(row r, col c)`` spans ``x in [c, c+1)``, ``y in [r, r+1)``, so its centre is ``(c + 0.5, r + 0.5)``.
A lattice point maps to the image by ``p_img = R(θ0) (p_lat - o_lat) + o_img`` on ``[x, y]``
pairs, with ``o_lat`` and ``o_img`` the centres of the two grids; the lattice's column axis runs
along the image direction ``(cos θ0, sin θ0)`` (y pointing down the image). The lattice kept may be
a part of the whole image's lattice (``Frame.crop``: the known cells and ``[lattice]
crop_margin_m`` around them, when that leaves out at least half the cells); ``o_lat`` is then the
whole lattice's centre in the part's indices, so every cell keeps its place.

Examples
--------
>>> import numpy as np
>>> from semmap_pp.model import load_model
>>> classes = np.zeros((5, 8), np.uint8)
>>> f = build_frame_from_classes(classes, 0.05, load_model())
>>> f.theta, f.classes.shape, bool(f.outside.any())
(0.0, (5, 8), False)
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from semmap_pp.cells import FREE, OCCUPIED, UNKNOWN, known_box
from semmap_pp.model import CellParams, LatticeParams, Model


def _soft_hist(u: np.ndarray) -> np.ndarray:
    """Histogram of fractional positions with linear interpolation between the two nearest bins."""
    f = np.floor(u)
    i = (f - f.min()).astype(np.intp)
    t = u - f
    return np.bincount(i, weights=1.0 - t, minlength=i.max() + 2) + np.bincount(
        i + 1, weights=t, minlength=i.max() + 2)


def projection_sharpness(x: np.ndarray, y: np.ndarray, theta: float, bin_cells: float = 1.0) -> float:
    """Sum of squared row and column profiles of points ``(x, y)`` on a lattice rotated by ``theta``.

    Walls are long straight runs, so the angle that stacks the occupied cells into the fewest
    lattice rows and columns is the wall direction. Linear-interpolated binning (bins of
    ``bin_cells``) makes the score smooth in ``theta``.
    """
    c, s = math.cos(theta), math.sin(theta)
    hu = _soft_hist((c * x + s * y) / bin_cells)
    hv = _soft_hist((-s * x + c * y) / bin_cells)
    return float(np.dot(hu, hu) + np.dot(hv, hv))


def _best(x, y, angles, bin_cells):
    scores = np.array([projection_sharpness(x, y, a, bin_cells) for a in angles])
    i = int(np.argmax(scores))
    return i, scores


def estimate_orientation(classes: np.ndarray, params: LatticeParams) -> float:
    """Dominant wall orientation θ0 in radians, in (-π/4, π/4].

    Maximises :func:`projection_sharpness` of the occupied cells: a coarse scan over 90° in steps
    of ``angle_bin_deg`` (bins of 2 cells, so a peak between two steps is not missed), a fine scan
    of ±``refine_window_deg`` around the best coarse angle in tenth steps (1-cell bins), then a
    parabola through the best three fine angles. (A histogram of gradient orientations, tried
    first, is biased towards the axes on aliased walls: see docs/model.md.)

    Parameters
    ----------
    classes : (H, W) uint8
        Input classes (:mod:`semmap_pp.cells` codes).
    params : LatticeParams
        Step and refinement window from the model file.

    Returns
    -------
    float
        θ0; 0.0 when the map holds fewer than two occupied cells.
    """
    x, y = _occupied_points(classes)
    return _orientation_of_points(x, y, params) if x.size >= 2 else 0.0


def centred(x, y) -> tuple[np.ndarray, np.ndarray]:
    """``(x, y)`` as float64, centred on their integer mean: at theta = 0 every cell sits on a bin
    centre (no interpolation spread)."""
    x, y = np.asarray(x), np.asarray(y)
    if x.size == 0:
        return x.astype(np.float64), y.astype(np.float64)
    return ((x - round(float(x.mean()))).astype(np.float64),
            (y - round(float(y.mean()))).astype(np.float64))


def _occupied_points(classes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(x, y)`` of the occupied cells, :func:`centred`."""
    y, x = np.nonzero(np.asarray(classes) == OCCUPIED)
    return centred(x, y)


def sharpest_angle(x: np.ndarray, y: np.ndarray, coarse: np.ndarray, params: LatticeParams) -> float:
    """The angle (radians, not wrapped) that stacks the centred points ``(x, y)`` sharpest, from
    the coarse angles ``coarse`` (2-cell bins): tenth steps over ``refine_window_deg`` around the
    best of them (1-cell bins), then a parabola through the best three."""
    i, _ = _best(x, y, coarse, 2.0)
    fine_step = math.radians(params.angle_bin_deg) / 10.0
    half = int(math.ceil(math.radians(params.refine_window_deg) / fine_step))
    fine = coarse[i] + fine_step * np.arange(-half, half + 1)
    j, scores = _best(x, y, fine, 1.0)
    theta = float(fine[j])
    if 0 < j < len(fine) - 1:
        a, b, c = scores[j - 1], scores[j], scores[j + 1]
        den = a - 2 * b + c
        if den < 0:
            theta += 0.5 * fine_step * (a - c) / den
    return theta


def _orientation_of_points(x: np.ndarray, y: np.ndarray, params: LatticeParams) -> float:
    """:func:`estimate_orientation` of the centred points ``(x, y)`` (at least two)."""
    period = math.pi / 2
    step = math.radians(params.angle_bin_deg)
    coarse = -period / 2 + step * np.arange(int(math.ceil(period / step)))
    theta = math.remainder(sharpest_angle(x, y, coarse, params), period)  # into [-45°, 45°]
    if theta <= -period / 2:
        theta += period
    return float(theta)


def doorway_classes(classes: np.ndarray, speck_cells: int) -> np.ndarray:
    """``classes`` with every *speck* made FREE: a non-free cell whose 8-connected component of
    non-free cells has at most ``speck_cells`` cells (a chair leg and the unseen cell behind it;
    a wall, a jamb or a closed leaf is a longer line of cells). Doors are looked for on these.

    >>> m = np.array([[0, 0, 0, 0, 0], [0, 2, 0, 0, 2], [0, 1, 0, 0, 2], [0, 0, 0, 0, 2]], np.uint8)
    >>> doorway_classes(m, 2).tolist()
    [[0, 0, 0, 0, 0], [0, 0, 0, 0, 2], [0, 0, 0, 0, 2], [0, 0, 0, 0, 2]]
    >>> doorway_classes(m, 1).tolist() == m.tolist()
    True
    """
    blocked = classes != FREE
    labels, n = ndimage.label(blocked, structure=np.ones((3, 3), bool))
    if n == 0:
        return classes
    size = np.bincount(labels.ravel(), minlength=n + 1)
    small = size <= speck_cells
    small[0] = False
    out = classes.copy()
    out[small[labels]] = FREE
    return out



@dataclass(frozen=True)
class OffAxis:
    """Walls at another angle than θ0 (:func:`off_axis_walls`)."""

    share: float        # of the occupied cells in blocks with enough of them to have an orientation
    angle_deg: float    # orientation of those blocks (the median, weighted by their cells), degrees
    blocks: int         # how many blocks
    box_px: tuple | None = None   # (x0, y0, x1, y1): the pixels those blocks span (x1, y1 exclusive)


def off_axis_walls(classes: np.ndarray, theta: float, resolution: float, params: LatticeParams) -> OffAxis:
    """The part of the map whose walls run at another angle than θ0: a wing of the building built
    at an angle, which the lattice's axis-aligned rectangles cannot follow (the model's known limit,
    docs/robustness.md).

    The map is cut into square blocks of ``off_axis_block_m``; a block with at least two block
    sides' worth of occupied cells has its own orientation (:func:`estimate_orientation`). A block
    is off axis when that orientation differs from ``theta`` by more than ``off_axis_min_deg``
    (modulo 90°) and stacks its occupied cells at least ``off_axis_min_gain`` times sharper than
    ``theta`` does (:func:`projection_sharpness`): clutter has no orientation to speak of, and a
    block of walls at θ0 scores the same at both angles. Cartesium, intel, aces, freiburg-079, the
    ipa plans and the 30 synthetic floors have at most 3 % of their cells off axis (intel's one
    diagonal wall); two floors side by side at 10°, 30° or 45° from each other have 37–42 %.

    >>> import numpy as np
    >>> from semmap_pp.model import load_model
    >>> c = np.ones((200, 200), np.uint8); c[20:180:40, 10:190] = 2; c[10:190, 20:180:40] = 2
    >>> off_axis_walls(c, 0.0, 0.05, load_model().lattice).share
    0.0
    """
    classes = np.asarray(classes)
    b = max(16, int(round(params.off_axis_block_m / resolution)))
    need = 2 * b
    seen = off = 0
    angles, weights, corners = [], [], []
    h, w = classes.shape
    for r0 in range(0, h, b):
        for c0 in range(0, w, b):
            x, y = _occupied_points(classes[r0:r0 + b, c0:c0 + b])
            if x.size < need:
                continue
            seen += x.size
            own = _orientation_of_points(x, y, params)
            if abs(math.degrees(math.remainder(own - theta, math.pi / 2))) <= params.off_axis_min_deg:
                continue
            if projection_sharpness(x, y, own) < params.off_axis_min_gain * projection_sharpness(x, y, theta):
                continue
            off += x.size
            angles.append(math.degrees(own))
            weights.append(x.size)
            corners.append((c0, r0, min(c0 + b, w), min(r0 + b, h)))
    if not off:
        return OffAxis(0.0, math.nan, 0)
    order = np.argsort(angles)
    cum = np.cumsum(np.asarray(weights)[order])
    median = float(np.asarray(angles)[order][np.searchsorted(cum, cum[-1] / 2)])
    c = np.asarray(corners)
    box = (int(c[:, 0].min()), int(c[:, 1].min()), int(c[:, 2].max()), int(c[:, 3].max()))
    return OffAxis(off / seen, median, len(angles), box)


def off_axis_noted(share: float, params: LatticeParams) -> bool:
    """Whether walls at another angle holding ``share`` of the occupied cells get a note: from
    ``off_axis_note_share`` on, never when that is 0."""
    return 0 < params.off_axis_note_share <= share


def off_axis_note(classes: np.ndarray, frame: Frame, params: LatticeParams) -> str | None:
    """A note for the run when walls at another angle hold ``off_axis_note_share`` or more of the
    occupied cells (:func:`off_axis_walls`, :func:`off_axis_noted`), else None."""
    if params.off_axis_note_share <= 0:     # no note whatever the share: skip the blocks
        return None
    found = off_axis_walls(classes, frame.theta, frame.resolution, params)
    if not off_axis_noted(found.share, params):
        return None
    x0, y0, x1, y1 = found.box_px
    return (f"{100 * found.share:.0f} % of the occupied cells lie where the walls run at about "
            f"{found.angle_deg:.0f} deg, not along the lattice's {math.degrees(frame.theta):.1f} deg (a wing "
            f"built at another angle?), within pixels x {x0}-{x1}, y {y0}-{y1} of the image: the units "
            f"there are the lattice's rectangles and fit those walls poorly; a crop of the map to each "
            f"wing, mapped on its own, gets its own lattice (docs/robustness.md)")


@dataclass(frozen=True, eq=False)
class Frame:
    """The map resampled onto the building lattice.

    Attributes
    ----------
    theta : float
        θ0 in radians (0.0 for the identity frame).
    classes : (H', W') uint8
        Lattice classes; cells outside the input image are UNKNOWN.
    outside : (H', W') bool
        Lattice cells whose centre falls outside the input image.
    image_shape : (H, W)
        Shape of the input image.
    crop : (i0, j0, H_all, W_all) or None
        The lattice is the part of the whole image's lattice (shape ``(H_all, W_all)``) from row
        ``i0`` and column ``j0`` on that covers the known cells and a margin (:func:`known_window`);
        None: the whole image's lattice. Its cells are exactly those of the whole lattice.
    resolution : float
        Metres per cell (the same on the lattice).
    cells : CellParams
        The model's lengths in cells at this resolution.
    origin : (x, y, yaw)
        The input map's origin (ROS map_server), for metres.
    wall_samples, wall_join_px : int
        How the image is read onto this lattice where it is turned (:func:`resample`; ``[lattice]``
        of the model): sub-cells per side whose centres are read for a wall's pixels, and the
        radius in pixels of the image window that must show a wall running through a cell.
    """

    theta: float
    classes: np.ndarray
    outside: np.ndarray
    image_shape: tuple[int, int]
    resolution: float
    cells: CellParams
    origin: tuple[float, float, float] = (0.0, 0.0, 0.0)
    crop: tuple[int, int, int, int] | None = None
    wall_samples: int = 1
    wall_join_px: int = 0

    @property
    def shape(self) -> tuple[int, int]:
        return self.classes.shape

    @functools.cached_property
    def door_classes(self) -> np.ndarray:
        """``classes`` with specks made free (:func:`doorway_classes`): the cells doors and passages
        are looked for on."""
        return doorway_classes(self.classes, self.cells.door_speck)

    def _centres(self):
        h, w = self.image_shape
        i0, j0, hl, wl = self.crop if self.crop is not None else (0, 0) + tuple(self.classes.shape)
        return (w - 1) / 2.0, (h - 1) / 2.0, (wl - 1) / 2.0 - j0, (hl - 1) / 2.0 - i0

    def lattice_to_image(self, rows, cols) -> tuple[np.ndarray, np.ndarray]:
        """Continuous image coordinates ``(x_px, y_px)`` of (fractional) lattice ``(rows, cols)``."""
        oxi, oyi, oxl, oyl = self._centres()
        c, s = math.cos(self.theta), math.sin(self.theta)
        u = np.asarray(cols, dtype=np.float64) - oxl
        v = np.asarray(rows, dtype=np.float64) - oyl
        return c * u - s * v + oxi, s * u + c * v + oyi

    def image_to_lattice(self, x_px, y_px) -> tuple[np.ndarray, np.ndarray]:
        """Fractional lattice ``(rows, cols)`` of image coordinates; inverse of lattice_to_image."""
        oxi, oyi, oxl, oyl = self._centres()
        c, s = math.cos(self.theta), math.sin(self.theta)
        u = np.asarray(x_px, dtype=np.float64) - oxi
        v = np.asarray(y_px, dtype=np.float64) - oyi
        return -s * u + c * v + oyl, c * u + s * v + oxl

    def rect_vertices_px(self, rect) -> np.ndarray:
        """The four ``[x, y]`` corners of a lattice rectangle in the continuous pixel frame.

        Order: (r0, c0), (r0, c1), (r1, c1), (r1, c0) corners of the half-open cell box. The frame is
        that of :mod:`semmap_pp.cells` (pixel ``(r, c)`` spans ``[c, c+1) x [r, r+1)``), as written to
        world.json.
        """
        r0, c0, r1, c1 = (float(v) for v in rect)
        rows = np.array([r0, r0, r1, r1]) - 0.5
        cols = np.array([c0, c1, c1, c0]) - 0.5
        x, y = self.lattice_to_image(rows, cols)
        return np.stack([x + 0.5, y + 0.5], axis=1)

    def rect_from_vertices_px(self, vertices_px) -> tuple[tuple[int, int, int, int], float]:
        """The lattice rectangle nearest to four ``[x, y]`` corners in the continuous pixel frame,
        and how far (pixels) the corners lie from its own: the inverse of :meth:`rect_vertices_px`
        (0 up to the rounding of world.json's coordinates for a unit of this lattice).

        >>> from semmap_pp.model import load_model
        >>> f = build_frame_from_classes(np.zeros((50, 60), np.uint8), 0.05, load_model(), theta=0.3)
        >>> rect, off = f.rect_from_vertices_px(f.rect_vertices_px((3, 4, 20, 31)).round(3))
        >>> rect, off < 0.001
        ((3, 4, 20, 31), True)
        >>> f.rect_from_vertices_px([[0, 0], [10, 0], [10, 10], [0, 10]])[1] > 1   # not of this lattice
        True
        """
        p = np.asarray(vertices_px, dtype=np.float64).reshape(-1, 2)
        r, c = self.image_to_lattice(p[:, 0] - 0.5, p[:, 1] - 0.5)
        rect = tuple(int(round(v)) for v in (r.min() + 0.5, c.min() + 0.5, r.max() + 0.5, c.max() + 0.5))
        own = self.rect_vertices_px(rect)
        off = max(float(np.min(np.hypot(*(own - q).T))) for q in p)
        return rect, off

    def image_to_metres(self, x_px, y_px) -> tuple[np.ndarray, np.ndarray]:
        """Map-frame metres of continuous pixel-frame coordinates (ROS map_server, as :mod:`semmap_pp.grid`).

        ``(x_px, y_px) = (c + 0.5, r + 0.5)`` is the centre of pixel ``(r, c)``; ``(0, height)`` is the
        bottom-left image corner, which map_server places at the origin.
        """
        h = self.image_shape[0]
        u = np.asarray(x_px, dtype=np.float64) * self.resolution
        v = (h - np.asarray(y_px, dtype=np.float64)) * self.resolution
        ox, oy, yaw = self.origin
        c, s = math.cos(yaw), math.sin(yaw)
        return ox + c * u - s * v, oy + s * u + c * v

    def metres_to_image(self, x_m, y_m) -> tuple[np.ndarray, np.ndarray]:
        """Continuous pixel-frame coordinates of map-frame metres; inverse of :meth:`image_to_metres`."""
        ox, oy, yaw = self.origin
        c, s = math.cos(yaw), math.sin(yaw)
        dx, dy = np.asarray(x_m, dtype=np.float64) - ox, np.asarray(y_m, dtype=np.float64) - oy
        u, v = c * dx + s * dy, -s * dx + c * dy
        return u / self.resolution, self.image_shape[0] - v / self.resolution

    def rect_vertices_m(self, rect) -> np.ndarray:
        """The four corners of :meth:`rect_vertices_px` in map-frame metres."""
        v = self.rect_vertices_px(rect)
        x, y = self.image_to_metres(v[:, 0], v[:, 1])
        return np.stack([x, y], axis=1)

    def to_image(self, lattice_array: np.ndarray, fill=0) -> np.ndarray:
        """Resample a lattice array into the input image frame (nearest neighbour).

        Image pixels whose centre falls outside the lattice take ``fill``.
        """
        a = np.asarray(lattice_array)
        if a.shape[:2] != self.classes.shape:
            raise ValueError(f"expected a lattice array of shape {self.classes.shape}, got {a.shape}")
        if self.theta == 0.0 and self.crop is None:
            return a.copy()
        return self.box_to_image(a, (0, 0) + a.shape[:2], fill)

    def _box_args(self, box_array, box, window):
        """``(array, (r0, c0, r1, c1), (y0, y1, x0, x1))`` of :meth:`box_to_image`'s arguments, the
        array checked against the box, the window defaulting to the whole image."""
        a = np.asarray(box_array)
        r0, c0, r1, c1 = (int(v) for v in box)
        if a.shape[:2] != (r1 - r0, c1 - c0):
            raise ValueError(f"expected an array of the box's shape {(r1 - r0, c1 - c0)}, got {a.shape}")
        h, w = self.image_shape
        return a, (r0, c0, r1, c1), ((0, h, 0, w) if window is None else tuple(int(v) for v in window))

    def box_to_image(self, box_array: np.ndarray, box, fill=0, window=None, step: int = 1) -> np.ndarray:
        """:meth:`to_image` of an array that covers the lattice box ``(r0, c0, r1, c1)`` only:
        image pixels whose centre falls outside the box take ``fill`` (the same image as
        :meth:`to_image` of a lattice array holding ``fill`` outside the box, without one).
        ``window`` ``(y0, y1, x0, x1)`` and ``step``: only the pixels ``[y0:y1:step, x0:x1:step]``
        of that image (default: all of it)."""
        a, (r0, c0, r1, c1), (y0, y1, x0, x1) = self._box_args(box_array, box, window)
        h, w = self.image_shape
        ys, xs = np.arange(y0, y1, step), np.arange(x0, x1, step)
        if self.theta == 0.0:
            i0, j0 = self.crop[:2] if self.crop is not None else (0, 0)
            ri, ci = ys - i0, xs - j0
            out = np.full((len(ys), len(xs)) + a.shape[2:], fill, dtype=a.dtype)
            ok_r, ok_c = (ri >= r0) & (ri < r1), (ci >= c0) & (ci < c1)
            out[np.ix_(ok_r, ok_c)] = a[np.ix_(ri[ok_r] - r0, ci[ok_c] - c0)]
            return out
        out = np.full((len(ys), len(xs)) + a.shape[2:], fill, dtype=a.dtype)
        # only the pixels of the box's footprint (its corners' bounding box, a cell wider)
        x, y = self.lattice_to_image(np.array([r0 - 0.5, r0 - 0.5, r1 - 0.5, r1 - 0.5]),
                                     np.array([c0 - 0.5, c1 - 0.5, c0 - 0.5, c1 - 0.5]))
        fx0, fx1 = max(int(math.floor(x.min())) - 1, 0), min(int(math.ceil(x.max())) + 2, w)
        fy0, fy1 = max(int(math.floor(y.min())) - 1, 0), min(int(math.ceil(y.max())) + 2, h)
        cols = np.flatnonzero((xs >= fx0) & (xs < fx1))
        rows = np.flatnonzero((ys >= fy0) & (ys < fy1))
        if not len(cols) or not len(rows) or r0 >= r1 or c0 >= c1:
            return out
        k0, k1 = cols[0], cols[-1] + 1
        for b0 in range(rows[0], rows[-1] + 1, BAND_ROWS):   # in bands of rows: a band's coordinates only
            b1 = min(b0 + BAND_ROWS, rows[-1] + 1)
            yy, xx = np.meshgrid(ys[b0:b1], xs[k0:k1], indexing="ij")
            lr, lc = self.image_to_lattice(xx, yy)
            ri, ci = np.rint(lr).astype(np.intp), np.rint(lc).astype(np.intp)
            ok = (ri >= r0) & (ri < r1) & (ci >= c0) & (ci < c1)
            part = out[b0:b1, k0:k1]
            part[ok] = a[ri[ok] - r0, ci[ok] - c0]
        return out

    def lattice_pixels(self, i0: int, i1: int, j0: int = 0, j1: int | None = None):
        """The image pixel under the centre of each lattice cell of rows ``i0:i1``, columns
        ``j0:j1`` (default: every column): ``(xi, yi, inside)``, the pixel's column and row
        (``np.rint`` of :meth:`lattice_to_image`, intp) and whether it lies in the image. Callers
        go over the lattice in bands of :data:`BAND_ROWS` rows (:meth:`bands`), so that these
        arrays stay the size of a band, not of the lattice."""
        j1 = self.classes.shape[1] if j1 is None else j1
        rows, cols = np.mgrid[i0:i1, j0:j1]
        x, y = self.lattice_to_image(rows, cols)
        xi, yi = np.rint(x).astype(np.intp), np.rint(y).astype(np.intp)
        h, w = self.image_shape
        return xi, yi, (xi >= 0) & (xi < w) & (yi >= 0) & (yi < h)

    def bands(self, i0: int = 0, i1: int | None = None):
        """``(b0, b1)`` row ranges of at most :data:`BAND_ROWS` rows covering ``i0:i1``."""
        i1 = self.classes.shape[0] if i1 is None else i1
        return [(b, min(b + BAND_ROWS, i1)) for b in range(i0, i1, BAND_ROWS)]


#: Rows of the lattice (or the image) resampled at a time: the float64 coordinates of a band, not
#: of the whole lattice (on a 23 M-cell campus canvas those were 1.5 GB at once).
BAND_ROWS = 256


#: The lattice is cropped only when the part kept holds at most this share of the whole lattice's
#: cells: a crop saves time and memory in proportion to what it leaves out, and a few per cent are
#: not worth a lattice of another extent (the search's random draws depend on it: on three of the
#: 30 synthetic floors, whose crops kept 94-99 % of the cells, W* changed both ways).
CROP_MAX_SHARE = 0.5


def known_window(classes: np.ndarray, margin: int) -> tuple[int, int, int, int] | None:
    """``(r0, c0, r1, c1)``: the bounding box of the known (not unknown) cells grown by ``margin``
    cells and clipped to the image; None when that is the whole image, when ``margin`` is 0 (no
    crop) or when no cell is known.

    >>> c = np.full((100, 200), UNKNOWN, np.uint8); c[40:50, 90:120] = 0
    >>> known_window(c, 10), known_window(c, 0), known_window(c, 100)
    ((30, 80, 60, 130), None, None)
    """
    box = known_box(classes) if margin > 0 else None
    if box is None:
        return None
    h, w = np.shape(classes)
    r0, c0, r1, c1 = box
    win = (max(r0 - margin, 0), max(c0 - margin, 0), min(r1 + margin, h), min(c1 + margin, w))
    return None if win == (0, 0, h, w) else win


def lattice_orientation(classes: np.ndarray, params: LatticeParams, theta: float | None = None) -> float:
    """The lattice's θ0 in radians: ``theta`` (estimated by :func:`estimate_orientation` when
    None), 0.0 when it is below ``identity_below_deg`` (the image itself is the lattice)."""
    if theta is None:
        theta = estimate_orientation(classes, params)
    return 0.0 if abs(math.degrees(theta)) < params.identity_below_deg else float(theta)


def build_frame_from_classes(classes: np.ndarray, resolution: float, model: Model,
                             origin=(0.0, 0.0, 0.0), theta: float | None = None,
                             crop_max_share: float = None) -> Frame:
    """Estimate θ0 (unless given) and resample ``classes`` onto the lattice.

    Parameters
    ----------
    classes : (H, W) uint8
        Input classes.
    resolution : float
        Metres per cell.
    model : Model
        The model (lattice parameters, lengths).
    origin : (x, y, yaw)
        Map origin, for metres.
    theta : float, optional
        Use this orientation instead of estimating one (radians).
    crop_max_share : float, optional
        Crop the lattice to the known cells when that keeps at most this share of its cells
        (default :data:`CROP_MAX_SHARE`; 1.0 crops whenever there is a margin to cut).
    """
    share = CROP_MAX_SHARE if crop_max_share is None else float(crop_max_share)
    classes = np.asarray(classes, dtype=np.uint8)
    theta = lattice_orientation(classes, model.lattice, theta)
    samples, join_px = model.lattice.wall_samples, model.lattice.wall_join_px
    h, w = classes.shape
    cells = model.cells(resolution)
    origin = tuple(float(v) for v in origin)
    window = known_window(classes, int(math.ceil(model.lattice.crop_margin_m / resolution - 1e-9)))
    crop = None
    if window is not None and (window[2] - window[0]) * (window[3] - window[1]) > share * h * w:
        window = None   # too little to leave out (CROP_MAX_SHARE)
    if theta == 0.0:
        r0, c0, r1, c1 = window if window is not None else (0, 0, h, w)
        lat = classes[r0:r1, c0:c1].copy()
        outside = np.zeros(lat.shape, dtype=bool)
        if window is not None:
            crop = (r0, c0, h, w)
    else:
        c, s = abs(math.cos(theta)), abs(math.sin(theta))
        wl = int(math.ceil(w * c + h * s - 1e-9))
        hl = int(math.ceil(w * s + h * c - 1e-9))
        probe = Frame(theta, np.zeros((1, 1), np.uint8), np.zeros((1, 1), bool), (h, w),
                      float(resolution), cells, origin, (0, 0, hl, wl))
        i0, j0, i1, j1 = 0, 0, hl, wl
        if window is not None:   # the whole lattice's cells over the window's corners
            r0, c0, r1, c1 = window
            rr, cc = probe.image_to_lattice(np.array([c0 - 0.5, c1 - 0.5, c0 - 0.5, c1 - 0.5]),
                                            np.array([r0 - 0.5, r0 - 0.5, r1 - 0.5, r1 - 0.5]))
            i0, i1 = max(int(math.floor(rr.min())), 0), min(int(math.ceil(rr.max())) + 1, hl)
            j0, j1 = max(int(math.floor(cc.min())), 0), min(int(math.ceil(cc.max())) + 1, wl)
            if (i1 - i0) * (j1 - j0) <= share * hl * wl:
                crop = (i0, j0, hl, wl)
            else:
                i0, j0, i1, j1 = 0, 0, hl, wl
        lat, inside = resample(probe, classes, i0, i1, j0, j1, samples, join_px)
        outside = ~inside
    lat.setflags(write=False)
    outside.setflags(write=False)
    return Frame(float(theta), lat, outside, (h, w), float(resolution), cells, origin, crop, samples,
                 join_px)


def resample(frame: Frame, classes: np.ndarray, i0: int, i1: int, j0: int, j1: int,
             samples: int = 1, join_px: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """The image ``classes`` read onto rows ``i0:i1``, columns ``j0:j1`` of ``frame``'s lattice:
    ``(cells, inside)``. Each cell takes the class of the pixel under its centre
    (:meth:`Frame.lattice_pixels`; UNKNOWN where that lies outside the image, ``inside`` false).

    A wall one pixel thick at an angle to the lattice is a staircase of pixels; where it runs
    between two rows of cells the centres read it on either row by turns, with holes where neither
    does, and the rooms on its two sides become one. With ``samples`` > 1 and ``join_px`` > 0 a
    cell is occupied too when it closes such a hole (:func:`closes_wall`): an occupied pixel lies
    under the centre of one of its ``samples`` x ``samples`` sub-cells, and the cell joins what
    the image shows joined and the centres broke apart.
    """
    cells = np.full((i1 - i0, j1 - j0), UNKNOWN, dtype=np.uint8)
    inside = np.zeros(cells.shape, dtype=bool)
    joining = samples > 1 and join_px > 0
    hits = np.zeros(cells.shape, dtype=bool) if joining else None
    occupied_px = np.asarray(classes) == OCCUPIED
    h, w = occupied_px.shape
    offsets = (np.arange(samples) + 0.5) / samples - 0.5
    for b0, b1 in frame.bands(i0, i1):   # in bands: no coordinate array of the lattice's size
        xi, yi, ok = frame.lattice_pixels(b0, b1, j0, j1)
        cells[b0 - i0:b1 - i0][ok] = classes[yi[ok], xi[ok]]
        inside[b0 - i0:b1 - i0] = ok
        if not joining:
            continue
        rows, cols = np.mgrid[b0:b1, j0:j1]
        for dr in offsets:
            for dc in offsets:
                x, y = frame.lattice_to_image(rows + dr, cols + dc)
                xs, ys = np.rint(x).astype(np.intp), np.rint(y).astype(np.intp)
                sub = ok & (xs >= 0) & (xs < w) & (ys >= 0) & (ys < h)
                hits[b0 - i0:b1 - i0][sub] |= occupied_px[ys[sub], xs[sub]]
    if joining:
        cells[closes_wall(frame, classes, cells, hits, i0, j0, join_px)] = OCCUPIED
    return cells, inside


def closes_wall(frame: Frame, classes: np.ndarray, cells: np.ndarray, hits: np.ndarray, i0: int,
                j0: int, join_px: int) -> np.ndarray:
    """The cells of ``cells`` (lattice rows ``i0:``, columns ``j0:`` of ``frame``) that close a hole
    the centres left in a wall of the image ``classes``; ``hits``: an occupied pixel lies under one
    of the cell's sub-cell centres. A cell closes a hole when, besides its hit, it is not occupied
    and

    * the occupied cells around it form two or more 8-connected pieces (:func:`joins_pieces`),
    * the free cells around it two or more 4-connected pieces (:func:`ring_pieces`): floor on both
      sides, a hole that lets one side's floor into the other's (the edge of furniture with unknown
      behind it, or an outer wall, joins nothing),
    * and in the image the pixels that are not occupied within ``join_px`` of its centre form two
      or more 4-connected pieces of at least two pixels each (:func:`image_splits`): a wall of the
      image runs through it unbroken, so the cell does not join specks of clutter or a dotted line
      that the image leaves open.
    """
    occupied = cells == OCCUPIED
    cand = hits & ~occupied & joins_pieces(occupied) & (ring_pieces(cells == FREE, 4) >= 2)
    if cand.any():
        cand &= image_splits(frame, classes, cand, i0, j0, join_px)
    return cand


def image_splits(frame: Frame, classes: np.ndarray, cand: np.ndarray, i0: int, j0: int,
                 radius: int) -> np.ndarray:
    """For each cell of ``cand`` (lattice rows ``i0:``, columns ``j0:``): whether the pixels of the
    image ``classes`` that are not occupied, within ``radius`` pixels (a square window) of the
    pixel under its centre, form two or more 4-connected pieces of at least two pixels (a wall of
    the image runs through the cell). Cells whose window leaves the image: False.

    >>> c = np.full((9, 9), FREE, np.uint8); c[4, :] = OCCUPIED           # a wall across
    >>> f = Frame(0.0, c, np.zeros(c.shape, bool), c.shape, 0.05, None)
    >>> one = np.zeros(c.shape, bool); one[4, 4] = True
    >>> bool(image_splits(f, c, one, 0, 0, 2)[4, 4])
    True
    >>> c[4, 4] = FREE                                                      # a gap in it
    >>> bool(image_splits(f, c, one, 0, 0, 2)[4, 4])
    False
    """
    out = np.zeros(cand.shape, dtype=bool)
    rr, cc = np.nonzero(cand)
    x, y = frame.lattice_to_image(rr + i0, cc + j0)
    xs, ys = np.rint(x).astype(np.intp), np.rint(y).astype(np.intp)
    h, w = np.shape(classes)
    open_px = np.asarray(classes) != OCCUPIED
    for r, c, xa, ya in zip(rr, cc, xs - radius, ys - radius):
        if ya < 0 or xa < 0 or ya + 2 * radius + 1 > h or xa + 2 * radius + 1 > w:
            continue
        labels, n = ndimage.label(open_px[ya:ya + 2 * radius + 1, xa:xa + 2 * radius + 1])
        if n >= 2 and np.count_nonzero(np.bincount(labels.ravel())[1:] >= 2) >= 2:
            out[r, c] = True
    return out


@functools.cache
def _ring_table(connectivity: int) -> np.ndarray:
    """For each of the 256 ways the 8 neighbours of a cell can be set (bit k: the k-th of
    :data:`_RING`), how many pieces they form (``connectivity`` 4 or 8), the cell itself left out."""
    structure = np.ones((3, 3), bool) if connectivity == 8 else None
    out = np.zeros(256, dtype=np.uint8)
    for code in range(256):
        m = np.zeros((3, 3), bool)
        for k, (dr, dc) in enumerate(_RING):
            m[1 + dr, 1 + dc] = bool(code >> k & 1)
        out[code] = ndimage.label(m, structure=structure)[1]
    return out


#: the 8 neighbours of a cell, (row, column) offsets
_RING = ((0, 1), (-1, 1), (-1, 0), (-1, -1), (0, -1), (1, -1), (1, 0), (1, 1))


def ring_pieces(mask: np.ndarray, connectivity: int = 8) -> np.ndarray:
    """How many pieces (``connectivity`` 4 or 8) the cells of ``mask`` among each cell's 8
    neighbours form, the cell itself left out.

    >>> m = np.zeros((3, 3), bool); m[0, :] = m[2, :] = True               # floor above and below
    >>> int(ring_pieces(m, 4)[1, 1]), int(ring_pieces(~m, 8)[1, 1])
    (2, 2)
    """
    p = np.pad(np.asarray(mask, bool), 1)
    h, w = np.shape(mask)
    code = np.zeros((h, w), dtype=np.uint8)     # 8 neighbours, one bit each: a byte per cell
    for k, (dr, dc) in enumerate(_RING):
        code |= p[1 + dr:1 + dr + h, 1 + dc:1 + dc + w].view(np.uint8) << np.uint8(k)
    return _ring_table(connectivity)[code]


def joins_pieces(occupied: np.ndarray) -> np.ndarray:
    """Whether the occupied cells among each cell's 8 neighbours form two or more 8-connected
    pieces (a cell made occupied there would join them).

    >>> m = np.zeros((3, 5), bool); m[1, [1, 3]] = True         # two pieces of a wall, a gap
    >>> joins_pieces(m)[1].tolist()
    [False, False, True, False, False]
    >>> m[1, 3] = False; m[0, 2] = True                         # a bend: one piece
    >>> bool(joins_pieces(m)[1, 2])
    False
    """
    return ring_pieces(occupied, 8) >= 2


def build_frame(grid, model: Model, theta: float | None = None) -> Frame:
    """The building lattice of an :class:`~semmap_pp.grid.OccupancyGrid` (the module contract)."""
    return build_frame_from_classes(grid.classes, grid.resolution, model, origin=grid.origin,
                                    theta=theta)
