"""What `semmap map` checks before it samples (issue 55's F4, F5, F18): a FIFO as --roi, an --out
under a regular file or not writable, a --force run that would overwrite its own input. Each is
a one-line error, exit 2, nothing sampled and nothing created."""

import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest

from semmap_pp.cli import main

ROOT = Path(__file__).resolve().parents[2]
INTEL = ROOT / "tests" / "data" / "maps" / "intel_corner.yaml"
TINY = ["--chains", "2", "--cores", "1", "--tune", "2", "--draws", "4", "--n-inner", "5",
        "--spread-draws", "0", "--progress", "none"]


def _one_line(capsys) -> str:
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "Traceback" not in err
    return err


def test_a_fifo_as_roi_is_refused_without_being_opened(tmp_path):
    fifo = tmp_path / "roi.png"
    os.mkfifo(fifo)
    t0 = time.monotonic()
    p = subprocess.run([sys.executable, "-m", "semmap_pp", "map", str(INTEL), "--out", str(tmp_path / "o"),
                        "--roi", str(fifo), *TINY], capture_output=True, text=True, timeout=120)
    assert p.returncode == 2 and "roi.png" in p.stderr and "not a regular file" in p.stderr
    assert len(p.stderr.strip().splitlines()) == 1 and time.monotonic() - t0 < 120
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("below", ["", "deeper/still"])
def test_an_out_under_a_regular_file_is_refused_before_sampling(tmp_path, capsys, below):
    f = tmp_path / "afile"
    f.write_text("x")
    out = f / below if below else f / "run"
    assert main(["map", str(INTEL), "--out", str(out), *TINY]) == 2
    assert "is not a directory" in _one_line(capsys)
    assert f.read_text() == "x"


@pytest.mark.skipif(hasattr(os, "geteuid") and os.geteuid() == 0, reason="root writes anywhere")
def test_an_out_that_cannot_be_written_is_refused_before_sampling(tmp_path, capsys):
    ro = tmp_path / "ro"
    ro.mkdir()
    os.chmod(ro, 0o555)
    try:
        assert main(["map", str(INTEL), "--out", str(ro / "run"), *TINY]) == 2
        assert "is not writable" in _one_line(capsys)
    finally:
        os.chmod(ro, 0o755)


@pytest.mark.parametrize("name", ["types.yaml", "labels.png"])
def test_force_into_the_folder_of_its_own_input_is_refused(tmp_path, capsys, name):
    out = tmp_path / "run"
    out.mkdir()
    img = out / (name if name.endswith(".png") else "types.pgm")
    shutil.copy(INTEL.with_suffix(".png"), img if img.suffix == ".png" else out / "intel_corner.png")
    if name.endswith(".yaml"):
        (out / name).write_text(INTEL.read_text())
        target = out / name
    else:
        target = img
    before = target.read_bytes()
    args = ["map", str(target), "--out", str(out), "--force", *TINY]
    if target.suffix == ".png":
        args += ["--resolution", "0.05"]
    assert main(args) == 2
    err = _one_line(capsys)
    assert "is an input of this run" in err and name in err
    assert target.read_bytes() == before
