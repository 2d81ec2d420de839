"""Comparing knowledge sets (``semmap compare``): the same map and seed sampled under two rule files.

Pure functions over :class:`~semmap_pp.pipeline.MapRun` objects. Per rule set:

* W*: its number of units, cell prediction rate (CPR) and log posterior. The log posteriors of two
  rule sets are values of *different* targets (the knowledge changes the types, hence the prior),
  so only CPR and the defects below compare the two worlds on the same scale.
* convergence: R-hat and bulk / tail ESS of every label-invariant summary, and the verdict.
* posterior spread: ``n`` sampled worlds (evenly thinned over chains and draws), rasterised on the
  building lattice and accumulated in :class:`~semmap_pp.diagnostics.SpreadAccumulator`;
  ``wall_spread`` is its mean Bernoulli variance of the wall indicator over the cells ever wall
  (0 = every world agrees), ``wall_disagreement_m2`` the expected area on which two sampled worlds
  disagree about wall (:func:`semmap_pp.outputs.spread.wall_disagreement_m2`). The mean divides by a
  number of cells that differs from run to run (and grows with every rare excursion), so only the
  area compares two rule sets on the same cells (docs/knowledge_comparison.md).
* conditional wall spread (:func:`conditional_wall_sd`): per wall of W*, the posterior standard
  deviation of its position given the rest of W*, computed exactly over the offsets within
  ``CONDITIONAL_OFFSET_M`` (no sampling, so it does not depend on the chains converging);
  ``wall_sd_m`` is its mean over W*'s walls.
* topological defects (:mod:`semmap_pp.derive.defects`): adjacent rooms whose connecting walls
  differ by more than ``[diagnostics] defect_tolerance_m``, in W* and averaged over the sampled
  worlds (typed as the sampler typed them).

Examples
--------
>>> rows = [RuleSetSummary("table3", "table3.lp", 10, 0.9, -100.0, False, {"cpr": 1.2}, {"cpr": 40.0},
...                        {"cpr": 30.0}, 0.05, 8, 1, 1.5, 3.0),
...         RuleSetSummary("none", "none.lp", 12, 0.8, -120.0, False, {"cpr": 1.1}, {"cpr": 50.0},
...                        {"cpr": 45.0}, 0.09, 8, 3, 2.5, 2.0)]
>>> print(compare_table(rows).splitlines()[4])
| CPR of W* | 0.9000 | 0.8000 |
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

from semmap_pp import world as W
from semmap_pp.derive.defects import count_defects
from semmap_pp.diagnostics import SpreadAccumulator, format_rhat


@dataclass(frozen=True)
class RuleSetSummary:
    """One column of the comparison table (see the module docstring)."""

    name: str
    rules: str
    n_units: int
    cpr: float
    log_posterior: float
    converged: bool
    rhat: dict            # summary name -> R-hat
    ess_bulk: dict
    ess_tail: dict
    wall_spread: float
    n_worlds: int
    defects_best: int     # in W*
    defects_mean: float   # mean over the sampled worlds
    seconds: float
    wall_disagreement_m2: float = math.nan
    wall_sd_m: float = math.nan   # mean conditional sd of W*'s wall positions
    spread_chains: tuple = ()     # the chains (from 1) the sampled worlds come from: the best one's mode
    spread_first_draw: int = 1    # their first draw (from 1): the draws before it still settling
    around_wstar: bool = False    # whether they come from the sample around W* (else the search's draws)


# Offsets tried per wall by :func:`conditional_wall_sd` in ``summarise``: +- 0.25 m.
CONDITIONAL_OFFSET_M = 0.25


def conditional_wall_sd(post, world, max_offset: int) -> np.ndarray:
    """Posterior standard deviation (cells) of each wall of ``world`` given the rest of it.

    For every active unit (in slot order) and each of its four sides in the rectangle's order
    ``(r0, c0, r1, c1)`` (top, left, bottom, right on the lattice),
    the side is moved by ``-max_offset .. max_offset`` cells with everything else fixed; the
    target ``post`` (log posterior, knowledge as configured) weighs each offset, ``p(o) ∝
    exp(log π(W_o))`` (invalid worlds weigh 0), and the standard deviation of ``o`` under ``p``
    is the wall's spread: the exact Gibbs conditional, no sampling involved. Proposals go
    through one tracker (:meth:`Posterior.start`), so each costs an incremental update.

    Returns
    -------
    np.ndarray of float, shape (4 * n_units,)
    """
    tr = post.start(world)
    offsets = np.arange(-max_offset, max_offset + 1)
    out = []
    for s in W.active_slots(world).tolist():
        rect = [int(v) for v in world.rects[s]]
        for side in range(4):
            lp = np.full(len(offsets), -np.inf)
            for k, o in enumerate(offsets.tolist()):
                r = list(rect)
                r[side] += o
                if r[2] - r[0] < 1 or r[3] - r[1] < 1:
                    continue
                lp[k] = tr.logp if o == 0 else tr.propose(W.replace(world, s, tuple(r)), (s,)).logp
            p = np.exp(lp - lp.max())
            p /= p.sum()
            mean = float((p * offsets).sum())
            out.append(math.sqrt(max(float((p * (offsets - mean) ** 2).sum()), 0.0)))
    return np.array(out)


def mean_wall_sd_m(post, world) -> float:
    """:func:`conditional_wall_sd` over offsets within ``CONDITIONAL_OFFSET_M``, averaged over the
    walls of ``world``, in metres (NaN for a world without units)."""
    res = post.cells.resolution
    sd = conditional_wall_sd(post, world, max(1, round(CONDITIONAL_OFFSET_M / res)))
    return float(sd.mean()) * res if len(sd) else math.nan


def typed_sampled_worlds(run, n: int) -> list:
    """Up to ``n`` recorded worlds of ``run``'s chains in the best chain's mode, typed by its own
    target (knowledge on when it had rules): :func:`semmap_pp.outputs.write.posterior_worlds`."""
    from semmap_pp.outputs.write import posterior_worlds

    return posterior_worlds(run, n)


def _accumulate(worlds, shape, wall: int) -> SpreadAccumulator:
    from semmap_pp.outputs.spread import accumulate

    return accumulate(worlds, shape, wall)[0]


def wall_spread(worlds, shape, wall: int) -> float:
    """Mean Bernoulli variance of the wall indicator of ``worlds`` on a lattice of ``shape``."""
    return _accumulate(worlds, shape, wall).wall_spread()


def wall_disagreement(worlds, shape, wall: int, resolution: float) -> float:
    """Expected area (m²) where two of ``worlds`` disagree about wall (``Σ 2p(1-p)`` · cell area)."""
    from semmap_pp.outputs.spread import wall_disagreement_m2

    return wall_disagreement_m2(_accumulate(worlds, shape, wall).p_wall(), resolution)


def summarise(run, name: str, rules: str, worlds) -> RuleSetSummary:
    """The comparison column of one run, with ``worlds`` its typed sampled worlds."""
    frame, model = run.inputs.frame, run.inputs.model
    c = frame.cells
    tol = model.diagnostics.defect_tolerance_m
    defects = count_defects(worlds, c.resolution, c.wall, c.adjacency_dilation, tol)
    best = count_defects([run.world], c.resolution, c.wall, c.adjacency_dilation, tol)
    q = run.report.quantities
    from semmap_pp.outputs.spread import wall_disagreement_m2
    from semmap_pp.pipeline import figure_source, run_target, spread_first_draw

    acc = _accumulate(worlds, frame.shape, c.wall)
    src = figure_source(run)          # the sample around W*, or the search's own draws
    return RuleSetSummary(
        name=name, rules=rules, n_units=len(run.semantic.unit_ids), cpr=float(run.semantic.cpr),
        log_posterior=float(run.semantic.log_posterior), converged=bool(run.report.ok),
        rhat={x.name: x.rhat for x in q}, ess_bulk={x.name: x.ess_bulk for x in q},
        ess_tail={x.name: x.ess_tail for x in q},
        wall_spread=acc.wall_spread(), n_worlds=len(worlds),
        defects_best=int(best[0]), defects_mean=float(defects.mean()) if len(defects) else math.nan,
        seconds=float(run.seconds), wall_disagreement_m2=wall_disagreement_m2(acc.p_wall(), c.resolution),
        wall_sd_m=mean_wall_sd_m(run_target(run.inputs), run.world),
        spread_chains=tuple(src.report.mode_chains()), spread_first_draw=spread_first_draw(src) + 1,
        around_wstar=src is not run)


def _fmt(v, spec: str) -> str:
    if isinstance(v, float) and not math.isfinite(v):
        return "nan"
    return format(v, spec)


def compare_table(rows: list[RuleSetSummary]) -> str:
    """A Markdown table: one row per quantity, one column per rule set."""
    lines = ["| quantity | " + " | ".join(r.name for r in rows) + " |",
             "|---|" + "---:|" * len(rows)]

    def add(label, values):
        lines.append(f"| {label} | " + " | ".join(values) + " |")

    add("rule file", [r.rules for r in rows])
    add("units in W*", [str(r.n_units) for r in rows])
    add("CPR of W*", [_fmt(r.cpr, ".4f") for r in rows])
    add("log posterior of W* (own target)", [_fmt(r.log_posterior, ".1f") for r in rows])
    add("converged", ["yes" if r.converged else "no" for r in rows])
    add("topological defects in W*", [str(r.defects_best) for r in rows])
    add("defects, mean over sampled worlds", [_fmt(r.defects_mean, ".2f") for r in rows])
    add("wall spread (mean p(1-p) over cells ever wall)", [_fmt(r.wall_spread, ".4f") for r in rows])
    add("wall disagreement, m² (Σ 2p(1-p) · cell area)", [_fmt(r.wall_disagreement_m2, ".2f") for r in rows])
    add("wall sd given the rest of W*, mean over its walls, m", [_fmt(r.wall_sd_m, ".4f") for r in rows])
    add("sampled worlds (chains: the best one's mode; from draw; of the sample around W* or the search)",
        [f"{r.n_worlds} ({', '.join(map(str, r.spread_chains))}; {r.spread_first_draw}; "
         f"{'around W*' if r.around_wstar else 'search'})" for r in rows])
    names = list(rows[0].rhat)
    for n in names:
        add(f"R-hat {n}", [format_rhat(r.rhat.get(n, math.nan)) for r in rows])
    for n in names:
        add(f"ESS bulk / tail {n}", [f"{_fmt(r.ess_bulk.get(n, math.nan), '.0f')} / "
                                     f"{_fmt(r.ess_tail.get(n, math.nan), '.0f')}" for r in rows])
    add("sampling seconds", [_fmt(r.seconds, ".1f") for r in rows])
    return "\n".join(lines)


def compare_dict(rows: list[RuleSetSummary], *, map_path: str, settings: dict) -> dict:
    """compare.json: the settings shared by the runs and one object per rule set (NaN as null)."""
    def clean(v):
        if isinstance(v, dict):
            return {k: clean(x) for k, x in v.items()}
        if isinstance(v, float) and not math.isfinite(v):
            return None
        return v

    return {"format": "semmap_pp.compare/1", "map": map_path, "settings": settings,
            "rule_sets": [clean(asdict(r)) for r in rows]}


def compare_png(runs: list, worlds: list, rows: list[RuleSetSummary]) -> bytes:
    """compare.png: the sampled worlds of each run drawn thin on the map, side by side (paper Fig. 7)."""
    from semmap_pp.outputs.figures import classified_rgb, png, side_by_side, world_lines

    fig, axes, (y0, y1, x0, x1) = side_by_side([r.semantic for r in runs], extra_h=0.6)
    for ax, run, ws, row in zip(axes, runs, worlds, rows):
        ax.imshow(classified_rgb(run.semantic.grid.classes, light=True)[y0:y1, x0:x1],
                  extent=(x0, x1, y1, y0), interpolation="nearest")
        ax.add_collection(world_lines(run.semantic.frame, ws))
        ax.set_xlim(x0, x1)
        ax.set_ylim(y1, y0)
        ax.set_aspect("equal")
        ax.set_xticks([])
        ax.set_yticks([])
        ax.set_title(f"{row.name}: {row.n_worlds} worlds, walls disagree on "
                     f"{_fmt(row.wall_disagreement_m2, '.2f')} m², defects {_fmt(row.defects_mean, '.2f')}",
                     fontsize=9)
    fig.subplots_adjust(0.01, 0.01, 0.99, 1 - 0.5 / fig.get_figheight(), wspace=0.03)
    return png(fig)


__all__ = ["RuleSetSummary", "conditional_wall_sd", "mean_wall_sd_m", "typed_sampled_worlds", "wall_spread", "wall_disagreement", "summarise", "compare_table",
           "compare_dict", "compare_png"]
