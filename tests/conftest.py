"""Fixtures shared by the test modules."""

from pathlib import Path

import pytest

from semmap_pp.cli import main

ROOT = Path(__file__).resolve().parents[1]
#: The bundled crop of the intel map, and run lengths that make a W* of it in seconds.
INTEL_CORNER = ROOT / "tests" / "data" / "maps" / "intel_corner.yaml"
FAST_RUN = ["--chains", "2", "--cores", "1", "--tune", "4", "--draws", "4", "--n-inner", "20",
            "--spread-draws", "0"]


@pytest.fixture(scope="module")
def intel_corner_wstar(tmp_path_factory) -> Path:
    """world.json of a short `semmap map` run on the intel corner, seed 3 (one run per module)."""
    out = tmp_path_factory.mktemp("wstar") / "run"
    assert main(["map", str(INTEL_CORNER), "--out", str(out), "--seed", "3", *FAST_RUN]) == 0
    return out / "world.json"
