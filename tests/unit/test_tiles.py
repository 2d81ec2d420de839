"""The tiled lattice of a building of several directions (semmap_pp.lattice.tiles): its maps
between lattice and image, the prior's support of one tile per unit, exact detailed balance and
incremental = full target across two tiles, and what units of two tiles share (derive.crossing)."""

import dataclasses
import math

import numpy as np
import pytest
from scipy import sparse
from scipy.sparse import csgraph

from semmap_pp import cells
from semmap_pp import world as wm
from semmap_pp.derive import derive_world
from semmap_pp.derive.crossing import cross_data, cross_tile_openings, grown_overlap
from semmap_pp.lattice.frame import build_frame_from_classes
from semmap_pp.lattice.tiles import TiledFrame, build_tiled_frame, rect_spans, tile_gap, unit_theta
from semmap_pp.model import load_model
from semmap_pp.sampler.kernels import build_data, default_mix
from semmap_pp.target.posterior import Posterior
from semmap_pp.target.prior import log_p_rect_const, n_rects, rect_faults, rects_valid
from standin import TableTarget
from test_kernels_balance import SETTINGS, all_states, tiny_classes, transition_matrix
from test_posterior import recorded_bounds

MODEL = load_model()


def two_zone_map(rng, shape=(160, 260), theta=0.5, model=MODEL):
    classes = rng.choice(3, size=shape, p=[0.6, 0.25, 0.15]).astype(np.uint8)
    zones = np.zeros(shape, np.uint8)
    zones[:, shape[1] // 2:] = 1
    return classes, zones, build_tiled_frame(classes, 0.05, model, (0.0, theta), zones)


def test_one_direction_is_the_plain_frame():
    classes = np.random.default_rng(0).choice(3, size=(60, 80)).astype(np.uint8)
    f = build_tiled_frame(classes, 0.05, MODEL, (0.2,), np.zeros((60, 80), np.uint8))
    g = build_frame_from_classes(classes, 0.05, MODEL, theta=0.2)
    assert not isinstance(f, TiledFrame) and rect_spans(f) == ()
    assert np.array_equal(f.classes, g.classes) and f.theta == g.theta


@pytest.mark.parametrize("samples", [1, 2])
def test_every_lattice_cell_shows_its_own_pixel_and_maps_back(samples):
    """Each cell shows the pixel under its centre; with sub-cells (``[lattice] wall_samples``, the
    default 2) a cell that closes a gap in a wall may be occupied too, on the turned tile only."""
    model = dataclasses.replace(MODEL, lattice=dataclasses.replace(MODEL.lattice, wall_samples=samples))
    classes, zones, f = two_zone_map(np.random.default_rng(1), model=model)
    assert isinstance(f, TiledFrame) and len(f.spans) == 2
    (a0, a1), (b0, b1) = f.spans
    assert b0 - a1 == tile_gap(f.cells)
    for b0_, b1_ in f.bands():
        xi, yi, inside = f.lattice_pixels(b0_, b1_)
        assert np.array_equal(inside, ~f.outside[b0_:b1_])
        shown, pixel = f.classes[b0_:b1_][inside], classes[yi[inside], xi[inside]]
        cols = np.nonzero(inside)[1]
        differ = shown != pixel
        assert np.all(shown[differ] == cells.OCCUPIED) and np.all(cols[differ] >= b0)
        assert samples > 1 or not differ.any()
    rr, cc = np.nonzero(~f.outside)
    x, y = f.lattice_to_image(rr, cc)
    k = np.searchsorted([b0], cc, side="right")
    assert np.array_equal(zones[np.rint(y).astype(int), np.rint(x).astype(int)], k)
    r2, c2 = f.image_to_lattice(x, y)
    assert np.allclose(r2, rr) and np.allclose(c2, cc)


def test_a_units_corners_and_orientation_are_its_tiles():
    _, _, f = two_zone_map(np.random.default_rng(2), theta=0.5)
    (a0, _), (b0, _) = f.spans
    for rect, theta in (((5, a0 + 4, 30, a0 + 40), 0.0), ((12, b0 + 6, 44, b0 + 31), 0.5)):
        v = f.rect_vertices_px(rect)
        side = v[1] - v[0]
        assert math.atan2(side[1], side[0]) == pytest.approx(theta)
        assert unit_theta(f, rect) == pytest.approx(theta)
        back, off = f.rect_from_vertices_px(v.round(3))
        assert back == rect and off < 0.01


def test_to_image_paints_each_pixel_from_its_zones_tile():
    classes, zones, f = two_zone_map(np.random.default_rng(3))
    img = f.to_image(f.classes, fill=cells.UNKNOWN)
    away = np.ones(zones.shape, bool)       # the zones' edge aside (a cell there is the other zone's)
    away[:, zones.shape[1] // 2 - 3:zones.shape[1] // 2 + 3] = False
    for k, theta in enumerate((0.0, 0.5)):
        plain = build_frame_from_classes(classes, 0.05, MODEL, theta=theta)
        mine = away & (zones == k)
        assert np.array_equal(img[mine], plain.to_image(plain.classes, fill=cells.UNKNOWN)[mine])
    box = (10, f.spans[1][0] + 5, 40, f.spans[1][0] + 50)
    part = f.box_to_image(np.ones((30, 45), np.uint8), box, fill=0)
    full = np.zeros(f.shape, np.uint8)
    full[10:40, box[1]:box[3]] = 1
    assert np.array_equal(part, f.to_image(full, fill=0))


def test_the_priors_support_is_one_tile():
    spans = ((0, 7), (10, 16))
    shape, lo, hi = (9, 16), 3, 6
    rects = [(r0, c0, r1, c1) for r0 in range(10) for r1 in range(10) for c0 in range(17)
             for c1 in range(17)]
    valid = rects_valid(np.array(rects), shape, lo, hi, spans)
    assert valid.sum() == n_rects(9, lo, hi) * (n_rects(7, lo, hi) + n_rects(6, lo, hi))
    assert log_p_rect_const(shape, lo, hi, spans) == pytest.approx(-math.log(valid.sum()))
    for rect, ok in zip(rects, valid):
        assert (not rect_faults(rect, shape, lo, hi, spans)) == ok
    assert "straddles" in rect_faults((0, 5, 4, 11), shape, lo, hi, spans)


@pytest.mark.slow
@pytest.mark.filterwarnings("ignore:invalid value:RuntimeWarning")   # -inf - -inf from a state off the support
def test_detailed_balance_and_irreducibility_within_two_tiles():
    """The kernels on a lattice of two tiles (columns 0..2 and 4..6, column 3 the gap), the target
    zero on a unit across them: balance holds for every pair of states, and every state of the
    support reaches every other (a unit goes from one tile to the other by death and birth)."""
    classes = tiny_classes((3, 7))
    classes[:, 3] = cells.UNKNOWN
    data = build_data(classes, min_side=2, wall_cells=1, max_side=3, door_min=1, door_max=1,
                      settings=SETTINGS)
    spans = ((0, 3), (4, 7))
    states = all_states(data, 2)
    target = TableTarget(np.random.default_rng(5), 2)
    ok = np.array([rects_valid(s.rects[s.active], data.shape, 2, 3, spans).all() for s in states])
    logpi = np.array([target.evaluate(s) if good else -math.inf for s, good in zip(states, ok)])
    pi = np.exp(logpi - logpi.max())
    pi /= pi.sum()
    p, _ = transition_matrix(states, data, default_mix(SETTINGS), logpi)
    flow = sparse.diags(pi) @ p
    assert abs(flow - flow.T).max() < 1e-12 * abs(flow).max()
    assert np.max(np.abs(pi @ p - pi)) < 1e-12 * pi.max()
    inside = np.flatnonzero(ok)
    n_comp, _ = csgraph.connected_components(p[inside][:, inside], directed=True, connection="strong")
    assert n_comp == 1 and ok.sum() < len(states)


@pytest.mark.slow
def test_incremental_target_equals_the_full_one_on_two_tiles():
    rng = np.random.default_rng(11)
    _, _, f = two_zone_map(rng, shape=(140, 240))
    post = Posterior(f, MODEL)
    (a0, a1), (b0, b1) = f.spans
    h = f.shape[0]

    def rect():
        lo_, hi_ = (a0, a1) if rng.random() < 0.5 else (b0, b1)
        hh, ww = int(rng.integers(21, 60)), int(rng.integers(21, min(60, hi_ - lo_)))
        r0, c0 = int(rng.integers(0, h - hh + 1)), int(rng.integers(lo_ - 8, hi_ - ww + 9))
        return (r0, c0, r0 + hh, c0 + ww)

    w = wm.empty(6)
    for s in range(4):
        w = wm.add(w, s, rect())
    tr = post.start(w)
    across = 0
    for _ in range(300):
        s = int(rng.integers(w.capacity))
        nw = wm.remove(tr.world, s) if tr.world.active[s] and rng.random() < 0.2 else wm.replace(tr.world, s, rect()) if tr.world.active[s] else wm.add(tr.world, s, rect())
        prop = tr.propose(nw, [s])
        full = post.evaluate(nw).total
        across += math.isinf(full)
        assert (prop.logp == full) if math.isinf(full) else prop.logp == pytest.approx(full, rel=1e-9)
        if math.isfinite(prop.logp) and rng.random() < 0.7:
            tr.accept(prop)
    assert across > 0      # units across the gap or a tile's edge did occur, and scored -inf


def corridor_map(theta_deg=30.0, door=False):
    """A horizontal corridor (zone 0) that turns into one at ``theta_deg`` (zone 1) at x = 150; with
    ``door``, a wall across the turn with a door in it."""
    h, w = 300, 400
    classes = np.full((h, w), cells.UNKNOWN, np.uint8)
    yy, xx = np.mgrid[0:h, 0:w]
    t = math.radians(theta_deg)
    u, v = (xx - 150) * math.cos(t) + (yy - 150) * math.sin(t), -(xx - 150) * math.sin(t) + (yy - 150) * math.cos(t)
    left = (xx < 150) & (xx >= 20) & (abs(yy - 150) <= 22)
    right = (xx >= 150) & (u >= 0) & (u < 200) & (abs(v) <= 22)
    classes[left | right] = cells.OCCUPIED
    classes[(left & (abs(yy - 150) <= 19) & (xx >= 23)) | (right & (abs(v) <= 19) & (u < 197))] = cells.FREE
    if door:
        classes[(abs(xx - 150) <= 1) & (abs(yy - 150) <= 22) & (abs(yy - 150) > 8)] = cells.OCCUPIED
    zones = (xx >= 150).astype(np.uint8)
    return classes, zones, (0.0, t)


def corridor_units(f, thetas):
    """The two corridor units of :func:`corridor_map`, one on each tile."""
    def unit(k, xs, ys):      # the lattice rectangle of tile k over pixel centres (xs, ys)
        r, c = f.tile_image_to_lattice(k, np.asarray(xs, float), np.asarray(ys, float))
        return (int(round(r.min())), int(round(c.min())), int(round(r.max())) + 1, int(round(c.max())) + 1)

    rect0 = unit(0, [20, 149], [128, 172])
    u, v = np.array([0.0, 199.0, 0.0, 199.0]), np.array([-22.0, -22.0, 22.0, 22.0])
    t = thetas[1]
    rect1 = unit(1, 150 + u * math.cos(t) - v * math.sin(t), 150 + u * math.sin(t) + v * math.cos(t))
    return rect0, rect1


@pytest.mark.parametrize("door", [False, True])
def test_a_corridor_cut_by_the_zones_is_one_passage_and_a_wall_across_it_a_door(door):
    classes, zones, thetas = corridor_map(door=door)
    f = build_tiled_frame(classes, 0.05, MODEL, thetas, zones)
    rect0, rect1 = corridor_units(f, thetas)
    assert f.tile_of_rect(rect0) == 0 and f.tile_of_rect(rect1) == 1
    w = wm.add(wm.add(wm.empty(2), 0, rect0), 1, rect1)
    d = derive_world(f, w)
    assert d.adjacency[0, 1] and d.adjacency[1, 0]
    if door:
        assert len(d.doors) == 1 and not d.passages and d.doors[0].width < 30
    else:
        assert len(d.passages) == 1 and not d.doors


def test_a_gap_without_jambs_at_the_zones_boundary_is_no_door():
    """The door of :func:`corridor_map` with its wall made unknown (the free rays of a fan seen
    across the boundary end at unseen cells, not at a wall): no door. The door in the wall stays
    a door, and the corridor cut by the zones a passage, whether or not its walls touch it."""
    classes, zones, thetas = corridor_map(door=True)
    wall = (abs(np.mgrid[0:300, 0:400][1] - 150) <= 1) & (classes == cells.OCCUPIED)
    unseen = classes.copy()
    unseen[wall] = cells.UNKNOWN
    for grid, doors in ((classes, 1), (unseen, 0)):
        f = build_tiled_frame(grid, 0.05, MODEL, thetas, zones)
        rect0, rect1 = corridor_units(f, thetas)
        d = derive_world(f, wm.add(wm.add(wm.empty(2), 0, rect0), 1, rect1))
        assert len(d.doors) == doors and not d.passages
    open_side, zones, thetas = corridor_map(door=False)
    open_side[(open_side == cells.OCCUPIED) & (abs(np.mgrid[0:300, 0:400][1] - 150) <= 3)] = cells.UNKNOWN
    f = build_tiled_frame(open_side, 0.05, MODEL, thetas, zones)
    rect0, rect1 = corridor_units(f, thetas)
    d = derive_world(f, wm.add(wm.add(wm.empty(2), 0, rect0), 1, rect1))
    assert len(d.passages) == 1 and not d.doors


def test_a_doorway_is_one_door_between_the_units_nearest_to_it():
    """The door of :func:`corridor_map` with the corridor unit ending short of the wall and a
    second unit of the same tile inside it, farther from the doorway: both lie within a door's
    width of the doorway's pixels and neither covers them, but the doorway joins the space across
    the wall to the nearer one only (each boundary pixel goes to the nearest unit of each tile)."""
    classes, zones, thetas = corridor_map(door=True)
    f = build_tiled_frame(classes, 0.05, MODEL, thetas, zones)
    rect0, rect1 = corridor_units(f, thetas)
    short = (rect0[0], rect0[1], rect0[2], rect0[3] - 10)
    inner = (short[0] + 8, short[1] + 40, short[2] - 8, short[3] - 4)
    w = wm.add(wm.add(wm.add(wm.empty(3), 0, short), 1, rect1), 2, inner)
    d = derive_world(f, w)
    assert [(x.p, x.q) for x in d.doors] == [(0, 1)] and not d.passages
    # the inner unit alone on its tile (no nearer one): the doorway is its door
    d = derive_world(f, wm.add(wm.add(wm.empty(3), 1, rect1), 2, inner))
    assert [(x.p, x.q) for x in d.doors] == [(1, 2)]


class OpeningsProvider:
    """A stand-in engine whose types read every part of the evidence that units of two tiles
    change: corridor-like units (corridor pieces included) are corridors, MulDoor ones other,
    units with two or more neighbours halls, the rest rooms; P(SaLe) 0.9 for every adjacent pair."""

    needs_doors = True

    def infer(self, ev):
        from semmap_pp.target.geometry_evidence import FixedResult
        deg = {u: 0 for u in ev.units}
        for p, q in ev.adj:
            deg[p] += 1
            deg[q] += 1
        colike = {u for u, pr in ev.colike if pr > 0.5}
        many = {u for u, pr in ev.muldoor if pr > 0.5}
        names = {u: "corridor" if u in colike else "other" if u in many else
                 "hall" if deg[u] >= 2 else "room" for u in ev.units}
        eye = np.eye(4)
        return FixedResult({u: eye[cells.UNIT_TYPES.index(n)] for u, n in names.items()},
                           {pq: 0.9 for pq in ev.adj}, names)


def _near_the_boundary(rng, f, base):
    """A random unit near the zones' boundary: one of ``base`` with its sides moved, or a small
    unit around a point near the turn, on the tile of the point's side."""
    if rng.random() < 0.6:
        r = list(base[int(rng.integers(len(base)))])
        for k in range(4):
            r[k] += int(rng.integers(-14, 15))
        return tuple(r)
    x, y = 150 + rng.uniform(-45, 45), 150 + rng.uniform(-45, 45)
    k = int(x >= 150)
    r, c = f.tile_image_to_lattice(k, np.array([x]), np.array([y]))
    h, w = int(rng.integers(21, 40)), int(rng.integers(21, 40))
    return (int(r[0]) - h // 2, int(c[0]) - w // 2, int(r[0]) - h // 2 + h, int(c[0]) - w // 2 + w)


def _corridor_tracker(knowledge):
    """``(frame, posterior, base units, tracker)`` on the turn of :func:`corridor_map`, the
    tracker started at its two corridor units; knowledge from :class:`OpeningsProvider` or off."""
    classes, zones, thetas = corridor_map()
    f = build_tiled_frame(classes, 0.05, MODEL, thetas, zones)
    post = Posterior(f, MODEL, OpeningsProvider() if knowledge else None)
    post.knowledge_on = knowledge
    base = corridor_units(f, thetas)
    return f, post, base, post.start(wm.add(wm.add(wm.empty(5), 0, base[0]), 1, base[1]))


def _edit_near_the_boundary(rng, f, base, old):
    """``(slot, world)``: ``old`` with a random slot removed, moved or born near the boundary."""
    s = int(rng.integers(old.capacity))
    nw = (wm.remove(old, s) if old.active[s] and rng.random() < 0.2
          else wm.replace(old, s, _near_the_boundary(rng, f, base)) if old.active[s]
          else wm.add(old, s, _near_the_boundary(rng, f, base)))
    return s, nw


@pytest.mark.slow
@pytest.mark.parametrize("knowledge", [False, True])
def test_incremental_relations_across_tiles_equal_the_full_ones(knowledge):
    """Units of two tiles near the turn of :func:`corridor_map` edited at random: the tracker's
    adjacency, openings of pairs of two tiles, types and log posterior equal a full evaluation
    after every edit, while pairs of two tiles become and stop being adjacent, and a third unit's
    edit changes the openings of a pair it does not hold."""
    rng = np.random.default_rng(4)
    f, post, base, tr = _corridor_tracker(knowledge)
    seen = {"cross": 0, "flips": 0, "third": 0}
    for _ in range(400):
        s, nw = _edit_near_the_boundary(rng, f, base, tr.world)
        prop = tr.propose(nw, [s])
        full = post.evaluate(nw)
        assert (prop.logp == full.total) if math.isinf(full.total) else \
            prop.logp == pytest.approx(full.total, rel=1e-9, abs=0)
        adj, cross = post.relations(nw)
        assert np.array_equal(prop.typing.adj, adj) and np.array_equal(prop.typing.cross, cross)
        assert np.array_equal(prop.world.types, full.world.types)
        tiles = np.array([f.tile_of_rect(r) for r in nw.rects])
        two = nw.active[:, None] & nw.active[None, :] & (tiles[:, None] != tiles[None, :])
        seen["cross"] += int((adj & two).any())
        seen["flips"] += int(((adj != tr._typ.adj) & two).any())
        others = np.ones(adj.shape, bool)
        others[s, :] = others[:, s] = False
        seen["third"] += int(((cross != tr._typ.cross).any(axis=2) & others).any())
        if math.isfinite(prop.logp) and rng.random() < 0.7:
            tr.accept(prop)
    assert seen["cross"] > 50 and seen["flips"] > 20 and seen["third"] > 0, seen


def _nudged(rng, rect):
    """``rect`` with one or two of its sides moved by 1 to 4 cells (a SHRINK/DILATE-like edit)."""
    r = list(rect)
    for k in rng.choice(4, size=int(rng.integers(1, 3)), replace=False).tolist():
        r[k] += int(rng.choice([-4, -3, -2, -1, 1, 2, 3, 4]))
    return tuple(r)


def test_relations_across_tiles_follow_small_moves_and_edits_of_two_slots():
    """Pairs of two tiles keep their relation unless a pixel's candidacy, their overlap or a
    shorter side changes (derive.crossing.cross_update): on the turn of :func:`corridor_map`,
    edits that move one or two sides of a unit by a few cells (two units far from the corridor's
    free pixels among them, related by their grown rectangles alone), and edits of two slots at once
    (two units nudged, one nudged and one born or removed), leave the tracker's adjacency and
    openings equal to a full evaluation after every edit, while pairs holding an edited unit
    keep openings and change them."""
    rng = np.random.default_rng(7)
    f, post, base, _ = _corridor_tracker(False)
    w = wm.add(wm.add(wm.empty(7), 0, base[0]), 1, base[1])
    for s in range(2, 5):         # more units near the turn
        w = wm.add(w, s, _near_the_boundary(rng, f, base))
    for s, k, x in ((5, 0, 135.0), (6, 1, 165.0)):   # two far from the corridor's free pixels,
        r, c = f.tile_image_to_lattice(k, np.array([x]), np.array([60.0]))   # facing across the turn
        w = wm.add(w, s, (int(r[0]) - 10, int(c[0]) - 10, int(r[0]) + 10, int(c[0]) + 10))
    tr = post.start(w)
    seen = {"kept": 0, "changed": 0, "two": 0, "overlap": 0}
    for _ in range(500):
        old = tr.world
        units = np.flatnonzero(old.active)
        s = int(rng.choice(units))
        nw = wm.replace(old, s, _nudged(rng, old.rects[s]))
        changed = [s]
        if rng.random() < 0.4:
            t = int(rng.integers(old.capacity))
            if t != s:
                nw = (wm.replace(nw, t, _nudged(rng, old.rects[t])) if old.active[t] and rng.random() < 0.6
                      else wm.remove(nw, t) if old.active[t] else wm.add(nw, t, _near_the_boundary(rng, f, base)))
                changed.append(t)
                seen["two"] += 1
        prop = tr.propose(nw, changed)
        adj, cross = post.relations(nw)
        assert np.array_equal(prop.typing.adj, adj) and np.array_equal(prop.typing.cross, cross)
        full = post.evaluate(nw).total
        assert (prop.logp == full) if math.isinf(full) else prop.logp == pytest.approx(full, rel=1e-9, abs=0)
        held = cross[s].sum(axis=1) > 0
        seen["kept"] += int((held & (cross[s] == tr._typ.cross[s]).all(axis=1)).sum())
        seen["changed"] += int(((cross[s] != tr._typ.cross[s]).any(axis=1)).sum())
        seen["overlap"] += int(adj[5, 6] != tr._typ.adj[5, 6])
        if math.isfinite(prop.logp) and rng.random() < 0.7:
            tr.accept(prop)
    assert seen["kept"] > 50 and seen["changed"] > 10 and seen["two"] > 100 and seen["overlap"] > 5, seen


@pytest.mark.slow
@pytest.mark.parametrize("knowledge", [False, True])
def test_a_floor_skips_a_proposal_across_tiles_only_below_its_bound(knowledge, monkeypatch):
    """With a floor (MH with the uniform drawn first) on a tiled lattice, a proposal comes back
    unevaluated only when its full log posterior lies below the floor, and otherwise is the full
    evaluation; the bound taken before the relations of pairs of two tiles (the fixed provider's
    without those pairs, the type-free one with knowledge) is never below the full value. Both
    skips and full evaluations occur, near the zones' boundary of :func:`corridor_map`."""
    seen = recorded_bounds(monkeypatch, "_type_free_bound" if knowledge else "_fixed_bound")
    rng = np.random.default_rng(9)
    f, post, base, tr = _corridor_tracker(knowledge)
    counts = {"skipped": 0, "full": 0}
    for _ in range(300):
        s, nw = _edit_near_the_boundary(rng, f, base, tr.world)
        full = post.evaluate(nw).total
        if not math.isfinite(full):
            continue
        floor = full + float(rng.uniform(-100.0, 600.0))
        n_seen = len(seen)
        prop = tr.propose(nw, [s], floor=floor)
        if len(seen) > n_seen:
            assert seen[-1] + 1e-9 * abs(seen[-1]) >= full, (seen[-1], full)
        if prop.bounded:
            counts["skipped"] += 1
            assert full < floor
        else:
            counts["full"] += 1
            assert prop.logp == pytest.approx(full, rel=1e-9, abs=0)
            if rng.random() < 0.5:
                tr.accept(prop)
    assert counts["skipped"] > 20 and counts["full"] > 20, counts


def test_derive_world_and_the_target_agree_across_tiles():
    """The final world's adjacency and openings between units of two tiles (derive_world) are
    the target's, on random worlds near the turn of a corridor with a door across it."""
    rng = np.random.default_rng(6)
    classes, zones, thetas = corridor_map(door=True)
    f = build_tiled_frame(classes, 0.05, MODEL, thetas, zones)
    post = Posterior(f, MODEL)
    base = corridor_units(f, thetas)
    found = 0
    for _ in range(30):
        w = wm.empty(4)
        for s in range(int(rng.integers(2, 5))):
            w = wm.add(w, s, _near_the_boundary(rng, f, base))
        slots = wm.active_slots(w)
        adj, cross = post.relations(w)
        pairs, doors, passages = cross_tile_openings(f, w.rects[slots], slots)
        tiles = [f.tile_of_rect(r) for r in w.rects[slots]]
        want = {(int(slots[i]), int(slots[j])) for i in range(len(slots)) for j in range(i + 1, len(slots))
                if tiles[i] != tiles[j] and adj[slots[i], slots[j]]}
        assert want == {(int(slots[i]), int(slots[j])) for i, j in pairs}
        for p, q in want:
            assert tuple(cross[p, q]) == (sum((d.p, d.q) == (p, q) for d in doors),
                                          sum((d.p, d.q) == (p, q) for d in passages))
        found += len(want)
    assert found > 5


def test_grown_rectangles_of_two_tiles_overlap_as_their_points_do():
    """The rotated-rectangle test against points: two units of two tiles, each grown by g cells,
    overlap when a fine grid of image points holds a point inside both (up to the grid's spacing:
    grown by g + 0.3 they must share a point when the test says so, grown by g - 0.3 they must
    not when it says not)."""
    rng = np.random.default_rng(9)
    _, _, f = two_zone_map(rng, shape=(120, 200), theta=0.6)
    xd = cross_data(f)
    yy, xx = np.mgrid[-40:160:0.25, -40:240:0.25]

    def inside(k, rect, grow):
        r, c = f.tile_image_to_lattice(k, xx, yy)
        return ((r >= rect[0] - 0.5 - grow) & (r <= rect[2] - 0.5 + grow)
                & (c >= rect[1] - 0.5 - grow) & (c <= rect[3] - 0.5 + grow))

    (a0, a1), (b0, b1) = f.spans
    seen = set()
    for _ in range(60):
        rects = []
        for lo_, hi_ in ((a0, a1), (b0, b1)):
            hh, ww = int(rng.integers(5, 40)), int(rng.integers(5, 40))
            r0, c0 = int(rng.integers(0, f.shape[0] - hh)), int(rng.integers(lo_, hi_ - ww))
            rects.append(np.array([r0, c0, r0 + hh, c0 + ww], np.int64))
        for g in (0.0, 3.0):
            hit = grown_overlap(xd.aff, 0, rects[0], 1, rects[1], g)
            near, far = g + 0.3, max(g - 0.3, -0.4)
            if hit:
                assert (inside(0, rects[0], near) & inside(1, rects[1], near)).any()
            else:
                assert not (inside(0, rects[0], far) & inside(1, rects[1], far)).any()
            seen.add(bool(hit))
    assert seen == {True, False}


def test_the_posteriors_door_marginals_see_doors_across_tiles():
    """A door between units of two tiles is one of a sampled world's doors (sampler.marginals), as
    derive_world reports it."""
    from semmap_pp.sampler.marginals import world_doors
    classes, zones, thetas = corridor_map(door=True)
    f = build_tiled_frame(classes, 0.05, MODEL, thetas, zones)
    w = wm.add(wm.add(wm.empty(2), 0, corridor_units(f, thetas)[0]), 1, corridor_units(f, thetas)[1])
    doors = world_doors(f, w)
    assert [(d.p, d.q, d.box) for d in doors] == [(d.p, d.q, d.box) for d in derive_world(f, w).doors]
    assert len(doors) == 1


def test_an_opening_is_as_wide_as_along_the_tile_whose_wall_holds_it():
    """A run of boundary pixels crossing a doorway at 45° to the image: along the axes of a tile
    at the image's angle it spans its 21 columns, along a tile at 45° its full length (29 cells).
    The opening is a door when either width is a door's, a passage only when both exceed
    ``door_max`` or it spans a unit's interior on that unit's tile."""
    from semmap_pp.derive.crossing import _is_passage, _run_width
    c = math.cos(math.pi / 4)
    aff = np.array([[1.0, 0.0, 0.0, 0.0, 0.0, 0.0], [c, c, 0.0, 0.0, 0.0, 0.0]])
    pix = np.array([[i, i] for i in range(21)], np.int64)          # (row, col) on the diagonal
    members = np.arange(21, dtype=np.int64)
    assert _run_width(aff, 0, pix, 0, members) == 21
    assert _run_width(aff, 1, pix, 0, members) == 29                  # 20·√2 + 1
    ip = np.array([3, 25, 10, 2], np.int64)                           # door_max 25 cells
    room = np.array([0, 0, 80, 80], np.int64)                         # interiors 76 cells across
    assert not _is_passage(np.array([21, 29]), room, room, ip)        # a door of 21 cells
    assert _is_passage(np.array([26, 29]), room, room, ip)            # wider than a door both ways
    corridor = np.array([0, 0, 30, 200], np.int64)                    # 26 cells across its interior
    assert _is_passage(np.array([5, 22]), room, corridor, ip)         # spans the corridor's 22
    assert not _is_passage(np.array([22, 5]), room, corridor, ip)     # along the room's tile: no


@pytest.mark.parametrize("samples", [1, 2])
def test_seen_classes_show_every_pixel_on_each_tiles_lattice(samples):
    """TiledFrame.seen_classes: a tile's own cells as its classes, the cells over another zone's
    pixels as the image shows them (its classes hold them unknown), read as the tile's own cells
    are: the pixel under the centre, or occupied when a sub-cell's centre falls on a wall."""
    classes, zones, thetas = corridor_map(door=True)
    model = dataclasses.replace(MODEL, lattice=dataclasses.replace(MODEL.lattice, wall_samples=samples))
    f = build_tiled_frame(classes, 0.05, model, thetas, zones)
    seen = f.seen_classes
    own = ~f.outside
    assert np.array_equal(seen[own], f.classes[own])
    theirs = 0
    for k, (t, c) in enumerate(zip(f.tiles, f.cols)):
        for b0, b1 in t.bands():
            xi, yi, ok = t.lattice_pixels(b0, b1)
            other = ok & (zones[np.clip(yi, 0, zones.shape[0] - 1), np.clip(xi, 0, zones.shape[1] - 1)] != k)
            got = seen[b0:b1, c:c + t.shape[1]]
            differ = got[other] != classes[yi[other], xi[other]]
            assert np.all(got[other][differ] == cells.OCCUPIED) and (samples > 1 or not differ.any())
            assert (f.classes[b0:b1, c:c + t.shape[1]][other] == cells.UNKNOWN).all()
            theirs += int((classes[yi[other], xi[other]] != cells.UNKNOWN).sum())
    assert theirs > 0        # the tiles do reach over the boundary onto pixels the map saw

