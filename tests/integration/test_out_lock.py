"""Two runs into one output folder at once (issue 55's F13): the folder is locked (flock on
DIR/.semmap.lock) before sampling and held until the files are written; a second run is refused
in one line naming the holder's pid, exit 2, and touches nothing; a lock left by a killed run
does not block. `semmap map`, `edit`, `compare`, `stability` and `batch` all take it."""

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from semmap_pp.cli import main
from semmap_pp.run.outdir import LOCK_NAME, lock_out_dir
from test_faults_kill import check_complete

ROOT = Path(__file__).resolve().parents[2]
INTEL = ROOT / "tests" / "data" / "maps" / "intel_corner.yaml"
RUN = ["--chains", "2", "--cores", "1", "--tune", "2", "--draws", "4", "--n-inner", "5"]
TINY = RUN + ["--spread-draws", "0", "--progress", "none"]


def busy_line(out, pid) -> str:
    return (f"semmap: error: {out} is in use by another semmap run (pid {pid}); wait for it or "
            f"choose another --out")


def test_a_second_run_into_a_folder_being_written_is_refused(tmp_path, capsys):
    """The issue's case: a run samples into DIR and a second `semmap map --out DIR --force`
    starts; the second is refused with the first's pid, the first ends with its own files."""
    out = tmp_path / "run"
    first = subprocess.Popen([sys.executable, "-m", "semmap_pp", "map", str(INTEL), "--out", str(out), "--seed", "1",
                              "--chains", "1", "--cores", "1", "--tune", "2", "--draws", "100000", "--n-inner", "5",
                              "--spread-draws", "0", "--progress", "plain", "--progress-every", "0.2"],
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=ROOT)
    try:
        seen = []
        for line in first.stderr:
            seen.append(line)
            if "sampling started" in line:
                break
        assert any("sampling started" in s for s in seen), "".join(seen)
        assert main(["map", str(INTEL), "--out", str(out), "--force", "--seed", "2", *TINY]) == 2
        err = capsys.readouterr().err.strip()
        assert err == busy_line(out, first.pid)
        assert sorted(p.name for p in out.iterdir()) == [LOCK_NAME]     # nothing written by either yet
    finally:
        first.send_signal(signal.SIGINT)
        _, rest = first.communicate(timeout=300)
    assert first.returncode == 130, rest
    names = check_complete(out)
    assert "world.json" in names and "resume.npz" in names
    assert json.loads((out / "world.json").read_text())["seed"] == 1     # the first run's, whole
    assert not (out / LOCK_NAME).exists()


def test_the_second_run_never_removes_the_first_runs_temporaries(tmp_path, capsys):
    """A run that is refused never gets to remove_stale_temps: the holder's temporary files stay."""
    out = tmp_path / "run"
    with lock_out_dir(out):
        live = out / ".world.json.a1b2c3d4.tmp"
        live.write_text('{"units": [')           # the holder is writing world.json
        assert main(["map", str(INTEL), "--out", str(out), "--force", *TINY]) == 2
        assert capsys.readouterr().err.strip() == busy_line(out, os.getpid())
        assert live.read_text() == '{"units": ['
    assert sorted(p.name for p in out.iterdir()) == [live.name]


@pytest.mark.parametrize("command", ["edit", "compare", "stability", "batch", "map --resume"])
def test_every_command_that_writes_a_folder_takes_the_lock(tmp_path, capsys, intel_corner_wstar, command):
    out = tmp_path / "o"
    world = intel_corner_wstar
    args = {"edit": ["edit", str(INTEL), str(world), "--drop", "1", "--out", str(out)],
            "compare": ["compare", str(INTEL), "--rules", "rules/none.lp", "--rules", "rules/table3.lp",
                        "--out", str(out), *RUN],
            "stability": ["stability", str(INTEL), "--seeds", "0", "1", "--out", str(out), *RUN],
            "batch": ["batch", str(INTEL), "--out", str(out), "--workers", "1", "--progress", "none", *RUN],
            "map --resume": ["map", "--resume", str(world.parent), "--draws", "4", "--progress", "none"],
            }[command]
    target = world.parent if command == "map --resume" else out
    before = {p.name: p.stat().st_mtime_ns for p in target.iterdir()} if target.exists() else {}
    with lock_out_dir(target):
        t0 = time.monotonic()
        assert main(args) == 2
        assert time.monotonic() - t0 < 30            # refused before any sampling
    assert capsys.readouterr().err.strip() == busy_line(target, os.getpid())
    after = {p.name: p.stat().st_mtime_ns for p in target.iterdir()} if target.exists() else {}
    assert after == before


def test_a_lock_left_by_a_killed_run_does_not_block(tmp_path, capsys):
    """flock goes with its process: the lock file of a SIGKILLed holder (still there, with its
    pid) lets the next run in, without --force when the folder holds nothing else."""
    out = tmp_path / "run"
    holder = subprocess.Popen([sys.executable, "-c", "import sys, time; from semmap_pp.run.outdir import lock_out_dir; "
                               f"lock_out_dir({str(out)!r}); print('held', flush=True); time.sleep(600)"],
                              stdout=subprocess.PIPE, text=True, cwd=ROOT)
    assert holder.stdout.readline().strip() == "held"
    assert main(["map", str(INTEL), "--out", str(out), *TINY]) == 2
    assert capsys.readouterr().err.strip() == busy_line(out, holder.pid)
    holder.kill()
    holder.wait()
    assert (out / LOCK_NAME).read_text().strip() == str(holder.pid)     # left behind
    assert main(["map", str(INTEL), "--out", str(out), *TINY]) == 0
    assert "world.json" in check_complete(out) and not (out / LOCK_NAME).exists()


def test_the_lock_goes_with_the_run_and_so_does_a_folder_it_made(tmp_path):
    out = tmp_path / "a" / "b"
    lock = lock_out_dir(out)
    assert (out / LOCK_NAME).read_text() == f"{os.getpid()}\n"
    lock.release()
    lock.release()                                   # twice is harmless
    assert not (tmp_path / "a").exists()             # made for the run, left empty: removed
    keep = tmp_path / "keep"
    keep.mkdir()
    with lock_out_dir(keep):
        (keep / "world.json").write_text("{}")
    assert sorted(p.name for p in keep.iterdir()) == ["world.json"]


def test_an_input_error_after_the_lock_leaves_no_folder(tmp_path, capsys):
    """`semmap stability` takes the lock before reading its inputs: a bad map leaves nothing."""
    out = tmp_path / "o"
    bad = tmp_path / "bad.yaml"
    bad.write_text("image: nothing.pgm\nresolution: 0.05\norigin: [0, 0, 0]\n")
    assert main(["stability", str(bad), "--out", str(out), *RUN]) == 2
    assert "bad.yaml" in capsys.readouterr().err and not out.exists()
