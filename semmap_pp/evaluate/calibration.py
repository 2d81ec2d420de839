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


__all__ = ["Bin", "Reliability", "reliability"]
