"""Whether W* is reproducible: the same map searched with several seeds (``semmap stability``).

The chains of one run do not mix (docs/sampler.md, "Chains in separate modes"), so R-hat and ESS
cannot say which parts of W* to trust. What a user can check instead is whether independent
searches end in the same plan. Pure functions over the W*s of runs that share a map, a model and
a rule file (so one lattice):

* units are matched between two W*s one to one, by intersection over union of their rectangles
  on the lattice (walls included), greedily from the best pair, a match at IoU >= ``MATCH_IOU``
  (0.5, the unit matching of docs/evaluation.md);
* :func:`unit_agreement`: for every unit of the reference W* (the one of highest log posterior),
  in how many of the other W*s a unit matches it, in how many of those with the same type, and
  the mean IoU of its matches;
* :func:`pairwise_f1`: unit F1 between every two W*s (2 x matches / (units + units)), 1 when
  both are the same plan.

Examples
--------
>>> a = [(0, 0, 10, 10), (0, 10, 10, 20)]
>>> b = [(0, 0, 10, 11), (0, 11, 10, 20), (20, 0, 30, 5)]
>>> [(i, j, round(v, 2)) for i, j, v in match_units(a, b)]
[(0, 0, 0.91), (1, 1, 0.9)]
>>> round(unit_f1(a, b), 3)
0.8
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: the least IoU of two rectangles that counts as the same unit
MATCH_IOU = 0.5


def iou_matrix(a, b) -> np.ndarray:
    """IoU (len(a), len(b)) of rectangles ``(r0, c0, r1, c1)`` (half-open lattice boxes)."""
    a = np.asarray(a, dtype=np.float64).reshape(-1, 4)
    b = np.asarray(b, dtype=np.float64).reshape(-1, 4)
    h = np.clip(np.minimum(a[:, None, 2], b[None, :, 2]) - np.maximum(a[:, None, 0], b[None, :, 0]), 0, None)
    w = np.clip(np.minimum(a[:, None, 3], b[None, :, 3]) - np.maximum(a[:, None, 1], b[None, :, 1]), 0, None)
    inter = h * w
    area_a = (a[:, 2] - a[:, 0]) * (a[:, 3] - a[:, 1])
    area_b = (b[:, 2] - b[:, 0]) * (b[:, 3] - b[:, 1])
    union = area_a[:, None] + area_b[None, :] - inter
    return np.divide(inter, union, out=np.zeros_like(inter), where=union > 0)


def match_units(a, b, min_iou: float = MATCH_IOU) -> list[tuple[int, int, float]]:
    """One-to-one matches ``(i, j, iou)`` between the rectangles ``a`` and ``b``, greedily from
    the highest IoU (ties: the lower indices first), each at least ``min_iou``; sorted by ``i``."""
    return greedy_matches(iou_matrix(a, b), min_iou)


def greedy_matches(iou: np.ndarray, min_iou: float = MATCH_IOU) -> list[tuple[int, int, float]]:
    """One-to-one matches ``(i, j, iou[i, j])`` of the rows and columns of an IoU matrix, greedily
    from the highest value (ties: the lower indices first), each at least ``min_iou``; sorted by
    ``i`` (:func:`match_units`, and ``semmap diff``'s units in map metres).

    >>> greedy_matches(np.array([[0.9, 0.6], [0.7, 0.2]]))
    [(0, 0, 0.9)]
    """
    iou = np.asarray(iou, dtype=np.float64)
    if iou.size == 0:
        return []
    out, used_a, used_b = [], set(), set()
    order = np.argsort(-iou, axis=None, kind="stable")
    for k in order.tolist():
        i, j = divmod(k, iou.shape[1])
        if iou[i, j] < min_iou:
            break
        if i in used_a or j in used_b:
            continue
        used_a.add(i)
        used_b.add(j)
        out.append((i, j, float(iou[i, j])))
    return sorted(out)


def unit_f1(a, b, min_iou: float = MATCH_IOU) -> float:
    """Unit F1 of two sets of rectangles: 2 x matches / (len(a) + len(b)); 1 when both are empty."""
    n = len(a) + len(b)
    return 1.0 if n == 0 else 2.0 * len(match_units(a, b, min_iou)) / n


@dataclass(frozen=True)
class SeedPlan:
    """The building units of one W*: ids (as world.json numbers them), lattice rectangles and
    types, with the run's seed, log posterior and CPR."""

    seed: int
    ids: tuple
    rects: tuple          # (r0, c0, r1, c1) per unit, lattice cells
    types: tuple          # type name per unit
    log_posterior: float
    cpr: float
    seconds: float = float("nan")
    vertices_m: tuple = ()   # per unit, its four corners in the map frame (metres), as world.json

    @classmethod
    def from_semantic(cls, seed: int, sm, seconds: float = float("nan")) -> "SeedPlan":
        """The plan of a :class:`~semmap_pp.semantic.semantic_map.SemanticMap` (exterior units left out)."""
        ids = sm.unit_ids
        rects = tuple(tuple(int(v) for v in sm.world.rects[sm.slot_of(u)]) for u in ids)
        corners = tuple(tuple((round(float(x), 4), round(float(y), 4)) for x, y in sm.frame.rect_vertices_m(r))
                        for r in rects)
        return cls(seed, tuple(ids), rects, tuple(sm.type_of(u) for u in ids),
                   float(sm.log_posterior), float(sm.cpr), float(seconds), corners)


@dataclass(frozen=True)
class UnitAgreement:
    """One unit of the reference W*: matched in ``found`` of ``others`` W*s, with the same type
    in ``same_type`` of them; ``mean_iou`` over its matches (NaN without one)."""

    id: int
    type: str
    found: int
    same_type: int
    others: int
    mean_iou: float

    @property
    def agreed(self) -> bool:
        """Whether every other W* holds this unit, with its type."""
        return self.found == self.others and self.same_type == self.others


def unit_agreement(ref: SeedPlan, others: list[SeedPlan]) -> list[UnitAgreement]:
    """:class:`UnitAgreement` of every unit of ``ref`` against the plans ``others``."""
    hits = [[] for _ in ref.ids]
    for other in others:
        for i, j, v in match_units(ref.rects, other.rects):
            hits[i].append((v, other.types[j] == ref.types[i]))
    return [UnitAgreement(u, t, len(h), sum(s for _, s in h), len(others),
                          float(np.mean([v for v, _ in h])) if h else float("nan"))
            for u, t, h in zip(ref.ids, ref.types, hits)]


def pairwise_f1(plans: list[SeedPlan]) -> np.ndarray:
    """Unit F1 (n, n) between every two plans (symmetric, 1 on the diagonal)."""
    n = len(plans)
    f = np.ones((n, n))
    for i in range(n):
        for j in range(i + 1, n):
            f[i, j] = f[j, i] = unit_f1(plans[i].rects, plans[j].rects)
    return f


@dataclass(frozen=True)
class Stability:
    """The whole comparison: the plans in seed order, the reference's index (highest log
    posterior), its units' agreement and the pairwise unit F1."""

    plans: tuple
    ref: int
    units: tuple
    f1: np.ndarray

    @classmethod
    def of(cls, plans: list[SeedPlan]) -> "Stability":
        if len(plans) < 2:
            raise ValueError("stability needs the W*s of at least two seeds")
        ref = int(np.argmax([p.log_posterior for p in plans]))
        others = plans[:ref] + plans[ref + 1:]
        return cls(tuple(plans), ref, tuple(unit_agreement(plans[ref], others)), pairwise_f1(plans))

    @property
    def reference(self) -> SeedPlan:
        return self.plans[self.ref]

    @property
    def others(self) -> tuple:
        """The plans other than the reference, in seed order."""
        return self.plans[:self.ref] + self.plans[self.ref + 1:]

    def stable_units(self) -> int:
        """Units of the reference W* found, with the same type, in every other W*."""
        return sum(u.agreed for u in self.units)

    def mean_f1(self) -> float:
        """Mean unit F1 over the pairs of different seeds."""
        n = len(self.plans)
        return float(self.f1[np.triu_indices(n, 1)].mean())

    def table(self) -> str:
        """Markdown: the runs, the pairwise unit F1, and the reference's units."""
        ref = self.reference
        lines = ["| seed | units | CPR | log posterior | seconds |", "|---:|---:|---:|---:|---:|"]
        for k, p in enumerate(self.plans):
            mark = " (reference)" if k == self.ref else ""
            lines.append(f"| {p.seed}{mark} | {len(p.ids)} | {p.cpr:.4f} | {p.log_posterior:.1f} | "
                         f"{p.seconds:.1f} |")
        lines += ["", "unit F1 between the W*s (IoU >= 0.5):", "",
                  "| seed | " + " | ".join(str(p.seed) for p in self.plans) + " |",
                  "|---:|" + "---:|" * len(self.plans)]
        for p, row in zip(self.plans, self.f1):
            lines.append(f"| {p.seed} | " + " | ".join(f"{v:.3f}" for v in row) + " |")
        n_other = len(self.plans) - 1
        lines += ["", f"units of the reference W* (seed {ref.seed}; ids as its world.json): found in the "
                  f"other {n_other} W*(s), with the same type, mean IoU of the matches:", "",
                  "| unit | type | size (cells) | found | same type | mean IoU |",
                  "|---:|---|---|---:|---:|---:|"]
        for u, r in zip(self.units, ref.rects):
            iou = "-" if np.isnan(u.mean_iou) else f"{u.mean_iou:.3f}"
            lines.append(f"| {u.id} | {u.type} | {r[2] - r[0]} x {r[3] - r[1]} | {u.found}/{u.others} | "
                         f"{u.same_type}/{u.others} | {iou} |")
        lines += ["", f"{self.stable_units()} of {len(ref.ids)} units found with the same type in every "
                  f"other W*; mean unit F1 between seeds {self.mean_f1():.3f}"]
        return "\n".join(lines)

    def to_dict(self) -> dict:
        """Every number, JSON-ready (NaN as None)."""
        def num(v):
            return None if isinstance(v, float) and np.isnan(v) else v
        ref_m = self.reference.vertices_m
        return {
            "format": "semmap_pp.stability/1",
            "match_iou": MATCH_IOU,
            "reference_seed": self.reference.seed,
            "runs": [{"seed": p.seed, "units": len(p.ids), "cpr": num(p.cpr),
                      "log_posterior": p.log_posterior, "seconds": num(p.seconds)} for p in self.plans],
            "unit_f1": [[float(v) for v in row] for row in self.f1],
            "mean_unit_f1": self.mean_f1(),
            "stable_units": self.stable_units(),
            "units": [{"id": u.id, "type": u.type, "rect_cells": list(r),
                       "vertices_m": [list(v) for v in ref_m[k]] if ref_m else None, "found": u.found,
                       "same_type": u.same_type, "others": u.others, "mean_iou": num(u.mean_iou)}
                      for k, (u, r) in enumerate(zip(self.units, self.reference.rects))],
        }


__all__ = ["MATCH_IOU", "iou_matrix", "match_units", "unit_f1", "SeedPlan", "UnitAgreement",
           "unit_agreement", "pairwise_f1", "Stability"]
