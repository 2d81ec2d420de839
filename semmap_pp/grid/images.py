"""Decoding map images into grey levels (0..255 scale) and an optional alpha channel.

PGM (P2 plain and P5 binary, any maxval 1..65535) is parsed here, so that 16-bit samples,
odd maxvals and truncated files are handled exactly; every other image format goes through
Pillow. ``.npy`` arrays are read with ``allow_pickle=False``. Every failure raises
:class:`~semmap_pp.errors.MapError` naming the file. The size is checked against ``max_cells``
from the header alone, before any pixel is decoded.
"""

from __future__ import annotations

import struct
import tokenize
import warnings
import zlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from PIL import Image

from semmap_pp.errors import MapError

# Refuse images with more cells than this unless the caller raises the limit (about 1 GB of work
# arrays; the largest real floor maps are a few million cells).
MAX_CELLS = 100_000_000

NPY_MAGIC = b"\x93NUMPY"
_WHITESPACE = b" \t\r\n\v\f"


@dataclass(frozen=True)
class Decoded:
    """A decoded map image: grey levels on the 0..255 scale, alpha (or None), a description."""

    grey: np.ndarray          # float64 [H, W], mean of the colour channels
    alpha: np.ndarray | None  # uint8 [H, W] or None
    description: str          # e.g. "PGM P5 16-bit (maxval 65535)"


def check_file(path: Path, what: str = "image") -> None:
    """Raise MapError unless ``path`` is an existing regular file."""
    if not path.exists():
        raise MapError(path, f"{what} file does not exist")
    if path.is_dir():
        raise MapError(path, f"{what} path is a directory, not a file")
    if not path.is_file():
        raise MapError(path, f"{what} path is not a regular file")


def _check_size(path: Path, width: int, height: int, max_cells: int) -> None:
    if width <= 0 or height <= 0:
        raise MapError(path, f"image has no cells ({width}x{height})")
    if width * height > max_cells:
        raise MapError(path, f"image is {width}x{height} = {width * height} cells, more than the "
                             f"limit of {max_cells} cells")


def decode_image(path: Path, *, max_cells: int = MAX_CELLS) -> Decoded:
    """Decode the map image at ``path`` (PGM, ``.npy`` or anything Pillow reads).

    The format is recognised from the file's first bytes, not its name.
    """
    check_file(path)
    try:
        with open(path, "rb") as fh:
            magic = fh.read(6)
    except OSError as exc:
        raise MapError(path, f"cannot read image: {exc.strerror or exc}") from exc
    if magic[:2] in (b"P2", b"P5") and (len(magic) < 3 or magic[2:3] in _WHITESPACE + b"#"):
        return decode_pgm(path, max_cells=max_cells)
    if magic == NPY_MAGIC:
        return decode_npy(path, max_cells=max_cells)
    return decode_pillow(path, max_cells=max_cells)


# --- PGM ---------------------------------------------------------------------------------------

def _header_tokens(data: bytes, path: Path, count: int) -> tuple[list[int], int]:
    """The first ``count`` integers after the magic number, and the offset just past the last one."""
    tokens: list[int] = []
    i, n = 2, len(data)
    while len(tokens) < count:
        while i < n and data[i] in _WHITESPACE:
            i += 1
        if i < n and data[i] == ord("#"):
            while i < n and data[i] not in b"\r\n":
                i += 1
            continue
        start = i
        while i < n and data[i] not in _WHITESPACE and data[i] != ord("#"):
            i += 1
        if start == i:
            raise MapError(path, "truncated PGM header (expected width, height and maxval)")
        token = data[start:i]
        if not token.isdigit():
            raise MapError(path, f"bad PGM header: {token[:20].decode('latin-1')!r} is not a "
                                 f"non-negative integer")
        tokens.append(int(token))
    return tokens, i


def decode_pgm(path: Path, *, max_cells: int = MAX_CELLS) -> Decoded:
    """Decode a PGM file (P2 plain or P5 binary; maxval 1..65535, scaled to 0..255)."""
    try:
        with open(path, "rb") as fh:
            head = fh.read(4096)
            # Comments can make a header long; read on until three numbers are in.
            while True:
                try:
                    (width, height, maxval), end = _header_tokens(head, path, 3)
                    break
                except MapError:
                    more = fh.read(65536)
                    if not more or len(head) > 1 << 20:
                        raise
                    head += more
            magic = head[:2]
            _check_size(path, width, height, max_cells)
            if not 1 <= maxval <= 65535:
                raise MapError(path, f"PGM maxval must be 1..65535, got {maxval}")
            # Exactly one whitespace character separates the header from the raster.
            if end < len(head) and head[end] not in _WHITESPACE:
                raise MapError(path, "bad PGM header: no whitespace after maxval")
            fh.seek(end + 1)
            rest = fh.read()
    except OSError as exc:
        raise MapError(path, f"cannot read image: {exc.strerror or exc}") from exc

    cells = width * height
    depth = 2 if maxval > 255 else 1
    bits = "16-bit" if depth == 2 else "8-bit"
    if magic == b"P5":
        need = cells * depth
        if len(rest) < need:
            raise MapError(path, f"truncated PGM: header says {width}x{height} {bits} pixels "
                                 f"({need} bytes) but only {len(rest)} bytes follow")
        samples = np.frombuffer(rest, dtype=">u2" if depth == 2 else np.uint8, count=cells)
        kind = "P5"
    else:
        samples = _plain_samples(rest, path, cells)
        kind = "P2"
    if samples.max(initial=0) > maxval:
        raise MapError(path, f"PGM sample value {int(samples.max())} exceeds maxval {maxval}")
    grey = samples.astype(np.float64).reshape(height, width)
    if maxval != 255:
        grey *= 255.0 / maxval
    return Decoded(grey, None, f"PGM {kind} {bits} (maxval {maxval})")


def _plain_samples(text: bytes, path: Path, cells: int) -> np.ndarray:
    lines = [line.split(b"#", 1)[0] for line in text.splitlines()]
    tokens = b" ".join(lines).split()[:cells]
    if len(tokens) < cells:
        raise MapError(path, f"truncated PGM: header says {cells} pixels but only "
                             f"{len(tokens)} values follow")
    bad = next((t for t in tokens if not t.isdigit() or len(t) > 5), None)
    if bad is not None:
        raise MapError(path, f"bad plain PGM sample {bad[:20].decode('latin-1')!r}")
    return np.array([int(t) for t in tokens], dtype=np.int64)


# --- Pillow ------------------------------------------------------------------------------------

_PILLOW_ERRORS = (OSError, SyntaxError, ValueError, EOFError, zlib.error, struct.error,
                  IndexError, TypeError)


def decode_pillow(path: Path, *, max_cells: int = MAX_CELLS) -> Decoded:
    """Decode an image with Pillow (PNG modes 1, L, I;16, I, LA, RGB, RGBA, P, PA, ...)."""
    try:
        with warnings.catch_warnings():
            # The size is checked against max_cells below; Pillow's own warning adds nothing.
            warnings.simplefilter("ignore", Image.DecompressionBombWarning)
            with Image.open(path) as im:
                width, height = im.size
                _check_size(path, width, height, max_cells)
                im.load()
                return _from_pillow(im, path)
    except MapError:
        raise
    except Image.DecompressionBombError:
        # Pillow refuses before reading the size out to us; PNG headers are easy to read here.
        size = _png_size(path)
        if size is not None:
            _check_size(path, *size, max_cells)
        raise MapError(path, f"image is larger than Pillow decodes safely "
                             f"({2 * Image.MAX_IMAGE_PIXELS} pixels)") from None
    except Image.UnidentifiedImageError:
        size = _png_size(path)  # Pillow does not identify a PNG of 0 columns or rows
        if size is not None:
            _check_size(path, *size, max_cells)
        raise MapError(path, "not an image file that can be read (unknown or damaged format)") from None
    except MemoryError:
        raise MapError(path, "not enough memory to decode the image") from None
    except _PILLOW_ERRORS as exc:
        message = str(exc) or type(exc).__name__
        raise MapError(path, f"damaged or truncated image: {message}") from None


def _png_size(path: Path) -> tuple[int, int] | None:
    """``(width, height)`` from a PNG's IHDR chunk, or None if the file is not a PNG."""
    with open(path, "rb") as fh:
        head = fh.read(24)
    if len(head) == 24 and head[:8] == b"\x89PNG\r\n\x1a\n" and head[12:16] == b"IHDR":
        return struct.unpack(">II", head[16:24])
    return None


def _from_pillow(im: Image.Image, path: Path) -> Decoded:
    fmt = im.format or "image"
    mode = im.mode
    if mode in ("I;16", "I;16B", "I;16L", "I;16N", "I"):
        a = np.asarray(im).astype(np.float64)
        if mode == "I" and (a.min(initial=0) < 0 or a.max(initial=0) > 65535):
            raise MapError(path, f"{fmt} mode I image holds values outside 0..65535")
        return Decoded(a * (255.0 / 65535.0), None, f"{fmt} {mode} 16-bit")
    if mode == "F":
        raise MapError(path, f"{fmt} image of floating-point mode F is not supported")
    if mode == "P":
        has_alpha = "transparency" in im.info
        im = im.convert("RGBA" if has_alpha else "RGB")
    elif mode == "1":
        im = im.convert("L")
    elif mode in ("PA", "La", "RGBa"):
        im = im.convert("RGBA" if mode != "La" else "LA")
    elif mode not in ("L", "LA", "RGB", "RGBA"):
        try:
            im = im.convert("RGB")
        except _PILLOW_ERRORS:
            raise MapError(path, f"{fmt} image of mode {mode} is not supported") from None
    a = np.asarray(im)
    if a.ndim == 2:
        return Decoded(a.astype(np.float64), None, f"{fmt} {mode} 8-bit")
    if im.mode in ("LA", "RGBA"):
        colour, alpha = a[..., :-1], np.ascontiguousarray(a[..., -1])
    else:
        colour, alpha = a, None
    return Decoded(colour.astype(np.float64).mean(axis=-1), alpha, f"{fmt} {mode} 8-bit")


# --- .npy --------------------------------------------------------------------------------------

_NPY_HEADER_ERRORS = (ValueError, OSError, EOFError, SyntaxError, TypeError, RecursionError,
                      tokenize.TokenError)

def decode_npy(path: Path, *, max_cells: int = MAX_CELLS) -> Decoded:
    """Decode a 2-D ``.npy`` array.

    uint8 is read as grey levels (like a PGM), uint16 as grey levels with maxval 65535, a float
    array as occupancy probabilities in [0, 1] (NaN = unknown; grey = 255 * (1 - p)), a bool array
    as an occupied mask (True occupied, False free).
    """
    check_file(path)
    try:
        header = np.load(path, mmap_mode="r", allow_pickle=False)
    except _NPY_HEADER_ERRORS as exc:  # numpy parses the header with tokenize and literal_eval
        raise MapError(path, f"not a readable .npy array: {str(exc)[:200]}") from None
    except SystemError:     # CPython 3.12.1's tokenizer, given null bytes, can leave its error set
        raise MapError(path, "not a readable .npy array: its header does not parse") from None
    shape, dtype = header.shape, header.dtype
    if len(shape) != 2:
        raise MapError(path, f".npy array must be 2-D (rows, cols), got shape {shape}")
    _check_size(path, shape[1], shape[0], max_cells)
    try:
        a = np.array(header)
    except (ValueError, OSError) as exc:
        raise MapError(path, f"truncated or damaged .npy array: {exc}") from None
    finally:
        del header
    if dtype == np.bool_:
        grey = np.where(a, 0.0, 255.0)
        return Decoded(grey, None, "NPY bool (True occupied)")
    if dtype == np.uint8:
        return Decoded(a.astype(np.float64), None, "NPY uint8 grey")
    if dtype == np.uint16:
        return Decoded(a.astype(np.float64) * (255.0 / 65535.0), None, "NPY uint16 grey")
    if np.issubdtype(dtype, np.floating):
        p = a.astype(np.float64)
        finite = np.isfinite(p)
        if finite.any() and (p[finite].min() < 0.0 or p[finite].max() > 1.0):
            raise MapError(path, "float .npy array must hold occupancy probabilities in [0, 1] "
                                 "(NaN for unknown)")
        if np.isinf(p).any():
            raise MapError(path, "float .npy array holds infinite values")
        grey = 255.0 * (1.0 - p)
        alpha = np.where(finite, 255, 0).astype(np.uint8) if not finite.all() else None
        return Decoded(grey, alpha, "NPY float occupancy")
    raise MapError(path, f".npy array of dtype {dtype} is not supported "
                         "(use uint8, uint16, float or bool)")
