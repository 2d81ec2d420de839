"""The cell prediction rate of every draw, from the tracker's category tallies (:class:`LatticeCPR`)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from semmap_pp.lattice.frame import Frame
from semmap_pp.target.likelihood import (N_X, R_INTERIOR, R_OUT, R_WALL, X_FREE, X_OBJECTLIKE, X_SHADOW,
                                         X_UNKNOWN, X_WALLLIKE)


# Which (extended input code, region) pairs count as correctly explained (docs/evaluation.md, CPR): the sampler's
# cell categories are x + N_X * (region + 3 * corridor).
_CORRECT = np.zeros((N_X, 3), bool)
_CORRECT[X_UNKNOWN, R_OUT] = True
_CORRECT[[X_OBJECTLIKE, X_WALLLIKE], R_WALL] = True
_CORRECT[[X_FREE, X_UNKNOWN, X_OBJECTLIKE, X_SHADOW], R_INTERIOR] = True


CORRECT_CATEGORY = np.concatenate([_CORRECT.T.ravel()] * 2)  # corridor or not: same verdict


def category_hist(tracker) -> np.ndarray:
    """The tracker's (30,) category histogram of the current world."""
    hist = getattr(tracker, "hist", None)
    if hist is None:  # older trackers kept it on their likelihood cover
        hist = tracker.cover.hist
    return hist


@dataclass(frozen=True, eq=False)
class LatticeCPR:
    """Per-draw cell prediction rate from the likelihood's category tallies — O(1) per draw.

    The tracker keeps how many lattice cells fall in each (input code, region, corridor) category.
    Cells outside the ROI are unknown by construction (the default ROI contains every known cell),
    so as long as no unit reaches beyond the ROI each of them counts as correct (unknown, outside
    every unit), and ``CPR = (correct cells - cells outside the ROI) / ROI cells``. A unit reaching past
    the ROI makes this a slight under-estimate. It is a proxy for the convergence diagnostics; the
    reported CPR of W* is computed exactly on the input image by :func:`~semmap_pp.semantic.semantic_map.semantic_map`.
    """

    n_roi: int
    n_outside: int

    @classmethod
    def from_roi(cls, frame: Frame, roi_image: np.ndarray) -> "LatticeCPR":
        hl, wl = frame.shape
        n_roi = 0
        for b0, b1 in frame.bands():   # in bands of rows (memory of a band, not of the lattice)
            xi, yi, inside = frame.lattice_pixels(b0, b1)
            ok = inside & ~frame.outside[b0:b1]
            n_roi += int(np.count_nonzero(roi_image[yi[ok], xi[ok]]))
        return cls(n_roi, hl * wl - n_roi)

    def __call__(self, tracker) -> float:
        if self.n_roi == 0:
            return math.nan
        correct = int(np.dot(category_hist(tracker), CORRECT_CATEGORY))
        return (correct - self.n_outside) / self.n_roi
