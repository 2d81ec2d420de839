"""A full disk under --out (issue 55's F6): every output writer goes through semmap_pp.atomic, so
a write that fails is one line (``cannot write OUT/FILE: no space left on device``), exit 2, and
every file under its final name is complete. A fake ``os.write`` raises ENOSPC at the Nth write
into the output folder (a real full file system cannot be relied on: tests may run as root, and
a tmpfs of a few kB cannot be mounted here). Also: the free space checked before sampling."""

import errno
import os
import shutil
from collections import namedtuple
from pathlib import Path

import pytest

from semmap_pp import atomic
from semmap_pp.cli import main
from semmap_pp.errors import WriteError
from test_faults_kill import check_complete

ROOT = Path(__file__).resolve().parents[2]
INTEL = ROOT / "tests" / "data" / "maps" / "intel_corner.yaml"
TINY = ["--chains", "2", "--cores", "1", "--tune", "2", "--draws", "4", "--n-inner", "5",
        "--spread-draws", "0", "--progress", "none"]
#: with a sample around W*, so that spread.nc is written too
SPREAD = TINY[:-4] + ["--spread-draws", "4", "--progress", "none"]
REAL_WRITE = os.write


def _target(fd: int) -> str:
    try:
        return os.readlink(f"/proc/self/fd/{fd}")
    except OSError:
        return ""


class FullDisk:
    """``os.write`` that fails with ``error`` at the ``nth`` output file written into ``folder``
    (1 = the first; None: never) or at the first write to a file named ``name``, and records the
    final name of each file written there (through a temporary ``.NAME.XXXXXXXX.tmp``), in order;
    ``chunk``: write at most that many bytes per call."""

    def __init__(self, folder: Path, nth: int | None = None, name: str | None = None,
                 error: int = errno.ENOSPC, chunk: int | None = None):
        self.folder, self.nth, self.name, self.error, self.chunk = str(folder.resolve()), nth, name, error, chunk
        self.files: list[str] = []

    def __call__(self, fd, data):
        where = _target(fd)
        if not where.startswith(self.folder + os.sep) or not where.endswith(".tmp"):
            return REAL_WRITE(fd, data)          # not an output (the folder's lock file, a pipe)
        final = Path(where).name[1:].rsplit(".", 2)[0]      # .NAME.XXXXXXXX.tmp -> NAME
        if not self.files or self.files[-1] != final:
            self.files.append(final)
        if (self.nth is not None and len(self.files) == self.nth) or final == self.name:
            raise OSError(self.error, os.strerror(self.error))
        if self.chunk is not None:
            data = memoryview(data)[:self.chunk]
        return REAL_WRITE(fd, data)


@pytest.fixture(scope="module")
def written(tmp_path_factory):
    """A complete `semmap map` result, and the order in which its files are written."""
    out = tmp_path_factory.mktemp("full") / "run"
    mp = pytest.MonkeyPatch()
    fake = FullDisk(out)
    mp.setattr(os, "write", fake)
    try:
        assert main(["map", str(INTEL), "--out", str(out), "--seed", "2", *SPREAD]) == 0
    finally:
        mp.undo()
    return out, fake.files


def test_every_output_is_written_through_the_atomic_writer(written):
    out, order = written
    names = sorted(p.name for p in out.iterdir() if p.name != "rosbag2")
    assert sorted(order) == names and len(set(order)) == len(order)   # each file once, none around it
    assert (out / "rosbag2" / "metadata.yaml").is_file()     # the one folder: atomic.atomic_dir
    assert order[0] == "resume.npz" and order[-1] == "report.html"
    assert {"world.json", "graph.graphml", "trace.nc", "spread.nc", "types.pgm", "world.geojson"} <= set(order)


def test_a_full_disk_at_the_world_json_is_one_line_and_keeps_resume_npz(tmp_path, capsys, monkeypatch):
    """The issue's case: ENOSPC while world.json is written (resume.npz, written first, is kept)."""
    out = tmp_path / "run"
    monkeypatch.setattr(os, "write", FullDisk(out, name="world.json"))
    assert main(["map", str(INTEL), "--out", str(out), "--seed", "2", *TINY]) == 2
    monkeypatch.undo()
    last = capsys.readouterr().err.strip().splitlines()[-1]
    assert last == f"semmap: error: cannot write {out / 'world.json'}: no space left on device"
    assert sorted(p.name for p in out.iterdir()) == ["resume.npz"]      # no temporary, no lock left
    check_complete(out)
    assert main(["map", "--resume", str(out), "--draws", "4", "--progress", "none"]) == 0   # the search goes on


#: every file of a run with a sample around W*, in the order written
FILES = ["resume.npz", "world.json", "labels.png", "trace.nc", "spread.nc", "diagnostics.txt",
         "world.geojson", "graph.graphml", "regions.png", "rooms.png", "types.pgm", "types.yaml",
         "overlay.png", "graph.png", "posterior.png", "posterior_cells.png", "report.html"]


def test_the_files_are_written_in_this_order(written):
    assert written[1] == FILES


@pytest.mark.parametrize("nth", range(1, len(FILES) + 1))
def test_a_full_disk_at_any_file_keeps_every_file_complete(written, tmp_path, capsys, monkeypatch, nth):
    """ENOSPC at the Nth file of a --force run into a folder holding a complete earlier result:
    one line naming that file, exit 2, every file is the old one or the new one, complete."""
    previous, order = written
    out = tmp_path / "run"
    shutil.copytree(previous, out)
    monkeypatch.setattr(os, "write", FullDisk(out, nth=nth))
    assert main(["map", str(INTEL), "--out", str(out), "--seed", "5", "--force", *SPREAD]) == 2
    monkeypatch.undo()
    err = capsys.readouterr().err
    assert "Traceback" not in err
    assert err.strip().splitlines()[-1] == (f"semmap: error: cannot write {out / FILES[nth - 1]}: "
                                            f"no space left on device")
    assert check_complete(out) == set(order) | {"rosbag2"}       # nothing lost, nothing truncated
    assert sorted(p.name for p in out.iterdir()) == sorted([*order, "rosbag2"])   # no temporary left


@pytest.mark.parametrize("error, words", [(errno.EDQUOT, "disk quota exceeded"),
                                          (errno.EROFS, "read-only file system"),
                                          (errno.EFBIG, "file too large")])
def test_other_write_errors_are_one_line_too(tmp_path, error, words):
    target = tmp_path / "a.json"
    atomic.write_text(target, "old")
    mp = pytest.MonkeyPatch()
    mp.setattr(os, "write", FullDisk(tmp_path, nth=1, error=error))
    try:
        with pytest.raises(WriteError) as info:
            atomic.write_text(target, "new" * 1000)
    finally:
        mp.undo()
    assert str(info.value) == f"cannot write {target}: {words}"
    assert target.read_text() == "old" and [p.name for p in tmp_path.iterdir()] == ["a.json"]


def test_a_full_disk_found_only_at_fsync_keeps_the_old_file(tmp_path, monkeypatch):
    """Some file systems (NFS, ext4's delayed allocation) report ENOSPC at fsync or close."""
    target = tmp_path / "graph.graphml"
    atomic.write_text(target, "<old/>")

    def fsync(fd):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(os, "fsync", fsync)
    with pytest.raises(WriteError, match="no space left on device"):
        atomic.write_text(target, "<new/>")
    assert target.read_text() == "<old/>" and [p.name for p in tmp_path.iterdir()] == ["graph.graphml"]


def test_short_writes_still_give_whole_files(written, tmp_path, monkeypatch):
    """A disk nearly full takes a few bytes per write: the writer goes on until the file is whole
    (the same bytes as written at once)."""
    previous, order = written
    out = tmp_path / "run"
    monkeypatch.setattr(os, "write", FullDisk(out, chunk=777))
    assert main(["map", str(INTEL), "--out", str(out), "--seed", "2", *SPREAD]) == 0
    monkeypatch.undo()
    for name in ("world.json", "labels.png", "graph.graphml", "world.geojson", "types.pgm", "regions.png"):
        assert (out / name).read_bytes() == (previous / name).read_bytes(), name
    check_complete(out)


def test_edit_on_a_full_disk_is_one_line(written, tmp_path, capsys, monkeypatch):
    """`semmap edit` writes through the same writers."""
    previous, _ = written
    out = tmp_path / "edited"
    monkeypatch.setattr(os, "write", FullDisk(out, name="graph.graphml"))
    assert main(["edit", str(INTEL), str(previous / "world.json"), "--drop", "1", "--out", str(out)]) == 2
    monkeypatch.undo()
    err = capsys.readouterr().err.strip()
    assert err.splitlines()[-1] == f"semmap: error: cannot write {out / 'graph.graphml'}: no space left on device"
    assert not [p for p in out.iterdir() if p.name.startswith(".")]
    check_complete(out)


Statvfs = namedtuple("Statvfs", "f_bavail f_frsize")


@pytest.mark.parametrize("command", ["map", "stability", "edit"])
def test_too_little_free_space_is_refused_before_sampling(written, tmp_path, capsys, monkeypatch, command):
    previous, _ = written
    monkeypatch.setattr(os, "statvfs", lambda path: Statvfs(3, 4096))      # 12 kB free
    out = tmp_path / "deep" / "run"
    args = {"map": ["map", str(INTEL), "--out", str(out), *TINY],
            "stability": ["stability", str(INTEL), "--seeds", "0", "1", "--out", str(out), *TINY[:-4]],
            "edit": ["edit", str(INTEL), str(previous / "world.json"), "--drop", "1", "--out", str(out)]}[command]
    assert main(args) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "Traceback" not in err, err
    assert err.startswith(f"semmap: error: {out}: only 12 kB free on its file system"), err
    assert not (tmp_path / "deep").exists()                       # nothing created, nothing sampled
