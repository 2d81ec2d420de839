"""``semmap diagnose DIR [--model FILE] [--json]``: re-read a run's trace.nc and judge convergence.

Reads ``DIR/trace.nc`` (or a trace file given directly) with
:func:`semmap_pp.sampler.diagnostics.read_trace` and prints the run's provenance (its attributes), R-hat
and bulk / tail ESS of every label-invariant summary with the verdict, the posterior spread of
each summary (mean, sd, 5 % / 50 % / 95 % quantiles over the draws of the chains in the best
chain's mode, :meth:`~semmap_pp.sampler.diagnostics.ConvergenceReport.mode_chains`, as the run's figures
use them), the acceptance rates, and any spread numbers stored as trace attributes. The thresholds are the model file's
``[diagnostics]`` (``rhat_max``, ``ess_min``), as ``semmap map`` uses them. When DIR also holds
``spread.nc`` (the sample around W* that the spread figures are drawn from), the same report of it
follows (JSON: ``spread_sample``).

Exit status (of trace.nc, W*'s search): 0 converged, 1 not converged (so scripts can write ``semmap diagnose DIR && ...``),
2 when DIR holds no readable trace.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np


def register(subparsers) -> None:
    p = subparsers.add_parser("diagnose", help="R-hat, ESS, verdict and spread of a run's trace.nc",
                              description=__doc__.splitlines()[0])
    p.add_argument("dir", metavar="DIR", type=Path, help="output folder of `semmap map` (or its trace.nc)")
    p.add_argument("--model", metavar="FILE", default=None,
                   help="model file with the [diagnostics] thresholds (default models/default.toml)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=run)


def _clean(v):
    if isinstance(v, dict):
        return {k: _clean(x) for k, x in v.items()}
    if isinstance(v, (np.integer,)):
        return int(v)
    if isinstance(v, (float, np.floating)):
        v = float(v)
        return v if math.isfinite(v) else None
    if isinstance(v, np.ndarray):
        return _clean(v.tolist())
    if isinstance(v, list):
        return [_clean(x) for x in v]
    return v


def diagnose(tree, rhat_max: float, ess_min: float, *, figures: bool = True) -> dict:
    """Everything ``semmap diagnose`` reports, from a trace DataTree (``figures``: whether the
    run's spread figures were drawn from this trace's draws)."""
    from dataclasses import replace

    from semmap_pp.sampler.diagnostics import convergence

    around = tree.attrs.get("start") == "W*"      # spread.nc: the sample around W*
    report = convergence(tree, rhat_max=rhat_max, ess_min=ess_min,
                         draws_option="--spread-draws" if around else "--draws").with_figures(figures)
    if int(tree.attrs.get("rungs", 1)) > 1:      # a sample with replica exchange (--tempered)
        report = replace(report, tempered=True)
    post = tree["posterior"]
    # A chain thousands of nats below the best one carries no posterior mass worth summarising;
    # pooled, its draws would report the spread between modes (docs/sampler.md).
    chains = report.mode_chains()
    keep = [c - 1 for c in chains]          # the posterior group's first dimension is the chain
    first = report.within_mode.first_draw   # the draws before it: those chains still settling
    spread = {}
    for name in post.data_vars:
        a = np.asarray(post[name].values, float)[keep, first:].ravel()
        a = a[np.isfinite(a)]
        spread[name] = ({"mean": float(a.mean()), "sd": float(a.std()),
                         "q05": float(np.quantile(a, 0.05)), "q50": float(np.quantile(a, 0.5)),
                         "q95": float(np.quantile(a, 0.95))} if a.size else
                        {"mean": math.nan, "sd": math.nan, "q05": math.nan, "q50": math.nan, "q95": math.nan})
    accept = {}
    if "sample_stats" in tree.children:
        stats = tree["sample_stats"]
        for name in stats.data_vars:
            if name.startswith("accept") or name == "swap_accept":
                a = np.asarray(stats[name].values, float)
                accept[name] = float(np.nanmean(a)) if np.isfinite(a).any() else math.nan
    attrs = {k: (v.item() if hasattr(v, "item") else v) for k, v in tree.attrs.items()}
    return {"attrs": attrs, "convergence": report.to_dict(), "spread": spread, "spread_chains": chains,
            "spread_first_draw": first + 1,
            "acceptance": accept,
            "stored_spread": {k: v for k, v in attrs.items() if "spread" in k}, "text": report.to_text()}


def _chains_text(chains: list[int], n_chains: int, first: int = 1) -> str:
    """Whose draws the spread pools, for its heading (``first``: the first draw used, from 1).

    >>> _chains_text([1, 2], 2), _chains_text([1], 2), _chains_text([1, 3], 3, 5)
    ('all chains and draws', "chain 1's draws: the best chain's mode", "chains 1, 3's draws from draw 5: the best chain's mode")
    """
    from semmap_pp.sampler.diagnostics import chains_phrase

    since = f" from draw {first}" if first > 1 else ""
    if len(chains) == n_chains:
        return f"all chains and draws{since}"
    return f"{chains_phrase(chains)}'s draws{since}: the best chain's mode"


def format_text(d: dict) -> str:
    a = d["attrs"]
    lines = ["run: " + ", ".join(f"{k} {v}" for k, v in a.items() if "spread" not in k), "", d["text"], "",
             "posterior spread of the summaries (" + _chains_text(d["spread_chains"], d["convergence"]["chains"],
                                                             d["spread_first_draw"])
             + ")",
             f"{'quantity':<16}{'mean':>12}{'sd':>10}{'5 %':>12}{'50 %':>12}{'95 %':>12}"]
    for name, s in d["spread"].items():
        lines.append(f"{name:<16}{s['mean']:>12.4g}{s['sd']:>10.3g}{s['q05']:>12.4g}{s['q50']:>12.4g}"
                     f"{s['q95']:>12.4g}")
    if d["acceptance"]:
        lines += ["", "acceptance (mean over draws): " + ", ".join(
            f"{k.removeprefix('accept_') if k != 'accept' else 'all'} {v:.3f}" for k, v in d["acceptance"].items())
            + (" (swap: replica exchange between neighbouring rungs)" if "swap_accept" in d["acceptance"] else "")]
    for k, v in d["stored_spread"].items():
        lines.append(f"{k}: {v}")
    return "\n".join(lines)


def run(args) -> int:
    from semmap_pp.sampler.diagnostics import read_trace
    from semmap_pp.model import load_model

    path = args.dir / "trace.nc" if args.dir.is_dir() else args.dir
    tree = read_trace(path)
    model = load_model(args.model)
    # a run with a sample around W* (spread.nc beside trace.nc) draws its spread figures from it
    spread_path = args.dir / "spread.nc" if args.dir.is_dir() else None
    spread_path = spread_path if spread_path is not None and spread_path.is_file() else None
    d = _diagnose_file(path, tree, model, figures=spread_path is None)
    around = _diagnose_file(spread_path, read_trace(spread_path), model) if spread_path else None
    if args.json:
        out = {k: v for k, v in d.items() if k != "text"}
        out["trace"] = str(path)
        if around is not None:
            out["spread_sample"] = {k: v for k, v in around.items() if k != "text"} | {"trace": str(spread_path)}
        print(json.dumps(_clean(out)))
    else:
        print(format_text(d))
        if around is not None:
            print(f"\n--- the sample around W* ({spread_path}): the draws posterior.png and "
                  f"posterior_cells.png are made of ---\n")
            print(format_text(around))
    return 0 if d["convergence"]["ok"] else 1


def _diagnose_file(path, tree, model, *, figures: bool = True) -> dict:
    try:
        return diagnose(tree, model.diagnostics.rhat_max, model.diagnostics.ess_min, figures=figures)
    except (ValueError, KeyError) as exc:
        from semmap_pp.errors import SemmapError
        raise SemmapError(path, f"trace has no usable summaries ({exc})") from None
