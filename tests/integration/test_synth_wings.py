"""Synthetic floors of several wings: determinism, each wing at the angle asked (from the truth and
from the map's walls), truth labels against the truth's polygons and the map, links that connect
the wings, unit matching of rotated truth units, bad arguments.

Every check recomputes what it tests from the written geometry (corners, door centres, labels,
occupied cells), never from the generator's own bookkeeping.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy import ndimage

from semmap_pp.cells import FREE, OCCUPIED
from semmap_pp.cli import main
from semmap_pp.evaluate import score_world
from semmap_pp.evaluate.truth import polygon_mask
from semmap_pp.synth import generate_floor, write_floor


@pytest.fixture(scope="module")
def floors():
    """Two wings at 30 and 45 degrees, three wings at a drawn angle, all turned as a whole."""
    return [generate_floor(2, units=12, rotation_deg=20.0, wings=2, wing_angle_deg=30.0),
            generate_floor(4, units=14, rotation_deg=0.0, wings=2, wing_angle_deg=45.0),
            generate_floor(7, rotation_deg=111.0, wings=3)]


def _fold(deg):
    """An angle mod 90 as an offset in [-45, 45)."""
    return (np.asarray(deg, float) + 45.0) % 90.0 - 45.0


def _edge_angles(corners):
    """Directions of a polygon's edges, counter-clockwise as displayed (image y grows down)."""
    c = np.asarray(corners, float)
    d = np.roll(c, -1, axis=0) - c
    return np.degrees(np.arctan2(-d[:, 1], d[:, 0]))


def _expected(truth):
    """Wing number -> expected wall direction mod 90: the floor's rotation plus the link angles."""
    out, angle = {1: truth["rotation_deg"]}, truth["rotation_deg"]
    for link in truth["links"]:
        angle += link["angle_deg"]
        out[link["wings"][1]] = angle
    return out


def _dominant_orientation_deg(occupied):
    """Dominant wall direction of an occupied mask, counter-clockwise as displayed, mod 90
    (gradient orientations folded four times, squared-magnitude weights; as test_synth.py)."""
    occ = ndimage.gaussian_filter(occupied.astype(float), 2.0)
    gx, gy = ndimage.sobel(occ, axis=1), ndimage.sobel(occ, axis=0)
    z = (np.hypot(gx, gy) ** 2 * np.exp(4j * np.arctan2(gy, gx))).sum()
    return (-np.degrees(np.angle(z)) / 4.0) % 90.0


def test_same_seed_same_bytes_other_angle_differs(tmp_path):
    kw = dict(units=11, wings=2, wing_angle_deg=30.0)
    paths = [write_floor(generate_floor(5, **kw), tmp_path / name) for name in ("a", "b")]
    for key in paths[0]:
        assert paths[0][key].read_bytes() == paths[1][key].read_bytes(), key
    other = write_floor(generate_floor(5, **(kw | {"wing_angle_deg": 45.0})), tmp_path / "c")
    assert other["map_image"].read_bytes() != paths[0]["map_image"].read_bytes()


def test_each_wing_lies_at_the_angle_asked_in_the_truth(floors):
    for f in floors:
        t = f.truth
        assert len(t["wings"]) == len(t["links"]) + 1 >= 2
        want = _expected(t)
        if t["links"][0]["angle_deg"] in (30.0, 45.0):
            assert len(want) == 2
        for u in t["units"]:
            if u["wing"] == 0:
                continue
            err = _fold(_edge_angles(u["corners_px"]) - want[u["wing"]])
            assert np.abs(err).max() < 0.01, (u["id"], err)
        # the wings really differ: the second wing's walls are not the first's
        assert abs(_fold(want[2] - want[1])) > 10.0


def test_each_wing_lies_at_the_angle_asked_in_the_map(floors):
    for f in floors:
        t = f.truth
        for wing, want in _expected(t).items():
            ids = [u["id"] for u in t["units"] if u["wing"] == wing]
            near = ndimage.binary_dilation(np.isin(f.truth_labels, ids), iterations=3)
            est = _dominant_orientation_deg((f.classes == OCCUPIED) & near)
            assert abs(_fold(est - want)) < 2.5, (wing, est, want)


def test_labels_agree_with_the_polygons_and_the_map(floors):
    for f in floors:
        t, lab = f.truth, f.truth_labels
        assert set(np.unique(lab).tolist()) == set(range(len(t["units"]) + 1))
        for u in t["units"]:
            poly = polygon_mask(u["corners_px"], lab.shape)
            # a link ends on a wing's exterior wall, which belongs wholly to the wing (<= 0.3 m)
            inner = ndimage.binary_erosion(poly, iterations=2 if u["wing"] else 7)
            assert inner.any() and (lab[inner] == u["id"]).all(), u["id"]
            # nothing of the unit beyond its walls (at most 0.3 m, 6 cells, past its outline)
            assert not ((lab == u["id"]) & ~ndimage.binary_dilation(poly, iterations=7)).any(), u["id"]
            core = ndimage.binary_erosion(lab == u["id"], iterations=8)
            if u["entered"] and core.sum() > 50:      # furniture shadows leave some unknown
                assert (f.classes[core] == FREE).mean() > 0.2, u["id"]
            if not u["explored"]:
                assert (f.classes[core] == FREE).mean() < 0.1, u["id"]
        entered = [u["id"] for u in t["units"] if u["entered"]]
        core = ndimage.binary_erosion(np.isin(lab, entered), iterations=8)
        assert (f.classes[core] == FREE).mean() > 0.6
        # the free space inside the building is the truth's: few free cells far outside every unit
        outside = ~ndimage.binary_dilation(lab > 0, iterations=10)
        assert (f.classes[lab > 0] == FREE).sum() > 2 * (f.classes[outside] == FREE).sum()


def test_links_join_the_wings_through_doors(floors):
    for f in floors:
        t = f.truth
        res = t["resolution"]
        units = {u["id"]: u for u in t["units"]}
        for link in t["links"]:
            lid = link["unit"]
            doors = [d for d in t["doors"] if lid in d["units"]]
            wings = sorted(units[next(v for v in d["units"] if v != lid)]["wing"] for d in doors)
            assert wings == link["wings"]
            corners = np.asarray(units[lid]["corners_px"])
            for d, (a, b) in zip(doors, ((0, 1), (3, 2))):
                # each door on an end of the link's outline: near end first, far end second
                p, q = corners[a], corners[b]
                c = np.asarray(d["center_px"])
                e, v = q - p, c - p
                dist = abs(e[0] * v[1] - e[1] * v[0]) / np.linalg.norm(e)
                assert dist < 1.0 and d["open"], (lid, d)
                assert sorted(d["units"]) in t["adjacency"]
                # the door and its margins fit in the end of the link
                assert d["width_m"] + 0.6 <= np.linalg.norm(e) * res + 0.01
        # doors and open boundaries reach every unit
        nbrs = {u: set() for u in units}
        for a, b in [d["units"] for d in t["doors"]] + t["open_boundaries"]:
            nbrs[a].add(b)
            nbrs[b].add(a)
        seen, todo = {1}, [1]
        while todo:
            for v in nbrs[todo.pop()] - seen:
                seen.add(v)
                todo.append(v)
        assert seen == set(units)


def test_rotated_truth_units_are_matched_by_their_polygons(floors):
    f = floors[1]                                 # the second wing at 45 degrees
    t = f.truth
    pred = {"units": [{"id": u["id"], "type": u["type"], "vertices_px": u["corners_px"]}
                      for u in t["units"]], "adjacency": t["adjacency"], "doors": t["doors"]}
    s = score_world(pred, t)
    assert s.unit_f1 == 1.0 and s.door_recall == 1.0 and s.adjacency_recall == 1.0
    assert all(k == v for k, v in s.matches.items())
    # the same units as axis-aligned boxes: the turned wing's long units no longer match
    boxed = []
    for u in t["units"]:
        c = np.asarray(u["corners_px"])
        (x0, y0), (x1, y1) = c.min(axis=0), c.max(axis=0)
        boxed.append({"id": u["id"], "type": u["type"],
                      "vertices_px": [[x0, y0], [x1, y0], [x1, y1], [x0, y1]]})
    sb = score_world({"units": boxed}, t)
    # a box around an a x b rectangle turned by 45 degrees has IoU 2ab / (a + b)^2 with it
    iou45 = {u["id"]: 2 * np.prod(u["size_m"]) / sum(u["size_m"]) ** 2
             for u in t["units"] if u["wing"] == 2}
    long_ones = {k for k, v in iou45.items() if v < 0.499}       # below the match threshold 0.5
    assert long_ones and not long_ones & set(sb.matches)
    assert all(u["wing"] != 1 or u["id"] in sb.matches for u in t["units"])


@pytest.mark.parametrize("kwargs", [dict(wings=0), dict(wings=5), dict(wings=True),
                                    dict(wing_angle_deg=30.0),
                                    dict(wings=2, wing_angle_deg=float("nan")),
                                    dict(wings=2, units=6)])
def test_bad_wing_arguments_are_refused(kwargs):
    with pytest.raises(ValueError, match="wing|units"):
        generate_floor(1, **kwargs)


def test_cli_writes_a_floor_of_wings(tmp_path, capsys):
    out = tmp_path / "w"
    assert main(["synth", "--seed", "3", "--out", str(out), "--wings", "2", "--wing-angle", "30",
                 "--units", "9"]) == 0
    t = json.loads((out / "truth.json").read_text())
    assert [w["wing"] for w in t["wings"]] == [1, 2] and t["links"][0]["angle_deg"] == 30.0
    assert len(t["units"]) == 9
    assert "wing 2 at" in capsys.readouterr().out
    assert main(["synth", "--seed", "3", "--out", str(tmp_path / "x"), "--wing-angle", "30"]) == 2
    assert "--wing-angle" in capsys.readouterr().err
