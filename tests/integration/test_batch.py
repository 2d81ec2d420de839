"""`semmap batch`: tasks on a Dask LocalCluster (processes), failures kept apart, resumable."""

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from semmap_pp.run import batch as B
from semmap_pp.cli import main
from semmap_pp.errors import MapError

ROOT = Path(__file__).resolve().parents[2]
INTEL = ROOT / "tests" / "data" / "maps" / "intel_corner.yaml"
TINY = ["--chains", "2", "--tune", "2", "--draws", "4", "--n-inner", "5", "--spread-draws", "0"]


def test_tasks_are_laid_out_by_map_rules_and_seed(tmp_path):
    maps = [Path("a/x.yaml"), Path("b/x.yaml"), Path("y.png"), Path("c/y.pgm")]
    one = B.plan_tasks(maps, tmp_path, None, None)       # a folder per floor: named by the folder
    assert [Path(t.out).relative_to(tmp_path).as_posix() for t in one] == ["a", "b", "y", "c"]
    assert [Path(t.out).name for t in B.plan_tasks([Path("a/x.yaml"), Path("a/x.png")], tmp_path,
                                                   None, None)] == ["a", "a-2"]
    many = B.plan_tasks(maps[:1], tmp_path, ["rules/table3.lp", "rules/none.lp"], [0, 3])
    assert [Path(t.out).relative_to(tmp_path).as_posix() for t in many] == [
        "x/table3/seed-0", "x/table3/seed-3", "x/none/seed-0", "x/none/seed-3"]
    assert [(t.rules, t.seed) for t in many][1] == ("rules/table3.lp", 3)
    cmd = B.task_command(many[1], ["--cores", "1"])
    assert cmd[3:] == ["map", "a/x.yaml", "--out", many[1].out, "--force", "--progress", "none",
                       "--rules", "rules/table3.lp", "--seed", "3", "--cores", "1"]


def test_maps_are_files_folders_or_patterns(tmp_path):
    for name in ("b.yaml", "a.yaml", "c.png"):
        (tmp_path / name).write_text("")
    (tmp_path / "imgs").mkdir()
    (tmp_path / "imgs" / "m.pgm").write_text("")
    assert [p.name for p in B.expand_maps([str(tmp_path)])] == ["a.yaml", "b.yaml"]
    assert [p.name for p in B.expand_maps([str(tmp_path / "imgs")])] == ["m.pgm"]
    assert [p.name for p in B.expand_maps([str(tmp_path / "*.png"), str(tmp_path / "c.png")])] == ["c.png"]
    with pytest.raises(MapError, match="matches no file"):
        B.expand_maps([str(tmp_path / "*.npy")])
    with pytest.raises(MapError, match="no such file"):
        B.expand_maps([str(tmp_path / "nope.yaml")])


@pytest.mark.parametrize("found_by", ["folder", "pattern"])
def test_a_map_found_under_a_name_that_is_not_utf8_stops_the_batch_before_it_starts(tmp_path, capsys, found_by):
    # the folder's own names are UTF-8 (semmap checks its arguments); one it holds is not (issue 55 F7:
    # the task's name broke the cluster's messages, and every task failed)
    (tmp_path / "a.yaml").write_text("")
    os.close(os.open(os.fsencode(tmp_path) + b"/b\xe9.yaml", os.O_CREAT | os.O_WRONLY))
    item = str(tmp_path) if found_by == "folder" else str(tmp_path / "*.yaml")
    with pytest.raises(MapError, match="not UTF-8 text") as exc:
        B.expand_maps([item])
    assert str(exc.value).startswith(f"{tmp_path}/b\\xe9.yaml: ")
    assert main(["batch", item, "--out", str(tmp_path / "out")]) == 2
    assert "b\\xe9.yaml: not UTF-8 text" in capsys.readouterr().err
    assert not (tmp_path / "out").exists()


@pytest.fixture(scope="module")
def maps(tmp_path_factory):
    d = tmp_path_factory.mktemp("maps")
    for f in INTEL.parent.glob("intel_corner.*"):
        shutil.copy(f, d / f.name)
    (d / "broken.png").write_bytes(b"not a png at all")
    return d


@pytest.fixture(scope="module")
def batch_run(maps, tmp_path_factory):
    out = tmp_path_factory.mktemp("batch") / "out"
    code = main(["batch", str(maps / "intel_corner.yaml"), str(maps / "broken.png"), "--out", str(out),
                 "--workers", "2", "--progress", "none", *TINY])
    return code, out


def test_a_failed_map_is_recorded_and_the_others_go_on(batch_run):
    code, out = batch_run
    assert code == 1
    rows = {Path(r["map"]).name: r for r in json.loads((out / "summary.json").read_text())["tasks"]}
    assert rows["intel_corner.yaml"]["status"] == "ok"
    assert rows["broken.png"]["status"] == "failed"
    assert "broken.png" in rows["broken.png"]["error"] and "\n" not in rows["broken.png"]["error"]
    assert B.complete(out / "intel_corner")
    csv = (out / "summary.csv").read_text().splitlines()
    assert csv[0].startswith("map,rules,seed,status,room,corridor,hall,other,doors,cpr")
    assert len(csv) == 3
    index = (out / "index.html").read_text()
    assert 'href="intel_corner/report.html"' in index and 'src="intel_corner/overlay.png"' in index


def test_batch_writes_what_semmap_map_writes(batch_run, maps, tmp_path):
    _, out = batch_run
    alone = tmp_path / "alone"
    assert main(["map", str(maps / "intel_corner.yaml"), "--out", str(alone), "--progress", "none",
                 *TINY]) == 0                       # the model's two cores; the batch's task ran on one
    mine = sorted(p.name for p in (out / "intel_corner").iterdir())
    assert mine == sorted(p.name for p in alone.iterdir())
    for name in ("world.json", "labels.png", "rooms.png", "regions.png", "types.pgm", "world.geojson"):
        assert (out / "intel_corner" / name).read_bytes() == (alone / name).read_bytes(), name


def test_a_rerun_skips_complete_tasks_and_force_redoes_them(batch_run, maps, capsys):
    _, out = batch_run
    before = (out / "intel_corner" / "world.json").stat().st_mtime_ns
    assert main(["batch", str(maps / "intel_corner.yaml"), "--out", str(out), "--workers", "1",
                 "--progress", "none", *TINY]) == 0
    assert "0 run, 1 skipped" in capsys.readouterr().out
    assert (out / "intel_corner" / "world.json").stat().st_mtime_ns == before
    rows = json.loads((out / "summary.json").read_text())["tasks"]
    assert [r["status"] for r in rows] == ["skipped"] and rows[0]["room"] is not None
    assert main(["batch", str(maps / "intel_corner.yaml"), "--out", str(out), "--workers", "1",
                 "--progress", "none", "--force", *TINY]) == 0
    assert "1 run, 0 skipped" in capsys.readouterr().out
    assert (out / "intel_corner" / "world.json").stat().st_mtime_ns > before


def test_a_task_past_its_timeout_fails_alone(maps, tmp_path, capsys):
    out = tmp_path / "t"
    assert main(["batch", str(maps / "intel_corner.yaml"), "--out", str(out), "--workers", "1",
                 "--progress", "plain", "--timeout", "0.5", *TINY]) == 1
    err = capsys.readouterr().err
    assert "batch: 1/1 done, intel_corner failed: timed out after 0.5 s (1 failed, 0 running)" in err
    row = json.loads((out / "summary.json").read_text())["tasks"][0]
    assert row["status"] == "failed" and row["error"] == "timed out after 0.5 s"
    assert not B.complete(out / "intel_corner")


def test_bad_rules_stop_the_batch_before_any_task(maps, tmp_path, capsys):
    bad = tmp_path / "bad.lp"
    bad.write_text('#script (python) import os #end.\n')
    assert main(["batch", str(maps / "intel_corner.yaml"), "--out", str(tmp_path / "o"),
                 "--rules", str(bad), "--progress", "none"]) == 2
    err = capsys.readouterr().err.strip()
    assert "bad.lp" in err and "\n" not in err
    assert not (tmp_path / "o" / "intel_corner").exists()


def _scheduler(tmp_path, *worker_args, env=None):
    """A scheduler and two workers started as a user would (`dask scheduler`, `dask worker`)."""
    sched_file = tmp_path / "scheduler.json"
    e = dict(os.environ, **(env or {}))
    procs = [subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_scheduler", "--host", "127.0.0.1",
                               "--port", "0", "--dashboard-address", ":0", "--scheduler-file", str(sched_file)],
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=e)]
    for _ in range(100):
        if sched_file.exists() and sched_file.stat().st_size:
            break
        time.sleep(0.2)
    address = json.loads(sched_file.read_text())["address"]
    for _ in range(2):
        procs.append(subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_worker", address,
                                       "--nthreads", "1", "--nworkers", "1", *worker_args],
                                      stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=e))
    from distributed import Client
    with Client(address, timeout="30s") as c:
        c.wait_for_workers(2, timeout=60)
    return address, procs


def _stop(procs):
    for p in procs:
        p.send_signal(signal.SIGTERM)
    for p in procs:
        try:
            p.wait(timeout=20)
        except subprocess.TimeoutExpired:
            p.kill()


def test_a_worker_killed_mid_task_is_recorded_and_the_others_go_on(maps, tmp_path):
    """Against a scheduler that gives up on a task once a worker died with it (allowed-failures 0),
    one worker is killed while it runs a task: that task is failed with its one-line error, the other
    is done by the worker left."""
    address, procs = _scheduler(tmp_path, env={"DASK_DISTRIBUTED__SCHEDULER__ALLOWED_FAILURES": "0"})
    try:
        second = maps / "second"
        second.mkdir(exist_ok=True)
        for f in maps.glob("intel_corner.*"):
            shutil.copy(f, second / f.name)
        out = tmp_path / "k"
        batch = subprocess.Popen([sys.executable, "-m", "semmap_pp", "batch", str(maps / "intel_corner.yaml"),
                                  str(second / "intel_corner.yaml"), "--out", str(out), "--scheduler", address,
                                  "--progress", "none", *TINY], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                 text=True)
        from distributed import Client
        with Client(address, timeout="30s") as c:
            victim = None
            for _ in range(300):
                busy = {w: ks for w, ks in c.processing().items() if ks}
                if len(busy) >= 1:
                    victim = sorted(busy)[0]
                    break
                time.sleep(0.1)
            assert victim is not None
            time.sleep(1.0)                         # the task's run has started
            pid = c.run(os.getpid, workers=[victim])[victim]
            os.kill(pid, signal.SIGKILL)
        stdout, stderr = batch.communicate(timeout=600)
        assert batch.returncode == 1, stderr
        rows = json.loads((out / "summary.json").read_text())["tasks"]
        status = sorted((r["status"], r["error"] or "") for r in rows)
        assert status[0][0] == "failed" and "a worker died while running it" in status[0][1]
        assert status[1][0] == "ok"
    finally:
        _stop(procs)


def test_a_map_too_large_for_the_workers_is_refused_up_front(maps, tmp_path):
    address, procs = _scheduler(tmp_path, "--memory-limit", "300MB")
    try:
        out = tmp_path / "m"
        assert main(["batch", str(maps / "intel_corner.yaml"), "--out", str(out), "--scheduler", address,
                     "--progress", "none", *TINY]) == 1
        row = json.loads((out / "summary.json").read_text())["tasks"][0]
        assert row["status"] == "failed" and "exceeds the workers' memory limit of 0.3 GB" in row["error"]
        assert not (out / "intel_corner").exists()
    finally:
        _stop(procs)


def test_an_unreachable_scheduler_is_one_line(maps, tmp_path, capsys):
    assert main(["batch", str(maps / "intel_corner.yaml"), "--out", str(tmp_path / "u"),
                 "--scheduler", "tcp://127.0.0.1:9", "--progress", "none"]) == 2
    err = capsys.readouterr().err.strip()
    assert "cannot reach the Dask scheduler at tcp://127.0.0.1:9" in err and "\n" not in err
