"""The map_server YAML file and the parameters that classify pixels, validated.

Every problem raises :class:`~semmap_pp.errors.MapError` naming the file (and the line and column
for YAML syntax errors).
"""

from __future__ import annotations

import math
import os
import re
import reprlib
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
# Sanity limits of the file format (not modelling choices): a map_server YAML is a few hundred
# bytes, and map coordinates beyond a million kilometres only turn into overflows downstream.
MAX_YAML_BYTES = 1 << 20
MAX_EXTENT_M = 1e9

# Values quoted in error messages are shortened: a hostile YAML (nested aliases) can hold a value
# whose repr is gigabytes long.
_SHORT = reprlib.Repr(maxlevel=2, maxlist=4, maxtuple=4, maxdict=4, maxstring=40, maxlong=40,
                      maxother=40)


def short(value) -> str:
    """A bounded repr of ``value`` for error messages."""
    return _SHORT.repr(value)


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


def _finite(value) -> bool:
    """A number that converts to a finite float (a huge YAML integer overflows)."""
    try:
        return _is_number(value) and math.isfinite(float(value))
    except OverflowError:
        return False


def check_resolution(path: Path, value) -> float:
    """A positive finite resolution, or MapError."""
    if not _is_number(value):
        raise MapError(path, f"resolution must be a number of metres per cell, got {short(value)}")
    if not _finite(value) or float(value) <= 0:
        raise MapError(path, f"resolution must be a positive finite number, got {short(value)}")
    return float(value)


def check_threshold(path: Path, key: str, value) -> float:
    """A threshold in [0, 1], or MapError."""
    if not _finite(value):
        raise MapError(path, f"{key} must be a number in [0, 1], got {short(value)}")
    if not 0.0 <= float(value) <= 1.0:
        raise MapError(path, f"{key} must be in [0, 1], got {value}")
    return float(value)


def check_negate(path: Path, value) -> bool:
    """0/1/false/true, or MapError."""
    if isinstance(value, bool) or (isinstance(value, int) and value in (0, 1)):
        return bool(value)
    raise MapError(path, f"negate must be 0 or 1, got {short(value)}")


def check_mode(path: Path, value) -> str:
    """One of trinary/scale/raw, or MapError."""
    if not isinstance(value, str) or value not in MODES:
        raise MapError(path, f"mode must be one of {', '.join(MODES)}, got {short(value)}")
    return value


def check_origin(path: Path, value) -> tuple[float, float, float]:
    """Three finite numbers (x, y, yaw), or MapError."""
    if (not isinstance(value, (list, tuple)) or len(value) != 3
            or not all(_finite(v) for v in value)):
        raise MapError(path, f"origin must be a list of 3 finite numbers [x, y, yaw], "
                             f"got {short(value)}")
    return tuple(float(v) for v in value)


def check_extent(path: Path, width: int, height: int, resolution: float,
                 origin: tuple[float, float, float]) -> None:
    """The map's corners in metres lie within ``MAX_EXTENT_M`` of 0, or MapError."""
    reach = max(abs(origin[0]), abs(origin[1])) + (width + height) * resolution
    if not reach <= MAX_EXTENT_M:
        raise MapError(path, f"map reaches {reach:.3g} m from the map frame's origin ({width}x{height} "
                             f"cells of {resolution:g} m at origin [{origin[0]:g}, {origin[1]:g}]); "
                             f"at most {MAX_EXTENT_M:g} m is accepted")


def check_thresholds(path: Path, occupied: float, free: float) -> None:
    """``free < occupied``, or MapError."""
    if not free < occupied:
        raise MapError(path, f"free_thresh ({free}) must be smaller than occupied_thresh "
                             f"({occupied})")


class MapYamlLoader(yaml.SafeLoader):
    """PyYAML's safe loader, reading a map_server YAML as map_server's yaml-cpp does: a number in
    scientific notation without a dot or an exponent sign (``5e-2``, ``1e1``) is a number, not a
    string (YAML 1.2), and a key given twice is an error at its line (yaml-cpp keeps one silently)."""

    def construct_mapping(self, node, deep=False):
        seen = set()
        for key_node, _ in node.value:
            key = self.construct_object(key_node, deep=deep)
            try:
                dup = key in seen
            except TypeError:           # an unhashable key: the base class reports it
                dup = False
            if dup:
                raise yaml.constructor.ConstructorError(
                    None, None, f"key {short(key)} is given twice", key_node.start_mark)
            try:
                seen.add(key)
            except TypeError:
                pass
        return super().construct_mapping(node, deep=deep)


MapYamlLoader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(r"^[-+]?(?:[0-9][0-9_]*(?:\.[0-9_]*)?|\.[0-9_]+)[eE][-+]?[0-9]+$"),
    list("-+0123456789."))


def read_yaml(path: Path) -> dict:
    """The mapping in a map_server YAML file (a regular file of at most ``MAX_YAML_BYTES``)."""
    if not path.is_file():  # a FIFO or device would block or never end
        raise MapError(path, "map file is not a regular file")
    try:
        size = path.stat().st_size
        if size > MAX_YAML_BYTES:
            raise MapError(path, f"YAML file of {size} bytes is too large for a map_server map "
                                 f"(at most {MAX_YAML_BYTES})")
        text = path.read_text(encoding="utf-8")
    except UnicodeDecodeError:
        raise MapError(path, "not a YAML text file (not UTF-8)") from None
    except OSError as exc:
        raise MapError(path, f"cannot read map file: {exc.strerror or exc}") from None
    if not text.strip():
        raise MapError(path, "empty YAML file (expected map_server keys image, resolution, ...)")
    try:
        doc = yaml.load(text, Loader=MapYamlLoader)   # safe: no Python tags, no code
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


def escapes_folder(image: str) -> bool:
    """Whether the YAML's ``image`` text leaves the YAML's folder: absolute, ``~`` or ``..``.

    The test is on the text (lexical), so a symlink the owner of the folder put there is followed;
    what a shared YAML file cannot do is name an arbitrary file (docs/formats.md).

    Examples
    --------
    >>> [escapes_folder(s) for s in ("m.pgm", "sub/m.pgm", "a/../m.pgm", "../m.pgm", "/etc/m.pgm")]
    [False, False, False, True, True]
    """
    if image.startswith("~") or Path(image).is_absolute():
        return True
    parts = Path(os.path.normpath(image)).parts
    return bool(parts) and parts[0] == ".."


def params_from_yaml(path: Path, doc: dict, overrides: dict, *,
                     allow_outside: bool = False) -> MapParams:
    """Validate a YAML mapping, with non-None ``overrides`` taking precedence.

    An ``image`` outside the YAML's folder (absolute, ``~`` or ``..``) is refused unless
    ``allow_outside``; it must then still decode as an image.
    """
    notes: list[str] = []
    image = doc.get("image")
    if image is None:
        raise MapError(path, "YAML has no 'image' key (the map image file)")
    if not isinstance(image, str) or not image.strip() or "\0" in image:
        raise MapError(path, f"'image' must be a file name, got {short(image)}")
    try:     # "\udcff" escapes a byte that is no UTF-8: the name would be written into the outputs
        image.encode("utf-8")
    except UnicodeEncodeError:
        raise MapError(path, "'image' is not UTF-8 text (an escape such as \\udcff of a byte that is "
                             "none); semmap writes the image's name into its outputs: rename it") from None
    if escapes_folder(image):
        if not allow_outside:
            raise MapError(path, f"image {short(image)} is outside the YAML file's folder "
                                 "(use --allow-outside to read it)")
        notes.append(f"image {image} is outside the YAML file's folder (allowed)")
    image_path = Path(image).expanduser()
    if not image_path.is_absolute():
        image_path = path.parent / image_path
    if not image_path.exists():
        raise MapError(path, f"image file {short(image)} does not exist (looked for {image_path})")
    if image_path.is_dir():
        raise MapError(path, f"image {short(image)} is a directory, not an image file")
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
