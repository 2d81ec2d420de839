"""world.json files sized or typed to hurt (issue 55's F3 and the ``"width": "395"`` case): each
is one line naming the file, before anything large is built from it.

Most cases use the literal floor (tests/literal_floor.py: four units on a lattice of 116 x 162
cells, 0.05 m cells, no sampling); the commands of the issue (``semmap score``, ``semmap map
--start``) run on the bundled intel corner."""

import json
import time
from pathlib import Path

import numpy as np
import pytest

import semmap_pp.plans.world_file as wf
from semmap_pp.cli import main
from semmap_pp.errors import SemmapError
from semmap_pp.model import load_model
from semmap_pp.semantic.world_json import dumps, world_dict
from semmap_pp.plans.places import read_places
from semmap_pp.plans.diff import diff_worlds
from semmap_pp.plans.world_file import read_previous_ids, read_start_world, read_world_units

from literal_floor import literal_floor

ROOT = Path(__file__).resolve().parents[2]
INTEL = ROOT / "tests" / "data" / "maps" / "intel_corner.yaml"
FAST = ["--chains", "1", "--cores", "1", "--tune", "2", "--draws", "4", "--n-inner", "10",
        "--progress", "none"]


@pytest.fixture(scope="module")
def floor():
    return literal_floor(load_model())


@pytest.fixture(scope="module")
def floor_doc(floor):
    return json.loads(dumps(world_dict(floor)))


def write(tmp_path, doc, name="w.json") -> Path:
    path = tmp_path / name
    path.write_text(json.dumps(doc))
    return path


def with_rects(doc, frame, rects, key="units") -> dict:
    """``doc`` whose ``key`` list holds one unit per lattice rectangle (ids 1, 2, ...)."""
    base = doc["units"][0]
    out = json.loads(json.dumps(doc))
    out[key] = [dict(base, id=i + 1, vertices_px=frame.rect_vertices_px(r).round(3).tolist(),
                     vertices_m=np.stack(frame.image_to_metres(*frame.rect_vertices_px(r).T), axis=1)
                     .round(4).tolist()) for i, r in enumerate(rects)]
    if key == "units":
        out["doors"], out["passages"], out["adjacency"] = [], [], []
    return out


def one_line(capsys) -> str:
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err, err[:2000]
    return err.strip()


# ---- a unit given twice ---------------------------------------------------------------------------

@pytest.mark.parametrize("copies, new_id", [(2, False), (2, True), (3, True)])
def test_a_unit_given_twice_is_refused_naming_both(floor, floor_doc, tmp_path, copies, new_id):
    doc = json.loads(json.dumps(floor_doc))
    for k in range(1, copies):
        doc["units"].append(dict(doc["units"][1], id=10 + k if new_id else doc["units"][1]["id"]))
    path = write(tmp_path, doc)
    with pytest.raises(SemmapError) as exc:
        read_world_units(path, floor.frame, floor.grid)
    want = ("unit 11 is the same lattice rectangle as unit 2" if new_id else
            "unit 2 (units[4]) is the same lattice rectangle as unit 2 (units[1])")
    assert want in exc.value.message and exc.value.path == str(path)
    if new_id:    # the readers in metres refuse it too
        for read in (read_places, read_previous_ids):
            with pytest.raises(SemmapError, match="unit 11 has the same corners as unit 2"):
                read(path)


def test_an_exterior_unit_over_a_unit_is_one_too(floor, floor_doc, tmp_path):
    doc = json.loads(json.dumps(floor_doc))
    doc["exterior"] = [dict(doc["units"][3], id=1)]
    with pytest.raises(SemmapError, match="exterior unit X1 is the same lattice rectangle as unit 4"):
        read_world_units(write(tmp_path, doc), floor.frame, floor.grid)


# ---- more units than the map holds, units piled on each other -------------------------------------

def test_the_lattice_bounds_the_number_of_units(floor, floor_doc, tmp_path):
    from semmap_pp.plans.world_file import lattice_fit

    c = floor.frame.cells
    fit = lattice_fit(floor.frame.shape, c.min_side, c.wall)
    assert fit == 48           # (116 - 20) // 18 + 1 = 6 rows by (162 - 20) // 18 + 1 = 8 columns
    # a tiling of the smallest units, neighbours sharing a wall, is exactly what fits: accepted
    pitch = c.min_side - c.wall
    tiles = [(r, q, r + c.min_side, q + c.min_side) for r in range(0, 116 - c.min_side + 1, pitch)
             for q in range(0, 162 - c.min_side + 1, pitch)]
    assert len(tiles) == fit
    assert len(read_world_units(write(tmp_path, with_rects(floor_doc, floor.frame, tiles)),
                                floor.frame, floor.grid)) == fit
    # one more than MAX_OVERLAP layers of them is refused before any unit is looked at
    doc = json.loads(json.dumps(floor_doc))
    doc["units"] = [{"id": i + 1, "vertices_px": "never read"} for i in range(wf.MAX_OVERLAP * fit)]
    doc["exterior"] = [{"id": 1}]
    with pytest.raises(SemmapError) as exc:
        read_world_units(write(tmp_path, doc), floor.frame, floor.grid)
    assert exc.value.message.startswith(f"{wf.MAX_OVERLAP * fit + 1} units and exterior units; this "
                                        f"map holds at most {wf.MAX_OVERLAP * fit}: {fit} units")


@pytest.mark.parametrize("deep", [4, 5, 40])       # world_file.MAX_OVERLAP is 4
def test_units_piled_deeper_than_max_overlap_are_refused(floor, floor_doc, tmp_path, deep):
    # distinct rectangles, each a cell larger than the last, all over the cell (30, 30)
    rects = [(10 + k % 5, 10 + k // 5, 50 + k, 60 + 2 * k) for k in range(deep)]
    path = write(tmp_path, with_rects(floor_doc, floor.frame, rects))
    if deep <= 4:
        assert len(read_world_units(path, floor.frame, floor.grid)) == deep
        return
    with pytest.raises(SemmapError) as exc:
        read_world_units(path, floor.frame, floor.grid)
    assert f"{deep} units overlap at lattice row" in exc.value.message
    assert "at most 4 deep" in exc.value.message


def test_units_that_share_walls_are_not_piled(floor, floor_doc, tmp_path):
    # wall bands overlap freely: four units meeting at a corner, eight around one unit
    c = floor.frame.cells
    s, w = 30, c.wall
    rects = [(r, q, r + s, q + s) for r in (0, s - w, 2 * (s - w)) for q in (0, s - w, 2 * (s - w))]
    assert len(read_world_units(write(tmp_path, with_rects(floor_doc, floor.frame, rects)),
                                floor.frame, floor.grid)) == 9


# ---- the commands -------------------------------------------------------------------------

@pytest.fixture(scope="module")
def intel_unit(tmp_path_factory):
    """A world.json of the intel corner holding one lattice unit (the file the issue copied)."""
    from semmap_pp.run.inputs import load_inputs

    inputs = load_inputs(INTEL, rules_path=None)
    f = inputs.frame
    v = f.rect_vertices_px((40, 40, 80, 90)).round(3).tolist()
    unit = {"id": 1, "type": "room", "vertices_px": v,
            "vertices_m": np.stack(f.image_to_metres(*np.asarray(v).T), axis=1).round(4).tolist()}
    doc = {"format": "semmap_pp.world/1",
           "map": {"width": inputs.grid.width, "height": inputs.grid.height,
                   "resolution": inputs.grid.resolution}, "units": [unit], "exterior": []}
    return inputs, doc


@pytest.mark.parametrize("copies, same_id", [(20_000, True), (2_000, False), (600, False)])
def test_thousands_of_copies_of_one_unit_to_score_are_one_line(intel_unit, tmp_path, capsys, copies, same_id):
    inputs, doc = intel_unit
    doc = dict(doc, units=[dict(doc["units"][0], id=1 if same_id else i + 1) for i in range(copies)])
    path = write(tmp_path, doc)
    t0 = time.perf_counter()
    assert main(["score", str(INTEL), str(path)]) == 2
    err = one_line(capsys)
    assert time.perf_counter() - t0 < 60        # was 4.2 GB and > 100 s for 2,000 copies
    assert err.startswith(f"semmap: error: {path}: {copies} units and exterior units; this map holds at most")


def test_copies_of_one_unit_as_a_start_world_stop_before_sampling(intel_unit, tmp_path, capsys):
    inputs, doc = intel_unit
    doc = dict(doc, units=[dict(doc["units"][0], id=i + 1) for i in range(3)])
    path = write(tmp_path, doc)
    out = tmp_path / "out"
    assert main(["map", str(INTEL), "--out", str(out), "--start", str(path), *FAST]) == 2
    err = one_line(capsys)
    assert f"{path}: unit 2 is the same lattice rectangle as unit 1" in err
    assert not out.exists()
    with pytest.raises(SemmapError, match="unit 2 is the same lattice rectangle"):
        read_start_world(path, inputs.frame, inputs.grid, 64)


# ---- bounds every reader gets: bytes, JSON containers, units, openings ------------------------------

def test_a_file_of_too_many_json_objects_is_refused_unparsed(tmp_path, capsys, monkeypatch):
    path = tmp_path / "w.json"
    path.write_text('{"format": "semmap_pp.world/1", "objects": [' + ",".join(["{}"] * 2_000_001) + "]}")
    assert main(["where", str(path), "0", "0"]) == 2
    assert "2000003 JSON objects and lists are too many for a world.json (at most 2000000" in one_line(capsys)
    monkeypatch.setattr(wf, "MAX_BYTES", 1000)
    for argv in (["where", str(path), "0", "0"], ["diff", str(path), str(path)], ["score", str(INTEL), str(path)]):
        assert main(argv) == 2
        assert f"{path}: {path.stat().st_size} bytes is too large for a world.json (at most 1000)" in one_line(capsys)


@pytest.mark.parametrize("key, n", [("units", 20_001), ("exterior", 20_005), ("doors", 80_001)])
def test_more_units_or_openings_than_a_world_json_holds(tmp_path, key, n):
    path = write(tmp_path, {"format": "semmap_pp.world/1", key: [0] * n})
    what = "doors and passages" if key == "doors" else "units and exterior"
    for read in (read_places, read_previous_ids):
        with pytest.raises(SemmapError, match=f"{n} {what}; a world.json holds at most"):
            read(path)


def test_a_unit_with_hundreds_of_doors_is_refused(floor_doc, tmp_path):
    doc = json.loads(json.dumps(floor_doc))
    door = doc["doors"][0]
    doc["doors"] = [dict(door, id=i + 1) for i in range(300)]     # unit 2 (B) also has its passage to C
    with pytest.raises(SemmapError, match="unit 2 has 301 doors and passages; a unit has at most 256"):
        read_places(write(tmp_path, doc))
    doc["doors"] = doc["doors"][:200]               # many, but within the bound: routes still work
    places = read_places(write(tmp_path, doc))
    assert [s.opening.id for s in places.route(places.unit("1"), places.unit("2")).steps] == [1]


def test_units_piled_on_each_other_stop_a_diff_before_it_pairs_them(floor_doc, tmp_path, capsys):
    doc = json.loads(json.dumps(floor_doc))
    base = doc["units"][0]
    doc["units"] = [dict(base, id=i + 1, vertices_m=[[x + 1e-3 * i, y] for x, y in base["vertices_m"]])
                    for i in range(2_000)]     # not copies: each a millimetre further
    doc["doors"], doc["passages"] = [], []
    path = write(tmp_path, doc)
    t0 = time.perf_counter()
    assert main(["diff", str(path), str(path)]) == 2
    assert "pairs of the 2000 and 2000 units overlap (at most 64 per unit)" in one_line(capsys)
    assert time.perf_counter() - t0 < 30
    # the pairs a diff of real plans needs are the nonzero entries of the matrix it replaces
    from semmap_pp.semantic.ids import overlap_iou_matrix, overlap_pairs

    places = read_places(write(tmp_path, floor_doc))
    a = [u.corners for u in places.units]
    b = [u.corners + [0.3, -0.1] for u in places.units]
    m = overlap_iou_matrix(a, b)
    assert [(i, j) for i, j, _ in overlap_pairs(a, b)] == [tuple(ij) for ij in np.argwhere(m > 0)]
    assert diff_worlds(places, places).same


# ---- types named by their key ----------------------------------------------------------------------

@pytest.mark.parametrize("edit, message", [
    (lambda d: d["map"].update(width="162"), "map.width must be a positive integer (pixels), got '162' (a string)"),
    (lambda d: d["map"].update(width="395"), "map.width must be a positive integer (pixels), got '395' (a string)"),
    (lambda d: d["map"].update(height=116.0), "map.height must be a positive integer (pixels), got 116.0"),
    (lambda d: d["map"].update(height=True), "map.height must be a positive integer (pixels), got true"),
    (lambda d: d["map"].update(resolution="0.05"), "map.resolution must be a number (m/cell), got '0.05' (a string)"),
    (lambda d: d["map"].pop("resolution"), "map.resolution must be a number (m/cell), got null"),
    (lambda d: d.update(map=[162, 116]), "'map' must be an object with the map's width, height and resolution, got a list"),
    (lambda d: d.update(exterior="none"), "'exterior' must be a list, got 'none' (a string)"),
    (lambda d: d["units"].__setitem__(1, [1, 2]), "units[1] must be an object, got a list"),
    (lambda d: d["units"][2].update(id="3"), "units[2]: 'id' must be an integer of at least 1, got '3' (a string)"),
    (lambda d: d["units"][2].update(id=[3] * 10 ** 5), "units[2]: 'id' must be an integer of at least 1, got a list"),
])
def test_a_field_of_the_wrong_type_is_named_by_its_key(floor, floor_doc, tmp_path, capsys, edit, message):
    doc = json.loads(json.dumps(floor_doc))
    edit(doc)
    path = write(tmp_path, doc)
    with pytest.raises(SemmapError) as exc:
        read_world_units(path, floor.frame, floor.grid)
    assert exc.value.message == message and exc.value.path == str(path)
    assert len(str(exc.value)) < 200 + len(str(path))


def test_the_size_message_no_longer_contradicts_itself(floor, floor_doc, tmp_path):
    doc = json.loads(json.dumps(floor_doc))
    doc["map"]["width"] = 163
    with pytest.raises(SemmapError, match="written for a 163x116 map at 0.05 m/cell; this map is 162x116"):
        read_world_units(write(tmp_path, doc), floor.frame, floor.grid)


@pytest.mark.parametrize("escape, at", [("\\ud800", "units[1].type"), ("x\\udcff", "units[2].type")])
def test_a_string_that_is_no_text_is_refused_before_it_is_printed(floor, floor_doc, tmp_path, capsys, escape, at):
    # "\ud800" is valid JSON but no character: `semmap where` printed it and died (UnicodeEncodeError)
    doc = json.loads(json.dumps(floor_doc))
    doc["units"][int(at[6])]["type"] = "TYPE"
    path = tmp_path / "w.json"
    path.write_text(json.dumps(doc).replace('"TYPE"', f'"{escape}"'))
    x, y = floor_doc["units"][1]["center_m"]
    for argv in (["where", str(path), str(x), str(y)], ["diff", str(path), str(path)],
                 ["route", str(path), "1", "3"]):
        assert main(argv) == 2
        assert f"{path}: {at} holds an escape of half a UTF-16 pair" in one_line(capsys)
    with pytest.raises(SemmapError, match="half a UTF-16 pair"):
        read_world_units(path, floor.frame, floor.grid)
    # a whole pair is one character (an emoji): read as any other string
    path.write_text(json.dumps(doc).replace('"TYPE"', '"room \\ud83d\\ude00"'))
    assert read_places(path).unit(str(int(at[6]) + 1)).type == "room \U0001f600"
