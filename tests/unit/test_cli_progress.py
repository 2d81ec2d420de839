"""The live progress of ``semmap map`` (semmap_pp.cli.progress): the time left comes from the
time per draw since each chain's first draw, not from the set-up before sampling."""

import io
import math

from semmap_pp.cli.progress import Progress


class Clock:
    def __init__(self):
        self.t = 0.0

    def __call__(self):
        return self.t


def info(chain, draw, stopped=False):
    return {"chain": chain, "draw": draw, "total": 40, "phase": "burn-in", "logp": -1.0,
            "best_logp": -1.0, "n_units": 3, "cpr": 0.9, "temperature": 1.0, "stopped": stopped}


def test_set_up_time_does_not_count_as_sampling_time():
    """40 s of start worlds, then two chains in parallel at 0.5 s a draw: after a few draws the
    time left is the draws left times 0.5 s over two chains, not 40 s a draw."""
    clock = Clock()
    p = Progress(2, 80, mode="plain", stream=io.StringIO(), parallel=2, clock=clock)
    with p:
        clock.t = 40.0
        p(info(0, 0))
        p(info(1, 0))
        assert math.isinf(p.seconds_left())        # no chain has two draws yet
        for d in range(1, 5):
            clock.t += 0.5
            p(info(0, d))
            p(info(1, d))
        assert p.done == 10
        assert abs(p.seconds_left() - 70 * 0.5 / 2) < 1e-9
        assert "~17.5 s left" in p.line(info(1, 4))


def test_sequential_chains_and_the_budget_cap():
    """One core: the chains run one after another, so the draws left take their full time; a
    budget counted from the first draw caps the estimate; stopped draws are not draws."""
    clock = Clock()
    p = Progress(2, 20, mode="none", budget=6.0, parallel=1, clock=clock)
    clock.t = 10.0
    for d in range(5):
        p(info(0, d))
        clock.t += 1.0
    # 5 draws at 1 s (the last at 14 s, now 15 s); 15 left at 1 s = 15 s, but the budget
    # counted from the first draw leaves 6 - (15 - 10) = 1 s
    assert abs(p.seconds_left() - 1.0) < 1e-9
    p.budget = None
    assert abs(p.seconds_left() - 15.0) < 1e-9
    p(info(0, 5, stopped=True))
    assert p.done == 5
    q = Progress(2, 20, mode="none", parallel=4, clock=clock)   # parallel capped by the chains
    assert q.parallel == 2


def test_a_first_draw_that_compiled_code_is_said_with_its_cause():
    """A chain's first draw over COMPILE_SECONDS gets a line naming the compiling; a fast first
    draw, or a slow later one, does not."""
    out = io.StringIO()
    p = Progress(2, 80, mode="plain", stream=out, parallel=2, clock=Clock())
    with p:
        p(dict(info(0, 0), seconds=7.5))
        p(dict(info(1, 0), seconds=0.01))
        p(dict(info(1, 1), seconds=9.0))
    lines = [ln for ln in out.getvalue().splitlines() if "compiling code on first use" in ln]
    assert len(lines) == 1 and "chain 1 7.5 s" in lines[0]
    assert p.compiled == {0: 7.5}
    quiet = Progress(1, 10, mode="none", clock=Clock())
    quiet(info(0, 0))                     # records without the time of the draw: nothing said
    assert quiet.compiled == {}
