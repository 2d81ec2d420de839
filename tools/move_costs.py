"""What a death, birth, merge and split of W*'s units cost under the (tempered) target, term by term.

    .venv/bin/python tools/move_costs.py MAP WORLD_JSON [--lag-m 1.5] [--json]

For every unit of W* (world.json's units, read onto the map's lattice) and the target W* is judged
by (knowledge on), the log acceptance ratio of

* its death (REMOVE) and, reversed, its birth (ADD) from W* without it;
* its best split (SPLIT at the three strongest cut positions per axis) and that split's merge;
* the merge of every pair MERGE may join (units attached along a whole wall, the same span);
* every pair of units replaced by their bounding box where it exceeds their union by at most 15 %
  (the target's view of a unit fewer there; no kernel proposes it in one step);

split into: the likelihood's change, untempered and tempered (times 1/A), the prior's number of
units and slots (``log p_n − log C(K, n)``), the rectangles (``Σ log p_rect``), the SaLe factor,
and the proposal's log ratio (``log q(reverse) − log q(forward)``; for a death, the birth density
``log q_b(r)`` and its uniform share apart). ``log α = λ Δℓ + Δ prior + log ratio``.
"""

from __future__ import annotations

import argparse
import json
import math
import sys

import numpy as np

from semmap_pp import world as wm
from semmap_pp.plans.world_file import read_start_world
from semmap_pp.run.inputs import load_inputs
from semmap_pp.run.target_factory import run_target
from semmap_pp.sampler.kernels import data_from_frame
from semmap_pp.sampler.kernels.add_remove import _rho, add_log_ratio, birth_q
from semmap_pp.sampler.kernels.split_merge import (_merge_proposal, _split_proposal, cut_weights,
                                                   mergeable)
from semmap_pp.target.prior import log_p_n, log_slots
from semmap_pp.target.tempering import likelihood_exponent


def parts(post, world):
    """The terms of ``log π(world)``: loglik, n-and-slots, rectangles, SaLe (types from ``post``)."""
    t = post.evaluate(world)
    n, K = int(world.active.sum()), world.capacity
    nslots = log_p_n(n, K, post.model.prior) - log_slots(n, K)
    rects = n * post.log_rect
    return {"loglik": t.loglik, "n_slots": nslots, "rects": rects,
            "sale": t.logprior - nslots - rects, "types": t.world.types}


def delta(post, lam, before, after, log_ratio):
    a, b = parts(post, before), parts(post, after)
    d = {k: b[k] - a[k] for k in ("loglik", "n_slots", "rects", "sale")}
    d["tempered_loglik"] = lam * d["loglik"]
    d["log_ratio"] = log_ratio
    d["log_alpha"] = d["tempered_loglik"] + d["n_slots"] + d["rects"] + d["sale"] + log_ratio
    d["retyped"] = int(np.sum(a["types"][before.active & after.active] != b["types"][before.active & after.active]))
    return d


def best_split(post, lam, world, slot, data):
    n = int(world.active.sum())
    free = int(np.flatnonzero(~world.active)[0])
    best = None
    for axis in (0, 1):
        lo, hi, w = cut_weights(world.rects[slot], axis, data)
        if w is None:
            continue
        for i in np.argsort(-w)[:3]:
            s = lo + int(i)
            prop = _split_proposal(world, slot, free, axis, s, n, data, (lo, hi, w))
            d = delta(post, lam, world, prop.world, prop.log_ratio)
            d.update(axis=axis, cut=s)
            if best is None or d["log_alpha"] > best["log_alpha"]:
                best = d
    return best


def box_merges(post, lam, world, max_side, slack=0.15):
    """Every pair of ``world``'s units replaced by their bounding box (in the first's slot) where
    it exceeds their union by at most ``slack`` and is a valid unit: the target's terms only."""
    out = []
    slots = [int(s) for s in wm.active_slots(world)]
    for i in slots:
        for j in (j for j in slots if j > i):
            a, b = world.rects[i], world.rects[j]
            box = (min(a[0], b[0]), min(a[1], b[1]), max(a[2], b[2]), max(a[3], b[3]))
            area = (box[2] - box[0]) * (box[3] - box[1])
            union = (a[2] - a[0]) * (a[3] - a[1]) + (b[2] - b[0]) * (b[3] - b[1])
            if area > (1.0 + slack) * union or max(box[2] - box[0], box[3] - box[1]) > max_side:
                continue
            d = delta(post, lam, world, wm.remove(wm.replace(world, i, box), j), 0.0)
            d["pair"] = [i, j]
            out.append(d)
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("map")
    ap.add_argument("world")
    ap.add_argument("--lag-m", type=float, default=None)
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args(argv)
    inputs = load_inputs(a.map)
    post = run_target(inputs)
    frame = inputs.frame
    wstar = read_start_world(a.world, frame, inputs.grid, inputs.model.prior.k_max)
    lag = inputs.model.sampler.spread_correlation_lag_m if a.lag_m is None else a.lag_m
    lam, area = likelihood_exponent(post, wstar, lag)
    data = data_from_frame(frame, inputs.model.kernels)
    uniform = math.log(_rho(data) / (data.side_counts[0] * data.side_counts[1]))
    rows = []
    n = int(wstar.active.sum())
    for s in wm.active_slots(wstar):
        rect = tuple(int(v) for v in wstar.rects[s])
        without = wm.remove(wstar, int(s))
        death = delta(post, lam, wstar, without, -add_log_ratio(n - 1, wstar.capacity, rect, data))
        death["log_qb"] = math.log(birth_q(rect, data))
        death["log_qb_uniform"] = uniform
        split = best_split(post, lam, wstar, int(s), data)
        area_m2 = (rect[2] - rect[0]) * (rect[3] - rect[1]) * frame.cells.resolution ** 2
        rows.append({"slot": int(s), "rect": rect, "area_m2": area_m2,
                     "type": int(post.evaluate(wstar).world.types[s]), "death": death, "split": split})
    merges = []
    pairs = mergeable(wstar, data)
    for p in pairs:
        prop = _merge_proposal(wstar, p, len(pairs), data)
        d = delta(post, lam, wstar, prop.world, prop.log_ratio)
        d["pair"] = [int(p[1]), int(p[2])]
        merges.append(d)
    boxes = box_merges(post, lam, wstar, data.max_side)
    out = {"A": area, "lambda": lam, "units": n, "K": wstar.capacity, "log_rect": post.log_rect,
           "log_qb_uniform": uniform, "rows": rows, "merges": merges, "box_merges": boxes}
    if a.json:
        json.dump(out, sys.stdout, indent=1, default=lambda o: o.tolist() if hasattr(o, "tolist") else str(o))
        return 0
    print(f"A = {area:.1f} cells, λ = 1/A = {lam:.4g}; {n} units in {wstar.capacity} slots; "
          f"log p_rect = {post.log_rect:.2f}; log q_b(uniform part) = {uniform:.2f}")
    hdr = "slot  m²    type | death: Δℓ  λΔℓ  n,slots rects  SaLe  logratio (log q_b) log α | split: λΔℓ  n,slots rects SaLe logratio log α"
    print(hdr)
    for r in rows:
        d, sp = r["death"], r["split"]
        line = (f"{r['slot']:4d} {r['area_m2']:6.1f} {r['type']:3d} | {d['loglik']:9.1f} {d['tempered_loglik']:7.1f} "
                f"{d['n_slots']:6.2f} {d['rects']:6.2f} {d['sale']:6.2f} {d['log_ratio']:7.2f} ({d['log_qb']:7.2f}) "
                f"{d['log_alpha']:8.1f}")
        if sp:
            line += (f" | {sp['tempered_loglik']:7.1f} {sp['n_slots']:6.2f} {sp['rects']:6.2f} {sp['sale']:6.2f} "
                     f"{sp['log_ratio']:7.2f} {sp['log_alpha']:8.1f}")
        print(line)
    if not merges:
        print("merge: no pair of units MERGE may join")
    for m in boxes:
        print(f"bounding box of {m['pair']}: Δℓ {m['loglik']:.1f} λΔℓ {m['tempered_loglik']:.1f} "
              f"n,slots {m['n_slots']:.2f} rects {m['rects']:.2f} SaLe {m['sale']:.2f} log π change {m['log_alpha']:.1f}")
    for m in merges:
        print(f"merge {m['pair']}: Δℓ {m['loglik']:.1f} λΔℓ {m['tempered_loglik']:.1f} n,slots {m['n_slots']:.2f} "
              f"rects {m['rects']:.2f} SaLe {m['sale']:.2f} log ratio {m['log_ratio']:.2f} log α {m['log_alpha']:.1f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
