"""rooms.png: every free cell of the building given the room it belongs to.

The units of W* are the abstract model (the paper's rectangles); a *room* is what a person, or a
room segmenter such as ipa_room_segmentation or ROSE2, draws on the map's free cells. Rooms are
made from W* in three steps, all on the input image's cells of floor (:func:`floor_cells`: the
free cells, and on a map saved with graded values the cells seen free a few times):

1. **Seeds.** Every free cell inside a unit's interior (its rectangle less the wall band) takes
   the unit's region (:mod:`semmap_pp.semantic.regions`: units joined by an open wall are one
   region). W*'s door cells are never part of a room: a door separates the rooms it joins. A unit
   too small for a room (interior under ``min_room_m2``) seeds none (its floor joins the nearest
   room in step 3, or keeps its unit's room where none reaches it), and joins through a passage
   only where the floor crosses it (:class:`UnitPieces`): drawn across a wall, it does not join
   the rooms on its two sides. A region whose walls hold rooms apart is a room per core
   (:func:`split_cores`, after step 3: which floor is the region's, and the rooms seen through
   their door, are decided as if it were one room): where two or more parts of its interior lie
   farther than ``split_core_m`` from the map's walls (occupied cells on wall lines, and unknown
   stretches of at least ``split_unknown_m2`` or open to the map's edge), each of at least
   ``split_min_m2``, each such core is a room and each cell of the region's floor goes to the
   core nearest to it along the floor. That is a unit W* drew over a room and the corridor in
   front of it, or over two rooms with a door between them: a door is narrower than twice
   ``split_core_m``, furniture is no wall, so a cluttered room keeps one core.
2. **Rooms seen through their door.** The strips along each interior (up to ``band_m`` along the
   floor) go to it; the free cells left fall into connected pieces. A piece of at least
   ``min_room_m2`` that meets the rooms only through openings no wider than a door (``door_max_m``
   of ``[rooms]``, in the model file) is a room of its own when walls enclose it: at least
   ``walled_min`` of the non-free cells around it (not the specks inside it) lie within
   ``wall_blur_m`` of an occupied cell
   (a SLAM map blurs its walls into a margin of cells neither free nor occupied). That is a room
   the robot saw through its door, or entered without W* giving it a unit, flagged
   ``seen_through_door`` in world.json's ``rooms``. Without such walls it is rays into the open
   through a window or an exit: no room. A piece that meets the rooms through a wider opening is
   the open side of the room in front and joins it in step 3, unless more than
   ``exit_fan_exterior_min`` of it lies in W*'s exterior units and less than
   ``exit_fan_walled_max`` of the non-free cells around it are walls: rays into the open through
   an exit, no room. A unit too small for a room keeps no room in rays into the open.
3. **Every other free cell** (rays through a door, an alcove, a strip along a ragged wall) joins
   the room it is nearest to along the free floor, never across a door (a breadth-first
   geodesic flood, 8-connected but never cutting the corner between two wall or door cells: a
   ray's cells may touch only at their corners, a wall drawn as a staircase stays shut).
4. **Rooms of units over rays into the open.** A room of units (or one of a region's rooms walled
   apart) is no room when walls enclose less than ``walled_min`` of its own floor (the units'
   interiors and the strips along them, counted as in step 2) and less than
   ``exit_fan_walled_max`` of all its floor: W* covered rays through a window or an exit with a
   unit. A room never entered, seen through its door, keeps its room: its far wall, seen in part,
   puts more walls around it than the open has; so does a walled room with rays out through its
   exit joined to it.

Free cells that no room reaches (specks beyond a wall, free space seen outside through a window
with no room behind it) are 0. ``docs/outputs.md`` compares the convention with ipa's and ROSE2's.
"""

from __future__ import annotations

import weakref
from dataclasses import dataclass

import numba
import numpy as np
from scipy import ndimage as ndi
from scipy.spatial import ConvexHull, QhullError

from semmap_pp.cells import FREE, OCCUPIED, UNIT_TYPES, UNKNOWN, border_cells, mask_box, rects_mask
from semmap_pp.derive.doors import connecting_wall, wall_strip
from semmap_pp.derive.states import interior
from semmap_pp.lattice.tiles import rect_spans
from semmap_pp.model import RoomParams
from semmap_pp.semantic.regions import join_regions, passage_pairs, region_lut
from semmap_pp.target.likelihood import wall_like

_FOUR = ndi.generate_binary_structure(2, 1)
_EIGHT = np.ones((3, 3), bool)


@dataclass(frozen=True)
class Room:
    """One room of rooms.png.

    Attributes
    ----------
    id : int
        Its value in rooms.png (1..k).
    units : tuple of int
        The unit ids it grew from, in order; empty for a room seen through its door that no unit
        covers.
    cells : int
        Its free cells.
    seen_share : float
        ``cells`` over the area of the convex hull of its cells: 1 for a room seen whole and
        empty, less for one seen in part (a fan of rays through its door) or cluttered.
    through_door : bool
        Its unit was added to W* over a room seen through its door
        (``SemanticMap.through_door``).
    """

    id: int
    units: tuple
    cells: int
    seen_share: float
    through_door: bool = False

    @property
    def seen_through_door(self) -> bool:
        """Seen only through its door: no unit covers it, or its unit was added over such a room."""
        return not self.units or self.through_door


@dataclass(frozen=True)
class Rooms:
    """rooms.png's labels (``(H, W)`` int32, 0 none) and its rooms, by id."""

    labels: np.ndarray
    rooms: tuple


@numba.njit(cache=True, nogil=True)
def _flood(labels, passable, walls, max_steps, queue, steps):  # pragma: no cover - compiled
    """Breadth-first geodesic flood: every passable 0-cell reachable from a labelled cell in at most
    ``max_steps`` steps (any number when negative) takes the label of the nearest one. Steps go to
    the 4 neighbours, and to the 4 diagonal ones unless both cells beside the diagonal are
    ``walls`` (a ray's cells touch at their corners; a wall drawn as a staircase is not crossed);
    ties go to the label that reached the cell first (row-major order of the seeds). ``queue``
    holds a cell index per cell (``h * w`` of them), ``steps`` each cell's steps from its seed
    (used only when ``max_steps`` is not negative)."""
    h, w = labels.shape
    out = labels.copy()
    bounded = max_steps >= 0
    head = 0
    tail = 0
    for i in range(h):
        for j in range(w):
            if out[i, j] > 0:
                queue[tail] = i * w + j
                tail += 1
    while head < tail:
        k = queue[head]
        head += 1
        i = k // w
        j = k - i * w
        lab = out[i, j]
        if bounded and steps[k] >= max_steps:
            continue
        for d in range(8):
            di = _DI[d]
            dj = _DJ[d]
            ii = i + di
            jj = j + dj
            if not (0 <= ii < h and 0 <= jj < w) or out[ii, jj] != 0 or not passable[ii, jj]:
                continue
            if d >= 4 and walls[ii, j] and walls[i, jj]:
                continue
            out[ii, jj] = lab
            if bounded:
                steps[ii * w + jj] = steps[k] + 1
            queue[tail] = ii * w + jj
            tail += 1
    return out


_DI = np.array([1, -1, 0, 0, 1, 1, -1, -1], np.int64)
_DJ = np.array([0, 0, 1, -1, 1, -1, 1, -1], np.int64)


def geodesic_flood(labels: np.ndarray, passable: np.ndarray, max_steps: int = -1,
                   walls: np.ndarray | None = None) -> np.ndarray:
    """Each 0-cell of ``passable`` reachable from a labelled cell (in at most ``max_steps`` steps
    when it is not negative) takes the nearest cell's label: 8-connected, a diagonal step taken
    unless both cells beside it are ``walls`` (None: every cell not ``passable``).

    >>> lab = np.array([[1, 0, 0, 0, 2]], np.int32)
    >>> geodesic_flood(lab, np.array([[1, 1, 0, 1, 1]], bool)).tolist()
    [[1, 1, 0, 2, 2]]
    >>> geodesic_flood(np.array([[1, 0, 0, 0]]), np.ones((1, 4), bool), max_steps=2).tolist()
    [[1, 1, 1, 0]]

    A ray whose cells touch at their corners is followed, a staircase wall is not crossed:

    >>> ray = np.eye(4, dtype=bool); lab = np.zeros((4, 4), np.int32); lab[0, 0] = 1
    >>> geodesic_flood(lab, ray, walls=np.zeros((4, 4), bool)).diagonal().tolist()
    [1, 1, 1, 1]
    >>> geodesic_flood(lab, ray).diagonal().tolist()
    [1, 0, 0, 0]
    """
    passable = np.ascontiguousarray(passable, np.bool_)
    walls = ~passable if walls is None else np.ascontiguousarray(walls, np.bool_)
    n = passable.size
    # int32 indexes while the image has fewer than 2**31 cells: 4 bytes a cell instead of 8 (a
    # campus canvas has tens of millions); steps are kept only for a bounded flood
    queue = np.empty(n, np.int32 if n < 2**31 else np.int64)
    steps = np.zeros(n if max_steps >= 0 else 1, np.int32 if 0 <= max_steps < 2**31 else np.int64)
    return _flood(np.ascontiguousarray(labels, np.int32), passable, walls, int(max_steps), queue, steps)


def _contact_widths(piece: np.ndarray, seeds: np.ndarray) -> np.ndarray:
    """Per seed label, how many of its cells touch ``piece`` (4-connected)."""
    ring = ndi.binary_dilation(piece, _FOUR) & ~piece
    return np.bincount(seeds[ring], minlength=int(seeds.max(initial=0)) + 1)


def _walled_share(piece: np.ndarray, free: np.ndarray, walls: np.ndarray | None) -> float:
    """Share of the non-free cells around ``piece`` (8-connected, its holes filled: specks and
    furniture inside it are no walls around it) that are ``walls`` (cells near an occupied one;
    None: every non-free cell)."""
    if walls is None:
        return 1.0
    piece = ndi.binary_fill_holes(piece)
    ring = ndi.binary_dilation(piece, _EIGHT) & ~piece & ~free
    n = int(ring.sum())
    return float((ring & walls).sum()) / n if n else 1.0


def room_labels(free: np.ndarray, seeds: np.ndarray, doors: np.ndarray, resolution: float,
                params: RoomParams = RoomParams(), occupied: np.ndarray | None = None,
                fallback: np.ndarray | None = None,
                walls_apart: np.ndarray | None = None,
                outside: np.ndarray | None = None) -> tuple[np.ndarray, list[tuple[int, int, int]]]:
    """Rooms of the free cells (see the module docstring).

    Parameters
    ----------
    free : (H, W) bool
        The map's free cells.
    seeds : (H, W) int
        Region id (1..m) of every cell inside a unit's interior, 0 elsewhere.
    doors : (H, W) bool
        W*'s door cells.
    resolution : float
        Metres per cell.
    occupied : (H, W) bool, optional
        The map's occupied cells (the other non-free cells are unknown); None: every non-free
        cell counts as occupied.
    fallback : (H, W) int, optional
        Region id of cells that keep it when no room reaches them (a unit's interior that seeds
        nothing: a closet behind its door), 0 elsewhere.
    walls_apart : (H, W) bool, optional
        The walls that hold rooms apart (:func:`walls_apart`): a room per core of each region
        (:func:`split_cores`); None: one per region.
    outside : (H, W) bool, optional
        The cells of W*'s exterior units, for the rays into the open through an exit (step 2:
        ``exit_fan_exterior_min``); None: every piece beyond a wide opening is flooded.

    Returns
    -------
    labels : (H, W) int32, room 1..k per cell, 0 none
    rooms : list of (room id, region it grew from or 0 for a room seen through its door, cells)

    Examples
    --------
    A corridor unit (region 1) with a room behind a one-cell door that no unit covers:

    >>> free = np.zeros((6, 9), bool); free[0:2, :] = True; free[3:6, 2:7] = True
    >>> free[2, 4] = True                        # the doorway through the wall row 2
    >>> seeds = np.zeros((6, 9), int); seeds[0:2, :] = 1
    >>> lab, rooms = room_labels(free, seeds, np.zeros_like(free), 1.0,
    ...                          RoomParams(min_room_m2=10.0, door_max_m=2.0))
    >>> rooms                  # the doorway cell, one band_m step from the corridor, went to it
    [(1, 1, 19), (2, 0, 15)]
    """
    free = np.asarray(free, bool)
    full = np.zeros(free.shape, np.int32)
    if not free.any():
        return full, []
    # work on the free cells' bounding box, with the walls just beyond them (the blur's margin and one cell)
    blur = int(round(params.wall_blur_m / resolution))
    box = _free_box(free, 2 + blur)
    free = free[box]
    doors = np.asarray(doors, bool)[box]
    seeds = np.asarray(seeds)[box]
    # cells that count as walls: within the blur's margin of an occupied cell
    walls = None if occupied is None else np.asarray(occupied, bool)[box]
    # what a flood's diagonal step may not cut between: the map's walls (or every non-free cell)
    # and W*'s doors; unknown cells between the cells of a ray are no walls
    blocked = (~free if walls is None else walls) | doors
    if walls is not None and blur > 0:
        walls = ndi.binary_dilation(walls, _EIGHT, iterations=blur)
    passable = free & ~doors
    seeds = np.where(passable, seeds, 0).astype(np.int32)
    n_regions = int(seeds.max(initial=0))

    # the strips along each interior (its wall band, a ragged wall's margin) go to it first, so that
    # what is left falls apart into the pieces beyond the walls
    near = geodesic_flood(seeds, passable, max(1, int(round(params.band_m / resolution))), blocked)
    flooded, n_extra = _pieces_flooded(near, passable, free, walls, blocked, n_regions, resolution, params,
                                       None if outside is None else np.asarray(outside, bool)[box],
                                       None if fallback is None else np.asarray(fallback)[box])
    # a region's rooms walled apart: its floor shared among its cores
    flooded, parent = _divided(flooded, seeds, walls_apart, box, resolution, params, n_regions + n_extra, blocked)
    flooded = _unwalled_dropped(flooded, near > 0, free, walls, range(n_regions + 1, n_regions + n_extra + 1), params)
    labels, found = _numbered(flooded)
    full[box] = labels
    return full, [(k, parent.get(old, old if old <= n_regions else 0), n) for k, old, n in found]


def _pieces_flooded(near, passable, free, walls, blocked, n_regions, resolution, params, outside, fallback):
    """Steps 2 and 3 of the module docstring on the seeds grown by their strips (``near``):
    ``(flooded, rooms seen through their door)``; ``fallback`` (cells that keep a unit's region
    where no room reaches them) never in rays into the open."""
    seeded, n_extra, passable = _rooms_beyond_doors(
        near, passable, free, walls, n_regions, params.min_room_m2 / resolution ** 2,
        params.door_max_m / resolution, params.walled_min,
        outside if params.exit_fan_exterior_min > 0 else None, params.exit_fan_exterior_min,
        params.exit_fan_walled_max)
    flooded = geodesic_flood(seeded, passable, walls=blocked)
    if fallback is not None:      # not in rays into the open (out of passable): those are no room
        flooded = np.where((flooded == 0) & (fallback > 0) & passable, fallback, flooded)
    return flooded, n_extra


def _unwalled_dropped(flooded, own, free, walls, judged, params):
    """``flooded`` without the rooms of units over rays into the open (step 4 of the module
    docstring): walls enclose less than ``walled_min`` of their own floor (``own``: the units'
    interiors and the strips along them; :func:`_walled_share`) and less than
    ``exit_fan_walled_max`` of their whole floor. The labels in ``judged`` (rooms seen through
    their door, which step 2 judged on their whole piece) are kept."""
    walled_min, open_max = params.walled_min, params.exit_fan_walled_max
    if walls is None or walled_min <= 0 or open_max <= 0:
        return flooded
    judged = set(judged)
    drop = []
    for k, sl in enumerate(ndi.find_objects(flooded), start=1):
        if sl is None or k in judged:
            continue
        sl = tuple(slice(max(s.start - 1, 0), s.stop + 1) for s in sl)
        room = flooded[sl] == k
        mine = room & own[sl]
        if (mine.any() and _walled_share(mine, free[sl], walls[sl]) < walled_min
                and _walled_share(room, free[sl], walls[sl]) < open_max):
            drop.append(k)
    return np.where(np.isin(flooded, drop), 0, flooded).astype(flooded.dtype) if drop else flooded


def _free_box(free: np.ndarray, pad: int) -> tuple[slice, slice]:
    """The bounding box of ``free`` (not empty) with ``pad`` cells around it: a SLAM map's canvas
    is mostly unknown."""
    r0, c0, r1, c1 = mask_box(free)
    return slice(max(r0 - pad, 0), r1 + pad), slice(max(c0 - pad, 0), c1 + pad)


def _divided(flooded, seeds, walls, box, resolution, params, first, blocked):
    """``(flooded, parent)``: the rooms of ``flooded`` whose region's seeds hold two or more
    cores (:func:`split_cores`, ``walls[box]`` the walls; None: no room is divided) divided among
    them, each cell of the room to the core nearest to it along the room's floor (its first core
    keeps the region's id, the others take ``first + 1, ...``, which ``parent`` maps to the
    region); the other rooms as they are. The rooms seen through their door, and which cells are
    a region's, are those of ``flooded``."""
    if walls is None:
        return flooded, {}
    cores, parent = split_cores(seeds, np.asarray(walls, bool)[box], resolution, params)
    if not parent:
        return flooded, {}
    m = int(seeds.max())
    cores = np.where(cores > m, cores - m + first, cores)    # after the rooms seen through a door
    parent = {j - m + first: k for j, k in parent.items()}
    out = flooded.copy()
    for k in sorted(set(parent.values())):
        room = flooded == k
        shared = geodesic_flood(np.where(room, cores, 0).astype(np.int32), room, walls=blocked)
        out[room & (shared > 0)] = shared[room & (shared > 0)]
    return out, parent


def split_cores(seeds: np.ndarray, walls: np.ndarray, resolution: float,
                params: RoomParams = RoomParams()) -> tuple[np.ndarray, dict[int, int]]:
    """The cores of step 1's rooms walled apart (module docstring): ``(seeds, parent)``, each region of
    ``seeds`` (ids 1..m) whose interior holds two or more cores seeded by them instead (the
    first keeps the region's id, the others take ``m + 1, ...``; ``parent`` maps those to the
    region), its other cells no seeds; the other regions as they are.

    A core is a connected part of the region's area (its seed cells, closed and their holes
    filled: furniture inside is area too) farther than ``split_core_m`` from ``walls``, of at least
    ``split_min_m2``. ``split_core_m`` 0: no region is split.

    >>> seeds = np.zeros((9, 21), int); seeds[1:8, 1:20] = 1      # one unit over two rooms
    >>> walls = np.zeros((9, 21), bool); walls[0, :] = walls[8, :] = True
    >>> walls[:, 0] = walls[:, 20] = True; walls[:, 10] = True; walls[4, 10] = False  # a door
    >>> split, parent = split_cores(seeds, walls, 1.0, RoomParams(split_core_m=1.5, split_min_m2=4.0))
    >>> parent, int(split[4, 5]), int(split[4, 15]), int(split[4, 10])      # the doorway is no core
    ({2: 1}, 1, 2, 0)
    """
    seeds = np.asarray(seeds)
    out, parent = seeds.copy(), {}
    if params.split_core_m <= 0 or not seeds.any():
        return out, parent
    core = ndi.distance_transform_edt(~np.asarray(walls, bool)) > params.split_core_m / resolution
    least = params.split_min_m2 / resolution ** 2
    nxt = int(seeds.max())
    for k, sl in enumerate(ndi.find_objects(seeds), start=1):
        if sl is None:
            continue
        own = seeds[sl] == k
        area = _filled(ndi.binary_closing(own, _EIGHT, iterations=3))
        parts, n = ndi.label(core[sl] & area, _EIGHT)
        sizes = np.bincount(parts.ravel(), minlength=n + 1)
        cores = [j for j in range(1, n + 1) if sizes[j] >= least]
        if len(cores) < 2:
            continue
        sub = out[sl]
        sub[own] = 0
        sub[own & (parts == cores[0])] = k
        for j in cores[1:]:
            nxt += 1
            sub[own & (parts == j)] = nxt
            parent[nxt] = k
    return out, parent


def _filled(mask: np.ndarray) -> np.ndarray:
    """``mask`` with its holes filled: :func:`scipy.ndimage.binary_fill_holes` (the background's
    4-connected pieces that do not reach the edge are holes), from one labelling instead of
    dilating the edge's background step by step.

    >>> m = np.ones((5, 6), bool); m[2, 2] = m[2, 4] = False; m[0, 3] = False
    >>> bool((_filled(m) == ndi.binary_fill_holes(m)).all()), int(_filled(m).sum())
    (True, 29)
    """
    background, n = ndi.label(~mask, _FOUR)
    hole = np.ones(n + 1, bool)
    hole[0] = False
    hole[border_cells(background)] = False
    return mask | hole[background]


#: The walls of :func:`walls_apart` of each frame a run's rooms were made on (its three semantic
#: maps read the same map): ``frame -> (grid, split_unknown_m2, walls)``.
_WALLS_OF: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def _walls_apart_of(sm, params: RoomParams) -> np.ndarray:
    """:func:`walls_apart` of ``sm``, made once per frame, grid and ``split_unknown_m2``."""
    known = _WALLS_OF.get(sm.frame)
    if known is not None and known[0]() is sm.grid and known[1] == params.split_unknown_m2:
        return known[2]
    walls = walls_apart(sm, params)
    walls.setflags(write=False)
    _WALLS_OF[sm.frame] = (weakref.ref(sm.grid), params.split_unknown_m2, walls)
    return walls


def walls_apart(sm, params: RoomParams = RoomParams()) -> np.ndarray:
    """(H, W) bool: the walls that hold rooms apart in :func:`split_cores`, in the input
    image's frame: the occupied cells on wall lines of each lattice of ``sm.frame`` (the
    likelihood's wall-like cells: :func:`~semmap_pp.target.likelihood.wall_like`), and the
    unknown stretches of at least ``split_unknown_m2`` or open to the map's edge (the building's
    outside, a room never seen). Furniture, specks and the shadows behind them are no walls."""
    frame, grid = sm.frame, sm.grid
    c = frame.cells
    lines = wall_like(frame.classes == OCCUPIED, c.object_max_extent, c.wall_line_tolerance, c.wall_line_gap)
    walls = np.asarray(frame.to_image(lines, fill=False), bool)
    unknown, n = ndi.label(grid.classes == UNKNOWN)
    if n:
        sizes = np.bincount(unknown.ravel(), minlength=n + 1)
        wide = sizes >= params.split_unknown_m2 / grid.resolution ** 2
        wide[border_cells(unknown)] = True
        wide[0] = False
        walls |= wide[unknown]
    return walls


def _rooms_beyond_doors(near, passable, free, walls, n_regions, min_cells, door_cells, walled_min,
                        outside=None, outside_min=0.0, open_walled_max=0.0):
    """Step 2 of the module docstring on the seeds grown by their strips (``near``): ``(seeded,
    rooms added, passable)``, each piece of the floor left that is a room seen through its door
    labelled ``n_regions + 1, ...``, and the pieces of rays into the open taken out of ``passable``
    (through a window; through an exit, ``outside``: the cells of W*'s exterior units, more than
    ``outside_min`` of the piece in them and fewer walls around it than ``open_walled_max``)."""
    pieces, n = ndi.label(passable & (near == 0), _EIGHT)
    seeded = near.copy()
    extra = 0
    if not n:
        return seeded, extra, passable
    sizes = np.bincount(pieces.ravel(), minlength=n + 1)
    objs = ndi.find_objects(pieces)
    for k in range(1, n + 1):
        if sizes[k] < min_cells or objs[k - 1] is None:
            continue
        sl = tuple(slice(max(s.start - 1, 0), s.stop + 1) for s in objs[k - 1])
        piece = pieces[sl] == k
        contact = _contact_widths(piece, near[sl])
        contact[0] = 0
        if contact.max(initial=0) > door_cells:
            # rays into the open through an exit, where W* has an exterior unit: no room either
            if outside is not None and (piece & outside[sl]).sum() > outside_min * sizes[k] and \
                    _walled_share(piece, free[sl], None if walls is None else walls[sl]) < open_walled_max:
                passable = passable & (pieces != k)
            continue
        if _walled_share(piece, free[sl], None if walls is None else walls[sl]) >= walled_min:
            extra += 1
            seeded[pieces == k] = n_regions + extra
        else:                  # rays into the open (a window's fan): no room, not flooded either
            passable = passable & (pieces != k)
    return seeded, extra, passable


def _numbered(flooded):
    """The rooms numbered 1..k in the order of their labels in ``flooded`` (the regions first,
    then the rooms seen through their door, then a region's further rooms walled apart):
    ``(labels, [(room id, label, cells), ...])``."""
    present = np.bincount(flooded.ravel())
    lut = np.zeros(present.size, np.int32)
    kept = [old for old in range(1, present.size) if present[old]]
    lut[kept] = np.arange(1, len(kept) + 1, dtype=np.int32)
    return lut[flooded], [(int(lut[old]), old, int(present[old])) for old in kept]


def seen_share(mask: np.ndarray) -> float:
    """Cells of ``mask`` over the area (in cells) of the convex hull of their squares.

    >>> m = np.zeros((4, 4), bool); m[:, :2] = True
    >>> seen_share(m)
    1.0
    >>> m[1:, 1] = False; round(seen_share(m), 3)      # an L of 5 cells; its hull holds 6.5
    0.769
    """
    mask = np.asarray(mask, bool)
    n = int(mask.sum())
    if n == 0:
        return 0.0
    # the hull of the cells' squares is the hull of each row's outermost squares' corners
    rows = np.flatnonzero(mask.any(axis=1))
    first = mask[rows].argmax(axis=1)
    last = mask.shape[1] - 1 - mask[rows, ::-1].argmax(axis=1)
    corners = np.concatenate([np.stack([rows + dr, cols], 1)
                              for dr in (0, 1) for cols in (first, last + 1)])
    try:
        area = ConvexHull(corners).volume
    except QhullError:            # all corners on a line: a hull of no area
        return 1.0
    return float(min(1.0, n / area)) if area > 0 else 1.0


def opening_share(classes: np.ndarray, rp, rq, wall: int) -> float:
    """Share of the lines across the connecting wall of rectangles ``rp`` and ``rq`` that are
    open (free all the way across, ``classes`` the lattice's door classes), on the strip
    :func:`~semmap_pp.derive.doors.wall_strip` finds doors on; 0 without one."""
    found = wall_strip(classes, rp, rq, wall)
    if found is None:
        return 0.0
    strip, _, vertical = found
    lines = (strip == FREE).all(axis=1 if vertical else 0)
    return float(lines.mean()) if lines.size else 0.0


def wide_opening(free: np.ndarray, rp, rq, wall: int, width: float) -> bool:
    """Whether the free floor joins rectangles ``rp`` and ``rq`` across their connecting wall
    through a gap at least ``width`` cells wide: a path from one side of the wall to the other,
    within ``width`` of it, whose cells all lie at least ``width / 2`` from every non-free cell
    (``free`` the lattice's free cells, its specks made free). A door, or a gap that clutter
    narrows to a door's width, is no such gap.

    >>> free = np.ones((40, 60), bool); free[:, 29:31] = False       # a wall down column 29-30
    >>> rp, rq = (0, 0, 40, 31), (0, 29, 40, 60)                       # two units, walls 2 cells
    >>> free[5:25, 29:31] = True; wide_opening(free, rp, rq, 2, 16.0)  # a 20-cell gap
    True
    >>> free[13:25, 29:31] = False; wide_opening(free, rp, rq, 2, 16.0)  # an 8-cell door
    False
    """
    cw = connecting_wall(rp, rq, wall)
    if cw is None or width <= 0:
        return False
    (r0, c0, r1, c1), vertical = cw
    reach = int(np.ceil(width))
    # the wall strip and ``width`` of floor on each side of it
    b0, b1 = (r0, r1) if vertical else (r0 - reach, r1 + reach)
    d0, d1 = (c0 - reach, c1 + reach) if vertical else (c0, c1)
    pad = int(np.ceil(width / 2)) + 1
    H, W = free.shape
    y0, y1, x0, x1 = max(b0 - pad, 0), min(b1 + pad, H), max(d0 - pad, 0), min(d1 + pad, W)
    if y0 >= y1 or x0 >= x1:
        return False
    clear = ndi.distance_transform_edt(np.pad(free[y0:y1, x0:x1], 1))[1:-1, 1:-1]
    wide = clear >= width / 2
    band = np.zeros(wide.shape, bool)
    band[max(b0, 0) - y0:min(b1, H) - y0, max(d0, 0) - x0:min(d1, W) - x0] = True
    wide &= band
    side_a, side_b = np.zeros_like(band), np.zeros_like(band)
    if vertical:
        side_a[:, :max(c0 - x0, 0)] = True
        side_b[:, max(c1 - x0, 0):] = True
    else:
        side_a[:max(r0 - y0, 0), :] = True
        side_b[max(r1 - y0, 0):, :] = True
    lab, n = ndi.label(wide, _EIGHT)
    if not n:
        return False
    return bool(np.intersect1d(lab[wide & side_a], lab[wide & side_b]).size)


#: unit types whose side openings lead into other rooms, however wide (a corridor's, a hall's)
_THROUGH_TYPES = frozenset({"corridor", "hall"})


def _through_door_ids(sm) -> set:
    """The unit ids of ``sm``'s units added over rooms seen through their door (``sm.through_door``
    holds their slots)."""
    return {sm.slot_ids[s] for s in sm.through_door if s in sm.slot_ids}


class UnitPieces:
    """Each unit's interior on the input image and its *main piece* (docs/outputs.md, rooms.png
    step 1).

    A unit whose interior holds at least ``small_cells`` image cells is its own main piece, and
    it is its room's seed. A
    smaller one (less than ``min_room_m2``: a doorway, a niche) seeds no room (:meth:`seeds`),
    and can be drawn across a wall, with floor of a room at each end: its main piece is the
    largest part of its interior, by floor cells, that the map's occupied cells leave connected
    (4-neighbours over the cells not occupied), and :meth:`joined` tells whether a passage of it
    joins it to another unit.

    Attributes
    ----------
    units : (H, W) int32, the unit id of each interior cell (a cell inside two interiors: the
        smaller id's, as the seeds always were), 0 elsewhere
    main : (H, W) int32, the unit id on its main piece's cells, 0 elsewhere
    """

    def __init__(self, sm, floor: np.ndarray, open_cells: np.ndarray, small_cells: float):
        wall = sm.frame.cells.wall
        unit_lat = np.zeros(sm.frame.shape, np.int32)
        pass_lat = np.zeros(sm.frame.shape, np.int32)
        for s, uid in sorted(sm.slot_ids.items(), key=lambda kv: kv[1]):
            r0, c0, r1, c1 = (max(int(v), 0) for v in interior(sm.world.rects[s], wall))
            box = unit_lat[r0:r1, c0:c1]
            box[box == 0] = uid
        self._passages: dict[tuple[int, int], list[int]] = {}
        for j, d in enumerate(sm.derived.passages, 1):
            r0, c0, r1, c1 = (max(int(v), 0) for v in d.box)
            pass_lat[r0:r1, c0:c1] = j
            pair = tuple(sorted((sm.slot_ids[d.p], sm.slot_ids[d.q])))
            self._passages.setdefault(pair, []).append(j)
        self.units = sm.frame.to_image(unit_lat, fill=0)
        self._pass = sm.frame.to_image(pass_lat, fill=0)
        self._pass_slices = ndi.find_objects(self._pass)
        self._open = np.asarray(open_cells, bool)
        self.main = np.zeros(self.units.shape, np.int32)
        self._slices, self._small = {}, set()
        for uid, sl in enumerate(ndi.find_objects(self.units), 1):
            if sl is None:
                continue
            self._slices[uid] = sl
            inside = self.units[sl] == uid
            if inside.sum() < small_cells:
                self._small.add(uid)
                inside = self._largest(inside & self._open[sl], np.asarray(floor, bool)[sl])
            self.main[sl][inside] = uid

    def seeds(self) -> np.ndarray:
        """(H, W) int32: the unit id on the cells that seed its room: every unit's main piece but
        a small unit's (its floor joins the room nearest along the floor)."""
        if not self._small:
            return self.main
        return np.where(np.isin(self.main, sorted(self._small)), 0, self.main)

    @staticmethod
    def _largest(cells: np.ndarray, floor: np.ndarray) -> np.ndarray:
        """The 4-connected piece of ``cells`` with the most ``floor`` cells (the first on a tie)."""
        lab, n = ndi.label(cells, _FOUR)
        if n <= 1:
            return cells
        counts = np.bincount(lab[floor & cells], minlength=n + 1)
        counts[0] = -1
        return lab == int(counts.argmax())

    def joined(self, a: int, b: int) -> bool:
        """Whether units ``a`` and ``b`` (ids, joined by a passage) are one floor: True unless one
        of them is small and the open cells of the two interiors and their passages do not join
        the two main pieces."""
        if not self._small & {a, b} or a not in self._slices or b not in self._slices:
            return True
        js = self._passages.get((min(a, b), max(a, b)), [])
        sls = [self._slices[a], self._slices[b]] + [self._pass_slices[j - 1] for j in js
                                                   if self._pass_slices[j - 1] is not None]
        sl = tuple(slice(min(s[k].start for s in sls), max(s[k].stop for s in sls)) for k in (0, 1))
        units, main = self.units[sl], self.main[sl]
        cells = ((units == a) | (units == b) | np.isin(self._pass[sl], js)) & self._open[sl]
        lab, _ = ndi.label(cells, _FOUR)
        in_a, in_b = set(np.unique(lab[main == a])) - {0}, set(np.unique(lab[main == b])) - {0}
        return not (in_a and in_b) or bool(in_a & in_b)


def wall_open(kinds: set, classes: np.ndarray, rp, rq, wall: int, share_min: float) -> bool:
    """Whether the wall between two units of types ``kinds`` (rectangles ``rp``, ``rq``) is open,
    the open side of one space that W* cut in two rather than a wall with a door: at least
    ``share_min`` of its lines are open (:func:`opening_share`), and it is not a corridor's or a
    hall's wall to a room (a room open to the corridor along it is a room of its own)."""
    if _THROUGH_TYPES & kinds and "room" in kinds:
        return False
    return opening_share(classes, rp, rq, wall) >= share_min


def open_walls(derived, world, frame, through_door, params: RoomParams, wall_lines=None):
    """``derived`` with the doors on open walls listed as passages: an opening that takes most of
    the wall two units share (:func:`wall_open`, ``open_share_min``) where no wall line stands
    beside it (:func:`walled_beside`) is no door in a wall but a cut through one space. A door
    at the narrow end of a corridor takes most of its wall too, but the wall beside it is drawn.
    A unit added over a room seen through its door (slots ``through_door``) keeps its doors. On a
    lattice of several directions every door stays a door: a wall at another angle than the
    tile's is no wall line of its lattice, so what stands beside an opening is not read there.
    ``wall_lines``: a callable giving the lattice's wall-like cells (the likelihood's, made once
    per map), called only when a door's wall is open; None: found here."""
    if rect_spans(frame):
        return derived
    keep, opened = [], []
    decided: dict = {}
    lines = None
    for d in derived.doors:
        pair = (min(d.p, d.q), max(d.p, d.q))
        if pair not in decided:
            rp, rq = world.rects[d.p], world.rects[d.q]
            kinds = {UNIT_TYPES[int(world.types[s])] for s in pair}
            decided[pair] = not set(pair) & set(through_door) and wall_open(
                kinds, frame.door_classes, rp, rq, frame.cells.wall, params.open_share_min)
            if decided[pair]:
                if lines is None:
                    c = frame.cells
                    lines = wall_lines() if wall_lines is not None else wall_like(
                        frame.classes == OCCUPIED, c.object_max_extent, c.wall_line_tolerance,
                        c.wall_line_gap)
                decided[pair] = not walled_beside(frame.door_classes, lines, rp, rq, frame.cells.wall)
        (opened if decided[pair] else keep).append(d)
    if not opened:
        return derived
    return derived._replace(doors=keep, passages=list(derived.passages) + opened)


def walled_beside(classes: np.ndarray, lines: np.ndarray, rp, rq, wall: int) -> bool:
    """Whether a wall stands beside the openings of the wall ``rp`` and ``rq`` share: at least half
    of the strip's closed lines (:func:`~semmap_pp.derive.doors.wall_strip`) cross a cell of a wall
    line (``lines``: the likelihood's wall-like cells), not only furniture or a unit's corner."""
    found = wall_strip(classes, rp, rq, wall)
    if found is None:
        return True
    strip, (a0, b0, a1, b1), vertical = found
    axis = 1 if vertical else 0
    closed = ~(strip == FREE).all(axis=axis)
    if not closed.any():
        return False
    walled = np.asarray(lines[a0:a1, b0:b1]).any(axis=axis)
    return 2 * int((closed & walled).sum()) >= int(closed.sum())


def room_joins(sm, params: RoomParams, pieces=None) -> tuple[list[tuple[int, int]], list]:
    """Unit-id pairs one room joins, and the doors that stay doors between rooms.

    Units joined by a passage (:func:`~semmap_pp.semantic.regions.passage_pairs`) are one room; so
    are two units whose door takes at least ``open_share_min`` of the wall they share, unless one
    of them is a corridor or a hall and the other a room: an opening that wide is the open side
    of one space that W* cut in two, not a door in a wall, but a room open to the corridor along
    it is a room of its own. So are two
    units, neither a corridor nor a hall, whose floor meets through a gap wider than a double door
    (``door_max_m``, :func:`wide_opening`): the open side of a room that a partition, a stub of
    wall or a row of cupboards half divides. A corridor's or a hall's openings, however wide, lead
    into the rooms along it. A unit added over a room seen through its door
    (``sm.through_door``) is a room of its own: it joins no other unit. With ``pieces``
    (:class:`UnitPieces`), a passage of a unit too small for a room joins only where the floor
    crosses it (:meth:`UnitPieces.joined`)."""
    ids, rects, classes = sm.slot_ids, sm.world.rects, sm.frame.door_classes
    alone = _through_door_ids(sm)
    wall = sm.frame.cells.wall
    width = params.door_max_m / sm.frame.resolution
    free = None
    pairs = [p for p in passage_pairs(sm) if not alone & set(p)]
    if pieces is not None:
        pairs = [p for p in pairs if pieces.joined(*p)]
    doors, decided = [], {}
    for d in sm.derived.doors:
        pair = tuple(sorted((ids[d.p], ids[d.q])))
        if alone & set(pair):
            decided[pair] = False
        if pair not in decided:
            kinds = {sm.type_of(pair[0]), sm.type_of(pair[1])}
            through = bool(_THROUGH_TYPES & kinds)            # a corridor or a hall
            joined = wall_open(kinds, classes, rects[d.p], rects[d.q], wall, params.open_share_min)
            if not joined and not through:
                free = classes == FREE if free is None else free
                joined = wide_opening(free, rects[d.p], rects[d.q], wall, width)
            decided[pair] = joined
        if decided[pair]:
            pairs.append(pair)
        else:
            doors.append(d)
    return sorted(set(pairs)), doors


def floor_cells(grid, params: RoomParams = RoomParams()) -> np.ndarray:
    """(H, W) bool: the cells rooms.png labels, the cells the robot saw free.

    The free cells, and the cells the map's thresholds call unknown whose occupancy lies nearer to
    the free cells' (their median) than to the map's own unknown value (the occupancy most unknown
    cells hold); within ``wall_blur_m`` of an occupied cell only those whose occupancy is at most
    ``wall_floor_max`` as well. A map saved with graded values holds cells seen free a few times,
    lighter than its unknown grey but above ``free_thresh``: room segmenters and hand-drawn room
    truth count them as floor, along the walls too. A wall's blur, the grey between its black and
    the floor's white, is darker: not floor. A trinary map (only free, unknown and occupied
    values) has no such cells.

    >>> from semmap_pp.grid.occupancy import OccupancyGrid
    >>> g = OccupancyGrid(np.array([[2, 1, 0, 1, 1, 1, 1, 1, 1, 2]], np.uint8),
    ...                   np.array([[1.0, 0.15, 0.0, 0.05, 0.4, 0.4, 0.4, 0.15, 0.05, 1.0]]), 0.05)
    >>> floor_cells(g).astype(int).tolist()     # nearer to free (0) than to unknown (0.4); 0.15 by a wall: its blur
    [[0, 0, 1, 1, 0, 0, 0, 1, 1, 0]]
    >>> floor_cells(g, RoomParams(wall_floor_max=0.0)).astype(int).tolist()   # none beside a wall
    [[0, 0, 1, 1, 0, 0, 0, 1, 0, 0]]
    """
    classes, occ = grid.classes, grid.occupancy
    free = classes == FREE
    unknown = (classes == UNKNOWN) & np.isfinite(occ)
    if not (free.any() and unknown.any()):
        return free
    values, counts = np.unique(occ[unknown], return_counts=True)
    p_unknown, p_free = float(values[counts.argmax()]), float(np.median(occ[free]))
    if p_unknown <= p_free:
        return free
    seen = unknown & (occ < (p_unknown + p_free) / 2)
    blur = int(round(params.wall_blur_m / grid.resolution))
    if blur > 0 and seen.any():
        seen &= (occ <= params.wall_floor_max) | ~ndi.binary_dilation(classes == OCCUPIED, _EIGHT,
                                                                       iterations=blur)
    return free | seen


def rooms_of(sm, params: RoomParams = RoomParams()) -> Rooms:
    """rooms.png's rooms of a :class:`~semmap_pp.semantic.semantic_map.SemanticMap` (module docstring)."""
    classes = sm.grid.classes
    floor = floor_cells(sm.grid, params)
    pieces = UnitPieces(sm, floor, classes != OCCUPIED, params.min_room_m2 / sm.grid.resolution ** 2)
    pairs, doors = room_joins(sm, params, pieces)
    region = join_regions(sm.unit_ids, pairs)
    door_lat = rects_mask([d.box for d in doors], sm.frame.shape)
    lut = region_lut(region, max(sm.unit_ids, default=0) + 1)
    seeds = lut[pieces.seeds()]
    fallback = lut[pieces.units]
    door_img = sm.frame.to_image(door_lat, fill=False)
    apart = _walls_apart_of(sm, params) if params.split_core_m > 0 else None
    labels, found = room_labels(floor, seeds, door_img, sm.grid.resolution, params,
                                occupied=classes == OCCUPIED, fallback=fallback, walls_apart=apart,
                                outside=_exterior_cells(sm))
    units_of: dict[int, list[int]] = {}
    for uid, rid in region.items():
        units_of.setdefault(rid, []).append(uid)
    objs = ndi.find_objects(labels)
    alone = _through_door_ids(sm)
    rooms = []
    for k, rid, n in found:
        units = tuple(units_of.get(rid, ())) if rid else ()
        rooms.append(Room(k, units, n, seen_share(labels[objs[k - 1]] == k),
                          bool(units) and set(units) <= alone))
    rooms = tuple(rooms)
    return Rooms(labels, rooms)


def _exterior_cells(sm) -> np.ndarray | None:
    """(H, W) bool: the image cells of W*'s exterior units (their rectangles, on their tiles);
    None without any."""
    if not sm.derived.exterior:
        return None
    rects = [sm.world.rects[e.slot] for e in sm.derived.exterior]
    return sm.frame.to_image(rects_mask(rects, sm.frame.shape), fill=False)


def through_door_boxes(sm) -> list[tuple[int, int, int, int]]:
    """The lattice rectangle ``(r0, c0, r1, c1)`` of each room of ``sm.rooms`` seen through its
    door that no unit covers: the bounding box of its cells on the lattice, with the wall band
    around it, clipped to the lattice; largest room first. What the run proposes to add to W*
    (:func:`semmap_pp.sampler.ascent.add_units`: kept only where the target gains)."""
    frame, rooms = sm.frame, sm.rooms
    wall = int(frame.cells.wall)
    h, w = frame.shape
    boxes = []
    for room in sorted((r for r in rooms.rooms if r.seen_through_door), key=lambda r: -r.cells):
        ys, xs = np.nonzero(rooms.labels == room.id)
        rows, cols = frame.image_to_lattice(xs, ys)
        r0, c0 = int(np.rint(rows.min())) - wall, int(np.rint(cols.min())) - wall
        r1, c1 = int(np.rint(rows.max())) + 1 + wall, int(np.rint(cols.max())) + 1 + wall
        boxes.append((max(r0, 0), max(c0, 0), min(r1, h), min(c1, w)))
    return boxes


__all__ = ["Room", "Rooms", "room_labels", "split_cores", "walls_apart", "through_door_boxes", "room_joins", "rooms_of", "opening_share", "seen_share", "wide_opening",
           "geodesic_flood"]
