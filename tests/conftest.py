"""Fixtures shared by the test modules, and the markers of the two folders.

tests/unit holds fast tests of one module or a few, without a whole-map run (``make test-fast``);
tests/integration the CLI and whole runs. Each test gets the marker of its folder (``-m unit``,
``-m integration``); the doctests of the package count as unit tests.
"""

from pathlib import Path

import pytest

from semmap_pp.cli import main

ROOT = Path(__file__).resolve().parents[1]
#: The bundled crop of the intel map, and run lengths that make a W* of it in seconds.
INTEL_CORNER = ROOT / "tests" / "data" / "maps" / "intel_corner.yaml"
FAST_RUN = ["--chains", "2", "--cores", "1", "--tune", "4", "--draws", "4", "--n-inner", "20",
            "--spread-draws", "0"]


def pytest_collection_modifyitems(config, items):
    unit, integration = ROOT / "tests" / "unit", ROOT / "tests" / "integration"
    for item in items:
        path = Path(item.path)
        if path.is_relative_to(integration):
            item.add_marker(pytest.mark.integration)
        elif path.is_relative_to(unit) or path.is_relative_to(ROOT / "semmap_pp"):
            item.add_marker(pytest.mark.unit)


@pytest.fixture(scope="session")
def intel_corner_run(tmp_path_factory) -> Path:
    """The folder of a short `semmap map` run on the intel corner, seed 3: one run per test process.
    Read it, or copy it before changing anything (every test of the process shares it)."""
    out = tmp_path_factory.mktemp("wstar") / "run"
    assert main(["map", str(INTEL_CORNER), "--out", str(out), "--seed", "3", *FAST_RUN]) == 0
    return out


@pytest.fixture(scope="session")
def intel_corner_wstar(intel_corner_run) -> Path:
    """world.json of :func:`intel_corner_run`."""
    return intel_corner_run / "world.json"
