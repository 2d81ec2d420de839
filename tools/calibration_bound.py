"""How calibrated could a tempered posterior around W* be? A two-state reading on the synthetic floors.

    .venv/bin/python bench/run.py quality --subset synthetic --save DIR     # the W*s, once
    .venv/bin/python tools/calibration_bound.py DIR [--floors 30] [--json OUT]

For every unit of each saved W* (world.json's units; right when it matches a true unit, as the
quality bench scores it) the target's terms of its alternatives, untempered (tools/move_costs.py):
its death, every bounding box it makes with another unit (at most 15 % over their union), and
its best split. For a likelihood exponent ``λ`` each alternative's log posterior change is
``λ Δℓ + Δ prior``, and the unit's two-state probability of existing

    p = 1 / (1 + Σ_alt exp(λ Δℓ_alt + Δprior_alt))

is what a chain that mixed between W* and those alternatives alone would give it (the volume of
nearby wall positions left out). The expected calibration error of these ``p`` against right /
wrong, for fixed exponents and for ``c / A`` (``A`` the floor's correlation area,
:func:`semmap_pp.target.tempering.likelihood_exponent`), bounds what tempering the likelihood can
do for the units' ``posterior_exists``; so does the AUC of each alternative's cost.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT / "bench"), str(ROOT / "tools")]

from move_costs import best_split, box_merges, delta  # noqa: E402

from semmap_pp import world as wm  # noqa: E402
from semmap_pp.evaluate.calibration import KINDS, calibration_summary  # noqa: E402
from semmap_pp.sampler.kernels.add_remove import add_log_ratio  # noqa: E402
from semmap_pp.sampler.kernels.split_merge import mergeable  # noqa: E402

FIXED = (1.0, 0.3, 0.1, 0.05, 0.03, 0.02, 0.01, 0.005)
OVER_A = (3.0, 1.0, 0.5, 0.3)


def floor_units(seed: int, wstars: Path, model, rules) -> dict:
    """One floor: its ``A``, the number of pairs MERGE may join, and per unit right / wrong and the
    untempered ``[Δℓ, Δprior]`` of its alternatives."""
    import bench_quality as bq
    from semmap_pp.evaluate import score_world
    from semmap_pp.run.target_factory import run_target
    from semmap_pp.target.tempering import likelihood_exponent
    floor, _grid, inputs = bq._floor(seed, model, rules)
    post, data = run_target(inputs), bq.kernel_data(inputs, model)
    pred = json.loads((wstars / f"synth-{seed}" / "world.json").read_text())
    polygons = [u["vertices_px"] for u in pred["units"]] + [u["vertices_px"] for u in pred.get("exterior", [])]
    w = bq.polygons_world(inputs.frame, polygons, max(model.prior.k_max, len(polygons)))
    score = score_world(pred, floor.truth, shape=floor.classes.shape, resolution=floor.resolution)
    area = likelihood_exponent(post, w, model.sampler.spread_correlation_lag_m)[1]
    n = int(w.active.sum())
    terms = (lambda d: [d["loglik"], d["n_slots"] + d["rects"] + d["sale"]])
    boxes = box_merges(post, 1.0, w, data.max_side)
    units = []
    for slot, u in enumerate(pred["units"]):
        death = delta(post, 1.0, w, wm.remove(w, slot),
                      -add_log_ratio(n - 1, w.capacity, tuple(int(v) for v in w.rects[slot]), data))
        split = best_split(post, 1.0, w, slot, data)
        units.append({"id": u["id"], "right": u["id"] in score.matches, "death": terms(death),
                      "boxes": [terms(b) for b in boxes if slot in b["pair"]],
                      "split": terms(split) if split else None})
    return {"seed": seed, "A": area, "mergeable": len(mergeable(w, data)), "units": units}


def two_state(units, lam_of, kinds=("death", "boxes")) -> list[float]:
    out = []
    for area, u in units:
        lam = lam_of(area)
        alts = ([u["death"]] if "death" in kinds else []) + (u["boxes"] if "boxes" in kinds else [])
        x = [lam * a[0] + a[1] for a in alts]
        m = max(x + [0.0])
        out.append(math.exp(-m) / (math.exp(-m) + sum(math.exp(v - m) for v in x)))
    return out


def auc(score, right) -> float:
    """P(a right unit's score < a wrong unit's): how well a cost (more negative for right) ranks."""
    s, y = np.asarray(score, float), np.asarray(right, bool)
    pos, neg = s[y], s[~y]
    return float(np.mean([(p < neg).mean() + 0.5 * (p == neg).mean() for p in pos]))


def report(floors) -> dict:
    units = [(f["A"], u) for f in floors for u in f["units"]]
    right = [u["right"] for _, u in units]
    out = {"floors": len(floors), "units": len(units), "wrong": right.count(False),
           "A": [min(f["A"] for f in floors), float(np.median([f["A"] for f in floors])), max(f["A"] for f in floors)],
           "mergeable_pairs": sum(f["mergeable"] for f in floors),
           "auc": {"death": auc([u["death"][0] for _, u in units], right),
                   "box": auc([max([b[0] for b in u["boxes"]], default=-1e12) for _, u in units], right),
                   "split": auc([u["split"][0] if u["split"] else -1e12 for _, u in units], right)},
           "ece": {}}
    for kinds in (("death", "boxes"), ("death",)):
        for name, lam_of in ([(f"{c}", (lambda a, c=c: c)) for c in FIXED]
                             + [(f"{c}/A", (lambda a, c=c: c / a)) for c in OVER_A]):
            claims = {k: ([], []) for k in KINDS} | {"units": (two_state(units, lam_of, kinds), right)}
            s = calibration_summary([claims])["units"]
            out["ece"]["+".join(kinds) + " " + name] = {"ece": s["ece"], "mean_p": s["mean_p"]}
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("wstars", type=Path)
    ap.add_argument("--floors", type=int, default=30)
    ap.add_argument("--json", type=Path, default=None, help="write the per-unit terms here")
    a = ap.parse_args(argv)
    from semmap_pp.knowledge import load_rules
    from semmap_pp.model import load_model
    from semmap_pp.resources import DEFAULT_RULES
    model, rules = load_model(), load_rules(DEFAULT_RULES)
    floors = []
    for seed in range(a.floors):
        floors.append(floor_units(seed, a.wstars, model, rules))
        f = floors[-1]
        print(f"floor {seed}: A {f['A']:.1f}, {len(f['units'])} units, "
              f"{sum(not u['right'] for u in f['units'])} wrong, {f['mergeable']} pairs MERGE may join", flush=True)
    if a.json:
        a.json.write_text(json.dumps(floors))
    rep = report(floors)
    print(json.dumps({k: v for k, v in rep.items() if k != "ece"}))
    for k, v in rep["ece"].items():
        print(f"{k:28s} ECE {v['ece']:.3f}  mean p {v['mean_p']:.3f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
