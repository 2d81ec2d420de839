"""The model file (``models/*.toml``): every number of the semantic map model, validated.

:func:`load_model` reads a TOML file into frozen dataclasses. Every problem (a missing key, a wrong
type, a probability outside [0, 1], a sensor table row that does not sum to 1, ...) raises
:class:`~semmap_pp.errors.ModelError` naming the file and the dotted key. Lengths are stored in
metres; :meth:`Model.cells` converts them to lattice cells for one map resolution.

Examples
--------
>>> m = load_model()
>>> m.sensor.psi
0.5
>>> c = m.cells(0.05)
>>> c.wall, c.object_max_extent
(2, 30)
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Mapping, NamedTuple

import numpy as np

from semmap_pp.cells import UNIT_TYPES, WORLD_STATES
from semmap_pp.errors import ModelError
from semmap_pp.resources import DEFAULT_MODEL

SIZE_MEASURES = ("short_side", "long_side", "area")
# Whose doors count towards MulDoor: the unit's own, or for a corridor-like unit those of the
# space it forms with the units joined to it by open passages (semmap_pp.target.geometry_evidence.muldoor_counts).
MULDOOR_SCOPES = ("unit", "space")
#: [evidence] colike_scope: each unit's own Table 4 class, or room-like pieces of a corridor space
#: corridor-like (semmap_pp.target.geometry_evidence.space_colike)
COLIKE_SCOPES = ("unit", "space")
N_PRIORS = ("poisson", "geometric")
#: [outside] mode: read the free space outside the building as unknown when enough of the map's
#: border is open free space ("auto"), always ("unknown") or never ("keep"; semmap_pp.grid.outside)
OUTSIDE_MODES = ("auto", "unknown", "keep")
# Sanity limits (not modelling choices): a model file is a few kilobytes; unit slots are allocated
# up front, so k_max bounds memory; a length in cells must fit the int32 arrays of the samples.
MAX_MODEL_BYTES = 1 << 20
MAX_K = 100_000
MAX_CELLS_PER_LENGTH = 2**31 - 1
#: Most draws per chain of the sample around W* (each records a world: memory grows with it).
MAX_SPREAD_DRAWS = 100_000
#: What ``spread_draws`` must be (:func:`spread_draws_ok`), as the model file and the options say it.
SPREAD_DRAWS_RULE = "must be 0 (no sample around W*) or at least 4 (R-hat and ESS need them)"


def spread_draws_ok(n: int) -> bool:
    """Whether ``n`` draws per chain make a sample around W*: none, or enough for R-hat and ESS."""
    return n == 0 or n >= 4


@dataclass(frozen=True)
class LatticeParams:
    identity_below_deg: float
    angle_bin_deg: float
    refine_window_deg: float
    crop_margin_m: float = 0.0   # the lattice covers the known cells and this much around them; 0: the whole image
    # walls at another angle (frame.off_axis_walls): blocks of off_axis_block_m whose own orientation
    # differs from θ0 by more than off_axis_min_deg and stacks their occupied cells off_axis_min_gain
    # times sharper; a note when they hold off_axis_note_share of the occupied cells (0: no note)
    off_axis_block_m: float = 8.0
    off_axis_min_deg: float = 5.0
    off_axis_min_gain: float = 1.5
    off_axis_note_share: float = 0.0
    # building directions and zones (lattice.zones.building_zones): a further direction is a zone
    # when its zone holds zone_min_share of the wall faces and walls along both of its axes (0: one
    # zone, whatever the map); local wall
    # directions from the structure tensor over zone_wall_scale_m where at least zone_min_coherence;
    # free space cut at narrowings below zone_door_m; a region needs zone_min_votes_m of voting
    # walls, and is shared between directions when a second one has zone_split_share of the first's
    zone_min_share: float = 0.0
    zone_wall_scale_m: float = 0.25
    zone_min_coherence: float = 0.5
    zone_door_m: float = 1.0
    zone_min_votes_m: float = 1.0
    zone_split_share: float = 0.25
    # resampling onto a turned lattice (lattice.frame.resample): each cell takes the class of the
    # pixel under its centre, and a cell that closes a hole the centres left in a wall of the image
    # is occupied (lattice.frame.closes_wall): an occupied pixel under the centre of one of its
    # wall_samples x wall_samples sub-cells, and the image showing a wall through it within
    # wall_join_px pixels (wall_samples 1 or wall_join_px 0: the centre alone)
    wall_samples: int = 1
    wall_join_px: int = 0


@dataclass(frozen=True)
class WorldParams:
    wall_thickness_m: float
    object_max_extent_m: float
    wall_line_tolerance_m: float
    wall_line_gap_m: float
    door_min_m: float
    door_max_m: float
    min_unit_side_m: float
    max_unit_side_m: float
    adjacency_dilation_m: float
    unexplored_min_area_m2: float
    exterior_max_share: float = 0.0
    exterior_seen_min: float = 0.1
    exterior_fan_seen_max: float = 0.0
    exterior_outline_gap_m: float = 0.0
    exterior_outline_walls_max: float = 0.0
    exterior_outline_trust_min: float = 0.0
    wall_min_cells: int = 1
    door_speck_m2: float = 0.0
    passage_gap_m: float = 0.0


@dataclass(frozen=True)
class SensorParams:
    """Semantic sensor model.

    ``corridor`` and ``other`` are (4, 3) arrays ``p(input class | world state)``: rows in the
    order of :data:`semmap_pp.cells.WORLD_STATES`, columns in the order of
    :data:`semmap_pp.cells.INPUT_CLASSES`. ``table(corridor)`` gives the paper's 3x4 layout.
    """

    psi: float
    corridor: np.ndarray
    other: np.ndarray
    enclosure_min_share: float = 0.0
    enclosure_cost: float = 0.0

    def table(self, corridor: bool) -> np.ndarray:
        """The 3x4 look-up table (input class x world state) of the paper."""
        return (self.corridor if corridor else self.other).T


@dataclass(frozen=True)
class EvidenceParams:
    size_measure: str
    hall_min_size: float
    corridor_min_ratio: float
    size_scale: float
    ratio_scale: float
    hard_above: float
    soft_step: float
    multiple_doors: int
    muldoor_scope: str = "unit"
    #: "space": room-like units joined by open passages to a corridor-like unit at most
    #: space_width_ratio times as wide are corridor-like (semmap_pp.target.geometry_evidence.space_colike)
    colike_scope: str = "unit"
    space_width_ratio: float = 2.0


@dataclass(frozen=True)
class PriorParams:
    n_prior: str
    n_mean: float
    k_max: int
    sale_sigma_m: float
    sale_threshold: float


@dataclass(frozen=True)
class KnowledgeParams:
    coverage_threshold: float
    fixed_sale: np.ndarray  # (4, 4) symmetric, order of UNIT_TYPES


@dataclass(frozen=True)
class EvaluateParams:
    roi_closing_m: float


@dataclass(frozen=True)
class CellParams:
    """The model's lengths in lattice cells for one resolution (see :meth:`Model.cells`)."""

    resolution: float
    wall: int
    object_max_extent: int
    door_min: int
    door_max: int
    min_side: int
    max_side: int
    adjacency_dilation: int
    unexplored_min_area: int
    wall_line_tolerance: int = 1
    wall_line_gap: int = 1
    exterior_max_share: float = 0.0
    exterior_seen_min: float = 0.1
    exterior_fan_seen_max: float = 0.0
    exterior_outline_gap: int = 0
    exterior_outline_walls_max: float = 0.0
    exterior_outline_trust_min: float = 0.0
    door_speck: int = 1
    passage_gap: int = 0


@dataclass(frozen=True)
class SamplerParams:
    """Run lengths of ``semmap map`` (command-line options override them)."""

    chains: int
    cores: int
    tune: int
    draws: int
    n_inner: int
    anneal: float
    start_factor: int
    #: The sample around W* (paper Fig. 7) after the search: recorded draws per chain, each of
    #: ``spread_n_inner`` kernels, every chain started at W* (0 draws: no such sample; the spread
    #: figures then use the search's draws). Optional: a model file without the keys gets 0.
    spread_draws: int = 0
    spread_n_inner: int = 20
    #: Opt-in (``semmap map --tempered``): the sample around W* with its likelihood raised to
    #: 1 / A, A the correlation area (cells) of W*'s residuals over lags up to
    #: ``spread_correlation_lag_m`` metres (semmap_pp.target.tempering; 0: exponent 1), and replica
    #: exchange over ``spread_rungs`` rungs (1: none), each the next one's likelihood exponent times
    #: ``spread_ladder_ratio``, ``spread_swaps`` swap proposals per draw. Off: the plain sample.
    spread_tempered: bool = False
    spread_correlation_lag_m: float = 0.0
    spread_rungs: int = 1
    spread_ladder_ratio: float = 0.5
    spread_swaps: int = 1
    #: With spread_tempered: rung k's kernels also run at temperature spread_temperature_ratio^k
    #: (its whole target, prior and knowledge too, to the power 1 / T; 1: likelihood-only ladder).
    spread_temperature_ratio: float = 1.0


@dataclass(frozen=True)
class DiagnosticsParams:
    """Thresholds by which label-invariant summaries are judged converged."""

    rhat_max: float
    ess_min: float
    #: Adjacent rooms whose connecting walls differ by more than this (metres) are a topological
    #: defect (semmap_pp.target.defects); a missing key means 2 * prior.sale_sigma_m.
    defect_tolerance_m: float
    #: A W* unit whose interior holds at least this share of the map's wall-like cells gets a note
    #: (semmap_pp.target.walls_inside: the map probably shows the outside as free); a missing key
    #: means 0.5, 1.0 switches the note off.
    walls_inside_max: float = 0.5


@dataclass(frozen=True)
class OutsideParams:
    """``[outside]``: free space around the building in maps that show it (semmap_pp.grid.outside).

    A model file without the table gets ``mode = "keep"`` (the map as it is)."""

    mode: str = "keep"
    border_open_min: float = 0.25
    seal_gap_m: float = 1.5


@dataclass(frozen=True)
class RoomParams:
    """``[rooms]``: how rooms.png gives every free cell a room (semmap_pp.semantic.rooms).

    A model file without the table gets these values."""

    min_room_m2: float = 2.0
    door_max_m: float = 1.6
    open_share_min: float = 0.6
    band_m: float = 0.3
    walled_min: float = 0.2
    exit_fan_exterior_min: float = 0.5
    exit_fan_walled_max: float = 0.1
    wall_blur_m: float = 0.05
    wall_floor_max: float = 0.1
    split_core_m: float = 0.45
    split_min_m2: float = 1.5
    split_unknown_m2: float = 4.0


#: The five kernel pairs of the sampler, by kind (:mod:`semmap_pp.sampler.kernels`).
KIND_NAMES = ("add_remove", "split_merge", "shrink_dilate", "allocate_delete", "interchange")


class KernelSettings(NamedTuple):
    """Tuning of the proposal distributions (defaults here; a model file's ``[kernels]`` table overrides).

    None of these changes the target distribution; they change how fast the chain mixes.

    Attributes
    ----------
    line_floor : float
        Weight added to every lattice position before line evidence (in [0, 1]) is added; keeps
        every position proposable (irreducibility).
    local_prob : float
        Probability that a wall move is a local step of 1..``local_radius`` cells instead of a jump
        drawn from the line evidence.
    local_radius : int
    birth_uniform : float
        Probability that a birth draws its rectangle uniformly over all valid rectangles instead of
        from the data-driven candidate table.
    birth_jitter : int
        Each coordinate of a candidate birth is moved by a uniform offset in ``[-j, j]``.
    box_prob, box_jitter_prob : float
        ALLOCATE draws each coordinate of the new unit exactly from the free-space box behind the
        wall (``box_prob``), near it (``box_jitter_prob``, offset within ``box_jitter``) or uniformly
        over its range (the rest).
    box_jitter : int
    wall_line_min : int
        Shortest run of occupied cells reported as a wall line.
    max_candidates : int
        Most birth candidates kept (largest distance-transform values first).
    weights : tuple of (kind, weight)
        Mixing weights of the five kernel pairs.
    start_rounds : int
        Rounds of the greedy ascent that refines the data-driven start world
        (:func:`semmap_pp.sampler.ascent.refine_world`; 0 = the greedy cover as it is).
    polish_rounds : int
        Rounds of the greedy ascent of the full target that polishes W* after sampling (0 = W* as
        sampled).
    ascent_peaks : int
        The ascent's wall moves try a few local steps and the strongest peaks of the wall-line
        evidence along the wall's range: this many at 0.05 m cells and coarser, more on finer maps
        (:func:`semmap_pp.sampler.ascent.ascent_peaks`).
    cross_tries : int
        W*'s polish cuts a unit along both axes at once (four pieces) at this many of the best
        crosses of its wall lines, each tried with its pieces' walls moved (0 = never;
        :meth:`semmap_pp.sampler.ascent_cuts.CutMoves.crosses`).
    """

    line_floor: float = 0.05
    local_prob: float = 0.5
    local_radius: int = 3
    birth_uniform: float = 0.2
    birth_jitter: int = 2
    box_prob: float = 0.5
    box_jitter_prob: float = 0.3
    box_jitter: int = 2
    wall_line_min: int = 5
    max_candidates: int = 2000
    weights: tuple = (("add_remove", 1.0), ("split_merge", 1.0), ("shrink_dilate", 4.0),
                      ("allocate_delete", 1.0), ("interchange", 2.0))
    start_rounds: int = 6
    polish_rounds: int = 3
    ascent_peaks: int = 8
    cross_tries: int = 2


def settings_from_mapping(table: Mapping, source="<model> [kernels]") -> KernelSettings:
    """Read a ``[kernels]`` table (e.g. from a model file) into :class:`KernelSettings`.

    Unknown keys and values of the wrong kind raise :class:`~semmap_pp.errors.ModelError`.
    ``weights`` is a table ``{kind = weight}``.
    """
    base = KernelSettings()._asdict()
    out = {}
    for key, value in dict(table).items():
        if key not in base:
            raise ModelError(source, f"unknown key {key!r}")
        if key == "weights":
            if not isinstance(value, Mapping) or any(k not in KIND_NAMES for k in value):
                raise ModelError(source, f"weights must be a table over {KIND_NAMES}")
            w = dict(base["weights"]) | {k: float(v) for k, v in value.items()}
            if any(v < 0 for v in w.values()) or sum(w.values()) <= 0:
                raise ModelError(source, "weights must be >= 0 with a positive sum")
            out[key] = tuple(w.items())
        elif isinstance(base[key], int):
            if isinstance(value, bool) or not isinstance(value, int) or value < 0:
                raise ModelError(source, f"{key} must be a non-negative integer")
            out[key] = int(value)
        else:
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0 <= value <= 1:
                raise ModelError(source, f"{key} must be a number in [0, 1]")
            out[key] = float(value)
    s = KernelSettings(**(base | out))
    if s.box_prob + s.box_jitter_prob > 1:
        raise ModelError(source, "box_prob + box_jitter_prob must be <= 1")
    if s.local_radius < 1:
        raise ModelError(source, "local_radius must be >= 1")
    return s


#: The settings class of each stage (docs/architecture.md, "Settings"): the model file's tables, each
#: read into the class of one stage's folder and validated here; ``Model.<table>`` is that class.
#: The run's own settings (run lengths, seed) are :class:`semmap_pp.run.results.RunSettings`.
STAGE_SETTINGS = {
    "grid": ("outside",),                          # OutsideParams: the free space around the building
    "lattice": ("lattice",),                       # LatticeParams: θ0 and the lattice's crop
    "derive": ("world",),                          # WorldParams: walls, doors, objects, unit sides
    "target": ("sensor", "evidence", "prior"),     # SensorParams, EvidenceParams, PriorParams
    "knowledge": ("knowledge",),                   # KnowledgeParams: coverage threshold, fixed SaLe
    "sampler": ("sampler", "kernels", "diagnostics"),  # SamplerParams, KernelSettings, DiagnosticsParams
    "evaluate": ("evaluate",),                     # EvaluateParams: the default region of interest
    "semantic": ("rooms",),                        # RoomParams: rooms.png
}


@dataclass(frozen=True)
class Model:
    path: Path
    lattice: LatticeParams
    world: WorldParams
    sensor: SensorParams
    evidence: EvidenceParams
    prior: PriorParams
    knowledge: KnowledgeParams
    evaluate: EvaluateParams
    sampler: SamplerParams
    diagnostics: DiagnosticsParams
    kernels: KernelSettings  # the [kernels] table: proposal tuning, validated (settings_from_mapping)
    outside: OutsideParams = OutsideParams()
    rooms: RoomParams = RoomParams()

    def cells(self, resolution: float) -> CellParams:
        """Convert the model's lengths to whole lattice cells at ``resolution`` metres per cell.

        Rounded to the nearest cell; the wall band is at least 1 cell, a unit side at least
        ``2 * wall + 1`` cells (so every unit has an interior).
        """
        w = self.world
        resolution = float(resolution)

        def n(m: float, dims: int = 1) -> int:
            cells = m / resolution if dims == 1 else m / resolution / resolution
            if not (math.isfinite(cells) and cells <= MAX_CELLS_PER_LENGTH):
                raise ModelError(self.path, f"at a resolution of {resolution:g} m/cell the model's "
                                 f"lengths do not fit in lattice cells ({m:g} m{'' if dims == 1 else '^2'} "
                                 f"-> {cells:.3g} cells); is the map's resolution right?")
            return int(round(cells))

        wall = max(w.wall_min_cells, n(w.wall_thickness_m))
        min_side = max(2 * wall + 1, n(w.min_unit_side_m))
        return CellParams(
            resolution=float(resolution), wall=wall,
            object_max_extent=max(1, n(w.object_max_extent_m)),
            door_min=max(1, n(w.door_min_m)), door_max=max(1, n(w.door_max_m)),
            min_side=min_side, max_side=max(min_side, n(w.max_unit_side_m)),
            adjacency_dilation=max(1, n(w.adjacency_dilation_m)),
            unexplored_min_area=max(1, n(w.unexplored_min_area_m2, dims=2)),
            wall_line_tolerance=max(1, n(w.wall_line_tolerance_m)),
            wall_line_gap=max(1, n(w.wall_line_gap_m)),
            exterior_max_share=w.exterior_max_share, exterior_seen_min=w.exterior_seen_min,
            exterior_fan_seen_max=w.exterior_fan_seen_max,
            exterior_outline_gap=n(w.exterior_outline_gap_m),
            exterior_outline_walls_max=w.exterior_outline_walls_max,
            exterior_outline_trust_min=w.exterior_outline_trust_min,
            door_speck=max(1, n(w.door_speck_m2, dims=2)), passage_gap=n(w.passage_gap_m))


class _Reader:
    """Typed access to one TOML document with errors naming the file and dotted key."""

    def __init__(self, path: Path, doc: dict):
        self.path, self.doc = path, doc

    def error(self, key: str, problem: str) -> ModelError:
        return ModelError(self.path, f"{key}: {problem}")

    def raw(self, key: str):
        node = self.doc
        for part in key.split("."):
            if not isinstance(node, dict) or part not in node:
                raise self.error(key, "missing")
            node = node[part]
        return node

    def has(self, key: str) -> bool:
        try:
            self.raw(key)
        except ModelError:
            return False
        return True

    def optional(self, key: str, default, read, *args, **kwargs):
        """``read(key, *args, **kwargs)`` when ``key`` is present, else ``default`` (keys added
        after the first model files: older files keep their behaviour)."""
        return read(key, *args, **kwargs) if self.has(key) else default

    def number(self, key: str, *, lo: float | None = None, hi: float | None = None,
               positive: bool = False) -> float:
        v = self.raw(key)
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            raise self.error(key, f"expected a number, got {type(v).__name__}")
        v = float(v)
        if not math.isfinite(v):
            raise self.error(key, "must be finite")
        if positive and v <= 0:
            raise self.error(key, f"must be > 0, got {v}")
        if lo is not None and v < lo:
            raise self.error(key, f"must be >= {lo}, got {v}")
        if hi is not None and v > hi:
            raise self.error(key, f"must be <= {hi}, got {v}")
        return v

    def integer(self, key: str, *, lo: int, hi: int | None = None) -> int:
        v = self.raw(key)
        if isinstance(v, bool) or not isinstance(v, int):
            raise self.error(key, f"expected an integer, got {type(v).__name__}")
        if v < lo:
            raise self.error(key, f"must be >= {lo}, got {v}")
        if hi is not None and v > hi:
            raise self.error(key, f"must be <= {hi}, got {v}")
        return int(v)

    def flag(self, key: str) -> bool:
        v = self.raw(key)
        if not isinstance(v, bool):
            raise self.error(key, f"expected true or false, got {type(v).__name__}")
        return v

    def choice(self, key: str, options: tuple[str, ...]) -> str:
        v = self.raw(key)
        if not isinstance(v, str) or v not in options:
            raise self.error(key, f"must be one of {', '.join(options)}, got {v!r}")
        return v

    def probabilities(self, key: str, n: int) -> np.ndarray:
        v = self.raw(key)
        if (not isinstance(v, list) or len(v) != n
                or any(isinstance(x, bool) or not isinstance(x, (int, float)) for x in v)):
            raise self.error(key, f"expected a list of {n} numbers")
        a = np.array(v, dtype=np.float64)
        if not np.all(np.isfinite(a)) or np.any(a < 0) or np.any(a > 1):
            raise self.error(key, "probabilities must lie in [0, 1]")
        return a

    def sensor_table(self, key: str) -> np.ndarray:
        rows = []
        for state in WORLD_STATES:
            row = self.probabilities(f"{key}.{state}", 3)
            if abs(row.sum() - 1.0) > 1e-9:
                raise self.error(f"{key}.{state}", f"row must sum to 1, sums to {row.sum():.6g}")
            if np.any(row <= 0):
                raise self.error(f"{key}.{state}", "every probability must be > 0 (log space)")
            rows.append(row)
        table = np.array(rows)
        table.setflags(write=False)
        return table


def load_model(path: str | Path | None = None) -> Model:
    """Read and validate a model file; ``None`` reads the shipped ``models/default.toml``
    (:mod:`semmap_pp.resources`).

    Raises
    ------
    ModelError
        The file cannot be read, is not TOML, or a key is missing or invalid.
    """
    path = DEFAULT_MODEL if path is None else Path(path)
    r = _Reader(path, _read_toml(path))
    lattice, world, sensor, evidence = _lattice(r), _world(r), _sensor(r), _evidence(r)
    prior, knowledge = _prior(r), _knowledge(r)
    evaluate = EvaluateParams(roi_closing_m=r.number("evaluate.roi_closing_m", lo=0.0))
    sampler = _sampler(r)
    diagnostics, kernels, outside = _diagnostics(r, prior), _kernels(r, path), _outside(r)
    rooms = RoomParams()        # optional table (model files written before it: the defaults)
    if r.has("rooms"):
        if not isinstance(r.raw("rooms"), dict):
            raise r.error("rooms", "must be a table")
        rooms = RoomParams(
            min_room_m2=r.optional("rooms.min_room_m2", rooms.min_room_m2, r.number, positive=True, hi=1e4),
            door_max_m=r.optional("rooms.door_max_m", rooms.door_max_m, r.number, positive=True, hi=100.0),
            open_share_min=r.optional("rooms.open_share_min", rooms.open_share_min, r.number,
                                      lo=0.0, hi=1.0),
            band_m=r.optional("rooms.band_m", rooms.band_m, r.number, positive=True, hi=100.0),
            walled_min=r.optional("rooms.walled_min", rooms.walled_min, r.number, lo=0.0, hi=1.0),
            exit_fan_exterior_min=r.optional("rooms.exit_fan_exterior_min", rooms.exit_fan_exterior_min, r.number,
                                        lo=0.0, hi=1.0),
            exit_fan_walled_max=r.optional("rooms.exit_fan_walled_max",
                                               rooms.exit_fan_walled_max, r.number, lo=0.0, hi=1.0),
            wall_blur_m=r.optional("rooms.wall_blur_m", rooms.wall_blur_m, r.number, lo=0.0, hi=10.0),
            wall_floor_max=r.optional("rooms.wall_floor_max", rooms.wall_floor_max, r.number, lo=0.0, hi=1.0),
            split_core_m=r.optional("rooms.split_core_m", rooms.split_core_m, r.number, lo=0.0, hi=100.0),
            split_min_m2=r.optional("rooms.split_min_m2", rooms.split_min_m2, r.number, positive=True, hi=1e4),
            split_unknown_m2=r.optional("rooms.split_unknown_m2", rooms.split_unknown_m2, r.number,
                                        lo=0.0, hi=1e6))
    return Model(path=path, lattice=lattice, world=world, sensor=sensor, evidence=evidence,
                 prior=prior, knowledge=knowledge, evaluate=evaluate, sampler=sampler,
                 diagnostics=diagnostics, kernels=kernels, outside=outside, rooms=rooms)


def _read_toml(path: Path) -> dict:
    """The TOML document of a model file (a regular UTF-8 file, not too large)."""
    if path.exists() and not path.is_file():  # a directory, FIFO or device
        raise ModelError(path, "cannot read model file: not a regular file")
    try:
        if path.stat().st_size > MAX_MODEL_BYTES:
            raise ModelError(path, f"model file is larger than {MAX_MODEL_BYTES} bytes")
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise ModelError(path, f"cannot read model file: {exc.strerror or exc}") from None
    except UnicodeDecodeError:
        raise ModelError(path, "not a UTF-8 text file") from None
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ModelError(path, f"not valid TOML: {exc}") from None
    return doc


def _lattice(r: _Reader) -> LatticeParams:
    """[lattice]."""
    lattice = LatticeParams(
        identity_below_deg=r.number("lattice.identity_below_deg", lo=0.0, hi=45.0),
        angle_bin_deg=r.number("lattice.angle_bin_deg", positive=True, hi=15.0),
        refine_window_deg=r.number("lattice.refine_window_deg", positive=True, hi=45.0),
        crop_margin_m=r.optional("lattice.crop_margin_m", 0.0, r.number, lo=0.0, hi=1000.0),
        # optional: a model file without them gets no note about walls at another angle
        off_axis_block_m=r.optional("lattice.off_axis_block_m", 8.0, r.number, positive=True, hi=1000.0),
        off_axis_min_deg=r.optional("lattice.off_axis_min_deg", 5.0, r.number, positive=True, hi=45.0),
        off_axis_min_gain=r.optional("lattice.off_axis_min_gain", 1.5, r.number, lo=1.0, hi=1000.0),
        off_axis_note_share=r.optional("lattice.off_axis_note_share", 0.0, r.number, lo=0.0, hi=1.0),
        # optional: a model file without them keeps one zone (lattice.zones)
        zone_min_share=r.optional("lattice.zone_min_share", 0.0, r.number, lo=0.0, hi=1.0),
        zone_wall_scale_m=r.optional("lattice.zone_wall_scale_m", 0.25, r.number, positive=True, hi=100.0),
        zone_min_coherence=r.optional("lattice.zone_min_coherence", 0.5, r.number, lo=0.0, hi=1.0),
        zone_door_m=r.optional("lattice.zone_door_m", 1.0, r.number, positive=True, hi=100.0),
        zone_min_votes_m=r.optional("lattice.zone_min_votes_m", 1.0, r.number, lo=0.0, hi=1000.0),
        zone_split_share=r.optional("lattice.zone_split_share", 0.25, r.number, lo=0.0, hi=1.0),
        # optional: a model file without them resamples a turned lattice from cell centres alone
        wall_samples=r.optional("lattice.wall_samples", 1, r.integer, lo=1, hi=8),
        wall_join_px=r.optional("lattice.wall_join_px", 0, r.integer, lo=0, hi=10))
    return lattice


def _world(r: _Reader) -> WorldParams:
    """[world], its lengths checked against each other."""
    # the exterior test is optional (off when its keys are absent: model files written before it)
    exterior = {k: r.number(f"world.{k}", lo=0.0, hi=1.0) for k in
                ("exterior_max_share", "exterior_seen_min", "exterior_fan_seen_max",
                 "exterior_outline_walls_max", "exterior_outline_trust_min")
                if r.has(f"world.{k}")}
    world = WorldParams(**{k: r.number(f"world.{k}", positive=True) for k in (
        "wall_thickness_m", "object_max_extent_m", "door_min_m", "door_max_m", "min_unit_side_m",
        "max_unit_side_m", "adjacency_dilation_m", "unexplored_min_area_m2",
        "wall_line_tolerance_m", "wall_line_gap_m")}, **exterior,
        # optional too: model files written before it keep the one-cell minimum
        wall_min_cells=r.optional("world.wall_min_cells", 1, r.integer, lo=1, hi=64),
        # optional: model files written before it have no outline (exterior units by the hulls only)
        exterior_outline_gap_m=r.optional("world.exterior_outline_gap_m", 0.0, r.number, lo=0.0,
                                          hi=100.0),
        # optional: model files written before it keep one-cell specks
        door_speck_m2=r.optional("world.door_speck_m2", 0.0, r.number, lo=0.0, hi=1.0),
        # optional: model files written before it list no passages across free floor
        passage_gap_m=r.optional("world.passage_gap_m", 0.0, r.number, lo=0.0, hi=10.0))
    if world.door_max_m < world.door_min_m:
        raise r.error("world.door_max_m", "must be >= world.door_min_m")
    if world.max_unit_side_m < world.min_unit_side_m:
        raise r.error("world.max_unit_side_m", "must be >= world.min_unit_side_m")
    return world


def _sensor(r: _Reader) -> SensorParams:
    """[sensor]: the two tables of the sensor model, psi and the enclosure term."""
    corridor, other = r.sensor_table("sensor.corridor"), r.sensor_table("sensor.other")
    unknown = WORLD_STATES.index("unknown")
    if not np.allclose(corridor[unknown], other[unknown], rtol=0, atol=1e-12):
        raise r.error("sensor.corridor.unknown", "must equal sensor.other.unknown "
                      "(cells outside every unit have no type)")
    psi = r.number("sensor.psi", positive=True)
    if psi >= 1:
        raise r.error("sensor.psi", f"must lie in (0, 1), got {psi}")
    # the enclosure term is optional (off when its keys are absent: model files written before it)
    enclosure = {k: r.number(f"sensor.{k}", lo=0.0, hi=hi) for k, hi in
                 (("enclosure_min_share", 1.0), ("enclosure_cost", None)) if r.has(f"sensor.{k}")}
    sensor = SensorParams(psi=psi, corridor=corridor, other=other, **enclosure)
    return sensor


def _evidence(r: _Reader) -> EvidenceParams:
    """[evidence]."""
    evidence = EvidenceParams(
        size_measure=r.choice("evidence.size_measure", SIZE_MEASURES),
        hall_min_size=r.number("evidence.hall_min_size", positive=True),
        corridor_min_ratio=r.number("evidence.corridor_min_ratio", lo=1.0),
        size_scale=r.number("evidence.size_scale", positive=True),
        ratio_scale=r.number("evidence.ratio_scale", positive=True),
        hard_above=r.number("evidence.hard_above", lo=0.5, hi=1.0),
        soft_step=r.number("evidence.soft_step", positive=True, hi=0.5),
        multiple_doors=r.integer("evidence.multiple_doors", lo=1),
        # optional (model files written before them: each unit its own doors and geometry class)
        muldoor_scope=r.optional("evidence.muldoor_scope", "unit", r.choice, MULDOOR_SCOPES),
        colike_scope=r.optional("evidence.colike_scope", "unit", r.choice, COLIKE_SCOPES),
        space_width_ratio=r.optional("evidence.space_width_ratio", 2.0, r.number, lo=1.0, hi=100.0))
    return evidence


def _prior(r: _Reader) -> PriorParams:
    """[prior]."""
    prior = PriorParams(
        n_prior=r.choice("prior.n_prior", N_PRIORS),
        n_mean=r.number("prior.n_mean", positive=True),
        k_max=r.integer("prior.k_max", lo=1, hi=MAX_K),
        sale_sigma_m=r.number("prior.sale_sigma_m", positive=True),
        sale_threshold=r.number("prior.sale_threshold", lo=0.0, hi=1.0))
    return prior


def _knowledge(r: _Reader) -> KnowledgeParams:
    """[knowledge], its fixed P(SaLe) table symmetric."""
    n = len(UNIT_TYPES)
    raw = r.raw("knowledge.fixed_sale")
    if not isinstance(raw, list) or len(raw) != n:
        raise r.error("knowledge.fixed_sale", f"expected {n} rows of {n} probabilities")
    fixed = np.array([_row(r, "knowledge.fixed_sale", raw, i, n) for i in range(n)])
    if not np.allclose(fixed, fixed.T):
        raise r.error("knowledge.fixed_sale", "must be symmetric")
    fixed.setflags(write=False)
    knowledge = KnowledgeParams(
        coverage_threshold=r.number("knowledge.coverage_threshold", lo=0.0, hi=1.0),
        fixed_sale=fixed)
    return knowledge


def _sampler(r: _Reader) -> SamplerParams:
    """[sampler]."""
    sampler = SamplerParams(
        chains=r.integer("sampler.chains", lo=1), cores=r.integer("sampler.cores", lo=1),
        tune=r.integer("sampler.tune", lo=0), draws=r.integer("sampler.draws", lo=4),
        n_inner=r.integer("sampler.n_inner", lo=1), anneal=r.number("sampler.anneal", lo=1.0),
        start_factor=r.integer("sampler.start_factor", lo=1),
        spread_draws=r.optional("sampler.spread_draws", 0, r.integer, lo=0, hi=MAX_SPREAD_DRAWS),
        spread_n_inner=r.optional("sampler.spread_n_inner", 20, r.integer, lo=1),
        spread_tempered=r.optional("sampler.spread_tempered", False, r.flag),
        spread_correlation_lag_m=r.optional("sampler.spread_correlation_lag_m", 0.0, r.number,
                                            lo=0.0, hi=100.0),
        spread_rungs=r.optional("sampler.spread_rungs", 1, r.integer, lo=1, hi=64),
        spread_ladder_ratio=r.optional("sampler.spread_ladder_ratio", 0.5, r.number, positive=True,
                                       hi=1.0),
        spread_swaps=r.optional("sampler.spread_swaps", 1, r.integer, lo=0, hi=10_000),
        spread_temperature_ratio=r.optional("sampler.spread_temperature_ratio", 1.0, r.number, lo=1.0,
                                            hi=1e6))
    if not spread_draws_ok(sampler.spread_draws):
        raise r.error("sampler.spread_draws", SPREAD_DRAWS_RULE)
    return sampler


def _diagnostics(r: _Reader, prior: PriorParams) -> DiagnosticsParams:
    """[diagnostics] (the defect tolerance defaults to twice [prior] sale_sigma_m)."""
    r.raw("diagnostics")                   # a missing table is named as such
    defect_tol = r.optional("diagnostics.defect_tolerance_m", 2.0 * prior.sale_sigma_m, r.number, lo=0.0)
    walls_inside_max = r.optional("diagnostics.walls_inside_max", 0.5, r.number, lo=0.0, hi=1.0)
    diagnostics = DiagnosticsParams(rhat_max=r.number("diagnostics.rhat_max", lo=1.0),
                                    ess_min=r.number("diagnostics.ess_min", lo=0.0),
                                    defect_tolerance_m=defect_tol, walls_inside_max=walls_inside_max)
    return diagnostics


def _kernels(r: _Reader, path: Path) -> KernelSettings:
    """[kernels], validated by :func:`settings_from_mapping`."""
    kernels = r.raw("kernels")
    if not isinstance(kernels, dict):
        raise r.error("kernels", "must be a table")
    try:
        kernels = settings_from_mapping(kernels, source=f"{path} [kernels]")
    except (TypeError, ValueError) as exc:
        raise ModelError(path, f"[kernels]: {exc}") from None
    if not all(math.isfinite(v) for _, v in kernels.weights):
        raise ModelError(path, "[kernels] weights must be finite numbers")
    return kernels


def _outside(r: _Reader) -> OutsideParams:
    """[outside] (optional)."""
    outside = OutsideParams()   # optional table (model files written before it: the map as it is)
    if r.has("outside"):
        if not isinstance(r.raw("outside"), dict):
            raise r.error("outside", "must be a table")
        outside = OutsideParams(
            mode=r.choice("outside.mode", OUTSIDE_MODES),
            border_open_min=r.number("outside.border_open_min", lo=0.0, hi=1.0),
            seal_gap_m=r.number("outside.seal_gap_m", positive=True))
    return outside



def _row(r: _Reader, key: str, raw: list, i: int, n: int) -> np.ndarray:
    row = raw[i]
    if (not isinstance(row, list) or len(row) != n
            or any(isinstance(x, bool) or not isinstance(x, (int, float)) for x in row)):
        raise r.error(f"{key}[{i}]", f"expected a list of {n} numbers")
    a = np.array(row, dtype=np.float64)
    if np.any(a < 0) or np.any(a > 1) or not np.all(np.isfinite(a)):
        raise r.error(f"{key}[{i}]", "probabilities must lie in [0, 1]")
    return a
