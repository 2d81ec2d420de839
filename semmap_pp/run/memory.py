"""The memory a run will need, estimated before it starts, and the check against ``--max-memory``.

A run's peak resident set size follows three sizes of its map: the lattice's cells (the
likelihood's prefix sums while they are made: about 24 bytes a cell for a moment; the kernels' and
the likelihood's tables themselves are mapped from files, :mod:`semmap_pp.run.shared`, and only
the pages read are resident), the input image's cells (the outputs that are images of the input:
rooms.png's flood holds 16 bytes a pixel) and the known cells (what the units cover, the pages of
the tables they read, the knowledge engine's networks that grow with the units).
:func:`estimate_peak_bytes` is a linear bound fitted to `bench/run.py large`'s whole runs
(docs/benchmarks.md, "Whole runs against known cells") with a margin: the peak of the run's
largest process, as ``/usr/bin/time -v`` reports it (the chains' worker processes map the same
tables; they do not copy them).

>>> estimate_peak_bytes(lattice_cells=0, image_cells=0, known_cells=0) == BASE_BYTES
True
>>> parse_size("2G"), parse_size("1500M"), parse_size("123")
(2147483648, 1572864000, 123)
"""

from __future__ import annotations

import contextlib
import ctypes
import gc
import os
import re

import numpy as np

from semmap_pp.cells import UNKNOWN
from semmap_pp.errors import MapError

#: The interpreter with numpy, scipy, numba, PyMC and ArviZ imported, bytes.
BASE_BYTES = 500 * 2**20
#: Bytes per lattice cell at the peak (the likelihood's prefix sums being made, the lattice itself).
PER_LATTICE_CELL = 16
#: Bytes per input image cell at the peak (the outputs of the input's size).
PER_IMAGE_CELL = 10
#: Bytes per known cell at the peak (the units, the table pages they read, the knowledge engine).
PER_KNOWN_CELL = 570


def estimate_peak_bytes(*, lattice_cells: int, image_cells: int, known_cells: int) -> int:
    """The estimated peak resident set size of ``semmap map`` on a map of these sizes, bytes."""
    return int(BASE_BYTES + PER_LATTICE_CELL * lattice_cells + PER_IMAGE_CELL * image_cells
               + PER_KNOWN_CELL * known_cells)


def trim_heap() -> bool:
    """Give the C heap's free memory back to the system (glibc's ``malloc_trim``); whether it could.

    numpy's arrays under glibc's mmap threshold (which rises to 32 MiB once a larger array is
    freed) come from the heap, and the heap keeps what they freed: after the middle floor's search
    of docs/benchmarks.md 94 MiB, resident through the outputs that follow. Elsewhere
    (another C library, no ``libc.so.6``) nothing is done.
    """
    try:
        libc = ctypes.CDLL("libc.so.6")
        return bool(libc.malloc_trim(0))
    except (OSError, AttributeError):
        return False


@contextlib.contextmanager
def young_heap():
    """A stage of a run whose garbage collections should read only the objects it makes: the
    objects alive before it are set aside from the collector (:func:`gc.freeze`, after a
    collection of those not set aside yet) and handed back when the outermost such stage ends
    (:func:`gc.unfreeze`, which hands back whatever was frozen), on an error or Ctrl-C too.

    ``semmap map`` runs in one (the modules imported and the inputs set aside: the chains'
    processes, forked from it, do not read them either) and writes its outputs in another inside
    it (the search's objects set aside too). Each full collection otherwise read the whole heap:
    0.1-0.2 s on a real floor, and the figures ask for one each
    (:func:`semmap_pp.outputs.figures.png`). What a stage makes, the figures' cycles among it, is
    as young as the stage and collected all the same."""
    gc.collect()
    gc.freeze()
    _depth[0] += 1
    try:
        yield
    finally:
        _depth[0] -= 1
        if not _depth[0]:
            gc.unfreeze()


#: How many :func:`young_heap` stages are open (the outermost one hands the heap back).
_depth = [0]


def machine_memory_bytes() -> int | None:
    """The machine's physical memory, bytes (None where the system does not say)."""
    try:
        return int(os.sysconf("SC_PHYS_PAGES")) * int(os.sysconf("SC_PAGE_SIZE"))
    except (AttributeError, ValueError, OSError):
        return None


_SIZE = re.compile(r"^\s*(\d+(?:\.\d+)?)\s*([kKmMgGtT]?)(?:i?[bB])?\s*$")


def parse_size(text: str) -> int:
    """Bytes of a size such as ``2G``, ``1.5GB``, ``800M``, ``800MiB`` or ``123`` (binary units)."""
    m = _SIZE.match(str(text))
    if m is None:
        raise ValueError(f"not a size: {text!r} (e.g. 2G, 800M)")
    return int(float(m.group(1)) * 1024 ** "_KMGT".index(m.group(2).upper() or "_"))


def gib(n: int) -> str:
    """``n`` bytes in GB (GiB), one decimal."""
    return f"{n / 2**30:.1f} GB"


def check_memory(inputs, max_bytes: int | None) -> int:
    """The estimated peak of a run on ``inputs`` (:class:`~semmap_pp.run.inputs.Inputs`);
    raises :class:`~semmap_pp.errors.MapError` naming the map when it exceeds ``max_bytes`` (None:
    the machine's memory; no check where that is unknown)."""
    grid, frame = inputs.grid, inputs.frame
    known = int(np.count_nonzero(np.asarray(grid.classes) != UNKNOWN))
    h, w = frame.shape
    need = estimate_peak_bytes(lattice_cells=h * w, image_cells=grid.width * grid.height, known_cells=known)
    limit = machine_memory_bytes() if max_bytes is None else int(max_bytes)
    if limit is not None and need > limit:
        what = "--max-memory" if max_bytes is not None else "the machine's memory"
        raise MapError(grid.source, f"the run would need about {gib(need)} at its peak (estimated from its "
                                    f"{h * w / 1e6:.1f} M lattice cells, {grid.width * grid.height / 1e6:.1f} M "
                                    f"image cells and {known / 1e6:.2f} M known cells; docs/cli.md), more than "
                                    f"{what} ({gib(limit)}); crop the map to its known part (semmap crop) or "
                                    f"raise --max-memory")
    return need
