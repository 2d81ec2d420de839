"""The loaded map: :class:`OccupancyGrid`, and the cell <-> metre conventions."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from semmap_pp.cells import FREE, INPUT_CLASSES, OCCUPIED, UNKNOWN


def _frozen_copy(a: np.ndarray, dtype) -> np.ndarray:
    out = np.array(a, dtype=dtype, copy=True)
    out.flags.writeable = False
    return out


@dataclass(frozen=True, eq=False)
class OccupancyGrid:
    """A classified occupancy grid map.

    Arrays are indexed ``[row, col]`` with row 0 the top row of the image (see
    :mod:`semmap_pp.cells`). Both arrays are read-only copies.

    Attributes
    ----------
    classes : np.ndarray of uint8, shape (H, W)
        FREE / UNKNOWN / OCCUPIED codes of :mod:`semmap_pp.cells`.
    occupancy : np.ndarray of float32, shape (H, W)
        map_server's occupancy ``p`` in [0, 1]; NaN where the image itself says unknown
        (transparent pixel, raw value above 100).
    resolution : float
        Metres per cell.
    origin : (x, y, yaw)
        Map-frame pose of the bottom-left corner of the bottom-left pixel (ROS map_server).
    source : Path or None
        The file the map was loaded from (YAML or image).
    image_path : Path or None
        The image file holding the pixels.
    mode, occupied_thresh, free_thresh, negate
        The map_server parameters used to classify the pixels.
    image_format : str
        How the image was decoded, e.g. ``"PNG L 8-bit"``.
    notes : tuple of str
        Assumptions made while loading (e.g. a default resolution).
    frame_id, stamp_ns, topic
        The map message's frame, header stamp (ns) and topic when the map came from a bag
        (:mod:`semmap_pp.grid.rosbag`); ``"map"``, 0 and None for a YAML or an image.

    Examples
    --------
    >>> import numpy as np
    >>> g = OccupancyGrid(np.array([[0, 2]], dtype=np.uint8), np.array([[0.0, 1.0]]), 0.5)
    >>> g.shape, g.counts()
    ((1, 2), {'free': 1, 'unknown': 0, 'occupied': 1})
    """

    classes: np.ndarray
    occupancy: np.ndarray
    resolution: float
    origin: tuple[float, float, float] = (0.0, 0.0, 0.0)
    source: Path | None = None
    image_path: Path | None = None
    mode: str = "trinary"
    occupied_thresh: float = 0.65
    free_thresh: float = 0.196
    negate: bool = False
    image_format: str = ""
    notes: tuple[str, ...] = field(default=())
    frame_id: str = "map"
    stamp_ns: int = 0
    topic: str | None = None

    def __post_init__(self) -> None:
        classes = np.asarray(self.classes)
        if classes.ndim != 2 or classes.size == 0:
            raise ValueError(f"classes must be a non-empty 2-D array, got shape {classes.shape}")
        if not np.isin(classes, (FREE, UNKNOWN, OCCUPIED)).all():
            raise ValueError("classes holds codes other than FREE/UNKNOWN/OCCUPIED")
        occupancy = np.asarray(self.occupancy)
        if occupancy.shape != classes.shape:
            raise ValueError(f"occupancy shape {occupancy.shape} != classes shape {classes.shape}")
        resolution = float(self.resolution)
        if not (math.isfinite(resolution) and resolution > 0):
            raise ValueError(f"resolution must be positive and finite, got {self.resolution}")
        origin = tuple(float(v) for v in self.origin)
        if len(origin) != 3:
            raise ValueError(f"origin must be (x, y, yaw), got {self.origin!r}")
        object.__setattr__(self, "classes", _frozen_copy(classes, np.uint8))
        object.__setattr__(self, "occupancy", _frozen_copy(occupancy, np.float32))
        object.__setattr__(self, "resolution", resolution)
        object.__setattr__(self, "origin", origin)
        object.__setattr__(self, "notes", tuple(self.notes))
        for name in ("source", "image_path"):
            value = getattr(self, name)
            if value is not None:
                object.__setattr__(self, name, Path(value))

    @property
    def shape(self) -> tuple[int, int]:
        """``(H, W)``: rows and columns."""
        return self.classes.shape

    @property
    def height(self) -> int:
        """Number of rows."""
        return self.classes.shape[0]

    @property
    def width(self) -> int:
        """Number of columns."""
        return self.classes.shape[1]

    def counts(self) -> dict[str, int]:
        """Number of cells of each class: ``{"free": n, "unknown": n, "occupied": n}``."""
        tally = np.bincount(self.classes.ravel(), minlength=len(INPUT_CLASSES))
        return {name: int(tally[code]) for code, name in enumerate(INPUT_CLASSES)}

    def cells_to_metres(self, rows, cols) -> tuple[np.ndarray, np.ndarray]:
        """Map-frame metres of (fractional) cell indices; integer indices are cell centres.

        ``x_m = ox + (col + 0.5) * res`` and ``y_m = oy + (H - row - 0.5) * res`` when the
        origin's yaw is 0; a non-zero yaw rotates the image about the origin, as in ROS.

        Examples
        --------
        >>> import numpy as np
        >>> g = OccupancyGrid(np.zeros((4, 3), np.uint8), np.zeros((4, 3)), 0.5, (10.0, 20.0, 0.0))
        >>> [v.tolist() for v in g.cells_to_metres(3, 0)]  # bottom-left cell's centre
        [10.25, 20.25]
        """
        rows = np.asarray(rows, dtype=np.float64)
        cols = np.asarray(cols, dtype=np.float64)
        u = (cols + 0.5) * self.resolution
        v = (self.height - rows - 0.5) * self.resolution
        ox, oy, yaw = self.origin
        c, s = math.cos(yaw), math.sin(yaw)
        return ox + c * u - s * v, oy + s * u + c * v

    def metres_to_cells(self, x_m, y_m) -> tuple[np.ndarray, np.ndarray]:
        """Fractional ``(rows, cols)`` of map-frame points; the inverse of :meth:`cells_to_metres`.

        Round to the nearest integer to get the cell that holds the point.

        Examples
        --------
        >>> import numpy as np
        >>> g = OccupancyGrid(np.zeros((4, 3), np.uint8), np.zeros((4, 3)), 0.5, (10.0, 20.0, 0.0))
        >>> [v.tolist() for v in g.metres_to_cells(10.25, 20.25)]
        [3.0, 0.0]
        """
        ox, oy, yaw = self.origin
        dx = np.asarray(x_m, dtype=np.float64) - ox
        dy = np.asarray(y_m, dtype=np.float64) - oy
        c, s = math.cos(yaw), math.sin(yaw)
        u = c * dx + s * dy
        v = -s * dx + c * dy
        return self.height - v / self.resolution - 0.5, u / self.resolution - 0.5

    @property
    def size_m(self) -> tuple[float, float]:
        """``(width_m, height_m)`` of the map."""
        return self.width * self.resolution, self.height * self.resolution
