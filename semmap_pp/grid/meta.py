"""The map_server YAML file and the parameters that classify pixels, validated.

Every problem raises :class:`~semmap_pp.errors.MapError` naming the file (and the line and column
for YAML syntax errors).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import yaml

from semmap_pp.errors import MapError
from semmap_pp.grid.pixels import MODES

# ROS map_server's defaults (its documentation and map_saver's output); they are properties of the
# file format, not modelling choices.
DEFAULT_OCCUPIED_THRESH = 0.65
DEFAULT_FREE_THRESH = 0.196
DEFAULT_MODE = "trinary"
# Used only for maps that do not state a resolution (bare images); always reported as a note.
DEFAULT_RESOLUTION = 0.05


@dataclass(frozen=True)
class MapParams:
    """The map_server parameters of one map, complete and valid."""

    image: Path
    resolution: float
    origin: tuple[float, float, float]
    negate: bool
    occupied_thresh: float
    free_thresh: float
    mode: str
    notes: tuple[str, ...] = ()


def _is_number(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def check_resolution(path: Path, value) -> float:
    """A positive finite resolution, or MapError."""
    if not _is_number(value):
        raise MapError(path, f"resolution must be a number of metres per cell, got {value!r}")
    value = float(value)
    if not math.isfinite(value) or value <= 0:
        raise MapError(path, f"resolution must be a positive finite number, got {value}")
    return value


def check_threshold(path: Path, key: str, value) -> float:
    """A threshold in [0, 1], or MapError."""
    if not _is_number(value) or not math.isfinite(float(value)):
        raise MapError(path, f"{key} must be a number in [0, 1], got {value!r}")
    if not 0.0 <= float(value) <= 1.0:
        raise MapError(path, f"{key} must be in [0, 1], got {value}")
    return float(value)


def check_negate(path: Path, value) -> bool:
    """0/1/false/true, or MapError."""
    if isinstance(value, bool) or (isinstance(value, int) and value in (0, 1)):
        return bool(value)
    raise MapError(path, f"negate must be 0 or 1, got {value!r}")


def check_mode(path: Path, value) -> str:
    """One of trinary/scale/raw, or MapError."""
    if value not in MODES:
        raise MapError(path, f"mode must be one of {', '.join(MODES)}, got {value!r}")
    return value


def check_origin(path: Path, value) -> tuple[float, float, float]:
    """Three finite numbers (x, y, yaw), or MapError."""
    if (not isinstance(value, (list, tuple)) or len(value) != 3
            or not all(_is_number(v) and math.isfinite(float(v)) for v in value)):
        raise MapError(path, f"origin must be a list of 3 finite numbers [x, y, yaw], got {value!r}")
    return tuple(float(v) for v in value)


def check_thresholds(path: Path, occupied: float, free: float) -> None:
    """``free < occupied``, or MapError."""
    if not free < occupied:
        raise MapError(path, f"free_thresh ({free}) must be smaller than occupied_thresh "
                             f"({occupied})")


def read_yaml(path: Path) -> dict:
    """The mapping in a map_server YAML file."""
    try:
        text = path.read_text(encoding="utf-8")
    except UnicodeDecodeError:
        raise MapError(path, "not a YAML text file (not UTF-8)") from None
    except OSError as exc:
        raise MapError(path, f"cannot read map file: {exc.strerror or exc}") from None
    if not text.strip():
        raise MapError(path, "empty YAML file (expected map_server keys image, resolution, ...)")
    try:
        doc = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        problem = getattr(exc, "problem", None) or str(exc)
        if mark is not None:
            raise MapError(path, f"YAML syntax error: {problem}",
                           mark.line + 1, mark.column + 1) from None
        raise MapError(path, f"YAML syntax error: {problem}") from None
    if not isinstance(doc, dict):
        raise MapError(path, f"YAML must be a mapping of map_server keys, got a "
                             f"{type(doc).__name__}")
    return doc


def params_from_yaml(path: Path, doc: dict, overrides: dict) -> MapParams:
    """Validate a YAML mapping, with non-None ``overrides`` taking precedence."""
    notes: list[str] = []
    image = doc.get("image")
    if image is None:
        raise MapError(path, "YAML has no 'image' key (the map image file)")
    if not isinstance(image, str) or not image.strip():
        raise MapError(path, f"'image' must be a file name, got {image!r}")
    image_path = Path(image).expanduser()
    if not image_path.is_absolute():
        image_path = path.parent / image_path
    if not image_path.exists():
        raise MapError(path, f"image file {image!r} does not exist (looked for {image_path})")
    if image_path.is_dir():
        raise MapError(path, f"image {image!r} is a directory, not an image file")
    if image_path.resolve() == path.resolve():
        raise MapError(path, "'image' names this YAML file itself, not an image")

    def pick(key, default, note=None):
        if overrides.get(key) is not None:
            return overrides[key]
        if key in doc:
            return doc[key]
        if default is None:
            raise MapError(path, f"YAML has no '{key}' key")
        if note:
            notes.append(note)
        return default

    resolution = check_resolution(path, pick("resolution", None))
    origin = check_origin(path, pick("origin", (0.0, 0.0, 0.0), "no origin given; assumed [0, 0, 0]"))
    negate = check_negate(path, pick("negate", 0))
    occupied = check_threshold(path, "occupied_thresh", pick(
        "occupied_thresh", DEFAULT_OCCUPIED_THRESH,
        f"no occupied_thresh given; map_server default {DEFAULT_OCCUPIED_THRESH} used"))
    free = check_threshold(path, "free_thresh", pick(
        "free_thresh", DEFAULT_FREE_THRESH,
        f"no free_thresh given; map_server default {DEFAULT_FREE_THRESH} used"))
    check_thresholds(path, occupied, free)
    mode = check_mode(path, pick("mode", DEFAULT_MODE))
    return MapParams(image_path, resolution, origin, negate, occupied, free, mode, tuple(notes))


def params_for_image(path: Path, overrides: dict) -> MapParams:
    """Parameters for a bare image or array: map_server defaults, completed by ``overrides``."""
    notes: list[str] = []
    if overrides.get("resolution") is None:
        notes.append(f"no resolution given; assumed {DEFAULT_RESOLUTION} m/cell")
    resolution = check_resolution(path, overrides.get("resolution") or DEFAULT_RESOLUTION)
    occupied = check_threshold(path, "occupied_thresh",
                               _default(overrides.get("occupied_thresh"), DEFAULT_OCCUPIED_THRESH))
    free = check_threshold(path, "free_thresh",
                           _default(overrides.get("free_thresh"), DEFAULT_FREE_THRESH))
    check_thresholds(path, occupied, free)
    negate = check_negate(path, _default(overrides.get("negate"), 0))
    mode = check_mode(path, _default(overrides.get("mode"), DEFAULT_MODE))
    return MapParams(path, resolution, (0.0, 0.0, 0.0), negate, occupied, free, mode, tuple(notes))


def _default(value, default):
    return default if value is None else value
