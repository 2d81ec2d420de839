"""Cache and config folders that can be written, or a private one for this run.

pytensor (``~/.pytensor``), numba and the knowledge templates (``$XDG_CACHE_HOME``, by default
``~/.cache``: :mod:`semmap_pp.jitcache`) and matplotlib (``~/.config/matplotlib``) each want a
folder they can write, derived from HOME unless a variable names one (``PYTENSOR_FLAGS``'s
``base_compiledir`` or ``compiledir``, ``XDG_CACHE_HOME``, ``NUMBA_CACHE_DIR``, ``MPLCONFIGDIR``).
When HOME does not exist, is not a folder or cannot be written, pytensor stops with a traceback
once sampling begins, and the others would create the missing HOME tree.

:func:`configure` runs when the package is imported, before any of them is: it checks each folder
(a folder the user named may be created; a missing HOME is never created), and points the ones
that cannot be used at a private temporary folder (mode 0700, removed at exit) with a one-line
note on stderr. The run then works as usual, but compiles its code afresh: nothing is kept for
the next run. Children (sampling processes, ``semmap batch``'s runs) inherit the variables.
"""

from __future__ import annotations

import atexit
import os
import shutil
import sys
import tempfile
from pathlib import Path


def _exists(p: Path) -> bool:
    try:
        return p.exists()
    except OSError:          # a name too long, a loop of links: not there for our purpose
        return False


def unusable(path: Path, home: Path | None = None) -> str | None:
    """Why ``path`` cannot be a folder this process writes (None if it can): it, or the nearest
    part of it that exists, is not a folder or not writable, or making it would create ``home``.

    >>> import tempfile
    >>> d = Path(tempfile.mkdtemp())
    >>> unusable(d / "a" / "b") is None, unusable(d / "home" / ".cache", home=d / "home") == f"HOME {d / 'home'} does not exist"
    (True, True)
    """
    probe = path
    while not _exists(probe):
        if home is not None and probe == home:
            return f"HOME {home} does not exist"
        if probe.parent == probe:
            return f"{path} cannot be made"
        probe = probe.parent
    what = f"HOME {probe}" if home is not None and probe == home else str(probe)
    if not probe.is_dir():
        return f"{what} is not a folder"
    if not os.access(probe, os.W_OK | os.X_OK):
        return f"{what} is not writable"
    return None


def _pytensor_flags(text: str) -> list[tuple[str, str]]:
    """``PYTENSOR_FLAGS`` as (key, value) pairs (``key=value`` separated by commas)."""
    pairs = []
    for item in text.split(","):
        if item.strip():
            key, _, value = item.partition("=")
            pairs.append((key.strip(), value.strip()))
    return pairs


def _folders(environ, home: Path) -> list[tuple[str, str, Path, Path | None]]:
    """(what uses it, the variable that names it, the folder, HOME when it is derived from it)."""
    out = []
    flags = dict(_pytensor_flags(environ.get("PYTENSOR_FLAGS", "")))
    named = flags.get("compiledir") or flags.get("base_compiledir")
    out.append(("pytensor", "PYTENSOR_FLAGS", Path(named).expanduser() if named else home / ".pytensor",
                None if named else home))
    xdg = environ.get("XDG_CACHE_HOME")
    out.append(("numba, the knowledge templates", "XDG_CACHE_HOME",
                Path(xdg) if xdg else home / ".cache", None if xdg else home))
    if environ.get("NUMBA_CACHE_DIR"):
        out.append(("numba", "NUMBA_CACHE_DIR", Path(environ["NUMBA_CACHE_DIR"]), None))
    mpl = environ.get("MPLCONFIGDIR")
    if mpl:
        out.append(("matplotlib", "MPLCONFIGDIR", Path(mpl), None))
    else:
        xdg_config = environ.get("XDG_CONFIG_HOME")
        out.append(("matplotlib", "MPLCONFIGDIR",
                    Path(xdg_config) / "matplotlib" if xdg_config else home / ".config" / "matplotlib",
                    None if xdg_config else home))
    return out


def _redirect(environ, variable: str, private: Path) -> None:
    if variable == "PYTENSOR_FLAGS":
        kept = [f"{k}={v}" if v else k for k, v in _pytensor_flags(environ.get("PYTENSOR_FLAGS", ""))
                if k not in ("base_compiledir", "compiledir")]
        environ["PYTENSOR_FLAGS"] = ",".join(kept + [f"base_compiledir={private / 'pytensor'}"])
    else:
        environ[variable] = str(private / {"XDG_CACHE_HOME": "cache", "NUMBA_CACHE_DIR": "numba",
                                           "MPLCONFIGDIR": "matplotlib"}[variable])


def _join(names: list[str]) -> str:
    """Names joined by commas and a last "and".

    >>> _join(["pytensor", "numba, the knowledge templates", "matplotlib"])
    'pytensor, numba, the knowledge templates and matplotlib'
    """
    names = [n for name in names for n in name.split(", ")]
    return names[0] if len(names) == 1 else ", ".join(names[:-1]) + " and " + names[-1]


def configure(environ=os.environ, *, note=None) -> Path | None:
    """Point every cache or config folder of :func:`_folders` that cannot be used at a private
    temporary folder; return that folder (None when every one can be used, the usual case:
    then nothing is created or changed). ``note``: where the one-line note goes (stderr)."""
    home = Path(environ.get("HOME") or os.path.expanduser("~"))
    bad = [(who, var, why) for who, var, path, derived in _folders(environ, home)
           for why in [unusable(path, derived)] if why is not None]
    if not bad:
        return None
    private = Path(tempfile.mkdtemp(prefix="semmap-cache-"))      # mode 0700
    atexit.register(shutil.rmtree, private, ignore_errors=True)
    for _who, var, _why in bad:
        _redirect(environ, var, private)
    reasons = list(dict.fromkeys(why for _, _, why in bad))
    who = list(dict.fromkeys(w for w, _, _ in bad))
    line = (f"note: {'; '.join(reasons)}: {_join(who)} keep their files in {private} for this run "
            f"(removed at exit, so code is compiled afresh each time; a writable HOME or "
            f"XDG_CACHE_HOME keeps it)")
    print(line, file=note if note is not None else sys.stderr, flush=True)
    return private


__all__ = ["configure", "unusable"]
