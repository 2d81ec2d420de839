"""``rosbag2/``: the semantic map as a ROS 2 bag (MCAP storage, ``metadata.yaml``) for
``ros2 bag play``, RViz 2 and Foxglove, written with rosbags (pure Python: no ROS installation).

Three topics, one message each, every header with the input map's frame id and stamp (a bag's map
message's; a YAML's or image's: frame ``map``, time 0), the bag's log time the same stamp:

``/semantic_map/types`` (``nav_msgs/msg/OccupancyGrid``)
    types.pgm's codes (0 none, 1 room, 2 corridor, 3 hall, 4 other, 5 door:
    :mod:`semmap_pp.outputs.types_layer`) in the input map's size, resolution and origin, rows
    from the origin as the message wants them. The values are labels, not occupancy.
``/semantic_map/units`` (``visualization_msgs/msg/MarkerArray``)
    a DELETEALL first (a replay clears the previous one's markers), then per unit its outline
    (``LINE_STRIP``, namespace ``units``, id = the unit's id, coloured by type) and its label
    (``TEXT_VIEW_FACING``, namespace ``labels``, e.g. ``R7 room``), per door a ``LINE_LIST`` segment
    across its opening (namespace ``doors``, id = the door's id).
``/semantic_map/graph`` (``visualization_msgs/msg/MarkerArray``)
    the unit graph: a DELETEALL, per unit a ``SPHERE`` at its centre (namespace ``graph_units``),
    the adjacent pairs as one ``LINE_LIST`` (namespace ``adjacency``), per door a ``LINE_STRIP`` from
    one unit's centre through the door to the other's (namespace ``graph_doors``, id = the door's).

Each topic is offered reliable and transient-local with depth 1, as map_server offers ``/map``: a
display that subscribes after ``ros2 bag play`` published still gets the message.

Everything is read from world.json's content and the types layer (:func:`plan_from_doc` checks a
world.json read from disk, for ``semmap export ros2``), and the folder is written whole or not at
all (:func:`semmap_pp.atomic.atomic_dir`).
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from rosbags.interfaces import Qos, QosDurability, QosHistory, QosLiveliness, QosReliability, QosTime
from rosbags.rosbag2 import CompressionFormat, CompressionMode, StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

from semmap_pp import atomic
from semmap_pp.cells import TYPE_LETTER, UNIT_TYPES
from semmap_pp.errors import MapError
from semmap_pp.errors import OutputError, SemmapError
from semmap_pp.grid.images import decode_image
from semmap_pp.outputs.types_layer import types_image
from semmap_pp.plans.places import places_from_doc
from semmap_pp.plans.world_file import finite, read_world_doc

#: The folder in a run's output.
BAG_NAME = "rosbag2"
TYPES_TOPIC = "/semantic_map/types"
UNITS_TOPIC = "/semantic_map/units"
GRAPH_TOPIC = "/semantic_map/graph"
GRID_TYPE = "nav_msgs/msg/OccupancyGrid"
MARKERS_TYPE = "visualization_msgs/msg/MarkerArray"
#: rosbag2 metadata version (ROS 2 Jazzy's).
BAG_VERSION = 9

#: RGBA of each unit type's markers (bright enough on RViz's dark background), and of the doors.
TYPE_RGBA = {"room": (1.0, 0.78, 0.0, 1.0), "corridor": (0.2, 0.6, 1.0, 1.0),
             "hall": (1.0, 0.45, 0.1, 1.0), "other": (0.75, 0.75, 0.75, 1.0)}
DOOR_RGBA = (0.0, 0.9, 0.9, 1.0)
LABEL_RGBA = (1.0, 1.0, 1.0, 1.0)
EDGE_RGBA = (0.6, 0.6, 0.6, 0.8)


@dataclass(frozen=True)
class BagPlan:
    """What the bag holds, checked: the map layer, the units, doors and adjacent pairs in metres."""

    codes: np.ndarray                       # uint8 (H, W), image rows (row 0 on top)
    resolution: float
    origin: tuple[float, float, float]
    frame_id: str
    stamp_ns: int
    units: tuple                            # (id, type, (4, 2) corners, (x, y) centre)
    doors: tuple                            # (id, (unit a, unit b), (2, 2) ends, (x, y) centre)
    adjacency: tuple                        # (unit a, unit b)


def _pixel_to_metres(doc_map: dict, px: np.ndarray) -> np.ndarray:
    """Map-frame metres of continuous pixel coordinates ``[x, y]`` (as :mod:`semmap_pp.lattice.frame`)."""
    res, (ox, oy, yaw), h = doc_map["resolution"], doc_map["origin"], doc_map["height"]
    u, v = px[:, 0] * res, (h - px[:, 1]) * res
    c, s = math.cos(yaw), math.sin(yaw)
    return np.stack([ox + c * u - s * v, oy + s * u + c * v], axis=1)


def _finite_list(value, n: int) -> list[float] | None:

    vals = [finite(v) for v in value] if isinstance(value, list) and len(value) == n else None
    return None if vals is None or None in vals else vals


def plan_from_doc(doc: dict, codes: np.ndarray, *, path=None, frame_id: str | None = None,
                  stamp_ns: int | None = None) -> BagPlan:
    """The bag's content from world.json's ``doc`` and the types layer ``codes`` (image rows).

    ``frame_id`` and ``stamp_ns`` default to the world.json's ``map`` (``frame_id``, ``stamp_ns``;
    ``"map"`` and 0 when it has none). A unit, door, adjacent pair or map field that is not as
    semmap map writes it is one :class:`~semmap_pp.errors.SemmapError` naming ``path``.
    """

    m = doc.get("map")
    if not isinstance(m, dict):
        raise SemmapError(path, "'map' must be an object (width, height, resolution, origin)")
    width, height = m.get("width"), m.get("height")
    if not all(isinstance(v, int) and not isinstance(v, bool) and v >= 1 for v in (width, height)):
        raise SemmapError(path, "map: 'width' and 'height' must be integers of at least 1")
    origin = _finite_list(m.get("origin"), 3)
    res = _finite_list([m.get("resolution")], 1)
    if origin is None or res is None or res[0] <= 0:
        raise SemmapError(path, "map: 'resolution' must be a positive number and 'origin' three numbers")
    codes = np.asarray(codes)
    if codes.shape != (height, width):
        raise SemmapError(path, f"the types layer is {codes.shape[1]} x {codes.shape[0]} cells, the "
                                f"world.json's map {width} x {height}")
    frame = m.get("frame_id", "map") if frame_id is None else frame_id
    stamp = m.get("stamp_ns", 0) if stamp_ns is None else stamp_ns
    if not isinstance(frame, str) or not frame:
        raise SemmapError(path, "map: 'frame_id' must be a non-empty string")
    if isinstance(stamp, bool) or not isinstance(stamp, int) or not 0 <= stamp < 2 ** 63:
        raise SemmapError(path, "map: 'stamp_ns' must be an integer of nanoseconds >= 0")
    geo = {"resolution": res[0], "origin": origin, "height": height}
    places = places_from_doc(doc, path)        # ids, types, corners and doors checked
    units = []
    for u in places.units:
        if u.type not in UNIT_TYPES:
            raise SemmapError(path, f"unit {u.key}: 'type' must be one of {', '.join(UNIT_TYPES)}")
        units.append((int(u.key), u.type, np.asarray(u.corners, float), tuple(u.center)))
    centre = {uid: c for uid, _, _, c in units}
    raw_doors = {d.get("id"): d for d in doc.get("doors", []) if isinstance(d, dict)}
    doors = []
    for o in places.openings:
        if o.kind != "door":
            continue
        ends = raw_doors[o.id].get("endpoints_px")
        flat = _finite_list([v for e in ends for v in e] if isinstance(ends, list) and all(
            isinstance(e, list) for e in ends) else None, 4)
        if flat is None:
            raise SemmapError(path, f"door {o.id}: 'endpoints_px' must be two [x, y] numbers")
        doors.append((o.id, (int(o.units[0]), int(o.units[1])),
                      _pixel_to_metres(geo, np.array(flat).reshape(2, 2)), tuple(o.center)))
    pairs = doc.get("adjacency", [])
    if not isinstance(pairs, list):
        raise SemmapError(path, "'adjacency' must be a list")
    adjacency = []
    for i, pair in enumerate(pairs):
        if not (isinstance(pair, list) and len(pair) == 2 and all(
                isinstance(k, int) and not isinstance(k, bool) and k in centre for k in pair)):
            raise SemmapError(path, f"adjacency[{i}] must be two ids of the file's units")
        adjacency.append((pair[0], pair[1]))
    return BagPlan(codes.astype(np.uint8, copy=False), res[0], tuple(origin), frame, int(stamp),
                   tuple(units), tuple(doors), tuple(adjacency))


class _Messages:
    """rosbags message builders of one typestore (every field given: rosbags has no defaults)."""

    def __init__(self, plan: BagPlan):

        self.store = get_typestore(Stores.ROS2_JAZZY)
        self.t = self.store.types
        sec, nsec = divmod(plan.stamp_ns, 1_000_000_000)
        self.stamp = self.t["builtin_interfaces/msg/Time"](sec=int(sec), nanosec=int(nsec))
        self.header = self.t["std_msgs/msg/Header"](stamp=self.stamp, frame_id=plan.frame_id)
        self.plan = plan
        # sizes in metres: lines two cells wide (5 cm at least), labels ten cells high (30 cm)
        self.line = max(0.05, 2 * plan.resolution)
        self.text = max(0.3, 10 * plan.resolution)

    def point(self, x: float, y: float, z: float = 0.0):
        return self.t["geometry_msgs/msg/Point"](x=float(x), y=float(y), z=float(z))

    def pose(self, x: float = 0.0, y: float = 0.0, z: float = 0.0, yaw: float = 0.0):
        q = self.t["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=math.sin(yaw / 2), w=math.cos(yaw / 2))
        return self.t["geometry_msgs/msg/Pose"](position=self.point(x, y, z), orientation=q)

    def colour(self, rgba):
        r, g, b, a = rgba
        return self.t["std_msgs/msg/ColorRGBA"](r=r, g=g, b=b, a=a)

    def marker(self, ns: str, mid: int, kind: int, *, points=(), rgba=LABEL_RGBA, scale=(0.0, 0.0, 0.0),
               pose=None, text: str = "", action: int = 0):
        t = self.t
        return t["visualization_msgs/msg/Marker"](
            header=self.header, ns=ns, id=int(mid), type=kind, action=action,
            pose=pose if pose is not None else self.pose(),
            scale=t["geometry_msgs/msg/Vector3"](x=float(scale[0]), y=float(scale[1]), z=float(scale[2])),
            color=self.colour(rgba), lifetime=t["builtin_interfaces/msg/Duration"](sec=0, nanosec=0),
            frame_locked=False, points=[self.point(x, y) for x, y in points], colors=[],
            texture_resource="",
            texture=t["sensor_msgs/msg/CompressedImage"](header=self.header, format="",
                                                         data=np.zeros(0, np.uint8)),
            uv_coordinates=[], text=text, mesh_resource="",
            mesh_file=t["visualization_msgs/msg/MeshFile"](filename="", data=np.zeros(0, np.uint8)),
            mesh_use_embedded_materials=False)

    def types_grid(self):
        p, t = self.plan, self.t
        h, w = p.codes.shape
        ox, oy, yaw = p.origin
        info = t["nav_msgs/msg/MapMetaData"](map_load_time=self.stamp, resolution=float(p.resolution),
                                             width=int(w), height=int(h), origin=self.pose(ox, oy, 0.0, yaw))
        data = np.ascontiguousarray(p.codes[::-1]).reshape(-1).astype(np.int8)
        return t["nav_msgs/msg/OccupancyGrid"](header=self.header, info=info, data=data)

    def clear(self):
        return self.marker("", 0, 0, action=3)          # DELETEALL

    def units(self):
        M = self.t["visualization_msgs/msg/Marker"]
        out = [self.clear()]
        for uid, kind, corners, (cx, cy) in self.plan.units:
            ring = [tuple(v) for v in corners] + [tuple(corners[0])]
            out.append(self.marker("units", uid, M.LINE_STRIP, points=ring, rgba=TYPE_RGBA[kind],
                                   scale=(self.line, 0, 0)))
            out.append(self.marker("labels", uid, M.TEXT_VIEW_FACING, pose=self.pose(cx, cy, self.text),
                                   text=f"{TYPE_LETTER[kind]}{uid} {kind}", scale=(0, 0, self.text)))
        for did, _, ends, _ in self.plan.doors:
            out.append(self.marker("doors", did, M.LINE_LIST, points=[tuple(e) for e in ends],
                                   rgba=DOOR_RGBA, scale=(2.5 * self.line, 0, 0)))
        return self.t[MARKERS_TYPE](markers=out)

    def graph(self):
        M = self.t["visualization_msgs/msg/Marker"]
        centre = {uid: c for uid, _, _, c in self.plan.units}
        out = [self.clear()]
        d = 6 * self.line
        for uid, kind, _, (cx, cy) in self.plan.units:
            out.append(self.marker("graph_units", uid, M.SPHERE, pose=self.pose(cx, cy), rgba=TYPE_RGBA[kind],
                                   scale=(d, d, d)))
        if self.plan.adjacency:
            pts = [centre[k] for pair in self.plan.adjacency for k in pair]
            out.append(self.marker("adjacency", 0, M.LINE_LIST, points=pts, rgba=EDGE_RGBA,
                                   scale=(self.line, 0, 0)))
        for did, (a, b), _, c in self.plan.doors:
            out.append(self.marker("graph_doors", did, M.LINE_STRIP, points=[centre[a], c, centre[b]],
                                   rgba=DOOR_RGBA, scale=(1.5 * self.line, 0, 0)))
        return self.t[MARKERS_TYPE](markers=out)


def _qos():

    zero = QosTime(0, 0)
    return [Qos(QosHistory.KEEP_LAST, 1, QosReliability.RELIABLE, QosDurability.TRANSIENT_LOCAL, zero,
                zero, QosLiveliness.AUTOMATIC, zero, False)]


def write_bag(path: str | os.PathLike, plan: BagPlan) -> Path:
    """Write the bag of ``plan`` as the folder ``path`` (replacing one there, whole); return it."""


    path = Path(path)
    msgs = _Messages(plan)
    content = [(TYPES_TOPIC, GRID_TYPE, msgs.types_grid()), (UNITS_TOPIC, MARKERS_TYPE, msgs.units()),
               (GRAPH_TOPIC, MARKERS_TYPE, msgs.graph())]
    try:
        with atomic.atomic_dir(path) as tmp:
            writer = Writer(tmp, version=BAG_VERSION, storage_plugin=StoragePlugin.MCAP)
            # MCAP's own zstd chunks: a types layer of 4000 x 4000 cells takes 16 MB raw
            writer.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)
            with writer:
                for topic, kind, msg in content:
                    conn = writer.add_connection(topic, kind, typestore=msgs.store, offered_qos_profiles=_qos())
                    writer.write(conn, plan.stamp_ns, msgs.store.serialize_cdr(msg, kind))
    except OSError as exc:
        raise OutputError(path, f"cannot write the bag: {exc.strerror or exc}") from None
    return path


def write_run_bag(out: str | os.PathLike, sm, doc: dict) -> Path:
    """``out/rosbag2`` of a semantic map ``sm`` and its world.json content ``doc`` (frame id and
    stamp: the input map's)."""

    plan = plan_from_doc(doc, types_image(sm, doc), frame_id=sm.grid.frame_id, stamp_ns=sm.grid.stamp_ns)
    return write_bag(Path(out) / BAG_NAME, plan)


def read_types_layer(run_dir: Path) -> np.ndarray:
    """types.pgm of a run's folder (its codes, image rows), or one error naming the file."""

    path = run_dir / "types.pgm"
    if not path.exists():
        raise SemmapError(path, "does not exist: RUN_DIR must be a folder `semmap map` wrote")
    try:
        grey = decode_image(path).grey
    except MapError as exc:
        raise SemmapError(path, exc.message) from None
    if grey.max(initial=0) > 5 or not np.array_equal(grey, np.round(grey)):
        raise SemmapError(path, "holds values other than the types layer's codes 0..5")
    return grey.astype(np.uint8)


def export_run(run_dir: str | os.PathLike) -> Path:
    """Write ``run_dir/rosbag2`` again from the run's world.json and types.pgm (``semmap export
    ros2``); return the folder."""

    run_dir = Path(run_dir)
    if not run_dir.is_dir():
        raise SemmapError(run_dir, "is not a folder (RUN_DIR: the output folder of `semmap map`)")
    world = run_dir / "world.json"
    if not world.exists():
        raise SemmapError(world, "does not exist: RUN_DIR must be a folder `semmap map` wrote")
    doc = read_world_doc(world)
    plan = plan_from_doc(doc, read_types_layer(run_dir), path=world)
    return write_bag(run_dir / BAG_NAME, plan)


__all__ = ["BAG_NAME", "GRAPH_TOPIC", "TYPES_TOPIC", "UNITS_TOPIC", "BagPlan", "export_run", "plan_from_doc",
           "write_bag", "write_run_bag"]
