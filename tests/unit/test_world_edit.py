"""``semmap_pp.plans.edit``: hand edits by unit id and map point, on a rotated lattice with a moved
origin, in metres and in pixels."""

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from semmap_pp.errors import SemmapError
from semmap_pp.lattice.frame import build_frame_from_classes
from semmap_pp.model import load_model
from semmap_pp.plans.edit import EDITS, Edit, apply_edits, check_args, edit_origins, id_changes, to_lattice, unit_key

RES = 0.05


#: The tests' lattice coordinates are offset by this many cells: a rotated lattice's corners lie
#: outside the image, and an edit's points must lie on the map.
OFF = 250


@pytest.fixture(scope="module")
def frame():
    # a rotated lattice (0.3 rad) over a map whose origin is moved and turned: every conversion counts
    return build_frame_from_classes(np.zeros((800, 900), np.uint8), RES, load_model(),
                                    origin=(3.5, -2.0, 0.4), theta=0.3)


def at(rect):
    """A test rectangle on the lattice."""
    return tuple(v + OFF for v in rect)


def metres(frame, row, col):
    """Map-frame metres of a fractional test coordinate (an integer = a cell's centre)."""
    x, y = frame.lattice_to_image(row + OFF, col + OFF)
    mx, my = frame.image_to_metres(float(x) + 0.5, float(y) + 0.5)
    return float(mx), float(my)


def pixels(frame, row, col):
    x, y = frame.lattice_to_image(row + OFF, col + OFF)
    return float(x) + 0.5, float(y) + 0.5


def band_centre(start, t):
    return start + (t - 1) / 2


def args(*values):
    return tuple(f"{v:.6f}" if isinstance(v, float) else str(v) for v in values)


UNITS = [("1", at((40, 40, 100, 160))), ("2", at((98, 40, 150, 100))), ("X1", at((150, 200, 200, 260)))]


def test_ids_are_read_as_overlay_png_writes_them():
    assert [unit_key(t) for t in ("3", "R3", "c3", "H03", "E3", "X2", "x2")] == ["3"] * 5 + ["X2"] * 2
    for bad in ("", "R", "3R", "Q3", "-3", "R 3x"):
        with pytest.raises(ValueError, match="not a unit id"):
            unit_key(bad)
    check_args(Edit("cut", ("R3", "1", "2", "3.5", "-4e1")))
    for edit, message in ((Edit("merge", ("3",)), "two unit ids"), (Edit("cut", ("3", "1", "2")), "takes 5"),
                          (Edit("wall", ("3", "x", "2")), "not a number"),
                          (Edit("add", ("1", "2", "3", "inf")), "finite")):
        with pytest.raises(ValueError, match=message):
            check_args(edit)


def test_a_point_in_metres_or_pixels_lands_on_its_lattice_coordinate(frame):
    for row, col in ((40.0, 40.0), (97.5, 161.25), (0.0, 0.0)):
        p = to_lattice(frame, *metres(frame, row, col))
        assert (p.row, p.col) == pytest.approx((row + OFF, col + OFF), abs=1e-9)
        p = to_lattice(frame, *pixels(frame, row, col), pixels=True)
        assert (p.row, p.col) == pytest.approx((row + OFF, col + OFF), abs=1e-9)


@pytest.mark.parametrize("in_pixels", [False, True])
def test_a_unit_added_at_its_walls_centres_is_that_rectangle(frame, in_pixels):
    t = frame.cells.wall
    rect = (60, 80, 131, 177)
    where = pixels if in_pixels else metres
    a = where(frame, band_centre(rect[0], t), band_centre(rect[1], t))
    b = where(frame, band_centre(rect[2] - t, t), band_centre(rect[3] - t, t))
    out = apply_edits(UNITS, [Edit("add", args(*b, *a))], frame, pixels=in_pixels)   # corners in any order
    assert out[-1] == (None, at(rect), True)
    assert out[:3] == [(k, r, False) for k, r in UNITS]


def test_a_cut_shares_one_wall_band_centred_on_the_line_whichever_way_it_runs(frame):
    t = frame.cells.wall
    # a line along the lattice's columns (slightly skewed: snapped to the axis) at row 70.3
    p, q = metres(frame, 70.0, 50.0), metres(frame, 70.6, 150.0)
    out = apply_edits(UNITS, [Edit("cut", args("R1", *p, *q))], frame)
    assert [k for k, _, _ in out] == ["2", "X1", None, None]
    (_, first, _), (_, second, _) = out[2:]
    assert first[:2] == at((40, 40, 0, 0))[:2] and second[2:] == at((0, 0, 100, 160))[2:]
    assert first[3] == second[3] == 160 + OFF
    assert first[2] - second[0] == t                                  # the pieces share the band
    assert abs(band_centre(second[0], t) - 70.3 - OFF) <= 0.5
    # a steep line cuts along the other axis
    p, q = metres(frame, 45.0, 121.0), metres(frame, 95.0, 119.0)
    (_, first, _), (_, second, _) = apply_edits(UNITS, [Edit("cut", args("1", *p, *q))], frame)[2:]
    assert first[0] == second[0] == 40 + OFF and first[3] - second[1] == t
    assert abs(band_centre(second[1], t) - 120.0 - OFF) <= 0.5


def test_a_wall_moves_its_nearest_side_onto_the_point_only(frame):
    t = frame.cells.wall
    out = apply_edits(UNITS, [Edit("wall", args("1", *metres(frame, 70.0, 170.2)))], frame)
    rect = out[0][1]
    assert rect[:3] == at((40, 40, 100, 0))[:3] and abs(band_centre(rect[3] - t, t) - 170.2 - OFF) <= 0.5
    assert out[0][2] and not out[1][2]
    # a unit's own wall centre leaves it as it is
    same = apply_edits(UNITS, [Edit("wall", args("2", *metres(frame, band_centre(98, t), 70.0)))], frame)
    assert same[1] == ("2", UNITS[1][1], True)


def test_merge_drop_and_the_order_of_edits(frame):
    out = apply_edits(UNITS, [Edit("merge", ("2", "R1")), Edit("drop", ("x1",))], frame)
    assert out == [("2", at((40, 40, 150, 160)), True)]
    with pytest.raises(SemmapError, match=r"--wall 1 .*: unit 1 no longer exists after --merge 2 R1"):
        apply_edits(UNITS, [Edit("merge", ("2", "R1")), Edit("wall", args("1", 1.0, 2.0))], frame)
    with pytest.raises(SemmapError, match=r"no unit 7 in this world \(its units: 1, 2, X1\)"):
        apply_edits(UNITS, [Edit("drop", ("7",))], frame, path="w.json")
    with pytest.raises(SemmapError, match="named twice"):
        apply_edits(UNITS, [Edit("merge", ("1", "R1"))], frame)
    with pytest.raises(SemmapError, match=r"no unit 3 in this world \(its units: 1, 2, 10, abc, X1\)"):
        apply_edits(UNITS + [("10", at((0, 0, 30, 30))), ("abc", at((0, 40, 30, 90)))], [Edit("drop", ("3",))], frame)
    with pytest.raises(SemmapError, match="appears twice"):
        apply_edits(UNITS + [("2", (0, 0, 30, 30))], [Edit("drop", ("1",))], frame)


def test_edits_that_make_no_valid_unit_are_refused_naming_the_file_and_the_edit(frame):
    # a cut 0.3 m from the unit's edge leaves a piece below min_unit_side_m
    p, q = metres(frame, 46.0, 50.0), metres(frame, 46.0, 150.0)
    with pytest.raises(SemmapError) as err:
        apply_edits(UNITS, [Edit("cut", args("1", *p, *q))], frame, path="w.json")
    assert str(err.value).startswith("w.json: --cut 1 ") and "a unit's sides are at least 1.00 m" in str(err.value)
    p, q = metres(frame, 120.0, 50.0), metres(frame, 120.0, 150.0)       # the line misses unit 1
    with pytest.raises(SemmapError, match="does not cross unit 1"):
        apply_edits(UNITS, [Edit("cut", args("1", *p, *q))], frame)
    flat = build_frame_from_classes(np.zeros((300, 400), np.uint8), RES, load_model(), theta=0.0)
    with pytest.raises(SemmapError, match="beyond the map's lattice"):     # a band half off the image
        apply_edits([], [Edit("add", ("0.01", "0.5", "60", "70"))], flat, pixels=True)
    far = metres(frame, -600.0, 10.0)
    with pytest.raises(SemmapError, match=r"--wall 1 .*: the point .* lies outside the map \(900 x 800 pixels; "
                                          r"points are map-frame metres"):
        apply_edits(UNITS, [Edit("wall", args("1", *far))], frame)
    with pytest.raises(SemmapError, match="new unit would be"):
        apply_edits(UNITS, [Edit("add", args(*metres(frame, 20.0, 10.0), *metres(frame, 25.0, 90.0)))], frame)


_TEXT = st.one_of(st.sampled_from(["1", "R2", "x1", "X9", "7", "-3", "R", "nan", "1e400", ""]),
                  st.floats(allow_nan=True, allow_infinity=True).map(repr),
                  st.integers(-10**6, 10**6).map(str), st.text(max_size=6))
_ID = st.sampled_from(["1", "R1", "2", "C2", "X1", "x1"])
_PX = st.floats(250, 650).map(lambda v: f"{v:.2f}")      # image pixels over the test units
_JUNK = st.tuples(st.sampled_from(sorted(EDITS)), st.lists(_TEXT, max_size=6))
_WELL_FORMED = st.one_of(
    st.tuples(st.just("drop"), st.lists(_ID, min_size=1, max_size=2)),
    st.tuples(st.just("merge"), st.lists(_ID, min_size=2, max_size=3)),
    st.tuples(st.just("cut"), st.tuples(_ID, _PX, _PX, _PX, _PX).map(list)),
    st.tuples(st.just("wall"), st.tuples(_ID, _PX, _PX).map(list)),
    st.tuples(st.just("add"), st.tuples(_PX, _PX, _PX, _PX).map(list)))


@settings(max_examples=300, deadline=None, database=None, derandomize=True,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@pytest.mark.slow
@given(st.lists(st.one_of(_WELL_FORMED, _JUNK), min_size=1, max_size=4))
def test_any_edits_give_valid_units_or_one_semmap_error(frame, edits):
    """Whatever is typed (image points over the units, or anything): valid lattice rectangles of
    the model's sizes and unique ids, or a SemmapError naming the file and the edit; never another
    exception."""
    try:
        out = apply_edits(UNITS, [Edit(k, tuple(a)) for k, a in edits], frame, pixels=True, path="w.json")
    except SemmapError as exc:
        assert str(exc).startswith("w.json: --") and "\n" not in str(exc)
        return
    c = frame.cells
    for key, (r0, c0, r1, c1), _ in out:
        assert 0 <= r0 and 0 <= c0 and r1 <= frame.shape[0] and c1 <= frame.shape[1]
        assert c.min_side <= min(r1 - r0, c1 - c0) and max(r1 - r0, c1 - c0) <= c.max_side
    keys = [k for k, _, _ in out if k is not None]
    assert len(keys) == len(set(keys))
    # edit_origins names one edit per new unit, in apply_edits' order
    origins = edit_origins([Edit(k, tuple(a)) for k, a in edits])
    assert len(origins) == sum(k is None for k, _, _ in out)
    assert all(o.startswith(("--cut ", "--add ")) for o in origins)


def test_id_changes_follow_the_slots_into_the_new_numbering():
    edited = [("3", (0, 0, 9, 9), False), ("X1", (0, 9, 9, 18), False), (None, (9, 0, 18, 9), True),
              (None, (9, 9, 18, 18), True), ("7", (18, 0, 27, 9), True)]
    origins = ["--cut 5 a b c d", "--cut 5 a b c d"]
    slot_ids, exterior_ids = {0: 2, 2: 1, 3: 3, 4: 4}, {1: 1}
    letters = {0: "R", 2: "C", 3: "E", 4: "R"}
    assert id_changes(edited, origins, slot_ids, exterior_ids, letters) == [
        {"was": None, "now": "C1", "by": "--cut 5 a b c d"}, {"was": "3", "now": "R2", "by": None},
        {"was": None, "now": "E3", "by": "--cut 5 a b c d"}, {"was": "7", "now": "R4", "by": None},
        {"was": "X1", "now": "X1", "by": None}]
