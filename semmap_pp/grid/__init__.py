"""Occupancy grid maps: reading ROS map_server maps (YAML + PGM/PNG), bare images and ``.npy``
arrays, classifying cells into FREE / UNKNOWN / OCCUPIED, and writing maps back.

See ``docs/formats.md`` for the accepted files and the pixel -> class rule.
"""

from semmap_pp.grid.images import MAX_CELLS
from semmap_pp.grid.load import load_map
from semmap_pp.grid.meta import (DEFAULT_FREE_THRESH, DEFAULT_OCCUPIED_THRESH,
                                 DEFAULT_RESOLUTION)
from semmap_pp.grid.occupancy import OccupancyGrid
from semmap_pp.grid.pixels import classify, occupancy_from_grey, ros_values
from semmap_pp.grid.write import classes_to_image, save_grid, write_map

__all__ = [
    "DEFAULT_FREE_THRESH", "DEFAULT_OCCUPIED_THRESH", "DEFAULT_RESOLUTION", "MAX_CELLS",
    "OccupancyGrid", "classes_to_image", "classify", "load_map", "occupancy_from_grey",
    "ros_values", "save_grid", "write_map",
]
