"""``bench/bench_quality.py`` loaded as a module (``bench/`` is not a package), for the tests of its
helpers: ``from benchmod import bench_quality as bq``; another module of ``bench/`` by
:func:`load`."""

import importlib.util
import sys
from pathlib import Path

BENCH = Path(__file__).parents[1] / "bench"
if str(BENCH) not in sys.path:     # as bench/run.py runs them: their imports of each other
    sys.path.append(str(BENCH))


def load(name: str):
    """``bench/NAME.py`` loaded as a module."""
    spec = importlib.util.spec_from_file_location(name, BENCH / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


bench_quality = load("bench_quality")
