"""Comparing knowledge sets (``semmap compare``): the same map and seed sampled under two rule files.

Pure functions over :class:`~semmap_pp.run.results.MapRun` objects. Per rule set:

* W*: its number of units, cell prediction rate (CPR) and log posterior. The log posteriors of two
  rule sets are values of *different* targets (the knowledge changes the types, hence the prior),
  so only CPR and the defects below compare the two worlds on the same scale.
* convergence: R-hat and bulk / tail ESS of every label-invariant summary, and the verdict.
* posterior spread: ``n`` sampled worlds (evenly thinned over chains and draws), rasterised on the
  building lattice and accumulated in :class:`~semmap_pp.sampler.diagnostics.SpreadAccumulator`;
  ``wall_spread`` is its mean Bernoulli variance of the wall indicator over the cells ever wall
  (0 = every world agrees), ``wall_disagreement_m2`` the expected area on which two sampled worlds
  disagree about wall (:func:`semmap_pp.sampler.spread.wall_disagreement_m2`). The mean divides by a
  number of cells that differs from run to run (and grows with every rare excursion), so only the
  area compares two rule sets on the same cells (docs/knowledge_comparison.md).
* conditional wall spread (:func:`conditional_wall_sd`): per wall of W*, the posterior standard
  deviation of its position given the rest of W*, computed exactly over the offsets within
  ``CONDITIONAL_OFFSET_M`` (no sampling, so it does not depend on the chains converging);
  ``wall_sd_m`` is its mean over W*'s walls.
* topological defects (:mod:`semmap_pp.target.defects`): adjacent rooms whose connecting walls
  differ by more than ``[diagnostics] defect_tolerance_m``, in W* and averaged over the sampled
  worlds (typed as the sampler typed them).

With several seeds (``semmap compare --seeds``) each rule set gets one such column per seed, and
:class:`AcrossSeeds` sums them up: every quantity's mean, standard deviation and range over the
seeds, and how far the seeds' W*s agree (:mod:`semmap_pp.studies.stability`: the mean unit F1 between
them, and the units of the best one found with their type in every other). What a rule set
changes is often which local maximum the search ends in (docs/knowledge_comparison.md), so a
difference between two rule sets means little unless it is larger than the spread between seeds.

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
from pathlib import Path

import numpy as np

from semmap_pp import world as wm
from semmap_pp.plans.diff import diff_worlds
from semmap_pp.plans.places import places_from_doc
from semmap_pp.run.results import figure_source, spread_first_draw
from semmap_pp.run.spread import posterior_worlds
from semmap_pp.run.target_factory import run_target
from semmap_pp.sampler.diagnostics import SpreadAccumulator, format_rhat
from semmap_pp.sampler.spread import accumulate, wall_disagreement_m2
from semmap_pp.semantic.world_json import world_dict
from semmap_pp.studies.stability import Stability
from semmap_pp.target.defects import count_defects


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
    for s in wm.active_slots(world).tolist():
        rect = [int(v) for v in world.rects[s]]
        for side in range(4):
            lp = np.full(len(offsets), -np.inf)
            for k, o in enumerate(offsets.tolist()):
                r = list(rect)
                r[side] += o
                if r[2] - r[0] < 1 or r[3] - r[1] < 1:
                    continue
                lp[k] = tr.logp if o == 0 else tr.propose(wm.replace(world, s, tuple(r)), (s,)).logp
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
    target (knowledge on when it had rules): :func:`semmap_pp.run.spread.posterior_worlds`."""

    return posterior_worlds(run, n)


def _accumulate(worlds, shape, wall: int) -> SpreadAccumulator:

    return accumulate(worlds, shape, wall)[0]


def wall_spread(worlds, shape, wall: int) -> float:
    """Mean Bernoulli variance of the wall indicator of ``worlds`` on a lattice of ``shape``."""
    return _accumulate(worlds, shape, wall).wall_spread()


def wall_disagreement(worlds, shape, wall: int, resolution: float) -> float:
    """Expected area (m²) where two of ``worlds`` disagree about wall (``Σ 2p(1-p)`` · cell area)."""

    return wall_disagreement_m2(_accumulate(worlds, shape, wall).p_wall(), resolution)


def summarise(run, name: str, rules: str, worlds) -> RuleSetSummary:
    """The comparison column of one run, with ``worlds`` its typed sampled worlds."""
    frame, model = run.inputs.frame, run.inputs.model
    c = frame.cells
    tol = model.diagnostics.defect_tolerance_m
    defects = count_defects(worlds, c.resolution, c.wall, c.adjacency_dilation, tol)
    best = count_defects([run.world], c.resolution, c.wall, c.adjacency_dilation, tol)
    q = run.report.quantities

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


def wstar_diffs(runs: list, names: list[str]) -> list:
    """The W* of every rule set after the first against the first's, unit by unit
    (:func:`semmap_pp.plans.diff.diff_worlds`: retyped, moved, removed, added units and openings)."""


    plans = [places_from_doc(world_dict(r.semantic), Path(f"W* of {n}")) for r, n in zip(runs, names)]
    return [diff_worlds(plans[0], p) for p in plans[1:]]


def diffs_section(diffs: list, seed: int | None = None) -> str:
    """compare.md's section on the W*s unit by unit (:func:`wstar_diffs`)."""
    which = f", seed {seed}" if seed is not None else ""
    return (f"## W* unit by unit (`semmap diff`{which})\n\n"
            + "\n\n".join(f"```\n{d.text()}\n```" for d in diffs))


#: The quantities of :class:`RuleSetSummary` summed up over seeds: (field, table label, format).
ACROSS_QUANTITIES = (
    ("n_units", "units in W*", ".1f"),
    ("cpr", "CPR of W*", ".4f"),
    ("log_posterior", "log posterior of W* (own target)", ".1f"),
    ("defects_best", "topological defects in W*", ".2f"),
    ("defects_mean", "defects, mean over sampled worlds", ".2f"),
    ("wall_spread", "wall spread (mean p(1-p) over cells ever wall)", ".4f"),
    ("wall_disagreement_m2", "wall disagreement, m² (Σ 2p(1-p) · cell area)", ".2f"),
    ("wall_sd_m", "wall sd given the rest of W*, mean over its walls, m", ".4f"),
    ("seconds", "sampling seconds", ".1f"),
)


def spread_of(values) -> dict:
    """``{"mean", "sd", "min", "max", "n"}`` of the finite ``values`` (sd with n - 1; NaN for
    fewer than two values, every statistic NaN when none is finite)."""
    v = np.array([float(x) for x in values], dtype=np.float64)
    v = v[np.isfinite(v)]
    if not v.size:
        return {"mean": math.nan, "sd": math.nan, "min": math.nan, "max": math.nan, "n": 0}
    return {"mean": float(v.mean()), "sd": float(v.std(ddof=1)) if v.size > 1 else math.nan,
            "min": float(v.min()), "max": float(v.max()), "n": int(v.size)}


@dataclass(frozen=True)
class AcrossSeeds:
    """One rule set's columns over several seeds: ``rows`` (a :class:`RuleSetSummary` per seed,
    in the order of ``seeds``) and the agreement of the seeds' W*s (``mean_unit_f1``, the mean
    unit F1 between every two of them; ``stable_units`` of the ``reference_units`` units of the
    best one, seed ``reference_seed``, found with their type in every other)."""

    name: str
    rules: str
    seeds: tuple
    rows: tuple
    mean_unit_f1: float
    stable_units: int
    reference_units: int
    reference_seed: int

    @classmethod
    def of(cls, seeds, rows, plans) -> "AcrossSeeds":
        """From one rule set's summaries and :class:`~semmap_pp.studies.stability.SeedPlan` s (W*s), both
        in the order of ``seeds`` (at least two)."""

        if len(seeds) < 2 or not len(seeds) == len(rows) == len(plans):
            raise ValueError("AcrossSeeds needs one summary and one plan for each of two or more seeds")
        st = Stability.of(list(plans))
        return cls(rows[0].name, rows[0].rules, tuple(int(s) for s in seeds), tuple(rows), st.mean_f1(),
                   st.stable_units(), len(st.reference.ids), int(st.reference.seed))

    def spread(self, field: str) -> dict:
        """:func:`spread_of` the quantity ``field`` over the seeds."""
        return spread_of(getattr(r, field) for r in self.rows)

    @property
    def converged(self) -> int:
        """Seeds whose chains passed the convergence verdict."""
        return sum(bool(r.converged) for r in self.rows)


def _mean_sd(stats: dict, spec: str) -> str:
    if not stats["n"]:
        return "nan"
    text = _fmt(stats["mean"], spec)
    if stats["n"] > 1:
        text += f" ± {_fmt(stats['sd'], spec)} ({_fmt(stats['min'], spec)} – {_fmt(stats['max'], spec)})"
    return text


def across_table(cols: list[AcrossSeeds]) -> str:
    """A Markdown table over seeds: one row per quantity (mean ± sd (min – max)), one column per
    rule set, then the agreement of the seeds' W*s."""
    seeds = ", ".join(map(str, cols[0].seeds))
    lines = [f"| quantity (seeds {seeds}: mean ± sd (min – max)) | " + " | ".join(c.name for c in cols) + " |",
             "|---|" + "---:|" * len(cols)]

    def add(label, values):
        lines.append(f"| {label} | " + " | ".join(values) + " |")

    add("rule file", [c.rules for c in cols])
    for field, label, spec in ACROSS_QUANTITIES:
        add(label, [_mean_sd(c.spread(field), spec) for c in cols])
    add("converged", [f"{c.converged} of {len(c.seeds)} seeds" for c in cols])
    add("W* between seeds: mean unit F1 (IoU >= 0.5)", [_fmt(c.mean_unit_f1, ".3f") for c in cols])
    add("units of the best W* found with their type in every other seed's",
        [f"{c.stable_units} of {c.reference_units} (seed {c.reference_seed})" for c in cols])
    return "\n".join(lines)


def across_dict(cols: list[AcrossSeeds]) -> list[dict]:
    """compare.json's ``across_seeds``: per rule set every quantity's :func:`spread_of` (NaN as
    null) and the agreement of its seeds' W*s."""
    def clean(v):
        return None if isinstance(v, float) and not math.isfinite(v) else v

    out = []
    for c in cols:
        q = {field: {k: clean(v) for k, v in c.spread(field).items()} for field, _label, _spec in ACROSS_QUANTITIES}
        out.append({"name": c.name, "rules": c.rules, "seeds": list(c.seeds), "quantities": q,
                    "converged": c.converged, "mean_unit_f1": clean(c.mean_unit_f1),
                    "stable_units": c.stable_units, "reference_units": c.reference_units,
                    "reference_seed": c.reference_seed})
    return out


__all__ = ["RuleSetSummary", "AcrossSeeds", "ACROSS_QUANTITIES", "spread_of", "across_table", "across_dict", "conditional_wall_sd", "mean_wall_sd_m", "typed_sampled_worlds", "wall_spread", "wall_disagreement", "summarise", "compare_table",
           "compare_dict"]
