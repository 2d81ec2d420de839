import json
from pathlib import Path

import jsonschema
import numpy as np
from PIL import Image

from semmap_pp import world as wm
from semmap_pp.cells import FREE, OCCUPIED, UNKNOWN
from semmap_pp.lattice.frame import build_frame
from semmap_pp.grid import OccupancyGrid
from semmap_pp.model import load_model
from semmap_pp.semantic.world_json import dumps, world_dict, write_labels_png
from semmap_pp.semantic.semantic_map import label_lattice, semantic_map
from semmap_pp.target.posterior import Posterior

SCHEMA = json.loads((Path(__file__).parents[2] / "docs" / "world.schema.json").read_text())
MODEL = load_model()


def two_rooms_grid(unseen_from=None):
    """Two 2 m x 3 m rooms side by side (walls 2 cells), a 1 m door in the shared wall; with
    ``unseen_from``, every column from there on unknown."""
    c = np.full((50, 110), UNKNOWN, np.uint8)
    c[4:46, 4:106] = OCCUPIED
    c[6:44, 6:54] = FREE
    c[6:44, 56:104] = FREE
    c[15:35, 54:56] = FREE          # door: 20 cells = 1.0 m
    if unseen_from is not None:
        c[:, unseen_from:] = UNKNOWN
    return OccupancyGrid(classes=c, occupancy=np.zeros(c.shape, np.float32), resolution=0.05,
                         origin=(1.0, 2.0, 0.0), source=None, image_path=None)


def two_rooms_world(slots=(0, 1)):
    w = wm.empty(4)
    w = wm.add(w, slots[0], (4, 4, 46, 56))
    return wm.add(w, slots[1], (4, 54, 46, 106))


def build(world):
    g = two_rooms_grid()
    f = build_frame(g, MODEL)
    return g, f, semantic_map(g, f, Posterior(f, MODEL), world)


def test_world_json_validates_and_says_what_is_there():
    g, f, sm = build(two_rooms_world())
    doc = world_dict(sm, seed=3)
    jsonschema.validate(doc, SCHEMA)
    assert f.theta == 0.0
    assert [u["id"] for u in doc["units"]] == [1, 2]          # left room first (reading order)
    assert doc["adjacency"] == [[1, 2]]
    assert len(doc["doors"]) == 1 and doc["doors"][0]["units"] == [1, 2]
    assert abs(doc["doors"][0]["width_m"] - 1.0) < 1e-9
    # unit 1 spans columns 4..55, rows 4..45: pixel-frame corners at x = 4 and 56, y = 4 and 46
    assert doc["units"][0]["vertices_px"] == [[4.0, 4.0], [56.0, 4.0], [56.0, 46.0], [4.0, 46.0]]
    # metres: x = 1.0 + 4 * 0.05; y = 2.0 + (50 - 46) * 0.05 for the bottom edge
    assert doc["units"][0]["vertices_m"][3] == [1.2, 2.2]
    assert doc["units"][0]["size_m"] == [2.6, 2.1]
    assert doc["units"][0]["doors"] == [1] and doc["units"][1]["doors"] == [1]
    assert 0.9 < doc["cpr"] <= 1.0


def test_ids_and_bytes_do_not_depend_on_slots():
    a = dumps(world_dict(build(two_rooms_world((0, 1)))[2]))
    b = dumps(world_dict(build(two_rooms_world((3, 1)))[2]))
    assert a == b


def test_labels_interior_beats_a_neighbours_wall(tmp_path):
    w = two_rooms_world()
    ids = {0: 1, 1: 2}
    lab = label_lattice((50, 110), w, ids, wall=2)
    assert lab[20, 55] == 2 and lab[20, 54] == 1 or lab[20, 54] in (1, 2)
    # columns 54..55 are in both wall bands: the smaller id wins between equals
    assert lab[20, 54] == 1 and lab[20, 55] == 1
    assert lab[20, 57] == 2 and lab[0, 0] == 0
    # an interior overlapping another unit's wall band takes the interior's id
    w2 = wm.add(wm.add(wm.empty(2), 0, (0, 0, 20, 20)), 1, (0, 18, 20, 40))
    lab2 = label_lattice((20, 40), wm.replace(w2, 1, (0, 10, 20, 40)), {0: 1, 1: 2}, wall=2)
    assert lab2[10, 12] == 1 and lab2[10, 19] == 2   # 12: inside 1, wall of 2; 19: wall of 1, inside 2
    p = write_labels_png(tmp_path / "labels.png", lab)
    back = np.asarray(Image.open(p))
    assert back.dtype == np.uint16 or Image.open(p).mode.startswith("I")
    np.testing.assert_array_equal(back.astype(np.uint16), lab)


def test_empty_world_is_a_valid_document():
    g, f, sm = build(wm.empty(4))
    doc = world_dict(sm)
    jsonschema.validate(doc, SCHEMA)
    assert doc["units"] == [] and doc["adjacency"] == [] and doc["cpr"] < 0.5


def test_each_unit_says_how_much_of_it_the_map_shows():
    # both rooms fully seen: interior free, wall band occupied (the door free)
    g, f, sm = build(two_rooms_world())
    doc = world_dict(sm)
    assert [(u["seen_share"], u["walls_seen_share"]) for u in doc["units"]] == [(1.0, 1.0), (1.0, 1.0)]
    # the right room's far half unseen: its floor and walls there are inferred, not observed
    g = two_rooms_grid(unseen_from=80)
    f = build_frame(g, MODEL)
    sm = semantic_map(g, f, Posterior(f, MODEL), two_rooms_world())
    doc = world_dict(sm)
    jsonschema.validate(doc, SCHEMA)
    right = doc["units"][1]
    # interior: rows 6..43, columns 56..103 (38 x 48 cells), columns 56..79 seen
    assert right["seen_share"] == round(24 / 48, 4)
    # band: the 42 x 52 rectangle less the interior; seen are columns 54..79 of its top and
    # bottom bands (2 x 2 x 26) and the left band (38 x 2)
    assert right["walls_seen_share"] == round((2 * 2 * 26 + 38 * 2) / (42 * 52 - 38 * 48), 4)
    assert doc["units"][0]["seen_share"] == 1.0


def test_the_overlay_tells_inferred_walls_from_walls_the_map_shows():
    from semmap_pp.outputs.figures import RGB, overlay_rgb

    g = two_rooms_grid(unseen_from=80)
    f = build_frame(g, MODEL)
    sm = semantic_map(g, f, Posterior(f, MODEL), two_rooms_world())
    rgb = overlay_rgb(sm)
    assert tuple(rgb[4, 60]) == RGB["wall"]             # the top wall where the map shows it
    assert tuple(rgb[4, 90]) == RGB["inferred wall"]    # and where it is unknown
    assert tuple(rgb[20, 105]) == RGB["inferred wall"]  # the right wall: never seen
    assert tuple(rgb[20, 90]) == RGB["object"]          # unknown inside a unit: object (the paper)
