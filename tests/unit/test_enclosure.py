"""Tests of the enclosure term (semmap_pp.target.likelihood.enclosure_loglik, ``[sensor] enclosure_*``):
its value against a plain numpy count, its meaning on a room and a ray fan, and the tracker's
incremental target against the full evaluation with the term switched on."""

import dataclasses
import math

import numpy as np
import pytest

from semmap_pp import world as wm
from semmap_pp.cells import FREE, OCCUPIED, UNKNOWN
from semmap_pp.lattice.frame import build_frame_from_classes
from semmap_pp.target.likelihood import (SEEN_MIN, X_FREE, X_OBJECTLIKE, X_SHADOW, X_WALLLIKE,
                                  enclosure_loglik, prepare)
from semmap_pp.model import load_model
from semmap_pp.target.posterior import Posterior

DEFAULT = load_model()
ON = dataclasses.replace(DEFAULT, sensor=dataclasses.replace(
    DEFAULT.sensor, enclosure_min_share=0.3, enclosure_cost=1.0))


def oracle(xcode, rects, wall, min_share, cost):
    """The term written out with array slices, one unit and one side at a time."""
    total = 0.0
    for r0, c0, r1, c1 in rects:
        b = min(wall, r1 - r0, c1 - c0)
        shares = []
        for band in (xcode[r0:r0 + b, c0:c1], xcode[r1 - b:r1, c0:c1],
                     xcode[r0:r1, c0:c0 + b], xcode[r0:r1, c1 - b:c1]):
            occ = np.isin(band, (X_OBJECTLIKE, X_WALLLIKE)).sum()
            seen = occ + np.isin(band, (X_FREE, X_SHADOW)).sum()   # every input-free cell
            shares.append(occ / seen if seen >= SEEN_MIN * band.size else 1.0)
        second = sorted(shares)[2]
        if second < min_share:
            total -= cost * (r1 - r0) * (c1 - c0) * (1 - second / min_share)
    return total


def data_for(classes, model=ON):
    frame = build_frame_from_classes(np.asarray(classes, np.uint8), 0.05, model, theta=0.0)
    return prepare(frame, model)


def term(data, rects, model=ON):
    rects = np.array(rects, np.int64).reshape(-1, 4)
    s = model.sensor
    return enclosure_loglik(data.xsum, rects, np.ones(len(rects), np.bool_), data.wall,
                            s.enclosure_min_share, s.enclosure_cost)


def test_equals_the_plain_count_on_random_maps_and_rectangles():
    rng = np.random.default_rng(5)
    for trial in range(20):
        cls = rng.choice(3, size=(60, 80), p=rng.dirichlet([2, 2, 1])).astype(np.uint8)
        d = data_for(cls)
        rects = []
        for _ in range(4):
            h, w = rng.integers(1, 40), rng.integers(1, 50)
            r0, c0 = rng.integers(0, 60 - h + 1), rng.integers(0, 80 - w + 1)
            rects.append((int(r0), int(c0), int(r0 + h), int(c0 + w)))
        want = oracle(d.xcode, rects, d.wall, 0.3, 1.0)
        assert term(d, rects) == pytest.approx(want, rel=1e-12, abs=1e-12)


def room_and_fan():
    """A walled 30 x 30 room (rows/cols 5..35) and, right of it, a fan: free rays running across
    unknown through the rectangle (20, 40)-(50, 75), crossing three of its sides."""
    c = np.full((60, 90), UNKNOWN, np.uint8)
    c[5:35, 5:35] = FREE
    c[5:35, [5, 6, 33, 34]] = OCCUPIED
    c[[5, 6, 33, 34], 5:35] = OCCUPIED
    for r in range(18, 54, 3):          # horizontal rays
        c[r, 38:80] = FREE
    c[18:54, 40] = OCCUPIED             # the wall the rays came through (a window row)
    c[18:54:3, 40] = FREE
    return c


def test_a_room_costs_nothing_and_a_ray_fan_pays_per_cell():
    d = data_for(room_and_fan())
    assert term(d, [(5, 5, 35, 35)]) == 0.0
    fan = term(d, [(20, 40, 50, 75)])
    assert fan < -0.5 * 30 * 35          # rays cross top, bottom and right: most of the area
    assert fan == pytest.approx(oracle(d.xcode, [(20, 40, 50, 75)], d.wall, 0.3, 1.0))
    # switched off (the default model): nothing
    off = data_for(room_and_fan(), DEFAULT)
    assert DEFAULT.sensor.enclosure_cost == 0.0
    assert term(off, [(20, 40, 50, 75)], DEFAULT) == 0.0


def test_an_unseen_side_counts_as_a_wall():
    c = np.full((40, 40), UNKNOWN, np.uint8)
    c[10:30, 10:30] = FREE
    c[10:30, [10, 11]] = OCCUPIED       # one wall seen, the other three sides unknown
    d = data_for(c)
    assert term(d, [(8, 10, 32, 32)]) == 0.0     # bands on unknown: not seen, not penalised
    assert term(d, [(12, 10, 28, 28)]) < 0.0     # bands inside the free floor: rays cross them


@pytest.mark.parametrize("seed", [0, 1])
def test_tracker_equals_full_evaluation_with_the_term_on(seed):
    rng = np.random.default_rng(seed)
    cls = rng.choice(3, size=(90, 120), p=[0.6, 0.25, 0.15]).astype(np.uint8)
    post = Posterior(build_frame_from_classes(cls, 0.05, ON, theta=0.0), ON)
    shape = post.frame.shape
    w = wm.empty(8)
    for s in range(5):
        w = wm.add(w, s, (10 * s, 5 * s, 10 * s + 30, 5 * s + 40))
    tr = post.start(w)
    assert post.enclosure(w) < 0.0        # the term is active on this world
    assert tr.logp == pytest.approx(post.evaluate(w).total, rel=1e-12)
    for _ in range(400):
        s = int(rng.integers(w.capacity))
        cur = tr.world
        if cur.active[s] and rng.random() < 0.15:
            nw = wm.remove(cur, s)
        elif not cur.active[s]:
            h, wd = int(rng.integers(21, 60)), int(rng.integers(21, 60))
            r0, c0 = int(rng.integers(0, shape[0] - h)), int(rng.integers(0, shape[1] - wd))
            nw = wm.add(cur, s, (r0, c0, r0 + h, c0 + wd))
        else:
            r = [int(v) for v in cur.rects[s]]
            r[int(rng.integers(4))] += int(rng.integers(-8, 9))
            nw = wm.replace(cur, s, r)
        prop = tr.propose(nw, [s])
        full = post.evaluate(nw)
        if math.isinf(full.total):
            assert prop.logp == full.total
            continue
        assert prop.logp == pytest.approx(full.total, rel=1e-9, abs=0)
        assert prop.loglik == pytest.approx(full.loglik, rel=1e-9, abs=0)
        if rng.random() < 0.7:
            tr.accept(prop)


def room_with_window_fan():
    """A walled 3 m room and a fan of 41 rays leaving it through a window in its right wall, out
    into unknown space (0.05 m cells)."""
    c = np.full((140, 200), UNKNOWN, np.uint8)
    c[35:95, 5:65] = FREE
    c[35:95, [5, 6, 63, 64]] = OCCUPIED
    c[[35, 36, 93, 94], 5:65] = OCCUPIED
    for a in np.linspace(-0.75, 0.75, 41):
        for t in np.arange(0, 130, 0.5):
            r, q = int(round(65 + t * np.sin(a))), int(round(63 + t * np.cos(a)))
            if 0 <= r < 140 and 0 <= q < 200:
                c[r, q] = FREE
    return c


@pytest.mark.parametrize("model,kept", [(DEFAULT, True), (ON, False)])
def test_the_ascent_keeps_a_unit_over_a_ray_fan_only_with_the_term_off(model, kept):
    """Without the term the per-cell model pays for covering the fan (+1,182 nats); with it the
    unit costs thousands and the ascent's removals drop it. The room is kept either way."""
    from semmap_pp.sampler.ascent import _Ascent
    from semmap_pp.sampler.kernels import data_from_frame

    frame = build_frame_from_classes(room_with_window_fan(), 0.05, model, theta=0.0)
    post = Posterior(frame, model)
    room = wm.add(wm.empty(4), 0, (35, 5, 95, 65))
    both = wm.add(room, 1, (20, 65, 110, 160))
    gain = post.evaluate(both).total - post.evaluate(room).total
    assert (gain > 500) if kept else (gain < -1000)
    asc = _Ascent(post, both, data_from_frame(post.frame))
    asc.removals()
    assert wm.active_slots(asc.world).tolist() == ([0, 1] if kept else [0])
