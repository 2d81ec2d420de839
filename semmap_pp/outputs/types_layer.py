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
5     a door of world.json (its cells across the wall band, drawn over the units)
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


def types_image(sm, doc: dict) -> np.ndarray:
    """The layer's codes (uint8, the input image's shape) from the semantic map ``sm`` and its
    world.json content ``doc``: each unit's pixels of labels.png get its type's code, then the
    door cells (:meth:`~semmap_pp.semantic.semantic_map.SemanticMap.door_image`, the doors
    overlay.png draws) get :data:`DOOR_CODE`.

    Examples
    --------
    >>> from types import SimpleNamespace
    >>> import numpy as np
    >>> labels = np.array([[1, 1, 0, 2, 2]] * 3, dtype=np.uint16)
    >>> doors = np.zeros(labels.shape, bool)
    >>> doors[:, 2] = True
    >>> sm = SimpleNamespace(labels_image=labels, door_image=lambda: doors)
    >>> doc = {"units": [{"id": 1, "type": "room"}, {"id": 2, "type": "corridor"}]}
    >>> types_image(sm, doc).tolist()
    [[1, 1, 5, 2, 2], [1, 1, 5, 2, 2], [1, 1, 5, 2, 2]]
    """
    labels = np.asarray(sm.labels_image)
    code = np.zeros(int(labels.max(initial=0)) + 1, dtype=np.uint8)
    for u in doc["units"]:
        if u["id"] < len(code):
            code[u["id"]] = TYPE_CODES[u["type"]]
    image = code[labels]
    image[sm.door_image()] = DOOR_CODE
    return image


def write_types_layer(out: str | Path, sm, doc: dict) -> list[Path]:
    """Write ``types.pgm`` and ``types.yaml`` into ``out`` (the image first, both atomically;
    :func:`semmap_pp.grid.write.write_map`) with the input map's resolution and origin; return
    their paths."""
    yaml_path = write_map(Path(out) / "types.yaml", types_image(sm, doc), sm.grid.resolution,
                          origin=tuple(sm.grid.origin), mode="raw")
    return [yaml_path.with_suffix(".pgm"), yaml_path]


__all__ = ["DOOR_CODE", "TYPE_CODES", "types_image", "write_types_layer"]
