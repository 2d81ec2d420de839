"""Maps from bags (ROS 1 .bag, ROS 2 bag folders in sqlite3 and MCAP storage, bare .mcap) and the
ROS 2 bag every run writes (rosbag2/): the same W* as from the YAML, the messages read back with
rosbags, and one line naming the bag for every broken one."""

from __future__ import annotations

import json
import math
import shutil
from collections import Counter
from pathlib import Path

import numpy as np
import pytest
from rosbags.rosbag1 import Writer as Writer1
from rosbags.rosbag2 import Reader as Reader2
from rosbags.rosbag2 import StoragePlugin
from rosbags.rosbag2 import Writer as Writer2
from rosbags.typesys import Stores, get_typestore

from conftest import FAST_RUN, INTEL_CORNER
from semmap_pp.cli import main
from semmap_pp.errors import MapError, SemmapError
from semmap_pp.grid import load_map, ros_values

GRID = "nav_msgs/msg/OccupancyGrid"
TS2 = get_typestore(Stores.ROS2_JAZZY)
TS1 = get_typestore(Stores.ROS1_NOETIC)
KINDS = ("mcap-folder", "sqlite3-folder", "mcap-file", "ros1")


# --- bags written here --------------------------------------------------------------------------

def grid_msg(image_values, *, res=0.05, origin=(0.0, 0.0, 0.0), frame="map", stamp=(0, 0), ros1=False,
             data=None, width=None, quat=None):
    """An OccupancyGrid message of int8 values given in image rows (row 0 on top)."""
    ts = TS1 if ros1 else TS2
    t = ts.types
    values = np.asarray(image_values, np.int8)
    h, w = values.shape
    time = t["builtin_interfaces/msg/Time"]
    extra = {"seq": 0} if ros1 else {}
    header = t["std_msgs/msg/Header"](**extra, stamp=time(sec=stamp[0], nanosec=stamp[1]), frame_id=frame)
    ox, oy, yaw = origin
    pose = t["geometry_msgs/msg/Pose"](
        position=t["geometry_msgs/msg/Point"](x=ox, y=oy, z=0.0),
        orientation=t["geometry_msgs/msg/Quaternion"](
            *(quat if quat is not None else (0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2)))))
    info = t["nav_msgs/msg/MapMetaData"](map_load_time=time(sec=0, nanosec=0), resolution=res,
                                         width=w if width is None else width, height=h, origin=pose)
    return t[GRID](header=header, info=info,
                   data=values[::-1].ravel() if data is None else np.asarray(data, np.int8))


def string_msg(text, ros1=False):
    return (TS1 if ros1 else TS2).types["std_msgs/msg/String"](data=text)


def write_bag(path: Path, kind: str, topics: dict) -> Path:
    """A bag of ``kind`` at ``path`` (a folder, or ``path`` with the file's suffix) with
    ``topics``: name -> (type, [(seconds, message), ...]). Returns the path to give semmap."""
    if kind == "ros1":
        path = path.with_suffix(".bag")
        with Writer1(path) as w:
            for name, (msgtype, msgs) in topics.items():
                conn = w.add_connection(name, msgtype, typestore=TS1)
                for t, m in msgs:
                    w.write(conn, int(t * 1e9) + 10**9, TS1.serialize_ros1(m, msgtype))
        return path
    plugin = StoragePlugin.SQLITE3 if kind == "sqlite3-folder" else StoragePlugin.MCAP
    with Writer2(path, version=9, storage_plugin=plugin) as w:
        for name, (msgtype, msgs) in topics.items():
            conn = w.add_connection(name, msgtype, typestore=TS2)
            for t, m in msgs:
                w.write(conn, int(t * 1e9) + 10**9, TS2.serialize_cdr(m, msgtype))
    if kind == "mcap-file":
        return path / f"{path.name}.mcap"
    return path


def intel_values():
    """The bundled intel corner as map_server publishes it (int8, image rows)."""
    g = load_map(INTEL_CORNER)
    return ros_values(g.occupancy, mode=g.mode, occupied_thresh=g.occupied_thresh, free_thresh=g.free_thresh)


def intel_bag(path: Path, kind: str, **kw) -> Path:
    ros1 = kind == "ros1"
    return write_bag(path, kind, {"/map": (GRID, [(0.5, grid_msg(intel_values(), ros1=ros1, **kw))]),
                                  "/chatter": ("std_msgs/msg/String", [(0.0, string_msg("hi", ros1))])})


def error_line(capsys, argv) -> tuple[int, str]:
    code = main(argv)
    err = capsys.readouterr().err
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    return code, lines[0]


# --- reading ------------------------------------------------------------------------------------

@pytest.mark.parametrize("kind", KINDS)
def test_a_bag_of_each_kind_loads_as_the_yaml_of_the_same_map(tmp_path, kind):
    yaml_grid = load_map(INTEL_CORNER)
    path = intel_bag(tmp_path / "rec", kind, stamp=(1700000000, 250))
    grid = load_map(path)
    assert np.array_equal(grid.classes, yaml_grid.classes)
    assert grid.resolution == 0.05                       # the float32 field read as the 0.05 written
    assert grid.origin == yaml_grid.origin and grid.shape == yaml_grid.shape
    assert (grid.frame_id, grid.stamp_ns, grid.topic) == ("map", 1700000000_000000250, "/map")


@pytest.mark.parametrize("kind", ["mcap-file", "ros1"])
def test_rows_start_at_the_origin_and_yaw_and_position_are_the_maps(tmp_path, kind):
    """An occupied cell in the message's first row (at the origin) is the image's bottom row, and
    its centre lies where ROS puts cell (0, col) of a map turned by the origin's yaw."""
    image = np.full((3, 4), -1, np.int8)
    image[2, 1] = 100                                    # bottom row of the image = message row 0
    image[0, 3] = 0
    yaw = 0.5
    path = write_bag(tmp_path / "rec", kind, {"/map": (GRID, [(0, grid_msg(image, res=0.25, origin=(2.0, -1.0, yaw),
                                                                           ros1=kind == "ros1"))])})
    grid = load_map(path)
    assert grid.classes.tolist() == [[1, 1, 1, 0], [1, 1, 1, 1], [1, 2, 1, 1]]
    assert grid.origin[:2] == (2.0, -1.0) and grid.origin[2] == pytest.approx(yaw, abs=1e-12)
    x, y = grid.cells_to_metres(2, 1)                    # the occupied cell's centre
    u, v = 1.5 * 0.25, 0.5 * 0.25
    assert (float(x), float(y)) == pytest.approx((2.0 + math.cos(yaw) * u - math.sin(yaw) * v,
                                                  -1.0 + math.sin(yaw) * u + math.cos(yaw) * v))


def test_cell_values_classify_as_map_server_reads_them(tmp_path):
    """-1 and anything outside 0..100 unknown; p = v/100 against 0.65 / 0.196 (strict)."""
    values = [[-1, 0, 19, 20, 65, 66, 100, 101, -7]]
    path = write_bag(tmp_path / "rec", "mcap-folder", {"/map": (GRID, [(0, grid_msg(values))])})
    assert load_map(path).classes.tolist() == [[1, 0, 0, 1, 1, 2, 2, 1, 1]]
    # the thresholds given on the command line replace map_server's defaults
    assert load_map(path, occupied_thresh=0.5, free_thresh=0.3).classes.tolist() == [[1, 0, 0, 0, 2, 2, 2, 1, 1]]


def test_topic_and_at_pick_the_message(tmp_path):
    msgs = [(t, grid_msg(np.zeros((2, w), np.int8))) for t, w in ((1.0, 3), (5.0, 4), (10.0, 5))]
    path = write_bag(tmp_path / "rec", "mcap-folder", {
        "/map": (GRID, msgs), "/start": ("std_msgs/msg/String", [(0.0, string_msg("go"))])})
    assert load_map(path).width == 5                      # last
    assert load_map(path, at="last").width == 5
    assert load_map(path, at=7.5).width == 4              # the last at or before 7.5 s
    assert load_map(path, at=5.0).width == 4
    assert load_map(path, at=1.0).width == 3
    assert load_map(path, topic="/map", at=10.0).width == 5
    with pytest.raises(MapError, match=r"no message at or before --at 0.5 s \(its first is logged 1.000 s"):
        load_map(path, at=0.5)


def test_a_bag_folder_is_one_map_for_batch(tmp_path):
    from semmap_pp.run.batch import expand_maps

    a = intel_bag(tmp_path / "maps" / "floor_a", "mcap-folder")
    b = intel_bag(tmp_path / "maps" / "floor_b", "ros1")
    shutil.copy(INTEL_CORNER, tmp_path / "maps")
    shutil.copy(INTEL_CORNER.with_suffix(".png"), tmp_path / "maps")
    assert expand_maps([str(a)]) == [a]
    assert expand_maps([str(tmp_path / "maps")]) == [tmp_path / "maps" / "intel_corner.yaml", a, b]


def test_info_describes_a_bags_map(tmp_path, capsys):
    path = intel_bag(tmp_path / "rec", "ros1", frame="world", stamp=(12, 5))
    assert main(["info", str(path), "--json"]) == 0
    facts = json.loads(capsys.readouterr().out)
    assert (facts["topic"], facts["frame_id"], facts["stamp_ns"]) == ("/map", "world", 12_000_000_005)
    assert facts["image"] is None and facts["image_format"].startswith("ROS 1 bag, /map")
    assert main(["info", str(path)]) == 0
    assert "message     /map, frame 'world', stamp 12.000000005 s" in capsys.readouterr().out


# --- broken bags: one line naming the file, exit 2 ----------------------------------------------

def two_map_topics(d: Path):
    return write_bag(d / "rec", "mcap-folder", {"/map": (GRID, [(0, grid_msg([[0]]))]),
                                                "/local_map": (GRID, [(0, grid_msg([[0]]))])}), [], \
        r"holds 2 nav_msgs/msg/OccupancyGrid topics \(/local_map, /map\); choose one with --topic"


def wrong_type(d: Path):
    return write_bag(d / "rec", "ros1", {"/map": ("std_msgs/msg/String", [(0, string_msg("x", True))])}), \
        ["--topic", "/map"], r"topic /map holds std_msgs/msg/String, not nav_msgs/msg/OccupancyGrid"


def no_grid_topic(d: Path):
    return write_bag(d / "rec", "mcap-file", {"/chatter": ("std_msgs/msg/String", [(0, string_msg("x"))])}), \
        [], r"holds no nav_msgs/msg/OccupancyGrid topic \(its topics: /chatter \(std_msgs/msg/String\)\)"


def unknown_topic(d: Path):
    return write_bag(d / "rec", "sqlite3-folder", {"/map": (GRID, [(0, grid_msg([[0]]))])}), \
        ["--topic", "/mapp"], r"has no topic '/mapp'; its topics: /map \(nav_msgs/msg/OccupancyGrid\)"


def empty_topic(d: Path):
    return write_bag(d / "rec", "mcap-folder", {"/map": (GRID, []),
                                                "/chatter": ("std_msgs/msg/String", [(0, string_msg("x"))])}), \
        [], r"topic /map holds no message"


def empty_topic_ros1(d: Path):
    return write_bag(d / "rec", "ros1", {"/map": (GRID, [])}), [], r"topic /map holds no message"


def at_past_the_end(d: Path):
    return write_bag(d / "rec", "ros1", {"/map": (GRID, [(0, grid_msg([[0]], ros1=True)),
                                                         (2.0, grid_msg([[0]], ros1=True))])}), \
        ["--at", "2.5"], r"--at 2.5 s is past the bag's end \(it lasts 2.000 s\)"


def at_before_the_first(d: Path):
    return write_bag(d / "rec", "mcap-file", {"/map": (GRID, [(3.0, grid_msg([[0]]))]),
                                              "/go": ("std_msgs/msg/String", [(0, string_msg("x"))])}), \
        ["--at", "1"], r"topic /map has no message at or before --at 1.0 s \(its first is logged 3.000 s"


def truncated(kind: str, keep: float):
    def build(d: Path):
        path = intel_bag(d / "rec", kind)
        storage = path if path.is_file() else next(p for p in path.iterdir() if p.suffix in (".mcap", ".db3"))
        data = storage.read_bytes()
        storage.write_bytes(data[:int(len(data) * keep)])
        return path, [], r"cannot read the .* \(damaged or truncated\?\): "
    return build


def no_metadata(d: Path):
    path = intel_bag(d / "rec", "mcap-folder")
    (path / "metadata.yaml").unlink()
    return path, [], r"bag folder has no metadata.yaml .*; read its storage file alone: semmap map .*rec.mcap"


def no_metadata_sqlite(d: Path):
    path = intel_bag(d / "rec", "sqlite3-folder")
    (path / "metadata.yaml").unlink()
    return path, [], r"bag folder has no metadata.yaml"


def garbage_metadata(d: Path):
    path = intel_bag(d / "rec", "mcap-folder")
    (path / "metadata.yaml").write_text("rosbag2_bagfile_information: [: oops\n")
    return path, [], r"cannot read the ROS 2 bag \(damaged or truncated\?\): "


def empty_bag_file(d: Path):
    (d / "rec.bag").write_bytes(b"")
    return d / "rec.bag", [], r"empty file \(not a ROS 1 bag\)"


def cells_do_not_match_the_size(d: Path):
    return write_bag(d / "rec", "mcap-folder", {"/map": (GRID, [(0, grid_msg([[0, 0]], width=3))])}), [], \
        r"/map message 1 holds 2 cells for its 3 x 1 \(3\): a damaged message"


def too_many_cells(d: Path):
    return intel_bag(d / "rec", "ros1"), ["--max-cells", "1000"], \
        r"/map message 1 is 240x207 = 49680 cells, more than the limit of 1000 cells"


def bad_resolution(d: Path):
    return write_bag(d / "rec", "mcap-file", {"/map": (GRID, [(0, grid_msg([[0]], res=0.0))])}), [], \
        r"resolution must be a positive finite number, got 0.0"


def nan_resolution(d: Path):
    return write_bag(d / "rec", "ros1", {"/map": (GRID, [(0, grid_msg([[0]], res=math.nan, ros1=True))])}), [], \
        r"resolution must be a positive finite number, got nan"


def infinite_origin(d: Path):
    return write_bag(d / "rec", "mcap-folder", {"/map": (GRID, [(0, grid_msg([[0]], origin=(math.inf, 0.0, 0.0)))])}), \
        [], r"/map message 1: origin position must be finite, got \(inf, 0.0\)"


def nan_orientation(d: Path):
    return write_bag(d / "rec", "mcap-file", {"/map": (GRID, [(0, grid_msg([[0]], quat=(0.0, 0.0, math.nan, 1.0)))])}), \
        [], r"the map's origin orientation is not finite"


def metadata_fifo(d: Path):
    import os

    path = intel_bag(d / "rec", "mcap-folder")
    (path / "metadata.yaml").unlink()
    os.mkfifo(path / "metadata.yaml")
    return path / "metadata.yaml", [], r"metadata.yaml: is not a regular file"


def huge_frame_id(d: Path):
    return write_bag(d / "rec", "mcap-file", {"/map": (GRID, [(0, grid_msg([[0]], frame="f" * 5000))])}), [], \
        r"header frame_id .* is not a frame name"


BROKEN = [two_map_topics, wrong_type, no_grid_topic, unknown_topic, empty_topic, empty_topic_ros1,
          at_past_the_end, at_before_the_first, truncated("mcap-file", 0.6), truncated("ros1", 0.5),
          truncated("mcap-folder", 0.3), truncated("sqlite3-folder", 0.5), no_metadata, no_metadata_sqlite,
          garbage_metadata, empty_bag_file, cells_do_not_match_the_size, too_many_cells, bad_resolution,
          nan_resolution, infinite_origin, nan_orientation, metadata_fifo, huge_frame_id]


@pytest.mark.parametrize("build", BROKEN, ids=lambda b: getattr(b, "__name__", "truncated"))
def test_a_broken_bag_is_one_line_naming_it(tmp_path, capsys, build):
    import re

    named, extra, phrase = build(tmp_path)
    path = named.parent if named.name == "metadata.yaml" else named       # the error names the file
    for argv in (["info", str(path), *extra], ["map", str(path), "--out", str(tmp_path / "out"), *extra]):
        code, line = error_line(capsys, argv)
        assert code == 2
        assert line.startswith(f"semmap: error: {named}"), line
        assert re.search(phrase, line), line
    assert not (tmp_path / "out").exists()               # nothing written


def test_metadata_larger_than_a_bags_is_refused_unread(tmp_path, monkeypatch):
    from semmap_pp.grid import rosbag

    path = intel_bag(tmp_path / "rec", "sqlite3-folder")
    size = (path / "metadata.yaml").stat().st_size
    monkeypatch.setattr(rosbag, "MAX_METADATA_BYTES", size - 1)
    with pytest.raises(MapError, match=rf"metadata.yaml: is {size} bytes, more than a bag's metadata holds"):
        load_map(path)


@pytest.mark.parametrize("quat, yaw, note", [
    ((0.0, 0.0, 0.0, 0.0), 0.0, "the map's origin orientation is the zero quaternion; read as yaw 0"),
    ((0.0, 0.0, 0.0, 2.0), 0.0, None),                                         # not unit length: normalised
    ((0.1, 0.0, math.sin(0.3), math.cos(0.3)), None, "the map's origin is tilted (roll or pitch); only its yaw"),
])
def test_the_origins_quaternion_gives_its_yaw(tmp_path, quat, yaw, note):
    path = write_bag(tmp_path / "rec", "mcap-file", {"/map": (GRID, [(0, grid_msg([[0, 100]], quat=quat))])})
    grid = load_map(path)
    if yaw is not None:
        assert grid.origin[2] == yaw
    else:
        x, y, z, w = np.array(quat) / np.linalg.norm(quat)
        assert grid.origin[2] == pytest.approx(math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z)))
    about_origin = [n for n in grid.notes if "origin" in n]
    assert about_origin == [] if note is None else (len(about_origin) == 1 and about_origin[0].startswith(note))


def test_bad_at_is_argparses_error(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["info", "x.bag", "--at", "-1"])
    assert exc.value.code == 2 and "must be 'last' or seconds >= 0" in capsys.readouterr().err


# --- the same W* from a bag of each kind ---------------------------------------------------------

@pytest.fixture(scope="module")
def bag_runs(tmp_path_factory, intel_corner_wstar):
    """``semmap map`` of the intel corner from a bag of each kind (seed 3, as the YAML's run)."""
    d = tmp_path_factory.mktemp("bags")
    runs = {}
    for i, kind in enumerate(KINDS):
        frame, stamp = ("world", (1700000000 + i, 5)) if kind != "mcap-folder" else ("map", (0, 0))
        path = intel_bag(d / kind, kind, frame=frame, stamp=stamp)
        out = d / f"out-{kind}"
        assert main(["map", str(path), "--out", str(out), "--seed", "3", *FAST_RUN, "--progress", "none"]) == 0
        runs[kind] = out
    return runs


@pytest.mark.parametrize("kind", KINDS)
def test_semmap_map_from_a_bag_gives_the_yamls_wstar(bag_runs, intel_corner_wstar, kind):
    yaml_doc = json.loads(intel_corner_wstar.read_text())
    doc = json.loads((bag_runs[kind] / "world.json").read_text())
    for key in ("units", "doors", "passages", "adjacency", "rooms", "log_posterior", "cpr"):
        assert doc[key] == yaml_doc[key], key
    assert doc["map"]["topic"] == "/map" and yaml_doc["map"]["frame_id"] == "map"
    import jsonschema

    schema = json.loads((Path(__file__).resolve().parents[2] / "docs" / "world.schema.json").read_text())
    jsonschema.validate(doc, schema)
    assert "topic" not in yaml_doc["map"] and yaml_doc["map"]["stamp_ns"] == 0


def read_bag(path: Path) -> dict:
    """topic -> (log time, message) of a ROS 2 bag folder, as rosbags reads it."""
    out = {}
    with Reader2(path) as r:
        assert not r.compression_mode                  # MCAP's own chunk compression: no metadata mode
        for conn, t, raw in r.messages():
            assert conn.topic not in out
            out[conn.topic] = (t, TS2.deserialize_cdr(raw, conn.msgtype), conn)
    return out


def check_output_bag(run: Path, frame: str, stamp_ns: int) -> None:
    from semmap_pp.grid.images import decode_image

    doc = json.loads((run / "world.json").read_text())
    meta = (run / "rosbag2" / "metadata.yaml").read_text()
    assert "storage_identifier: mcap" in meta and (run / "rosbag2" / "rosbag2.mcap").is_file()
    msgs = read_bag(run / "rosbag2")
    assert sorted(msgs) == ["/semantic_map/graph", "/semantic_map/types", "/semantic_map/units"]
    for t, m, conn in msgs.values():
        assert t == stamp_ns
        qos = conn.ext.offered_qos_profiles[0]
        assert (qos.durability.name, qos.reliability.name, qos.depth) == ("TRANSIENT_LOCAL", "RELIABLE", 1)
    t, grid, conn = msgs["/semantic_map/types"]
    assert conn.msgtype == GRID
    assert grid.header.frame_id == frame and grid.header.stamp.sec * 10**9 + grid.header.stamp.nanosec == stamp_ns
    m = doc["map"]
    assert (grid.info.width, grid.info.height) == (m["width"], m["height"])
    assert float(np.float32(m["resolution"])) == grid.info.resolution
    o = grid.info.origin
    assert (o.position.x, o.position.y) == tuple(m["origin"][:2])
    assert 2 * math.atan2(o.orientation.z, o.orientation.w) == pytest.approx(m["origin"][2], abs=1e-12)
    types = decode_image(run / "types.pgm").grey.astype(np.int8)
    assert np.array_equal(grid.data.reshape(grid.info.height, grid.info.width), types[::-1])

    _, units, conn = msgs["/semantic_map/units"]
    assert conn.msgtype == "visualization_msgs/msg/MarkerArray"
    assert units.markers[0].action == 3                # DELETEALL first
    kinds = Counter((mk.ns, mk.type) for mk in units.markers[1:])
    assert kinds == {("units", 4): len(doc["units"]), ("labels", 9): len(doc["units"]),
                     ("doors", 5): len(doc["doors"])}
    assert all(mk.header.frame_id == frame for mk in units.markers)
    by_id = {(mk.ns, mk.id): mk for mk in units.markers[1:]}
    for u in doc["units"]:
        ring = [(p.x, p.y) for p in by_id[("units", u["id"])].points]
        assert ring == [tuple(v) for v in u["vertices_m"]] + [tuple(u["vertices_m"][0])]
        label = by_id[("labels", u["id"])]
        assert label.text.endswith(f"{u['id']} {u['type']}")
        assert (label.pose.position.x, label.pose.position.y) == tuple(u["center_m"])
    for door in doc["doors"]:
        a, b = by_id[("doors", door["id"])].points
        mid = ((a.x + b.x) / 2, (a.y + b.y) / 2)
        assert mid == pytest.approx(tuple(door["center_m"]), abs=1e-3)
        assert math.hypot(a.x - b.x, a.y - b.y) == pytest.approx(door["width_m"], abs=0.11)

    _, graph, _ = msgs["/semantic_map/graph"]
    kinds = Counter((mk.ns, mk.type) for mk in graph.markers[1:])
    assert kinds[("graph_units", 2)] == len(doc["units"]) and kinds[("graph_doors", 4)] == len(doc["doors"])
    (adj,) = [mk for mk in graph.markers if mk.ns == "adjacency"]
    assert len(adj.points) == 2 * len(doc["adjacency"])


def test_every_run_writes_the_ros2_bag_of_its_world(intel_corner_wstar):
    check_output_bag(intel_corner_wstar.parent, "map", 0)


@pytest.mark.parametrize("kind", ["ros1", "mcap-file"])
def test_the_output_bag_carries_the_input_messages_frame_and_stamp(bag_runs, kind):
    i = KINDS.index(kind)
    check_output_bag(bag_runs[kind], "world", (1700000000 + i) * 10**9 + 5)


def test_the_anyreader_reads_the_output_bag(intel_corner_wstar):
    from rosbags.highlevel import AnyReader

    with AnyReader([intel_corner_wstar.parent / "rosbag2"]) as r:
        topics = {c.topic: c.msgtype for c in r.connections}
        assert topics["/semantic_map/units"] == "visualization_msgs/msg/MarkerArray"
        msgs = [r.deserialize(raw, c.msgtype) for c, _, raw in r.messages()]
    assert len(msgs) == 3


# --- semmap export ros2 -------------------------------------------------------------------------

def test_export_ros2_writes_the_same_bag_again(intel_corner_wstar, tmp_path, capsys):
    run = tmp_path / "run"
    shutil.copytree(intel_corner_wstar.parent, run)
    before = (run / "rosbag2" / "rosbag2.mcap").read_bytes()
    shutil.rmtree(run / "rosbag2")
    assert main(["export", "ros2", str(run)]) == 0
    assert capsys.readouterr().out.strip() == str(run / "rosbag2")
    check_output_bag(run, "map", 0)
    assert read_bag(run / "rosbag2").keys() == read_bag(intel_corner_wstar.parent / "rosbag2").keys()
    assert len((run / "rosbag2" / "rosbag2.mcap").read_bytes()) == len(before)
    # a damaged bag folder is replaced whole; nothing else is left beside it
    (run / "rosbag2" / "rosbag2.mcap").write_bytes(b"junk")
    assert main(["export", "ros2", str(run)]) == 0
    check_output_bag(run, "map", 0)
    assert not [p.name for p in run.iterdir() if p.name.startswith(".")]


def test_export_ros2_takes_the_frame_and_stamp_world_json_records(bag_runs, tmp_path):
    run = tmp_path / "run"
    shutil.copytree(bag_runs["ros1"], run)
    shutil.rmtree(run / "rosbag2")
    assert main(["export", "ros2", str(run)]) == 0
    check_output_bag(run, "world", (1700000000 + KINDS.index("ros1")) * 10**9 + 5)


@pytest.mark.parametrize("damage, phrase", [
    (lambda run: (run / "world.json").unlink(), r"world.json: does not exist: RUN_DIR must be a folder"),
    (lambda run: (run / "types.pgm").unlink(), r"types.pgm: does not exist"),
    (lambda run: (run / "types.pgm").write_bytes(b"P5\n2 2\n255\n\x00\x01\x02\x09"),
     r"types.pgm: holds values other than the types layer's codes"),
    (lambda run: (run / "types.pgm").write_bytes(b"P5\n2 2\n255\n\x00\x01\x02\x03"),
     r"world.json: the types layer is 2 x 2 cells, the world.json's map 240 x 207"),
    (lambda run: (run / "world.json").write_text(
        (run / "world.json").read_text().replace('"vertices_m": [', '"vertices_m": [[1e400, 0], ', 1)),
     r"world.json: unit \d+: 'vertices_m' must be four"),
    (lambda run: (run / "world.json").write_text(
        (run / "world.json").read_text().replace('"frame_id": "map"', '"frame_id": ""')),
     r"world.json: map: 'frame_id' must be a non-empty string"),
])
def test_export_ros2_of_a_broken_run_is_one_line(intel_corner_wstar, tmp_path, capsys, damage, phrase):
    import re

    run = tmp_path / "run"
    shutil.copytree(intel_corner_wstar.parent, run)
    before = (run / "rosbag2" / "rosbag2.mcap").read_bytes()
    damage(run)
    code, line = error_line(capsys, ["export", "ros2", str(run)])
    assert code == 2 and re.search(phrase, line), line
    assert (run / "rosbag2" / "rosbag2.mcap").read_bytes() == before     # the old bag stays


def test_export_ros2_of_a_folder_that_is_not_a_run(tmp_path, capsys):
    code, line = error_line(capsys, ["export", "ros2", str(tmp_path / "nothing")])
    assert code == 2 and line == f"semmap: error: {tmp_path / 'nothing'}: is not a folder (RUN_DIR: the output folder of `semmap map`)"


# --- atomic folder output -----------------------------------------------------------------------

def test_a_failed_bag_write_leaves_the_old_bag_and_no_temporary(intel_corner_wstar, tmp_path, monkeypatch):
    from semmap_pp.outputs import ros2

    run = tmp_path / "run"
    shutil.copytree(intel_corner_wstar.parent, run)
    before = (run / "rosbag2" / "rosbag2.mcap").read_bytes()

    def fail(*args, **kwargs):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(Writer2, "write", fail)        # the disk fills while the messages go in
    with pytest.raises(SemmapError, match="rosbag2: cannot write the bag: No space left on device"):
        ros2.export_run(run)
    assert (run / "rosbag2" / "rosbag2.mcap").read_bytes() == before
    assert not [p.name for p in run.iterdir() if p.name.startswith(".")]


def test_a_killed_runs_temporary_bag_folder_is_removed(tmp_path):
    from semmap_pp.outputs.write import remove_stale_temps

    stale = tmp_path / ".rosbag2.k2j4h1x0.tmp" / "rosbag2"
    stale.mkdir(parents=True)
    (stale / "rosbag2.mcap").write_bytes(b"half")
    (tmp_path / ".mine.tmp").mkdir()
    assert remove_stale_temps(tmp_path) == [tmp_path / ".rosbag2.k2j4h1x0.tmp"]
    assert [p.name for p in tmp_path.iterdir()] == [".mine.tmp"]


def test_an_input_bag_named_rosbag2_in_the_output_folder_is_refused(tmp_path, capsys):
    path = intel_bag(tmp_path / "rosbag2", "mcap-folder")
    code, line = error_line(capsys, ["map", str(path), "--out", str(tmp_path), "--force", *FAST_RUN])
    assert code == 2 and "is an input of this run, and --out" in line
    assert (path / "metadata.yaml").is_file()


# --- the options on every command that takes a map ----------------------------------------------

def test_batch_hands_topic_and_at_to_every_task():
    from semmap_pp.cli import build_parser
    from semmap_pp.cli.cmd_batch import map_args

    args = build_parser().parse_args(["batch", "a.bag", "--out", "o", "--topic", "/map", "--at", "12.5"])
    extra = map_args(args)
    assert extra[extra.index("--topic") + 1] == "/map" and extra[extra.index("--at") + 1] == "12.5"
    assert "--topic" not in map_args(build_parser().parse_args(["batch", "a.bag", "--out", "o"]))


@pytest.mark.parametrize("command", [["compare", "--rules", "a.lp", "--rules", "b.lp"], ["info"], ["map", "--out", "o"]])
def test_every_map_command_takes_topic_and_at(command):
    from semmap_pp.cli import build_parser
    from semmap_pp.cli.options import map_options

    name, *rest = command
    args = build_parser().parse_args([name, "rec.mcap", *rest, "--topic", "/slam/map", "--at", "last"])
    assert (map_options(args)["topic"], map_options(args)["at"]) == ("/slam/map", "last")


def test_resume_refuses_topic_and_at(tmp_path, capsys):
    for option in (["--topic", "/map"], ["--at", "3"]):
        assert main(["map", "--resume", str(tmp_path), *option]) == 2
        assert f"{option[0]} cannot be given with --resume" in capsys.readouterr().err
