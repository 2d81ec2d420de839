"""Continuing a run (``semmap map --resume DIR``): the resume file and the draws kept from chains.

``semmap map`` writes ``DIR/resume.npz`` (atomically, before the other files) with everything a
later run needs to go on: the inputs and settings, per chain its start world, its last world, its
draw count, burn-in length, random state (``bit_generator.state`` after its last draw), knowledge
phase and best world, and every real draw so far (its scalar stats and its world), so a resumed run *appends* draws to the old ones instead of starting a new trace.

Chains can end with different numbers of draws (Ctrl-C, ``--budget``, sequential chains of which
only the first ran). Diagnostics need a (chains, draws) rectangle, so :func:`keep_common_draws`
keeps the ``k`` longest chains cut to the length of the shortest of them, choosing ``k`` to keep the
most draws (``k * L_k``, ties to more chains). The resume file keeps every draw, including those
left out of that rectangle.
"""

from __future__ import annotations

import io
import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from semmap_pp import atomic
from semmap_pp import world as wm
from semmap_pp.errors import SemmapError

FORMAT = "semmap_pp.resume/1"
FILE_NAME = "resume.npz"
#: R-hat and ESS need at least this many draws per chain.
MIN_DRAWS = 4


def merge_records(history, new) -> list:
    """Per chain, the earlier real draws followed by the new ones (``ChainRecord`` lists)."""
    from semmap_pp.sampling import ChainRecord

    out = []
    for old, rec in zip(history, new):
        if old is None or not old.stats:
            out.append(rec)
            continue
        if not rec.stats:
            out.append(old)
            continue
        keys = [k for k in old.stats if k in rec.stats]
        stats = {k: np.concatenate([old.stats[k], rec.stats[k]]) for k in keys}
        out.append(ChainRecord(stats, np.concatenate([old.rects, rec.rects]),
                               np.concatenate([old.active, rec.active]), rec.last))
    return out


def _rectangle(lengths: list[int]) -> tuple[list[int], int]:
    order = sorted(range(len(lengths)), key=lambda c: (-lengths[c], c))
    best_k, best_total = 0, -1
    for k in range(1, len(order) + 1):
        total = k * lengths[order[k - 1]]
        if total >= best_total and lengths[order[k - 1]] > 0:
            best_k, best_total = k, total
    kept = sorted(order[:best_k])
    return kept, (lengths[order[best_k - 1]] if best_k else 0)


def keep_common_draws(records, min_draws: int = MIN_DRAWS):
    """Which chains and draws the summaries use.

    Returns ``(chains, n, index, notes)``: the kept chain numbers, the draws per chain, per chain
    the positions of the kept draws in its record (its first ``n`` recorded draws), and notes for
    the report. When no chain has ``min_draws``
    recorded (post-burn-in) draws, burn-in draws are used and a note says so.

    Raises
    ------
    SemmapError
        When no chain has even ``min_draws`` real draws (nothing to diagnose or write).

    Examples
    --------
    >>> _rectangle([200, 10, 0, 0])      # one long chain beats two short ones
    ([0], 200)
    >>> _rectangle([150, 148])
    ([0, 1], 148)
    """
    notes = []
    recorded = [np.flatnonzero(r.stats["burn_in"] == 0) if r.stats else np.zeros(0, int) for r in records]
    chains, n = _rectangle([len(i) for i in recorded])
    if n < min_draws:
        recorded = [np.arange(len(r.stats["logp"])) if r.stats else np.zeros(0, int) for r in records]
        chains, n = _rectangle([len(i) for i in recorded])
        if n < min_draws:
            raise SemmapError(None, f"fewer than {min_draws} draws in every chain: nothing to keep")
        notes.append(f"no chain reached {min_draws} draws after burn-in: summaries and diagnostics "
                     "cover burn-in draws (annealed, knowledge possibly off)")
    index = {c: recorded[c][:n] for c in chains}
    if len(chains) < len(records) or any(len(recorded[c]) > n for c in chains):
        notes.append(f"chains of unequal length: kept chain(s) {', '.join(str(c + 1) for c in chains)} of {len(records)}, "
                     f"{n} draws each (DIR/{FILE_NAME} keeps every draw)")
    return chains, n, index, notes


@dataclass
class ResumeState:
    """What ``--resume`` reads back (see :func:`read_resume`)."""

    path: Path
    meta: dict                  # inputs, settings, per-chain scalars
    starts: list                # per chain: its first start world
    last: list                  # per chain: its last world
    history: list               # per chain: ChainRecord of every real draw so far
    total_draws: int            # per chain, burn-in included, that the continued run aims at

    def last_worlds(self) -> list:
        return self.last

    def done(self) -> list[int]:
        return [c["draw"] for c in self.meta["chains"]]

    def remaining(self) -> int:
        return max(self.total_draws - d for d in self.done())

    def chain_starts(self) -> dict:
        from semmap_pp.step import ChainStart

        out = {}
        for i, c in enumerate(self.meta["chains"]):
            if c["draw"] == 0:
                continue   # never ran: it starts afresh with the random stream PyMC gives it
            h = self.history[i]
            out[i] = ChainStart(c["draw"], c["n_tune"], c["rng_state"], c["knowledge_on"],
                                c["best_logp"], h.last.best_rects, h.last.best_active)
        return out

    def better_best(self, world, logp: float, chain: int):
        """``(world, chain)``: the best of ``world`` and the stored chains' best worlds."""
        for i, c in enumerate(self.meta["chains"]):
            h = self.history[i]
            if c["draw"] and h.last is not None and c["best_logp"] > logp:
                K = len(h.last.best_active)
                world = wm.make(np.asarray(h.last.best_rects).reshape(K, 4), h.last.best_active,
                                np.full(K, wm.NO_TYPE))
                logp, chain = c["best_logp"], i
        return world, chain


def _json_safe(v):
    if isinstance(v, dict):
        return {k: _json_safe(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_json_safe(x) for x in v]
    if isinstance(v, np.integer):
        return int(v)
    if isinstance(v, np.floating):
        return float(v)
    if isinstance(v, float) and not math.isfinite(v):
        return repr(v)
    return v


def write_resume(out_dir, run, inputs_meta: dict) -> Path:
    """Write ``out_dir/resume.npz`` atomically from a :class:`~semmap_pp.pipeline.MapRun`."""
    settings = run.settings
    chains = []
    arrays = {}
    K = run.starts[0].capacity
    for c, rec in enumerate(run.records):
        last = rec.last
        chains.append({"draw": 0 if last is None else last.draw,
                       "n_tune": settings.tune if last is None else last.n_tune,
                       "rng_state": None if last is None else last.rng_state,
                       "knowledge_on": False if last is None else bool(last.knowledge_on),
                       "best_logp": None if last is None else float(last.best_logp)})
        arrays[f"start_rects_{c}"] = run.starts[c].rects.astype(np.int32)
        arrays[f"start_active_{c}"] = run.starts[c].active
        if last is not None:
            arrays[f"best_rects_{c}"] = np.asarray(last.best_rects, np.int64).reshape(K, 4)
            arrays[f"best_active_{c}"] = np.asarray(last.best_active, bool).reshape(K)
            for k, v in rec.stats.items():
                arrays[f"stat_{c}_{k}"] = v
            dtype = np.int16 if rec.rects.max(initial=0) < 32767 else np.int32
            arrays[f"rects_{c}"] = rec.rects.astype(dtype)
            arrays[f"active_{c}"] = rec.active
    meta = {"format": FORMAT, "inputs": inputs_meta,
            "settings": {k: getattr(settings, k) for k in
                         ("chains", "cores", "tune", "draws", "n_inner", "anneal", "seed",
                          "spread_draws", "spread_n_inner")},
            "capacity": K, "chains": chains, "stopped": run.stopped}
    arrays["meta"] = np.array(json.dumps(_json_safe(meta)))
    buf = io.BytesIO()
    np.savez_compressed(buf, **arrays)
    path = Path(out_dir) / FILE_NAME
    atomic.write_bytes(path, buf.getvalue())
    return path


def read_resume(run_dir, extra_draws: int | None = None) -> ResumeState:
    """Read ``run_dir/resume.npz``.

    ``extra_draws`` None continues to the stored plan (``tune + draws`` per chain); a number asks for
    that many recorded draws per chain beyond the longest chain's.
    """
    from semmap_pp.sampling import ChainRecord
    from semmap_pp.step import ChainStart

    path = Path(run_dir) / FILE_NAME
    if not Path(run_dir).is_dir():
        raise SemmapError(run_dir, "no such run directory to resume")
    if not path.is_file():
        raise SemmapError(path, "no resume file here (written by `semmap map` since this version)")
    try:
        with np.load(path, allow_pickle=False) as z:
            arrays = {k: z[k] for k in z.files}
        meta = json.loads(str(arrays["meta"]))
    except Exception as exc:   # zip, npy and JSON errors: the user needs one line
        raise SemmapError(path, f"not a readable resume file ({type(exc).__name__}: {exc})") from None
    if meta.get("format") != FORMAT:
        raise SemmapError(path, f"unknown resume format {meta.get('format')!r} (expected {FORMAT})")
    K = int(meta["capacity"])
    starts, last, history = [], [], []
    for c, info in enumerate(meta["chains"]):
        start = wm.make(arrays[f"start_rects_{c}"], arrays[f"start_active_{c}"], np.full(K, wm.NO_TYPE))
        starts.append(start)
        if info["draw"] == 0:
            last.append(start)
            history.append(None)
            continue
        stats = {k[len(f"stat_{c}_"):]: v for k, v in arrays.items() if k.startswith(f"stat_{c}_")}
        rects = arrays[f"rects_{c}"].astype(np.int32)
        active = arrays[f"active_{c}"].astype(bool)
        cs = ChainStart(info["draw"], info["n_tune"], info["rng_state"], info["knowledge_on"],
                        float(info["best_logp"]), arrays[f"best_rects_{c}"], arrays[f"best_active_{c}"])
        history.append(ChainRecord(stats, rects, active, cs))
        last.append(wm.make(rects[-1], active[-1], np.full(K, wm.NO_TYPE)))
    s = meta["settings"]
    done = [c["draw"] for c in meta["chains"]]
    if extra_draws is None:
        total = s["tune"] + s["draws"]
    else:
        total = max(max(done), s["tune"]) + extra_draws
    if max(total - d for d in done) <= 0:
        raise SemmapError(path, f"the run is complete ({s['tune']} burn-in + {s['draws']} draws per chain); "
                                "give --draws N to add N draws per chain")
    return ResumeState(path, meta, starts, last, history, total)
