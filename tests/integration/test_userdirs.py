"""HOME missing, not a folder or read-only (issue 55's F15): pytensor, numba, the knowledge
templates and matplotlib get a private temporary folder (mode 0700, removed at exit) with a
one-line note, the run works, and a missing HOME is never created. Subprocesses: the folders are
chosen when semmap_pp is imported."""

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from semmap_pp import userdirs

ROOT = Path(__file__).resolve().parents[2]
TINY_MAP = ROOT / "tests" / "data" / "maps" / "tiny.yaml"
PROBE = ("import json, os, stat, semmap_pp, pytensor, matplotlib; p = os.environ['XDG_CACHE_HOME']; "
         "print(json.dumps({'pytensor': str(pytensor.config.compiledir), 'mpl': matplotlib.get_configdir(), "
         "'mplcache': matplotlib.get_cachedir(), 'numba': os.environ['NUMBA_CACHE_DIR'], 'cache': p, "
         "'mode': stat.S_IMODE(os.stat(os.path.dirname(p)).st_mode)}))")


def _env(home, **extra):
    env = {k: v for k, v in os.environ.items()
           if k not in ("XDG_CACHE_HOME", "XDG_CONFIG_HOME", "NUMBA_CACHE_DIR", "MPLCONFIGDIR", "PYTENSOR_FLAGS")}
    env.update(HOME=str(home), **extra)
    return env


def _probe(home, **extra):
    p = subprocess.run([sys.executable, "-c", PROBE], capture_output=True, text=True, cwd=ROOT,
                       env=_env(home, **extra), timeout=300)
    assert p.returncode == 0, p.stderr
    return json.loads(p.stdout), p.stderr


def _private_everywhere(seen, stderr, why):
    lines = [ln for ln in stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith(f"note: {why}: pytensor, numba, the knowledge "
                                                   "templates and matplotlib keep their files in "), stderr
    private = Path(lines[0].split(" keep their files in ")[1].split(" ")[0])
    assert Path(seen["cache"]).parent == private and seen["mode"] == 0o700
    for key in ("pytensor", "mpl", "mplcache", "numba"):
        assert Path(seen[key]).is_relative_to(private), (key, seen[key])
    assert not private.exists()                      # removed when the process ended
    return private


def test_a_missing_home_gets_a_private_folder_and_is_not_created(tmp_path):
    home = tmp_path / "nonexistent"
    seen, err = _probe(home)
    _private_everywhere(seen, err, f"HOME {home} does not exist")
    assert not home.exists()


def test_a_run_with_a_missing_home_works_and_creates_no_home(tmp_path):
    """`semmap map` end to end (pytensor samples) with HOME missing; numba's compiled code comes from
    the usual cache (XDG_CACHE_HOME given), so only pytensor and matplotlib are redirected."""
    home = tmp_path / "nobody"
    cache = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache")
    p = subprocess.run([sys.executable, "-m", "semmap_pp", "map", str(TINY_MAP), "--out", str(tmp_path / "o"),
                        "--chains", "1", "--cores", "1", "--tune", "2", "--draws", "4", "--n-inner", "5",
                        "--spread-draws", "0", "--progress", "none"], capture_output=True, text=True, cwd=ROOT,
                       env=_env(home, XDG_CACHE_HOME=str(cache)), timeout=600)
    assert p.returncode == 0, p.stderr
    assert "Traceback" not in p.stderr
    assert p.stderr.splitlines()[0].startswith(f"note: HOME {home} does not exist: pytensor and matplotlib "
                                               "keep their files in ")
    assert (tmp_path / "o" / "world.json").is_file() and not home.exists()


def test_a_home_under_a_regular_file_is_not_a_folder(tmp_path):
    """A variant that fails even as root: HOME names a regular file (or a path below one)."""
    f = tmp_path / "afile"
    f.write_text("x")
    seen, err = _probe(f)
    _private_everywhere(seen, err, f"HOME {f} is not a folder")
    seen, err = _probe(f / "home")
    _private_everywhere(seen, err, f"HOME {f / 'home'} does not exist")
    assert f.read_text() == "x"


@pytest.mark.skipif(hasattr(os, "geteuid") and os.geteuid() == 0, reason="root writes into read-only folders")
def test_a_read_only_home_gets_a_private_folder(tmp_path):
    home = tmp_path / "ro"
    home.mkdir()
    os.chmod(home, 0o555)
    try:
        seen, err = _probe(home)
        _private_everywhere(seen, err, f"HOME {home} is not writable")
        assert list(home.iterdir()) == []
    finally:
        os.chmod(home, 0o755)


def test_a_named_folder_that_cannot_be_made_is_replaced(tmp_path):
    """A folder the user named (PYTENSOR_FLAGS, MPLCONFIGDIR) below a regular file is redirected
    too; a usable HOME and a usable named folder are left alone."""
    f = tmp_path / "afile"
    f.write_text("x")
    env = {"HOME": str(tmp_path), "PYTENSOR_FLAGS": f"floatX=float64,base_compiledir={f}/pt",
           "MPLCONFIGDIR": str(f / "mpl"), "XDG_CACHE_HOME": str(tmp_path / "cache")}
    lines = []

    class Note:
        def write(self, s):
            lines.append(s)

        def flush(self):
            pass

    private = userdirs.configure(env, note=Note())
    assert private is not None and private.is_dir() and (private.stat().st_mode & 0o777) == 0o700
    assert env["PYTENSOR_FLAGS"] == f"floatX=float64,base_compiledir={private / 'pytensor'}"
    assert env["MPLCONFIGDIR"] == str(private / "matplotlib")
    assert env["XDG_CACHE_HOME"] == str(tmp_path / "cache")          # usable: kept (and not made)
    assert "".join(lines).startswith(f"note: {f} is not a folder: pytensor and matplotlib keep their files in ")
    assert not (tmp_path / "cache").exists() and not (tmp_path / ".pytensor").exists()
    fine = {"HOME": str(tmp_path)}
    assert userdirs.configure(fine) is None and fine == {"HOME": str(tmp_path)}
