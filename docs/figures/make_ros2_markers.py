"""The markers of a run's rosbag2/ drawn as RViz 2 places them (docs/figures/ros2_markers.png).

No RViz is at hand where the docs are made, so this draws the bag's own messages with matplotlib:
it records the intel lab map as a robot's ROS 2 bag would hold it (``/map``, a
``nav_msgs/msg/OccupancyGrid``, MCAP storage), runs ``semmap map`` on that bag, reads the output
``rosbag2/`` back with rosbags and draws, on RViz's dark background, the ``/semantic_map/types`` grid
(its codes in faint type colours), then every marker of ``/semantic_map/units`` (left) and
``/semantic_map/graph`` (right) at its pose and points, in its colour, its line width and text
height converted from metres. What the picture shows is what the bag holds, marker by marker.

Run: ``.venv/bin/python docs/figures/make_ros2_markers.py [RUN_DIR]`` (a finished run's folder to
draw instead of making one; about a minute otherwise).
"""

from __future__ import annotations

import math
import sys
import tempfile
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from rosbags.rosbag2 import Reader, StoragePlugin, Writer  # noqa: E402
from rosbags.typesys import Stores, get_typestore  # noqa: E402

from semmap_pp.atomic import atomic_path  # noqa: E402
from semmap_pp.cli import main  # noqa: E402
from semmap_pp.grid import load_map, ros_values  # noqa: E402

MAP = ROOT / "data" / "maps" / "intel-lab.yaml"
OUT = ROOT / "docs" / "figures" / "ros2_markers.png"
TS = get_typestore(Stores.ROS2_JAZZY)
GRID = "nav_msgs/msg/OccupancyGrid"
BACKGROUND = "#303030"            # RViz 2's default background
CODE_RGB = {0: (0.19, 0.19, 0.19), 1: (0.45, 0.39, 0.16), 2: (0.18, 0.3, 0.45), 3: (0.45, 0.29, 0.16),
            4: (0.33, 0.33, 0.33), 5: (0.1, 0.4, 0.4)}
DPI = 100


def record_bag(path: Path) -> Path:
    """The map as slam_toolbox would have published it on /map: int8 cells, rows from the origin."""
    g = load_map(MAP)
    values = ros_values(g.occupancy, mode=g.mode, occupied_thresh=g.occupied_thresh,
                        free_thresh=g.free_thresh)[::-1].ravel()
    t = TS.types
    stamp = t["builtin_interfaces/msg/Time"](sec=1_700_000_000, nanosec=0)
    pose = t["geometry_msgs/msg/Pose"](position=t["geometry_msgs/msg/Point"](x=g.origin[0], y=g.origin[1], z=0.0),
                                       orientation=t["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0))
    msg = t[GRID](header=t["std_msgs/msg/Header"](stamp=stamp, frame_id="map"),
                  info=t["nav_msgs/msg/MapMetaData"](map_load_time=stamp, resolution=g.resolution,
                                                     width=g.width, height=g.height, origin=pose),
                  data=values.astype(np.int8))
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as w:
        conn = w.add_connection("/map", GRID, typestore=TS)
        w.write(conn, 1_700_000_000 * 10**9, TS.serialize_cdr(msg, GRID))
    return path


def read_messages(bag: Path) -> dict:
    with Reader(bag) as r:
        return {c.topic: TS.deserialize_cdr(raw, c.msgtype) for c, _, raw in r.messages()}


def draw_grid(ax, grid) -> None:
    info = grid.info
    h, w = info.height, info.width
    codes = np.asarray(grid.data, np.int8).reshape(h, w)          # row 0 at the origin
    rgb = np.array([CODE_RGB[int(c)] for c in range(6)])[np.clip(codes, 0, 5)]
    x0, y0 = info.origin.position.x, info.origin.position.y        # yaw 0 for this map
    ax.imshow(rgb, origin="lower", extent=(x0, x0 + w * info.resolution, y0, y0 + h * info.resolution),
              interpolation="nearest", zorder=0)


def points_per_metre(ax) -> float:
    (x0, _), (x1, _) = ax.transData.transform([(0, 0), (1, 0)])
    return (x1 - x0) * 72.0 / DPI


def draw_markers(ax, markers) -> None:
    ppm = points_per_metre(ax)
    for mk in markers:
        if mk.action == 3:                         # DELETEALL: nothing to draw
            continue
        colour = (mk.color.r, mk.color.g, mk.color.b, mk.color.a)
        pts = np.array([(p.x, p.y) for p in mk.points]) if len(mk.points) else np.zeros((0, 2))
        if mk.type == 4:                           # LINE_STRIP
            ax.plot(pts[:, 0], pts[:, 1], color=colour, lw=mk.scale.x * ppm, solid_capstyle="butt", zorder=2)
        elif mk.type == 5:                         # LINE_LIST: pairs of points
            for a, b in zip(pts[::2], pts[1::2]):
                ax.plot([a[0], b[0]], [a[1], b[1]], color=colour, lw=mk.scale.x * ppm, zorder=3)
        elif mk.type == 2:                         # SPHERE, seen from above
            ax.add_patch(plt.Circle((mk.pose.position.x, mk.pose.position.y), mk.scale.x / 2, color=colour,
                                    zorder=4))
        elif mk.type == 9:                         # TEXT_VIEW_FACING
            ax.text(mk.pose.position.x, mk.pose.position.y, mk.text, color=colour, ha="center", va="center",
                    fontsize=mk.scale.z * ppm, zorder=5)


def render(run: Path) -> None:
    msgs = read_messages(run / "rosbag2")
    grid = msgs["/semantic_map/types"]
    info = grid.info
    w_m, h_m = info.width * info.resolution, info.height * info.resolution
    side = 7.0
    fig, axes = plt.subplots(1, 2, figsize=(2 * side, side * h_m / w_m + 0.6), dpi=DPI,
                             facecolor=BACKGROUND)
    titles = {"/semantic_map/units": "/semantic_map/units: outlines, labels, doors",
              "/semantic_map/graph": "/semantic_map/graph: units, adjacency, doors"}
    for ax, topic in zip(axes, titles):
        ax.set_facecolor(BACKGROUND)
        draw_grid(ax, grid)
        x0, y0 = info.origin.position.x, info.origin.position.y
        ax.set_xlim(x0, x0 + w_m)
        ax.set_ylim(y0, y0 + h_m)
        ax.set_aspect("equal")
        ax.set_axis_off()
        ax.set_title(titles[topic], color="white", fontsize=11)
    fig.tight_layout()
    for ax, topic in zip(axes, titles):     # line widths and text sizes need the final axes
        draw_markers(ax, msgs[topic].markers)
    stamp = grid.header.stamp
    fig.text(0.5, 0.01, f"frame '{grid.header.frame_id}', stamp {stamp.sec}.{stamp.nanosec:09d} s; "
             f"drawn with matplotlib from the bag's markers (docs/figures/make_ros2_markers.py), not an RViz screenshot",
             color="0.75", ha="center", fontsize=8)
    with atomic_path(OUT) as tmp:
        fig.savefig(tmp, format="png", dpi=DPI, facecolor=BACKGROUND)
    plt.close(fig)
    print(OUT)


def make_run(work: Path) -> Path:
    bag = record_bag(work / "intel_recording")
    out = work / "run"
    code = main(["map", str(bag), "--out", str(out), "--seed", "0", "--spread-draws", "0",
                 "--progress", "none"])
    if code != 0:
        raise SystemExit(code)
    return out


if __name__ == "__main__":
    if len(sys.argv) > 1:
        render(Path(sys.argv[1]))
    else:
        with tempfile.TemporaryDirectory() as d:
            render(make_run(Path(d)))
