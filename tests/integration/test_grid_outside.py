"""The free space around a building, in maps that show it, read as unknown (semmap_pp.grid.outside)."""

import numpy as np
import pytest

from semmap_pp.cells import FREE, OCCUPIED, UNKNOWN
from semmap_pp.grid import OccupancyGrid, load_map
from semmap_pp.grid.outside import border_open_share, clear_outside, outside_free
from semmap_pp.grid.write import save_grid
from semmap_pp.model import DEFAULT_MODEL, OutsideParams


def building(gap=0, sea=FREE):
    """Two 3 x 3 m rooms (0.1 m walls at 0.05 m a cell), a door between them, in a sea of ``sea``
    cells 1 m wide; ``gap`` free cells cut into the left room's outer wall."""
    c = np.full((100, 160), sea, np.uint8)
    c[20:80, 20:140] = OCCUPIED
    c[22:78, 22:78] = FREE
    c[22:78, 80:138] = FREE
    c[24:39, 78:80] = FREE                    # a 0.75 m door near a corner, between the rooms
    if gap:
        c[78:80, 30:30 + gap] = FREE          # an opening in the outer wall
    return c


def grid_of(c):
    return OccupancyGrid(classes=c, occupancy=np.zeros(c.shape, np.float32), resolution=0.05)


def test_the_sea_is_cleared_up_to_the_outer_walls_and_the_rooms_are_kept():
    c = building()
    out = outside_free(c, 15)
    sea = np.ones(c.shape, bool)
    sea[20:80, 20:140] = False
    assert np.array_equal(out, sea)            # every free cell outside, none inside


def test_a_gap_narrower_than_the_seal_keeps_the_sea_out_and_a_wider_one_lets_it_in():
    narrow = outside_free(building(gap=20), 15)        # 1.0 m < 1.55 m: sealed
    assert not narrow[22:78, 22:138].any()             # the room's core is nearer its doorway
    assert np.array_equal(narrow[:20], np.ones((20, 160), bool))
    wide = outside_free(building(gap=36), 15)          # 1.8 m: the documented limit
    assert wide[22:78, 22:78].any()
    assert not wide[22:78, 80:138].any()                # the room behind the inner door stays


def test_a_map_without_a_free_border_is_left_alone():
    c = building(sea=UNKNOWN)
    assert border_open_share(c, 15) == 0.0
    assert not outside_free(c, 15).any()
    g = grid_of(c)
    assert clear_outside(g, OutsideParams(mode="auto"))[0] is g


@pytest.mark.parametrize("mode, cleared", [("auto", True), ("unknown", True), ("keep", False)])
def test_modes(mode, cleared):
    g = grid_of(building())
    g2, note = clear_outside(g, OutsideParams(mode=mode))
    if not cleared:
        assert g2 is g and note is None
        return
    assert (g2.classes[:20] == UNKNOWN).all() and (g2.classes[20:80, 20:140] == g.classes[20:80, 20:140]).all()
    assert (g2.classes == OCCUPIED).sum() == (g.classes == OCCUPIED).sum()
    assert note in g2.notes and "read as unknown" in note and 'mode = "keep"' in note
    assert ("border cells are open free space" in note) == (mode == "auto")
    assert not g.classes.flags.writeable and not g2.classes.flags.writeable


def test_auto_needs_open_space_along_the_border():
    g = grid_of(building())
    assert border_open_share(g.classes, 15) == 1.0
    assert clear_outside(g, OutsideParams(mode="auto", border_open_min=1.0))[1] is not None
    c = building()
    c[:, :3] = UNKNOWN                              # the left side unknown: 80 % of the border open
    assert border_open_share(c, 15) == pytest.approx(1 - 104 / 516)
    assert clear_outside(grid_of(c), OutsideParams(mode="auto", border_open_min=0.8))[1] is None
    assert clear_outside(grid_of(c), OutsideParams(mode="auto", border_open_min=0.75))[1] is not None


def test_a_map_cropped_through_its_rooms_is_not_a_building_in_open_space():
    """The bundled crop of intel's corner: 26 % of its border cells are free (its rooms and
    corridors run off the image) but few are farther than 0.75 m from a wall; auto keeps it."""
    from pathlib import Path

    g = load_map(Path(__file__).parents[1] / "data" / "maps" / "intel_corner.yaml")
    border = np.concatenate([g.classes[0], g.classes[-1], g.classes[1:-1, 0], g.classes[1:-1, -1]])
    assert (border == FREE).mean() > 0.25
    assert border_open_share(g.classes, 15) < 0.05
    assert clear_outside(g, OutsideParams(mode="auto"))[0] is g


def _validate(doc):
    import json
    from pathlib import Path

    import jsonschema

    schema = json.loads((Path(__file__).parents[2] / "docs" / "world.schema.json").read_text())
    jsonschema.validate(doc, schema)


def test_semmap_map_explains_the_rooms_not_the_sea(tmp_path):
    """End to end: the map file as a renderer that marks every crossed cell free writes it; the
    run reads the sea as unknown, says so, and W* holds the two rooms, not one unit over all."""
    from semmap_pp.run.inputs import load_inputs
    from semmap_pp.run.pipeline import run_map
    from semmap_pp.run.results import RunSettings
    from semmap_pp import world as wm

    path = save_grid(grid_of(building()), tmp_path / "sea.yaml")
    inputs = load_inputs(path)
    assert len(inputs.notes) == 1 and "read as unknown" in inputs.notes[0]
    assert not inputs.roi[:10].any()                # the default ROI no longer holds the sea
    run = run_map(inputs, RunSettings.from_model(inputs.model, seed=1, chains=1, cores=1, tune=5,
                                                 draws=5), log=lambda m: None)
    assert run.notes[0] == inputs.notes[0]
    from semmap_pp.semantic.world_json import world_dict
    doc = world_dict(run.semantic)
    assert doc["map"]["notes"] == [inputs.notes[0]]        # programs reading world.json see it too
    _validate(doc)
    rects = sorted(tuple(int(v) for v in run.world.rects[s]) for s in wm.active_slots(run.world))
    assert len(rects) == 2 and run.semantic.cpr > 0.9
    assert load_map(path).classes[0, 0] == FREE     # the file itself is untouched
    # the same map with the sea kept: units over the sea besides the rooms (exterior strips)
    keep = tmp_path / "keep.toml"
    keep.write_text(DEFAULT_MODEL.read_text().replace('mode = "auto"', 'mode = "keep"'))
    kept = load_inputs(path, model_path=keep)
    assert kept.notes == () and kept.grid.classes[0, 0] == FREE
    run = run_map(kept, RunSettings.from_model(kept.model, seed=1, chains=1, cores=1, tune=5,
                                               draws=5), log=lambda m: None)
    assert wm.n_units(run.world) > 2


@pytest.mark.parametrize("seal_gap_m", [1e-9, 1e308])
def test_extreme_seal_gaps_are_harmless(seal_gap_m):
    """A seal gap under a cell is one cell; one beyond any map leaves nothing open to clear."""
    g = grid_of(building())
    g2, note = clear_outside(g, OutsideParams(mode="unknown", seal_gap_m=seal_gap_m))
    if seal_gap_m > 1:
        assert g2 is g and note is None
    else:
        assert (g2.classes[:18] == UNKNOWN).all() and note is not None
