"""semmap_pp.plans.places and `semmap where` / `semmap route`: the unit at a map point and routes through
doors and passages, on the literal floor (tests/literal_floor.py: A | B a door, B : C open, A / D a
closed wall), on random grids of rooms against a brute-force search, and on broken files."""

import itertools
import json
import math

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from semmap_pp.cli import main
from semmap_pp.errors import SemmapError
from semmap_pp.model import load_model
from semmap_pp.semantic.world_json import dumps, world_dict
from semmap_pp.plans.places import Unit, read_places

from literal_floor import literal_floor


@pytest.fixture(scope="module")
def floor_doc():
    return world_dict(literal_floor(load_model()))


@pytest.fixture()
def floor_file(floor_doc, tmp_path):
    path = tmp_path / "world.json"
    path.write_text(dumps(floor_doc))
    return path


def test_units_at_a_point(floor_file, floor_doc):
    places = read_places(floor_file.parent)                     # a run's folder will do
    by = {u["id"]: u for u in floor_doc["units"]}
    for uid in (1, 2, 3, 4):
        assert [u.key for u in places.units_at(*by[uid]["center_m"])] == [str(uid)]
    x_bc = (by[2]["vertices_m"][1][0] + by[3]["vertices_m"][0][0]) / 2   # B's east and C's west wall
    assert [u.key for u in places.units_at(x_bc, by[2]["center_m"][1])] == ["2", "3"]
    patch = floor_doc["unexplored"][0]["center_m"]                 # free floor outside every unit
    assert places.units_at(*patch) == []
    assert places.unit("R1").key == "1" and places.unit("c3").key == "3"


def test_route_through_a_door_and_a_passage(floor_file, floor_doc):
    places = read_places(floor_file)
    route = places.route(places.unit("1"), places.unit("3"))
    assert [(s.opening.kind, s.opening.id, s.from_unit.key, s.into.key) for s in route.steps] == [
        ("door", 1, "1", "2"), ("passage", 1, "2", "3")]
    a, c = floor_doc["units"][0]["center_m"], floor_doc["units"][2]["center_m"]
    door, passage = floor_doc["doors"][0]["center_m"], floor_doc["passages"][0]["center_m"]
    assert route.length_m == pytest.approx(math.dist(a, door) + math.dist(door, passage) + math.dist(passage, c))
    assert route.units == ["1", "2", "3"] and route.waypoints == [tuple(a), tuple(door), tuple(passage), tuple(c)]
    assert places.route(places.unit("1"), places.unit("4")) is None      # only a closed wall between
    same = places.route(places.unit("4"), places.unit("4"))
    assert same.steps == () and same.length_m == 0.0
    d = route.to_dict()
    assert d["units"] == [1, 2, 3] and [s["kind"] for s in d["steps"]] == ["door", "passage"]
    assert "through 1 door and 1 passage" in route.text()


def test_a_point_on_a_shared_wall_starts_in_either_unit(floor_file, floor_doc):
    places = read_places(floor_file)
    by = {u["id"]: u for u in floor_doc["units"]}
    x_bc = (by[2]["vertices_m"][1][0] + by[3]["vertices_m"][0][0]) / 2
    route = places.route((x_bc, by[3]["center_m"][1]), places.unit("3"))
    assert route.steps == ()                                     # already inside C


def test_exterior_units_are_never_on_a_route(floor_doc, tmp_path):
    doc = json.loads(dumps(floor_doc))
    doc["exterior"] = [{"id": 1, "vertices_m": [[20, 20], [22, 20], [22, 22], [20, 22]]}]
    path = tmp_path / "world.json"
    path.write_text(json.dumps(doc))
    places = read_places(path)
    assert [u.label for u in places.units_at(21, 21)] == ["X1"]
    with pytest.raises(SemmapError, match="exterior unit X1"):
        places.route((21, 21), places.unit("1"))
    with pytest.raises(SemmapError, match="X1 is an exterior unit"):
        places.route(places.unit("1"), places.unit("X1"))


def test_a_file_without_passages_routes_through_doors_only(floor_doc, tmp_path, capsys):
    doc = json.loads(dumps(floor_doc))
    del doc["passages"]
    for u in doc["units"]:
        del u["passages"]
    path = tmp_path / "world.json"
    path.write_text(json.dumps(doc))
    places = read_places(path)
    assert not places.has_passages and places.route(places.unit("1"), places.unit("3")) is None
    assert main(["route", str(path), "1", "2"]) == 0
    assert "lists no passages" in capsys.readouterr().err


# ---- random grids of rooms against a brute-force search ------------------------------------------

def grid_world(rows, cols, doors, rng):
    """A world.json-like dict: rows x cols rooms of 4 x 3 m (rotated by a random angle about the
    origin), and an opening at a random place of every shared wall in ``doors`` (pairs of cells)."""
    theta = rng.uniform(-math.pi, math.pi)
    rot = np.array([[math.cos(theta), -math.sin(theta)], [math.sin(theta), math.cos(theta)]])
    w, h = 4.0, 3.0
    units, openings = [], []
    for r, c in itertools.product(range(rows), range(cols)):
        corners = np.array([[c * w, r * h], [(c + 1) * w, r * h], [(c + 1) * w, (r + 1) * h], [c * w, (r + 1) * h]])
        units.append({"id": r * cols + c + 1, "type": "room", "vertices_m": (corners @ rot.T).tolist()})
    for k, ((r0, c0), (r1, c1)) in enumerate(doors, 1):
        t = rng.uniform(0.2, 0.8)
        if r0 == r1:                                  # side by side: the wall x = max(c) * w
            p = np.array([max(c0, c1) * w, (r0 + t) * h])
        else:
            p = np.array([(c0 + t) * w, max(r0, r1) * h])
        openings.append({"id": k, "units": [r0 * cols + c0 + 1, r1 * cols + c1 + 1],
                         "center_m": (rot @ p).tolist(), "width_m": 0.9})
    return {"format": "semmap_pp.world/1", "units": units, "doors": openings, "passages": []}, rot


def brute_force(places, start, goal, starts, goals):
    """The shortest chain by trying every sequence of distinct openings."""
    best = math.inf

    def walk(unit, point, used, length):
        nonlocal best
        if unit in goals:
            best = min(best, length + math.dist(point, goal))
        for i, o in enumerate(places.openings):
            if i not in used and unit in o.units:
                walk(o.other(unit), o.center, used | {i}, length + math.dist(point, o.center))
    for u in starts:
        walk(u, start, frozenset(), 0.0)
    return best


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2 ** 31 - 1), rows=st.integers(1, 3), cols=st.integers(1, 3),
       share=st.floats(0.3, 1.0))
def test_routes_are_shortest_and_stay_inside_their_units(seed, rows, cols, share, tmp_path_factory):
    rng = np.random.default_rng(seed)
    pairs = [((r, c), (r, c + 1)) for r in range(rows) for c in range(cols - 1)]
    pairs += [((r, c), (r + 1, c)) for r in range(rows - 1) for c in range(cols)]
    doors = [p for p in pairs if rng.random() < share]
    doc, rot = grid_world(rows, cols, doors, rng)
    path = tmp_path_factory.mktemp("grid") / "world.json"
    path.write_text(json.dumps(doc))
    places = read_places(path)
    local = [np.array([rng.uniform(0.1, cols * 4 - 0.1), rng.uniform(0.1, rows * 3 - 0.1)]) for _ in range(2)]
    start, goal = (tuple(rot @ p) for p in local)
    starts = [u.key for u in places.units_at(*start)]
    goals = [u.key for u in places.units_at(*goal)]
    assert starts and goals
    route = places.route(start, goal)
    expected = brute_force(places, start, goal, starts, goals)
    if route is None:
        assert expected == math.inf
        return
    assert route.length_m == pytest.approx(expected, abs=1e-9)
    by = {u.key: u for u in places.units}
    keys = route.units
    for (p, q), key in zip(itertools.pairwise(route.waypoints), keys):   # each segment inside its unit
        assert by[key].holds(*p) and by[key].holds(*q)
    assert keys[0] in starts and keys[-1] in goals


@settings(max_examples=200, deadline=None)
@given(theta=st.floats(-math.pi, math.pi), x=st.floats(-6, 6), y=st.floats(-6, 6),
       clockwise=st.booleans())
def test_holds_is_the_rotated_rectangle(theta, x, y, clockwise):
    rot = np.array([[math.cos(theta), -math.sin(theta)], [math.sin(theta), math.cos(theta)]])
    box = np.array([[-2.0, -1.0], [2.0, -1.0], [2.0, 1.0], [-2.0, 1.0]])
    corners = box[::-1] if clockwise else box
    unit = Unit("1", "room", corners @ rot.T + [0.5, 0.25], (0.5, 0.25))
    lx, ly = rot.T @ (np.array([x, y]) - [0.5, 0.25])           # the point in the box's own frame
    margin = max(abs(lx) - 2.0, abs(ly) - 1.0)
    if abs(margin) > 1e-6 and abs(margin - 1e-3) > 1e-6:
        assert unit.holds(x, y) == (margin <= 1e-3)


# ---- broken files ---------------------------------------------------------------------------------

@pytest.mark.parametrize("change, message", [
    (lambda d: d.update(units={}), "'units' must be a list"),
    (lambda d: d["units"][0].pop("vertices_m"), "unit 1: 'vertices_m' must be four"),
    (lambda d: d["units"][1].update(id=1), "unit id 1 is used twice"),
    (lambda d: d["units"][0].update(id=True), r"units\[0\]: 'id' must be an integer"),
    (lambda d: d["units"][0].update(type=None), "unit 1: 'type' must be a string"),
    (lambda d: d["doors"][0].update(units=[1, 9]), "door 1: 'units' must be two ids"),
    (lambda d: d["doors"][0].update(center_m=[1.0, "x"]), "door 1: 'center_m' must be two finite"),
    (lambda d: d["passages"][0].update(width_m=-1), "passage 1: 'width_m' must be a positive"),
    (lambda d: d.update(format="other/1"), "not a world.json of semmap_pp"),
    (lambda d: d["units"][2]["vertices_m"][1].__setitem__(0, 1e300), "unit 3: 'vertices_m' lie beyond 1e"),
    (lambda d: d["passages"][0].update(center_m=[0, -1e12]), "passage 1: 'center_m' must be two finite"),
])
def test_a_broken_file_is_one_line_naming_it(floor_doc, tmp_path, capsys, change, message):
    doc = json.loads(dumps(floor_doc))
    change(doc)
    path = tmp_path / "world.json"
    path.write_text(json.dumps(doc))
    with pytest.raises(SemmapError, match=message) as err:
        read_places(path)
    assert str(path) in str(err.value) and "\n" not in str(err.value)
    assert main(["where", str(path), "0", "0"]) == 2
    out = capsys.readouterr()
    assert out.out == "" and out.err.count("\n") == 1 and str(path) in out.err


def test_a_nan_centre_is_refused(floor_doc, tmp_path):
    text = dumps(floor_doc).replace(json.dumps(floor_doc["doors"][0]["center_m"][0]), "NaN", 1)
    path = tmp_path / "world.json"
    path.write_text(text)
    with pytest.raises(SemmapError, match="door 1: 'center_m' must be two finite"):
        read_places(path)


# ---- the command line -----------------------------------------------------------------------------

def test_cli_where(floor_file, floor_doc, capsys):
    a = floor_doc["units"][0]["center_m"]
    assert main(["where", str(floor_file), str(a[0]), str(a[1])]) == 0
    out = capsys.readouterr().out
    unit = floor_doc["units"][0]
    letter = {"room": "R", "corridor": "C", "hall": "H", "other": "E"}[unit["type"]]
    assert out.startswith(f"{letter}1: {unit['type']}, 3.30 x 2.60 m; door 1 to ")
    assert main(["where", str(floor_file), str(a[0]), str(a[1]), "--json"]) == 0
    got = json.loads(capsys.readouterr().out)
    assert [u["id"] for u in got["units"]] == [1]
    assert got["units"][0]["openings"] == [{"kind": "door", "id": 1, "to": 2, "width_m": 1.0,
                                            "center_m": floor_doc["doors"][0]["center_m"]}]
    assert main(["where", str(floor_file), "-50", "-2e1"]) == 1     # negative numbers are numbers
    assert "no unit of" in capsys.readouterr().err


def test_cli_route(floor_file, floor_doc, capsys):
    assert main(["route", str(floor_file), "1", "C3"]) == 0
    text = capsys.readouterr().out
    assert "through 1 door and 1 passage" in text and "passage 1" in text
    assert main(["route", str(floor_file), "1", "3", "--json"]) == 0
    got = json.loads(capsys.readouterr().out)
    assert got["units"] == [1, 2, 3] and len(got["waypoints_m"]) == 4
    d = floor_doc["units"][3]["center_m"]
    assert main(["route", str(floor_file), f"{d[0]},{d[1]}", "1"]) == 1   # D: a closed wall only
    assert "no route from" in capsys.readouterr().err
    assert main(["route", str(floor_file), "-50,-20", "1"]) == 2          # "-50,-20" is a point
    assert "no unit of the building holds the start point -50 -20" in capsys.readouterr().err
    assert main(["route", str(floor_file), "1", "1,x"]) == 2
    assert "is not a map point X,Y" in capsys.readouterr().err
    assert main(["route", str(floor_file), "1", "R9"]) == 2
    assert "no unit R9 in this world" in capsys.readouterr().err


def test_a_two_cell_speck_in_a_doorway_keeps_the_route(tmp_path):
    """The literal floor with a chair leg (two cells) in the door A | B: the default model's specks
    (``[world] door_speck_m2``) keep the door, and the route A -> C with it; one-cell specks (a
    model file without the key) lose both."""
    from semmap_pp.cells import OCCUPIED
    from semmap_pp.lattice.frame import build_frame
    from semmap_pp.semantic.semantic_map import semantic_map
    from semmap_pp.target.posterior import Posterior

    from literal_floor import floor_grid, floor_world

    import dataclasses

    g = floor_grid()
    classes = g.classes.copy()
    classes[34:36, 54] = OCCUPIED                         # the doorway's rows 25..44: 9 + 9 lines left
    g = dataclasses.replace(g, classes=classes)
    old = model_without(tmp_path, "door_speck_m2")
    found = {}
    for name, model in (("default", load_model()), ("one-cell", old)):
        f = build_frame(g, model)
        doc = world_dict(semantic_map(g, f, Posterior(f, model), floor_world()))
        places = read_places_doc(doc, tmp_path / f"{name}.json")
        found[name] = ([d["units"] for d in doc["doors"]], places.route(places.unit("1"), places.unit("3")))
    assert found["default"][0] == [[1, 2]] and found["default"][1].units == ["1", "2", "3"]
    assert found["one-cell"][0] == [] and found["one-cell"][1] is None


def model_without(tmp_path, key):
    """The default model read from a copy without the line of ``key`` (a model file written
    before the key existed)."""
    path = tmp_path / f"without_{key}.toml"
    path.write_text("\n".join(ln for ln in load_model().path.read_text().splitlines()
                              if not ln.startswith(key)) + "\n")
    return load_model(path)


def read_places_doc(doc, path):
    path.write_text(dumps(doc))
    return read_places(path)


def test_units_facing_across_free_floor_are_joined_by_a_passage(tmp_path):
    """Two rooms 0.6 m apart with open floor between them and no wall: not adjacent, but a
    passage joins them (``[world] passage_gap_m``) in world.json, graph.graphml and routes; the
    strip itself stays outside both units (the same CPR), and regions.png keeps them apart (rooms
    as a person draws them); a model file without the key lists none."""
    from semmap_pp import world as wm
    from semmap_pp.cells import FREE, OCCUPIED
    from semmap_pp.lattice.frame import build_frame
    from semmap_pp.grid import OccupancyGrid
    from semmap_pp.semantic.semantic_map import semantic_map
    from semmap_pp.outputs.graphml import world_graph
    from semmap_pp.semantic.regions import unit_regions
    from semmap_pp.target.posterior import Posterior

    c = np.full((60, 100), OCCUPIED, np.uint8)
    c[4:56, 4:96] = FREE
    g = OccupancyGrid(classes=c, occupancy=np.zeros(c.shape, np.float32), resolution=0.05)
    world = wm.add(wm.add(wm.empty(4), 0, (4, 4, 56, 44)), 1, (4, 56, 56, 96))
    old = model_without(tmp_path, "passage_gap_m")
    got = {}
    for name, model in (("default", load_model()), ("without", old)):
        f = build_frame(g, model)
        sm = semantic_map(g, f, Posterior(f, model), world)
        doc = world_dict(sm)
        places = read_places_doc(doc, tmp_path / f"{name}.json")
        edges = {tuple(sorted(e)): a["relation"] for *e, a in world_graph(sm, doc).edges(data=True)}
        got[name] = (doc, places.route(places.unit("1"), places.unit("2")), edges, sm.cpr)
        assert unit_regions(sm) == {1: 1, 2: 2}
    doc, route, edges, cpr = got["default"]
    assert doc["adjacency"] == [] and [(p["units"], p["width_m"]) for p in doc["passages"]] == [([1, 2], 2.4)]
    assert [s.opening.kind for s in route.steps] == ["passage"] and edges[("u1", "u2")] == "passage"
    doc0, route0, edges0, cpr0 = got["without"]
    assert doc0["passages"] == [] and route0 is None and ("u1", "u2") not in edges0
    assert cpr == cpr0
