"""Unit ids carried from an earlier world.json (``--ids-from``): the exact overlap of two rotated
rectangles, the one-to-one matching, the reader's refusals, and `semmap map` on a map that has grown
since the earlier run (padded with unknown cells, its origin moved), `semmap edit` keeping ids."""

from __future__ import annotations

import json
import math
from pathlib import Path

import jsonschema
import numpy as np
import pytest
import yaml
from PIL import Image

from semmap_pp.cli import main
from semmap_pp.errors import SemmapError
from semmap_pp.semantic.ids import carry_ids, overlap_iou
from semmap_pp.plans.world_file import PreviousIds, read_previous_ids

from conftest import FAST_RUN, INTEL_CORNER

ROOT = Path(__file__).resolve().parents[2]
SCHEMA = json.loads((ROOT / "docs" / "world.schema.json").read_text())


def rect(cx, cy, w, h, angle) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    half = np.array([[-w, -h], [w, -h], [w, h], [-w, h]]) / 2
    return half @ np.array([[c, s], [-s, c]]) + [cx, cy]


def raster_iou(a, b, step=0.01) -> float:
    pts = np.concatenate([a, b])
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    xs, ys = np.meshgrid(np.arange(lo[0], hi[0], step) + step / 2, np.arange(lo[1], hi[1], step) + step / 2)
    p = np.stack([xs.ravel(), ys.ravel()], axis=1)

    def inside(poly):
        ok = np.ones(len(p), bool)
        sign = np.sign((poly[1, 0] - poly[0, 0]) * (poly[2, 1] - poly[0, 1])
                       - (poly[1, 1] - poly[0, 1]) * (poly[2, 0] - poly[0, 0]))
        for i in range(4):
            q, r = poly[i], poly[(i + 1) % 4]
            ok &= sign * ((r[0] - q[0]) * (p[:, 1] - q[1]) - (r[1] - q[1]) * (p[:, 0] - q[0])) >= 0
        return ok

    ia, ib = inside(a), inside(b)
    return (ia & ib).sum() / max((ia | ib).sum(), 1)


def test_the_overlap_of_two_rotated_rectangles_is_exact():
    rng = np.random.default_rng(0)
    for _ in range(60):
        a = rect(*rng.uniform(0, 2, 2), *rng.uniform(0.5, 3, 2), rng.uniform(0, math.pi))
        b = rect(*rng.uniform(0, 2, 2), *rng.uniform(0.5, 3, 2), rng.uniform(0, math.pi))
        assert overlap_iou(a, b) == pytest.approx(raster_iou(a, b), abs=0.02)
        assert overlap_iou(a, b) == pytest.approx(overlap_iou(b[::-1], a), abs=1e-12)  # order, orientation
    a = rect(0, 0, 2, 1, 0.3)
    assert overlap_iou(a, a) == pytest.approx(1.0)
    assert overlap_iou(a, a + [5, 0]) == 0.0


def previous(ids, corners, next_id=None) -> PreviousIds:
    return PreviousIds(Path("old.json"), tuple(ids), np.asarray(corners, float),
                       next_id if next_id is not None else max(ids) + 1)


def test_matched_units_keep_their_ids_and_the_others_get_ids_never_used():
    old = previous([4, 9, 2], [rect(0, 0, 4, 3, 0), rect(5, 0, 4, 3, 0), rect(10, 0, 4, 3, 0)], next_id=12)
    new = {7: rect(0.1, 0, 4, 3, 0.01),      # unit 4, moved a little
           3: rect(10, 0, 2, 3, 0),          # the middle half of unit 2 (IoU 0.5)
           5: rect(11.5, 0, 1, 3, 0),        # a quarter of unit 2: too small a share
           8: rect(20, 0, 3, 3, 0)}          # a new place
    ids, record = carry_ids(new, [8, 7, 3, 5], old)
    assert ids[7] == 4 and ids[3] == 2
    assert ids[8] == 12 and ids[5] == 13     # from next_id on, in the order given
    assert record == {"from": "old.json", "next": 14, "carried": [2, 4], "new": [12, 13], "gone": [9]}


def test_an_earlier_unit_is_carried_once_by_its_best_match():
    old = previous([1], [rect(0, 0, 4, 4, 0)])
    new = {0: rect(0, 0, 4, 3.2, 0), 1: rect(0, 0, 4, 3.8, 0)}     # both overlap it by IoU >= 0.5
    ids, record = carry_ids(new, [0, 1], old)
    assert ids == {1: 1, 0: 2} and record["carried"] == [1] and record["new"] == [2]


def world_json(tmp_path, units, **extra) -> Path:
    doc = {"format": "semmap_pp.world/1", "units": units, **extra}
    path = tmp_path / "w.json"
    path.write_text(json.dumps(doc))
    return path


SQUARE = [[0, 0], [1, 0], [1, 1], [0, 1]]


@pytest.mark.parametrize("units, extra, message", [
    ([{"id": True, "vertices_m": SQUARE}], {}, "unit 1 of the list: 'id' must be an integer from 1 to 65535, got True"),
    ([{"id": 0, "vertices_m": SQUARE}], {}, "'id' must be an integer from 1 to 65535, got 0"),
    ([{"id": "3", "vertices_m": SQUARE}], {}, "'id' must be an integer"),
    ([{"id": 2, "vertices_m": SQUARE}, {"id": 2, "vertices_m": SQUARE}], {}, "unit id 2 is used twice"),
    ([{"id": 2, "vertices_m": SQUARE[:3]}], {}, "unit 2: 'vertices_m' must be four [x, y] numbers"),
    ([{"id": 2, "vertices_m": [[0, 0], [1, 0], [1, 1e999], [0, 1]]}], {}, "'vertices_m' must be four"),
    ([{"id": 2, "vertices_m": SQUARE}], {"ids": {"next": -1}}, "ids.next must be an integer"),
    ([{"id": 65535, "vertices_m": SQUARE}], {}, "no unit id is left after 65535"),
])
def test_a_bad_earlier_world_json_is_one_error_naming_the_file(tmp_path, units, extra, message):
    path = world_json(tmp_path, units, **extra)
    with pytest.raises(SemmapError) as err:
        read_previous_ids(path)
    assert str(err.value).startswith(str(path)) and message in str(err.value)


def test_the_next_id_honours_the_files_own(tmp_path):
    path = world_json(tmp_path, [{"id": 3, "vertices_m": SQUARE},
                                 {"id": 1, "vertices_m": [[x + 2, y] for x, y in SQUARE]}], ids={"next": 9})
    prev = read_previous_ids(path)
    assert prev.ids == (3, 1) and prev.next_id == 9 and prev.corners_m.shape == (2, 4, 2)
    assert read_previous_ids(world_json(tmp_path, [{"id": 3, "vertices_m": SQUARE}], ids={"next": 2})).next_id == 4
    (tmp_path / "run").mkdir()
    (tmp_path / "w.json").rename(tmp_path / "run" / "world.json")
    assert read_previous_ids(tmp_path / "run").path == tmp_path / "run" / "world.json"   # a run's folder
    with pytest.raises(SemmapError, match="not a regular file"):
        read_previous_ids(tmp_path)
    (tmp_path / "x.json").write_text('{"format": "other"}')
    with pytest.raises(SemmapError, match="not a world.json of semmap_pp"):
        read_previous_ids(tmp_path / "x.json")


@pytest.fixture(scope="module")
def grown(tmp_path_factory) -> Path:
    """The intel corner map padded with unknown cells (30 rows above, 10 below, 50 columns left,
    20 right), its origin moved so that every cell keeps its map-frame place: a SLAM map that grew."""
    d = tmp_path_factory.mktemp("grown")
    meta = yaml.safe_load(INTEL_CORNER.read_text())
    im = np.asarray(Image.open(INTEL_CORNER.parent / meta["image"]).convert("L"))
    values, counts = np.unique(im[(im > 200) & (im < 250)], return_counts=True)
    big = np.full((im.shape[0] + 40, im.shape[1] + 70), values[np.argmax(counts)], np.uint8)   # the map's unknown
    big[30:30 + im.shape[0], 50:50 + im.shape[1]] = im
    Image.fromarray(big).save(d / "big.png")
    res = meta["resolution"]
    meta.update(image="big.png", origin=[meta["origin"][0] - 50 * res, meta["origin"][1] - 10 * res, 0.0])
    (d / "big.yaml").write_text(yaml.safe_dump(meta))
    return d / "big.yaml"


def test_a_run_on_a_grown_map_carries_the_ids_of_the_same_places(intel_corner_wstar, grown, tmp_path, capsys):
    out = tmp_path / "b"
    assert main(["map", str(grown), "--out", str(out), "--seed", "3", *FAST_RUN,
                 "--ids-from", str(intel_corner_wstar)]) == 0
    err = capsys.readouterr().err
    assert "unit ids from " in err
    # how the new plan differs from the earlier one, as `semmap diff` counts it
    assert main(["diff", str(intel_corner_wstar), str(out), "--json"]) in (0, 1)
    c = json.loads(capsys.readouterr().out)["counts"]
    line = next(x for x in err.splitlines() if x.endswith(f"(`semmap diff {intel_corner_wstar} {out}` lists them)"))
    assert line.startswith(f"since {intel_corner_wstar}: units {c['units'][0]} -> {c['units'][1]} "
                           f"({c['paired']} paired: {c['retyped']} retyped, {c['moved']} moved; "
                           f"{c['removed']} removed, {c['added']} added); doors and passages: "
                           f"{c['openings_removed']} removed, {c['openings_added']} added") \
        or line.startswith(f"the same plan as {intel_corner_wstar}")
    old = json.loads(intel_corner_wstar.read_text())
    new = json.loads((out / "world.json").read_text())
    jsonschema.validate(new, SCHEMA)
    rec = new["ids"]
    old_ids = {u["id"] for u in old["units"]}
    carried = 0
    for u in new["units"]:
        best = max(old["units"], key=lambda o: raster_iou(np.array(u["vertices_m"]), np.array(o["vertices_m"])))
        iou = raster_iou(np.array(u["vertices_m"]), np.array(best["vertices_m"]))
        if iou > 0.52:               # the same place: its id carried
            assert u["id"] == best["id"], (u["id"], best["id"], iou)
            carried += 1
        elif iou < 0.48:             # a new place: an id the earlier file never used
            assert u["id"] > max(old_ids) and u["id"] in rec["new"]
    assert carried >= len(new["units"]) // 2        # the grown map is the same building
    assert sorted(rec["carried"] + rec["new"]) == sorted(u["id"] for u in new["units"])
    assert set(rec["gone"]) == old_ids - set(rec["carried"])
    assert rec["next"] == max([max(old_ids) + 1, *[i + 1 for i in rec["new"]]])
    labels = np.asarray(Image.open(out / "labels.png"))
    assert set(np.unique(labels).tolist()) - {0} <= {u["id"] for u in new["units"]}


def test_edit_keeps_the_ids_of_the_world_it_edits(intel_corner_wstar, tmp_path, capsys):
    old = json.loads(intel_corner_wstar.read_text())
    drop = old["units"][0]["id"]
    out = tmp_path / "e"
    assert main(["edit", str(INTEL_CORNER), str(intel_corner_wstar), "--out", str(out), "--drop", str(drop),
                 "--ids-from", str(intel_corner_wstar)]) == 0
    text = capsys.readouterr().out
    assert f"ids carried from {intel_corner_wstar}" in text and "every other unit keeps its id" in text
    new = json.loads((out / "world.json").read_text())
    jsonschema.validate(new, SCHEMA)
    assert [u["id"] for u in new["units"]] == [u["id"] for u in old["units"] if u["id"] != drop]
    assert [u["vertices_m"] for u in new["units"]] == [u["vertices_m"] for u in old["units"] if u["id"] != drop]
    assert new["ids"]["gone"] == [drop] and new["ids"]["new"] == []


def test_a_bad_ids_file_stops_the_run_before_it_starts(intel_corner_wstar, tmp_path, capsys):
    bad = tmp_path / "bad.json"
    bad.write_text('{"format": "semmap_pp.world/1", "units": [{"id": 1}]}')
    out = tmp_path / "run"
    assert main(["map", str(INTEL_CORNER), "--out", str(out), *FAST_RUN, "--ids-from", str(bad)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"semmap: error: {bad}: unit 1: 'vertices_m' must be four [x, y] numbers"]
    assert not out.exists() or not any(out.iterdir())


def test_the_larger_piece_of_a_cut_keeps_the_units_id(intel_corner_wstar, tmp_path, capsys):
    old = json.loads(intel_corner_wstar.read_text())
    unit = max(old["units"], key=lambda u: u["size_m"][0] * u["size_m"][1])
    v = np.array(unit["vertices_m"])
    a, b = v[1] - v[0], v[2] - v[1]
    if np.hypot(*a) >= np.hypot(*b):     # v0-v1 is a long side: the cut runs across it, a quarter in
        p, q = v[0] + 0.25 * a, v[3] + 0.25 * a
    else:
        p, q = v[1] + 0.25 * b, v[0] + 0.25 * b
    inset = (q - p) * 0.2
    line = [*(p + inset), *(q - inset)]
    out = tmp_path / "cut"
    assert main(["edit", str(INTEL_CORNER), str(intel_corner_wstar), "--out", str(out), "--cut", str(unit["id"]),
                 *map(str, line), "--ids-from", str(intel_corner_wstar)]) == 0
    text = capsys.readouterr().out
    new = json.loads((out / "world.json").read_text())
    rows = {r["now"].lstrip("RCHE"): r for r in new["edited"]["ids"]}
    kept = rows[str(unit["id"])]
    assert kept["was"] == str(unit["id"]) and kept["by"].startswith("--cut")
    made = [r for r in new["edited"]["ids"] if r["was"] is None]
    assert len(made) == 1 and int(made[0]["now"].lstrip("RCHE")) == max(u["id"] for u in old["units"]) + 1
    assert new["ids"]["gone"] == [] and new["ids"]["new"] == [int(made[0]["now"].lstrip("RCHE"))]
    assert "gone:" not in text and f"new {made[0]['now']}: --cut" in text


def test_a_resumed_run_keeps_the_ids_its_run_carried(intel_corner_wstar, grown, tmp_path, capsys):
    out = tmp_path / "run"
    assert main(["map", str(grown), "--out", str(out), "--seed", "3", *FAST_RUN,
                 "--ids-from", str(intel_corner_wstar)]) == 0
    first = json.loads((out / "world.json").read_text())
    capsys.readouterr()
    assert main(["map", "--resume", str(out), "--draws", "2", "--progress", "none"]) == 0
    err = capsys.readouterr().err
    assert f"unit ids from {out / 'world.json'}" in err
    # compared with the file as it was before the resumed run overwrote it
    line = next(x for x in err.splitlines() if "the world.json this run overwrote" in x)
    assert line.startswith(("since the world.json this run overwrote: units ",
                            "the same plan as the world.json this run overwrote")) and "semmap diff" not in line
    again = json.loads((out / "world.json").read_text())
    assert again["ids"]["next"] >= first["ids"]["next"]
    same = {tuple(map(tuple, u["vertices_m"])): u["id"] for u in first["units"]}
    for u in again["units"]:          # a unit where it was keeps its id; none takes an id of the first
        key = tuple(map(tuple, u["vertices_m"]))
        assert u["id"] == same[key] if key in same else u["id"] >= first["ids"]["next"]
