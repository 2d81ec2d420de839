"""Cell prediction rate (CPR), the seed paper's measure, and its region of interest (ROI).

A cell of the ROI is *correctly explained* when the pair (input class, world state) is one of
(FREE, FREE), (OCCUPIED, WALL), (OCCUPIED, OBJECT), (UNKNOWN, OBJECT), (UNKNOWN, UNKNOWN)
(docs/evaluation.md, "Cell prediction rate"). CPR = correctly explained ROI cells / ROI cells.

The paper's ROI was drawn by hand. Ours is a mask file (:func:`load_roi`) or, by default, the
known part of the map closed morphologically and with its holes filled (:func:`default_roi`).
The project's closing radius is ``[evaluate] roi_closing_m`` in ``models/default.toml`` (1.0 m);
:func:`closing_radius_cells` turns it into cells.
"""

from __future__ import annotations

import os

import numpy as np
from scipy import ndimage as ndi

from semmap_pp.cells import (FREE, OCCUPIED, UNKNOWN, W_FREE, W_OBJECT, W_UNKNOWN, W_WALL,
                             WORLD_STATES, mask_box)
from semmap_pp.errors import MapError
from semmap_pp.evaluate.io import read_image

# The (input class, world state) pairs that count as correctly explained (docs/evaluation.md).
CORRECT_PAIRS = ((FREE, W_FREE), (OCCUPIED, W_WALL), (OCCUPIED, W_OBJECT),
                 (UNKNOWN, W_OBJECT), (UNKNOWN, W_UNKNOWN))

# correct[input_class, world_state] as a lookup table.
_CORRECT = np.zeros((3, len(WORLD_STATES)), dtype=bool)
for _c, _w in CORRECT_PAIRS:
    _CORRECT[_c, _w] = True


def _check_codes(arr: np.ndarray, n: int, what: str) -> None:
    if arr.size and (not np.issubdtype(arr.dtype, np.integer) or arr.min() < 0 or arr.max() >= n):
        raise MapError(None, f"{what} must hold integer codes 0..{n - 1}")


def cpr(input_classes: np.ndarray, world_states: np.ndarray,
        roi: np.ndarray | None = None) -> tuple[float, int]:
    """Cell prediction rate of a world over a region of interest.

    Parameters
    ----------
    input_classes : np.ndarray of uint8, shape (H, W)
        FREE / UNKNOWN / OCCUPIED codes of the input map (:mod:`semmap_pp.cells`).
    world_states : np.ndarray of uint8, shape (H, W)
        W_WALL / W_FREE / W_OBJECT / W_UNKNOWN state of each cell in the world.
    roi : np.ndarray of bool, shape (H, W), optional
        Cells to score. ``None`` scores every cell of the map; the project's default ROI is
        :func:`default_roi`, which the caller computes and passes (it needs a radius).

    Returns
    -------
    rate : float
        Correct ROI cells / ROI cells; NaN when the ROI is empty.
    n_cells : int
        Number of ROI cells (0 for an empty ROI).

    Raises
    ------
    MapError
        When the shapes differ or a code is out of range.

    Examples
    --------
    Input row F F O U U, world row FREE WALL OBJECT OBJECT FREE: the pairs (F,FREE), (O,OBJECT)
    and (U,OBJECT) are correct, (F,WALL) and (U,FREE) are not -> 3/5.

    >>> import numpy as np
    >>> from semmap_pp.cells import FREE as F, OCCUPIED as O, UNKNOWN as U
    >>> from semmap_pp.cells import W_FREE, W_WALL, W_OBJECT
    >>> c = np.array([[F, F, O, U, U]], dtype=np.uint8)
    >>> w = np.array([[W_FREE, W_WALL, W_OBJECT, W_OBJECT, W_FREE]], dtype=np.uint8)
    >>> cpr(c, w)
    (0.6, 5)
    >>> cpr(c, w, roi=np.array([[True, True, False, False, False]]))
    (0.5, 2)
    """
    c = np.asarray(input_classes)
    w = np.asarray(world_states)
    if c.shape != w.shape:
        raise MapError(None, f"input map has shape {c.shape} but the world states have {w.shape}")
    _check_codes(c, 3, "input classes")
    _check_codes(w, len(WORLD_STATES), "world states")
    if roi is None:
        roi = np.ones(c.shape, dtype=bool)
    else:
        roi = np.asarray(roi, dtype=bool)
        if roi.shape != c.shape:
            raise MapError(None, f"ROI has shape {roi.shape} but the map has {c.shape}")
    n = int(roi.sum())
    if n == 0:
        return float("nan"), 0
    correct = _CORRECT[c[roi].astype(np.intp), w[roi].astype(np.intp)]
    return float(correct.sum()) / n, n


def disk(radius: int) -> np.ndarray:
    """Boolean disk structuring element: cells with dx² + dy² <= radius².

    Examples
    --------
    >>> disk(1).astype(int).tolist()
    [[0, 1, 0], [1, 1, 1], [0, 1, 0]]
    """
    r = int(radius)
    if r < 0:
        raise ValueError(f"radius must be >= 0, got {radius}")
    yy, xx = np.mgrid[-r:r + 1, -r:r + 1]
    return xx * xx + yy * yy <= r * r


def closing_radius_cells(closing_m: float, resolution: float) -> int:
    """Closing radius in cells: ``round(closing_m / resolution)``.

    Examples
    --------
    >>> closing_radius_cells(1.0, 0.05)
    20
    """
    if resolution <= 0 or closing_m < 0:
        raise ValueError(f"need resolution > 0 and closing_m >= 0, got {resolution}, {closing_m}")
    return int(round(closing_m / resolution))


def closing_disk(mask: np.ndarray, radius: int) -> np.ndarray:
    """Morphological closing of ``mask`` with :func:`disk` ``(radius)``, by distance transforms.

    The same cells as ``scipy.ndimage.binary_closing(mask, structure=disk(radius))`` away from
    the array's border (a cell is in the dilation when some cell of ``mask`` lies within
    ``radius``, and in the closing when no cell outside the dilation does; pad the array by
    ``radius + 1`` to close up to its edge), in time linear in the cells: the disk's cost grows
    with its area, so a 1 m disk at 0.05 m a cell took most of the set-up time of a 5,000 x 5,000
    map (docs/benchmarks.md, "Large maps").

    >>> m = np.zeros((7, 11), bool); m[2:5, 2:5] = m[2:5, 6:9] = True
    >>> closing_disk(m, 1)[3].astype(int).tolist()   # the one-cell gap is closed
    [0, 0, 1, 1, 1, 1, 1, 1, 1, 0, 0]
    """
    m = np.asarray(mask, dtype=bool)
    r = int(radius)
    if r <= 0 or not m.any():
        return m.copy()
    h, w = m.shape
    out = np.zeros((h, w), dtype=bool)
    for r0 in range(0, h, CLOSING_TILE):
        for c0 in range(0, w, CLOSING_TILE):
            _close_tile(m, r, (r0, c0, min(r0 + CLOSING_TILE, h), min(c0 + CLOSING_TILE, w)), out)
    return out


#: Side of the tiles :func:`closing_disk` works on, cells: its distance transforms are a tile's
#: and its margin's (float64 and scipy's int32 feature transform: 16 bytes a cell), not the map's.
CLOSING_TILE = 1024


def _close_tile(m: np.ndarray, r: int, tile, out: np.ndarray) -> None:
    """:func:`closing_disk` of the cells of ``tile`` ``(r0, c0, r1, c1)`` into ``out``. A cell of the
    dilation needs the mask within ``r`` of it, a cell of the closing the dilation within ``r``:
    the mask within ``2r`` of the tile decides it (a transform on a crop gives the whole array's
    distance wherever that distance is within the crop, and a larger one, also over ``r``,
    where it is not)."""
    h, w = m.shape
    r0, c0, r1, c1 = tile
    a0, b0, a1, b1 = max(r0 - 2 * r, 0), max(c0 - 2 * r, 0), min(r1 + 2 * r, h), min(c1 + 2 * r, w)
    crop = m[a0:a1, b0:b1]
    if not crop.any():       # no mask cell near: the tile is outside the dilation, so the closing
        return
    dilated = ndi.distance_transform_edt(~crop) <= r
    d0, e0, d1, e1 = max(r0 - r, 0), max(c0 - r, 0), min(r1 + r, h), min(c1 + r, w)
    near = dilated[d0 - a0:d1 - a0, e0 - b0:e1 - b0]
    inner = (slice(r0 - d0, r1 - d0), slice(c0 - e0, c1 - e0))
    if near.all():           # no cell outside the dilation within r: the whole tile is closed
        out[r0:r1, c0:c1] = True
        return
    out[r0:r1, c0:c1] = (ndi.distance_transform_edt(near) > r)[inner]


def default_roi(input_classes: np.ndarray, closing_radius_cells: int) -> np.ndarray:
    """Default region of interest: the known part of the map, closed, holes filled.

    Known cells are those that are not UNKNOWN. They are closed with a disk of the given radius
    (:func:`closing_disk`; the array is padded first so that the map border does not erode the
    result), and every hole (a region not connected to the map border) is filled.
    Every known cell is inside the ROI.

    Parameters
    ----------
    input_classes : np.ndarray of uint8, shape (H, W)
    closing_radius_cells : int
        Radius of the disk, in cells; the project's default is 1.0 m
        (``[evaluate] roi_closing_m``), i.e. 20 cells at 0.05 m.

    Returns
    -------
    np.ndarray of bool, shape (H, W)

    Examples
    --------
    Two known blocks separated by a one-cell unknown column: the disk of radius 1 (a cross)
    bridges the gap only in the middle row (there the gap cell's four neighbours are all in the
    dilation; in rows 1 and 3 the cell above or below is not); the unknown frame stays outside.

    >>> import numpy as np
    >>> c = np.array([[1, 1, 1, 1, 1, 1, 1],
    ...               [1, 0, 0, 1, 0, 0, 1],
    ...               [1, 2, 2, 1, 2, 2, 1],
    ...               [1, 0, 0, 1, 0, 0, 1],
    ...               [1, 1, 1, 1, 1, 1, 1]], dtype=np.uint8)
    >>> default_roi(c, 1).astype(int)[1:4].tolist()
    [[0, 1, 1, 0, 1, 1, 0], [0, 1, 1, 1, 1, 1, 0], [0, 1, 1, 0, 1, 1, 0]]
    """
    c = np.asarray(input_classes)
    _check_codes(c, 3, "input classes")
    known = c != UNKNOWN
    r = int(closing_radius_cells)
    if r < 0:
        raise ValueError(f"closing radius must be >= 0, got {closing_radius_cells}")
    bounds = mask_box(known)    # the known cells' bounding box (cells.known_box)
    if bounds is None:
        return ndi.binary_fill_holes(known)
    # Work on the known cells' bounding box: the closing of a set lies within its bounding box,
    # and a background region touching the box's edge reaches the map border around it, so the
    # result is the same as on the whole map (a ROS map's canvas is often mostly unknown).
    a0, b0, a1, b1 = bounds
    box = known[a0:a1, b0:b1]
    if r > 0:
        padded = np.pad(box, r + 1, mode="constant", constant_values=False)
        box = closing_disk(padded, r)[r + 1:-(r + 1), r + 1:-(r + 1)] | box
    out = np.zeros(known.shape, dtype=bool)
    out[a0:a1, b0:b1] = ndi.binary_fill_holes(box)
    return out


def load_roi(path: str | os.PathLike, shape: tuple[int, int]) -> np.ndarray:
    """Read a region-of-interest mask image: non-zero pixels are inside.

    For colour images a pixel is inside when any of R, G, B is non-zero (alpha is ignored).
    The image is in the input map's pixel frame (row 0 = top row of the image).

    Parameters
    ----------
    path : path-like
    shape : (int, int)
        (rows, cols) of the map the ROI belongs to.

    Returns
    -------
    np.ndarray of bool, shape ``shape``

    Raises
    ------
    MapError
        When the file cannot be read or its size differs from the map's.
    """
    image = read_image(path)
    if image.ndim == 3:
        channels = image[..., :1] if image.shape[2] == 2 else image[..., :3]
        mask = (channels != 0).any(axis=2)
    elif image.ndim == 2:
        mask = image != 0
    else:
        raise MapError(path, f"unexpected image shape {image.shape}")
    if mask.shape != tuple(shape):
        raise MapError(path, f"ROI mask is {mask.shape[1]}x{mask.shape[0]} pixels but the map is "
                             f"{shape[1]}x{shape[0]}")
    return mask
