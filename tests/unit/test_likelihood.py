"""Tests of semmap_pp.target.likelihood: the sensor model's semantics and full == incremental."""

import math

import numpy as np
import pytest

from semmap_pp.cells import FREE, OCCUPIED, UNKNOWN
from semmap_pp.lattice.frame import build_frame_from_classes
from semmap_pp.target.likelihood import (R_INTERIOR, R_WALL, X_FREE, X_OBJECTLIKE, X_SHADOW,
                                  X_UNKNOWN, X_WALLLIKE, Change, CoverTracker, category, changed_box,
                                  cover_counts, full_loglik, full_tallies, prepare, wall_like)
from semmap_pp.model import load_model

MODEL = load_model()


def data_for(classes):
    return prepare(build_frame_from_classes(np.asarray(classes, np.uint8), 0.05, MODEL, theta=0.0),
                   MODEL)


def room_map():
    """A 40x40 free room with 2-cell walls (long enough to be wall-like), unknown outside."""
    c = np.full((50, 50), UNKNOWN, np.uint8)
    c[5:45, 5:45] = FREE
    c[5:45, [5, 6, 43, 44]] = OCCUPIED
    c[[5, 6, 43, 44], 5:45] = OCCUPIED
    return c


def ll(data, rects, corr=None):
    rects = np.array(rects).reshape(-1, 4)
    corr = np.zeros(len(rects), bool) if corr is None else np.array(corr)
    return full_loglik(data, rects, corr)


def test_true_room_is_a_strict_local_optimum():
    d = data_for(room_map())
    best = ll(d, [(5, 5, 45, 45)])
    for k in range(4):
        for step in (-2, -1, 1, 2):
            r = [5, 5, 45, 45]
            r[k] += step
            assert ll(d, [r]) < best, (k, step)


def test_empty_world_is_the_baseline():
    d = data_for(room_map())
    expected = sum(np.count_nonzero(room_map() == k) * math.log(MODEL.sensor.other[3, k]) for k in range(3))
    assert math.isclose(ll(d, np.zeros((0, 4))), expected)
    assert d.baseline == pytest.approx(expected)


def test_gains_follow_the_tables():
    d = data_for(room_map())
    other, corr = MODEL.sensor.other, MODEL.sensor.corridor
    # free input in an interior: log p(free|FREE) - log p(free|UNKNOWN)
    assert d.gain[category(X_FREE, R_INTERIOR, False)] == pytest.approx(math.log(other[1, 0] / other[3, 0]))
    # unknown input inside a corridor is an object under the corridor table
    assert d.gain[category(X_UNKNOWN, R_INTERIOR, True)] == pytest.approx(math.log(corr[2, 1] / other[3, 1]))
    # a wall-like occupied cell inside is a mismatch (state FREE), an object-like one an object
    assert d.gain[category(X_WALLLIKE, R_INTERIOR, False)] == pytest.approx(math.log(other[1, 2] / other[3, 2]))
    assert d.gain[category(X_OBJECTLIKE, R_INTERIOR, False)] == pytest.approx(math.log(other[2, 2] / other[3, 2]))
    assert d.gain[category(X_OBJECTLIKE, R_WALL, False)] == pytest.approx(math.log(other[0, 2] / other[3, 2]))


def test_a_wall_thinner_than_the_band_reads_whole():
    """Two rooms with a wall of one cell between them, the band being two cells: the free cells
    beside that wall are X_SHADOW, read by a wall band as the wall's occupied cells and by an
    interior as free. The two rooms beat one unit over both by what the three rows of the wall
    are worth, column by column; read as free, the band's second row would cost the split −1.46
    a cell and the one unit would win. Beside a wall of two cells there are none."""
    c = room_map()
    c[25, 7:43] = OCCUPIED
    d = data_for(c)
    shadow = np.argwhere(d.xcode == X_SHADOW)
    assert sorted(set(shadow[:, 0].tolist())) == [24, 26] and len(shadow) == 2 * 36
    g = lambda x, region: d.gain[category(x, region, False)]
    per_column = (2 * g(X_SHADOW, R_WALL) + g(X_WALLLIKE, R_WALL)
                  - 2 * g(X_SHADOW, R_INTERIOR) - g(X_WALLLIKE, R_INTERIOR))
    split = ll(d, [(5, 5, 26, 45), (25, 5, 45, 45)]) - ll(d, [(5, 5, 45, 45)])
    assert split == pytest.approx(36 * per_column) and split > 36 * 4.0
    assert g(X_SHADOW, R_WALL) == g(X_WALLLIKE, R_WALL) and g(X_SHADOW, R_INTERIOR) == g(X_FREE, R_INTERIOR)
    c[26, 7:43] = OCCUPIED               # a wall of two cells: as thick as the band
    assert not (data_for(c).xcode == X_SHADOW).any()


def test_corridor_table_penalises_clutter_more():
    c = room_map()
    c[20:26, 20:26] = UNKNOWN           # a small unexplored patch inside
    c[30:33, 30:33] = OCCUPIED          # and a small object
    d = data_for(c)
    rect = [(5, 5, 45, 45)]
    assert ll(d, rect, [True]) < ll(d, rect, [False])


def test_wall_like_needs_a_run_longer_than_object_max_extent():
    occ = np.zeros((20, 40), bool)
    occ[2, 0:31] = True      # 31 cells: longer than 30 -> wall-like
    occ[5, 0:30] = True      # 30 cells: not
    occ[10:16, 10:16] = True  # a blob: not
    wl = wall_like(occ, 30)
    assert wl[2].sum() == 31 and not wl[5].any() and not wl[10:16].any()


def test_wall_like_tolerates_a_ragged_wall_but_not_clutter():
    occ = np.zeros((40, 60), bool)
    # a ragged 40-cell wall: it steps a row up or down every 5 cells, with two 1-cell holes
    for i, c in enumerate(range(5, 45, 5)):
        occ[10 + (i % 2), c:c + 5] = True
    occ[10:12, 17] = False
    occ[10:12, 33] = False
    # clutter: 4-cell boxes 3 cells apart along a line (gaps wider than the gap closed)
    for c in range(5, 45, 7):
        occ[25:29, c:c + 4] = True
    strict = wall_like(occ, 30)
    ragged = wall_like(occ, 30, tolerance=1, gap=1)
    assert not strict[5:15].any()               # no single straight run of 31 cells
    assert ragged[5:15].sum() == occ[5:15].sum()  # every cell of the ragged wall
    assert not ragged[20:35].any()              # the boxes stay objects
    # a 2-cell hole splits the wall when only 1-cell gaps are closed: two runs of 20 cells
    occ2 = np.zeros((5, 60), bool)
    occ2[2, 5:25] = True
    occ2[2, 27:47] = True
    assert not wall_like(occ2, 30, tolerance=1, gap=1).any()
    assert wall_like(occ2, 30, tolerance=1, gap=2).sum() == 40
    with pytest.raises(ValueError):
        wall_like(occ2, 30, tolerance=-1)


def test_prepare_uses_the_model_wall_line_tolerance():
    c = np.zeros((40, 60), np.uint8)
    for i, col in enumerate(range(5, 45, 5)):   # the ragged wall of the test above
        c[10 + (i % 2), col:col + 5] = OCCUPIED
    d = data_for(c)
    assert (d.xcode[c == OCCUPIED] == X_WALLLIKE).all()


def test_shared_wall_bands_are_not_penalised_but_overlapping_interiors_are():
    c = np.zeros((30, 60), np.uint8)
    d = data_for(c)
    a, b = (0, 0, 30, 32), (0, 30, 30, 60)      # wall bands (2 cells) overlap on columns 30-31
    _, gamma = full_tallies(d, np.array([a, b]), np.array([False, False]))
    assert gamma == 0
    a2 = (0, 0, 30, 35)                          # now b's wall band lies on a's interior
    _, gamma = full_tallies(d, np.array([a2, b]), np.array([False, False]))
    # rows 2..27: columns 30..32 are in a2's interior and b's band or interior, columns 33..34 in
    # a2's band and b's interior: k = 2 on 26 x 5 cells
    assert gamma == 26 * 5
    a3, b3 = (0, 0, 30, 30), (0, 0, 30, 30)      # identical units: every interior cell k = 2
    _, gamma = full_tallies(d, np.array([a3, b3]), np.array([False, False]))
    assert gamma == 26 * 26


def test_changed_box_of_one_wall_move_is_a_strip():
    wall = 2
    box = changed_box(Change((10, 10, 90, 90), False, (10, 10, 93, 90), False), wall)
    assert box == (88, 10, 93, 90)
    box = changed_box(Change((10, 10, 90, 90), False, (10, 14, 90, 90), False), wall)
    assert box == (10, 10, 90, 16)
    assert changed_box(Change((1, 2, 3, 4), True, (1, 2, 3, 4), True), wall) is None
    # a type change touches the whole rectangle
    assert changed_box(Change((1, 2, 30, 40), False, (1, 2, 30, 40), True), wall) == (1, 2, 30, 40)


def test_counts_outside_the_strip_do_not_change():
    rng = np.random.default_rng(5)
    for _ in range(200):
        r0, c0 = rng.integers(0, 20, 2)
        a = (r0, c0, r0 + rng.integers(8, 40), c0 + rng.integers(8, 40))
        b = list(a)
        k = rng.integers(4)
        b[k] += rng.integers(-5, 6)
        if b[2] - b[0] < 5 or b[3] - b[1] < 5:
            continue
        box = changed_box(Change(a, False, tuple(b), False), 2)
        ca = cover_counts((80, 80), np.array([a]), np.array([False]), 2)
        cb = cover_counts((80, 80), np.array([b]), np.array([False]), 2)
        diff = np.any(ca != cb, axis=0)
        if box is None:
            assert not diff.any()
            continue
        mask = np.zeros((80, 80), bool)
        mask[max(box[0], 0):box[2], max(box[1], 0):box[3]] = True
        assert not np.any(diff & ~mask)


def random_map(rng, shape):
    c = rng.choice(3, size=shape, p=[0.55, 0.25, 0.20]).astype(np.uint8)
    r = rng.integers(0, shape[0] - 1)
    c[r, :] = OCCUPIED                       # one long wall so wall-like cells exist
    return c


def random_rect(rng, shape):
    h, w = rng.integers(5, 35), rng.integers(5, 35)
    r0, c0 = rng.integers(-3, shape[0] - 2), rng.integers(-3, shape[1] - 2)
    return (int(r0), int(c0), int(r0 + h), int(c0 + w))


def random_edit(rng, rects, corr, shape):
    """A random edit of a list-of-slots world: returns the list of Changes and applies it."""
    kind = rng.integers(6)
    n = len(rects)
    i = int(rng.integers(n))
    changes = []

    def setslot(j, rect, c):
        changes.append(Change(rects[j], corr[j], rect, c))
        rects[j], corr[j] = rect, c

    if kind == 0 and rects[i] is not None:               # move one side
        r = list(rects[i])
        r[rng.integers(4)] += int(rng.integers(-5, 6))
        if r[2] - r[0] >= 5 and r[3] - r[1] >= 5:
            setslot(i, tuple(r), corr[i])
    elif kind == 1 and rects[i] is not None:             # type change
        setslot(i, rects[i], not corr[i])
    elif kind == 2 and rects[i] is not None:             # translate
        dr, dc = rng.integers(-6, 7, 2)
        r = rects[i]
        setslot(i, (r[0] + dr, r[1] + dc, r[2] + dr, r[3] + dc), corr[i])
    elif kind == 3:                                      # birth or death
        setslot(i, None if rects[i] is not None else random_rect(rng, shape), bool(rng.integers(2)))
    elif kind == 4:                                      # two slots at once (split/merge-like)
        j = int(rng.integers(n))
        if j != i:
            setslot(i, random_rect(rng, shape), corr[i])
            setslot(j, None if rects[j] is not None else random_rect(rng, shape), corr[j])
    else:                                                # several sides and the type
        if rects[i] is not None:
            r = np.array(rects[i]) + rng.integers(-3, 4, 4)
            if r[2] - r[0] >= 5 and r[3] - r[1] >= 5:
                setslot(i, tuple(int(v) for v in r), not corr[i])
    return changes


@pytest.mark.slow
def test_incremental_equals_full_over_10000_random_edits():
    rng = np.random.default_rng(20260)
    edits = worst = shadows = 0
    for _world in range(25):
        shape = (int(rng.integers(30, 70)), int(rng.integers(30, 70)))
        d = data_for(random_map(rng, shape))
        shadows += int((d.xcode == X_SHADOW).sum())
        n = int(rng.integers(1, 8))
        rects = [random_rect(rng, shape) if rng.random() < 0.8 else None for _ in range(n)]
        corr = [bool(rng.integers(2)) for _ in range(n)]

        def full():
            live = [(r, c) for r, c in zip(rects, corr) if r is not None]
            return ll(d, [r for r, _ in live] or np.zeros((0, 4)), [c for _, c in live])

        tracker = CoverTracker(d, np.array([r for r in rects if r is not None]).reshape(-1, 4),
                               np.array([c for r, c in zip(rects, corr) if r is not None]))
        assert tracker.loglik == full()
        for _ in range(400):
            before = (list(rects), list(corr))
            changes = random_edit(rng, rects, corr, shape)
            patch = tracker.propose(changes)
            expected = full()
            worst = max(worst, abs(patch.loglik - expected) / abs(expected))
            if rng.random() < 0.6:
                tracker.commit(patch)
            else:                                        # rejected: drop it and restore
                rects[:], corr[:] = before
                assert tracker.loglik == full()
            edits += 1
    assert edits >= 10_000 and shadows > 0
    assert worst <= 1e-9


@pytest.mark.slow
def test_slot_world_delta_equals_full_tallies():
    """The sampler's compiled path (:func:`world_delta` over slot arrays, several slots edited at
    once: moves, births, deaths, corridor flips) gives exactly the tallies of a full count."""
    from semmap_pp.target.likelihood import world_delta

    rng = np.random.default_rng(31)
    checked = 0
    for _world in range(20):
        shape = (int(rng.integers(30, 70)), int(rng.integers(30, 70)))
        d = data_for(random_map(rng, shape))
        K = 6
        rects = np.zeros((K, 4), np.int32)
        on = rng.random(K) < 0.6
        corr = rng.random(K) < 0.3
        for s in np.flatnonzero(on):
            rects[s] = random_rect(rng, shape)
        hist, gamma = full_tallies(d, rects[on], corr[on])
        for _ in range(100):
            new_rects, new_on, new_corr = rects.copy(), on.copy(), corr.copy()
            for s in rng.choice(K, int(rng.integers(1, 4)), replace=False):
                kind = rng.integers(4)
                if kind == 0 and new_on[s]:                  # move one side
                    new_rects[s, rng.integers(4)] += int(rng.integers(-5, 6))
                elif kind == 1:                              # birth or death
                    new_on[s] = not new_on[s]
                    new_rects[s] = random_rect(rng, shape) if new_on[s] else 0
                elif kind == 2:                              # type change
                    new_corr[s] = not new_corr[s]
                else:                                        # a new rectangle
                    new_rects[s] = random_rect(rng, shape)
            h, w = new_rects[:, 2] - new_rects[:, 0], new_rects[:, 3] - new_rects[:, 1]
            if not np.all((h >= 1) & (w >= 1) | ~new_on):
                continue
            hh = hist.copy()
            g = gamma + world_delta(d.xsum, rects, on, corr, new_rects, new_on, new_corr, d.wall, hh)
            expected_hist, expected_gamma = full_tallies(d, new_rects[new_on], new_corr[new_on])
            assert np.array_equal(hh, expected_hist) and g == expected_gamma
            checked += 1
            if rng.random() < 0.6:
                rects, on, corr, hist, gamma = new_rects, new_on, new_corr, hh, g
    assert checked >= 1500
