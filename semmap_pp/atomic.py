"""Atomic file output: write to a temporary file in the same folder, then rename.

A reader (or a crash) sees either the previous complete file or the new complete one, never a
half-written file. Every output file of the package is written through :func:`write_bytes` (the
writers build the file's bytes in memory first), so a write that fails (a full disk, a quota, a
read-only file system) fails in one place: the temporary file is removed, the file under the final
name is untouched, and a :class:`~semmap_pp.errors.WriteError` says ``cannot write PATH: no space
left on device``. A whole directory (:func:`atomic_dir`) is written in a temporary folder beside
it and renamed into place the same way.
"""

from __future__ import annotations

import contextlib
import errno
import os
import shutil
import tempfile
from pathlib import Path
from typing import Callable, Iterator

from semmap_pp.errors import WriteError

#: Called before each file is written (:func:`write_bytes`, :func:`atomic_path`,
#: :func:`atomic_dir`), when set: a command's SIGINT handler raises KeyboardInterrupt wherever the
#: signal lands, and where that is a library object's ``__del__`` Python swallows the exception
#: (prints "Exception ignored" and goes on). The command sets this to a check that raises it again
#: for a Ctrl-C it has seen, so the writing stops before its next file.
before_write: Callable[[], None] | None = None


def _check_interrupt() -> None:
    if before_write is not None:
        before_write()


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def reason(exc: OSError) -> str:
    """The reason of an OSError in a message's words: ``no space left on device``.

    >>> reason(OSError(errno.ENOSPC, "No space left on device"))
    'no space left on device'
    """
    text = os.strerror(exc.errno) if exc.errno else (exc.strerror or str(exc) or type(exc).__name__)
    return text[:1].lower() + text[1:]


def _discard(tmp: str | os.PathLike) -> None:
    try:
        os.unlink(tmp)
    except OSError:
        pass


def _temporary(path: Path) -> tuple[int, str]:
    """An open temporary file ``.NAME.XXXXXXXX.tmp`` beside ``path``, with the usual permissions
    (mkstemp makes 0600)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        os.fchmod(fd, 0o666 & ~_umask())
    except BaseException:
        os.close(fd)
        _discard(tmp)
        raise
    return fd, tmp


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; on success rename it onto ``path``. For a library
    that writes a file by name only; an OSError while it writes is a WriteError.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> d = pathlib.Path(tempfile.mkdtemp())
    >>> with atomic_path(d / "a.txt") as tmp:
    ...     _ = tmp.write_text("hello")
    >>> (d / "a.txt").read_text()
    'hello'
    """
    path = Path(path)
    _check_interrupt()
    try:
        fd, tmp = _temporary(path)
        os.close(fd)
    except OSError as exc:
        raise WriteError(path, reason(exc)) from None
    tmp_path = Path(tmp)
    try:
        yield tmp_path
        with open(tmp_path, "rb+") as fh:
            os.fsync(fh.fileno())
        os.replace(tmp_path, path)
    except OSError as exc:
        raise WriteError(path, reason(exc)) from None
    finally:
        if tmp_path.exists():
            _discard(tmp_path)


def write_bytes(path: str | os.PathLike, data: bytes) -> None:
    """Write ``data`` to ``path`` atomically: a temporary file beside it, written whole and
    synced, then renamed onto ``path``.

    Raises
    ------
    WriteError
        When any step fails (``cannot write PATH: no space left on device``); the temporary file
        is removed and ``path`` is as it was.
    """
    path = Path(path)
    _check_interrupt()
    try:
        fd, tmp = _temporary(path)
    except OSError as exc:
        raise WriteError(path, reason(exc)) from None
    try:
        try:
            view = memoryview(data).cast("B")
            while view:
                n = os.write(fd, view)
                if n <= 0:       # a regular file that takes nothing more: the device is full
                    raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
                view = view[n:]
            os.fsync(fd)
        finally:
            os.close(fd)
        os.replace(tmp, path)
    except OSError as exc:
        _discard(tmp)
        raise WriteError(path, reason(exc)) from None
    except BaseException:      # Ctrl-C while writing: no temporary file left behind
        _discard(tmp)
        raise


def write_text(path: str | os.PathLike, text: str) -> None:
    """Write ``text`` (UTF-8) to ``path`` atomically. A lone surrogate (a byte of a file name that
    is not UTF-8, as Python keeps it) is written as the escape ``\\udcff``: JSON reads it back as
    the same name, a person sees where it was."""
    write_bytes(path, text.encode("utf-8", "backslashreplace"))


def _fsync_tree(top: Path) -> None:
    """fsync every file under ``top``, then each folder (their entries)."""
    for folder, _, files in os.walk(top):
        for name in files:
            with open(os.path.join(folder, name), "rb") as fh:
                os.fsync(fh.fileno())
        fd = os.open(folder, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)


@contextlib.contextmanager
def atomic_dir(path: str | os.PathLike) -> Iterator[Path]:
    """Yield a path, not yet existing, for the caller to make a whole directory at; on success it
    replaces ``path`` (a directory or file of that name, if any, goes).

    The path yielded is ``.NAME.XXXXXXXX.tmp/NAME`` beside ``path``: the same name, so a writer that
    names its files after their folder (a ROS 2 bag's ``NAME.mcap``) names them as at ``path``. Its
    files are synced, the old ``path`` is moved into the temporary folder, the new directory renamed
    onto ``path``, and the temporary folder removed. A failure or a crash leaves ``path`` as it was
    and at most the hidden temporary folder (:func:`semmap_pp.outputs.write.remove_stale_temps`
    deletes it on the next run into the folder).

    Examples
    --------
    >>> import tempfile, pathlib
    >>> d = pathlib.Path(tempfile.mkdtemp())
    >>> for text in ("one", "two"):
    ...     with atomic_dir(d / "bag") as tmp:
    ...         tmp.mkdir()
    ...         _ = (tmp / "data.txt").write_text(text)
    >>> (d / "bag" / "data.txt").read_text(), sorted(p.name for p in d.iterdir())
    ('two', ['bag'])
    """
    path = Path(path)
    _check_interrupt()
    path.parent.mkdir(parents=True, exist_ok=True)
    holder = Path(tempfile.mkdtemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent))
    try:
        new = holder / path.name
        yield new
        if not new.is_dir():
            raise FileNotFoundError(f"{new} was not made")
        os.chmod(new, 0o777 & ~_umask())
        _fsync_tree(new)
        if path.exists() or path.is_symlink():
            os.replace(path, holder / ".old")
        os.replace(new, path)
    finally:
        shutil.rmtree(holder, ignore_errors=True)
