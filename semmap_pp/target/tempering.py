"""A likelihood raised to a power: tempered copies of the target, and the exponent's rule.

The log-likelihood is a sum over the lattice's cells, as if every cell were an independent
observation. The sensor's errors are not independent: a wall drawn a cell off, a ray fan, a
piece of furniture spread over many neighbouring cells. Counted as independent, ``n`` cells make
the posterior as peaked as ``n`` independent observations would, while they carry the
information of about ``n / A`` of them, ``A`` the *correlation area* of the residuals (the sum of
their spatial autocorrelation over all lags, in cells). A power likelihood ``p(M|W)^(1/A)``
counts ``n / A`` observations (docs/model.md, "The likelihood's exponent").

:func:`tempered` gives the target with the likelihood raised to any power ``beta``: the gains,
the baseline, ``log ψ`` and the enclosure cost times ``beta`` (every term of ``log p(M|W)`` is one
of them), everything else shared with the original (types, knowledge caches, prior), so a tracker
moves between tempered copies by :meth:`~semmap_pp.target.posterior.Tracker.retarget` without
recomputing anything but one dot product (replica exchange, :mod:`semmap_pp.sampler.replicas`).

Examples
--------
>>> import numpy as np
>>> from semmap_pp import world as wm
>>> from semmap_pp.model import load_model
>>> from semmap_pp.lattice.frame import build_frame_from_classes
>>> from semmap_pp.target.posterior import Posterior
>>> classes = np.full((40, 60), 1, np.uint8); classes[5:35, 5:55] = 0
>>> post = Posterior(build_frame_from_classes(classes, 0.05, load_model()), load_model())
>>> w = wm.add(wm.empty(8), 0, (5, 5, 35, 30))
>>> full, half = post.evaluate(w), tempered(post, 0.5).evaluate(w)
>>> bool(abs(half.loglik - 0.5 * full.loglik) < 1e-9), half.logprior == full.logprior
(True, True)
"""

from __future__ import annotations

import copy

import numpy as np

from semmap_pp.cells import W_UNKNOWN, W_WALL
from semmap_pp.target.likelihood import (_X_INPUT, _X_INTERIOR_STATE, N_CATEGORIES, N_X, R_OUT,
                                         R_WALL, categorise, cover_counts, tempered_data)
from semmap_pp.target.posterior import (CORRIDOR, F_BASE, F_ENC_COST, F_LOGPSI, Posterior, _ro)


class TemperedPosterior(Posterior):
    """A :class:`Posterior` whose likelihood is the original's to the power :attr:`beta`.

    Made by :func:`tempered` (never by ``__init__``): it shares every cache and the knowledge
    engine with :attr:`base`, and its knowledge phase is the base's, so switching knowledge on the
    base switches every tempered copy with it.
    """

    base: Posterior
    beta: float

    @property
    def knowledge_on(self):
        return self.base.knowledge_on

    @knowledge_on.setter
    def knowledge_on(self, value):
        self.base.knowledge_on = value


def tempered(post: Posterior, beta: float) -> Posterior:
    """``post`` with its likelihood raised to the power ``beta`` (``beta = 1``: ``post`` itself).

    A tempered copy of a tempered copy raises the base's likelihood to the product of the powers.
    """
    beta = float(beta)
    base = getattr(post, "base", post)
    beta = beta * getattr(post, "beta", 1.0)
    if beta == 1.0:
        return base
    out = TemperedPosterior.__new__(TemperedPosterior)
    state = dict(base.__dict__)
    state.pop("knowledge_on", None)
    out.__dict__.update(state)
    out.base, out.beta = base, beta
    out.data = tempered_data(base.data, beta)
    g = out.data.gain.reshape(2, -1)
    out._gain_max = _ro(np.concatenate([np.maximum(g[0], g[1])] * 2))
    fp = base._fp.copy()
    fp[F_BASE], fp[F_LOGPSI] = out.data.baseline, out.data.log_psi
    fp[F_ENC_COST] = base._fp[F_ENC_COST] * beta
    out._fp = fp
    return out


def _category_residuals(sensor) -> np.ndarray:
    """Per likelihood category: the cell's log-likelihood term minus its expectation under the
    sensor model (a cell outside every unit: the UNKNOWN row). (30,) float64."""
    out = np.zeros(N_CATEGORIES)
    for corr, table in ((0, sensor.other), (1, sensor.corridor)):
        logt = np.log(table)
        expected = np.sum(table * logt, axis=1)          # per world state
        for region in range(3):
            for x in range(N_X):
                if region == R_OUT:
                    state = W_UNKNOWN
                elif region == R_WALL:
                    state = W_WALL
                else:
                    state = _X_INTERIOR_STATE[x]
                k = x + N_X * (region + 3 * corr)
                out[k] = logt[state, _X_INPUT[x]] - expected[state]
    return out


def residuals(post: Posterior, world) -> tuple[np.ndarray, np.ndarray]:
    """The residual of every lattice cell under ``world`` (types assigned) and the mask of the
    cells some unit covers: ``log p(input | state, table) - E[log p(· | state, table)]``."""
    slots = np.flatnonzero(world.active)
    counts = cover_counts(post.data.shape, world.rects[slots], world.types[slots] == CORRIDOR,
                          post.data.wall)
    cat, _gamma = categorise(counts, post.data.xcode)
    del counts
    region = (cat // N_X) % 3
    return _category_residuals(post.model.sensor)[cat], region != R_OUT


def correlation_area(resid: np.ndarray, mask: np.ndarray, max_lag: int) -> float:
    """``A = Σ_h ρ(h)`` over the lags ``|h_row|, |h_col| <= max_lag`` (cells), ``ρ`` the
    autocorrelation of ``resid`` over the cells of ``mask`` (centred on their mean; each lag's
    product averaged over the pairs of cells both in the mask). At least 1 (``ρ(0) = 1``);
    negative sums are not taken as more than independent."""
    lag = int(max_lag)
    m = np.asarray(mask, bool)
    if lag < 0 or m.sum() < 2:
        return 1.0
    e = np.where(m, resid - resid[m].mean(), 0.0)
    var = float(np.sum(e * e)) / m.sum()
    if var <= 0.0:
        return 1.0
    shape = (m.shape[0] + lag, m.shape[1] + lag)
    fe, fm = np.fft.rfft2(e, shape), np.fft.rfft2(m.astype(np.float64), shape)
    num = np.fft.irfft2(fe * np.conj(fe), shape)
    pairs = np.fft.irfft2(fm * np.conj(fm), shape)
    idx = np.r_[0:lag + 1, shape[0] - lag:shape[0]] if lag else np.array([0])
    jdx = np.r_[0:lag + 1, shape[1] - lag:shape[1]] if lag else np.array([0])
    num, pairs = num[np.ix_(idx, jdx)], pairs[np.ix_(idx, jdx)]
    rho = np.where(pairs > 0.5, num / np.maximum(pairs, 1.0), 0.0) / var
    return max(1.0, float(rho.sum()))


def likelihood_exponent(post: Posterior, world, max_lag_m: float) -> tuple[float, float]:
    """``(1 / A, A)``: the power of the likelihood that counts the map's cells as ``n / A``
    independent observations, ``A`` the correlation area (cells) of ``world``'s residuals within
    ``max_lag_m`` metres (:func:`correlation_area`); ``(1, 1)`` when ``max_lag_m`` is 0."""
    if not max_lag_m > 0:
        return 1.0, 1.0
    lag = max(1, int(round(float(max_lag_m) / post.cells.resolution)))
    base = getattr(post, "base", post)
    resid, mask = residuals(base, base.evaluate(world).world)
    area = correlation_area(resid, mask, lag)
    return 1.0 / area, area
