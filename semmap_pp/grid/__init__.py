"""Occupancy grid maps: reading ROS map_server maps (YAML + PGM/PNG), bare images and ``.npy``
arrays, classifying cells into FREE / UNKNOWN / OCCUPIED, and writing maps back.

See ``docs/formats.md`` for the accepted files and the pixel -> class rule.
"""

from semmap_pp.grid.write import classes_to_image, write_map

__all__ = ["classes_to_image", "write_map"]
