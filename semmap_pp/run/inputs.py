"""A run's inputs read from disk and checked before any work: the map, the model, the rules, the
region of interest (:func:`load_inputs`), and a run's outputs kept off its own inputs."""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from semmap_pp.errors import MapError, ModelError, SemmapError
from semmap_pp.evaluate import closing_radius_cells, default_roi, load_roi
from semmap_pp.grid import MAX_CELLS, OccupancyGrid, load_map
from semmap_pp.grid.outside import clear_outside
from semmap_pp.knowledge import load_rules
from semmap_pp.lattice.frame import Frame, off_axis_note
from semmap_pp.lattice.tiles import building_frame, rect_spans
from semmap_pp.model import Model, load_model
from semmap_pp.resources import DEFAULT_RULES


@dataclass(frozen=True)
class Inputs:
    """Everything read from disk, validated, before any sampling."""

    grid: OccupancyGrid
    model: Model
    rules: object | None      # knowledge.RuleSet, or None for no knowledge engine at all
    frame: Frame
    roi: np.ndarray           # (H, W) bool, image frame
    roi_name: str
    notes: tuple[str, ...] = ()  # what loading changed or found (the outside read as unknown, walls at


def load_inputs(map_path, *, model_path=None, rules_path=DEFAULT_RULES, roi_path=None,
                map_options: dict | None = None) -> Inputs:
    """Read and validate the map, model, rules and region of interest (each error names its file)."""

    grid = load_map(map_path, **(map_options or {}))
    model = load_model(model_path)
    grid, outside_note = clear_outside(grid, model.outside)
    rules = load_rules(rules_path) if rules_path is not None else None
    check_model_for_map(grid, model, (map_options or {}).get("max_cells") or MAX_CELLS)
    frame = building_frame(grid, model)
    off_axis = None if rect_spans(frame) else off_axis_note(grid.classes, frame, model.lattice)
    if off_axis:   # world.json's map notes too, as the outside's
        grid = replace(grid, notes=tuple(grid.notes) + (off_axis,))
    if roi_path is not None:
        roi, roi_name = load_roi(roi_path, grid.shape), Path(roi_path).name
    else:
        roi = default_roi(grid.classes, closing_radius_cells(model.evaluate.roi_closing_m, grid.resolution))
        roi_name = "default"
    return Inputs(grid, model, rules, frame, roi, roi_name, tuple(n for n in (outside_note, off_axis) if n))


def check_model_for_map(grid: OccupancyGrid, model: Model, max_cells: int) -> None:
    """Refuse a model and map that cannot run together, before any work array is built.

    The model's lengths at the map's resolution must fit in cells (:meth:`Model.cells`), and the
    map padded by the longest of them (ROI closing, wall, door, object extent) must stay within
    the cell limit: a mistaken resolution of nanometres per cell would otherwise ask for exabytes.
    """
    try:
        c = model.cells(grid.resolution)
    except ModelError as exc:  # the map's resolution is the likelier culprit: name the map
        raise MapError(grid.source, f"{exc.message} (model {model.path})") from None
    pad = 1 + max(closing_radius_cells(model.evaluate.roi_closing_m, grid.resolution), c.wall,
                  c.adjacency_dilation, c.door_max, c.object_max_extent)
    h, w = grid.shape
    if (h + 2 * pad) * (w + 2 * pad) > max_cells:
        raise MapError(grid.source, f"at {grid.resolution:g} m/cell the model's lengths reach {pad} "
                                    f"cells: the {w}x{h} map padded by them exceeds the limit of "
                                    f"{max_cells} cells (is the resolution right?)")


def check_inputs_not_outputs(out: Path, inputs: Inputs, output_names) -> None:
    """Refuse a run whose outputs would overwrite one of its own input files (``--force`` into
    the folder that holds the map, its image or the ROI under an output's name)."""
    paths = [inputs.grid.source, inputs.grid.image_path]
    for p in paths:
        if p is None:
            continue
        p = Path(p)
        try:
            if p.resolve().parent == out.resolve() and p.name in output_names:
                raise SemmapError(p, f"is an input of this run, and --out {out} would overwrite it "
                                     f"with its own {p.name}; choose another --out")
        except OSError:
            continue
