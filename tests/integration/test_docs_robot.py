"""docs/robot.md's Python blocks run as written on a world.json the tests make: one names the unit
that holds a point and a route from there, one turns a route into the poses of a Nav2 goal; the block
that needs a ROS 2 installation is compiled."""

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


#: Modules of a ROS 2 installation: a block that imports one is compiled, not run.
ROS_MODULES = ("rclpy", "geometry_msgs", "nav2_simple_commander")


def python_blocks() -> list[str]:
    return re.findall(r"```python\n(.*?)```", (ROOT / "docs" / "robot.md").read_text(), re.S)


def run_block(block: str, world_json, tmp_path) -> list[str]:
    """Run ``block`` in a folder holding ``run1/world.json``; its stdout lines."""
    (tmp_path / "run1").mkdir(exist_ok=True)
    shutil.copy(world_json, tmp_path / "run1" / "world.json")
    (tmp_path / "snippet.py").write_text(block)
    run = subprocess.run([sys.executable, "snippet.py"], cwd=tmp_path, capture_output=True, text=True,
                         timeout=60, env={**os.environ, "PYTHONPATH": ""})
    assert run.returncode == 0, run.stderr
    return run.stdout.splitlines()


def test_the_robot_pages_python_blocks_compile_and_only_the_nav2_one_needs_ros():
    blocks = python_blocks()
    for block in blocks:
        compile(block, "robot.md", "exec")
    needs_ros = [any(re.search(rf"^(from|import) {m}\b", b, re.M) for m in ROS_MODULES) for b in blocks]
    assert needs_ros == [False, False, True]


def test_the_robot_pages_python_block_runs(intel_corner_wstar, tmp_path):
    lines = run_block(python_blocks()[0], intel_corner_wstar, tmp_path)
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


def test_the_robot_pages_planner_block_runs(intel_corner_wstar, tmp_path):
    """The block that turns a route into the poses of a Nav2 goal, in world.json's map frame."""
    (line,) = run_block(python_blocks()[1], intel_corner_wstar, tmp_path)
    assert re.fullmatch(r"\d+ poses in frame 'map' to [RCHE]\d+ \((room|corridor|hall|other)\), [\d.]+ m"
                        r"|no door or passage leads to [RCHE]\d+", line), line
