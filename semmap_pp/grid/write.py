"""Writing maps in ROS map_server form (``NAME.yaml`` + ``NAME.pgm``).

The image is written as binary PGM (P5, maxval 255), the YAML names it by a path relative to the
YAML file, and both files are written atomically (image first, so a YAML never names a missing or
half-written image).
"""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np
import yaml

from semmap_pp import atomic
from semmap_pp.cells import FREE, OCCUPIED, UNKNOWN
from semmap_pp.errors import OutputError
from semmap_pp.grid.meta import DEFAULT_FREE_THRESH, DEFAULT_OCCUPIED_THRESH
from semmap_pp.grid.pixels import MODES

# map_saver's grey levels for the three classes (ROS map_saver writes exactly these).
GREY_FREE = 254
GREY_UNKNOWN = 205
GREY_OCCUPIED = 0


def classes_to_image(classes: np.ndarray) -> np.ndarray:
    """Map-server grey image of a class array (FREE -> 254, UNKNOWN -> 205, OCCUPIED -> 0).

    Parameters
    ----------
    classes : np.ndarray of uint8, shape (H, W)
        Codes from :mod:`semmap_pp.cells`.

    Returns
    -------
    np.ndarray of uint8, shape (H, W)

    Examples
    --------
    >>> import numpy as np
    >>> classes_to_image(np.array([[0, 1, 2]], dtype=np.uint8)).tolist()
    [[254, 205, 0]]
    """
    classes = np.asarray(classes)
    if classes.ndim != 2:
        raise ValueError(f"classes must be 2-D, got shape {classes.shape}")
    known = (classes == FREE) | (classes == UNKNOWN) | (classes == OCCUPIED)
    if not known.all():
        bad = np.unique(classes[~known])[:5].tolist()
        raise ValueError(f"classes holds codes that are not FREE/UNKNOWN/OCCUPIED: {bad}")
    image = np.full(classes.shape, GREY_UNKNOWN, dtype=np.uint8)
    image[classes == FREE] = GREY_FREE
    image[classes == OCCUPIED] = GREY_OCCUPIED
    return image


def encode_pgm(image: np.ndarray, comment: str | None = None) -> bytes:
    """Bytes of a binary PGM (P5, maxval 255) holding ``image`` (uint8, shape (H, W))."""
    image = np.ascontiguousarray(image, dtype=np.uint8)
    h, w = image.shape
    header = "P5\n"
    if comment:
        header += "# " + " ".join(comment.split()) + "\n"
    header += f"{w} {h}\n255\n"
    return header.encode("ascii") + image.tobytes()


def write_map(yaml_path: str | os.PathLike, image: np.ndarray, resolution: float,
              origin: tuple[float, float, float] = (0.0, 0.0, 0.0),
              occupied_thresh: float = DEFAULT_OCCUPIED_THRESH,
              free_thresh: float = DEFAULT_FREE_THRESH,
              negate: int = 0, mode: str = "trinary") -> Path:
    """Write ``NAME.yaml`` and ``NAME.pgm`` as ROS map_server reads them.

    Parameters
    ----------
    yaml_path : path-like
        Where the YAML goes; the image is written beside it with the suffix ``.pgm``.
    image : np.ndarray of uint8, shape (H, W)
        Map-server grey values, row 0 the top row (e.g. from :func:`classes_to_image`).
    resolution : float
        Metres per cell, > 0.
    origin : (x, y, yaw)
        Map frame position of the bottom-left corner of the bottom-left pixel.
    occupied_thresh, free_thresh : float
        Thresholds written to the YAML (``0 <= free < occupied <= 1``).
    negate : {0, 1}
    mode : {"trinary", "scale", "raw"}
        How map_server reads the grey values (``raw``: each value is the cell's value itself).

    Returns
    -------
    Path
        The YAML path written.

    Examples
    --------
    >>> import tempfile, pathlib, numpy as np
    >>> d = pathlib.Path(tempfile.mkdtemp())
    >>> p = write_map(d / "m.yaml", np.array([[254, 0]], dtype=np.uint8), 0.05)
    >>> sorted(x.name for x in d.iterdir())
    ['m.pgm', 'm.yaml']
    """
    yaml_path = Path(yaml_path)
    image = np.asarray(image)
    if image.ndim != 2 or image.size == 0:
        raise ValueError(f"image must be a non-empty 2-D array, got shape {image.shape}")
    if image.dtype != np.uint8:
        raise ValueError(f"image must be uint8, got {image.dtype}")
    resolution = float(resolution)
    if not (math.isfinite(resolution) and resolution > 0):
        raise ValueError(f"resolution must be a positive finite number, got {resolution}")
    origin_t = tuple(float(v) for v in origin)
    if len(origin_t) != 3 or not all(math.isfinite(v) for v in origin_t):
        raise ValueError(f"origin must be 3 finite numbers (x, y, yaw), got {origin!r}")
    occ, free = float(occupied_thresh), float(free_thresh)
    if not (0.0 <= free < occ <= 1.0):
        raise ValueError(f"need 0 <= free_thresh < occupied_thresh <= 1, got {free}, {occ}")
    if int(negate) not in (0, 1):
        raise ValueError(f"negate must be 0 or 1, got {negate!r}")
    if mode not in MODES:
        raise ValueError(f"mode must be one of {MODES}, got {mode!r}")

    image_path = yaml_path.with_suffix(".pgm")
    if image_path == yaml_path:
        raise ValueError(f"{yaml_path}: the YAML path must not end in .pgm")
    doc = {
        "image": image_path.name,
        "resolution": resolution,
        "origin": list(origin_t),
        "negate": int(negate),
        "occupied_thresh": occ,
        "free_thresh": free,
        "mode": mode,
    }
    text = yaml.safe_dump(doc, sort_keys=False, default_flow_style=None)
    try:
        atomic.write_bytes(image_path, encode_pgm(image, f"semmap_pp {resolution:.3f} m/pix"))
        atomic.write_text(yaml_path, text)
    except OSError as exc:
        raise OutputError(yaml_path, f"cannot write map: {exc.strerror or exc}") from exc
    return yaml_path


def save_grid(grid, yaml_path: str | os.PathLike) -> Path:
    """Write ``grid``'s classes back in map_server form (``NAME.yaml`` + ``NAME.pgm``).

    The image holds map_saver's grey levels (254 / 205 / 0) and the YAML the map_server default
    thresholds 0.65 / 0.196 with ``negate: 0``, which classify those levels back into the same
    classes whatever thresholds the grid was loaded with. Resolution and origin are kept; the
    scaled occupancy values are not.

    Examples
    --------
    >>> import tempfile, pathlib, numpy as np
    >>> from semmap_pp.grid import OccupancyGrid, load_map
    >>> g = OccupancyGrid(np.array([[0, 1], [2, 0]], np.uint8), np.zeros((2, 2)), 0.1)
    >>> d = pathlib.Path(tempfile.mkdtemp())
    >>> load_map(save_grid(g, d / "g.yaml")).classes.tolist()
    [[0, 1], [2, 0]]
    """
    return write_map(yaml_path, classes_to_image(grid.classes), grid.resolution,
                     origin=grid.origin)
