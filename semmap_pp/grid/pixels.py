"""The pixel -> occupancy -> class rule of ROS map_server, over whole arrays.

``v`` is the mean of a pixel's colour channels on the 0..255 scale (alpha never takes part; 16-bit
and other maxvals are scaled by ``v * 255 / maxval`` first). Then, as in map_server's
``image_loader.cpp``:

* ``negate`` replaces ``v`` by ``255 - v``;
* trinary and scale: ``p = (255 - v) / 255``; ``p > occupied_thresh`` -> OCCUPIED,
  ``p < free_thresh`` -> FREE, otherwise UNKNOWN; a fully transparent pixel (alpha == 0) is UNKNOWN
  (its ``p`` is NaN);
* raw: ``round(v)`` is the occupancy in percent: 0..100 gives ``p = round(v) / 100``, classified by
  the same thresholds; anything above 100 (255 is ROS's -1) is UNKNOWN with ``p`` NaN; alpha is
  ignored.
"""

from __future__ import annotations

import numpy as np

from semmap_pp.cells import FREE, OCCUPIED, UNKNOWN

MODES = ("trinary", "scale", "raw")


def occupancy_from_grey(grey: np.ndarray, alpha: np.ndarray | None = None, *,
                        negate: bool = False, mode: str = "trinary",
                        dtype: type = np.float32) -> np.ndarray:
    """Occupancy probability ``p`` in [0, 1] of each pixel (NaN where the map says unknown).

    Parameters
    ----------
    grey : np.ndarray, shape (H, W)
        Mean colour value of each pixel on the 0..255 scale (may be fractional).
    alpha : np.ndarray of uint8, shape (H, W), optional
        Alpha channel (0 = fully transparent), or None for images without one.
    negate : bool
        map_server's ``negate``: dark is free, light is occupied.
    mode : {"trinary", "scale", "raw"}
    dtype : numpy float type
        Type of the result (the arithmetic is float64, like map_server's doubles).

    Returns
    -------
    np.ndarray of ``dtype``, shape (H, W)

    Examples
    --------
    >>> import numpy as np
    >>> occupancy_from_grey(np.array([[255.0, 0.0, 204.0]]), dtype=np.float64).tolist()
    [[0.0, 1.0, 0.2]]
    >>> occupancy_from_grey(np.array([[0.0, 100.0, 255.0]]), mode="raw").tolist()
    [[0.0, 1.0, nan]]
    """
    if mode not in MODES:
        raise ValueError(f"mode must be one of {MODES}, got {mode!r}")
    v = np.asarray(grey, dtype=np.float64)
    if negate:
        v = 255.0 - v
    if mode == "raw":
        percent = np.floor(v + 0.5)
        p = np.where(percent <= 100.0, percent / 100.0, np.nan)
    else:
        p = (255.0 - v) / 255.0
        if alpha is not None:
            p = np.where(np.asarray(alpha) == 0, np.nan, p)
    return p.astype(dtype, copy=False)


def classify(occupancy: np.ndarray, occupied_thresh: float, free_thresh: float) -> np.ndarray:
    """Classes of :mod:`semmap_pp.cells` from occupancy probabilities (NaN -> UNKNOWN).

    Comparisons are strict, as in map_server: ``p > occupied_thresh`` is OCCUPIED and
    ``p < free_thresh`` is FREE; everything else, NaN included, is UNKNOWN.

    Examples
    --------
    >>> import numpy as np
    >>> classify(np.array([[0.0, 0.5, 1.0, np.nan]]), 0.65, 0.196).tolist()
    [[0, 1, 2, 1]]
    """
    p = np.asarray(occupancy, dtype=np.float64)
    classes = np.full(p.shape, UNKNOWN, dtype=np.uint8)
    with np.errstate(invalid="ignore"):
        classes[p > occupied_thresh] = OCCUPIED
        classes[p < free_thresh] = FREE
    return classes


def classify_grey(grey: np.ndarray, alpha: np.ndarray | None, *, negate: bool, mode: str,
                  occupied_thresh: float, free_thresh: float) -> tuple[np.ndarray, np.ndarray]:
    """``(classes, occupancy float32)`` of a grey image.

    The classes come from the float64 occupancy, so a grey level next to a threshold falls the way
    map_server's double arithmetic puts it, not the way the rounded float32 would.
    """
    p = occupancy_from_grey(grey, alpha, negate=negate, mode=mode, dtype=np.float64)
    return classify(p, occupied_thresh, free_thresh), p.astype(np.float32)


def ros_values(occupancy: np.ndarray, *, mode: str, occupied_thresh: float,
               free_thresh: float) -> np.ndarray:
    """map_server's int8 cell values (-1 unknown, 0..100), in image row order (row 0 on top).

    trinary: 0 / 100 / -1; scale: in-between cells get ``1 + 98 * ratio`` (truncated, as
    map_server's ``unsigned char`` assignment does); raw: the percentage itself. ``nav_msgs``
    stores rows bottom-up: flip with ``[::-1]`` to get its order.

    Examples
    --------
    >>> import numpy as np
    >>> ros_values(np.array([[0.0, 0.5, 1.0, np.nan]]), mode="scale",
    ...            occupied_thresh=0.75, free_thresh=0.25).tolist()
    [[0, 50, 100, -1]]
    """
    p = np.asarray(occupancy, dtype=np.float64)
    known = np.isfinite(p)
    out = np.full(p.shape, -1, dtype=np.int8)
    if mode == "raw":
        out[known] = np.floor(p[known] * 100.0 + 0.5).astype(np.int8)
        return out
    q = np.where(known, p, 0.0)
    occ = known & (q > occupied_thresh)
    free = known & (q < free_thresh)
    out[occ] = 100
    out[free] = 0
    if mode == "scale":
        mid = known & ~occ & ~free
        ratio = (q[mid] - free_thresh) / (occupied_thresh - free_thresh)
        out[mid] = np.floor(1.0 + 98.0 * ratio).astype(np.int8)
    return out
