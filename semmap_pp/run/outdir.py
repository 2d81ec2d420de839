"""An output folder held by one run at a time, with room for its files.

Every command that writes a folder of outputs (``semmap map``, ``edit``, ``compare``,
``stability``, ``batch``) takes :func:`lock_out_dir` on it before any sampling and holds it until
its files are written: a second run into the same folder is refused at once (``DIR is in use by
another semmap run (pid N); wait for it or choose another --out``), so the later run can neither
silently replace the earlier one's files nor delete its temporary files
(:func:`semmap_pp.outputs.write.remove_stale_temps` runs only under the lock).

The lock is ``fcntl.flock`` on ``DIR/.semmap.lock``, which holds the holder's pid. The kernel
releases it when the process ends however it ends, so a file left by a killed run never blocks
the next one: only a live holder does. The lock file is removed when the lock is released, and so
is a folder the lock created if the run wrote nothing into it.

:func:`check_free_space` refuses, before sampling, an output folder on a file system with less
than a small estimated minimum free (:func:`needed_bytes`).
"""

from __future__ import annotations

import contextlib
import errno
import os
import time
from pathlib import Path
from typing import Iterator

from semmap_pp.errors import BusyError, OutputError, SemmapError

LOCK_NAME = ".semmap.lock"
#: what every run's files take at least (report.html with its figures, trace.nc, resume.npz)
BASE_BYTES = 1 << 20
#: and per cell of the map (types.pgm alone is one byte per cell; the images and the report more)
BYTES_PER_CELL = 2


def needed_bytes(cells: int = 0) -> int:
    """The free space a run's files need at least: :data:`BASE_BYTES` and :data:`BYTES_PER_CELL`
    per map cell. An estimate from below: a run that needs more still fails in one line when
    the disk fills (:class:`~semmap_pp.errors.WriteError`), its complete files kept."""
    return BASE_BYTES + BYTES_PER_CELL * int(cells)


def _size(n: float) -> str:
    """A size in a message.

    >>> _size(12_288), _size(3 << 20)
    ('12 kB', '3.1 MB')
    """
    if n < 1e6:
        return f"{n / 1e3:.0f} kB"
    return f"{n / 1e6:.1f} MB" if n < 1e9 else f"{n / 1e9:.1f} GB"


def _nearest_existing(path: Path) -> Path:
    probe = path.absolute()
    while not probe.exists() and probe.parent != probe:
        probe = probe.parent
    return probe


def check_free_space(out: str | os.PathLike, need: int) -> None:
    """Refuse ``out`` when the file system it is (or would be) on has less than ``need`` bytes
    free for this user; a file system that cannot say is let through."""
    out = Path(out)
    try:
        st = os.statvfs(_nearest_existing(out))
    except (OSError, AttributeError):
        return
    free = st.f_bavail * st.f_frsize
    if free < need:
        raise OutputError(out, f"only {_size(free)} free on its file system, and the run's files need "
                               f"about {_size(need)}: free some space or choose another --out")


def _holder(fd: int) -> str:
    """The pid the holder wrote into the lock file (it writes it just after taking the lock)."""
    for _ in range(20):
        try:
            os.lseek(fd, 0, os.SEEK_SET)
            text = os.read(fd, 32).decode("ascii", "replace").strip()
        except OSError:
            text = ""
        if text.isdigit():
            return text
        time.sleep(0.01)
    return "unknown"


class OutLock:
    """The lock of one output folder (:func:`lock_out_dir`); release it with :meth:`release` or
    by leaving its ``with`` block."""

    def __init__(self, out: Path, fd: int | None, created: list[Path]):
        self.out, self.path, self._fd, self._created = out, out / LOCK_NAME, fd, created

    def release(self) -> None:
        """Remove the lock file and let the lock go; remove the folders the lock created when
        nothing was written into them. Safe to call twice."""
        if self._fd is None:
            return
        try:
            if os.path.samestat(os.fstat(self._fd), os.stat(self.path)):
                os.unlink(self.path)      # still ours: removed while held, so no one takes a stale copy
        except OSError:
            pass
        os.close(self._fd)
        self._fd = None
        _remove_empty(self._created)

    def __enter__(self) -> "OutLock":
        return self

    def __exit__(self, *exc) -> None:
        self.release()


def lock_out_dir(out: str | os.PathLike) -> OutLock:
    """Create ``out`` if missing and take its lock (never waiting).

    Raises
    ------
    BusyError
        When another live process holds it: ``OUT is in use by another semmap run (pid N); wait
        for it or choose another --out``.
    OutputError
        When the folder or its lock file cannot be made.
    """
    out = Path(out)
    created = []
    probe = out.absolute()
    while not probe.exists() and probe.parent != probe:
        created.insert(0, probe)
        probe = probe.parent
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OutputError(out, f"cannot create the output directory: {exc.strerror or exc}") from None
    path = out / LOCK_NAME
    fcntl = _fcntl()
    while True:
        try:
            fd = os.open(path, os.O_RDWR | os.O_CREAT | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_CLOEXEC", 0),
                         0o644)
        except OSError as exc:
            _remove_empty(created)
            raise OutputError(path, f"cannot create the lock file: {exc.strerror or exc}") from None
        if fcntl is None:
            break
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError as exc:
            if exc.errno not in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES):
                os.close(fd)
                _remove_empty(created)
                raise OutputError(path, f"cannot lock: {exc.strerror or exc}") from None
            pid = _holder(fd)
            os.close(fd)
            _remove_empty(created)
            raise BusyError(out, f"is in use by another semmap run (pid {pid}); wait for it or "
                                 f"choose another --out") from None
        try:                               # the holder before us may have removed it meanwhile
            same = os.path.samestat(os.fstat(fd), os.stat(path))
        except FileNotFoundError:
            same = False
        if same:
            break
        os.close(fd)
    lock = OutLock(out, fd, created)
    try:
        os.ftruncate(fd, 0)
        os.write(fd, f"{os.getpid()}\n".encode("ascii"))
    except OSError:
        pass                               # a full disk: the lock holds; the pid is only for messages
    return lock


def check_out_dir(out: Path, force: bool) -> None:
    """Refuse a non-empty output directory unless ``force``; refuse a file, a folder under a
    file, and one this user cannot write to (before any sampling, creating nothing). The lock
    file (:data:`LOCK_NAME`) does not count: a killed run may leave it behind."""
    if out.exists() and not out.is_dir():
        raise SemmapError(out, "output path exists and is not a directory")
    if out.is_dir() and any(p.name != LOCK_NAME for p in out.iterdir()) and not force:
        raise SemmapError(out, "output directory is not empty (use --force to overwrite)")
    probe = out.absolute()
    while not probe.exists():           # the nearest part of the path that exists
        probe = probe.parent
    if not probe.is_dir():
        raise SemmapError(out, f"cannot create the output directory: {probe} is not a directory")
    if not os.access(probe, os.W_OK | os.X_OK):
        raise SemmapError(out, f"cannot write the output directory: {probe} is not writable")


@contextlib.contextmanager
def claimed(out: str | os.PathLike | None, force: bool, need: int = BASE_BYTES) -> Iterator[OutLock | None]:
    """An output folder checked and held for a command's run: refused when it is not one to
    write (:func:`check_out_dir`: a file, not writable, not empty without
    ``force``), when its file system lacks ``need`` bytes, or when another run holds it; then
    locked (:func:`lock_out_dir`) and checked again under the lock. ``out`` None: nothing."""
    if out is None:
        yield None
        return
    out = Path(out)
    check_out_dir(out, force)
    check_free_space(out, need)
    with lock_out_dir(out) as lock:
        check_out_dir(out, force)       # a run that ended meanwhile may have filled it
        yield lock


def _remove_empty(created: list[Path]) -> None:
    """Remove the folders of ``created`` (outermost first in the list) that are empty, the
    deepest first."""
    for d in reversed(created):
        try:
            d.rmdir()
        except OSError:
            break


def _fcntl():
    try:
        import fcntl             # POSIX only: imported where a lock is taken, so Windows still runs
    except ImportError:                   # no flock (Windows): one run per folder is the user's care
        return None
    return fcntl


__all__ = ["LOCK_NAME", "check_out_dir", "BASE_BYTES", "BYTES_PER_CELL", "OutLock", "lock_out_dir", "claimed",
           "check_free_space", "needed_bytes"]
