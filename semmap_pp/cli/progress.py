"""Live progress of ``semmap map`` on stderr: a ``rich`` table on a terminal, plain lines otherwise.

Both read the per-draw records of :func:`semmap_pp.sampler.step.draw_info` (phase, chain, draw, log
posterior, units, CPR, temperature) that :func:`semmap_pp.sampler.sampling.sample_worlds` delivers in the
main process. PyMC's own progress bar stays off.

Plain mode (stderr is not a terminal, e.g. a log file or the tests) prints one line at the first
draw (``sampling started``), then one line every ``every`` seconds, each with the latest draw::

    progress: chain 1/2 burn-in draw 12/16 | log p -23345.1 | units 10 | CPR 0.853 | T 3.20 | 4.1 s, ~2.0 s left

A chain's first draw slower than :data:`COMPILE_SECONDS` compiled code on first use (numba, once
after an install or an update of the package; later runs load it from the cache): a plain line
says so when it ends, and the rich table's caption gives it.
"""

from __future__ import annotations

import math
import sys
import time


#: A chain's first draw slower than this, seconds, is said to have compiled code on first use.
COMPILE_SECONDS = 1.0


def compile_text(seconds: dict) -> str:
    """What the progress says of the first draws that compiled code (``seconds``: chain -> s).

    >>> compile_text({0: 7.84, 1: 9.1})
    'first draw of chain 1 7.8 s, chain 2 9.1 s: compiling code on first use (numba; once after an install or an update, later runs load it from the cache)'
    """
    each = ", ".join(f"chain {c + 1} {s:.1f} s" for c, s in sorted(seconds.items()))
    return (f"first draw of {each}: compiling code on first use (numba; once after an install or an "
            f"update, later runs load it from the cache)")


class Progress:
    """Per-draw progress callback; use as a context manager around sampling.

    The time left is the draws left times the mean time per draw of the chains that have made
    two or more, divided by the chains that run at once: measured from each chain's first draw,
    so the set-up before sampling (start worlds, worker processes; tens of seconds on a large
    map) does not count as sampling time. Unknown until a chain has made two draws.

    Parameters
    ----------
    chains : int
    draws_left : int
        Real draws still to make over all chains (for the time left).
    budget : float, optional
        Seconds of sampling allowed; caps the time left.
    mode : {"auto", "rich", "plain", "none"}
        ``auto`` is rich on a terminal, plain otherwise.
    every : float
        Seconds between plain lines.
    parallel : int
        Chains sampled at once (``min(cores, chains)``).
    clock : callable, optional
        Seconds, monotonic (tests pass their own).
    """

    def __init__(self, chains: int, draws_left: int, *, budget: float | None = None, mode: str = "auto",
                 every: float = 5.0, stream=None, parallel: int = 1, clock=time.monotonic):
        self.stream = stream if stream is not None else sys.stderr
        if mode == "auto":
            mode = "rich" if self.stream.isatty() else "plain"
        self.mode, self.every = mode, float(every)
        self.chains, self.draws_left, self.budget = chains, max(int(draws_left), 1), budget
        self.parallel = max(1, min(int(parallel), int(chains)))
        self.clock = clock
        self.latest: dict[int, dict] = {}
        self.done = 0
        self._first: dict[int, float] = {}     # chain -> elapsed seconds at its first draw
        self._last: dict[int, float] = {}      # chain -> elapsed seconds at its latest draw
        self._count: dict[int, int] = {}       # chain -> draws made
        self.compiled: dict[int, float] = {}   # chain -> seconds of a first draw that compiled code
        self.t0 = self.clock()
        self._next_line = 0.0
        self._live = None

    # ------------------------------------------------------------------ context
    def __enter__(self):
        self.t0 = self.clock()
        if self.mode == "rich":
            from rich.console import Console
            from rich.live import Live

            self._live = Live(self._table(), console=Console(file=self.stream), refresh_per_second=4,
                              transient=False)
            self._live.__enter__()
        return self

    def __exit__(self, *exc):
        if self._live is not None:
            self._live.update(self._table())
            self._live.__exit__(*exc)
            self._live = None
        return False

    # ------------------------------------------------------------------ numbers
    def elapsed(self) -> float:
        return self.clock() - self.t0

    def seconds_left(self) -> float:
        """Estimated seconds to go (class docstring), capped by what is left of the budget
        (counted from the first draw); ``inf`` while no chain has made two draws."""
        per_draw = [(self._last[c] - self._first[c]) / (n - 1)
                    for c, n in self._count.items() if n >= 2]
        if not per_draw:
            return math.inf
        left = max(self.draws_left - self.done, 0) * (sum(per_draw) / len(per_draw)) / self.parallel
        if self.budget is not None:
            left = min(left, max(self.budget - (self.elapsed() - min(self._first.values())), 0.0))
        return max(left, 0.0)

    def __call__(self, info: dict) -> None:
        chain, now = info["chain"], self.elapsed()
        if not info["stopped"]:
            self.done += 1
            self._first.setdefault(chain, now)
            self._last[chain] = now
            self._count[chain] = self._count.get(chain, 0) + 1
            slow = self._count[chain] == 1 and info.get("seconds", 0.0) > COMPILE_SECONDS
            if slow:
                self.compiled[chain] = info["seconds"]
                if self.mode == "plain":
                    print(f"progress: {compile_text({chain: info['seconds']})}", file=self.stream, flush=True)
        self.latest[chain] = info
        if self.mode == "plain":
            if now >= self._next_line:
                first = self._next_line == 0.0
                self._next_line = now + self.every
                head = "sampling started: " if first else ""
                print(f"progress: {head}{self.line(info)}", file=self.stream, flush=True)
        elif self._live is not None:
            self._live.update(self._table())

    # ------------------------------------------------------------------ text
    def line(self, info: dict) -> str:
        total = info["total"] if info["total"] >= 0 else "?"
        left = self.seconds_left()
        left_s = "?" if not math.isfinite(left) else f"~{left:.1f} s left"
        if info["stopped"]:
            return (f"chain {info['chain'] + 1}/{self.chains} stopped after {info['draw']} draws"
                    f" | best log p {info['best_logp']:.1f} | {self.elapsed():.1f} s")
        cpr = "-" if math.isnan(info["cpr"]) else f"{info['cpr']:.3f}"
        return (f"chain {info['chain'] + 1}/{self.chains} {info['phase']} draw {info['draw'] + 1}/{total}"
                f" | log p {info['logp']:.1f} | units {info['n_units']} | CPR {cpr}"
                f" | T {info['temperature']:.2f} | {self.elapsed():.1f} s, {left_s}")

    def _table(self):
        from rich.table import Table

        left = self.seconds_left()
        caption = (f"{self.elapsed():.0f} s elapsed, "
                   + ("time left unknown" if not math.isfinite(left) else f"about {left:.0f} s left")
                   + (f" (budget {self.budget:g} s)" if self.budget is not None else "")
                   + " - Ctrl-C stops and writes what is done"
                   + (f"\n{compile_text(self.compiled)}" if self.compiled else ""))
        table = Table(title="semmap map: sampling", caption=caption)
        for col in ("chain", "phase", "draw", "log posterior", "best", "units", "CPR", "T"):
            table.add_column(col, justify="right")
        for c in range(self.chains):
            i = self.latest.get(c)
            if i is None:
                table.add_row(str(c + 1), "waiting", "", "", "", "", "", "")
                continue
            phase = "stopped" if i["stopped"] else i["phase"]
            total = i["total"] if i["total"] >= 0 else "?"
            cpr = "-" if math.isnan(i["cpr"]) else f"{i['cpr']:.3f}"
            temp = "" if math.isnan(i["temperature"]) else f"{i['temperature']:.2f}"
            table.add_row(str(c + 1), phase, f"{i['draw'] + 1}/{total}", f"{i['logp']:.1f}",
                          f"{i['best_logp']:.1f}", str(i["n_units"]), cpr, temp)
        return table
