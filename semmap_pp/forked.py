"""A function run in a forked process while this one goes on: report.html's figures.

``semmap map`` with two cores or more (``--cores``) hands the figures of report.html that need
neither world.json nor the plan files (:func:`semmap_pp.outputs.write.posterior_pngs`: 1.5-2 s of
matplotlib on a real floor) to a child process forked after the sampling, and writes world.json,
the plan files and their own figures meanwhile; then it takes the child's PNG bytes through a pipe
and writes the rest. The child writes no file and ignores Ctrl-C (this process ends it). Whatever
keeps the child from handing the figures over (a system without ``fork``, a process running
other Python threads, which a fork does not copy, so that a lock one of them holds stays held in
the child; the child killed, an error in it, no answer within :data:`WAIT_S`), they are drawn in
this process instead, as with one core: the outputs are the same bytes either way.

``semmap map`` with two cores also makes its start world and the run's shared tables in one
(:func:`semmap_pp.run.pipeline.timed_start_world`, 1-2 s of one core on a real floor) while it
imports PyMC, ArviZ and matplotlib, which take as long, and draws graph.png beside the figures, and W*'s polish tries half of a round's
crosses in one while it tries the other half (:meth:`semmap_pp.sampler.ascent_walls.Climb.each`).

>>> import os
>>> Forked(os.getpid, fork=False).result() == os.getpid()
True
"""

from __future__ import annotations

import multiprocessing
import signal
import threading
from typing import Callable

#: Seconds to wait for the child's figures before it is ended and they are drawn here.
WAIT_S = 600.0


class Forked:
    """``make()`` run in a child process forked now (when ``fork`` and the system can), its
    result handed back by :meth:`result`; else, or when the child fails, run by :meth:`result`
    itself. ``make``'s result must pickle. :meth:`close` ends a child still running."""

    def __init__(self, make: Callable[[], object], *, fork: bool):
        self._make = make
        self._proc = self._conn = None
        # a daemonic process (a worker of a pool) may not have children of its own
        if fork and "fork" in multiprocessing.get_all_start_methods() and \
                not multiprocessing.current_process().daemon and _one_thread():
            self._start()

    def _start(self) -> None:
        ctx = multiprocessing.get_context("fork")
        recv, send = ctx.Pipe(duplex=False)
        proc = ctx.Process(target=_child, args=(self._make, send), daemon=True)
        # SIGINT blocked across the fork: the child sets it aside before it could run this
        # process's handler; one pressed meanwhile reaches this process when unblocked
        blocked = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
        try:
            proc.start()
        except OSError:          # no process to be had (limits, memory): drawn here
            recv.close()
            return
        finally:
            signal.pthread_sigmask(signal.SIG_SETMASK, blocked)
            send.close()
        self._proc, self._conn = proc, recv

    def result(self):
        """The child's result, or ``make()`` here when there is no child or it handed none."""
        if self._proc is not None:
            try:     # ready also when the child ended without a word: recv then raises EOFError
                ok, value = self._conn.recv() if self._conn.poll(WAIT_S) else (False, None)
            except (EOFError, OSError):
                ok, value = False, None
            finally:
                self.close()                     # ended, or no answer in time: ended now
            if ok:
                return value
        return self._make()

    def close(self) -> None:
        """End the child if it still runs (Ctrl-C or an error here before :meth:`result`); a child
        that has ended is only reaped."""
        if self._proc is not None:
            self._proc.kill()
            self._proc.join()
            self._conn.close()
            self._proc = self._conn = None


def _one_thread() -> bool:
    """Whether this process runs no Python thread but the main one. The idle worker threads of
    OpenBLAS (numpy's and scipy's, two on two cores) are not counted: OpenBLAS stops them
    before every fork (``pthread_atfork``) and starts them again when next needed, as PyMC's
    forked chains rely on too."""
    return threading.active_count() == 1


def _child(make, conn) -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)       # Ctrl-C is the parent's to handle
    signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})
    try:
        reply = (True, make())
    except BaseException:     # drawn again by the parent, which then reports what goes wrong
        reply = (False, None)
    try:
        conn.send(reply)
    except (OSError, ValueError):    # the parent is gone or closed the pipe
        pass
    finally:
        conn.close()


__all__ = ["Forked"]
