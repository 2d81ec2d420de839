"""Where numba keeps the compiled code of semmap_pp, keyed by the package's source.

numba's on-disk cache (``@numba.njit(cache=True)``) is checked against the source file of each
compiled function only: when a compiled function calls a compiled function of *another* module,
or reads a constant of another module, a change there is not noticed and the stale machine code
is loaded (numba documents this limit). semmap_pp's compiled code spans several modules (the
likelihood's category layout is read by the posterior's compiled scorer), so an edited or
upgraded package could run old code against new data. :func:`configure` therefore points numba's
cache at ``<cache>/semmap_pp/numba/<digest>``, where the digest covers the source of every module
of the package: any change of the source selects a fresh, empty cache.

It is called from ``semmap_pp/__init__.py`` before any module defines a compiled function. An
explicit ``NUMBA_CACHE_DIR`` of the user is kept as it is. ``SEMMAP_NUMBA_CACHE=off`` leaves
numba's own default (the ``__pycache__`` folders beside the source); ``SEMMAP_NUMBA_CACHE=DIR``
uses ``DIR/<digest>``.

Each source (each installed or edited version) gets a folder of its own, 4–17 MB; so that upgrades
do not pile them up, :func:`configure` marks the current folder as used and deletes sibling digest
folders (16 hex digits; nothing else is touched) unused for :data:`MAX_AGE_DAYS` days.
"""

from __future__ import annotations

import hashlib
import os
import re
import shutil
import sys
import tempfile
import time
from pathlib import Path

ENV = "SEMMAP_NUMBA_CACHE"
PACKAGE_DIR = Path(__file__).resolve().parent
MAX_AGE_DAYS = 30
_DIGEST = re.compile(r"[0-9a-f]{16}")


def source_digest(package_dir: str | os.PathLike = PACKAGE_DIR) -> str:
    """16 hex digits of SHA-256 over the relative path and bytes of every ``*.py`` file, sorted.

    >>> import tempfile
    >>> d = Path(tempfile.mkdtemp()); _ = (d / "a.py").write_text("x = 1")
    >>> one = source_digest(d); _ = (d / "a.py").write_text("x = 2")
    >>> one != source_digest(d) and len(one) == 16
    True
    """
    root = Path(package_dir)
    h = hashlib.sha256()
    for path in sorted(root.rglob("*.py")):
        h.update(path.relative_to(root).as_posix().encode())
        h.update(b"\0")
        h.update(path.read_bytes())
        h.update(b"\0")
    return h.hexdigest()[:16]


def cache_home(environ=os.environ) -> Path:
    """``$XDG_CACHE_HOME/semmap_pp`` (default ``~/.cache/semmap_pp``): where the package's caches
    on disk live (this numba cache, the knowledge template store)."""
    home = environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(home) / "semmap_pp"


def cache_dir(environ=os.environ, package_dir: str | os.PathLike = PACKAGE_DIR) -> Path | None:
    """The numba cache directory for this source, or None to leave numba's own choice."""
    if environ.get("NUMBA_CACHE_DIR"):
        return None
    setting = environ.get(ENV, "")
    if setting.lower() in ("off", "0", "false", "no"):
        return None
    if setting:
        base = Path(setting).expanduser()
    else:
        base = cache_home(environ) / "numba"
    return base / source_digest(package_dir)


def prune(current: Path, max_age_days: float = MAX_AGE_DAYS, now: float | None = None) -> list[Path]:
    """Delete the digest folders beside ``current`` not modified for ``max_age_days``; return them.

    Only folders named like a digest (16 hex digits) are candidates, and never ``current``; a
    folder another version is using is touched by that version's :func:`configure` at each start,
    so it stays young. Errors (a folder vanishing meanwhile, no permission) are ignored.
    """
    now = time.time() if now is None else now
    gone = []
    try:
        siblings = list(current.parent.iterdir())
    except OSError:
        return gone
    for d in siblings:
        try:
            if (d.name == current.name or not _DIGEST.fullmatch(d.name) or not d.is_dir()
                    or d.is_symlink() or now - d.stat().st_mtime < max_age_days * 86400):
                continue
            shutil.rmtree(d)
            gone.append(d)
        except OSError:
            continue
    return gone


def untrusted(path: Path, stop: Path | None = None) -> str | None:
    """Why ``path`` (and each parent up to ``stop``, included) cannot be trusted with code this
    process will load: not owned by this user, or writable by the group or others; None if it can.

    >>> import tempfile
    >>> d = Path(tempfile.mkdtemp()); (d / "x").mkdir(mode=0o700)
    >>> untrusted(d / "x", stop=d) is None or os.stat(d).st_mode & 0o022 != 0
    True
    >>> os.chmod(d / "x", 0o777); untrusted(d / "x", stop=d).endswith("writable by other users (mode 777)")
    True
    """
    if not hasattr(os, "getuid"):      # no POSIX owners (Windows): nothing to check against
        return None
    uid = os.getuid()
    p = path
    while True:
        st = os.stat(p)
        if st.st_uid != uid:
            return f"{p} belongs to another user (uid {st.st_uid})"
        if st.st_mode & 0o022:
            return f"{p} is writable by other users (mode {st.st_mode & 0o777:o})"
        if stop is None or p == stop or p.parent == p:
            return None
        p = p.parent


def configure(environ=os.environ) -> Path | None:
    """Point numba's cache at :func:`cache_dir` (if it can be created); return the directory used.

    Works whether or not numba is imported already: the variable is read by numba at import, and
    ``numba.config.CACHE_DIR`` when a compiled function is defined.
    """
    try:
        path = cache_dir(environ)
        if path is None:
            return None
        path.mkdir(parents=True, exist_ok=True, mode=0o700)
        if not os.access(path, os.W_OK):
            return None
        why = untrusted(path, stop=path.parent.parent)
        if why is not None:
            # numba's index files are pickles: a folder another user can write to could make this
            # process run their code. Compile into a private folder instead (slower, never theirs).
            private = Path(tempfile.mkdtemp(prefix="semmap-numba-"))
            print(f"note: numba cache {path} not used ({why}); compiling into {private}",
                  file=sys.stderr)
            path = private
        else:
            os.utime(path)  # in use: keeps it young for prune()
            prune(path)
    except OSError:
        return None  # unreadable source or unwritable cache: numba's default (see above)
    environ["NUMBA_CACHE_DIR"] = str(path)
    numba = sys.modules.get("numba")
    if numba is not None:
        numba.config.CACHE_DIR = str(path)
    return path


__all__ = ["ENV", "MAX_AGE_DAYS", "source_digest", "cache_home", "cache_dir", "prune", "configure",
           "untrusted"]
