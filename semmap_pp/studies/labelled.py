"""Labelled examples for :mod:`semmap_pp.knowledge.learn`: a world's evidence with true types.

A labelled example is a text file: the evidence facts ``semmap rules evidence`` writes for a
world (units, geometry classes, MulDoor, adjacency) followed by

* ``label(U, T).``: unit U's true type, T one of room, corridor, hall, other;
* optionally ``cells(U, T, N).``: N truth cells of type T lie in unit U, and ``uncovered(T, N).``:
  N truth cells of type T lie in no unit (what a per-cell score needs).

This module makes the label part from

* a per-cell type image (:func:`cell_counts`): each unit takes the majority type of its labelled
  cells (:func:`majority_labels`; a unit with none stays unlabelled, its type summed out when
  learning);
* a world.json's own ``type`` fields (:func:`world_labels`), e.g. after a user corrected them;
* a synthetic floor's truth (:func:`synthetic_example`): its seen true units as the world, their
  true types as labels.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from semmap_pp.cells import UNIT_TYPES
from semmap_pp.errors import MapError, SemmapError
from semmap_pp.evaluate.io import grey, read_image
from semmap_pp.lattice.tiles import building_frame
from semmap_pp.grid import OccupancyGrid
from semmap_pp.knowledge.evidence import evidence_to_facts
from semmap_pp.model import load_model
from semmap_pp.target.posterior import Posterior
from semmap_pp.synth import generate_floor
from semmap_pp.plans.world_file import pack_world
from semmap_pp.knowledge import Evidence
from semmap_pp.knowledge.dialect import SOFT_PREDICATES

#: The grey values of the ipa place-type images (``/work/shared/data/ipa-types/training_*.png``):
#: 77 room, 115 corridor; every other value (doorway 179, obstacle 0) labels nothing. The ipa
#: truth knows rooms and corridors only, and its score reads a hall or an *other* as a room
#: (:mod:`semmap_pp.evaluate.types`), so its room is the label set room | hall | other.
IPA_VALUES = {77: ("room", "hall", "other"), 115: ("corridor",)}


def parse_values(text: str) -> dict:
    """``"77=room|hall|other,115=corridor"`` as ``{77: ("room", "hall", "other"), 115:
    ("corridor",)}``: a grey value's cells are of one of the types named (the first one is the
    type their cells are counted as).

    >>> parse_values("77=room|other, 115=corridor")
    {77: ('room', 'other'), 115: ('corridor',)}
    """
    out = {}
    for part in text.split(","):
        if not part.strip():
            continue
        grey, sep, name = part.partition("=")
        names = tuple(n.strip() for n in name.split("|"))
        try:
            value = int(grey)
        except ValueError:
            value = None
        if (not sep or value is None or not 0 <= value <= 65535
                or not all(n in UNIT_TYPES for n in names) or len(set(names)) != len(names)):
            raise SemmapError(None, f"--truth-values takes GREY=TYPE pairs (TYPE one of "
                                    f"{', '.join(UNIT_TYPES)}, or several joined by |), got "
                                    f"{part.strip()!r}")
        out[value] = names
    if not out:
        raise SemmapError(None, "--truth-values names no GREY=TYPE pair")
    return out


def read_truth_image(path, values: dict, shape=None) -> np.ndarray:
    """A per-cell type image as type indices (``UNIT_TYPES``; a grey value's first type), -1
    where its grey value is not one of ``values``; its size must be ``shape`` (the map's) when
    given."""
    image = read_image(path)
    if image.ndim == 3:
        image = np.rint(grey(image)).astype(np.int64)
    image = np.asarray(image).astype(np.int64)
    if shape is not None and image.shape != tuple(shape):
        raise MapError(path, f"the type image is {image.shape[1]} x {image.shape[0]} pixels, the "
                             f"map {shape[1]} x {shape[0]}")
    out = np.full(image.shape, -1, np.int8)
    for grey_value, names in values.items():
        out[image == grey_value] = UNIT_TYPES.index(names[0])
    if not (out >= 0).any():
        raise MapError(path, f"no pixel has one of the grey values {sorted(values)}")
    return out


def cell_counts(unit_image: np.ndarray, truth: np.ndarray, units) -> tuple[dict, np.ndarray]:
    """Truth cells of each type per unit: ``({unit: counts (4,)}, uncovered (4,))`` for the
    unit ids ``units`` of ``unit_image`` (0 none; ids not in ``units`` count as none)."""
    units = [int(u) for u in units]
    ids = np.asarray(unit_image, np.int64)
    t = np.asarray(truth, np.int64)
    keep = t >= 0
    lut = np.zeros(int(max(ids.max(initial=0), max(units, default=0))) + 1, np.int64)
    for k, u in enumerate(units, 1):
        lut[u] = k
    slot = lut[ids[keep]]
    table = np.zeros((len(units) + 1, 4), np.int64)
    np.add.at(table, (slot, t[keep]), 1)
    return {u: table[k] for k, u in enumerate(units, 1)}, table[0]


def majority_labels(counts: dict, values: dict | None = None) -> dict:
    """Unit -> the label set (type indices) of the type most of its labelled cells have (the
    first of ``UNIT_TYPES`` on a tie): that type's set in ``values`` (grey -> type names, as
    :func:`parse_values` gives; default the type alone). Units without a labelled cell are left
    out."""
    sets = {UNIT_TYPES.index(n[0]): tuple(sorted(UNIT_TYPES.index(m) for m in n))
            for n in (values or {}).values()}
    return {u: sets.get(int(np.argmax(c)), (int(np.argmax(c)),))
            for u, c in counts.items() if c.sum() > 0}


def world_labels(world_path) -> dict:
    """Unit id -> (type index,) from a world.json's ``type`` fields (units without one left
    out)."""
    doc = json.loads(Path(world_path).read_text(encoding="utf-8"))
    out = {}
    for u in doc.get("units", []):
        if isinstance(u, dict) and u.get("type") in UNIT_TYPES and isinstance(u.get("id"), int):
            out[u["id"]] = (UNIT_TYPES.index(u["type"]),)
    return out


def label_facts(labels: dict, counts: dict | None = None, uncovered=None, comment: str = "") -> str:
    """The label part of a labelled example (see the module docstring)."""
    lines = [f"% {comment}"] if comment else []
    for u in sorted(labels):
        lines.append(" ".join(f"label({u}, {UNIT_TYPES[t]})." for t in labels[u]))
    for u in sorted(counts or {}):
        for k, n in enumerate(counts[u]):
            if n:
                lines.append(f"cells({u}, {UNIT_TYPES[k]}, {int(n)}).")
    if uncovered is not None:
        for k, n in enumerate(uncovered):
            if n:
                lines.append(f"uncovered({UNIT_TYPES[k]}, {int(n)}).")
    return "\n".join(lines) + "\n"


def synthetic_example(seed: int, model=None) -> str:
    """The labelled example of synthetic floor ``seed`` (:func:`semmap_pp.synth.generate_floor`):
    the true units the simulated robot saw, each as the lattice rectangle enclosing it, are the
    world; the evidence is what the engine computes for that world on the floor's map (the same
    code as for any world); the labels are the truth's types, and the cells of each unit's
    rectangle are counted as its true type."""

    model = model or load_model(None)
    floor = generate_floor(int(seed))
    grid = OccupancyGrid(floor.classes, np.zeros(floor.classes.shape, np.float32),
                         floor.resolution, source=Path(f"synth-{seed}"))
    frame = building_frame(grid, model)
    seen = [u for u in floor.truth["units"] if u.get("explored", True)]
    rects = [frame.rect_from_vertices_px(u["corners_px"])[0] for u in seen]
    world = pack_world(rects, model.prior.k_max)
    ev = Posterior(frame, model, None).knowledge_evidence(world)
    # the evidence numbers units by world slot: unit k + 1 is seen[k]
    relabel = {name: {u + 1: p for u, p in ev.unary(name)} for name in SOFT_PREDICATES}
    ev = Evidence.build([u + 1 for u in ev.units], adj=[(p + 1, q + 1) for p, q in ev.adj],
                        **relabel)
    labels = {k + 1: (UNIT_TYPES.index(u["type"]),) for k, u in enumerate(seen)}
    counts = {}
    for k, (r0, c0, r1, c1) in enumerate(rects):
        c = np.zeros(4, np.int64)
        c[labels[k + 1][0]] = (int(r1) - int(r0)) * (int(c1) - int(c0))
        counts[k + 1] = c
    head = (f"% synthetic floor {seed} (semmap_pp.synth.generate_floor): its {len(seen)} seen true "
            f"units as the world, the evidence the engine computes for it (model "
            f"{Path(model.path).name}), the true types as labels\n")
    return head + evidence_to_facts(ev) + label_facts(labels, counts, comment="true types")
