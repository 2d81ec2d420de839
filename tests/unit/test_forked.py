"""Figures drawn in a forked process (semmap_pp/forked.py): the child's result when it
hands one over, the same thing drawn here whenever it cannot."""

from __future__ import annotations

import os
import signal
import time

import pytest

from semmap_pp import forked
from semmap_pp.forked import Forked

PARENT = os.getpid()


@pytest.fixture(autouse=True)
def one_thread(monkeypatch):
    """`semmap map` forks from a process of one thread; the test runner may hold others."""
    monkeypatch.setattr(forked, "_one_thread", lambda: True)


def _pid():
    return os.getpid()


def test_the_result_comes_from_a_child_with_fork_and_from_here_without():
    assert Forked(_pid, fork=True).result() != PARENT       # drawn in another process
    assert Forked(_pid, fork=False).result() == PARENT


def _fails_in_child():
    if os.getpid() != PARENT:
        raise RuntimeError("a figure failed")
    return "drawn here"


def _killed_in_child():
    if os.getpid() != PARENT:
        os.kill(os.getpid(), signal.SIGKILL)
    return "drawn here"


@pytest.mark.parametrize("make", [_fails_in_child, _killed_in_child])
def test_a_child_that_hands_nothing_over_leaves_the_drawing_to_this_process(make):
    assert Forked(make, fork=True).result() == "drawn here"


def _ctrl_c_in_child():
    if os.getpid() != PARENT:
        os.kill(os.getpid(), signal.SIGINT)     # a Ctrl-C reaches the whole process group
        time.sleep(0.2)
    return os.getpid()


def test_the_child_leaves_ctrl_c_to_this_process():
    assert Forked(_ctrl_c_in_child, fork=True).result() != PARENT


def _sleeps_in_child():
    if os.getpid() != PARENT:
        time.sleep(60)
    return "drawn here"


def test_a_child_that_does_not_answer_in_time_is_ended_and_the_drawing_done_here(monkeypatch):
    monkeypatch.setattr(forked, "WAIT_S", 0.5)
    f = Forked(_sleeps_in_child, fork=True)
    child = f._proc
    assert f.result() == "drawn here" and not child.is_alive()


def _threads_in_child():
    return forked._one_thread()


def test_no_fork_from_a_process_running_other_threads(monkeypatch):
    import threading

    monkeypatch.undo()                         # the real count
    stop = threading.Event()
    t = threading.Thread(target=stop.wait)
    t.start()
    try:
        assert not forked._one_thread()
        assert Forked(_pid, fork=True).result() == PARENT
    finally:
        stop.set()
        t.join()


def _matmul_in_child():
    import numpy as np
    import scipy.linalg

    a = np.arange(90000, dtype=float).reshape(300, 300) / 90000
    return os.getpid(), float((a @ a).sum()), float(scipy.linalg.norm(a @ a.T))


def test_a_child_forked_beside_the_idle_blas_threads_uses_blas(monkeypatch):
    """numpy's and scipy's OpenBLAS keep idle worker threads (native, not Python's): a fork
    beside them still happens, and the child's products are right, not deadlocked."""
    import numpy as np
    import scipy.linalg

    import threading

    monkeypatch.setattr(forked, "WAIT_S", 60.0)
    a = np.arange(90000, dtype=float).reshape(300, 300) / 90000
    here = (float((a @ a).sum()), float(scipy.linalg.norm(a @ a.T)))   # the pools started
    assert len(os.listdir("/proc/self/task")) > threading.active_count()   # native threads beside
    pid, *sums = Forked(_matmul_in_child, fork=True).result()
    assert pid != PARENT and tuple(sums) == pytest.approx(here, rel=1e-12)


def test_close_ends_a_child_that_still_runs():
    f = Forked(_sleeps_in_child, fork=True)
    child = f._proc
    t = time.perf_counter()
    f.close()
    assert time.perf_counter() - t < 10 and not child.is_alive()
    assert f.result() == "drawn here"           # nothing left to wait for: drawn here
    f.close()                                   # a second close is harmless


def _in_a_daemon(conn):
    conn.send((os.getpid(), Forked(_pid, fork=True).result()))


def test_a_daemonic_process_draws_itself():
    """A pool's worker is daemonic and may not have children: it draws the figures itself."""
    import multiprocessing

    ctx = multiprocessing.get_context("fork")
    recv, send = ctx.Pipe(duplex=False)
    p = ctx.Process(target=_in_a_daemon, args=(send,), daemon=True)
    p.start()
    me, drawn_by = recv.recv()
    p.join()
    assert me == drawn_by and p.exitcode == 0
