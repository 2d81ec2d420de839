"""``load_map``: a map file (YAML, image or ``.npy``) -> :class:`OccupancyGrid`."""

from __future__ import annotations

import os
from pathlib import Path

from semmap_pp.errors import MapError
from semmap_pp.grid import images, meta
from semmap_pp.grid.model import OccupancyGrid
from semmap_pp.grid.pixels import classify_grey

YAML_SUFFIXES = (".yaml", ".yml")
IMAGE_SUFFIXES = (".png", ".pgm", ".npy")


def load_map(path: str | os.PathLike, *, occupied_thresh: float | None = None,
             free_thresh: float | None = None, negate: int | bool | None = None,
             resolution: float | None = None, mode: str | None = None,
             max_cells: int = images.MAX_CELLS, allow_outside: bool = False) -> OccupancyGrid:
    """Load and classify an occupancy grid map.

    Parameters
    ----------
    path : path-like
        A ROS map_server YAML file (``.yaml``/``.yml``) naming its image, or a bare image
        (``.png``, ``.pgm``) or 2-D array (``.npy``).
    occupied_thresh, free_thresh, negate, resolution, mode : optional
        Override the YAML's values, or complete a bare image's (defaults 0.65, 0.196, 0,
        0.05 m/cell with a note, ``"trinary"``).
    max_cells : int
        Refuse images with more cells (checked from the header, before decoding).
    allow_outside : bool
        Let a YAML name an image outside its own folder (absolute path, ``~`` or ``..``); by
        default such a YAML is refused, so that a shared map file cannot make the program read
        arbitrary files (docs/formats.md).

    Returns
    -------
    OccupancyGrid

    Raises
    ------
    MapError
        For any unreadable, malformed or nonsensical input; the message names the file.

    Examples
    --------
    >>> import tempfile, pathlib, numpy as np
    >>> from semmap_pp.grid import write_map
    >>> d = pathlib.Path(tempfile.mkdtemp())
    >>> _ = write_map(d / "m.yaml", np.array([[254, 205, 0]], dtype=np.uint8), 0.1)
    >>> load_map(d / "m.yaml").classes.tolist()
    [[0, 1, 2]]
    """
    path = Path(path)
    if not path.exists():
        raise MapError(path, "map file does not exist")
    if path.is_dir():
        raise MapError(path, "is a directory; expected a map .yaml file, an image or a .npy array")
    if max_cells <= 0:
        raise ValueError(f"max_cells must be positive, got {max_cells}")
    overrides = {"occupied_thresh": occupied_thresh, "free_thresh": free_thresh,
                 "negate": negate, "resolution": resolution, "mode": mode}
    suffix = path.suffix.lower()
    if suffix in YAML_SUFFIXES:
        params = meta.params_from_yaml(path, meta.read_yaml(path), overrides,
                                       allow_outside=allow_outside)
    elif suffix in IMAGE_SUFFIXES:
        params = meta.params_for_image(path, overrides)
    else:
        raise MapError(path, f"unsupported map file type {path.suffix or '(no suffix)'!r}; "
                             f"expected {', '.join(YAML_SUFFIXES + IMAGE_SUFFIXES)}")
    decoded = images.decode_image(params.image, max_cells=max_cells)
    height, width = decoded.grey.shape
    meta.check_extent(path, width, height, params.resolution, params.origin)
    classes, occupancy = classify_grey(
        decoded.grey, decoded.alpha, negate=params.negate, mode=params.mode,
        occupied_thresh=params.occupied_thresh, free_thresh=params.free_thresh)
    return OccupancyGrid(
        classes=classes, occupancy=occupancy, resolution=params.resolution,
        origin=params.origin, source=path, image_path=params.image, mode=params.mode,
        occupied_thresh=params.occupied_thresh, free_thresh=params.free_thresh,
        negate=params.negate, image_format=decoded.description, notes=params.notes)
