"""The literal floor of tests/unit/test_outputs_files.py and tests/integration/test_places.py (0.05 m cells, walls 2
cells, doors 10..50 cells)::

    +------+------+------+      A | B : a 1 m door          -> separate regions, edge "door"
    |  A o |  B   :  C   |      B : C : wall open for 3.1 m -> one region (an open passage)
    |      D      :      |      A / D : closed wall         -> separate regions, edge "adjacent"
    +------+------+------+      o : an object in A;  n : a small free patch below B (unexplored)
    |  D   |   n
    +------+

Ids follow reading order of the unit centres: A = 1, B = 2, C = 3, D = 4.
"""

import numpy as np

from semmap_pp import world as wm
from semmap_pp.cells import FREE, OCCUPIED, UNKNOWN
from semmap_pp.lattice.frame import build_frame
from semmap_pp.grid import OccupancyGrid
from semmap_pp.semantic.semantic_map import semantic_map
from semmap_pp.target.posterior import Posterior

RECTS = {"A": (4, 4, 70, 56), "B": (4, 54, 70, 106), "C": (4, 104, 70, 156), "D": (68, 4, 110, 56)}


def floor_grid(source=None):
    c = np.full((116, 162), UNKNOWN, np.uint8)
    c[4:70, 4:156] = OCCUPIED
    c[68:110, 4:56] = OCCUPIED
    c[6:68, 6:54] = FREE        # A
    c[6:68, 56:104] = FREE      # B
    c[6:68, 106:154] = FREE     # C
    c[70:108, 6:54] = FREE      # D
    c[25:45, 54:56] = FREE      # door A|B, 20 cells = 1 m
    c[6:68, 104:106] = FREE     # B:C open over 62 cells > door_max
    c[20:24, 20:24] = OCCUPIED  # an object in A
    c[73:83, 70:82] = FREE      # unexplored patch, 3 rows below B
    return OccupancyGrid(classes=c, occupancy=np.zeros(c.shape, np.float32), resolution=0.05,
                         origin=(-1.0, 0.5, 0.0), source=source, image_path=None)


def floor_world():
    w = wm.empty(6)
    for slot, key in zip((0, 2, 3, 5), "ABCD"):  # slots scattered: ids must not depend on them
        w = wm.add(w, slot, RECTS[key])
    return w


def literal_floor(model, source=None):
    """The floor's semantic map (:class:`semmap_pp.semantic.semantic_map.SemanticMap`) under ``model``."""
    g = floor_grid(source)
    f = build_frame(g, model)
    return semantic_map(g, f, Posterior(f, model), floor_world())
