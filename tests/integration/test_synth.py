"""Synthetic floors: determinism, truth consistency, rotation, bounded noise, files and CLI.

Every check recomputes what it tests from the written geometry (corners, door centres, labels),
never from the generator's own bookkeeping.
"""

from __future__ import annotations

import hashlib
import json
import os
import subprocess
import sys

import numpy as np
import pytest
import yaml
from scipy import ndimage

from semmap_pp.cells import FREE, OCCUPIED, UNKNOWN
from semmap_pp.cli import main
from semmap_pp.synth import generate_floor, write_floor
from semmap_pp.synth.layout import partition
from semmap_pp.synth.topology import exterior_intervals, shared_boundary
from semmap_pp.synth.truth import encode_labels, encode_truth, read_labels

TOL = 0.02  # px: truth.json rounds to 1e-3, rotation adds a little


@pytest.fixture(scope="module")
def floors():
    """Small floors of every layout kind, axis-aligned and rotated."""
    return [generate_floor(s, units=u, rotation_deg=r)
            for s, u, r in ((1, 4, 0.0), (2, 7, 33.0), (5, 9, 251.5), (11, 15, None))]


def _unrotate(points, rotation_deg):
    """Building-frame coordinates (up to a translation) of image points."""
    a = np.deg2rad(rotation_deg)
    rot = np.array([[np.cos(a), np.sin(a)], [-np.sin(a), np.cos(a)]])
    return np.asarray(points, dtype=float) @ rot  # inverse of p @ rot.T


def _boxes(truth):
    """Axis-aligned (x0, y0, x1, y1) of every unit in the building frame."""
    out = []
    for u in truth["units"]:
        c = _unrotate(u["corners_px"], truth["rotation_deg"])
        out.append((c[:, 0].min(), c[:, 1].min(), c[:, 0].max(), c[:, 1].max()))
    return out


def _shared(b, c):
    """(orient, line, s0, s1) when two boxes share an edge of positive length, else None."""
    for line_b, line_c in ((b[2], c[0]), (b[0], c[2])):  # a vertical line x = line
        s0, s1 = max(b[1], c[1]), min(b[3], c[3])
        if abs(line_b - line_c) < TOL and s1 - s0 > TOL:
            return "v", line_b, s0, s1
    for line_b, line_c in ((b[3], c[1]), (b[1], c[3])):  # a horizontal line y = line
        s0, s1 = max(b[0], c[0]), min(b[2], c[2])
        if abs(line_b - line_c) < TOL and s1 - s0 > TOL:
            return "h", line_b, s0, s1
    return None


# --- determinism ----------------------------------------------------------------------------

def test_same_seed_same_bytes_different_seed_differs(tmp_path):
    a = write_floor(generate_floor(7, units=5), tmp_path / "a")
    b = write_floor(generate_floor(7, units=5), tmp_path / "b")
    c = write_floor(generate_floor(8, units=5), tmp_path / "c")
    for key in a:
        assert a[key].read_bytes() == b[key].read_bytes(), key
    assert a["map_image"].read_bytes() != c["map_image"].read_bytes()
    assert a["truth"].read_bytes() != c["truth"].read_bytes()


def _digest(f) -> str:
    return hashlib.sha256(f.image.tobytes() + encode_truth(f.truth).encode()
                          + encode_labels(f.truth_labels)).hexdigest()


# The floor of one fixed request, frozen. A change of the generator that changes floors must
# update this digest on purpose and say so in docs/synthetic.md (old seeds give new floors).
GOLDEN = (dict(seed=12345, units=3, rotation_deg=30.0),
          "90cac67cc9554eb31235837758b9d74773dba3e3a9e0a881f74633665b587aab")


def test_golden_floor_is_unchanged():
    kwargs, digest = GOLDEN
    assert _digest(generate_floor(**kwargs)) == digest


def test_another_process_with_another_hash_seed_makes_the_same_floor():
    code = ("import hashlib; from semmap_pp.synth import generate_floor; "
            "from semmap_pp.synth.truth import encode_truth, encode_labels; "
            "f = generate_floor(**%r); "
            "print(hashlib.sha256(f.image.tobytes() + encode_truth(f.truth).encode() "
            "+ encode_labels(f.truth_labels)).hexdigest())" % (GOLDEN[0],))
    env = dict(os.environ, PYTHONHASHSEED="12345")
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True,
                         check=True).stdout.strip()
    assert out == _digest(generate_floor(**GOLDEN[0]))


def test_units_argument_does_not_change_the_drawn_rotation():
    # separate random streams: asking for a unit count keeps the seed's rotation
    r1 = generate_floor(21, units=3).truth["rotation_deg"]
    r2 = generate_floor(21, units=6).truth["rotation_deg"]
    assert r1 == r2


# --- truth consistency ----------------------------------------------------------------------

def test_unit_ids_count_and_types(floors):
    for f, want in zip(floors, (4, 7, 9, 15)):
        units = f.truth["units"]
        assert [u["id"] for u in units] == list(range(1, len(units) + 1))
        assert len(units) == want
        assert {u["type"] for u in units} <= {"room", "corridor", "hall", "other"}
        for u in units:
            assert len(u["corners_px"]) == 4
            assert u["size_m"][0] >= u["size_m"][1] > 0


def test_units_tile_without_overlap(floors):
    for f in floors:
        boxes = _boxes(f.truth)
        for i in range(len(boxes)):
            for j in range(i + 1, len(boxes)):
                a, b = boxes[i], boxes[j]
                ox = min(a[2], b[2]) - max(a[0], b[0])
                oy = min(a[3], b[3]) - max(a[1], b[1])
                assert ox <= TOL or oy <= TOL, (i + 1, j + 1)


def test_adjacency_is_the_shared_walls(floors):
    for f in floors:
        t = f.truth
        boxes = _boxes(t)
        pairs = [tuple(p) for p in t["adjacency"]]
        assert len(pairs) == len(set(pairs))
        assert all(a < b for a, b in pairs)
        relation = {(a, b) for a, b in pairs} | {(b, a) for a, b in pairs}
        geometric = {(i + 1, j + 1) for i in range(len(boxes)) for j in range(len(boxes))
                     if i != j and _shared(boxes[i], boxes[j]) is not None}
        assert relation == geometric


def test_every_door_lies_on_a_wall_its_units_share(floors):
    for f in floors:
        t = f.truth
        boxes = _boxes(t)
        assert t["doors"], "a floor of several units needs doors"
        for d in t["doors"]:
            a, b = d["units"]
            s = _shared(boxes[a - 1], boxes[b - 1])
            assert s is not None, d
            o, line, s0, s1 = s
            x, y = _unrotate([d["center_px"]], t["rotation_deg"])[0]
            across, along = (x, y) if o == "v" else (y, x)
            half = d["width_m"] / t["resolution"] / 2
            assert abs(across - line) < TOL
            assert s0 + half - TOL <= along <= s1 - half + TOL
            assert 0.7 - 1e-9 <= d["width_m"] <= 1.5 + 1e-9
            assert [a, b] not in t["open_boundaries"]


def test_doors_and_open_boundaries_reach_every_unit(floors):
    for f in floors:
        t = f.truth
        n = len(t["units"])
        edges = [d["units"] for d in t["doors"]] + t["open_boundaries"]
        graph = np.zeros((n + 1, n + 1), dtype=bool)
        for a, b in edges:
            graph[a, b] = graph[b, a] = True
        seen, todo = {1}, [1]
        while todo:
            u = todo.pop()
            for v in np.nonzero(graph[u])[0]:
                if int(v) not in seen:
                    seen.add(int(v))
                    todo.append(int(v))
        assert seen == set(range(1, n + 1))


def test_l_shapes_are_open_and_l_shaped(floors):
    found = 0
    for f in floors + [generate_floor(s, units=6, rotation_deg=0.0) for s in range(30, 36)]:
        t = f.truth
        boxes = _boxes(t)
        for a, b in t["l_shapes"]:
            found += 1
            assert [a, b] in t["adjacency"] and [a, b] in t["open_boundaries"]
            o, line, s0, s1 = _shared(boxes[a - 1], boxes[b - 1])
            spans = [(bx[1], bx[3]) if o == "v" else (bx[0], bx[2]) for bx in (boxes[a - 1], boxes[b - 1])]
            # an L: the open boundary is shorter than the wider unit's side along it
            assert s1 - s0 < max(hi - lo for lo, hi in spans) - TOL
    assert found > 0


def test_labels_cover_each_unit_and_nothing_else(floors):
    for f in floors:
        t = f.truth
        lab = f.truth_labels
        assert lab.dtype == np.uint16 and lab.shape == f.image.shape
        assert set(np.unique(lab).tolist()) == set(range(0, len(t["units"]) + 1))
        rows, cols = np.mgrid[0:lab.shape[0], 0:lab.shape[1]]
        centres = _unrotate(np.stack([cols.ravel() + 0.5, rows.ravel() + 0.5], 1), t["rotation_deg"])
        for (x0, y0, x1, y1), u in zip(_boxes(t), t["units"]):
            inner = ((centres[:, 0] > x0 + 1) & (centres[:, 0] < x1 - 1)
                     & (centres[:, 1] > y0 + 1) & (centres[:, 1] < y1 - 1)).reshape(lab.shape)
            assert inner.any()
            assert (lab[inner] == u["id"]).all(), u["id"]
            # walls included: the unit's label reaches its rectangle's edge, not beyond a wall
            grown = ((centres[:, 0] > x0 - 8) & (centres[:, 0] < x1 + 8)
                     & (centres[:, 1] > y0 - 8) & (centres[:, 1] < y1 + 8)).reshape(lab.shape)
            assert not ((lab == u["id"]) & ~grown).any()
            assert (lab == u["id"]).sum() >= inner.sum()


# --- rotation -------------------------------------------------------------------------------

def _dominant_orientation_deg(classes):
    """Dominant wall direction of the occupied cells, counter-clockwise as displayed, mod 90.

    Gradient orientations of the smoothed occupied mask, folded four times (walls at right angles
    vote together) and averaged on the circle with squared-magnitude weights.
    """
    occ = ndimage.gaussian_filter((classes == OCCUPIED).astype(float), 2.0)
    gx, gy = ndimage.sobel(occ, axis=1), ndimage.sobel(occ, axis=0)
    z = (np.hypot(gx, gy) ** 2 * np.exp(4j * np.arctan2(gy, gx))).sum()
    # image rows grow downwards: a counter-clockwise turn as displayed is a negative image angle
    return (-np.degrees(np.angle(z)) / 4.0) % 90.0


@pytest.mark.parametrize("rotation", [0.0, 12.0, 37.5, 80.0, 145.0, 301.3])
def test_rotation_is_respected(rotation):
    f = generate_floor(40, units=4, rotation_deg=rotation)
    assert f.truth["rotation_deg"] == pytest.approx(rotation % 360.0)
    est = _dominant_orientation_deg(f.classes)
    err = (est - rotation % 90.0 + 45.0) % 90.0 - 45.0
    assert abs(err) < 2.0, (rotation, est)


def test_rotation_drawn_from_the_seed_is_sometimes_zero_sometimes_not():
    rots = [generate_floor(s, units=2).truth["rotation_deg"] for s in range(12)]
    assert any(r == 0.0 for r in rots)
    assert any(r % 90.0 != 0.0 for r in rots)


# --- realism: noise present but bounded ------------------------------------------------------

def test_noise_is_present_but_bounded(floors):
    f = floors[3]
    t, c, lab = f.truth, f.classes, f.truth_labels
    entered = [u["id"] for u in t["units"] if u["entered"]]
    assert entered
    # interiors of units the robot drove through: mostly free, yet not perfectly clean
    interior = np.isin(lab, entered) & ndimage.binary_erosion(np.isin(lab, entered), iterations=8)
    free_frac = (c[interior] == FREE).mean()
    assert 0.75 < free_frac < 0.995, free_frac
    # walls are seen: cells within 3 px of a unit boundary are often occupied
    boundary = np.zeros(lab.shape, dtype=bool)
    boundary[:, 1:] |= lab[:, 1:] != lab[:, :-1]
    boundary[1:, :] |= lab[1:, :] != lab[:-1, :]
    near_wall = ndimage.binary_dilation(boundary, iterations=3) & np.isin(
        ndimage.grey_dilation(lab, size=9), entered)
    occ_on_walls = (c[near_wall] == OCCUPIED).mean()
    assert 0.1 < occ_on_walls < 0.8, occ_on_walls
    # occupied cells are mostly walls or furniture inside units, a few are speckle or outside
    assert (lab[c == OCCUPIED] > 0).mean() > 0.8
    # outside the building: mostly never scanned, but rays leak through doors and windows
    outside = ndimage.distance_transform_edt(lab == 0) > 10
    assert (c[outside] == UNKNOWN).mean() > 0.6
    assert (c[outside] == FREE).sum() > 0


def test_closed_doors_hide_rooms():
    for seed in range(60):
        f = generate_floor(seed, units=8, rotation_deg=0.0)
        hidden = [u["id"] for u in f.truth["units"] if not u["explored"]]
        if hidden:
            break
    else:
        pytest.fail("no floor with an unexplored room in 60 seeds")
    inner = ndimage.binary_erosion(np.isin(f.truth_labels, hidden), iterations=6)
    assert (f.classes[inner] == UNKNOWN).mean() > 0.9


# --- pieces ---------------------------------------------------------------------------------

@pytest.mark.parametrize("length, lo, hi", [(100, 20, 40), (50, 50, 160), (7, 10, 20), (161, 50, 160)])
def test_partition_sums_and_respects_bounds(length, lo, hi):
    w = partition(np.random.default_rng(3), length, lo, hi)
    assert sum(w) == length
    if length >= lo:
        assert all(lo <= x <= hi for x in w)


def test_shared_boundary_and_exterior_intervals():
    # a 10x10 room with a corridor along half of its right edge
    rects = [[0, 0, 10, 10], [10, 5, 30, 8]]
    assert shared_boundary(*rects) == ("v", 10, 5, 8)
    ext = exterior_intervals(rects, {(0, 1): ("v", 10, 5, 8)}, 0)
    assert ("v", 10, 0, 5) in ext and ("v", 10, 8, 10) in ext
    assert sum(s1 - s0 for _, _, s0, s1 in ext) == 40 - 3


@pytest.mark.parametrize("kwargs", [dict(units=1), dict(units=10_000), dict(rotation_deg=float("nan")),
                                    dict(resolution=0.0)])
def test_bad_arguments_are_refused(kwargs):
    with pytest.raises(ValueError):
        generate_floor(1, **kwargs)
    with pytest.raises(ValueError):
        generate_floor(-1)


# --- files and CLI --------------------------------------------------------------------------

def test_written_files_read_back(tmp_path):
    f = generate_floor(4, units=3)
    paths = write_floor(f, tmp_path)
    doc = yaml.safe_load(paths["map_yaml"].read_text())
    assert doc["image"] == "map.pgm" and doc["resolution"] == pytest.approx(0.05)
    raw = paths["map_image"].read_bytes()
    assert raw.startswith(b"P5")
    assert np.frombuffer(raw[-f.image.size:], dtype=np.uint8).reshape(f.image.shape).tolist() == f.image.tolist()
    assert set(np.unique(f.image).tolist()) <= {0, 205, 254}
    assert json.loads(paths["truth"].read_text()) == f.truth
    np.testing.assert_array_equal(read_labels(paths["truth_labels"]), f.truth_labels)


def test_cli_writes_files_and_refuses_a_non_empty_dir(tmp_path, capsys):
    out = tmp_path / "floor"
    assert main(["synth", "--seed", "5", "--units", "3", "--rotation", "10", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    names = sorted(p.name for p in out.iterdir())
    assert names == ["map.pgm", "map.yaml", "truth.json", "truth_labels.png"]
    for name in names:
        assert str(out / name) in printed
    assert json.loads((out / "truth.json").read_text())["rotation_deg"] == 10.0
    before = (out / "map.pgm").read_bytes()
    assert main(["synth", "--seed", "6", "--units", "3", "--out", str(out)]) == 2
    assert "not empty" in capsys.readouterr().err
    assert (out / "map.pgm").read_bytes() == before
    assert main(["synth", "--seed", "6", "--units", "3", "--out", str(out), "--force"]) == 0
    assert (out / "map.pgm").read_bytes() != before
    (tmp_path / "file").write_text("x")
    assert main(["synth", "--seed", "1", "--out", str(tmp_path / "file")]) == 2
    assert "not a directory" in capsys.readouterr().err


@pytest.mark.parametrize("seed,resolution", [(9, 0.1), (5, 0.025)])
def test_a_seed_gives_the_same_building_at_every_resolution(seed, resolution):
    """The plan is drawn in 0.05 m cells and scaled: units, types, sizes, doors and what the robot
    explored are the same at another resolution, to within one cell's rounding. Seeds 9 and 5 drew
    other buildings at 0.1 m and 0.025 m while the plan was drawn in the map's own cells."""
    a, b = generate_floor(seed), generate_floor(seed, resolution=resolution)
    ua, ub = a.truth["units"], b.truth["units"]
    assert len(ua) == len(ub) and b.truth["layout"] == a.truth["layout"]
    tol = 2 * max(resolution, 0.05) + 1e-9
    for u, v in zip(ua, ub):
        assert (u["type"], u["explored"], u["entered"]) == (v["type"], v["explored"], v["entered"])
        assert np.allclose(u["size_m"], v["size_m"], atol=tol)
    assert [(d["units"], d["open"]) for d in a.truth["doors"]] == \
        [(d["units"], d["open"]) for d in b.truth["doors"]]
    assert np.allclose([d["width_m"] for d in a.truth["doors"]],
                       [d["width_m"] for d in b.truth["doors"]], atol=tol)
