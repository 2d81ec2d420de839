"""Posterior spread per cell: sampled worlds rasterised on the lattice and counted with
:class:`~semmap_pp.sampler.diagnostics.SpreadAccumulator`.

A world's wall cells are the wall bands of its units; the type of a cell is that of the unit it
belongs to (walls included; a unit's interior wins over another's wall band, as in labels.png).
Only the box that some sampled unit touches is accumulated, then placed back on the lattice.

Examples
--------
>>> from semmap_pp import world as wm
>>> a = wm.add(wm.empty(2), 0, (0, 0, 4, 4), type_index=0)
>>> b = wm.add(wm.empty(2), 0, (0, 0, 4, 6), type_index=1)
>>> p_wall, p_type = cell_probabilities((4, 8), [a, b], wall=1)
>>> p_wall[0].tolist()
[1.0, 1.0, 1.0, 1.0, 0.5, 0.5, 0.0, 0.0]
>>> p_type[0][2].tolist(), p_type[1][2].tolist()
([0.5, 0.5, 0.5, 0.5, 0.0, 0.0, 0.0, 0.0], [0.5, 0.5, 0.5, 0.5, 0.5, 0.5, 0.0, 0.0])

Two numbers summarise the spread of the wall indicator over the sampled worlds:

* :meth:`~semmap_pp.sampler.diagnostics.SpreadAccumulator.wall_spread`: the *mean* of ``p (1 - p)`` over the
  cells that are ever wall. Its denominator is a property of the run (how many cells some world
  ever put a wall on), so two runs are not measured on the same cells, and a rare excursion (a
  cell walled in 1 world of 1000, ``p (1 - p)`` near 0) *lowers* it: more exploration can read as
  less spread;
* :func:`wall_disagreement_m2`: the *sum* of ``2 p (1 - p)`` times the cell area, the expected area
  on which two independently drawn worlds disagree about wall or not. Cells that are never or
  always wall add nothing, so no denominator is needed and runs on one map compare directly
  (the per-cell picture of the paper's Fig. 7: thin lines of many samples).

>>> round(wall_disagreement_m2(p_wall, resolution=0.5), 3)   # 8 cells at p = 0.5: 8 * 0.5 * 0.25 m²
1.0
"""

from __future__ import annotations

import numpy as np

from semmap_pp import world as wm
from semmap_pp.cells import UNIT_TYPES
from semmap_pp.sampler.diagnostics import SpreadAccumulator


def _clip(rect, box):
    r0, c0, r1, c1 = (int(v) for v in rect)
    b0, d0, b1, d1 = box
    return max(r0, b0) - b0, max(c0, d0) - d0, min(r1, b1) - b0, min(c1, d1) - d0


def rasterise(world: wm.World, box, wall: int) -> tuple[np.ndarray, np.ndarray]:
    """Wall mask and type index (-1 none) of ``world`` over the lattice ``box`` ``(r0, c0, r1, c1)``."""
    shape = (box[2] - box[0], box[3] - box[1])
    band = np.zeros(shape, np.int16)    # units with the cell in their wall band
    tidx = np.full(shape, -1, np.int8)
    slots = wm.active_slots(world)
    inner = {}
    for s in slots:  # whole rectangles first: every cell of a unit takes its type ...
        r0, c0, r1, c1 = (int(v) for v in world.rects[s])
        a0, b0, a1, b1 = _clip((r0, c0, r1, c1), box)
        if a0 < a1 and b0 < b1:
            band[a0:a1, b0:b1] += 1
            tidx[a0:a1, b0:b1] = world.types[s]
            inner[s] = _clip((r0 + wall, c0 + wall, r1 - wall, c1 - wall), box)
    for s, (i0, j0, i1, j1) in inner.items():  # ... then interiors win over another unit's wall band
        if i0 < i1 and j0 < j1:
            band[i0:i1, j0:j1] -= 1
            tidx[i0:i1, j0:j1] = world.types[s]
    # a band cell is wall even inside another unit's interior (as derive.states.cell_states)
    return band > 0, tidx


def sampled_box(worlds, shape) -> tuple[int, int, int, int]:
    """The lattice box ``(r0, c0, r1, c1)`` every unit of every world lies in, clipped to ``shape``."""
    rects = [w.rects[w.active] for w in worlds]
    rects = np.concatenate(rects) if rects else np.zeros((0, 4), int)
    if len(rects) == 0:
        return 0, 0, 0, 0
    return (max(int(rects[:, 0].min()), 0), max(int(rects[:, 1].min()), 0),
            min(int(rects[:, 2].max()), shape[0]), min(int(rects[:, 3].max()), shape[1]))


def accumulate(worlds, shape, wall: int) -> tuple[SpreadAccumulator, tuple[int, int, int, int]]:
    """Typed ``worlds`` counted on the lattice box they lie in (:func:`sampled_box`), and the box.
    A world repeated in ``worlds`` (a chain that stayed put: most draws near W*) is rasterised once
    and counted as often as it occurs, which gives the same counts."""
    box = sampled_box(worlds, shape)
    # a count is at most the number of worlds: uint16 holds it exactly below 65,536 worlds
    acc = SpreadAccumulator((box[2] - box[0], box[3] - box[1]),
                            dtype=np.uint16 if len(worlds) < 2 ** 16 else np.int32)
    counts: dict[bytes, list] = {}
    for w in worlds:
        key = w.rects.tobytes() + w.active.tobytes() + w.types.tobytes()
        if key in counts:
            counts[key][1] += 1
        else:
            counts[key] = [w, 1]
    for w, n in counts.values():
        acc.add(*rasterise(w, box, wall), count=n)
    return acc, box


def cell_probabilities(shape, worlds, wall: int) -> tuple[np.ndarray, np.ndarray]:
    """Per-cell p(wall) (H', W') and p(type) (4, H', W') on the lattice over typed ``worlds``."""
    acc, box = accumulate(worlds, shape, wall)
    p_wall = np.zeros(shape)
    p_type = np.zeros((len(UNIT_TYPES),) + tuple(shape))
    if worlds:   # one channel at a time (acc.p_type() of every channel at once: 4 float64 boxes)
        n = max(acc.n, 1)
        p_wall[box[0]:box[2], box[1]:box[3]] = acc.wall / n
        for k in range(len(UNIT_TYPES)):
            p_type[k, box[0]:box[2], box[1]:box[3]] = acc.types[k] / n
    return p_wall, p_type


def wall_disagreement_m2(p_wall: np.ndarray, resolution: float) -> float:
    """Expected area (m²) where two independent sampled worlds disagree on wall: ``Σ 2p(1-p) · res²``.

    ``p_wall`` is the per-cell wall probability on the lattice (:func:`cell_probabilities`),
    ``resolution`` metres per lattice cell. 0 when every world has the same walls.
    """
    p = np.asarray(p_wall, dtype=float)
    return float(np.sum(2.0 * p * (1.0 - p)) * resolution * resolution)


def typed_worlds(posterior, worlds) -> list[wm.World]:
    """``worlds`` with types from ``posterior`` (the MAP types the sampler used); repeats typed
    once, and a world whose units all have a type already (the sampler's) kept as it is."""
    cache: dict[bytes, np.ndarray] = {}
    out = []
    for w in worlds:
        if (np.asarray(w.types)[np.asarray(w.active, bool)] != wm.NO_TYPE).all():
            out.append(w)
            continue
        key = w.rects.tobytes() + w.active.tobytes()
        if key not in cache:
            cache[key] = np.asarray(posterior.typing(w).world.types)
        out.append(wm.with_types(w, cache[key]))
    return out


__all__ = ["rasterise", "sampled_box", "cell_probabilities", "wall_disagreement_m2", "typed_worlds"]
