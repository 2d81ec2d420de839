import numpy as np
import pytest

from semmap_pp import world as wm


def test_functions_never_edit_their_input():
    w0 = wm.add(wm.empty(3), 1, (2, 3, 12, 20), 0)
    snapshot = (w0.rects.copy(), w0.active.copy(), w0.types.copy())
    wm.add(w0, 0, (0, 0, 5, 5), 2)
    wm.remove(w0, 1)
    wm.replace(w0, 1, (1, 1, 9, 9))
    wm.with_types(w0, [3, 3, 3])
    for a, b in zip(snapshot, (w0.rects, w0.active, w0.types)):
        np.testing.assert_array_equal(a, b)
    with pytest.raises(ValueError):
        w0.rects[1, 0] = 7  # read-only: an in-place edit fails loudly


def test_slots_and_keys():
    w = wm.add(wm.add(wm.empty(4), 2, (0, 0, 4, 6), 1), 0, (4, 0, 9, 6), 0)
    assert wm.n_units(w) == 2
    assert wm.active_slots(w).tolist() == [0, 2]
    assert wm.free_slots(w).tolist() == [1, 3]
    # the same units in other slots are the same world
    v = wm.add(wm.add(wm.empty(4), 3, (4, 0, 9, 6), 0), 1, (0, 0, 4, 6), 1)
    assert wm.canonical_key(v) == wm.canonical_key(w)
    assert wm.canonical_key(wm.with_types(v, [2, 2, 2, 2])) != wm.canonical_key(w)


def test_double_add_and_bad_remove_raise():
    w = wm.add(wm.empty(2), 0, (0, 0, 3, 3))
    with pytest.raises(ValueError):
        wm.add(w, 0, (0, 0, 3, 3))
    with pytest.raises(ValueError):
        wm.remove(w, 1)


def test_validity():
    w = wm.add(wm.empty(2), 0, (0, 0, 3, 5))
    assert wm.is_valid(w, (10, 10), min_side=3)
    assert not wm.is_valid(w, (10, 10), min_side=4)
    assert not wm.is_valid(w, (2, 10), min_side=1)
    assert wm.with_types(w, [1, 1]).types.tolist() == [1, -1]


def test_fit_moves_units_into_fewer_slots_and_grow_adds_empty_ones():
    w = wm.empty(8)
    for slot, rect in ((1, (0, 0, 10, 10)), (4, (0, 12, 10, 30)), (7, (12, 0, 30, 30))):
        w = wm.add(w, slot, rect, type_index=slot % 3)
    small = wm.fit(w, 3)
    assert small.capacity == 3 and small.active.all()
    assert small.rects.tolist() == [w.rects[s].tolist() for s in (1, 4, 7)]
    assert small.types.tolist() == [w.types[s] for s in (1, 4, 7)]
    big = wm.grow(w, 12)
    assert big.capacity == 12 and np.array_equal(big.rects[:8], w.rects)
    assert not big.active[8:].any() and (big.types[8:] == wm.NO_TYPE).all()
    assert wm.fit(w, 12).capacity == 12
    with pytest.raises(ValueError):
        wm.fit(w, 2)
    with pytest.raises(ValueError):
        wm.grow(w, 4)
