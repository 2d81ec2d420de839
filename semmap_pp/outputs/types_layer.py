"""types.yaml + types.pgm: W*'s place types as a map layer that ROS map_server loads.

A planner on a ROS robot reads maps through map_server; this layer gives it the semantic map in
the same form and frame as the input map: the input image's size, resolution and origin, each
pixel holding a small code (``mode: raw``, so map_server passes the value through unchanged):

====  =====================================================================
code  pixel
====  =====================================================================
0     in no unit of the building (outside, exterior units, unexplored)
1     a room (its walls included, as in labels.png)
2     a corridor
3     a hall
4     other
5     a door of world.json (the opening across the wall band, drawn over the units)
====  =====================================================================

Published as an ``OccupancyGrid`` the codes are the cells' values 0..5, to be read as labels, not
as occupancy (a costmap layer that wants costs must map them). labels.png (16-bit unit ids) and
world.json give the same units by id.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from semmap_pp.grid.write import write_map

#: Pixel code of each unit type; 0 is no unit.
TYPE_CODES = {"room": 1, "corridor": 2, "hall": 3, "other": 4}
#: Pixel code of the doors, drawn over the units.
DOOR_CODE = 5


def _segment_mask(shape, a, b, radius: float) -> tuple[slice, slice, np.ndarray]:
    """The pixels whose centres lie within ``radius`` of the segment ``a``-``b`` (continuous
    ``[x, y]`` pixel frame), as a mask over its bounding box: ``(rows, cols, mask)``."""
    h, w = shape
    (ax, ay), (bx, by) = a, b
    c0 = max(0, int(np.floor(min(ax, bx) - radius)))
    c1 = min(w, int(np.ceil(max(ax, bx) + radius)) + 1)
    r0 = max(0, int(np.floor(min(ay, by) - radius)))
    r1 = min(h, int(np.ceil(max(ay, by) + radius)) + 1)
    if c0 >= c1 or r0 >= r1:
        return slice(0, 0), slice(0, 0), np.zeros((0, 0), bool)
    y, x = np.mgrid[r0:r1, c0:c1] + 0.5
    dx, dy = bx - ax, by - ay
    n2 = dx * dx + dy * dy
    t = np.clip(((x - ax) * dx + (y - ay) * dy) / n2, 0.0, 1.0) if n2 > 0 else np.zeros_like(x)
    d2 = (x - ax - t * dx) ** 2 + (y - ay - t * dy) ** 2
    return slice(r0, r1), slice(c0, c1), d2 <= radius * radius


def types_image(sm, doc: dict) -> np.ndarray:
    """The layer's codes (uint8, the input image's shape) from the semantic map ``sm`` and its
    world.json content ``doc``: each unit's pixels of labels.png get its type's code, then each
    door's segment, as wide as the wall band, gets :data:`DOOR_CODE`.

    Examples
    --------
    >>> from types import SimpleNamespace
    >>> import numpy as np
    >>> labels = np.array([[1, 1, 0, 2, 2]] * 3, dtype=np.uint16)
    >>> sm = SimpleNamespace(labels_image=labels, frame=SimpleNamespace(
    ...     cells=SimpleNamespace(wall=1), resolution=0.05), grid=SimpleNamespace(resolution=0.05))
    >>> doc = {"units": [{"id": 1, "type": "room"}, {"id": 2, "type": "corridor"}],
    ...        "doors": [{"endpoints_px": [[2.5, 0.0], [2.5, 3.0]]}]}
    >>> types_image(sm, doc).tolist()
    [[1, 1, 5, 2, 2], [1, 1, 5, 2, 2], [1, 1, 5, 2, 2]]
    """
    labels = np.asarray(sm.labels_image)
    code = np.zeros(int(labels.max(initial=0)) + 1, dtype=np.uint8)
    for u in doc["units"]:
        if u["id"] < len(code):
            code[u["id"]] = TYPE_CODES[u["type"]]
    image = code[labels]
    # the wall band's width in input pixels (the lattice may be finer or coarser than the image)
    radius = max(0.5, 0.5 * sm.frame.cells.wall * sm.frame.resolution / sm.grid.resolution)
    for d in doc.get("doors", []):
        a, b = d["endpoints_px"]
        rows, cols, mask = _segment_mask(image.shape, a, b, radius)
        image[rows, cols][mask] = DOOR_CODE
    return image


def write_types_layer(out: str | Path, sm, doc: dict) -> list[Path]:
    """Write ``types.pgm`` and ``types.yaml`` into ``out`` (the image first, both atomically;
    :func:`semmap_pp.grid.write.write_map`) with the input map's resolution and origin; return
    their paths."""
    yaml_path = write_map(Path(out) / "types.yaml", types_image(sm, doc), sm.grid.resolution,
                          origin=tuple(sm.grid.origin), mode="raw")
    return [yaml_path.with_suffix(".pgm"), yaml_path]


__all__ = ["DOOR_CODE", "TYPE_CODES", "types_image", "write_types_layer"]
