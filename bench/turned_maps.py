"""The real-gt floors turned: each floor's map and its truth rotated by an angle, as a robot whose
map frame lay at that angle to the building would have saved them.

A SLAM map's frame is where the robot started, so a user's floor comes at any angle; the five
floors of ``bench/data/real-gt`` come almost square to the image. Turned, the walls are drawn at
the angle as the staircases of pixels a map at that angle holds (nearest neighbour, no new grey
values); the canvas grows to hold the whole floor and the new corners are the map's own unknown
grey (the commonest grey value of the pixels the program reads as unknown). The truth turns with
the map, so the ROSE2 protocol scores rooms.png on the same cells.

The same folder and angle always give the same map.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import yaml
from PIL import Image
from scipy import ndimage as ndi

#: the angles (degrees, counter-clockwise on screen) of ``--subset real-gt --turn`` by default
ANGLES = (15.0, 30.0, 45.0)


def unknown_grey(folder: Path, img: np.ndarray) -> int:
    """The commonest grey value of ``img`` (the floor's image, as read here) among the pixels the
    program itself reads as unknown from ``folder``'s map.yaml (:func:`semmap_pp.grid.load_map`:
    its thresholds, negate and mode); 205 when none is."""
    from semmap_pp.cells import UNKNOWN
    from semmap_pp.grid import load_map
    unknown = load_map(folder / "map.yaml").classes == UNKNOWN
    counts = np.bincount(img[unknown], minlength=256)
    return int(counts.argmax()) if counts.any() else 205


def turn(folder: Path, degrees: float, truth: np.ndarray) -> tuple[np.ndarray, dict, np.ndarray]:
    """``(image, meta, truth)``: the floor's grey image turned by ``degrees``, its YAML fields, and
    ``truth`` (room labels, 0 none) turned with it."""
    meta = yaml.safe_load((folder / "map.yaml").read_text())
    img = np.asarray(Image.open(folder / meta["image"]).convert("L"))
    grey = unknown_grey(folder, img)
    out = ndi.rotate(img, degrees, order=0, reshape=True, mode="constant", cval=grey, prefilter=False)
    labels = ndi.rotate(np.asarray(truth), degrees, order=0, reshape=True, mode="constant", cval=0,
                        prefilter=False)
    return out.astype(np.uint8), dict(meta, image="map.png"), labels


def write(folder: Path, out: Path, degrees: float, truth: np.ndarray) -> np.ndarray:
    """Write the turned floor (``out/map.yaml`` + ``map.png``); returns its truth labels."""
    img, meta, labels = turn(folder, degrees, truth)
    out.mkdir(parents=True, exist_ok=True)
    Image.fromarray(img).save(out / "map.png")
    (out / "map.yaml").write_text(yaml.safe_dump(meta))
    return labels
