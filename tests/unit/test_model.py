"""Tests of semmap_pp.model: the default file loads, broken files fail with file and key."""

import numpy as np
import pytest

from semmap_pp.errors import ModelError
from semmap_pp.model import DEFAULT_MODEL, load_model


def test_default_model_loads_and_converts_to_cells():
    m = load_model()
    assert m.path == DEFAULT_MODEL
    assert np.allclose(m.sensor.corridor.sum(axis=1), 1) and np.allclose(m.sensor.other.sum(axis=1), 1)
    assert m.sensor.table(True).shape == (3, 4)
    c = m.cells(0.05)
    assert (c.wall, c.object_max_extent, c.door_min, c.door_max) == (2, 30, 10, 50)
    assert c.min_side >= 2 * c.wall + 1


def edited(tmp_path, old, new):
    text = DEFAULT_MODEL.read_text()
    assert old in text
    p = tmp_path / "m.toml"
    p.write_text(text.replace(old, new, 1))
    return p


@pytest.mark.parametrize("old,new,key", [
    ("psi = 0.5", "psi = 1.5", "sensor.psi"),
    ("psi = 0.5", "", "sensor.psi: missing"),
    ("enclosure_min_share = 0.3", "enclosure_min_share = 1.3", "sensor.enclosure_min_share"),
    ("enclosure_cost = 0.0", "enclosure_cost = -1.0", "sensor.enclosure_cost"),
    ("exterior_max_share = 0.3", "exterior_max_share = 1.5", "world.exterior_max_share"),
    ("exterior_seen_min = 0.1", 'exterior_seen_min = "low"', "world.exterior_seen_min"),
    ("exterior_fan_seen_max = 0.7", "exterior_fan_seen_max = 1.5", "world.exterior_fan_seen_max"),
    ("exterior_outline_gap_m = 2.5", "exterior_outline_gap_m = -1.0", "world.exterior_outline_gap_m"),
    ("exterior_outline_gap_m = 2.5", 'exterior_outline_gap_m = "wide"', "world.exterior_outline_gap_m"),
    ("walls_inside_max = 0.5", "walls_inside_max = 1.5", "diagnostics.walls_inside_max"),
    ('muldoor_scope = "space"', 'muldoor_scope = "building"', "evidence.muldoor_scope"),
    ('muldoor_scope = "space"', "muldoor_scope = 1", "evidence.muldoor_scope"),
    ("wall = [0.07, 0.25, 0.68]", "wall = [0.07, 0.25, 0.78]", "sensor.corridor.wall: row must sum to 1"),
    ("wall = [0.07, 0.25, 0.68]", "wall = [1.07, -0.75, 0.68]", "probabilities must lie in [0, 1]"),
    ("k_max = 64", "k_max = 6.5", "prior.k_max: expected an integer"),
    ('size_measure = "short_side"', 'size_measure = "volume"', "evidence.size_measure"),
    ("wall_line_gap_m = 0.05", "wall_line_gap_m = -0.05", "world.wall_line_gap_m: must be > 0"),
    ("door_max_m = 2.5", "door_max_m = 0.1", "world.door_max_m"),
    ("unknown = [0.30, 0.60, 0.10]", "unknown = [0.40, 0.50, 0.10]", "must equal sensor.other.unknown"),
    # [kernels] is validated when the model is loaded, with the rest of the file
    ("local_radius = 3", "local_radius = 0", "[kernels]: local_radius must be >= 1"),
    ("box_prob = 0.5", "box_prob = 0.9", "[kernels]: box_prob + box_jitter_prob must be <= 1"),
    ("max_candidates = 2000", "max_candidates = 2000\nmystery = 1", "[kernels]: unknown key 'mystery'"),
    ("add_remove = 1.0", "add_remove = nan", "[kernels] weights must be finite numbers"),
])
def test_bad_values_name_file_and_key(tmp_path, old, new, key):
    p = edited(tmp_path, old, new)
    with pytest.raises(ModelError) as e:
        load_model(p)
    assert str(p) in str(e.value) and key in str(e.value)


def test_unreadable_and_invalid_toml(tmp_path):
    with pytest.raises(ModelError, match="cannot read"):
        load_model(tmp_path / "nope.toml")
    p = tmp_path / "bad.toml"
    p.write_text("[sensor\npsi = ")
    with pytest.raises(ModelError, match="not valid TOML"):
        load_model(p)


def without_lines(tmp_path, prefix, n=2):
    """The default model file with the lines starting with ``prefix`` (``n`` keys) left out."""
    text = DEFAULT_MODEL.read_text()
    kept = [line for line in text.splitlines() if not line.startswith(prefix)]
    assert len(kept) == len(text.splitlines()) - n
    p = tmp_path / "old.toml"
    p.write_text("\n".join(kept) + "\n")
    return load_model(p)


def test_model_files_without_the_enclosure_keys_load_with_the_term_off(tmp_path):
    m = without_lines(tmp_path, "enclosure_")
    assert m.sensor.enclosure_min_share == 0.0 and m.sensor.enclosure_cost == 0.0


def test_model_files_without_the_exterior_keys_load_with_the_test_off(tmp_path):
    old = without_lines(tmp_path, "exterior_", n=6).cells(0.05)
    assert old.exterior_max_share == 0.0 and old.exterior_fan_seen_max == 0.0
    assert old.exterior_outline_gap == 0                      # no outline: the hull rules alone
    assert old.exterior_outline_walls_max == 0.0              # and no fan flagged by it alone
    assert old.exterior_outline_trust_min == 0.0              # nor by it where the hull holds it
    now = load_model().cells(0.05)
    assert now.exterior_max_share == 0.3 and now.exterior_fan_seen_max == 0.7
    assert now.exterior_outline_gap == 50                     # 2.5 m
    assert now.exterior_outline_walls_max == 0.5
    assert now.exterior_outline_trust_min == 0.8


def test_model_files_without_walls_inside_max_get_the_default(tmp_path):
    text = DEFAULT_MODEL.read_text()
    kept = [line for line in text.splitlines() if not line.startswith("walls_inside_max")]
    assert len(kept) == len(text.splitlines()) - 1
    p = tmp_path / "old.toml"
    p.write_text("\n".join(kept) + "\n")
    assert load_model(p).diagnostics.walls_inside_max == 0.5
    p.write_text("\n".join(kept).replace("defect_tolerance_m = 1.0", "defect_tolerance_m = 1.0\nwalls_inside_max = 1.0"))
    assert load_model(p).diagnostics.walls_inside_max == 1.0


def test_model_files_without_muldoor_scope_count_each_units_own_doors(tmp_path):
    assert without_lines(tmp_path, "muldoor_scope", n=1).evidence.muldoor_scope == "unit"
    assert load_model().evidence.muldoor_scope == "space"


def test_model_files_without_the_outside_table_keep_the_map_as_it_is(tmp_path):
    m = without_lines(tmp_path, ("[outside]", "mode =", "border_open_min", "seal_gap_m"), n=4)
    assert m.outside.mode == "keep"
    assert load_model().outside.mode == "auto"


def test_model_files_without_colike_scope_take_each_units_own_class(tmp_path):
    m = without_lines(tmp_path, ("colike_scope", "space_width_ratio"), n=2)
    assert (m.evidence.colike_scope, m.evidence.space_width_ratio) == ("unit", 2.0)
    assert load_model().evidence.colike_scope == "space"


@pytest.mark.parametrize("line, message", [
    ('mode = "sometimes"', "outside.mode: must be one of auto, unknown, keep, got 'sometimes'"),
    ("border_open_min = 1.5", "outside.border_open_min: must be <= 1.0, got 1.5"),
    ("seal_gap_m = 0", "outside.seal_gap_m: must be > 0, got 0.0"),
    ('colike_scope = "corridor"', "evidence.colike_scope: must be one of unit, space, got 'corridor'"),
    ("space_width_ratio = 0.5", "evidence.space_width_ratio: must be >= 1.0, got 0.5"),
    ("wall_min_cells = 0", "world.wall_min_cells: must be >= 1, got 0"),
    ("door_speck_m2 = -0.1", "world.door_speck_m2: must be >= 0.0, got -0.1"),
    ("door_speck_m2 = 2", "world.door_speck_m2: must be <= 1.0, got 2.0"),
    ("passage_gap_m = -1", "world.passage_gap_m: must be >= 0.0, got -1.0"),
    ("spread_draws = 3", "sampler.spread_draws: must be 0 (no sample around W*) or at least 4 (R-hat and "
                         "ESS need them)"),
    ("spread_draws = -1", "sampler.spread_draws: must be >= 0, got -1"),
    ("spread_draws = 100001", "sampler.spread_draws: must be <= 100000, got 100001"),
    ("spread_n_inner = 0", "sampler.spread_n_inner: must be >= 1, got 0"),
    ("off_axis_block_m = 0", "lattice.off_axis_block_m: must be > 0, got 0.0"),
    ("off_axis_min_deg = 50", "lattice.off_axis_min_deg: must be <= 45.0, got 50.0"),
    ("off_axis_min_gain = 0.5", "lattice.off_axis_min_gain: must be >= 1.0, got 0.5"),
    ('off_axis_note_share = "some"', "lattice.off_axis_note_share: expected a number, got str"),
    ("zone_min_share = 1.5", "lattice.zone_min_share: must be <= 1.0, got 1.5"),
    ("zone_wall_scale_m = 0", "lattice.zone_wall_scale_m: must be > 0, got 0.0"),
    ("zone_min_coherence = -0.1", "lattice.zone_min_coherence: must be >= 0.0, got -0.1"),
    ("zone_door_m = 0", "lattice.zone_door_m: must be > 0, got 0.0"),
    ("zone_min_votes_m = -1", "lattice.zone_min_votes_m: must be >= 0.0, got -1.0"),
    ("zone_split_share = 2", "lattice.zone_split_share: must be <= 1.0, got 2.0"),
])
def test_a_bad_value_of_an_optional_key_is_one_line_naming_file_and_key(tmp_path, line, message):
    """The default model with one line replaced ([outside], [evidence] colike keys)."""
    key = line.split(" =")[0] + " ="
    text = "\n".join(line if ln.startswith(key) else ln for ln in DEFAULT_MODEL.read_text().splitlines())
    p = tmp_path / "bad.toml"
    p.write_text(text + "\n")
    with pytest.raises(ModelError) as info:
        load_model(p)
    assert str(info.value) == f"{p}: {message}"


def test_model_files_without_the_spread_keys_have_no_sample_around_wstar(tmp_path):
    m = without_lines(tmp_path, ("spread_draws", "spread_n_inner"), n=2)
    assert (m.sampler.spread_draws, m.sampler.spread_n_inner) == (0, 20)
    assert (load_model().sampler.spread_draws, load_model().sampler.spread_n_inner) == (1000, 20)


def test_model_files_without_the_off_axis_keys_get_no_note_about_walls_at_another_angle(tmp_path):
    keys = ("off_axis_block_m", "off_axis_min_deg", "off_axis_min_gain", "off_axis_note_share")
    m = without_lines(tmp_path, keys, n=4)
    assert [getattr(m.lattice, k) for k in keys] == [8.0, 5.0, 1.5, 0.0]
    assert load_model().lattice.off_axis_note_share == 0.1


def test_model_files_without_the_zone_keys_keep_one_zone(tmp_path):
    keys = ("zone_min_share", "zone_wall_scale_m", "zone_min_coherence", "zone_door_m", "zone_min_votes_m",
            "zone_split_share")
    m = without_lines(tmp_path, keys, n=6)
    assert [getattr(m.lattice, k) for k in keys] == [0.0, 0.25, 0.5, 1.0, 1.0, 0.25]
    assert [getattr(load_model().lattice, k) for k in keys] == [0.07, 0.25, 0.5, 1.0, 1.0, 0.25]


def test_door_specks_are_an_area_of_at_least_one_cell(tmp_path):
    """0.005 m^2 is two cells at 0.05 m, eight at 0.025 m and (at least) one at 0.1 m; model
    files written before the key keep one-cell specks."""
    m = load_model()
    assert [m.cells(r).door_speck for r in (0.025, 0.05, 0.1)] == [8, 2, 1]
    old = without_lines(tmp_path, "door_speck_m2", n=1)
    assert [old.cells(r).door_speck for r in (0.025, 0.05, 0.1)] == [1, 1, 1]


def test_passages_across_free_floor_reach_passage_gap_m(tmp_path):
    """1.0 m is 20 cells at 0.05 m; model files written before the key find none (0)."""
    assert [load_model().cells(r).passage_gap for r in (0.025, 0.05, 0.1)] == [40, 20, 10]
    assert without_lines(tmp_path, "passage_gap_m", n=1).cells(0.05).passage_gap == 0


def test_the_wall_band_is_at_least_wall_min_cells_thick(tmp_path):
    """0.10 m is two cells at 0.05 m and one at 0.1 m; wall_min_cells = 2 keeps two there, and
    model files written before the key keep the one-cell minimum."""
    m = load_model()
    assert [m.cells(r).wall for r in (0.025, 0.05, 0.1, 0.2)] == [4, 2, 2, 2]
    assert m.cells(0.2).min_side >= 2 * 2 + 1
    old = without_lines(tmp_path, "wall_min_cells", n=1)
    assert [old.cells(r).wall for r in (0.025, 0.05, 0.1, 0.2)] == [4, 2, 1, 1]
