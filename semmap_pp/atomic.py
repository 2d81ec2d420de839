"""Atomic file output: write to a temporary file in the same folder, then rename.

A reader (or a crash) sees either the previous complete file or the new complete one, never a
half-written file. A whole directory (:func:`atomic_dir`) is written in a temporary folder beside
it and renamed into place the same way.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import tempfile
from pathlib import Path
from typing import Iterator


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; on success rename it onto ``path``.

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
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    os.close(fd)
    os.chmod(tmp, 0o666 & ~_umask())  # mkstemp makes 0600; outputs get the usual permissions
    tmp_path = Path(tmp)
    try:
        yield tmp_path
        with open(tmp_path, "rb+") as fh:
            os.fsync(fh.fileno())
        os.replace(tmp_path, path)
    finally:
        if tmp_path.exists():
            tmp_path.unlink()


def write_bytes(path: str | os.PathLike, data: bytes) -> None:
    """Write ``data`` to ``path`` atomically."""
    with atomic_path(path) as tmp:
        tmp.write_bytes(data)


def write_text(path: str | os.PathLike, text: str) -> None:
    """Write ``text`` (UTF-8) to ``path`` atomically."""
    write_bytes(path, text.encode("utf-8"))


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
