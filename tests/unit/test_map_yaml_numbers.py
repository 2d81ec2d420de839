"""map_server YAML read as yaml-cpp reads it (issue 55's F17): numbers in scientific notation
without a dot or an exponent sign are numbers, and a key given twice is an error at its line."""

import shutil
from pathlib import Path

import pytest

from semmap_pp.errors import MapError
from semmap_pp.grid import load_map

ROOT = Path(__file__).resolve().parents[2]
INTEL = ROOT / "tests" / "data" / "maps" / "intel_corner.yaml"


def _yaml(tmp_path, text: str) -> Path:
    shutil.copy(INTEL.with_suffix(".png"), tmp_path / "m.png")
    p = tmp_path / "m.yaml"
    p.write_text(text)
    return p


@pytest.mark.parametrize("res, origin, want", [
    ("5e-2", "[1e1, 0, 0]", (0.05, (10.0, 0.0, 0.0))),
    ("5E-2", "[-2e+1, 3.5e0, 0]", (0.05, (-20.0, 3.5, 0.0))),
    ("0.05", "[.5e1, 0, 1e-3]", (0.05, (5.0, 0.0, 0.001))),
])
def test_numbers_in_scientific_notation_are_numbers(tmp_path, res, origin, want):
    g = load_map(_yaml(tmp_path, f"image: m.png\nresolution: {res}\norigin: {origin}\n"
                                 "negate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.196\n"))
    assert (g.resolution, tuple(g.origin)) == (pytest.approx(want[0]), pytest.approx(want[1]))


def test_a_key_given_twice_is_refused_at_its_line(tmp_path):
    p = _yaml(tmp_path, "image: m.png\nresolution: 0.05\norigin: [0, 0, 0]\nresolution: 0.1\n")
    with pytest.raises(MapError, match=r"m\.yaml:4:1: YAML syntax error: key 'resolution' is given twice"):
        load_map(p)


def test_words_that_only_look_like_numbers_stay_words(tmp_path):
    p = _yaml(tmp_path, "image: m.png\nresolution: 1e\norigin: [0, 0, 0]\n")
    with pytest.raises(MapError, match="resolution must be a number"):
        load_map(p)
