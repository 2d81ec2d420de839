"""Fuzzing the map, rule and model loaders with hypothesis (CI-sized; bench/fuzz.py runs longer).

Inputs are random bytes and mutations of valid files: a PNG (grey, RGBA, 16-bit), a PGM (P5 and
P2), a ``.npy`` array, a map_server YAML, every rule file in rules/, models/default.toml and a
world.json (``semmap map --start``, ``semmap score``). The only
exception a loader may raise is the project's own :class:`~semmap_pp.errors.SemmapError`
(MapError, RuleError, ModelError); a rule file that loads must also ground against a small evidence
set (a RuleError for hard rules that admit no world is fine). Anything else -- a traceback, an
OverflowError, a hang past the deadline -- fails the test.

The ``check_*`` functions are the fuzz targets; bench/fuzz.py drives the same targets for a fixed
time (``python bench/fuzz.py --seconds 600``) and reports how many cases ran.
"""

from __future__ import annotations

import functools
import io
import json
import math
import tempfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from PIL import Image

from semmap_pp.errors import SemmapError
from semmap_pp.grid import load_map
from semmap_pp.knowledge import Evidence, load_rules
from semmap_pp.knowledge.ground import ground
from semmap_pp.model import DEFAULT_MODEL, load_model

ROOT = Path(__file__).resolve().parents[2]
MAX_CELLS = 1_000_000     # bounds the work of one case; the limit itself is tested elsewhere
CI = settings(max_examples=200, deadline=3000, database=None, derandomize=True,
              suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
COUNT = {"cases": 0}      # bench/fuzz.py reads this


# --- valid seed files --------------------------------------------------------------------------

def _pattern(dtype=np.uint8, top=255) -> np.ndarray:
    a = np.full((12, 10), int(top * 254 / 255), dtype)
    a[0, :] = a[-1, :] = a[:, 0] = a[:, -1] = 0
    a[5:7, 3:6] = int(top * 205 / 255)
    return a


def _png(mode: str) -> bytes:
    buf = io.BytesIO()
    if mode == "RGBA":
        a = np.dstack([_pattern()] * 3 + [np.full((12, 10), 255, np.uint8)])
        a[2, 2, 3] = 0
        Image.fromarray(a, "RGBA").save(buf, "PNG")
    elif mode == "I;16":
        Image.fromarray(_pattern(np.uint16, 65535)).save(buf, "PNG")
    else:
        Image.fromarray(_pattern(), "L").save(buf, "PNG")
    return buf.getvalue()


def _npy() -> bytes:
    buf = io.BytesIO()
    np.save(buf, _pattern(), allow_pickle=False)
    return buf.getvalue()


SEED_IMAGES = {
    "grey.png": _png("L"), "rgba.png": _png("RGBA"), "deep.png": _png("I;16"),
    "p5.pgm": b"P5\n10 12\n255\n" + _pattern().tobytes(),
    "p2.pgm": ("P2\n# plain\n10 12\n255\n" + " ".join(map(str, _pattern().ravel())) + "\n").encode(),
    "a.npy": _npy(),
}
SEED_YAML = ("image: m.pgm\nresolution: 0.05\norigin: [-1.0, 2.0, 0.0]\nnegate: 0\n"
             "occupied_thresh: 0.65\nfree_thresh: 0.196\nmode: trinary\n")
SEED_RULES = {p.name: p.read_text() for p in sorted((ROOT / "rules").glob("*.lp"))}
SEED_MODEL = DEFAULT_MODEL.read_text()
EVIDENCE = Evidence.build([1, 2, 3], rolike={1}, colike={2: 0.7}, halike={3}, muldoor={2},
                          adj=[(1, 2), (2, 3)])


@functools.cache
def _world_map():
    """A 4 x 3 m room (0.05 m cells) and its lattice, for the world.json target (built once)."""
    from semmap_pp.cells import FREE, OCCUPIED, UNKNOWN
    from semmap_pp.lattice.frame import build_frame
    from semmap_pp.grid import OccupancyGrid

    m = np.full((70, 90), UNKNOWN, np.uint8)
    m[4:66, 4:86] = OCCUPIED
    m[6:64, 6:84] = FREE
    grid = OccupancyGrid(m, np.zeros(m.shape, np.float32), 0.05)
    return grid, build_frame(grid, load_model())


@functools.cache
def _seed_world() -> bytes:
    import json

    from semmap_pp.semantic.world_json import FORMAT
    grid, frame = _world_map()
    r0, c0 = frame.crop[:2] if frame.crop is not None else (0, 0)
    units = []
    for uid, rect in ((1, (r0 + 2, c0 + 2, r0 + 30, c0 + 40)), (2, (r0 + 2, c0 + 38, r0 + 30, c0 + 80))):
        px = frame.rect_vertices_px(rect)
        metres = np.stack(frame.image_to_metres(px[:, 0], px[:, 1]), axis=1).round(4)
        units.append({"id": uid, "type": "room", "vertices_px": px.round(3).tolist(),
                      "vertices_m": metres.tolist(), "center_m": metres.mean(axis=0).round(4).tolist()})
    wall = ((np.asarray(units[0]["vertices_m"][1]) + np.asarray(units[0]["vertices_m"][2])) / 2).round(4)
    door = {"id": 1, "units": [1, 2], "center_m": wall.tolist(), "width_m": 0.9}
    doc = {"format": FORMAT, "map": {"width": grid.width, "height": grid.height, "resolution": 0.05,
                                     "orientation_deg": 0.0},
           "units": units, "doors": [door], "passages": [dict(door, width_m=3.0)], "exterior": [],
           "ids": {"next": 3}}
    return json.dumps(doc).encode()


# --- mutations -----------------------------------------------------------------------------------

@st.composite
def mutated(draw, seed: bytes, tokens: tuple[bytes, ...] = ()) -> bytes:
    """``seed`` with a few random edits: flip, delete, insert, duplicate, truncate, splice a token."""
    data = bytearray(seed)
    for _ in range(draw(st.integers(1, 4))):
        kind = draw(st.sampled_from(["flip", "delete", "insert", "duplicate", "truncate", "token"]
                                    if tokens else ["flip", "delete", "insert", "duplicate", "truncate"]))
        i = draw(st.integers(0, max(len(data) - 1, 0)))
        if kind == "flip" and data:
            data[i] ^= 1 << draw(st.integers(0, 7))
        elif kind == "delete":
            del data[i:i + draw(st.integers(1, 16))]
        elif kind == "insert":
            data[i:i] = draw(st.binary(min_size=1, max_size=8))
        elif kind == "duplicate":
            data[i:i] = data[i:i + draw(st.integers(1, 64))]
        elif kind == "truncate":
            del data[i:]
        elif kind == "token":
            data[i:i] = draw(st.sampled_from(tokens))
    return bytes(data)


RULE_TOKENS = tuple(t.encode() for t in (
    ":-", ":~", "not ", ".", ",", "(", ")", "[", "]", "@0", "@1", "U", "V", "_", "1..3", "X+1",
    "2147483648", "4294968296", "-5", "#const w = 7.", "w", "#script (python) #end.", "@f(U)",
    '#include "table3.lp".', '#include "/etc/passwd".', "#show room/1.", "#minimize { 1,U : room(U) }.",
    "room(U)", "corr(U)", "hall(U)", "other(U)", "sale(P,Q)", "adj(P,Q)", "unit(U)", "rolike(U)",
    "muldoor(U)", "helper(U) :- unit(U).", "#count { V : adj(U,V) } >= 3", "%", "%*", "*%", '"',
    "\\", "\n", "p(f(X)) :- p(X).", "{ room(U) } :- unit(U).", "a;b", "|", "#true", "#false",
    "\u00e9", "\u03d5", '"\u00e9', "\x00", "\x7f"))
YAML_TOKENS = tuple(t.encode() for t in (
    "image: ", "resolution: ", "origin: ", "negate: ", "mode: raw\n", "mode: scale\n", "~", "null",
    ".nan", ".inf", "-.inf", "1e400", "1.0e+308", "9" * 40, "[", "]", "{", "}", "&a ", "*a", "!!binary ",
    "!!python/object:os.system ", "../", "/etc/passwd", "m.yaml", "m.pgm", "'", '"', "\n", "- ", ": ",
    "true", "0x1F", "0o17", "1_000"))
WORLD_TOKENS = tuple(t.encode() for t in (
    "{", "}", "[", "]", ",", ":", '"', "null", "true", "NaN", "Infinity", "-Infinity", "1e400",
    "-1e400", "9" * 40, "-0", '"units"', '"exterior"', '"vertices_px"', '"map"', '"format"',
    '"width"', '"vertices_m"', '"ids"', '"next"', '"doors"', '"passages"', '"center_m"', '"width_m"', "65535", "[[0,0],[1,0],[1,1],[0,1]]", "[[1e308,0],[0,1e308],[1,1],[0,1]]", "\\u0000", "\n"))
MODEL_TOKENS = tuple(t.encode() for t in (
    "nan", "inf", "-inf", "1e308", "-1", "0", "99999999999999999999", "true", '"x"', "[", "]", "{",
    "}", "=", "\n", "[sensor]", "[prior]", "k_max = ", "psi = ", "weights = { add_remove = -1 }"))


# --- fuzz targets ----------------------------------------------------------------------------------

def check_map_bytes(data: bytes, name: str) -> None:
    """Load ``data`` saved as ``name`` (a bare image or array)."""
    COUNT["cases"] += 1
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / name
        path.write_bytes(data)
        try:
            grid = load_map(path, max_cells=MAX_CELLS)
        except SemmapError as exc:
            assert "\n" not in str(exc)
            return
        assert grid.classes.ndim == 2 and grid.classes.size > 0


def check_yaml_bytes(data: bytes) -> None:
    """Load ``data`` as ``m.yaml`` next to a valid ``m.pgm``."""
    COUNT["cases"] += 1
    with tempfile.TemporaryDirectory() as d:
        (Path(d) / "m.pgm").write_bytes(SEED_IMAGES["p5.pgm"])
        (Path(d) / "m.yaml").write_bytes(data)
        try:
            grid = load_map(Path(d) / "m.yaml", max_cells=MAX_CELLS)
        except SemmapError as exc:
            assert "\n" not in str(exc) and len(str(exc)) < 2000
            return
        assert np.isfinite(grid.resolution) and grid.resolution > 0


def check_rules_bytes(data: bytes) -> None:
    """Load ``data`` as a rule file beside the shipped ones; ground it if it loads."""
    COUNT["cases"] += 1
    with tempfile.TemporaryDirectory() as d:
        for name, text in SEED_RULES.items():
            (Path(d) / name).write_text(text)
        (Path(d) / "fuzz.lp").write_bytes(data)
        try:
            rules = load_rules(Path(d) / "fuzz.lp")
            ground(rules, EVIDENCE)
        except SemmapError as exc:
            assert "\n" not in str(exc)


def check_model_bytes(data: bytes) -> None:
    """Load ``data`` as a model file."""
    COUNT["cases"] += 1
    with tempfile.TemporaryDirectory() as d:
        (Path(d) / "m.toml").write_bytes(data)
        try:
            model = load_model(Path(d) / "m.toml")
            model.cells(0.05)
        except SemmapError as exc:
            assert "\n" not in str(exc)


def check_world_bytes(data: bytes) -> None:
    """Read ``data`` as a world.json onto a small map's lattice (``semmap map --start``), as the
    places of ``semmap where`` / ``semmap route`` (a route from the first unit to the last) and of
    ``semmap diff`` (the file against itself: the same plan), and in
    metres as the earlier world of ``--ids-from``, whose ids then number a one-unit world."""
    from semmap_pp import world as wm
    from semmap_pp.semantic.ids import MAX_ID, carry_ids
    from semmap_pp.plans.places import read_places
    from semmap_pp.plans.diff import diff_worlds
    from semmap_pp.plans.world_file import read_previous_ids, read_start_world

    COUNT["cases"] += 1
    grid, frame = _world_map()
    with tempfile.TemporaryDirectory() as d:
        (Path(d) / "world.json").write_bytes(data)
        try:
            places = read_places(Path(d) / "world.json")
            if places.units:
                a, b = places.units[0], places.units[-1]
                route = places.route(a, b)
                assert route is None or (math.isfinite(route.length_m) and route.length_m >= 0
                                         and route.units[0] == a.key and route.units[-1] == b.key)
                places.units_at(*a.center)
            d_self = diff_worlds(places, places)           # `semmap diff` of the file against itself
            assert d_self.same and len(d_self.pairs) == len(places.units) + len(places.exterior)
            d_self.text()
            json.dumps(d_self.to_dict())
        except SemmapError as exc:
            assert "\n" not in str(exc) and len(str(exc)) < 2000
        try:
            world = read_start_world(Path(d) / "world.json", frame, grid, 8)
            assert wm.is_valid(world, frame.shape, frame.cells.min_side)
        except SemmapError as exc:
            assert "\n" not in str(exc) and len(str(exc)) < 2000
        try:
            previous = read_previous_ids(Path(d) / "world.json")
        except SemmapError as exc:
            assert "\n" not in str(exc) and len(str(exc)) < 2000
            return
        corners = np.asarray([[0, 0], [2, 0], [2, 1.5], [0, 1.5]], float)
        try:
            ids, record = carry_ids({0: corners, 1: corners + 5}, [0, 1], previous)
        except SemmapError as exc:     # no id left: one line too
            assert "\n" not in str(exc) and "16-bit" in str(exc)
            return
        assert sorted(ids) == [0, 1] and len(set(ids.values())) == 2
        assert all(1 <= v <= MAX_ID for v in ids.values()) and record["next"] > max(record["new"], default=0)
        assert set(record["carried"]) <= set(previous.ids) and not set(record["new"]) & set(previous.ids)


# --- the targets with their inputs (bench/fuzz.py runs the same for longer) ----------------------

HOSTILE_VALUES = [10**400, -10**400, 2**63, 1e-320, 1e308, [1e308, 1e308, 0], [10**400, 0, 0],
                  "../m.pgm", "/dev/zero", "m.yaml", ""]
YAML_VALUES = st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats() | st.text(max_size=12),
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=5), inner, max_size=3),
    max_leaves=8)
YAML_KEYS = st.sampled_from(["image", "resolution", "origin", "negate", "occupied_thresh",
                             "free_thresh", "mode"])


def _yaml_doc(doc: dict) -> tuple[bytes]:
    import yaml
    return (yaml.safe_dump({"image": "m.pgm", "resolution": 0.05} | doc).encode(),)


WORLD_PATHS = st.sampled_from([("format",), ("map",), ("map", "width"), ("map", "height"),
                               ("map", "resolution"), ("units",), ("exterior",), ("units", 0),
                               ("units", 0, "vertices_px"), ("units", 0, "vertices_px", 0),
                               ("units", 0, "vertices_px", 0, 1), ("units", 0, "id"),
                               ("units", 0, "vertices_m"), ("units", 0, "vertices_m", 2, 0), ("ids",),
                               ("ids", "next"), ("doors",), ("doors", 0, "units"), ("doors", 0, "units", 1),
                               ("doors", 0, "center_m"), ("passages", 0, "width_m"), ("units", 1, "center_m"),
                               ("units", 1, "id")])


def _world_doc(edits) -> tuple[bytes]:
    """The seed world.json with each ``(path, value)`` edit made where the path still leads (each
    value a copy: a later edit must not write into a shared value, such as a list of
    HOSTILE_VALUES)."""
    import copy
    import json
    doc = json.loads(_seed_world())
    for path, value in edits:
        node = doc
        for key in path[:-1]:
            try:
                node = node[key]
            except (KeyError, IndexError, TypeError):
                break
        else:
            try:
                node[path[-1]] = copy.deepcopy(value)
            except (IndexError, TypeError):
                pass
    return (json.dumps(doc).encode(),)


def _one(strategy):
    return strategy.map(lambda b: (b,))


#: name -> (strategy of argument tuples, target)
TARGETS = {
    "random-bytes-image": (st.tuples(st.binary(max_size=512), st.sampled_from(["x.png", "x.pgm", "x.npy"])),
                           check_map_bytes),
    "mutated-image": (st.sampled_from(sorted(SEED_IMAGES)).flatmap(
        lambda n: st.tuples(mutated(SEED_IMAGES[n]), st.just(n))), check_map_bytes),
    "mutated-yaml": (_one(mutated(SEED_YAML.encode(), YAML_TOKENS)), check_yaml_bytes),
    "random-values-yaml": (st.dictionaries(YAML_KEYS, st.sampled_from(HOSTILE_VALUES) | YAML_VALUES)
                           .map(_yaml_doc), check_yaml_bytes),
    "mutated-rules": (_one(st.sampled_from(sorted(SEED_RULES)).flatmap(
        lambda n: mutated(SEED_RULES[n].encode(), RULE_TOKENS))), check_rules_bytes),
    "mutated-model": (_one(mutated(SEED_MODEL.encode(), MODEL_TOKENS)), check_model_bytes),
    "mutated-world": (st.just(None).flatmap(lambda _: _one(mutated(_seed_world(), WORLD_TOKENS))),
                      check_world_bytes),
    "random-values-world": (st.lists(st.tuples(WORLD_PATHS, st.sampled_from(HOSTILE_VALUES) | YAML_VALUES),
                                     min_size=1, max_size=3).map(_world_doc), check_world_bytes),
}


# --- CI-sized runs ---------------------------------------------------------------------------------

@CI
@given(TARGETS["random-bytes-image"][0])
def test_random_bytes_as_an_image(args):
    check_map_bytes(*args)


@CI
@given(TARGETS["mutated-image"][0])
def test_mutated_images(args):
    check_map_bytes(*args)


@CI
@given(TARGETS["mutated-yaml"][0])
def test_mutated_yaml(args):
    check_yaml_bytes(*args)


@pytest.mark.slow
@CI
@given(TARGETS["random-values-yaml"][0])
def test_yaml_of_random_values(args):
    check_yaml_bytes(*args)


@pytest.mark.slow
@CI
@given(TARGETS["mutated-rules"][0])
def test_mutated_rule_files(args):
    check_rules_bytes(*args)


@CI
@given(TARGETS["mutated-model"][0])
def test_mutated_model_file(args):
    check_model_bytes(*args)


def test_the_seed_world_reads_back():
    """The world.json target's seed is a valid world: mutations start from something that loads."""
    from semmap_pp import world as wm
    from semmap_pp.plans.places import read_places
    from semmap_pp.plans.world_file import read_start_world

    grid, frame = _world_map()
    with tempfile.TemporaryDirectory() as d:
        (Path(d) / "world.json").write_bytes(_seed_world())
        assert wm.n_units(read_start_world(Path(d) / "world.json", frame, grid, 8)) == 2
        route = read_places(Path(d) / "world.json").route((3.0, 2.7), (0.5, 2.7))
        assert route.units == ["2", "1"] and route.length_m == pytest.approx(2.5)


@CI
@given(TARGETS["mutated-world"][0])
def test_mutated_world_json(args):
    check_world_bytes(*args)


@pytest.mark.slow
@CI
@given(TARGETS["random-values-world"][0])
def test_random_values_in_a_world_json(args):
    check_world_bytes(*args)
