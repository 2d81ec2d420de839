"""Faults of `semmap map`: Ctrl-C (SIGINT) on one and two cores, --resume, --budget (subprocesses)."""

import json
import signal
import subprocess
import sys
import time
from pathlib import Path

import jsonschema
import numpy as np
import pytest

from semmap_pp.cli import main
from semmap_pp.sampler.diagnostics import read_trace

ROOT = Path(__file__).resolve().parents[2]
SCHEMA = json.loads((ROOT / "docs" / "world.schema.json").read_text())
# Far more draws than any budget or interruption of these tests lets a run make (a 3 s budget once
# finished the 5,000 draws left after an interruption on a fast, idle machine, so the budget never
# ended the run and its message was missing).
DRAWS = 100_000
LONG = ["--tune", "2", "--draws", str(DRAWS), "--n-inner", "5", "--progress", "plain",
        "--progress-every", "0.2"]


@pytest.fixture(scope="module")
def floor(tmp_path_factory):
    out = tmp_path_factory.mktemp("floor") / "f"
    assert main(["synth", "--seed", "3", "--units", "4", "--out", str(out)]) == 0
    return out / "map.yaml"


def sigint_after(args, trigger: str, wait: float = 0.5, command: str = "map", out: list | None = None):
    """Start `semmap COMMAND ARGS`, wait for a stderr line holding ``trigger`` and ``wait`` seconds
    more, send SIGINT; return (exit code, stderr); its stdout is appended to ``out``."""
    p = subprocess.Popen([sys.executable, "-m", "semmap_pp", command, *map(str, args)],
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    seen = []
    deadline = time.monotonic() + 300
    while time.monotonic() < deadline:
        line = p.stderr.readline()
        if not line:
            break
        seen.append(line)
        if trigger in line:
            break
    assert any(trigger in s for s in seen), "".join(seen)
    time.sleep(wait)
    p.send_signal(signal.SIGINT)
    stdout, err = p.communicate(timeout=300)
    if out is not None:
        out.append(stdout)
    return p.returncode, "".join(seen) + err


def interrupt(map_path, out, cores):
    """Start a long `semmap map`, wait until it samples, send SIGINT; return (code, stderr)."""
    return sigint_after([map_path, "--out", out, "--chains", "2", "--cores", cores, *LONG], "sampling started")


def resume_meta(out):
    with np.load(out / "resume.npz") as z:
        return json.loads(str(z["meta"]))


def chain_logp(out, c):
    with np.load(out / "resume.npz") as z:
        return z[f"stat_{c}_logp"]


def check_partial(out, code, err):
    assert code == 130, err
    assert "interrupted: wrote partial results" in err and "Traceback" not in err
    doc = json.loads((out / "world.json").read_text())
    jsonschema.validate(doc, SCHEMA)
    assert len(doc["units"]) >= 1
    tree = read_trace(out / "trace.nc")
    lp = tree["posterior"]["log_posterior"].values
    assert lp.shape[1] >= 4 and np.isfinite(lp).all()
    meta = resume_meta(out)
    assert meta["stopped"] == "interrupted"
    return tree, meta


@pytest.fixture(scope="module")
def interrupted(floor, tmp_path_factory):
    out = tmp_path_factory.mktemp("sigint") / "run"
    code, err = interrupt(floor, out, cores=1)
    tree, meta = check_partial(out, code, err)
    return out, tree, meta


def test_sigint_one_core_writes_partial_results(interrupted):
    out, tree, meta = interrupted
    done = [c["draw"] for c in meta["chains"]]
    assert 4 <= max(done) < DRAWS + 2            # stopped long before the planned draws
    assert (out / "diagnostics.txt").is_file() and (out / "labels.png").is_file()


@pytest.mark.slow
def test_sigint_two_cores_writes_partial_results(floor, tmp_path):
    out = tmp_path / "run2"
    code, err = interrupt(floor, out, cores=2)
    tree, meta = check_partial(out, code, err)
    assert meta["settings"]["cores"] == 2


def test_resume_appends_draws_until_the_budget(interrupted, capsys):
    out, tree, meta = interrupted
    interrupted_logp = chain_logp(out, 0)
    before = [c["draw"] for c in meta["chains"]]
    # in this process (no signal needed): the budget ends the continued run
    assert main(["map", "--resume", str(out), "--budget", "3", "--progress", "none"]) == 0
    err = capsys.readouterr().err
    assert "budget of 3 s reached" in err and "resuming:" in err
    after = resume_meta(out)["chains"]
    assert all(a["draw"] >= b for a, b in zip(after, before)) and sum(a["draw"] for a in after) > sum(before)
    assert resume_meta(out)["stopped"] == "budget"
    # the draws of the interrupted run are still the first ones of chain 1: new ones were appended
    old, new = interrupted_logp, chain_logp(out, 0)
    assert len(new) > len(old)
    np.testing.assert_array_equal(new[:len(old)], old)
    assert read_trace(out / "trace.nc")["posterior"]["log_posterior"].values.shape[1] >= 4


@pytest.mark.parametrize("extra, needle", [
    (["--chains", "3"], "--chains cannot be given with --resume"),
    (["MAP.yaml"], "MAP cannot be given with --resume"),
])
def test_resume_refuses_changed_settings(interrupted, extra, needle, capsys):
    out, _, _ = interrupted
    args = ["map", "--resume", str(out)] + [a for a in extra if a != "MAP.yaml"]
    if "MAP.yaml" in extra:
        args.insert(1, "some_map.yaml")
    assert main(args) == 2
    assert needle in capsys.readouterr().err


def test_resume_of_a_folder_without_resume_file(tmp_path, capsys):
    assert main(["map", "--resume", str(tmp_path)]) == 2
    assert "no resume file here" in capsys.readouterr().err


def test_resume_refuses_a_run_written_for_another_lattice(interrupted, tmp_path, capsys):
    """The stored worlds are in the lattice's cells: a resume file whose lattice differs from the
    one the map and model give now (another version, an edited model file) is refused by name."""
    import shutil

    out, _, _ = interrupted
    other = tmp_path / "other"
    shutil.copytree(out, other)
    with np.load(other / "resume.npz") as z:
        arrays = {k: z[k] for k in z.files}
    meta = json.loads(str(arrays["meta"]))
    assert meta["inputs"]["lattice"] and len(meta["inputs"]["lattice"]) == 2
    meta["inputs"]["lattice"] = [meta["inputs"]["lattice"][0] + 1, meta["inputs"]["lattice"][1]]
    arrays["meta"] = np.array(json.dumps(meta))
    np.savez_compressed(other / "resume.npz", **arrays)
    assert main(["map", "--resume", str(other), "--progress", "none"]) == 2
    err = capsys.readouterr().err
    assert "resume.npz" in err and "written for a lattice of" in err and "Traceback" not in err


def test_sigint_during_the_sample_around_wstar_keeps_wstar(floor, tmp_path):
    """Ctrl-C after W*'s search, while the chains sample around W*: W* and the sample's draws so far
    are written, the last line says the search had ended, exit status 130."""
    out = tmp_path / "around"
    code, err = sigint_after([floor, "--out", out, "--chains", "2", "--cores", "1", "--tune", "0", "--draws", "4",
                              "--n-inner", "5", "--spread-draws", DRAWS, "--progress", "none"],
                             "sampling around W*", wait=1.0)
    assert code == 130, err
    last = err.strip().splitlines()[-1]
    assert last.startswith("semmap: interrupted after W*'s search had ended: wrote W* and the sample around W* ("), last
    assert "Traceback" not in err
    jsonschema.validate(json.loads((out / "world.json").read_text()), SCHEMA)
    lp = read_trace(out / "spread.nc")["posterior"]["log_posterior"].values
    assert 4 <= lp.shape[1] < DRAWS and np.isfinite(lp).all()
    assert read_trace(out / "trace.nc")["posterior"]["log_posterior"].values.shape[1] == 4   # the whole search
    assert resume_meta(out)["stopped"] == "interrupted"


def _check_saved(out, err, code, more):
    """A run stopped by Ctrl-C while its outputs were written: exit 130, the last line says the
    search is saved and how to go on, resume.npz and every file written are complete."""
    from test_faults_kill import check_complete

    assert code == 130, err
    assert "Traceback" not in err
    assert err.strip().splitlines()[-1] == (
        f"semmap: interrupted while writing the outputs: the search is saved in {out / 'resume.npz'}; "
        f"`semmap map --resume {out}{more}` continues it and writes every file again")
    names = check_complete(out)
    assert "resume.npz" in names and "report.html" not in names          # written first; last not reached
    assert not [p.name for p in out.iterdir() if p.name.startswith(".")]  # no temporary, no lock
    return names


def test_sigint_while_the_outputs_are_written_keeps_the_search(floor, tmp_path):
    """The issue's case: Ctrl-C once the outputs are being written (resume.npz has appeared)."""
    out = tmp_path / "writing"
    p = subprocess.Popen([sys.executable, "-m", "semmap_pp", "map", str(floor), "--out", str(out), "--chains", "2",
                          "--cores", "1", "--tune", "2", "--draws", "6", "--n-inner", "5", "--spread-draws", "0",
                          "--progress", "none"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 300
    while not (out / "resume.npz").exists() and p.poll() is None and time.monotonic() < deadline:
        time.sleep(0.002)
    p.send_signal(signal.SIGINT)
    _, err = p.communicate(timeout=300)
    _check_saved(out, err, p.returncode, " --draws N")     # the search was complete: --draws N more
    assert main(["map", "--resume", str(out), "--draws", "4", "--progress", "none"]) == 0   # and it goes on
    assert (out / "report.html").is_file() and resume_meta(out)["chains"][0]["draw"] == 12


def test_sigint_whose_interrupt_a_finalizer_swallows_still_stops_the_writing(floor, tmp_path, capsys, monkeypatch):
    """Ctrl-C while the outputs are written whose KeyboardInterrupt lands in a library object's
    ``__del__`` (a clingo AST node's, say): Python swallows an exception raised there and goes
    on, so the run stops before its next file instead, says so in one line and prints no
    traceback."""
    import os
    from semmap_pp.run import spread

    real = spread.posterior_worlds

    class Finalized:
        def __del__(self):
            os.kill(os.getpid(), signal.SIGINT)
            for _ in range(100_000):         # the handler runs here, inside __del__
                pass

    def worlds(run, n):
        Finalized()
        return real(run, n)

    out = tmp_path / "swallowed"
    monkeypatch.setattr(spread, "posterior_worlds", worlds)
    code = main(["map", str(floor), "--out", str(out), "--chains", "2", "--cores", "1", "--tune", "2",
                 "--draws", "6", "--n-inner", "5", "--spread-draws", "0", "--progress", "none"])
    monkeypatch.undo()
    assert _check_saved(out, capsys.readouterr().err, code, " --draws N") == {"resume.npz"}


def _sigint_at(name):
    """An os.write that sends this process SIGINT at the first write of the file ``name``."""
    import os

    real = os.write

    def write(fd, data):
        try:
            where = os.readlink(f"/proc/self/fd/{fd}")
        except OSError:
            where = ""
        if Path(where).name.startswith(f".{name}.") and not write.sent:
            write.sent = True
            os.kill(os.getpid(), signal.SIGINT)
        return real(fd, data)

    write.sent = False
    return write


def test_sigint_while_resume_npz_is_written_lets_it_finish(floor, tmp_path, capsys, monkeypatch):
    import os

    out = tmp_path / "r"
    # the handler the command found (Python's own; SIG_IGN in a job a shell started in the
    # background, which ignores Ctrl-C) is the one it must put back
    before = signal.getsignal(signal.SIGINT)
    monkeypatch.setattr(os, "write", _sigint_at("resume.npz"))
    code = main(["map", str(floor), "--out", str(out), "--chains", "2", "--cores", "1", "--tune", "2",
                 "--draws", "6", "--n-inner", "5", "--spread-draws", "0", "--progress", "none"])
    monkeypatch.undo()
    err = capsys.readouterr().err
    assert "semmap: interrupted: finishing resume.npz, then stopping" in err
    assert _check_saved(out, err, code, " --draws N") == {"resume.npz"}
    assert signal.getsignal(signal.SIGINT) is before     # the handler put back


def test_sigint_while_writing_after_an_interrupted_search_says_resume(interrupted, tmp_path, capsys, monkeypatch):
    """A search stopped early (the interrupted run's resume file) and Ctrl-C again at graph.graphml:
    `--resume DIR` alone continues it; the files before graph.graphml are complete."""
    import os
    import shutil

    out = tmp_path / "again"
    shutil.copytree(interrupted[0], out)
    (out / "report.html").unlink()
    monkeypatch.setattr(os, "write", _sigint_at("graph.graphml"))
    code = main(["map", "--resume", str(out), "--budget", "1", "--progress", "none"])
    monkeypatch.undo()
    names = _check_saved(out, capsys.readouterr().err, code, "")
    assert {"world.json", "labels.png", "trace.nc", "diagnostics.txt", "world.geojson"} <= names
    assert resume_meta(out)["stopped"] == "budget"
