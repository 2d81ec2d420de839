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
from semmap_pp.model import MAX_K
from semmap_pp.sampler.sampling import ChainRecord
from semmap_pp.sampler.sampling import MAX_N_INNER, MAX_SEED

FORMAT = "semmap_pp.resume/1"
FILE_NAME = "resume.npz"
#: R-hat and ESS need at least this many draws per chain.
MIN_DRAWS = 4
#: Bounds of the settings a resume file may hold: ``semmap map``'s own where it has them
#: (:mod:`semmap_pp.sampler.sampling`, which :mod:`semmap_pp.cli.argtypes` applies), else far beyond
#: any run (a billion draws of one kernel take days).
MAX_COUNT = 10 ** 9
MAX_CHAINS = 10_000
_SETTINGS = {"chains": (1, MAX_CHAINS), "cores": (1, MAX_CHAINS), "tune": (0, MAX_COUNT),
             "draws": (1, MAX_COUNT), "n_inner": (1, MAX_N_INNER), "seed": (0, MAX_SEED),
             "spread_draws": (0, MAX_COUNT), "spread_n_inner": (1, MAX_N_INNER)}
_OPTIONAL_SETTINGS = ("spread_draws", "spread_n_inner")      # older files: RunSettings' defaults
_MAP_OPTIONS = {"occupied_thresh": float, "free_thresh": float, "negate": int, "resolution": float,
                "mode": str, "max_cells": int, "allow_outside": bool, "topic": str, "at": float}
_MAP_OPTION_MIN = {"max_cells": 1, "at": 0}       # a bag's --at: seconds since its start, or "last"


def merge_records(history, new) -> list:
    """Per chain, the earlier real draws followed by the new ones (``ChainRecord`` lists)."""

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
        types = None if old.types is None or rec.types is None else np.concatenate([old.types, rec.types])
        out.append(ChainRecord(stats, np.concatenate([old.rects, rec.rects]),
                               np.concatenate([old.active, rec.active]), rec.last, types))
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
        from semmap_pp.sampler.step import ChainStart  # step imports PyMC (about 1 s): not at import

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
    """Write ``out_dir/resume.npz`` atomically from a :class:`~semmap_pp.run.results.MapRun`."""
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
    from semmap_pp.sampler.step import ChainStart  # step imports PyMC (about 1 s): not at import

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
    if not isinstance(meta, dict) or meta.get("format") != FORMAT:
        shown = _brief(meta.get("format") if isinstance(meta, dict) else meta)
        raise SemmapError(path, f"unknown resume format {shown} (expected {FORMAT})")
    check_resume(meta, arrays, path)
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


def _brief(x) -> str:
    text = repr(x)
    return text if len(text) <= 40 else text[:36] + "..."


def _integer(path, where: str, v, lo: int, hi: int) -> int:
    if isinstance(v, bool) or not isinstance(v, int) or not lo <= v <= hi:
        raise SemmapError(path, f"{where} must be an integer from {lo} to {hi}, got {_brief(v)}")
    return v


def _array(path, arrays: dict, name: str, kinds: str, shape: tuple) -> np.ndarray:
    """``arrays[name]``, refused unless its dtype kind is one of ``kinds`` and its shape is
    ``shape`` (None: any length there)."""
    if name not in arrays:
        raise SemmapError(path, f"the array {name} is missing")
    a = arrays[name]
    if a.dtype.kind not in kinds or a.ndim != len(shape) or any(
            n is not None and m != n for m, n in zip(a.shape, shape)):
        want = " x ".join("n" if n is None else str(n) for n in shape) or "a scalar"
        raise SemmapError(path, f"the array {name} is {a.dtype} of shape {a.shape}; expected "
                                f"{'integers' if kinds == 'iu' else 'booleans' if kinds == 'b' else 'numbers'} "
                                f"of shape {want}")
    return a


def check_resume(meta: dict, arrays: dict, path) -> None:
    """Refuse, naming ``path`` and the key, a resume file whose settings, chains or arrays are not
    of the type, range and shape :func:`write_resume` writes: a seed beyond :data:`MAX_SEED`, a
    count that is not an integer, a random state numpy does not take, a world array of the wrong
    dtype or size, a rectangle beyond the lattice. Checked before anything is sampled."""
    settings = meta.get("settings")
    known = set(_SETTINGS) | {"anneal"}
    needed = known - set(_OPTIONAL_SETTINGS)
    if not isinstance(settings, dict):
        raise SemmapError(path, f"settings must be an object, got {_brief(settings)}")
    for key in sorted(needed - set(settings)):
        raise SemmapError(path, f"settings.{key} is missing")
    for key in sorted(set(settings) - known, key=str):
        raise SemmapError(path, f"settings.{_brief(key)[1:-1]} is not a setting of this version "
                                f"({', '.join(sorted(known))})")
    for key, (lo, hi) in _SETTINGS.items():
        if key in settings:
            _integer(path, f"settings.{key}", settings[key], lo, hi)
    a = settings["anneal"]
    if isinstance(a, bool) or not isinstance(a, (int, float)) or not (math.isfinite(a) and a >= 1.0):
        raise SemmapError(path, f"settings.anneal must be a number of at least 1, got {_brief(a)}")

    K = _integer(path, "capacity", meta.get("capacity"), 1, MAX_K)
    inputs = meta.get("inputs")
    if not isinstance(inputs, dict) or not isinstance(inputs.get("map"), str):
        raise SemmapError(path, "inputs.map must be the map's file name")
    for key in ("model", "rules", "roi"):
        if inputs.get(key) is not None and not isinstance(inputs[key], str):
            raise SemmapError(path, f"inputs.{key} must be a file name or null, got {_brief(inputs[key])}")
    options = inputs.get("map_options")
    if not isinstance(options, dict) or not set(options) <= set(_MAP_OPTIONS):
        raise SemmapError(path, f"inputs.map_options must be an object of {', '.join(_MAP_OPTIONS)}")
    for key, kind in _MAP_OPTIONS.items():
        v = options.get(key)
        if v is None or (key == "at" and v == "last"):
            continue
        ok = (isinstance(v, kind) if kind in (str, bool) else
              not isinstance(v, bool) and isinstance(v, (int, float) if kind is float else int)
              and math.isfinite(v) and v >= _MAP_OPTION_MIN.get(key, -math.inf))
        if not ok:
            raise SemmapError(path, f"inputs.map_options.{key} must be {kind.__name__} or null, got {_brief(v)}")
    lattice = inputs.get("lattice")
    if lattice is not None:
        if not (isinstance(lattice, list) and len(lattice) == 2
                and all(not isinstance(n, bool) and isinstance(n, int) and 1 <= n <= 10 ** 9 for n in lattice)):
            raise SemmapError(path, f"inputs.lattice must be two positive integers, got {_brief(lattice)}")
    chains = meta.get("chains")
    if not isinstance(chains, list) or len(chains) != settings["chains"]:
        raise SemmapError(path, f"chains must list one entry per chain (settings.chains = "
                                f"{settings['chains']}), got {len(chains) if isinstance(chains, list) else _brief(chains)}")
    for c, info in enumerate(chains):
        where = f"chains[{c}]"
        if not isinstance(info, dict):
            raise SemmapError(path, f"{where} must be an object")
        draw = _integer(path, f"{where}.draw", info.get("draw"), 0, 2 * MAX_COUNT)
        _integer(path, f"{where}.n_tune", info.get("n_tune"), 0, MAX_COUNT)
        if not isinstance(info.get("knowledge_on"), bool):
            raise SemmapError(path, f"{where}.knowledge_on must be true or false, got {_brief(info.get('knowledge_on'))}")
        worlds = [(f"start_rects_{c}", _array(path, arrays, f"start_rects_{c}", "iu", (K, 4)),
                   _array(path, arrays, f"start_active_{c}", "b", (K,)))]
        if draw > 0:
            worlds += _chain_arrays(path, arrays, c, info, draw, K)
        if lattice is not None:
            for name, r, on in worlds:
                r = r[on]
                if r.size and not (np.all(r[:, :2] >= 0) and np.all(r[:, 2] <= lattice[0])
                                   and np.all(r[:, 3] <= lattice[1]) and np.all(r[:, 2:] > r[:, :2])):
                    raise SemmapError(path, f"{name} holds a unit that is not a rectangle of the run's "
                                            f"lattice ({lattice[0]} x {lattice[1]} cells)")


def _chain_arrays(path, arrays: dict, c: int, info: dict, draw: int, K: int) -> list:
    """Check what chain ``c`` of a resume file that made ``draw`` draws holds beyond its start;
    returns its worlds ``(name, rects, active)`` for the lattice check."""
    where = f"chains[{c}]"
    best = info.get("best_logp")
    ok = (not isinstance(best, bool) and isinstance(best, (int, float)) and not math.isnan(best)) \
        or best in ("inf", "-inf")        # write_resume's spelling of an infinite one
    if not ok:
        raise SemmapError(path, f"{where}.best_logp must be a number, got {_brief(best)}")
    try:
        np.random.PCG64().state = info.get("rng_state")
    except (TypeError, ValueError, KeyError, OverflowError, AttributeError) as exc:
        raise SemmapError(path, f"{where}.rng_state is not a random state numpy takes ({exc})") from None
    rects = _array(path, arrays, f"rects_{c}", "iu", (None, K, 4))
    n = rects.shape[0]
    if n < 1:
        raise SemmapError(path, f"{where} made {draw} draws but rects_{c} holds none")
    active = _array(path, arrays, f"active_{c}", "b", (n, K))
    for stat in ("logp", "burn_in"):
        if f"stat_{c}_{stat}" not in arrays:
            raise SemmapError(path, f"the array stat_{c}_{stat} is missing")
    for name in [k for k in arrays if k.startswith(f"stat_{c}_")]:
        _array(path, arrays, name, "iufb", (n,))
    return [(f"rects_{c}", rects.reshape(-1, 4), active.reshape(-1)),
            (f"best_rects_{c}", _array(path, arrays, f"best_rects_{c}", "iu", (K, 4)),
             _array(path, arrays, f"best_active_{c}", "b", (K,)))]

