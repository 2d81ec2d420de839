"""``load_map``: a map file (YAML, image, ``.npy`` or a bag) -> :class:`OccupancyGrid`."""

from __future__ import annotations

import os
from pathlib import Path

from semmap_pp.errors import MapError
from semmap_pp.grid import images, meta, rosbag
from semmap_pp.grid.occupancy import OccupancyGrid
from semmap_pp.grid.pixels import classify_grey

YAML_SUFFIXES = (".yaml", ".yml")
IMAGE_SUFFIXES = (".png", ".pgm", ".npy")


def load_map(path: str | os.PathLike, *, occupied_thresh: float | None = None,
             free_thresh: float | None = None, negate: int | bool | None = None,
             resolution: float | None = None, mode: str | None = None,
             max_cells: int = images.MAX_CELLS, allow_outside: bool = False,
             topic: str | None = None, at: float | str | None = None) -> OccupancyGrid:
    """Load and classify an occupancy grid map.

    Parameters
    ----------
    path : path-like
        A ROS map_server YAML file (``.yaml``/``.yml``) naming its image, a bare image
        (``.png``, ``.pgm``) or 2-D array (``.npy``), or a bag holding ``nav_msgs/OccupancyGrid``
        messages: a ROS 2 bag folder, a ``.mcap`` or ``.db3`` file, a ROS 1 ``.bag``
        (:mod:`semmap_pp.grid.rosbag`).
    occupied_thresh, free_thresh, negate, resolution, mode : optional
        Override the YAML's values, or complete a bare image's (defaults 0.65, 0.196, 0,
        0.05 m/cell with a note, ``"trinary"``). A bag's message has its own resolution and no
        negate or mode (its cells are occupancy percentages).
    topic, at : optional
        A bag's map topic (default its one ``nav_msgs/OccupancyGrid`` topic) and message
        (``"last"``, the default, or seconds since the bag's start); other maps ignore them.
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
    if max_cells <= 0:
        raise ValueError(f"max_cells must be positive, got {max_cells}")
    if rosbag.is_bag(path):
        return rosbag.load_bag(path, topic=topic, at=at, occupied_thresh=occupied_thresh,
                               free_thresh=free_thresh, resolution=resolution, max_cells=max_cells)
    if path.is_dir():
        raise MapError(path, "is a directory; expected a map .yaml file, an image, a .npy array or a "
                             "bag (a ROS 2 bag folder holds metadata.yaml)")
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
                             f"expected {', '.join(YAML_SUFFIXES + IMAGE_SUFFIXES + rosbag.BAG_SUFFIXES)} "
                             "or a ROS 2 bag folder")
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
