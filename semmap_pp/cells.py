"""Cell classes, stated once for the whole project.

Arrays are indexed ``[row, col]`` with row 0 the *top* row of the input image, exactly as the image
is stored. ``x`` means column and ``y`` means row wherever pixel coordinates are written as pairs
(``[x, y]``). Metric coordinates follow ROS map_server: the map origin is the *bottom-left* pixel, so
``x_m = origin_x + (col + 0.5) * resolution`` and ``y_m = origin_y + (height - row - 0.5) * resolution``
(see :mod:`semmap_pp.grid`).
"""

from __future__ import annotations

import numpy as np

# Classes of the input map C_M (uint8 codes).
FREE = np.uint8(0)
UNKNOWN = np.uint8(1)
OCCUPIED = np.uint8(2)
INPUT_CLASSES = ("free", "unknown", "occupied")

# States of a cell in a semantic world W (uint8 codes). Order matches the sensor-model columns.
W_WALL = np.uint8(0)
W_FREE = np.uint8(1)
W_OBJECT = np.uint8(2)
W_UNKNOWN = np.uint8(3)
WORLD_STATES = ("wall", "free", "object", "unknown")

# Unit types, in the order used by every marginal vector.
UNIT_TYPES = ("room", "corridor", "hall", "other")
