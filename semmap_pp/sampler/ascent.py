"""Greedy ascent of a target with the kernels' own moves: the start world's refinement and W*'s
final polish.

The greedy cover of :mod:`semmap_pp.sampler.start_worlds` only sees free cells: a room whose walls are lined with
furniture comes out short of its walls, the pieces of free space between the furniture become units
of their own, and ray fans seen through windows become units outside the building. The sampler could
repair all that, but with knowledge on every proposal costs a knowledge inference; the
knowledge-free target (types from the geometry class, fixed P(SaLe)) costs a few hundred
microseconds. So the start world is the local optimum of that target reached by the kernels' own
moves, each taken only when it raises log p: remove a unit, move one wall to a nearby position or to
a line of wall evidence (SHRINK/DILATE), merge two units that share a wall (MERGE), add a unit from
the birth table where free space is left uncovered (ADD), split a unit at a wall line (SPLIT); and
one compound move no single kernel makes, *bridging* two collinear pieces of a corridor across the
unit between them (:meth:`_Ascent.bridges`); in W*'s polish also four more, recutting an L-shaped
pair the other way (:meth:`_Ascent.recuts`), moving every edge on one wall together
(:meth:`_Ascent.shared_wall_moves`), cutting a unit where a neighbour's wall jogs
(:meth:`_Ascent.jogs`) and cutting it along both axes at once into four spaces
(:meth:`_Ascent.crosses`), and two fewer: the start ascent cuts a unit twice at once when no single
cut helps (a room inside an L of walls) and adds units over uncovered free space (births), W*'s
polish cuts once, all along a plateau of line evidence, and adds none (:func:`polish`).

After sampling, the same ascent under the full target (knowledge on) polishes W*, the best sampled
world: a short chain at T = 1 leaves it a few wall moves or one merge short of the nearest local
maximum (on the 30 synthetic floors the polish raised log p on most floors, by up to 700 nats;
docs/quality.md). The search is greedy, so it proves nothing and never lowers log p; it changes
neither the chains nor their diagnostics, only the world reported as W*.

A split or a birth needs an empty slot: when every slot holds a unit, the ascent doubles the
world's capacity (:func:`semmap_pp.world.grow`, up to :data:`MAX_CAPACITY`), so a building with more
units than ``[prior] k_max`` is not cut off at that number (docs/model.md, "Prior"). A result that
fits the capacity it started with is returned in it (:func:`semmap_pp.world.fit`): the slot term of
the log posterior, ``-log C(K, n)``, depends on the capacity K.
"""

from __future__ import annotations

import numpy as np

from semmap_pp import world as wm
from semmap_pp.sampler.ascent_cuts import CutMoves
from semmap_pp.sampler.ascent_joins import JoinMoves
from semmap_pp.sampler.ascent_walls import MAX_CAPACITY, PEAKS_RESOLUTION, ascent_peaks

__all__ = ["MAX_CAPACITY", "PEAKS_RESOLUTION", "add_units", "align_walls", "ascent_peaks", "polish",
           "refine_world", "snap_walls"]


class _Ascent(JoinMoves, CutMoves):
    """Greedy ascent: the state and wall moves (:mod:`~semmap_pp.sampler.ascent_walls`), the joins
    (:mod:`~semmap_pp.sampler.ascent_joins`), the cuts and births
    (:mod:`~semmap_pp.sampler.ascent_cuts`)."""


def refine_world(posterior, world: wm.World, data, *, rounds: int = 3, births: bool = True,
                 merges: bool = True, recuts: bool = False, shared_walls: bool = False,
                 double_cuts: bool = True, wide_cuts: bool = False, jogs: bool = False,
                 crosses: bool = False, fork: bool = False, memo: bool = False) -> wm.World:
    """Greedy ascent of ``posterior`` from ``world`` with the kernels' moves (module docstring);
    ``merges=False`` leaves out the merges and the bridges, ``recuts=True`` adds the recuts of
    L-shaped pairs (:meth:`_Ascent.recuts`), ``shared_walls=True`` the moves of whole walls
    (:meth:`_Ascent.shared_wall_moves`), ``double_cuts=False`` the second cut of a piece when no
    single cut helps, ``wide_cuts=True`` cuts all along a plateau of line evidence
    (:meth:`_Ascent.splits`), ``jogs=True`` the jogs last (:meth:`_Ascent.jogs`), each followed
    by the joining moves, ``crosses=True`` the cuts along both axes at once after the splits
    (:meth:`_Ascent.crosses`); W*'s polish is :func:`polish`. ``fork``: the crosses try half their
    units in a forked process meanwhile (two cores; the same result:
    :meth:`~semmap_pp.sampler.ascent_walls.Climb.each`); ``memo``: the crosses, merges and bridges
    keep their failed tries (:class:`~semmap_pp.sampler.ascent_walls.FailedTries`).

    Parameters
    ----------
    posterior : Posterior
        The target to climb: the knowledge-free one (``knowledge_on = False``) for a start world,
        the full one for W*'s polish.
    world : World
        The start (e.g. :func:`~semmap_pp.sampler.start_worlds.start_world`, or W*).
    data : KernelData
        The kernels' data of the same lattice (line evidence, birth table).
    rounds : int
        Passes of removals, wall moves, merges, bridges, splits and births (stops early when nothing
        changes); with ``shared_walls`` also the bound on the passes of whole-wall moves, and on
        how often the phases alternate: after whole walls moved, the moves that join or drop
        units (removals, wall moves, merges, bridges) run again, since a moved wall may open a
        merge; splits, recuts and births do not (CHANGELOG.md, quality change 33).

    Returns
    -------
    World
        A world whose log posterior is at least that of ``world`` (types left undecided)."""
    asc = _Ascent(posterior, world, data)
    asc.fork = fork
    asc.tries = {} if memo else None
    if not np.isfinite(asc.tr.logp):
        return world

    def one_round() -> bool:     # each move in turn (`|` runs every one; `and` skips those off)
        changed = asc.removals() | asc.all_wall_moves() | asc.removals()
        changed |= (merges and (asc.merges() | asc.bridges())) | (recuts and asc.recuts())
        changed |= asc.splits(double_cuts, wide_cuts) | (crosses and asc.crosses())
        return changed | (births and asc.births())

    def join_round() -> bool:     # after whole walls moved: nothing cut, nothing born
        changed = asc.removals()
        changed |= asc.all_wall_moves()
        if merges:
            changed |= asc.merges()
            changed |= asc.bridges()
        return changed

    for phase in range(rounds if shared_walls else 1):
        for _ in range(rounds):
            if not (one_round() if phase == 0 else join_round()):
                break
        if not shared_walls:
            break
        walls_moved = False   # from where the other moves stop: the same world or a better one
        for _ in range(rounds):
            moved = asc.shared_wall_moves()
            if not moved:
                break
            walls_moved = True
            asc.all_wall_moves(asc.near(moved))   # the walls the moved ones may have unblocked
        if not walls_moved:   # else the joining moves again: a moved wall may open a merge
            break
    for _ in range(rounds if jogs else 0):   # last: only where the moves above left a wall jogging
        if not asc.jogs():
            break
        join_round()
    out = asc.untyped()
    if out.capacity > world.capacity and wm.n_units(out) <= world.capacity:
        out = wm.fit(out, world.capacity)   # grown on the way but fits again: the caller's slots
    return out


def polish(posterior, world: wm.World, data, rounds: int, fork: bool = False) -> wm.World:
    """W*'s polish: :func:`refine_world` of the full target with the recuts and the whole-wall
    moves, without double cuts and births. The knowledge-free start ascent cuts rooms out of
    L-shaped walls with two cuts and covers free space by births already; in the polish, under a
    rule file off the fast path, the second cuts took two thirds of its time on cartesium and the
    births a third on aces. Without the double cuts no W* of the 30 synthetic floors, the ipa
    types plans, cartesium, aces or freiburg-079 changed (CHANGELOG.md, quality change 35);
    without the births too, no W* measured changed at all (quality change 36).

    Its single cuts are wide (:func:`~semmap_pp.sampler.ascent_cuts._wall_runs`): a plateau of
    line evidence (a cupboard against a wall) is tried all along and a few steps past its ends,
    where the three strongest peaks can be three neighbouring lines of one wall (lab_d_furnitures: the
    room over the corridor is cut at its wall, and the corridor's pieces are joined by open
    passages). The start ascent keeps the peaks: wide cuts there, where the double cuts try every
    pair of them, made it up to 13 times as slow (CHANGELOG.md, "W*'s polish cuts along plateaus of line
    evidence"). ``fork``: as :func:`refine_world`'s; its crosses, merges and bridges keep their
    failed tries (``memo``)."""
    return refine_world(posterior, world, data, rounds=rounds, recuts=True, shared_walls=True,
                        double_cuts=False, births=False, wide_cuts=True, jogs=True, crosses=True,
                        fork=fork, memo=True)


def add_units(posterior, world: wm.World, data, boxes) -> tuple[wm.World, list[int]]:
    """Each of ``boxes`` (lattice rectangles ``(r0, c0, r1, c1)``, walls included) added to
    ``world`` as a unit, its walls then moved to their best positions (:meth:`_Ascent.tentative`),
    and kept only when the log posterior rises: a proposal from outside the kernels' birth table
    (the run proposes the rooms that rooms.png finds seen through their door and no unit covers:
    a fan of rays into a room has no large empty box for the birth table to find). Returns the
    world, whose log posterior is at least ``world``'s (types left undecided), and the slots of
    the units kept; ``(world, [])`` when ``world``'s log posterior is not finite or no box is
    kept."""
    asc = _Ascent(posterior, world, data)
    if not np.isfinite(asc.tr.logp):
        return world, []
    born = []
    for box in boxes:
        slot = int(asc.free(1)[0])
        if asc.tentative(wm.add(asc.world, slot, tuple(int(v) for v in box)), (slot,), [slot]):
            born.append(slot)
    if not born:
        return world, []
    out = asc.untyped()
    return out, [s for s in born if out.active[s]]


def snap_walls(posterior, world: wm.World, data, slots, *, reach: int, rounds: int = 2) -> wm.World:
    """Each wall of the units in ``slots`` to its best position within ``reach`` cells of where it
    is (local steps only, no line peak farther away, no unit swallowed), for up to ``rounds``
    passes: the walls of a hand-edited world (``semmap edit``) set on the map's own lines near
    the points given. Returns a world whose log posterior is at least that of ``world``, or
    ``world`` itself when its log posterior is not finite or ``reach`` is 0."""
    if reach <= 0:
        return world
    asc = _Ascent(posterior, world, data, peaks=0, local=int(reach), absorb_share=2.0)
    return _wall_rounds(asc, world, rounds, {int(s) for s in slots})


def align_walls(posterior, world: wm.World, data, *, rounds: int = 3) -> wm.World:
    """Wall moves only: each wall of each unit to its best position, for up to ``rounds`` passes.

    Sets given rectangles (a ground truth drawn in another frame, a hand-made world) on the
    lattice's best walls without adding, removing, merging or cutting units — except that a wall
    moved outwards may swallow a unit lying mostly inside the grown one (:meth:`_Ascent.wall_moves`).
    Returns a world whose log posterior is at least that of ``world`` (types left undecided), or
    ``world`` itself when its log posterior is not finite.
    """
    return _wall_rounds(_Ascent(posterior, world, data), world, rounds)


def _wall_rounds(asc: _Ascent, world: wm.World, rounds: int, within=None) -> wm.World:
    """Up to ``rounds`` passes of ``asc``'s wall moves (of the units in ``within``, when given)
    from ``world``, stopping when a pass moves nothing; ``world`` when its log p is not finite."""
    if not np.isfinite(asc.tr.logp):
        return world
    for _ in range(rounds):
        if not asc.all_wall_moves(within):
            break
    return asc.untyped()
