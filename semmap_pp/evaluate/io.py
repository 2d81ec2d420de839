"""Readers for the ground-truth and prediction formats that the metrics compare.

* ipa room-segmentation ground truth (``NAME_gt_segmentation.png``): rooms are the 8-connected
  white components of the image, see :func:`read_ipa_gt`.
* label images (``labels.png`` written by semmap, ``truth_labels.png`` written by the synthetic
  generator): 8- or 16-bit single-channel PNG, value = segment id, 0 = none, see
  :func:`read_label_image`.
* ipa per-cell place types (``training_*.png``), see :func:`read_ipa_types`.
* synthetic truth (``truth.json``) and predicted worlds (``world.json``), see :func:`read_json`.

Every reader raises :class:`~semmap_pp.errors.MapError` naming the file when it cannot be read or
holds something unexpected. Arrays are indexed ``[row, col]`` (see :mod:`semmap_pp.cells`).
"""

from __future__ import annotations

import json
import os

import numpy as np
from PIL import Image, UnidentifiedImageError
from scipy import ndimage as ndi

from semmap_pp.errors import MapError
from semmap_pp.evaluate.types import (TRUTH_CORRIDOR, TRUTH_DOORWAY, TRUTH_OUTSIDE,
                                      TRUTH_ROOM)

# The ipa benchmark's own protocol (Bormann et al., ICRA 2016, evaluation_segmentation.cpp):
# a ground-truth pixel is room space when its grey value is > 250, and only rooms (and predicted
# segments) of more than 100 pixels take part in the scores. These define the published metric,
# they are not modelling choices of semmap_pp.
IPA_WHITE_ABOVE = 250
IPA_MIN_REGION_CELLS = 100

# ROSE2's evaluation (Luperto et al. 2022, after Bormann et al.): ground-truth rooms are the
# connected regions of one colour of more than 200 cells; every predicted segment counts.
ROSE2_MIN_ROOM_CELLS = 200
SEGMENTATION_FORMATS = ("rose2", "ipa")

# Grey values of the ipa place-type images and the truth codes they become.
IPA_TYPE_PIXELS = {77: TRUTH_ROOM, 115: TRUTH_CORRIDOR, 179: TRUTH_DOORWAY, 0: TRUTH_OUTSIDE}


def read_image(path: str | os.PathLike) -> np.ndarray:
    """Pixel array of an image file, exactly as stored (no colour conversion).

    Parameters
    ----------
    path : path-like
        Any image Pillow reads (PNG 8/16-bit, PGM, ...).

    Returns
    -------
    np.ndarray
        Shape (H, W) for single-channel images, (H, W, C) for RGB / RGBA / LA.

    Raises
    ------
    MapError
        When the file is missing or is not an image.
    """
    if os.path.exists(path) and not os.path.isfile(path):     # a FIFO or a device is never opened
        raise MapError(path, "cannot read image: not a regular file")
    try:
        with Image.open(path) as img:
            img.load()
            if img.mode == "P":  # palette images: their colours, not their indices
                img = img.convert("RGBA" if "transparency" in img.info else "RGB")
            elif img.mode == "1":
                img = img.convert("L")
            return np.asarray(img)
    except FileNotFoundError:
        raise MapError(path, "no such file") from None
    except (UnidentifiedImageError, OSError, ValueError) as exc:
        raise MapError(path, f"cannot read image: {exc}") from None


def grey(image: np.ndarray) -> np.ndarray:
    """Grey level of an image array: itself if single-channel, else the mean of R, G and B.

    The alpha channel (RGBA, LA) is ignored.

    Examples
    --------
    >>> import numpy as np
    >>> grey(np.array([[[255, 255, 240, 0]]], dtype=np.uint8)).tolist()
    [[250.0]]
    """
    image = np.asarray(image)
    if image.ndim == 2:
        return image.astype(np.float64)
    if image.ndim == 3 and image.shape[2] in (2, 3, 4):
        channels = image[..., :1] if image.shape[2] == 2 else image[..., :3]
        return channels.astype(np.float64).mean(axis=2)
    raise ValueError(f"not an image array: shape {image.shape}")


def ipa_gt_labels(image: np.ndarray, min_room_cells: int = IPA_MIN_REGION_CELLS) -> np.ndarray:
    """Room labels of an ipa ground-truth image array.

    Every 8-connected component of cells whose grey level (mean of RGB) is above 250 and that
    holds more than ``min_room_cells`` cells is one room. Rooms are numbered 1..n in the order of
    their first cell in row-major order; every other cell is 0.

    Parameters
    ----------
    image : np.ndarray, shape (H, W) or (H, W, C)
    min_room_cells : int
        Components of at most this many cells are dropped (the benchmark's 100).

    Returns
    -------
    np.ndarray of int32, shape (H, W)

    Examples
    --------
    >>> import numpy as np
    >>> img = np.zeros((3, 7), dtype=np.uint8)
    >>> img[:, :3] = 255; img[:, 4:] = 255; img[0, 6] = 251
    >>> ipa_gt_labels(img, min_room_cells=0).tolist()
    [[1, 1, 1, 0, 2, 2, 2], [1, 1, 1, 0, 2, 2, 2], [1, 1, 1, 0, 2, 2, 2]]
    >>> int(ipa_gt_labels(img, min_room_cells=9).max())  # both rooms hold 9 cells, not more
    0
    """
    white = grey(image) > IPA_WHITE_ABOVE
    labels, n = ndi.label(white, structure=np.ones((3, 3), dtype=bool))
    sizes = np.bincount(labels.ravel(), minlength=n + 1)
    keep = sizes > min_room_cells
    keep[0] = False
    new_id = np.zeros(n + 1, dtype=np.int32)
    new_id[keep] = np.arange(1, int(keep.sum()) + 1, dtype=np.int32)
    return new_id[labels]


def read_ipa_gt(path: str | os.PathLike, min_room_cells: int = IPA_MIN_REGION_CELLS) -> np.ndarray:
    """Room labels of an ipa ``NAME_gt_segmentation.png`` (see :func:`ipa_gt_labels`).

    Grey, RGB and RGBA files are all accepted (the ten benchmark files mix them).

    Raises
    ------
    MapError
        When the file cannot be read or holds no room at all.
    """
    image = read_image(path)
    if image.ndim not in (2, 3):
        raise MapError(path, f"unexpected image shape {image.shape}")
    labels = ipa_gt_labels(image, min_room_cells)
    if labels.max() == 0:
        raise MapError(path, f"no white (> {IPA_WHITE_ABOVE}) region of more than "
                             f"{min_room_cells} cells: not an ipa ground-truth image")
    return labels


def _colour_codes(image: np.ndarray) -> np.ndarray:
    """One int64 per pixel for its colour (RGB; grey repeated), 0 for black or fully transparent."""
    image = np.asarray(image)
    if image.ndim == 2:
        rgb = np.repeat(image[..., None], 3, axis=2)
    elif image.ndim == 3 and image.shape[2] in (2, 3, 4):
        rgb = np.repeat(image[..., :1], 3, axis=2) if image.shape[2] == 2 else image[..., :3]
    else:
        raise ValueError(f"not an image array: shape {image.shape}")
    rgb = rgb.astype(np.int64)
    code = (rgb[..., 0] << 32) | (rgb[..., 1] << 16) | rgb[..., 2]
    if image.ndim == 3 and image.shape[2] in (2, 4):
        code[image[..., -1] == 0] = 0
    return code


def colour_room_labels(image: np.ndarray, min_room_cells: int = ROSE2_MIN_ROOM_CELLS) -> np.ndarray:
    """Rooms of a colour ground truth (ROSE2's ``gt.png``): every 8-connected region of one colour
    (black or transparent: no room) of more than ``min_room_cells`` cells, numbered 1..n in the
    order of their first cell.

    >>> img = np.zeros((2, 5, 3), np.uint8); img[:, :2] = (200, 0, 0); img[:, 3:] = (200, 0, 0)
    >>> colour_room_labels(img, 0).tolist()        # one colour, two rooms
    [[1, 1, 0, 2, 2], [1, 1, 0, 2, 2]]
    """
    code = _colour_codes(image)
    _, inv = np.unique(code, return_inverse=True)
    inv = inv.reshape(code.shape).astype(np.int64) + 1
    inv[code == 0] = 0
    # regions of one colour: 8-connected components of equal neighbours
    out = np.zeros(code.shape, np.int32)
    n_total = 0
    objs = ndi.find_objects(inv)
    for value, sl in enumerate(objs, start=1):
        if sl is None:
            continue
        lab, n = ndi.label(inv[sl] == value, structure=np.ones((3, 3), bool))
        if n == 0:
            continue
        sizes = np.bincount(lab.ravel(), minlength=n + 1)
        keep = sizes > min_room_cells
        keep[0] = False
        new_id = np.zeros(n + 1, np.int32)
        new_id[keep] = np.arange(n_total + 1, n_total + 1 + int(keep.sum()), dtype=np.int32)
        n_total += int(keep.sum())
        sub = out[sl]
        hit = new_id[lab] > 0
        sub[hit] = new_id[lab][hit]
    # number in the order of each room's first cell
    ids = out.ravel()
    first = np.unique(ids[ids > 0], return_index=True)
    order = np.argsort(first[1])
    lut = np.zeros(n_total + 1, np.int32)
    lut[first[0][order]] = np.arange(1, order.size + 1, dtype=np.int32)
    return lut[out]


def colour_segment_labels(image: np.ndarray) -> np.ndarray:
    """Segments of a colour segmentation (ROSE2's ``rose2.png``): one segment per colour, wherever
    its pixels lie (black or transparent: none), numbered 1..n by colour.

    >>> img = np.zeros((1, 5, 3), np.uint8); img[0, :2] = (9, 9, 9); img[0, 3:] = (9, 9, 9)
    >>> colour_segment_labels(img).tolist()
    [[1, 1, 0, 1, 1]]
    """
    code = _colour_codes(image)
    values, inv = np.unique(code, return_inverse=True)
    inv = inv.reshape(code.shape).astype(np.int32) + (0 if values[0] == 0 else 1)
    return np.where(code == 0, 0, inv).astype(np.int32)


def read_segmentation_truth(path: str | os.PathLike, fmt: str) -> np.ndarray:
    """Room labels of a segmentation ground truth: ``fmt`` "rose2" (a colour per room,
    :func:`colour_room_labels`) or "ipa" (white rooms, :func:`read_ipa_gt`).

    Raises
    ------
    MapError
        When the file cannot be read, the format is unknown, or it holds no room.
    """
    if fmt == "ipa":
        return read_ipa_gt(path)
    if fmt != "rose2":
        raise MapError(path, f"unknown segmentation format {fmt!r} (expected one of "
                             f"{', '.join(SEGMENTATION_FORMATS)})")
    image = read_image(path)
    try:
        labels = colour_room_labels(image)
    except ValueError as exc:
        raise MapError(path, str(exc)) from None
    if labels.max() == 0:
        raise MapError(path, f"no region of one colour of more than {ROSE2_MIN_ROOM_CELLS} cells: "
                             "not a room ground truth")
    return labels


def read_segmentation(path: str | os.PathLike) -> np.ndarray:
    """Segments of a prediction file: a single-channel label image (:func:`read_label_image`:
    rooms.png, regions.png, an ipa segmenter's output) or a colour image, one segment per colour
    (:func:`colour_segment_labels`: ROSE2's output)."""
    image = read_image(path)
    if image.ndim == 2:
        return read_label_image(path).astype(np.int32)
    try:
        return colour_segment_labels(image)
    except ValueError as exc:
        raise MapError(path, str(exc)) from None


def read_label_image(path: str | os.PathLike) -> np.ndarray:
    """Segment labels of a single-channel 8- or 16-bit label image (``labels.png``,
    ``truth_labels.png``): value = segment id, 0 = no segment.

    Returns
    -------
    np.ndarray of int32, shape (H, W)

    Raises
    ------
    MapError
        When the file cannot be read or has colour channels (a label image is one channel).
    """
    image = read_image(path)
    if image.ndim != 2:
        raise MapError(path, f"a label image must have one channel, this one has shape {image.shape}")
    if not np.issubdtype(image.dtype, np.integer):
        raise MapError(path, f"a label image must hold integers, this one holds {image.dtype}")
    if image.min() < 0:
        raise MapError(path, "a label image must not hold negative values")
    return image.astype(np.int32)


def read_ipa_types(path: str | os.PathLike) -> np.ndarray:
    """Per-cell place-type truth of an ipa ``training_*.png``.

    Grey 77 = room, 115 = corridor, 179 = doorway, 0 = obstacle or outside become
    ``TRUTH_ROOM``, ``TRUTH_CORRIDOR``, ``TRUTH_DOORWAY`` and ``TRUTH_OUTSIDE`` of
    :mod:`semmap_pp.evaluate.types`.

    Returns
    -------
    np.ndarray of int8, shape (H, W)

    Raises
    ------
    MapError
        When the file cannot be read or holds a grey value outside {0, 77, 115, 179}.
    """
    image = read_image(path)
    if image.ndim == 3:
        image = np.rint(grey(image)).astype(np.int64)
    values = np.unique(image)
    unknown = sorted(set(values.tolist()) - set(IPA_TYPE_PIXELS))
    if unknown:
        raise MapError(path, f"unexpected grey values {unknown[:5]} in a place-type image "
                             f"(expected {sorted(IPA_TYPE_PIXELS)})")
    truth = np.full(image.shape, TRUTH_OUTSIDE, dtype=np.int8)
    for pixel, code in IPA_TYPE_PIXELS.items():
        truth[image == pixel] = code
    return truth


def read_json(path: str | os.PathLike) -> dict:
    """The top-level object of a JSON file (``truth.json``, ``world.json``).

    Raises
    ------
    MapError
        When the file is missing, is not JSON, or its top level is not an object.
    """
    if os.path.exists(path) and not os.path.isfile(path):     # a FIFO or a device is never opened
        raise MapError(path, "cannot read: not a regular file")
    try:
        with open(path, encoding="utf-8") as fh:
            data = json.load(fh)
    except FileNotFoundError:
        raise MapError(path, "no such file") from None
    except json.JSONDecodeError as exc:
        raise MapError(path, f"not valid JSON: {exc.msg}", line=exc.lineno, col=exc.colno) from None
    except RecursionError:
        raise MapError(path, "not valid JSON here: nested too deeply (thousands of levels)") from None
    except ValueError as exc:      # an integer of thousands of digits (Python's conversion limit)
        raise MapError(path, f"not valid JSON here: {str(exc).split(';')[0]}") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise MapError(path, f"cannot read: {exc}") from None
    if not isinstance(data, dict):
        raise MapError(path, "the top level must be a JSON object")
    return data
