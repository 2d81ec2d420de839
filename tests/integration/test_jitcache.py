"""numba's cache keyed by the package source (semmap_pp/jitcache.py)."""

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import time

import numba

from semmap_pp.jitcache import ENV, MAX_AGE_DAYS, cache_dir, configure, prune, source_digest


def test_digest_follows_every_source_file(tmp_path):
    (tmp_path / "a.py").write_text("x = 1\n")
    (tmp_path / "sub").mkdir()
    (tmp_path / "sub" / "b.py").write_text("y = 1\n")
    d0 = source_digest(tmp_path)
    assert source_digest(tmp_path) == d0                     # stable
    (tmp_path / "sub" / "b.py").write_text("y = 2\n")
    d1 = source_digest(tmp_path)
    assert d1 != d0                                           # a change in any module
    (tmp_path / "sub" / "b.py").rename(tmp_path / "sub" / "c.py")
    assert source_digest(tmp_path) != d1                      # a renamed module
    (tmp_path / "notes.txt").write_text("not source")
    assert source_digest(tmp_path) == source_digest(tmp_path)


def test_cache_dir_settings(tmp_path):
    pkg = tmp_path / "pkg"
    pkg.mkdir()
    (pkg / "m.py").write_text("z = 0\n")
    digest = source_digest(pkg)
    assert cache_dir({"XDG_CACHE_HOME": str(tmp_path / "c")}, pkg) == \
        tmp_path / "c" / "semmap_pp" / "numba" / digest
    assert cache_dir({ENV: str(tmp_path / "mine")}, pkg) == tmp_path / "mine" / digest
    assert cache_dir({ENV: "off"}, pkg) is None
    assert cache_dir({"NUMBA_CACHE_DIR": "/somewhere"}, pkg) is None  # the user's choice stands


def test_configure_sets_numba_and_falls_back_when_it_cannot_write(tmp_path):
    env = {ENV: str(tmp_path / "cache")}
    path = configure(env)
    assert path is not None and path.is_dir() and env["NUMBA_CACHE_DIR"] == str(path)
    blocker = tmp_path / "file"
    blocker.write_text("")
    env = {ENV: str(blocker)}                                 # a file where a folder must go
    assert configure(env) is None and "NUMBA_CACHE_DIR" not in env


def test_old_digest_folders_are_pruned_and_nothing_else(tmp_path):
    base = tmp_path / "cache"
    base.mkdir()
    old, young = base / "0123456789abcdef", base / "fedcba9876543210"
    not_ours = [base / "keep-me", base / "0123456789abcdef0", base / "0123456789ABCDEF"]
    for d in (old, young, *not_ours):
        d.mkdir()
        (d / "f.nbi").write_text("")
    (base / "aaaaaaaaaaaaaaaa").write_text("a file named like a digest")
    past = time.time() - (MAX_AGE_DAYS + 1) * 86400
    for p in (old, *not_ours, base / "aaaaaaaaaaaaaaaa"):
        os.utime(p, (past, past))
    saved = numba.config.CACHE_DIR
    try:
        env = {ENV: str(base)}
        current = configure(env)
        assert current.parent == base and current.is_dir()
        assert not old.exists()                                   # unused for too long: deleted
        assert young.exists() and all(d.exists() for d in not_ours)
        assert (base / "aaaaaaaaaaaaaaaa").exists()
        os.utime(current, (past, past))                           # an old current folder ...
        assert configure({ENV: str(base)}) == current and current.is_dir()   # ... kept, marked used
        assert time.time() - current.stat().st_mtime < 3600
    finally:
        numba.config.CACHE_DIR = saved
    # prune() alone: the age limit is a parameter; the current folder is never a candidate
    assert prune(current, max_age_days=0, now=time.time() + 10) == [young]
    assert current.exists()


def test_a_change_in_a_called_module_is_not_served_from_a_stale_cache(tmp_path):
    """numba checks a cached function against its own file only; with the cache keyed by the
    digest of the whole package, editing the module of a *called* compiled function (or of a
    constant it reads) gives the new result, not the cached machine code of the old one."""
    pkg = tmp_path / "pkgx"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "b.py").write_text(textwrap.dedent("""
        import numba
        K = 1
        @numba.njit(cache=True)
        def g():
            return K
    """))
    (pkg / "a.py").write_text(textwrap.dedent("""
        import numba
        from pkgx.b import g
        @numba.njit(cache=True)
        def f():
            return g() * 10
    """))
    script = textwrap.dedent(f"""
        import os, sys
        sys.path.insert(0, {str(tmp_path)!r})
        from semmap_pp.jitcache import cache_dir
        os.environ["NUMBA_CACHE_DIR"] = str(cache_dir({{"{ENV}": {str(tmp_path / "cache")!r}}},
                                                      {str(pkg)!r}))
        from pkgx.a import f
        print(f())
    """)
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}

    def run():
        out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                             env=env, timeout=300)
        assert out.returncode == 0, out.stderr
        return int(out.stdout.strip())

    assert run() == 10
    assert run() == 10                                        # served from the cache
    assert any((tmp_path / "cache").rglob("*.nbi"))
    (pkg / "b.py").write_text((pkg / "b.py").read_text().replace("K = 1", "K = 2"))
    assert run() == 20


def test_the_package_configures_numba_on_import(tmp_path):
    code = "import os, semmap_pp; print(os.environ.get('NUMBA_CACHE_DIR', ''))"
    env = {k: v for k, v in os.environ.items() if k not in ("NUMBA_CACHE_DIR", ENV)}
    env["XDG_CACHE_HOME"] = str(tmp_path)                    # writable wherever the tests run
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env,
                         timeout=120, cwd=Path(__file__).resolve().parents[2])
    assert out.returncode == 0, out.stderr
    path = Path(out.stdout.strip())
    assert path == tmp_path / "semmap_pp" / "numba" / source_digest() and path.is_dir()


def test_a_cache_others_can_write_to_is_never_used(tmp_path, monkeypatch, capsys):
    """numba's index files are pickles: a cache folder writable by other users is replaced by a
    private one (0700), with a note, and nothing in the shared folder is read."""
    import numba

    monkeypatch.setattr(numba.config, "CACHE_DIR", numba.config.CACHE_DIR)   # restored afterwards
    shared = tmp_path / "shared"
    shared.mkdir()
    os.chmod(shared, 0o777)
    env = {ENV: str(shared)}
    used = configure(env)
    assert used is not None and shared not in used.parents
    assert os.stat(used).st_mode & 0o077 == 0
    assert env["NUMBA_CACHE_DIR"] == str(used)
    assert "not used" in capsys.readouterr().err
    os.chmod(shared, 0o755)
    env = {ENV: str(shared)}
    assert configure(env).parent == shared                 # the user's own folder: used
