"""Occupancy grids from a robot's recording: a ``nav_msgs/OccupancyGrid`` message of a ROS 1 bag
(``.bag``), a ROS 2 bag folder (``metadata.yaml`` with sqlite3 or MCAP storage), or a bare ``.mcap``
or ``.db3`` storage file, read with rosbags (pure Python: no ROS installation).

The message is the map: its resolution, its origin (position and yaw) and its header's frame id
become the grid's, and its int8 cells classify as map_server's are read back: -1 (any value outside
0..100) unknown, 0..100 an occupancy probability ``p = v / 100`` classified by the thresholds
(``p > occupied_thresh`` occupied, ``p < free_thresh`` free; map_server's defaults 0.65 and 0.196).
Its rows start at the origin (row 0 is the bottom of the map), the image's at the top: the rows are
flipped into the image order of :mod:`semmap_pp.cells`.

Which message: ``topic`` (default the bag's one ``nav_msgs/OccupancyGrid`` topic) and ``at``
(``"last"``, the default, or seconds since the bag's start: the last message logged then or before).
Every problem raises :class:`~semmap_pp.errors.MapError` naming the bag, in one line.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from rosbags.rosbag1 import Reader as Reader1
from rosbags.rosbag2 import Reader as Reader2
from rosbags.typesys import Stores, get_typestore

from semmap_pp.errors import MapError
from semmap_pp.grid import meta
from semmap_pp.grid.occupancy import OccupancyGrid
from semmap_pp.grid.pixels import classify

#: The message type of a map (rosbags' name for ROS 1's ``nav_msgs/OccupancyGrid`` too).
GRID_TYPE = "nav_msgs/msg/OccupancyGrid"
#: Storage files read as a bag on their own (a ROS 1 bag, a ROS 2 bag's storage file).
BAG_SUFFIXES = (".bag", ".mcap", ".db3")
#: A ROS 2 bag folder's metadata file.
METADATA = "metadata.yaml"
#: Its size limit (a bag of thousands of topics has a metadata.yaml of some hundred kB).
MAX_METADATA_BYTES = 16 << 20
#: The longest frame id taken (tf frame names are a few words).
MAX_FRAME_ID = 256
#: Topics named in an error message at most.
MAX_LISTED = 8


def is_bag(path: str | Path) -> bool:
    """Whether ``path`` names a bag: a folder holding ``metadata.yaml`` or storage files, or a
    ``.bag`` / ``.mcap`` / ``.db3`` file.

    >>> import tempfile
    >>> d = Path(tempfile.mkdtemp())
    >>> is_bag(d), is_bag(d / "run.mcap"), is_bag(d / "map.yaml")
    (False, True, False)
    >>> _ = (d / METADATA).write_text("")
    >>> is_bag(d)
    True
    """
    path = Path(path)
    if path.is_dir():
        return (path / METADATA).exists() or bool(_storage_files(path))
    return path.suffix.lower() in BAG_SUFFIXES


def _storage_files(folder: Path) -> list[Path]:
    try:
        return sorted(p for p in folder.iterdir() if p.suffix.lower() in (".mcap", ".db3"))
    except OSError:
        return []


def kind_of(path: Path) -> str:
    """``"ROS 2 bag"``, ``"MCAP file"``, ``"ROS 2 sqlite3 file"`` or ``"ROS 1 bag"`` (what the
    messages call the input)."""
    if path.is_dir():
        return "ROS 2 bag"
    return {".mcap": "MCAP file", ".db3": "ROS 2 sqlite3 file"}.get(path.suffix.lower(), "ROS 1 bag")


def _listing(topics: dict) -> str:
    """``/a (type), /b (type), ...``: at most :data:`MAX_LISTED` topics."""
    items = [f"{name} ({info.msgtype or 'several types'})" for name, info in sorted(topics.items())]
    more = len(items) - MAX_LISTED
    return ", ".join(items[:MAX_LISTED]) + (f" and {more} more" if more > 0 else "") if items else "none"


def _damaged(path: Path, exc: BaseException) -> MapError:
    """The one-line error of a bag its reader could not read."""
    if isinstance(exc, MemoryError):
        why = "a record claims more memory than there is (a damaged length field?)"
    else:
        why = " ".join(str(exc).split())[:200] or type(exc).__name__
    return MapError(path, f"cannot read the {kind_of(path)} (damaged or truncated?): {why}")


@dataclass(frozen=True)
class GridMessage:
    """One ``nav_msgs/OccupancyGrid`` message of a bag, checked."""

    values: np.ndarray            # int8 (H, W), image rows (row 0 at the top: the message's last row)
    resolution: float
    origin: tuple[float, float, float]
    frame_id: str
    stamp_ns: int                 # header stamp (ns); the log time when the header's is 0
    topic: str
    index: int                    # the message's place on its topic, from 1
    count: int                    # messages on the topic
    offset_s: float               # its log time, seconds after the bag's start
    notes: tuple[str, ...] = ()


def _open(path: Path):
    """An unopened rosbags reader of ``path`` and whether it is ROS 1."""

    if path.is_dir():
        metadata = path / METADATA
        if not metadata.exists():
            found = _storage_files(path)
            hint = f"; read its storage file alone: semmap map {found[0]}" if len(found) == 1 else ""
            raise MapError(path, f"bag folder has no {METADATA} (a ROS 2 bag folder holds it beside "
                                 f"its storage files){hint}")
        if not metadata.is_file():
            raise MapError(metadata, "is not a regular file")
        size = metadata.stat().st_size
        if size > MAX_METADATA_BYTES:
            raise MapError(metadata, f"is {size} bytes, more than a bag's metadata holds "
                                     f"(at most {MAX_METADATA_BYTES})")
        return Reader2(path), False
    if not path.is_file():
        raise MapError(path, f"{kind_of(path)} is not a regular file")
    if path.stat().st_size == 0:
        raise MapError(path, f"empty file (not a {kind_of(path)})")
    if path.suffix.lower() == ".bag":
        return Reader1(path), True
    return Reader2(path), False


def _pick_topic(path: Path, topics: dict, topic: str | None) -> str:
    if topic is not None:
        if topic not in topics:
            raise MapError(path, f"has no topic {topic!r}; its topics: {_listing(topics)}")
        if topics[topic].msgtype != GRID_TYPE:
            raise MapError(path, f"topic {topic} holds {topics[topic].msgtype or 'several types'}, "
                                 f"not {GRID_TYPE}")
        return topic
    grids = sorted(name for name, info in topics.items() if info.msgtype == GRID_TYPE)
    if not grids:
        raise MapError(path, f"holds no {GRID_TYPE} topic (its topics: {_listing(topics)})")
    if len(grids) > 1:
        shown = ", ".join(grids[:MAX_LISTED]) + (f" and {len(grids) - MAX_LISTED} more"
                                                 if len(grids) > MAX_LISTED else "")
        raise MapError(path, f"holds {len(grids)} {GRID_TYPE} topics ({shown}); choose one with --topic")
    return grids[0]


def _yaw(path: Path, q) -> tuple[float, str | None]:
    """The yaw of quaternion ``q`` (x, y, z, w), and a note when it is not a turn about z alone."""
    x, y, z, w = (float(q.x), float(q.y), float(q.z), float(q.w))
    if not all(math.isfinite(v) for v in (x, y, z, w)):
        raise MapError(path, f"the map's origin orientation is not finite ({x}, {y}, {z}, {w})")
    norm = math.sqrt(x * x + y * y + z * z + w * w)
    if norm == 0.0:
        return 0.0, "the map's origin orientation is the zero quaternion; read as yaw 0"
    x, y, z, w = x / norm, y / norm, z / norm, w / norm
    yaw = math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
    tilt = abs(x) > 1e-6 or abs(y) > 1e-6
    return yaw, ("the map's origin is tilted (roll or pitch); only its yaw is used, as map_server does"
                 if tilt else None)


def read_grid_message(path: str | Path, *, topic: str | None = None, at: float | str | None = None,
                      max_cells: int) -> GridMessage:
    """The ``nav_msgs/OccupancyGrid`` message of the bag at ``path`` that ``topic`` and ``at`` pick
    (module docstring), with its cells in image row order."""
    path = Path(path)
    try:
        reader, ros1 = _open(path)
        with reader:
            topics = reader.topics
            name = _pick_topic(path, topics, topic)
            info = topics[name]
            start = int(reader.start_time) if reader.message_count else 0
            end = int(reader.end_time) if reader.message_count else 0
            limit = None
            if at is not None and at != "last":
                at_s = float(at)
                duration = max(end - 1 - start, 0) / 1e9
                if not (math.isfinite(at_s) and at_s >= 0):
                    raise MapError(path, f"--at must be 'last' or seconds >= 0 since the bag's start, got {at}")
                if at_s > duration + 1e-9:
                    raise MapError(path, f"--at {at_s:g} s is past the bag's end (it lasts {duration:.3f} s)")
                limit = start + int(round(at_s * 1e9))
            best, count, index, first = None, 0, 0, None
            for _, t, raw in reader.messages(connections=info.connections):
                count += 1
                first = t if first is None else min(first, t)
                if (limit is None or t <= limit) and (best is None or t >= best[0]):
                    best, index = (t, raw), count
            if count == 0:
                raise MapError(path, f"topic {name} holds no message")
            if best is None:
                raise MapError(path, f"topic {name} has no message at or before --at {at} s (its first "
                                     f"is logged {(first - start) / 1e9:.3f} s after the bag's start)")
            log_ns, raw = best
            if ros1:
                msg = get_typestore(Stores.ROS1_NOETIC).deserialize_ros1(raw, GRID_TYPE)
            else:
                msg = get_typestore(Stores.ROS2_JAZZY).deserialize_cdr(raw, GRID_TYPE)
    except MapError:
        raise
    except KeyboardInterrupt:
        raise
    except FileNotFoundError:
        raise MapError(path, f"{kind_of(path)} does not exist or lacks a storage file") from None
    except Exception as exc:  # noqa: BLE001 - rosbags, apsw, struct, unicode: a damaged file, one line
        raise _damaged(path, exc) from None
    return _checked(path, msg, name, index, count, (log_ns - start) / 1e9, log_ns, max_cells)


def _checked(path: Path, msg, topic: str, index: int, count: int, offset_s: float, log_ns: int,
             max_cells: int) -> GridMessage:
    """The message's fields checked as a map_server map's are."""
    where = f"{topic} message {index}"
    info = msg.info
    width, height = int(info.width), int(info.height)
    if width <= 0 or height <= 0:
        raise MapError(path, f"{where} has no cells ({width} x {height})")
    if width * height > max_cells:
        raise MapError(path, f"{where} is {width}x{height} = {width * height} cells, more than the "
                             f"limit of {max_cells} cells")
    data = np.asarray(msg.data, dtype=np.int8)
    if data.size != width * height:
        raise MapError(path, f"{where} holds {data.size} cells for its {width} x {height} "
                             f"({width * height}): a damaged message")
    res32 = np.float32(info.resolution)
    if not (np.isfinite(res32) and res32 > 0):
        raise MapError(path, f"{where}: resolution must be a positive finite number, got {float(res32)}")
    # the float32 field's shortest decimal: 0.05 written is 0.0500000007 read, 0.05 again here
    resolution = float(str(res32))
    pos = info.origin.position
    ox, oy = float(pos.x), float(pos.y)
    if not (math.isfinite(ox) and math.isfinite(oy)):
        raise MapError(path, f"{where}: origin position must be finite, got ({ox}, {oy})")
    yaw, note = _yaw(path, info.origin.orientation)
    origin = (ox, oy, yaw)
    meta.check_extent(path, width, height, resolution, origin)
    stamp = msg.header.stamp
    stamp_ns = int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)
    if stamp_ns <= 0:
        stamp_ns = int(log_ns)
    frame_id = str(msg.header.frame_id) or "map"
    if len(frame_id) > MAX_FRAME_ID or not frame_id.isprintable():
        raise MapError(path, f"{where}: header frame_id {meta.short(frame_id)} is not a frame name "
                             f"(printable, at most {MAX_FRAME_ID} characters)")
    notes = [f"map from {topic} of the {kind_of(path)}: message {index} of {count}, logged "
             f"{offset_s:.3f} s after the bag's start, frame {frame_id!r}"]
    if note:
        notes.append(note)
    values = np.ascontiguousarray(data.reshape(height, width)[::-1])
    return GridMessage(values, resolution, origin, frame_id, stamp_ns, topic, index, count, offset_s,
                       tuple(notes))


def occupancy_of(values: np.ndarray) -> np.ndarray:
    """Occupancy ``p`` (float64) of int8 cell values: ``v / 100`` for 0..100, NaN otherwise.

    >>> occupancy_of(np.array([[-1, 0, 50, 100, 101]], dtype=np.int8)).tolist()
    [[nan, 0.0, 0.5, 1.0, nan]]
    """
    v = np.asarray(values).astype(np.float64)
    return np.where((v >= 0) & (v <= 100), v / 100.0, np.nan)


def load_bag(path: str | Path, *, topic: str | None = None, at: float | str | None = None,
             occupied_thresh: float | None = None, free_thresh: float | None = None,
             resolution: float | None = None, max_cells: int) -> OccupancyGrid:
    """The occupancy grid of the message ``topic`` and ``at`` pick in the bag at ``path``
    (``--resolution`` overrides the message's, the thresholds complete it)."""
    path = Path(path)
    m = read_grid_message(path, topic=topic, at=at, max_cells=max_cells)
    occupied = meta.check_threshold(path, "occupied_thresh", meta.DEFAULT_OCCUPIED_THRESH
                                    if occupied_thresh is None else occupied_thresh)
    free = meta.check_threshold(path, "free_thresh", meta.DEFAULT_FREE_THRESH
                                if free_thresh is None else free_thresh)
    meta.check_thresholds(path, occupied, free)
    res = m.resolution if resolution is None else meta.check_resolution(path, resolution)
    p = occupancy_of(m.values)
    return OccupancyGrid(
        classes=classify(p, occupied, free), occupancy=p, resolution=res, origin=m.origin,
        source=path, image_path=None, mode="raw", occupied_thresh=occupied, free_thresh=free,
        negate=False, image_format=f"{kind_of(path)}, {m.topic} {GRID_TYPE}", notes=m.notes,
        frame_id=m.frame_id, stamp_ns=m.stamp_ns, topic=m.topic)
