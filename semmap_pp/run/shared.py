"""Read-only arrays a run shares with its chains' processes instead of copying them.

The lattice-sized tables of a run (the kernels' line prefix sums and free-run lengths, the
likelihood's codes and prefix sums: 40 bytes per lattice cell) are built once in the main process,
then written as ``.npy`` files into the run's temporary folder and mapped into memory read-only
(:func:`share`). A mapped array pickles as its file's path, so a chain's process (started by
``pm.sample``, which pickles the step and the target's factory) maps the same file instead of
receiving a copy, and every process holds in memory only the pages it reads: those of the cells
near the units, not the unknown canvas around a campus floor's known band (each file is dropped
from the page cache once written and mapped without read-ahead, so that a process maps the
pages it reads, not those around them). The values, dtypes and
shapes are those of the arrays given: nothing a kernel or the likelihood computes changes.

>>> import tempfile
>>> folder = tempfile.mkdtemp()
>>> a = share(np.arange(6, dtype=np.int32).reshape(2, 3), folder)
>>> type(a).__name__, a.dtype.name, a.flags.writeable, a[1].tolist()
('SharedArray', 'int32', False, [3, 4, 5])
>>> import pickle
>>> b = pickle.loads(pickle.dumps(a))         # a path travels, not the values
>>> len(pickle.dumps(a)) < 200, b.tolist() == a.tolist(), share(a, folder) is a
(True, True, True)
>>> type(pickle.loads(pickle.dumps(a[:, 1:]))).__name__   # a view is pickled as an ordinary copy
'ndarray'
"""

from __future__ import annotations

import dataclasses
import itertools
import mmap
import os
import shutil
import tempfile
from contextlib import contextmanager
from pathlib import Path

import numpy as np

_COUNTER = itertools.count()


class SharedArray(np.ndarray):
    """A read-only array mapped from a ``.npy`` file; pickled as the file's path (see the module).

    Views and results of it are ordinary arrays when pickled (their values are copied)."""

    _path: str | None = None

    def __array_finalize__(self, obj) -> None:
        self._path = None

    def __reduce__(self):
        if self._path is None or not os.path.exists(self._path):
            return np.asarray(self).copy().__reduce__()
        return (open_shared, (self._path,))


def open_shared(path: str) -> SharedArray:
    """The array of the ``.npy`` file ``path``, mapped into memory read-only, its pages read one at
    a time when first touched (``MADV_RANDOM``: no read-ahead of the pages around)."""
    mapped = np.load(path, mmap_mode="r")
    advise = getattr(mmap, "MADV_RANDOM", None)
    if advise is not None and getattr(mapped, "_mmap", None) is not None:
        try:
            mapped._mmap.madvise(advise)
        except (OSError, ValueError):   # a system without it: the same values, more pages resident
            pass
    view = np.asarray(mapped).view(SharedArray)
    view._path = str(path)
    return view


def _drop_cached(path: Path) -> None:
    """Write ``path`` to disk and drop it from the page cache: a page a process maps is then read
    when the process touches it, not mapped with the cached pages around it (the kernel's
    fault-around: 16 pages a fault, so a column of a table read down its rows mapped every row
    whole). Where the system cannot, the pages stay cached: the same values."""
    if not hasattr(os, "posix_fadvise"):
        return
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
        os.posix_fadvise(fd, 0, 0, os.POSIX_FADV_DONTNEED)
    except OSError:
        pass
    finally:
        os.close(fd)


def share(array: np.ndarray, folder: str | os.PathLike | None) -> np.ndarray:
    """``array`` written into ``folder`` and mapped from there (:class:`SharedArray`); an array
    already mapped from a file of ``folder`` is returned as it is, and so is ``array`` where there
    is no folder or the file cannot be written (a full disk: the run holds and copies its tables
    as an ordinary array, with the same values)."""
    if folder is None:
        return array
    folder = Path(folder)
    if isinstance(array, SharedArray) and array._path is not None and Path(array._path).parent == folder:
        return array
    path = folder / f"{os.getpid()}-{next(_COUNTER)}.npy"
    try:
        np.save(path, np.ascontiguousarray(array), allow_pickle=False)
        _drop_cached(path)
        return open_shared(str(path))
    except OSError:
        path.unlink(missing_ok=True)
        return array


def share_fields(obj, names, folder: str | os.PathLike | None):
    """A copy of ``obj`` (a NamedTuple or a dataclass) with its arrays ``names`` shared (:func:`share`)."""
    new = {name: share(getattr(obj, name), folder) for name in names}
    if dataclasses.is_dataclass(obj):
        return dataclasses.replace(obj, **new)
    return obj._replace(**new)


@contextmanager
def shared_folder(path: str | None = None):
    """A temporary folder for a run's shared arrays, removed when the run ends (the processes that
    mapped a file keep it until they unmap it; the run's chains have all ended by then); ``path``:
    one made already (by an outer ``shared_folder``, whose process began using it earlier), removed
    here, when this one ends."""
    if path is None:
        try:
            path = tempfile.mkdtemp(prefix="semmap-arrays-")
        except OSError:          # no temporary folder to write: the tables stay ordinary arrays
            yield None
            return
    try:
        yield path
    finally:
        shutil.rmtree(path, ignore_errors=True)


__all__ = ["SharedArray", "open_shared", "share", "share_fields", "shared_folder"]
