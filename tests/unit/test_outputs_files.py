"""The output files of `semmap map` beyond world.json: GeoJSON, GraphML, regions, figures, report.

One literal floor (tests/literal_floor.py, whose docstring draws it) explains every case: A | B a
1 m door (separate regions, edge "door"), B : C a wall open for 3.1 m (one region, a passage),
A / D a closed wall (separate regions, edge "adjacent"), an object in A and a small free patch
below B (unexplored). Ids follow reading order of the unit centres: A = 1, B = 2, C = 3, D = 4.
"""

import html
import io
import json
import os
import re

import networkx as nx
import numpy as np
import pytest
from PIL import Image

from semmap_pp.cells import FREE, OCCUPIED
from semmap_pp.sampler.diagnostics import SUMMARIES, convergence
from semmap_pp.model import load_model
from semmap_pp.semantic.world_json import dumps, world_dict
from semmap_pp.outputs import figures
from semmap_pp.outputs.geojson import geojson_dict, ring_area, write_geojson
from semmap_pp.outputs.graphml import world_graph, write_graphml
from semmap_pp.semantic.regions import (join_regions, passage_pairs, regions_image,
                                       unit_regions, write_regions_png)
from semmap_pp.outputs.write import N_SAMPLED_WORLDS, write_all
from semmap_pp.run.inputs import Inputs
from semmap_pp.run.results import MapRun, RunSettings
from semmap_pp.run.spread import posterior_worlds

from literal_floor import literal_floor

MODEL = load_model()
HOSTILE = "<script>alert(1)</script>.yaml"


@pytest.fixture(scope="module")
def floor():
    sm = literal_floor(MODEL)
    assert sm.frame.theta == 0.0
    return sm, world_dict(sm)


def test_the_literal_floor_is_what_the_picture_says(floor):
    sm, doc = floor
    assert doc["adjacency"] == [[1, 2], [1, 4], [2, 3], [2, 4]]
    assert [d["units"] for d in doc["doors"]] == [[1, 2]]
    assert [(d["id"], d["units"], d["width_m"]) for d in doc["passages"]] == [(1, [2, 3], 3.1)]
    assert [(u["doors"], u["passages"]) for u in doc["units"]] == [([1], []), ([1], [1]), ([], [1]), ([], [])]
    assert [tuple(d["units"]) for d in doc["passages"]] == passage_pairs(sm)
    assert [o["unit"] for o in doc["objects"]] == [1]
    assert len(doc["unexplored"]) == 1


def test_join_regions_is_union_find_numbered_by_smallest_unit():
    assert join_regions([5, 1, 2, 3, 4], [(4, 5), (2, 3)]) == {1: 1, 2: 2, 3: 2, 4: 3, 5: 3}
    assert join_regions([1, 2, 3], [(3, 1), (1, 3), (2, 2)]) == {1: 1, 2: 2, 3: 1}  # repeats, self
    assert join_regions([1, 2, 3, 4], [(1, 2), (3, 4), (2, 4)]) == {1: 1, 2: 1, 3: 1, 4: 1}
    assert join_regions([], []) == {}


def test_an_opening_is_a_passage_when_wider_than_a_door_or_the_whole_wall():
    from semmap_pp.derive.doors import openings_between

    cells = MODEL.cells(0.05)                                    # doors 10..50 cells, wall 2
    cls = np.full((40, 40), OCCUPIED, np.uint8)
    cls[2:38, 2:18] = FREE
    cls[2:38, 22:38] = FREE
    left, right = (0, 0, 40, 20), (0, 18, 40, 40)                # shared wall: columns 18..19

    def widths():
        doors, passages = openings_between(cls, left, right, cells)
        return [d.width for d in doors], [p.width for p in passages]

    assert widths() == ([], [])                                  # closed
    cls[10:30, 18:20] = FREE
    assert widths() == ([20], [])                                # a door, wall on both sides
    cls[2:38, 18:22] = FREE
    assert widths() == ([], [36])                                # no wall left: a corridor cut in two
    big = np.full((100, 40), FREE, np.uint8)
    big[:, 18:20] = OCCUPIED
    big[10:61, 18:20] = FREE                                     # 51 cells: wider than any door
    assert [p.width for p in openings_between(big, (0, 0, 100, 20), (0, 18, 100, 40), cells)[1]] == [51]
    big[10:61, 18:20] = OCCUPIED
    big[10:18, 18:20] = FREE                                     # 8 cells: narrower than any door
    assert openings_between(big, (0, 0, 100, 20), (0, 18, 100, 40), cells) == ([], [])


def test_regions_join_only_through_an_open_wall(floor, tmp_path):
    sm, _ = floor
    assert passage_pairs(sm) == [(2, 3)]                     # not the door A|B, not the closed wall A/D
    regions = unit_regions(sm)
    assert regions == {1: 1, 2: 2, 3: 2, 4: 3}
    img = regions_image(sm, regions)
    assert img.dtype == np.uint16 and img.shape == sm.grid.classes.shape
    assert (img[30, 30], img[30, 80], img[30, 130], img[90, 30], img[112, 160]) == (1, 2, 2, 3, 0)
    back = np.asarray(Image.open(write_regions_png(tmp_path / "regions.png", img)))
    np.testing.assert_array_equal(back.astype(np.uint16), img)


def test_geojson_is_closed_ccw_in_the_stated_local_frame(floor, tmp_path):
    sm, doc = floor
    path = write_geojson(tmp_path / "world.geojson", geojson_dict(sm, doc))
    gj = json.loads(path.read_text())
    assert gj["type"] == "FeatureCollection"
    assert gj["properties"]["frame"] == "map" and gj["properties"]["units"] == "m"
    assert "WGS84" in gj["properties"]["note"]
    kinds = [f["properties"]["kind"] for f in gj["features"]]
    assert kinds == ["unit"] * 4 + ["door", "passage", "object", "unexplored"]
    by_id = {f["id"]: f for f in gj["features"]}
    assert len(by_id) == len(gj["features"])
    for u in doc["units"]:
        ring = by_id[f"unit/{u['id']}"]["geometry"]["coordinates"][0]
        assert len(ring) == 5 and ring[0] == ring[-1]
        assert ring_area(ring[:-1]) > 0                              # counter-clockwise
        assert sorted(map(tuple, ring[:-1])) == sorted(map(tuple, u["vertices_m"]))
    a = by_id["unit/1"]["properties"]
    assert a["type"] == doc["units"][0]["type"] and a["region"] == 1 and a["doors"] == [1]
    assert abs(a["area_m2"] - 3.3 * 2.6) < 1e-9 and abs(sum(a[f"p_{t}"] for t in
                                                          ("room", "corridor", "hall", "other")) - 1) < 1e-6
    door = by_id["door/1"]["geometry"]
    assert door["type"] == "LineString"
    (x0, y0), (x1, y1) = door["coordinates"]
    assert abs(np.hypot(x1 - x0, y1 - y0) - 1.0) < 1e-9          # the 1 m opening
    assert abs(x0 - (-1.0 + 55 * 0.05)) < 1e-9                   # on the wall's centre line, metres
    assert by_id["object/1"]["geometry"]["type"] == "Point" and by_id["object/1"]["properties"]["unit"] == 1
    passage = by_id["passage/1"]
    assert passage["properties"]["units"] == [2, 3] and by_id["unit/2"]["properties"]["passages"] == [1]
    (x0, y0), (x1, y1) = passage["geometry"]["coordinates"]
    assert abs(np.hypot(x1 - x0, y1 - y0) - 3.1) < 1e-9          # the open stretch of B:C


def test_graphml_reads_back_with_nodes_and_edges(floor, tmp_path):
    sm, doc = floor
    path = write_graphml(tmp_path / "graph.graphml", world_graph(sm, doc))
    g = nx.read_graphml(path)
    assert set(g.nodes) == {"u1", "u2", "u3", "u4", "o1", "n1"}
    assert g.nodes["u1"]["kind"] == "unit" and g.nodes["u1"]["label"][1:] == "1"
    assert abs(g.nodes["u1"]["area_m2"] - 3.3 * 2.6) < 1e-9
    rel = {tuple(sorted(e)): a for *e, a in g.edges(data=True)}
    assert rel[("u1", "u2")]["relation"] == "door" and rel[("u1", "u2")]["doors"] == "1"
    assert rel[("u2", "u3")] == {"relation": "adjacent", "passage": True}
    assert rel[("u1", "u4")] == {"relation": "adjacent", "passage": False}
    assert rel[("o1", "u1")]["relation"] == "contains"
    assert rel[("n1", "u2")]["relation"] == "next_to"
    assert len(rel) == 6


def _png_size(data: bytes) -> tuple[int, int]:
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    return Image.open(io.BytesIO(data)).size


def test_overlay_colours_walls_doors_objects(floor):
    sm, _ = floor
    rgb = figures.overlay_rgb(sm)
    assert tuple(rgb[30, 5]) == figures.RGB["wall"]        # A's left wall band
    assert tuple(rgb[30, 55]) == figures.RGB["door"]       # in the door A|B
    assert tuple(rgb[21, 21]) == figures.RGB["object"]
    assert tuple(rgb[30, 30]) == figures.RGB["free"] and tuple(rgb[0, 0]) == figures.RGB["unknown"]
    assert figures.crop_box(sm) == (0, 116, 0, 162)       # known part + margin, clipped


def make_run(sm, source_name=HOSTILE, n_draws=6):
    rng = np.random.default_rng(1)
    grid = sm.grid
    summaries = {k: rng.normal(size=(2, n_draws)) for k in SUMMARIES}
    world = sm.world
    K = world.capacity
    rects = np.broadcast_to(world.rects, (2, n_draws, K, 4)).copy()
    rects[:, ::2, 3, 3] -= 6                      # every other draw, C is shorter: visible spread
    active = np.broadcast_to(world.active, (2, n_draws, K)).copy()
    model = MODEL
    inputs = Inputs(grid, model, None, sm.frame, sm.roi, "default")
    settings = RunSettings(chains=2, cores=1, tune=0, draws=n_draws, n_inner=1, anneal=1.0, seed=4)
    report = convergence(summaries, rhat_max=1.05, ess_min=100)
    return MapRun(inputs, settings, world, sm, summaries, {"accept": np.ones((2, n_draws))}, report,
                  {"rects": rects.astype(np.int32), "active": active}, 1.5, 1000.0, 0,
                  notes=["<img src=x onerror=alert(2)>"])


@pytest.fixture(scope="module")
def hostile_run(tmp_path_factory):
    from pathlib import Path

    sm = literal_floor(MODEL, source=Path("/maps") / HOSTILE)
    out = tmp_path_factory.mktemp("out")
    (out / ".world.json.x1y2z3w4.tmp").write_text('{"units": [')   # left by a killed earlier run
    run = make_run(sm)
    written = write_all(out, run, posterior_worlds(run, N_SAMPLED_WORLDS), rules_name="<b>rules</b>.lp")
    return out, run, written


def test_write_all_writes_every_file_once(hostile_run):
    out, run, written = hostile_run
    names = [p.name for p in written]
    assert names[:4] == ["world.json", "labels.png", "trace.nc", "diagnostics.txt"]
    # exactly the outputs: the killed run's temporary file is gone too
    assert sorted(names) == sorted(p.name for p in out.iterdir()) and len(set(names)) == len(names)
    assert {"world.geojson", "graph.graphml", "regions.png", "types.pgm", "types.yaml", "overlay.png",
            "graph.png", "posterior.png", "posterior_cells.png", "report.html"} <= set(names)
    doc = world_dict(run.semantic, rules="<b>rules</b>.lp", model=MODEL.path.name, seed=4, roi_name="default")
    # world.json as world_dict makes it, with the posterior marginals over the sampled worlds added
    written_doc = json.loads((out / "world.json").read_text())
    assert written_doc["posterior_marginals"]["source"] == "the search's draws"
    for u in written_doc["units"]:
        assert 0.0 <= u.pop("posterior_exists") <= 1.0 and "posterior_type" in u
        del u["posterior_type"]
    for d in written_doc["doors"]:
        assert 0.0 <= d.pop("posterior_exists") <= 1.0
    del written_doc["posterior_marginals"]
    assert dumps(written_doc) == dumps(doc)
    assert (out / "diagnostics.txt").read_text().startswith(f"map: /maps/{HOSTILE}\nrules: <b>rules</b>.lp\n")


def test_the_types_layer_is_a_raw_map_server_map_of_the_units_types_and_doors(hostile_run):
    import yaml

    from semmap_pp.grid import load_map
    from semmap_pp.outputs.types_layer import DOOR_CODE, TYPE_CODES

    out, run, _ = hostile_run
    meta = yaml.safe_load((out / "types.yaml").read_text())
    grid = run.semantic.grid
    assert meta == {"image": "types.pgm", "resolution": grid.resolution, "origin": [-1.0, 0.5, 0.0],
                    "negate": 0, "occupied_thresh": 0.65, "free_thresh": 0.196, "mode": "raw"}
    codes = np.asarray(Image.open(out / "types.pgm"))
    labels = np.asarray(Image.open(out / "labels.png"))
    assert codes.shape == labels.shape == grid.classes.shape and codes.dtype == np.uint8
    doc = json.loads((out / "world.json").read_text())
    for d in doc["doors"]:                  # the door A|B: its centre pixel is a door pixel
        x, y = (int(v) for v in d["center_px"])
        assert codes[y, x] == DOOR_CODE
    door = codes == DOOR_CODE
    assert 0 < door.sum() < 3 * 22 * len(doc["doors"])
    # the same door pixels as overlay.png's picture (one rasterisation: SemanticMap.door_image)
    overlay = figures.overlay_rgb(run.semantic)
    assert np.array_equal(door, (overlay == figures.RGB["door"]).all(axis=2))
    for u in doc["units"]:                  # every other pixel of a unit holds its type's code
        mine = (labels == u["id"]) & ~door
        assert mine.any() and (codes[mine] == TYPE_CODES[u["type"]]).all()
    assert (codes[(labels == 0) & ~door] == 0).all()
    # map_server reads it back in the input's frame (semmap's own loader, raw mode)
    back = load_map(out / "types.yaml")
    assert back.shape == grid.classes.shape and back.origin == (-1.0, 0.5, 0.0)


def test_figures_are_pngs_of_sane_size(hostile_run):
    out, _, _ = hostile_run
    for name in ("overlay", "graph", "posterior", "posterior_cells"):
        data = (out / f"{name}.png").read_bytes()
        w, h = _png_size(data)
        assert 300 <= w <= 3000 and 200 <= h <= 3000, (name, w, h)
        assert len(data) < 3_000_000
        img = np.asarray(Image.open(io.BytesIO(data)).convert("L"))
        assert img.std() > 10, name                                 # not a blank canvas


def test_posterior_cells_see_the_spread(hostile_run):
    from semmap_pp.sampler.spread import cell_probabilities

    _, run, _ = hostile_run
    from semmap_pp.run.results import sampled_worlds
    worlds = sampled_worlds(run, 1000)
    p_wall, p_type = cell_probabilities(run.semantic.frame.shape, worlds, wall=2)
    assert len(worlds) == 12
    assert p_wall[30, 5] == 1.0 and p_wall[30, 30] == 0.0
    assert p_wall[30, 148] == 0.5                    # C's right wall moves by 6 cells every other draw
    assert p_type.shape == (4,) + p_wall.shape and p_type.sum(axis=0).max() == 0.0  # untyped worlds


def test_repeated_worlds_are_counted_as_often_as_they_occur(hostile_run):
    """accumulate rasterises a repeated world once and counts it k times: the counts equal those of
    adding every world one by one."""
    from semmap_pp.sampler.diagnostics import SpreadAccumulator
    from semmap_pp.sampler.spread import accumulate, rasterise, sampled_box
    from semmap_pp.run.results import sampled_worlds

    _, run, _ = hostile_run
    ws = sampled_worlds(run, 1000)
    worlds = ws[:3] * 4 + ws[5:7] + ws[:1] * 3     # repeats, in no order
    shape = run.semantic.frame.shape
    acc, box = accumulate(worlds, shape, 2)
    slow = SpreadAccumulator(acc.shape)
    for w in worlds:
        slow.add(*rasterise(w, sampled_box(worlds, shape), 2))
    assert box == sampled_box(worlds, shape) and acc.n == slow.n == len(worlds)
    np.testing.assert_array_equal(acc.wall, slow.wall)
    np.testing.assert_array_equal(acc.types, slow.types)


def test_report_is_self_contained_and_escapes_inputs(hostile_run):
    out, run, written = hostile_run
    text = (out / "report.html").read_text()
    srcs = re.findall(r'src="([^"]*)"', text)
    assert len(srcs) == 7 and all(s.startswith("data:image/png;base64,") for s in srcs)
    assert "http" not in text and "<link" not in text and "<script" not in text
    assert "&lt;script&gt;alert(1)&lt;/script&gt;.yaml" in text
    assert "<b>rules</b>" not in text and "&lt;b&gt;rules&lt;/b&gt;.lp" in text
    assert "onerror=alert(2)>" not in text
    for p in written:                                             # the file list names every file
        assert f'href="{p.name}"' in text
    for q in run.report.quantities:
        assert f"<td>{q.name}</td>" in text
    assert "<th>mean per chain</th>" in text
    assert "default" in text and "CPR" in text
    assert "<th>passages to units</th>" in text and "<th>passages</th>" in text


def test_report_keeps_a_place_for_the_calibration_section(hostile_run):
    """`semmap eval --report` fills the empty place report.html leaves between the posterior spread
    and the convergence section, and links it from the navigation."""
    from semmap_pp.outputs.report import CALIBRATION_BEGIN, CALIBRATION_END, with_calibration

    out, _, _ = hostile_run
    page = (out / "report.html").read_text()
    place = page.index(CALIBRATION_BEGIN + CALIBRATION_END)
    assert page.index('id="spread"') < place < page.index('id="convergence"') and 'id="calibration"' not in page
    filled = with_calibration(page, '<h2 id="calibration">x</h2>')
    assert filled.replace(f"{CALIBRATION_BEGIN}\n<h2 id=\"calibration\">x</h2>\n{CALIBRATION_END}",
                          CALIBRATION_BEGIN + CALIBRATION_END).replace(
        '<a href="#calibration">Calibration</a>', "") == page


def test_report_and_diagnostics_name_chains_in_separate_modes(floor, hostile_run, tmp_path):
    """A second chain 1000 nats below the first: report.html and diagnostics.txt say so in one
    line; the hostile run's chains (the same normal draws) get no such line."""
    import dataclasses

    sm, _ = floor
    run = make_run(sm)
    summaries = dict(run.summaries)
    summaries["log_posterior"] = summaries["log_posterior"] - np.array([[0.0], [1000.0]])
    report = convergence(summaries, rhat_max=1.05, ess_min=100)
    (c, gap), = report.separated_chains()
    assert c == 2 and 990 < gap < 1010
    again = dataclasses.replace(run, summaries=summaries, report=report)
    write_all(tmp_path, again, posterior_worlds(again, N_SAMPLED_WORLDS), rules_name="r.lp")
    note = report.separation_note()
    assert note.startswith("chains in separate modes: chain 2's mean log posterior lies")
    assert note in (tmp_path / "diagnostics.txt").read_text().splitlines()
    assert html.escape(note) in (tmp_path / "report.html").read_text()
    assert run.report.separation_note() == ""
    out, _, _ = hostile_run
    for name in ("diagnostics.txt", "report.html"):
        assert "chains in separate modes" not in (out / name).read_text()


def test_figures_drawn_in_a_forked_process_are_the_same_bytes(hostile_run, tmp_path, monkeypatch):
    """`semmap map` with two cores draws report.html's posterior figures and previews in a forked
    process (semmap_pp/forked.py) while it writes the other files: the same figures, byte for byte,
    and the same report, as drawn in one process."""
    from semmap_pp import forked as forked_module
    from semmap_pp.forked import Forked
    from semmap_pp.outputs.write import posterior_pngs, write_posterior, write_wstar

    monkeypatch.setattr(forked_module, "_one_thread", lambda: True)   # the test runner may hold threads

    out, run, _ = hostile_run
    worlds = posterior_worlds(run, N_SAMPLED_WORLDS)
    here = posterior_pngs(run, worlds)
    assert set(here) == {"posterior", "posterior_cells", "regions", "rooms", "roi"}
    forked = Forked(lambda: (os.getpid(), posterior_pngs(run, worlds)), fork=True).result()
    assert forked[0] != os.getpid() and forked[1] == here
    figures = Forked(lambda: posterior_pngs(run, worlds), fork=True)
    wstar = write_wstar(tmp_path, run, rules_name="<b>rules</b>.lp", worlds=worlds)
    write_posterior(tmp_path, run, worlds, wstar, rules_name="<b>rules</b>.lp", figures=figures.result)
    for name in ("posterior.png", "posterior_cells.png", "report.html"):
        assert (tmp_path / name).read_bytes() == (out / name).read_bytes(), name
    # as `semmap map` does: graph.png drawn there too (from world.json's content without the
    # posterior marginals), the other process drawing only overlay.png; or, with the figures drawn
    # here, by write_posterior itself
    assert set(posterior_pngs(run, worlds, graph=True)) == set(here) | {"graph"}
    for n, drawn in enumerate((Forked(lambda: posterior_pngs(run, worlds, graph=True), fork=True).result, None)):
        again = tmp_path / f"again{n}"
        wstar = write_wstar(again, run, rules_name="<b>rules</b>.lp", worlds=worlds, figures=("overlay",))
        assert not (again / "graph.png").exists()
        written = write_posterior(again, run, worlds, wstar, rules_name="<b>rules</b>.lp", figures=drawn)
        names = [p.name for p in written]
        assert names.count("graph.png") == 1 and names.count("overlay.png") == 1 and names[-1] == "report.html"
        for name in ("graph.png", "overlay.png", "posterior.png", "report.html"):
            assert (again / name).read_bytes() == (out / name).read_bytes(), (n, name)
