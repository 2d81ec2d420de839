"""Calibration of probabilities against what turned out true: reliability table and expected
calibration error (ECE).

A set of claims, each made with probability ``p`` and each right or wrong (``y``), is calibrated
when the claims made with probability ``p`` are right a fraction ``p`` of the time. The claims
are put in ``bins`` equal-width bins of ``p`` (``[0, 1/bins)``, ..., the last one closed); for each
bin its number of claims, their mean probability (confidence) and the fraction right (accuracy).
The ECE is the mean, weighted by the claims in each bin, of ``|accuracy - confidence|`` (Naeini et
al. 2015; Guo et al. 2017): 0 for calibrated claims, the share of wrong claims when every claim
is made with certainty.

>>> t = reliability([1.0, 1.0, 1.0, 1.0], [1, 1, 1, 0])
>>> round(t.ece, 3)                          # certain, and wrong once in four
0.25
>>> round(reliability([0.25] * 4, [1, 0, 0, 0]).ece, 3)      # a quarter, right a quarter
0.0
>>> [(b.n, round(b.confidence, 2), b.accuracy) for b in reliability([0.05, 0.95], [0, 1]).bins if b.n]
[(1, 0.05, 0.0), (1, 0.95, 1.0)]
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from semmap_pp.cells import UNIT_TYPES

#: The kinds of claim :func:`posterior_claims` reads off a world.json's posterior marginals.
KINDS = ("units", "types", "doors")


class Bin(NamedTuple):
    """One bin of a reliability table: ``[lo, hi)`` (the last one closed), its claims, their mean
    probability and the fraction of them right (NaN for an empty bin)."""

    lo: float
    hi: float
    n: int
    confidence: float
    accuracy: float


class Reliability(NamedTuple):
    """:func:`reliability`'s result: the bins, the claims counted and the ECE (NaN without claims)."""

    bins: tuple
    n: int
    ece: float


def reliability(p, y, bins: int = 10) -> Reliability:
    """The reliability table and ECE of claims made with probabilities ``p`` (in ``[0, 1]``) whose
    outcomes are ``y`` (true / false, or 1 / 0); ``bins`` equal-width bins."""
    p = np.asarray(p, dtype=np.float64).ravel()
    y = np.asarray(y, dtype=np.float64).ravel()
    if p.shape != y.shape:
        raise ValueError(f"{p.size} probabilities but {y.size} outcomes")
    if p.size and (not np.all(np.isfinite(p)) or p.min() < 0 or p.max() > 1):
        raise ValueError("probabilities must lie in [0, 1]")
    if bins < 1:
        raise ValueError(f"bins must be at least 1, got {bins}")
    k = np.minimum((p * bins).astype(np.int64), bins - 1)
    out, ece = [], 0.0
    for b in range(bins):
        sel = k == b
        n = int(sel.sum())
        conf = float(p[sel].mean()) if n else float("nan")
        acc = float(y[sel].mean()) if n else float("nan")
        if n:
            ece += n * abs(acc - conf)
        out.append(Bin(b / bins, (b + 1) / bins, n, conf, acc))
    return Reliability(tuple(out), int(p.size), ece / p.size if p.size else float("nan"))


def posterior_claims(doc, truth, score) -> dict:
    """The claims of a world.json's posterior marginals (``doc``; docs/outputs.md) and whether
    the synthetic ``truth`` bears them out, given ``score`` (:func:`~semmap_pp.evaluate.truth.score_world`
    of ``doc`` against ``truth``): ``{kind: (probabilities, outcomes)}`` for :data:`KINDS`.

    * ``units``: a unit of W* exists with its ``posterior_exists``; right when it matches a true unit;
    * ``types``: a matched unit with a ``posterior_type`` is of its most probable type with that
      type's probability; right when the true unit has that type;
    * ``doors``: a door of W* exists with its ``posterior_exists``; right when it matches a true
      door (``score.door_matches``, in the file's order).

    Units and doors without posterior marginals (a run that drew no worlds) make no claims.

    >>> from types import SimpleNamespace
    >>> doc = {"units": [{"id": 1, "posterior_exists": 0.9, "posterior_type": {"room": 0.8, "corridor": 0.2,
    ...        "hall": 0.0, "other": 0.0}}, {"id": 2, "posterior_exists": 0.4, "posterior_type": None}],
    ...        "doors": [{"posterior_exists": 0.7}]}
    >>> truth = {"units": [{"id": 7, "type": "corridor"}]}
    >>> c = posterior_claims(doc, truth, SimpleNamespace(matches={1: 7}, door_matches=(True,)))
    >>> c["units"], c["types"], c["doors"]
    (([0.9, 0.4], [True, False]), ([0.8], [False]), ([0.7], [True]))
    """
    true_type = {u["id"]: u["type"] for u in truth.get("units", [])}
    out = {k: ([], []) for k in KINDS}
    for u in doc.get("units", []):
        if "posterior_exists" not in u:
            continue
        matched = u["id"] in score.matches
        out["units"][0].append(float(u["posterior_exists"]))
        out["units"][1].append(matched)
        dist = u.get("posterior_type")
        if matched and dist:
            t = max(UNIT_TYPES, key=lambda k: dist[k])
            out["types"][0].append(float(dist[t]))
            out["types"][1].append(true_type.get(score.matches[u["id"]]) == t)
    for d, hit in zip(doc.get("doors", []), score.door_matches):
        if "posterior_exists" in d:
            out["doors"][0].append(float(d["posterior_exists"]))
            out["doors"][1].append(bool(hit))
    return out


def calibration_summary(claims: list, bins: int = 10) -> dict:
    """Each kind's claims pooled over ``claims`` (a list of :func:`posterior_claims` results):
    ``{kind: {"claims", "ece", "mean_p", "right", "bins": [[lo, hi, n, confidence, accuracy]]}}``,
    empty bins left out (``ece`` and the means None without claims)."""
    out = {}
    for kind in KINDS:
        p = [x for c in claims for x in c[kind][0]]
        y = [x for c in claims for x in c[kind][1]]
        t = reliability(p, y, bins)
        out[kind] = {"claims": t.n, "ece": round(t.ece, 4) if t.n else None,
                     "mean_p": round(float(np.mean(p)), 4) if p else None,
                     "right": round(float(np.mean(y)), 4) if y else None,
                     "bins": [[b.lo, b.hi, b.n, round(b.confidence, 4), round(b.accuracy, 4)]
                              for b in t.bins if b.n]}
    return out


__all__ = ["Bin", "KINDS", "Reliability", "calibration_summary", "posterior_claims", "reliability"]
