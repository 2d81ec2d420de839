"""docs/robot.md's Python block runs as written on a world.json the tests make: it names the unit
that holds a point and a route from there."""

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
    lines = run.stdout.splitlines()
    assert re.fullmatch(r"[RCHE]1: a (room|corridor|hall|other), [\d.]+ x [\d.]+ m, openings to \[[\d, ]*\]",
                        lines[0])
    assert len(lines) == 1 or re.fullmatch(r"[\d.]+ m through units \['1'(, '\d+')*\], waypoints \d+", lines[1])


def test_the_robot_pages_commands_run(intel_corner_wstar, capsys):
    """The page's `semmap where` and `semmap route` lines, with its point 12.5 4.2 moved to the
    centre of the test world's unit 1 (the page's map is not the test's)."""
    import json

    from semmap_pp.cli import main

    text = (ROOT / "docs" / "robot.md").read_text()
    x, y = json.loads(intel_corner_wstar.read_text())["units"][0]["center_m"]
    lines = re.findall(r"^semmap (where|route) run1 (.*?)\s+#", text, re.M)
    assert [kind for kind, _ in lines] == ["where", "route"]
    for kind, args in lines:
        args = args.replace("12.5", str(x)).replace("4.2", str(y))
        assert main([kind, str(intel_corner_wstar.parent), *args.split()]) in (0, 1)
        out = capsys.readouterr()
        assert "error" not in out.err and out.out
