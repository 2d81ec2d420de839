"""``semmap export ros2 RUN_DIR``: write a run's ROS 2 bag, ``RUN_DIR/rosbag2/``, again from its
world.json and types.pgm (a run of an earlier version, or a world.json edited by hand).

The bag is the one ``semmap map`` writes (:mod:`semmap_pp.outputs.ros2`): the types layer as an
``OccupancyGrid``, the units, doors and graph as ``MarkerArray`` messages, in the frame and at the
stamp world.json's ``map`` records (``map`` and 0 when it records none). It replaces the folder
there whole; the path is printed.
"""

from __future__ import annotations

from pathlib import Path


def register(subparsers) -> None:
    p = subparsers.add_parser("export", help="write a run's outputs for another system (ros2: its rosbag2/)",
                              description=__doc__.splitlines()[0])
    p.add_argument("format", choices=("ros2",), help="ros2: the ROS 2 bag RUN_DIR/rosbag2/")
    p.add_argument("run_dir", metavar="RUN_DIR", type=Path, help="a folder `semmap map` wrote")
    p.set_defaults(func=run)


def run(args) -> int:
    from semmap_pp.outputs.ros2 import export_run

    print(export_run(args.run_dir))
    return 0
