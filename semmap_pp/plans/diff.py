"""The changes between two world.json files (``semmap diff OLD NEW``).

Two semantic maps of one building differ when the map grew between two runs of a robot, when a rule
file or the model file was edited, when another seed was used, or when a person edited the world by
hand (``semmap edit``). Their ids need not agree (each world.json numbers its units afresh unless
``--ids-from`` carried them), so units are paired by where they are: their rectangles in map-frame
metres (``vertices_m``, walls included), one to one, greedily from the highest intersection over
union (IoU), each pair at least :data:`MIN_IOU` (the unit matching of ``semmap stability``,
``--ids-from`` and docs/evaluation.md). The maps may differ in size and origin, as a SLAM map does
between updates while its ``map`` frame stays put.

A pair of units is

* *retyped* when the types differ (``exterior`` counts as a type: free space seen outside the
  building in one file and a unit of the building in the other);
* *moved* when some corner of either rectangle lies farther than ``tolerance_m`` from every corner
  of the other (a wall moved, grew or shrank; :attr:`UnitPair.shift_m`);

and *unchanged* otherwise. A unit of one file that pairs with none is *removed* (OLD only) or
*added* (NEW only). Doors and passages are paired when they join the paired units and their
centres lie within the wider of the two openings, and at least :data:`OPENING_TOL_M` (as
docs/evaluation.md pairs doors with the truth's); a pair whose kind differs (a door that became a
passage) is *changed*, the others are removed or added.

Pure: two :class:`~semmap_pp.plans.places.Places` in, a :class:`WorldDiff` out.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from semmap_pp.plans.places import Opening, Places, Unit, _rounded, _xy
from semmap_pp.semantic.ids import MIN_IOU, greedy_pairs, overlap_pairs

#: Two doors or passages (of paired units) are the same opening when their centres lie within the
#: wider one's width, and at least this far (metres), as the evaluation pairs doors.
OPENING_TOL_M = 1.0

#: A unit whose corners all lie within this many metres of the other's is unchanged in shape
#: (``semmap diff --tolerance``): two cells at 0.05 m, less than a wall band.
TOLERANCE_M = 0.1


@dataclass(frozen=True)
class UnitPair:
    """A unit of OLD and the unit of NEW at the same place."""

    old: Unit
    new: Unit
    iou: float

    @property
    def shift_m(self) -> float:
        """The largest distance from a corner of either rectangle to the nearest corner of the
        other (0 when both are the same rectangle)."""
        d = np.hypot(*(self.old.corners[:, None, :] - self.new.corners[None, :, :]).transpose(2, 0, 1))
        return float(max(d.min(axis=1).max(), d.min(axis=0).max()))

    @property
    def retyped(self) -> bool:
        return self.old.type != self.new.type


@dataclass(frozen=True)
class OpeningPair:
    """A door or passage of OLD and the one of NEW between the same units, ``distance_m`` apart."""

    old: Opening
    new: Opening
    distance_m: float


@dataclass(frozen=True)
class WorldDiff:
    """Units and openings of OLD and NEW, paired (:func:`diff_worlds`)."""

    old: Places
    new: Places
    pairs: tuple[UnitPair, ...]          # in OLD's order (the building's units, then exterior ones)
    removed: tuple[Unit, ...]            # OLD's units that pair with none
    added: tuple[Unit, ...]              # NEW's units that pair with none
    opening_pairs: tuple[OpeningPair, ...]
    openings_removed: tuple[Opening, ...]
    openings_added: tuple[Opening, ...]
    tolerance_m: float

    def moved(self, p: UnitPair) -> bool:
        return p.shift_m > self.tolerance_m

    @property
    def same(self) -> bool:
        """Whether the two files hold the same plan: every unit paired, none retyped or moved,
        every opening paired with one of its kind."""
        return (not self.removed and not self.added and not self.openings_removed and not self.openings_added
                and not any(p.retyped or self.moved(p) for p in self.pairs)
                and all(o.old.kind == o.new.kind for o in self.opening_pairs))

    @property
    def unit_f1(self) -> float:
        """2 x pairs / (units of OLD + units of NEW), exterior units included; 1 for two empty files."""
        n = len(self.pairs) * 2 + len(self.removed) + len(self.added)
        return 1.0 if n == 0 else 2.0 * len(self.pairs) / n

    def counts(self) -> dict:
        n_old = len(self.old.units) + len(self.old.exterior)
        n_new = len(self.new.units) + len(self.new.exterior)
        moved = sum(self.moved(p) for p in self.pairs)
        retyped = sum(p.retyped for p in self.pairs)
        unchanged = sum(not (p.retyped or self.moved(p)) for p in self.pairs)
        kinds = {k: (sum(o.kind == k for o in self.old.openings), sum(o.kind == k for o in self.new.openings))
                 for k in ("door", "passage")}
        return {"units": [n_old, n_new], "paired": len(self.pairs), "unchanged": unchanged, "moved": moved,
                "retyped": retyped, "removed": len(self.removed), "added": len(self.added),
                "unit_f1": round(self.unit_f1, 4), "doors": list(kinds["door"]),
                "passages": list(kinds["passage"]), "openings_paired": len(self.opening_pairs),
                "openings_changed": sum(o.old.kind != o.new.kind for o in self.opening_pairs),
                "openings_removed": len(self.openings_removed), "openings_added": len(self.openings_added)}

    def summary(self, old_name: str | None = None) -> str:
        """One line: how NEW differs from OLD, named ``old_name`` or by its path (``semmap map
        --ids-from`` logs it)."""
        c = self.counts()
        old_name = old_name or str(self.old.path)
        if self.same:
            return f"the same plan as {old_name} ({c['units'][1]} units)"
        openings = (f"; doors and passages: {c['openings_removed']} removed, {c['openings_added']} added"
                    + (f", {c['openings_changed']} changed kind" if c["openings_changed"] else ""))
        return (f"since {old_name}: units {c['units'][0]} -> {c['units'][1]} ({c['paired']} paired: "
                f"{c['retyped']} retyped, {c['moved']} moved; {c['removed']} removed, {c['added']} added)"
                + openings)

    def to_dict(self) -> dict:
        def unit(u: Unit) -> dict:
            length, width = u.size_m
            return {"id": u.key if u.exterior else int(u.key), "label": u.label, "type": u.type,
                    "size_m": [round(length, 4), round(width, 4)], "center_m": _rounded(u.center)}

        def opening(o: Opening, places: Places) -> dict:
            return {"kind": o.kind, "id": o.id, "units": [_label(places, k) for k in o.units],
                    "width_m": o.width_m, "center_m": _rounded(o.center)}

        return {"old": str(self.old.path), "new": str(self.new.path), "same": self.same,
                "tolerance_m": self.tolerance_m, "counts": self.counts(),
                "units": [{"old": unit(p.old), "new": unit(p.new), "iou": round(p.iou, 4),
                           "shift_m": round(p.shift_m, 4), "retyped": p.retyped, "moved": self.moved(p)}
                          for p in self.pairs],
                "removed": [unit(u) for u in self.removed], "added": [unit(u) for u in self.added],
                "openings": [{"old": opening(o.old, self.old), "new": opening(o.new, self.new),
                              "distance_m": round(o.distance_m, 4)} for o in self.opening_pairs],
                "openings_removed": [opening(o, self.old) for o in self.openings_removed],
                "openings_added": [opening(o, self.new) for o in self.openings_added]}

    def text(self, all_units: bool = False) -> str:
        """The differences as lines a person reads: two summary lines, then one line per unit or
        opening that changed (``all_units``: the unchanged pairs too)."""
        c = self.counts()
        lines = [f"{self.old.path} -> {self.new.path}",
                 f"units: {c['units'][0]} -> {c['units'][1]}; {c['paired']} paired (unit F1 {c['unit_f1']:.3f}): "
                 f"{c['unchanged']} unchanged, {c['moved']} moved, {c['retyped']} retyped; "
                 f"{c['removed']} removed, {c['added']} added",
                 f"doors: {c['doors'][0]} -> {c['doors'][1]}, passages: {c['passages'][0]} -> "
                 f"{c['passages'][1]}; {c['openings_paired']} paired ({c['openings_changed']} changed kind), "
                 f"{c['openings_removed']} removed, {c['openings_added']} added"]
        for p in self.pairs:
            what = [w for w, on in (("retyped", p.retyped), ("moved", self.moved(p))) if on]
            if not what and not all_units:
                continue
            parts = []
            if p.retyped:
                parts.append(f"{p.old.type} -> {p.new.type}")
            if self.moved(p):
                parts.append(f"{_size(p.old)} -> {_size(p.new)} m, corners up to {p.shift_m:.2f} m "
                             f"(IoU {p.iou:.2f})")
            lines.append(_line(", ".join(what) or "unchanged", f"{p.old.label} -> {p.new.label}",
                               "; ".join(parts) if parts else f"{p.new.type}, {_size(p.new)} m"))
        for verb, units in (("removed", self.removed), ("added", self.added)):
            for u in units:
                lines.append(_line(verb, u.label, f"{u.type}, {_size(u)} m, centre {_xy(u.center)}"))
        for o in self.opening_pairs:
            if o.old.kind != o.new.kind:
                lines.append(_line("changed", f"{o.old.kind} {o.old.id} -> {o.new.kind} {o.new.id}",
                                   f"{_between(self.new, o.new)}, centre {_xy(o.new.center)}"))
        for verb, openings, places in (("removed", self.openings_removed, self.old),
                                       ("added", self.openings_added, self.new)):
            for o in openings:
                lines.append(_line(verb, f"{o.kind} {o.id}",
                                   f"{_between(places, o)}, {o.width_m:.2f} m wide, centre {_xy(o.center)}"))
        if self.same:
            lines.append(f"the same plan (every unit paired, unchanged within {self.tolerance_m:g} m)")
        elif not self.pairs and self.removed and self.added:
            lines.append("no unit of one file lies where a unit of the other does: are both of the same "
                         "building, in the same map frame?")
        return "\n".join(lines)


def diff_worlds(old: Places, new: Places, *, tolerance_m: float = TOLERANCE_M,
                min_iou: float = MIN_IOU) -> WorldDiff:
    """Pair the units and openings of ``old`` and ``new`` (the module's rules)."""
    if not (math.isfinite(tolerance_m) and tolerance_m >= 0):
        raise ValueError(f"tolerance_m must be a finite number >= 0, got {tolerance_m!r}")
    a, b = (*old.units, *old.exterior), (*new.units, *new.exterior)
    overlaps = overlap_pairs([u.corners for u in a], [v.corners for v in b], path=new.path or old.path)
    matches = greedy_pairs(overlaps, min_iou)
    pairs = tuple(UnitPair(a[i], b[j], v) for i, j, v in matches)
    paired_a, paired_b = {i for i, _, _ in matches}, {j for _, j, _ in matches}
    to_new = {p.old.key: p.new.key for p in pairs}

    # openings: those joining paired units, nearest first, each within the wider width (>= 1 m)
    cands = []
    by_units: dict[frozenset, list[int]] = {}
    for j, q in enumerate(new.openings):
        by_units.setdefault(frozenset(q.units), []).append(j)
    for i, o in enumerate(old.openings):
        mapped = {to_new.get(k) for k in o.units}
        if None in mapped:
            continue
        for j in by_units.get(frozenset(mapped), ()):
            q = new.openings[j]
            d = math.dist(o.center, q.center)
            if d <= max(o.width_m, q.width_m, OPENING_TOL_M):
                cands.append((d, i, j))
    used_i, used_j, opening_pairs = set(), set(), []
    for d, i, j in sorted(cands):
        if i not in used_i and j not in used_j:
            used_i.add(i)
            used_j.add(j)
            opening_pairs.append(OpeningPair(old.openings[i], new.openings[j], d))
    opening_pairs.sort(key=lambda o: (o.old.kind, o.old.id))
    return WorldDiff(old, new, pairs,
                     tuple(u for i, u in enumerate(a) if i not in paired_a),
                     tuple(u for j, u in enumerate(b) if j not in paired_b),
                     tuple(opening_pairs),
                     tuple(o for i, o in enumerate(old.openings) if i not in used_i),
                     tuple(o for j, o in enumerate(new.openings) if j not in used_j),
                     float(tolerance_m))


def _line(verb: str, label: str, rest: str) -> str:
    """One change, in columns: what happened, to which unit or opening, and how."""
    return f"  {verb:<16}{label:<15} {rest}"


def _label(places: Places, key: str) -> str:
    return places.by_key[key].label


def _between(places: Places, o: Opening) -> str:
    return f"{_label(places, o.units[0])} - {_label(places, o.units[1])}"


def _size(u: Unit) -> str:
    length, width = u.size_m
    return f"{length:.2f} x {width:.2f}"


__all__ = ["OPENING_TOL_M", "TOLERANCE_M", "OpeningPair", "UnitPair", "WorldDiff", "diff_worlds"]
