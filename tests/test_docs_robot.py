"""docs/robot.md's Python block runs as written on a world.json the tests make, and finds the unit
that holds a point."""

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_the_robot_pages_python_block_runs(intel_corner_wstar, tmp_path):
    text = (ROOT / "docs" / "robot.md").read_text()
    (block,) = re.findall(r"```python\n(.*?)```", text, re.S)
    (tmp_path / "run1").mkdir()
    shutil.copy(intel_corner_wstar, tmp_path / "run1" / "world.json")
    (tmp_path / "snippet.py").write_text(block)
    run = subprocess.run([sys.executable, "snippet.py"], cwd=tmp_path, capture_output=True, text=True,
                         timeout=60, env={**os.environ, "PYTHONPATH": ""})
    assert run.returncode == 0, run.stderr
    assert re.fullmatch(r"unit 1: a (room|corridor|hall|other), [\d.]+ x [\d.]+ m, doors to \[[\d, ]*\]\n", run.stdout)


def test_unit_at_tells_inside_from_outside(intel_corner_wstar):
    import json

    text = (ROOT / "docs" / "robot.md").read_text()
    (block,) = re.findall(r"```python\n(.*?)```", text, re.S)
    scope = {}
    exec(block.split("with open(")[0], scope)            # the function alone
    from matplotlib.path import Path as Polygon

    world = json.loads(intel_corner_wstar.read_text())
    order = [u["id"] for u in world["units"]]
    for unit in world["units"]:
        x, y = unit["center_m"]
        found = scope["unit_at"](world, x, y)
        # the unit itself, or one listed before it whose rectangle also holds the point
        assert order.index(found["id"]) <= order.index(unit["id"])
        assert Polygon(found["vertices_m"]).contains_point((x, y), radius=1e-6) or found is unit
        x0, y0 = unit["vertices_m"][0]                       # just outside a corner, away from the centre
        out = (x0 + 2 * (x0 - x), y0 + 2 * (y0 - y))
        hit = scope["unit_at"](world, *out)
        assert hit is None or Polygon(hit["vertices_m"]).contains_point(out, radius=1e-6)
    assert scope["unit_at"](world, -1e6, -1e6) is None
