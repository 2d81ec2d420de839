"""Learned rule weights, cross-validated: leave one ipa-types map out, learn on the rest.

``python bench/run.py learn --json [--wstars DIR] [--synth-floors N] [--rerun] [--rules FILE] [--sigma S]``

* The ipa-types maps' W*s are those of ``bench/run.py quality --subset types --save DIR`` (run
  here into a temporary folder when ``--wstars`` is not given), under ``--rules`` (default
  rules/table3.lp). Each becomes a labelled example (``semmap rules label MAP WORLD --truth
  training_*.png``: each W* unit takes the majority type of its cells, a truth room being a room,
  hall or other, as the ipa score reads it), with its cell counts.
* The synthetic floors 0..N-1 (``--synth-floors``, default 30) become labelled examples of their
  truth plans (``semmap rules label-synth``).
* For each ipa map: the weights are learned on the other maps and the synthetic floors, and the
  map's W* is typed (the engine's MAP) with the file's and with the learned weights: per-cell
  room/corridor accuracy with the code of the quality benchmark's types subset
  (:func:`semmap_pp.knowledge.learn.score`, equal to :func:`semmap_pp.evaluate.type_accuracy` of
  the W*'s type map). ``oracle`` is the accuracy when every unit takes the majority type of its
  cells: what the W*'s segmentation allows at best.
* ``--rerun``: each fold's learned file is also run through the whole pipeline on its map
  (:func:`bench_quality.bench_types`, the search steered by the learned rules), the score of the
  quality benchmark.
* The weights learned on every example are given too, and the synthetic truth plans' unit type
  accuracy under the file's and those weights.

``--tiny``: the bundled synthetic examples of tests/data/learn/synth as the maps, no W* runs.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def add_arguments(parser) -> None:
    parser.add_argument("--wstars", type=Path, default=None,
                        help="W*s of `bench/run.py quality --subset types --save DIR` (default: run it)")
    parser.add_argument("--synth-floors", type=int, default=30, help="synthetic floors in training (30)")
    parser.add_argument("--rules", type=Path, default=None, help="rule file (default rules/table3.lp)")
    parser.add_argument("--sigma", type=float, default=None, help="prior sigma (learn.SIGMA)")
    parser.add_argument("--rerun", action="store_true",
                        help="also run the pipeline on each left-out map with its fold's rules")
    parser.add_argument("--out", type=Path, default=None,
                        help="write the weights learned on every example here")
    parser.add_argument("--tiny", action="store_true", help="the bundled synthetic examples only")


def _ipa_examples(wstars: Path, model_path=None) -> list:
    import bench_quality as bq

    from semmap_pp.cli.cmd_rules import labelled_example_text
    from semmap_pp.knowledge.learn import example_from_text
    from semmap_pp.run.inputs import load_inputs
    base = bq.SHARED / "ipa-types"
    out = []
    for map_name, truth_name in bq.TYPE_MAPS:
        name = map_name[:-len("_original.png")]
        world = wstars / name / "world.json"
        if not world.exists():
            continue
        inputs = load_inputs(base / map_name, model_path=model_path, rules_path=None,
                             map_options=dict(resolution=0.05, **bq.IPA_FREE))
        text = labelled_example_text(inputs, world, base / truth_name)
        out.append((name, example_from_text(text, name)))
    return out


def run(args) -> dict:
    from semmap_pp.knowledge import learn as lm
    from semmap_pp.studies.labelled import synthetic_example
    from semmap_pp.resources import DEFAULT_RULES

    rules = args.rules or DEFAULT_RULES
    sigma = lm.SIGMA if args.sigma is None else args.sigma
    sr = lm.soft_rules(rules)
    out: dict = {"rules": str(rules), "sigma": sigma}
    if args.tiny:
        files = sorted((ROOT / "tests" / "data" / "learn" / "synth").glob("*.lp"))
        maps = [(f.stem, lm.read_example(f)) for f in files]
        synth = []
    else:
        t0 = time.perf_counter()
        wstars = args.wstars
        tmp = None
        if wstars is None:
            import bench_quality as bq
            tmp = tempfile.TemporaryDirectory(prefix="bench-learn-")
            wstars = Path(tmp.name)
            qa = argparse.Namespace(**{**_quality_defaults(), "save": wstars, "rules": rules})
            from semmap_pp.knowledge import load_rules
            from semmap_pp.model import load_model
            out["wstar_run"] = bq.bench_types(qa, load_model(None), load_rules(rules))["means"]
        maps = _ipa_examples(wstars)
        synth = [lm.example_from_text(synthetic_example(s), f"synth-{s}")
                 for s in range(args.synth_floors)]
        out["examples_s"] = round(time.perf_counter() - t0, 1)
    start = np.array([p.value / 1000 for p in sr.params])
    rows = []
    for i, (name, ex) in enumerate(maps):
        rest = [e for j, (_n, e) in enumerate(maps) if j != i] + synth
        t0 = time.perf_counter()
        fit = lm.learn(sr, rest, sigma=sigma)
        row = {"map": name, "learn_s": round(time.perf_counter() - t0, 1)}
        for tag, values in (("file", start), ("learned", fit.values)):
            sc = lm.score(ex, lm.map_types(sr, values, ex))
            row[f"accuracy_{tag}"] = round(sc.get("cell_accuracy", sc["unit_accuracy"]), 4)
            if "recall_corridor" in sc:
                row[f"recall_corridor_{tag}"] = round(sc["recall_corridor"], 4)
        if ex.cells:
            oracle = {u: max(range(4), key=lambda t: sum(c[k] for k in range(4)
                                                         if lm.correct_cells(k, t)))
                      for u, c in ex.cells.items()}
            oracle.update({u: 0 for u in ex.evidence.units if u not in oracle})
            row["oracle"] = round(lm.score(ex, oracle)["cell_accuracy"], 4)
        if args.rerun and not args.tiny:
            row.update(_rerun(sr, fit, name))
        rows.append(row)
        print(f"  {name}: {row}", file=sys.stderr, flush=True)
    out["rows"] = rows
    keys = [k for k in rows[0] if k != "map"] if rows else []
    out["means"] = {k: round(float(np.mean([r[k] for r in rows if k in r])), 4) for k in keys}
    everything = [e for _n, e in maps] + synth
    fit = lm.learn(sr, everything, sigma=sigma)
    out["weights_all"] = {p.name: int(round(v * 1000)) for p, v in zip(sr.params, fit.values)}
    if synth:
        for tag, values in (("file", start), ("learned", fit.values)):
            good = sum(lm.score(e, lm.map_types(sr, values, e))["unit_accuracy"] * len(e.labels)
                       for e in synth)
            out[f"synthetic_unit_accuracy_{tag}"] = round(good / sum(len(e.labels) for e in synth), 4)
    if args.out is not None:
        from semmap_pp import atomic
        desc = (f"bench/run.py learn: the ipa-types maps' W*s ({', '.join(n for n, _ in maps)}) "
                f"and synthetic floors 0-{args.synth_floors - 1}")
        atomic.write_text(args.out, lm.learned_text(fit, desc))
        out["out"] = str(args.out)
    return out


def _quality_defaults() -> dict:
    import bench_quality as bq
    p = argparse.ArgumentParser()
    bq.add_arguments(p)
    ns = p.parse_args(["--subset", "types", "--quiet"])
    return vars(ns)


def _rerun(sr, fit, name) -> dict:
    """The quality benchmark's types score of map ``name`` run with ``fit``'s weights."""
    import bench_quality as bq

    from semmap_pp.knowledge import learn as lm
    from semmap_pp.knowledge import load_rules
    from semmap_pp.model import load_model
    with tempfile.TemporaryDirectory(prefix="bench-learn-fold-") as d:
        f = Path(d) / "fold.lp"
        f.write_text(lm.rewritten_text(sr, fit.values), encoding="utf-8")
        qa = argparse.Namespace(**{**_quality_defaults(), "maps": name, "rules": f})
        res = bq.bench_types(qa, load_model(None), load_rules(f))
    row = res["rows"][0] if res.get("rows") else {}
    return {"pipeline_accuracy_learned": row.get("accuracy"),
            "pipeline_recall_corridor_learned": row.get("recall_corridor")}
