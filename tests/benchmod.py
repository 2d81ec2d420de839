"""``bench/bench_quality.py`` loaded as a module (``bench/`` is not a package), for the tests of its
helpers: ``from benchmod import bench_quality as bq``."""

import importlib.util
from pathlib import Path

_spec = importlib.util.spec_from_file_location(
    "bench_quality", Path(__file__).parents[1] / "bench" / "bench_quality.py")
bench_quality = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(bench_quality)
