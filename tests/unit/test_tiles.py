"""The tiled lattice of a building of several directions (semmap_pp.lattice.tiles): its maps
between lattice and image, the prior's support of one tile per unit, exact detailed balance and
incremental = full target across two tiles, and what units of two tiles share (derive.crossing)."""

import math

import numpy as np
import pytest
from scipy import sparse
from scipy.sparse import csgraph

from semmap_pp import cells
from semmap_pp import world as wm
from semmap_pp.derive import derive_world
from semmap_pp.lattice.frame import build_frame_from_classes
from semmap_pp.lattice.tiles import TiledFrame, build_tiled_frame, rect_spans, tile_gap, unit_theta
from semmap_pp.model import load_model
from semmap_pp.sampler.kernels import build_data, default_mix
from semmap_pp.target.posterior import Posterior
from semmap_pp.target.prior import log_p_rect_const, n_rects, rect_faults, rects_valid
from standin import TableTarget
from test_kernels_balance import SETTINGS, all_states, tiny_classes, transition_matrix

MODEL = load_model()


def two_zone_map(rng, shape=(160, 260), theta=0.5):
    classes = rng.choice(3, size=shape, p=[0.6, 0.25, 0.15]).astype(np.uint8)
    zones = np.zeros(shape, np.uint8)
    zones[:, shape[1] // 2:] = 1
    return classes, zones, build_tiled_frame(classes, 0.05, MODEL, (0.0, theta), zones)


def test_one_direction_is_the_plain_frame():
    classes = np.random.default_rng(0).choice(3, size=(60, 80)).astype(np.uint8)
    f = build_tiled_frame(classes, 0.05, MODEL, (0.2,), np.zeros((60, 80), np.uint8))
    g = build_frame_from_classes(classes, 0.05, MODEL, theta=0.2)
    assert not isinstance(f, TiledFrame) and rect_spans(f) == ()
    assert np.array_equal(f.classes, g.classes) and f.theta == g.theta


def test_every_lattice_cell_shows_its_own_pixel_and_maps_back():
    classes, zones, f = two_zone_map(np.random.default_rng(1))
    assert isinstance(f, TiledFrame) and len(f.spans) == 2
    (a0, a1), (b0, b1) = f.spans
    assert b0 - a1 == tile_gap(f.cells)
    for b0_, b1_ in f.bands():
        xi, yi, inside = f.lattice_pixels(b0_, b1_)
        assert np.array_equal(inside, ~f.outside[b0_:b1_])
        assert np.array_equal(f.classes[b0_:b1_][inside], classes[yi[inside], xi[inside]])
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


@pytest.mark.parametrize("door", [False, True])
def test_a_corridor_cut_by_the_zones_is_one_passage_and_a_wall_across_it_a_door(door):
    classes, zones, thetas = corridor_map(door=door)
    f = build_tiled_frame(classes, 0.05, MODEL, thetas, zones)
    (a0, _), (b0, _) = f.spans

    def unit(k, xs, ys):      # the lattice rectangle of tile k over pixel centres (xs, ys)
        r, c = f.tile_image_to_lattice(k, np.asarray(xs, float), np.asarray(ys, float))
        return (int(round(r.min())), int(round(c.min())), int(round(r.max())) + 1, int(round(c.max())) + 1)

    rect0 = unit(0, [20, 149], [128, 172])
    u, v = np.array([0.0, 199.0, 0.0, 199.0]), np.array([-22.0, -22.0, 22.0, 22.0])
    t = thetas[1]
    rect1 = unit(1, 150 + u * math.cos(t) - v * math.sin(t), 150 + u * math.sin(t) + v * math.cos(t))
    assert f.tile_of_rect(rect0) == 0 and f.tile_of_rect(rect1) == 1
    w = wm.add(wm.add(wm.empty(2), 0, rect0), 1, rect1)
    d = derive_world(f, w)
    assert d.adjacency[0, 1] and d.adjacency[1, 0]
    if door:
        assert len(d.doors) == 1 and not d.passages and d.doors[0].width < 30
    else:
        assert len(d.passages) == 1 and not d.doors
