"""Convergence diagnostics and posterior spread — the only module that imports ArviZ.

Slot-level quantities (the rectangle in slot 3) are meaningless across chains: units are born and die
in any slot (label switching). So chains are judged on *label-invariant* summaries of each sampled
world — its log posterior, number of units, total wall length, cell prediction rate and counts per
type — with ArviZ's rank-normalised split R-hat and bulk / tail ESS. A NaN R-hat or ESS (for example
a summary that never moved in any chain) counts as a failure, never as a pass.

Chains in separate modes never agree, so the verdict above fails on every map with dispersed starts.
What the posterior spread figures rest on is judged apart (:class:`ModeReport`): the same
diagnostics over the draws of the chains in the best chain's mode only, for the summaries that
moved there (one that is constant over those draws is listed with its value; it is the mode's, not
a mixing failure), after the draws in which those chains were still settling: climbing towards
the mode, or leaving a start at its top (:func:`warmup_draws`, the MSER rule). One chain is judged
by R-hat of its two halves, as ArviZ needs two chains.

Posterior spread is shown per cell: the probability, over sampled worlds, that a cell is wall or
belongs to a unit of each type (:class:`SpreadAccumulator`), and one number, the mean Bernoulli
variance ``p (1 - p)`` of the wall indicator over the cells that are ever wall.

ArviZ (and xarray) are imported by the functions that use them, not with this module: they take
about 1 s, which ``semmap map`` spends while its start world is made in another process.

Examples
--------
>>> import numpy as np
>>> rng = np.random.default_rng(0)
>>> report = convergence({"log_posterior": rng.normal(size=(4, 300))}, rhat_max=1.01, ess_min=100)
>>> report.ok
True
>>> stuck = rng.normal(size=(4, 300)); stuck[0] += 5.0
>>> convergence({"log_posterior": stuck}, rhat_max=1.01, ess_min=100).ok
False
"""

from __future__ import annotations

import math
import os
import warnings
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Mapping

import numpy as np

from semmap_pp import atomic
from semmap_pp.cells import UNIT_TYPES
from semmap_pp.errors import SemmapError

#: A chain whose mean log posterior lies more than this many within-chain standard deviations below
#: the best chain's sits in another mode (:meth:`ConvergenceReport.separated_chains`).
SEPARATION_SDS = 4.0

#: :func:`warmup_draws` cuts a chain's first draws where the squared standard error of the rest's
#: mean (MSER) comes within this factor of its least value.
WARMUP_GAIN = 2.0

#: A chain of the best chain's mode is *still climbing* (:func:`climb`) when, over its draws after
#: the warm-up cut, the mean log posterior of its last quarter exceeds its first quarter's by more
#: than :data:`CLIMB_MIN_NATS`, no quarter's mean falls below the one before by more than
#: :data:`CLIMB_DIP` of that rise, and at least :data:`CLIMB_SHARE` of the way its log posterior
#: travelled from draw to draw went up more than down (``(last - first) / sum |steps|``).
CLIMB_MIN_NATS = 1.0
CLIMB_DIP = 0.1
CLIMB_SHARE = 0.25

#: Label-invariant summaries recorded for every draw, in report order.
SUMMARIES = ("log_posterior", "n_units", "wall_length", "cpr") + tuple(f"n_{t}" for t in UNIT_TYPES)


@dataclass(frozen=True)
class QuantityDiagnostics:
    """R-hat and ESS of one summary across chains."""

    name: str
    mean: float
    sd: float
    rhat: float
    ess_bulk: float
    ess_tail: float
    ok: bool
    reason: str  # "" when ok, else why it failed
    chain_means: tuple = ()  # the summary's mean in each chain (chains stuck in different modes differ)
    chain_sds: tuple = ()    # its standard deviation within each chain


@dataclass(frozen=True)
class ModeReport:
    """Diagnostics over the draws of the chains in the best chain's mode only (the chains the
    posterior spread figures use), for the summaries that moved there.

    ``chains`` are numbered from 1; ``constant`` holds ``(name, value)`` for each summary that kept
    one value over all those draws. ``ok`` needs at least one summary that moved, and each of them
    to pass the report's thresholds. ``ess`` is the smallest bulk or tail ESS of those summaries:
    about how many independent draws the spread figures rest on.
    """

    chains: tuple[int, ...]
    n_draws: int
    quantities: tuple[QuantityDiagnostics, ...]
    constant: tuple[tuple[str, float], ...]
    first_draw: int = 0   # draws before it (from 0) left out: the mode's chains still settling
    figures: bool = True  # whether the spread figures are drawn from these draws (else: W*'s search)
    draws_option: str = "--draws"   # the option that lengthens these chains (for the verdict)
    climbing: tuple[tuple[int, float], ...] = ()   # (chain, rise in nats) of the chains still climbing

    @property
    def ok(self) -> bool:
        return bool(self.quantities) and all(q.ok for q in self.quantities)

    @property
    def ess(self) -> float:
        v = [min(q.ess_bulk, q.ess_tail) for q in self.quantities]
        return float(min(v)) if v and all(math.isfinite(x) for x in v) else math.nan

    def verdict(self) -> str:
        """One line: whether the chains mixed within the best chain's mode."""
        if self.ok:
            return f"mixed within the mode (smallest ESS {self.ess:.0f})"
        if not self.quantities:
            return ("NOT mixed within the mode: no summary moved over its draws (nothing to estimate a "
                    "spread from)")
        what = "the spread figures rest on" if self.figures else "its estimates rest on"
        ess = (f"{what} about {self.ess:.0f} independent draws (smallest ESS); "
               if math.isfinite(self.ess) else "")
        if self.climbing:
            chains = chains_phrase(c for c, _ in self.climbing)
            rises = ", ".join(f"{r:,.1f}" for _, r in self.climbing)
            return (f"NOT mixed within the mode: {ess}{chains} still climbing (log posterior up {rises} "
                    f"nats from the first quarter of these draws to the last, with few steps down): "
                    f"{'the figures follow' if self.figures else 'its draws follow'} a climb, and more "
                    f"draws ({self.draws_option}) climb further rather than steady them (docs/sampler.md, "
                    f"\"Chains that climb\")")
        return (f"NOT mixed within the mode: {ess}more draws ({self.draws_option}) may steady them "
                f"(docs/sampler.md, \"Chains that climb\")")

    def heading(self, n_chains: int) -> str:
        which = "all chains" if len(self.chains) == n_chains else chains_phrase(self.chains)
        limit = ("; at the rule's limit of half the draws, so maybe settling still"
                 if self.first_draw == self.n_draws // 2 else "")
        draws = (f"draws {self.first_draw + 1}-{self.n_draws}, the first {self.first_draw} left out as "
                 f"still settling (MSER{limit})" if self.first_draw else f"all {self.n_draws} draws")
        halves = "; one chain: R-hat of its two halves" if len(self.chains) == 1 else ""
        const = (("; constant there: " + ", ".join(f"{n} {v:.6g}" for n, v in self.constant))
                 if self.constant else "")
        return f"within the best chain's mode ({which}, {draws}{halves}{const})"

    def to_dict(self) -> dict:
        return {"ok": self.ok, "chains": list(self.chains), "draws": self.n_draws,
                "first_draw": self.first_draw, "ess": _clean(self.ess),
                "climbing": [{"chain": c, "rise": r} for c, r in self.climbing],
                "quantities": {q.name: _quantity_dict(q) for q in self.quantities},
                "constant": {n: v for n, v in self.constant}}


@dataclass(frozen=True)
class ConvergenceReport:
    """Diagnostics of every summary, with the thresholds they were judged by, and the same over the
    best chain's mode (``within_mode``, :class:`ModeReport`)."""

    quantities: tuple[QuantityDiagnostics, ...]
    n_chains: int
    n_draws: int
    rhat_max: float
    ess_min: float
    within_mode: ModeReport | None = None
    draws_option: str = "--draws"   # the option that lengthens these chains (for the remedy)
    tempered: bool = False          # drawn with replica exchange already (for the remedy)

    def with_figures(self, figures: bool) -> "ConvergenceReport":
        """The same report, its texts saying whether the spread figures are drawn from its draws
        (``ModeReport.figures``; False for W*'s search when the run has a sample around W*)."""
        if self.within_mode is None:
            return self
        return replace(self, within_mode=replace(self.within_mode, figures=figures))

    def shows_mode(self) -> bool:
        """Whether the within-mode diagnostics say more than the main table: some chain lies in
        another mode, was still settling, or some summary is constant there."""
        m = self.within_mode
        return m is not None and (len(m.chains) < self.n_chains or bool(m.constant) or m.first_draw > 0)

    @property
    def ok(self) -> bool:
        return all(q.ok for q in self.quantities)

    def separated_chains(self, name: str = "log_posterior") -> list[tuple[int, float]]:
        """Chains whose mean of ``name`` lies apart from the best chain's: ``(chain, gap)`` pairs
        (chain numbered from 1; gap = best chain's mean - this chain's mean) for every chain whose
        gap exceeds ``SEPARATION_SDS`` times the larger of the two chains' own standard deviations
        (and 1). Such a chain sits in another mode of the posterior, or is still climbing towards
        the best chain's. Empty with one chain or without the summary.

        >>> import numpy as np
        >>> lp = np.tile(np.arange(50.0) % 5, (3, 1)); lp[2] -= 100.0   # chain 3 far below
        >>> convergence({"log_posterior": lp}, rhat_max=1.01, ess_min=10).separated_chains()
        [(3, 100.0)]
        """
        return self._separation(name)[1]

    def _separation(self, name: str) -> tuple[int, list[tuple[int, float]]]:
        """``(best chain, numbered from 1, or 0 when there is none; separated_chains(name))``."""
        q = next((q for q in self.quantities if q.name == name), None)
        if q is None or len(q.chain_means) < 2:
            return 0, []
        means, sds = np.asarray(q.chain_means, float), np.asarray(q.chain_sds or [0.0] * len(q.chain_means))
        if not np.isfinite(means).any():
            return 0, []
        best = int(np.nanargmax(means))
        out = []
        for c, (m, sd) in enumerate(zip(means, sds)):
            gap = float(means[best] - m)
            if c != best and np.isfinite(gap) and gap > SEPARATION_SDS * max(float(sd), float(sds[best]), 1.0):
                out.append((c + 1, round(gap, 1)))
        return best + 1, out

    def mode_chains(self, name: str = "log_posterior") -> list[int]:
        """The chains (numbered from 1) in the best chain's mode: every chain that
        :meth:`separated_chains` does not name; all chains when there is no best one.

        >>> import numpy as np
        >>> lp = np.tile(np.arange(50.0) % 5, (3, 1)); lp[1] -= 100.0   # chain 2 far below
        >>> convergence({"log_posterior": lp}, rhat_max=1.01, ess_min=10).mode_chains()
        [1, 3]
        """
        apart = {c for c, _ in self._separation(name)[1]}
        return [c for c in range(1, self.n_chains + 1) if c not in apart]

    def separation_note(self) -> str:
        """One line naming the chains in separate modes (:meth:`separated_chains`), "" if none."""
        best, sep = self._separation("log_posterior")
        figures = self.within_mode is None or self.within_mode.figures
        return _separation_text(sep, best, self.mode_chains(), figures) if sep else ""

    def to_dict(self) -> dict:
        return {
            "ok": self.ok, "chains": self.n_chains, "draws": self.n_draws,
            "rhat_max": self.rhat_max, "ess_min": self.ess_min,
            "quantities": {q.name: dict(_quantity_dict(q), chain_means=[_clean(m) for m in q.chain_means],
                                        chain_sds=[_clean(m) for m in q.chain_sds])
                           for q in self.quantities},
            "separated_chains": [{"chain": c, "log_posterior_below_best": g}
                                 for c, g in self.separated_chains()],
            "within_mode": self.within_mode.to_dict() if self.within_mode is not None else None,
        }

    def failed(self) -> str:
        """Which summaries failed, by which quantity: "" when every one passed.

        >>> import numpy as np
        >>> rng = np.random.default_rng(1)
        >>> apart = rng.normal(size=(2, 40)); apart[1] += 8.0
        >>> text = convergence({"log_posterior": apart, "n_units": rng.normal(size=(2, 40))},
        ...                    rhat_max=1.01, ess_min=400).failed()
        >>> [part.split(" on ")[0] for part in text.split("; ")]
        ['R-hat > 1.01', 'bulk ESS < 400', 'tail ESS < 400']
        >>> text.split("; ")[0].startswith("R-hat > 1.01 on log_posterior (") and "n_units" not in text.split("; ")[0]
        True
        """
        parts = []
        rhat = [q for q in self.quantities if not (math.isfinite(q.rhat) and q.rhat <= self.rhat_max)]
        if rhat:
            parts.append(f"R-hat > {self.rhat_max:g} on " + ", ".join(
                f"{q.name} ({format_rhat(q.rhat)})" for q in rhat))
        for kind in ("bulk", "tail"):
            low = [(q.name, getattr(q, f"ess_{kind}")) for q in self.quantities]
            low = [(n, v) for n, v in low if not (math.isfinite(v) and v >= self.ess_min)]
            if low:
                parts.append(f"{kind} ESS < {self.ess_min:g} on " + ", ".join(
                    f"{n} ({v:.0f})" if math.isfinite(v) else f"{n} (NaN)" for n, v in low))
        return "; ".join(parts)

    def remedy(self) -> str:
        """What would fix a failing verdict, from which quantity failed: "" when it passed.

        Chains apart (R-hat, or chains in separate modes): more draws join them only slowly;
        replica exchange is the tool built for that (a longer ladder, when it ran already). ESS
        alone below the threshold: about ``ess_min / ESS`` times as many draws.

        >>> import numpy as np
        >>> rng = np.random.default_rng(2)
        >>> text = convergence({"log_posterior": rng.normal(size=(2, 50))}, rhat_max=1.1, ess_min=400).remedy()
        >>> text.startswith("about ") and "times as many draws (--draws " in text
        True
        """
        if self.ok:
            return ""
        rhat_fail = any(not (math.isfinite(q.rhat) and q.rhat <= self.rhat_max) for q in self.quantities)
        ess = [min(q.ess_bulk, q.ess_tail) for q in self.quantities]
        low = min((v for v in ess if math.isfinite(v) and v > 0), default=math.nan)
        more = ""
        if math.isfinite(low) and low < self.ess_min:
            factor = self.ess_min / low
            more = (f"about {factor:,.0f} times as many draws ({self.draws_option} "
                    f"{math.ceil(self.n_draws * factor)}) for ESS {self.ess_min:g}")
        if all(_constant(np.asarray(q.chain_means)) and all(sd == 0 for sd in q.chain_sds)
               for q in self.quantities):
            return ("no summary moved in any chain: every draw is the chains' start world, and the "
                    "kernels' proposals were all refused; more draws change nothing until the chains "
                    "move (a sample that flattens the target: `semmap map --tempered`)")
        if rhat_fail and (self.separated_chains() or any(q.rhat > 1.1 for q in self.quantities
                                                         if math.isfinite(q.rhat))
                          or any(math.isinf(q.rhat) for q in self.quantities)):
            cure = ("a ladder reaching nearer the prior (more rungs: `--rungs N`, a smaller "
                    "[sampler] spread_ladder_ratio) and more swaps (spread_swaps)" if self.tempered else
                    "what joins such modes is a flatter target, and none measured does yet: replica "
                    "exchange (`semmap map --tempered`) keeps them apart on the bundled maps, and at its "
                    "exponent the target prefers fewer units than W* (docs/model.md, \"What a unit more "
                    "or less costs at 1 / A\"); whether other seeds find the same plan: `semmap "
                    "stability`")
            return ("the chains disagree (R-hat): they sit in separate modes or have not left their "
                    f"starts, which more draws mend only slowly; {cure}" + (f"; then {more}" if more else ""))
        if more:
            return more
        return f"more draws ({self.draws_option})"

    def verdict(self) -> str:
        """The verdict's lines: "converged", or "NOT converged", what failed and what would fix it."""
        if self.ok:
            return "converged"
        return f"NOT converged\nfailed: {self.failed()}\nto fix: {self.remedy()}"

    def to_text(self) -> str:
        lines = [f"chains: {self.n_chains}, draws per chain: {self.n_draws}; "
                 f"pass when R-hat <= {self.rhat_max:g} and bulk and tail ESS >= {self.ess_min:g} "
                 f"(Vehtari et al. 2021; NaN fails)",
                 *_table_lines(self.quantities)]
        lines.append(self.verdict())
        note = self.separation_note()
        if note:
            lines.append(note)
        if self.shows_mode():
            m = self.within_mode
            lines += ["", m.heading(self.n_chains)]
            if m.quantities:
                lines += _table_lines(m.quantities)
            lines.append(m.verdict())
        if self.n_chains > 1:
            lines += ["", "mean per chain (chains that settled in different modes differ here)",
                      f"{'quantity':<16}" + "".join(f"{'chain ' + str(c + 1):>12}" for c in range(self.n_chains))]
            for q in self.quantities:
                lines.append(f"{q.name:<16}" + "".join(f"{m:>12.4g}" for m in q.chain_means))
        return "\n".join(lines)


def _clean(v):
    """NaN and infinities as None (JSON has neither)."""
    return None if isinstance(v, float) and not math.isfinite(v) else v


def _quantity_dict(q: QuantityDiagnostics) -> dict:
    return {"mean": _clean(q.mean), "sd": _clean(q.sd), "rhat": _clean(q.rhat), "ess_bulk": _clean(q.ess_bulk),
            "ess_tail": _clean(q.ess_tail), "ok": q.ok, "reason": q.reason}


def _constant(a: np.ndarray) -> bool:
    """Whether every value of ``a`` is finite and the same."""
    return bool(np.all(np.isfinite(a)) and np.all(a == a.flat[0]))


def format_rhat(rhat: float) -> str:
    """R-hat as the tables print it: three decimals, or three significant digits from 1000 on
    (a chain that barely moves beside one stuck at another value gives ArviZ numbers like
    5.77e+15), ``inf`` and ``nan`` as such.

    >>> [format_rhat(x) for x in (1.0123, 5768652578615959.0, float("inf"), float("nan"))]
    ['1.012', '5.77e+15', 'inf', 'nan']
    """
    if math.isnan(rhat):
        return "nan"
    if math.isinf(rhat):
        return "inf"
    return f"{rhat:.3g}" if abs(rhat) >= 1000 else f"{rhat:.3f}"


def _table_lines(quantities) -> list[str]:
    lines = [f"{'quantity':<16}{'mean':>12}{'sd':>10}{'R-hat':>8}{'ESS bulk':>10}{'ESS tail':>10}  verdict"]
    for q in quantities:
        verdict = "ok" if q.ok else f"FAIL: {q.reason}"
        lines.append(f"{q.name:<16}{q.mean:>12.4g}{q.sd:>10.3g}{format_rhat(q.rhat):>8}"
                     f"{q.ess_bulk:>10.0f}{q.ess_tail:>10.0f}  {verdict}")
    return lines


def _as_chain_draw(name: str, values) -> np.ndarray:
    a = np.asarray(values, dtype=float)
    if a.ndim == 1:
        a = a[None, :]
    if a.ndim != 2 or a.shape[1] < 4:
        raise ValueError(f"summary {name!r} must be (chains, draws) with at least 4 draws, got {a.shape}")
    return a


def _diagnose_one(name: str, a: np.ndarray, rhat_max: float, ess_min: float) -> QuantityDiagnostics:
    import arviz_stats  # ArviZ takes about 1 s to import: only when draws are judged (module docstring)

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        if np.all(np.isnan(a)):
            rhat = ess_b = ess_t = float("nan")
        else:
            # ArviZ gives NaN for one chain: judge its two halves as two chains instead.
            half = a.shape[1] // 2
            rhat = float(arviz_stats.rhat(a if a.shape[0] > 1 else a[:, :2 * half].reshape(2, half)))
            stuck = ""
            if a.shape[0] > 1 and np.all(np.ptp(a, axis=1) == 0) and np.ptp(a[:, 0]) > 0:
                stuck = "each chain stuck at its own value"
            elif a.shape[0] > 1 and half >= 2:
                halves = np.concatenate([a[:, :half], a[:, a.shape[1] - half:]])
                if np.all(np.ptp(halves, axis=1) == 0) and np.ptp(halves[:, 0]) > 0:
                    stuck = "each half of every chain stuck at one value: a chain jumped once"
            if stuck:
                rhat = math.inf     # ArviZ: a huge finite number (split R-hat, no variance within)
            ess_b = float(arviz_stats.ess(a, method="bulk"))
            ess_t = float(arviz_stats.ess(a, method="tail", prob=(0.05, 0.95)))
        mean, sd = float(np.nanmean(a)) if a.size else float("nan"), float(np.nanstd(a))
        chain_means = tuple(float(v) for v in np.nanmean(a, axis=1))
        chain_sds = tuple(float(v) for v in np.nanstd(a, axis=1))
    reasons = []
    if math.isinf(rhat):
        reasons.append(f"R-hat is infinite ({stuck or 'each chain stuck at its own value'})")
    elif not math.isfinite(rhat):
        same = _constant(a)
        reasons.append("R-hat is NaN (" + ("summary never moved in any chain" if same else "NaN values") + ")")
    elif rhat > rhat_max:
        reasons.append(f"R-hat {format_rhat(rhat)} > {rhat_max}")
    if math.isfinite(rhat) and not (math.isfinite(ess_b) and math.isfinite(ess_t)):
        reasons.append("ESS is NaN")
    elif math.isfinite(ess_b) and min(ess_b, ess_t) < ess_min:
        which = [f"{k} ESS {v:.0f}" for k, v in (("bulk", ess_b), ("tail", ess_t)) if v < ess_min]
        reasons.append(f"{' and '.join(which)} < {ess_min:g}")
    return QuantityDiagnostics(name, mean, sd, rhat, ess_b, ess_t, not reasons, "; ".join(reasons),
                               chain_means, chain_sds)


def chains_phrase(chains) -> str:
    """"chain 2" or "chains 1, 3": chain numbers as the reports name them.

    >>> chains_phrase([2]), chains_phrase([1, 3])
    ('chain 2', 'chains 1, 3')
    """
    chains = list(chains)
    return ("chain " if len(chains) == 1 else "chains ") + ", ".join(map(str, chains))


def _separation_text(separated: list[tuple[int, float]], best: int, mode: list[int], figures: bool = True) -> str:
    if len(separated) == 1:
        (c, g), = separated
        what = f"chain {c}'s mean log posterior lies {g:,.1f} nats below chain {best}'s"
    else:
        what = (f"the mean log posteriors of chains {', '.join(str(c) for c, _ in separated)} lie "
                f"{', '.join(f'{g:,.1f}' for _, g in separated)} nats below chain {best}'s")
    return (f"chains in separate modes: {what}, more than {SEPARATION_SDS:g} of the chains' own "
            f"standard deviations (another mode, or still climbing: docs/sampler.md, \"Chains in "
            f"separate modes\"); W* comes from the best world of any chain"
            + (f", the posterior spread from {chains_phrase(mode)} (chain {best}'s mode)" if figures else
               " (the spread figures from the sample around W*)"))


def warmup_draws(x) -> int:
    """How many leading draws of one chain's trace ``x`` to leave out as warm-up, by the MSER rule
    (White 1997): the squared standard error of the mean of the draws left,
    ``sum((x[d:] - mean)^2) / (n - d)^2``, for each cut ``d <= len(x) // 2``; the smallest cut whose
    error is within ``WARMUP_GAIN`` of the least. Plain MSER takes the least itself, which on a
    flat trace falls anywhere by chance (it cut 4 of 20 white-noise traces of 25 draws, and a
    chain 24 draws deep that had stopped climbing after 12); with the factor a cut is made only
    where it divides that error by at least ``WARMUP_GAIN``, and no further. 0 when ``x`` holds a
    non-finite value or fewer than 4 draws. A chain still climbing towards its mode (or leaving a
    start at its top) has a trend that the rule cuts off; one already there keeps every draw.

    >>> warmup_draws([-50.0, -20.0, -5.0, 0.0, 0.1, -0.1, 0.0, 0.1, -0.1, 0.0])
    3
    >>> warmup_draws([0.0, 0.1, -0.1, 0.0, 0.1, -0.1, 0.0, 0.1])
    0
    """
    x = np.asarray(x, float)
    n = x.size
    if n < 4 or not np.all(np.isfinite(x)):
        return 0
    x = x - x[-1]                                   # log posteriors are ~1e6: keep the sums small
    m = np.arange(n, 0, -1, dtype=float)            # draws left after cutting d = 0 .. n-1
    s1, s2 = np.cumsum(x[::-1])[::-1], np.cumsum((x * x)[::-1])[::-1]
    mser = np.maximum(s2 - s1 * s1 / m, 0.0) / (m * m)
    mser = mser[: n // 2 + 1]
    return int(np.flatnonzero(mser <= mser.min() * WARMUP_GAIN + 1e-300)[0])


def climb(x) -> float:
    """How far one chain's log posterior trace ``x`` (after the warm-up cut) still climbs: the
    mean of its last quarter minus its first quarter's, rounded to 0.1 nats, when the trace climbs
    as :data:`CLIMB_SHARE` and its neighbours say; else 0. Finite traces of at least 8 draws only.

    A chain at T = 1 in a target this peaked takes nearly every step up and few down: its trace is
    a staircase of plateaus, which the MSER cut does not remove, and its ESS does not grow with
    more draws (docs/sampler.md, "Chains that climb"). A stationary chain goes down as far as it
    goes up: what it travels grows with its length, where it ends does not.

    >>> climb(np.repeat([0.0, 5.0, 9.0, 20.0], 10) + np.tile([0.1, -0.1], 20))   # a staircase
    20.0
    >>> climb(np.tile([0.1, -0.1], 20)), climb(np.full(40, 3.0))
    (0.0, 0.0)
    """
    x = np.asarray(x, float)
    if x.size < 8 or not np.all(np.isfinite(x)):
        return 0.0
    x = x - x[-1]
    q = [float(part.mean()) for part in np.array_split(x, 4)]
    rise = q[-1] - q[0]
    travelled = float(np.abs(np.diff(x)).sum())
    if (rise > CLIMB_MIN_NATS and all(b >= a - CLIMB_DIP * rise for a, b in zip(q, q[1:]))
            and travelled > 0 and (x[-1] - x[0]) / travelled >= CLIMB_SHARE):
        return round(rise, 1)
    return 0.0


def convergence(summaries: Mapping[str, object] | "xr.DataTree", *, rhat_max: float,
                ess_min: float, draws_option: str = "--draws") -> ConvergenceReport:
    """Judge convergence of label-invariant summaries.

    Parameters
    ----------
    summaries : mapping of name to (chains, draws) array, or a DataTree from :func:`to_datatree`
    rhat_max, ess_min : float
        Thresholds (the model file's ``[diagnostics]`` section holds the project's values).
    draws_option : str
        The ``semmap map`` option that lengthens these chains, named by the within-mode verdict.

    The texts say the spread figures are drawn from these draws; :meth:`ConvergenceReport.with_figures`
    says otherwise.
    """
    if hasattr(summaries, "children"):  # an ArviZ DataTree (itself a Mapping of groups)
        post = summaries["posterior"]
        summaries = {k: np.asarray(post[k].values) for k in post.data_vars}
    if not summaries:
        raise ValueError("no summaries to diagnose")
    names = [n for n in SUMMARIES if n in summaries] + sorted(n for n in summaries if n not in SUMMARIES)
    arrays = {n: _as_chain_draw(n, summaries[n]) for n in names}
    shapes = {a.shape for a in arrays.values()}
    if len(shapes) != 1:
        raise ValueError(f"summaries differ in shape: {sorted(shapes)}")
    (n_chains, n_draws), = shapes
    qs = tuple(_diagnose_one(n, arrays[n], rhat_max, ess_min) for n in names)
    report = ConvergenceReport(qs, n_chains, n_draws, rhat_max, ess_min, draws_option=draws_option)
    chains = tuple(report.mode_chains())
    lp = arrays.get("log_posterior")
    first = max((warmup_draws(lp[c - 1]) for c in chains), default=0) if lp is not None else 0
    # the mode over every chain from the first draw: the same arrays, so the same diagnostics
    whole = dict(zip(names, qs)) if (list(chains) == list(range(1, n_chains + 1)) and first == 0) else {}
    moved, constant = [], []
    for n in names:
        a = arrays[n][[c - 1 for c in chains], first:]
        if _constant(a):
            constant.append((n, float(a.flat[0])))
        else:
            moved.append(whole.get(n) or _diagnose_one(n, a, rhat_max, ess_min))
    climbing = tuple((c, r) for c in chains if lp is not None for r in [climb(lp[c - 1, first:])] if r > 0)
    return replace(report, within_mode=ModeReport(chains, n_draws, tuple(moved), tuple(constant), first,
                                                  draws_option=draws_option, climbing=climbing))


def to_datatree(summaries: Mapping[str, object], *, sample_stats: Mapping[str, object] | None = None,
                attrs: Mapping[str, object] | None = None):
    """Pack (chains, draws) summaries (and optional sampler stats) into an ArviZ DataTree."""
    import arviz_base  # deferred, as in _diagnose_one

    groups = {"posterior": {k: _as_chain_draw(k, v) for k, v in summaries.items()}}
    if sample_stats:
        groups["sample_stats"] = {k: np.asarray(v) for k, v in sample_stats.items()}
    tree = arviz_base.from_dict(groups)
    tree.attrs.update({k: (v if isinstance(v, (int, float, str)) else str(v)) for k, v in (attrs or {}).items()})
    return tree


def write_trace(tree, path: str | os.PathLike) -> Path:
    """Write a DataTree as NetCDF atomically: made in memory, then written by
    :func:`semmap_pp.atomic.write_bytes` (a full disk is one WriteError, the old file kept)."""
    path = Path(path)
    atomic.write_bytes(path, tree.to_netcdf(None, engine="h5netcdf"))
    return path


def read_trace(path: str | os.PathLike):
    """Read a trace written by :func:`write_trace`; a clear error if it is missing or not a trace."""
    path = Path(path)
    if not path.is_file():
        raise SemmapError(path, "no trace file here (expected trace.nc written by `semmap map`)")
    import xarray as xr  # deferred, as in _diagnose_one

    try:
        tree = xr.open_datatree(path, engine="h5netcdf")
        tree["posterior"]
    except Exception as exc:  # h5py/xarray raise many kinds; the user needs one line
        raise SemmapError(path, f"not a readable ArviZ trace ({type(exc).__name__}: {exc})") from None
    return tree


@dataclass
class SpreadAccumulator:
    """Per-cell posterior probabilities of wall and of each unit type, accumulated over sampled worlds.

    Examples
    --------
    >>> import numpy as np
    >>> acc = SpreadAccumulator((1, 3))
    >>> acc.add(np.array([[True, False, False]]), np.array([[0, 1, -1]]))
    >>> acc.add(np.array([[False, False, False]]), np.array([[0, 1, -1]]))
    >>> acc.p_wall().tolist(), acc.p_type()[0].tolist()
    ([[0.5, 0.0, 0.0]], [[1.0, 0.0, 0.0]])
    >>> round(acc.wall_spread(), 3)  # mean p(1-p) over cells ever wall: 0.5 * 0.5
    0.25
    """

    shape: tuple[int, int]
    n: int = 0
    wall: np.ndarray = field(init=False)
    types: np.ndarray = field(init=False)
    #: the counts' dtype: ``uint16`` where the caller knows fewer than 65,536 worlds will be added
    #: (half the memory of a campus floor's box), int32 otherwise
    dtype: type = np.int32

    def __post_init__(self):
        self.wall = np.zeros(self.shape, self.dtype)
        self.types = np.zeros((len(UNIT_TYPES),) + tuple(self.shape), self.dtype)

    def add(self, wall_mask: np.ndarray, type_index: np.ndarray, count: int = 1) -> None:
        """Count one world ``count`` times: its wall cells and, per cell, the type index of its unit
        (-1 none)."""
        self.n += count
        # in place, on the cells counted (no int64 products of the whole box): the same counts
        self.wall[np.asarray(wall_mask, dtype=bool)] += count
        for t in range(len(UNIT_TYPES)):
            self.types[t][type_index == t] += count

    def p_wall(self) -> np.ndarray:
        return self.wall / max(self.n, 1)

    def p_type(self) -> np.ndarray:
        return self.types / max(self.n, 1)

    def wall_spread(self) -> float:
        """Mean Bernoulli variance of the wall indicator over cells that were ever wall (0 = no spread)."""
        p = self.p_wall()
        ever = p > 0
        return float(np.mean(p[ever] * (1 - p[ever]))) if ever.any() else 0.0
