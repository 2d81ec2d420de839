"""semmap_pp.plans.diff and `semmap diff`: units paired by place (not id) between two world.json
files, on the literal floor (tests/literal_floor.py: A | B a door, B : C open, A / D a closed wall)
edited in known ways, against its own mirror image, and on broken input."""

import copy
import json

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from semmap_pp.cli import main
from semmap_pp.model import load_model
from semmap_pp.semantic.world_json import dumps, world_dict
from semmap_pp.plans.places import places_from_doc
from semmap_pp.plans.diff import TOLERANCE_M, diff_worlds

from literal_floor import literal_floor


@pytest.fixture(scope="module")
def floor_doc():
    return world_dict(literal_floor(load_model()))


def write(tmp_path, name, doc):
    path = tmp_path / name
    path.write_text(dumps(doc))
    return path


def unit(doc, uid):
    return next(u for u in doc["units"] if u["id"] == uid)


def shift(u, dx, dy=0.0, corners=(0, 1, 2, 3)):
    """Move some corners of a unit (all: the unit moves; two on one side: it grows)."""
    for k in corners:
        u["vertices_m"][k] = [u["vertices_m"][k][0] + dx, u["vertices_m"][k][1] + dy]
    v = np.array(u["vertices_m"])
    u["center_m"] = v.mean(axis=0).tolist()


def renumber(doc, mapping):
    """The same plan with other unit ids (as a run without --ids-from numbers them)."""
    out = copy.deepcopy(doc)
    for u in out["units"]:
        u["id"] = mapping[u["id"]]
    for o in out["doors"] + out["passages"]:
        o["units"] = sorted(mapping[k] for k in o["units"])
    return out


def test_a_file_against_itself_and_against_its_renumbering_is_the_same_plan(floor_doc, tmp_path, capsys):
    a = write(tmp_path, "a.json", floor_doc)
    b = write(tmp_path, "b.json", renumber(floor_doc, {1: 4, 2: 3, 3: 2, 4: 1}))
    for other in (a, b):
        assert main(["diff", str(a), str(other)]) == 0
        out = capsys.readouterr().out
        assert "4 paired (unit F1 1.000): 4 unchanged, 0 moved, 0 retyped; 0 removed, 0 added" in out
        assert "doors: 1 -> 1, passages: 1 -> 1; 2 paired (0 changed kind)" in out
        assert out.rstrip().endswith(f"the same plan (every unit paired, unchanged within {TOLERANCE_M:g} m)")
    d = diff_worlds(places_from_doc(floor_doc), places_from_doc(renumber(floor_doc, {1: 4, 2: 3, 3: 2, 4: 1})))
    assert [(p.old.key, p.new.key) for p in d.pairs] == [("1", "4"), ("2", "3"), ("3", "2"), ("4", "1")]
    assert all(p.iou == pytest.approx(1.0) and p.shift_m == pytest.approx(0.0) for p in d.pairs)


def test_each_kind_of_change_is_listed(floor_doc, tmp_path, capsys):
    new = copy.deepcopy(floor_doc)
    unit(new, 1)["type"] = "other"                       # retyped
    shift(unit(new, 3), 0.3, corners=(1, 2))             # C grows 0.3 m east: moved
    new["units"] = [u for u in new["units"] if u["id"] != 4]       # D removed (no opening of its own)
    new["units"].append({**copy.deepcopy(unit(floor_doc, 4)), "id": 9, "type": "corridor"})
    shift(new["units"][-1], 0.0, -10.0)                 # a unit 10 m south: added
    new["passages"], new["doors"] = [], [dict(floor_doc["passages"][0], id=2)] + new["doors"]   # B:C a door now
    new["doors"] = [d for d in new["doors"] if d["units"] != [1, 2]]                               # A|B gone
    a, b = write(tmp_path, "a.json", floor_doc), write(tmp_path, "b.json", new)
    assert main(["diff", str(a), str(b)]) == 1
    out = capsys.readouterr().out.splitlines()
    assert out[1] == "units: 4 -> 4; 3 paired (unit F1 0.750): 1 unchanged, 1 moved, 1 retyped; 1 removed, 1 added"
    assert out[2] == "doors: 1 -> 1, passages: 1 -> 0; 1 paired (1 changed kind), 1 removed, 0 added"
    body = "\n".join(out[3:])
    assert "retyped         R1 -> E1        room -> other" in body
    assert "moved           R3 -> R3        3.30 x 2.60 -> 3.30 x 2.90 m, corners up to 0.30 m" in body
    assert "removed         R4              room, 2.60 x 2.10 m" in body
    assert "added           C9              corridor, 2.60 x 2.10 m" in body
    assert "changed         passage 1 -> door 2" in body and "R2 - R3" in body
    assert "removed         door 1          R1 - R2, 1.00 m wide" in body
    assert "the same plan" not in body
    assert main(["diff", str(a), str(b), "--json"]) == 1
    d = json.loads(capsys.readouterr().out)
    assert d["same"] is False and d["counts"]["moved"] == 1 and d["counts"]["openings_changed"] == 1
    moved = next(p for p in d["units"] if p["moved"])
    assert moved["old"]["label"] == "R3" and moved["shift_m"] == pytest.approx(0.3)
    assert [u["label"] for u in d["removed"]] == ["R4"] and [u["label"] for u in d["added"]] == ["C9"]
    assert d["openings_removed"][0]["units"] == ["R1", "R2"]
    # within the tolerance the grown unit is unchanged; --all lists the unchanged pairs too
    assert main(["diff", str(a), str(b), "--tolerance", "0.35", "--all"]) == 1
    body = capsys.readouterr().out
    assert "0 moved" in body and "unchanged       R2 -> R2        room, 3.30 x 2.60 m" in body


def test_units_pair_by_place_in_metres_whatever_the_map(floor_doc):
    grown = copy.deepcopy(floor_doc)          # the map grew: another size and origin, the same frame
    grown["map"] = dict(grown["map"], width=4000, height=4000, origin=[-100.0, -100.0, 0.0])
    assert diff_worlds(places_from_doc(floor_doc), places_from_doc(grown)).same
    moved = copy.deepcopy(floor_doc)
    for u in moved["units"]:
        shift(u, 1.5)                            # every unit 1.5 m east: IoU 0.27, no pair
    d = diff_worlds(places_from_doc(floor_doc), places_from_doc(moved))
    assert not d.pairs and len(d.removed) == len(d.added) == 4 and d.unit_f1 == 0.0
    assert len(d.openings_removed) == len(d.openings_added) == 2
    assert d.text().endswith("are both of the same building, in the same map frame?")


@settings(max_examples=60, deadline=None)
@given(st.data())
def test_the_diff_of_new_against_old_mirrors_old_against_new(floor_doc, data):
    """Random edits of the floor: dropped units, units moved by up to 0.35 m along each axis (IoU
    stays >= 0.5), retyped, renumbered. Reversing the files swaps removed and added and keeps every pair, its IoU
    and shift; an untouched unit is paired unchanged; a moved one is moved exactly when it moved
    farther than the tolerance."""
    new = copy.deepcopy(floor_doc)
    keep = data.draw(st.lists(st.booleans(), min_size=4, max_size=4))
    moves = {}
    for u, k in zip(list(new["units"]), keep):
        if not k:
            new["units"].remove(u)
            continue
        dx, dy = data.draw(st.floats(-0.35, 0.35)), data.draw(st.floats(-0.35, 0.35))
        if data.draw(st.booleans()):
            shift(u, dx, dy)
            moves[u["id"]] = float(np.hypot(dx, dy))
        if data.draw(st.booleans()):
            u["type"] = data.draw(st.sampled_from(["room", "corridor", "hall", "other"]))
    ids = {u["id"] for u in new["units"]}
    new["doors"] = [o for o in new["doors"] if set(o["units"]) <= ids]
    new["passages"] = [o for o in new["passages"] if set(o["units"]) <= ids]
    perm = dict(zip(sorted(ids), data.draw(st.permutations(sorted(ids)))))
    new = renumber(new, perm)
    old_p, new_p = places_from_doc(floor_doc), places_from_doc(new)
    fwd, back = diff_worlds(old_p, new_p), diff_worlds(new_p, old_p)
    assert {(p.old.key, p.new.key) for p in fwd.pairs} == {(p.new.key, p.old.key) for p in back.pairs}
    assert [u.key for u in fwd.removed] == [u.key for u in back.added]
    assert [u.key for u in fwd.added] == [u.key for u in back.removed]
    for p in fwd.pairs:
        q = next(q for q in back.pairs if q.old.key == p.new.key)
        assert p.iou == pytest.approx(q.iou) and p.shift_m == pytest.approx(q.shift_m)
        assert perm[int(p.old.key)] == int(p.new.key)                  # each unit found again
        s = moves.get(int(p.old.key), 0.0)
        assert p.shift_m == pytest.approx(s, abs=1e-3)
        if abs(s - TOLERANCE_M) > 1e-3:
            assert fwd.moved(p) == (s > TOLERANCE_M)
    assert len(fwd.pairs) == sum(keep) and fwd.same == back.same
    assert fwd.counts()["units"] == back.counts()["units"][::-1]


def test_broken_input_is_one_line_and_exit_2(floor_doc, tmp_path, capsys):
    a = write(tmp_path, "a.json", floor_doc)
    bad = tmp_path / "bad.json"
    bad.write_text("{not json")
    assert main(["diff", str(a), str(bad)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("semmap: error:") and "bad.json" in err and "\n" not in err
    assert main(["diff", str(a), str(tmp_path / "missing.json")]) == 2
    assert "missing.json" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exc:
        main(["diff", str(a), str(a), "--tolerance", "-1"])
    assert exc.value.code == 2
    with pytest.raises(ValueError):
        diff_worlds(places_from_doc(floor_doc), places_from_doc(floor_doc), tolerance_m=float("nan"))


def test_the_figure_draws_each_kind_of_change_in_its_colour(floor_doc, tmp_path, capsys):
    from PIL import Image

    from semmap_pp.outputs.figures import DIFF_COLOUR

    new = copy.deepcopy(floor_doc)
    shift(unit(new, 3), 0.3, corners=(1, 2))                              # moved: orange
    new["units"] = [u for u in new["units"] if u["id"] != 4]            # removed: red
    a, b = write(tmp_path, "a.json", floor_doc), write(tmp_path, "b.json", new)
    fig = tmp_path / "diff.png"
    assert main(["diff", str(a), str(b), "--png", str(fig)]) == 1
    assert capsys.readouterr().out.rstrip().endswith(str(fig))
    rgb = np.asarray(Image.open(fig).convert("RGB")).reshape(-1, 3)

    def count(name):
        c = np.array([int(DIFF_COLOUR[name][i:i + 2], 16) for i in (1, 3, 5)])
        return int(np.count_nonzero(np.abs(rgb.astype(int) - c).sum(axis=1) < 30))

    assert count("moved") > 100 and count("removed") > 100 and count("unchanged") > 100
    assert count("retyped") < 50                               # only its legend entry
    same = tmp_path / "same.png"
    assert main(["diff", str(a), str(a), "--png", str(same)]) == 0 and same.is_file()
    capsys.readouterr()
    assert main(["diff", str(a), str(b), "--png", str(a / "d.png")]) == 2      # under a file
    out, err = capsys.readouterr()
    assert err.strip().startswith("semmap: error:") and "d.png" in err and "\n" not in err.strip()
    assert out == ""                                           # nothing printed before the error
