"""Large maps' tables computed per tile and shared with the chains' processes give what the whole
lattice's computation gave (semmap_pp/sampler/kernels/data.py, semmap_pp/run/shared.py)."""

from __future__ import annotations

import pickle
from pathlib import Path

import numpy as np
import pytest
from scipy import ndimage

from semmap_pp.run import shared
from semmap_pp.sampler.kernels import data as kd


def whole_lattice_maxima(free, m, t):
    """The maxima as computed before: the transform and its maximum filter over the whole lattice."""
    dt = ndimage.distance_transform_edt(free)
    peak = (dt == ndimage.maximum_filter(dt, size=2 * m + 1)) & (dt >= max(1.0, t))
    pr, pc = np.nonzero(peak)
    return pr, pc, dt[pr, pc]


def random_free(rng, h, w):
    """Free rectangles of several sizes on an unknown lattice, with a few blocked cells."""
    free = np.zeros((h, w), bool)
    for _ in range(rng.integers(1, 12)):
        r0, c0 = rng.integers(0, h), rng.integers(0, w)
        free[r0:r0 + rng.integers(1, h), c0:c0 + rng.integers(1, w)] = True
    free[rng.random((h, w)) < rng.choice([0.0, 0.01, 0.1])] = False
    return free


@pytest.mark.parametrize("seed", range(40))
@pytest.mark.parametrize("tile,halo", [(16, 1), (7, 0), (512, 64)])
def test_tiled_maxima_equal_the_whole_lattice(monkeypatch, seed, tile, halo):
    rng = np.random.default_rng(seed)
    monkeypatch.setattr(kd, "DT_TILE", tile)
    monkeypatch.setattr(kd, "DT_HALO", halo)
    free = random_free(rng, int(rng.integers(5, 90)), int(rng.integers(5, 90)))
    m, t = int(rng.integers(1, 6)), int(rng.integers(1, 3))
    want = whole_lattice_maxima(free, m, t)
    got = kd.dt_maxima(free, m, t)
    for a, b in zip(got, want):
        np.testing.assert_array_equal(a, b)


def test_tiled_maxima_of_all_free_and_no_free_lattices(monkeypatch):
    monkeypatch.setattr(kd, "DT_TILE", 8)
    for free in (np.ones((20, 30), bool), np.zeros((20, 30), bool)):
        for a, b in zip(kd.dt_maxima(free, 2, 1), whole_lattice_maxima(free, 2, 1)):
            np.testing.assert_array_equal(a, b)


def test_a_shared_array_keeps_its_values_and_travels_as_its_path(tmp_path):
    a = np.random.default_rng(0).integers(-5, 5000, (300, 200)).astype(np.int32)
    s = shared.share(a, tmp_path)
    assert isinstance(s, shared.SharedArray) and s.dtype == a.dtype and not s.flags.writeable
    np.testing.assert_array_equal(s, a)
    blob = pickle.dumps(s)
    assert len(blob) < 1000                       # the path, not 240 kB of values
    back = pickle.loads(blob)
    np.testing.assert_array_equal(back, a)
    assert Path(back._path) == Path(s._path)
    assert shared.share(s, tmp_path) is s         # already in the folder: not written again
    again = shared.share(s, tmp_path / "other") if (tmp_path / "other").mkdir() is None else None
    assert Path(again._path).parent == tmp_path / "other"


def test_a_shared_array_whose_file_is_gone_pickles_its_values(tmp_path):
    with shared.shared_folder() as folder:
        s = shared.share(np.arange(10), folder)
    assert not Path(s._path).exists()
    np.testing.assert_array_equal(pickle.loads(pickle.dumps(s)), np.arange(10))


def test_shared_kernel_data_give_the_same_proposals(tmp_path):
    from semmap_pp import cells
    from semmap_pp.run.pipeline import KERNEL_TABLES
    from semmap_pp.sampler.kernels import build_data

    rng = np.random.default_rng(3)
    classes = np.full((40, 50), cells.FREE, np.uint8)
    classes[rng.random(classes.shape) < 0.05] = cells.OCCUPIED
    classes[::10, :] = cells.OCCUPIED
    data = build_data(classes, min_side=3, wall_cells=1)
    mapped = shared.share_fields(data, KERNEL_TABLES, tmp_path)
    back = pickle.loads(pickle.dumps(mapped))
    for name in data._fields:
        a, b = getattr(data, name), getattr(back, name)
        if isinstance(a, np.ndarray):
            assert a.dtype == b.dtype
            np.testing.assert_array_equal(a, b)
    assert all(isinstance(getattr(back, n), shared.SharedArray) for n in KERNEL_TABLES)


def random_frame(rng, theta_deg):
    """A frame of a random map: a known block in an unknown canvas, at ``theta_deg``."""
    import math

    from semmap_pp import cells
    from semmap_pp.lattice.frame import build_frame_from_classes
    from semmap_pp.model import load_model

    h, w = int(rng.integers(60, 140)), int(rng.integers(60, 140))
    img = np.full((h, w), cells.UNKNOWN, np.uint8)
    r0, c0 = int(rng.integers(0, h // 2)), int(rng.integers(0, w // 2))
    img[r0:r0 + h // 3, c0:c0 + w // 3] = cells.FREE
    img[r0, c0:c0 + w // 3] = cells.OCCUPIED
    return build_frame_from_classes(img, 0.05, load_model(), theta=math.radians(theta_deg))


@pytest.mark.parametrize("seed", range(12))
@pytest.mark.parametrize("theta_deg", [0.0, 5.0, 33.0])
def test_a_box_resampled_is_the_lattice_array_resampled(seed, theta_deg):
    rng = np.random.default_rng(seed)
    f = random_frame(rng, theta_deg)
    h, w = f.shape
    r0, c0 = int(rng.integers(0, h)), int(rng.integers(0, w))
    r1, c1 = int(rng.integers(r0, h + 1)), int(rng.integers(c0, w + 1))
    part = rng.random((r1 - r0, c1 - c0))
    whole = np.zeros(f.shape)
    whole[r0:r1, c0:c1] = part
    np.testing.assert_array_equal(f.box_to_image(part, (r0, c0, r1, c1), fill=0.0), f.to_image(whole, fill=0.0))


@pytest.mark.parametrize("seed", range(8))
def test_spread_panels_equal_the_lattice_probabilities_resampled(seed):
    from semmap_pp import world as wm
    from semmap_pp.outputs.write import SpreadImages
    from semmap_pp.sampler.spread import cell_probabilities

    rng = np.random.default_rng(seed)
    f = random_frame(rng, float(rng.choice([0.0, 7.0])))
    h, w = f.shape
    worlds = []
    for _ in range(int(rng.integers(0, 5))):
        world = wm.empty(4)
        for slot in range(int(rng.integers(1, 4))):
            r0, c0 = int(rng.integers(0, h - 8)), int(rng.integers(0, w - 8))
            rect = (r0, c0, r0 + int(rng.integers(6, 20)), c0 + int(rng.integers(6, 20)))
            world = wm.add(world, slot, rect, type_index=int(rng.integers(0, 4)))
        worlds += [world] * int(rng.integers(1, 3))
    p_wall, p_type = cell_probabilities(f.shape, worlds, f.cells.wall)
    images = SpreadImages(f, worlds)
    ih, iw = f.image_shape
    y0, x0 = int(rng.integers(0, ih // 2)), int(rng.integers(0, iw // 2))
    box = (y0, int(rng.integers(y0 + 1, ih + 1)), x0, int(rng.integers(x0 + 1, iw + 1)))
    for block, step in ((1, 1), (3, 1), (4, 3), (7, 2)):
        crop = f.to_image(p_wall, fill=0.0)[box[0]:box[1], box[2]:box[3]]
        want = ndimage.maximum_filter(crop, size=block) if block > 1 else crop
        np.testing.assert_array_equal(images.wall_panel(box, block, step), want[::step, ::step])
        for k in range(len(p_type)):
            want = f.to_image(p_type[k], fill=0.0)[box[0]:box[1], box[2]:box[3]][::step, ::step]
            np.testing.assert_array_equal(images.type_panel(k, box, step), want)


def test_wall_panel_bands_match_one_filter(monkeypatch):
    from semmap_pp import world as wm
    from semmap_pp.outputs import write
    from semmap_pp.sampler.spread import cell_probabilities

    monkeypatch.setattr(write, "PANEL_BAND_ROWS", 3)    # many bands, each with its margin
    f = random_frame(np.random.default_rng(1), 7.0)
    world = wm.add(wm.empty(2), 0, (5, 5, 40, 30), type_index=1)
    worlds = [world, wm.add(world, 1, (10, 28, 30, 50), type_index=0)]
    p_wall, _ = cell_probabilities(f.shape, worlds, f.cells.wall)
    ih, iw = f.image_shape
    for block, step in ((5, 1), (6, 2), (9, 4)):
        want = ndimage.maximum_filter(f.to_image(p_wall, fill=0.0), size=block)[::step, ::step]
        np.testing.assert_array_equal(write.SpreadImages(f, worlds).wall_panel((0, ih, 0, iw), block, step), want)


@pytest.mark.parametrize("seed", range(30))
def test_tiled_closing_equals_the_whole_map_transforms(monkeypatch, seed):
    import importlib

    cpr = importlib.import_module("semmap_pp.evaluate.cpr")   # the package's name cpr is a function
    rng = np.random.default_rng(seed)
    monkeypatch.setattr(cpr, "CLOSING_TILE", int(rng.integers(3, 25)))
    h, w = int(rng.integers(5, 80)), int(rng.integers(5, 80))
    mask = rng.random((h, w)) < rng.choice([0.02, 0.2, 0.6])
    mask[:, : int(rng.integers(0, w))] = False            # an empty part, tiles without mask cells
    r = int(rng.integers(1, 6))
    whole = ndimage.distance_transform_edt(ndimage.distance_transform_edt(~mask) <= r) > r
    if mask.any() and not (ndimage.distance_transform_edt(~mask) <= r).all():
        np.testing.assert_array_equal(cpr.closing_disk(mask, r), whole)


def test_kernel_data_stored_as_made_are_the_same_tables(tmp_path):
    import functools

    from semmap_pp import cells
    from semmap_pp.run.pipeline import KERNEL_TABLES
    from semmap_pp.sampler.kernels import build_data

    rng = np.random.default_rng(5)
    classes = rng.choice(np.array([cells.FREE, cells.UNKNOWN, cells.OCCUPIED], np.uint8), (60, 45), p=[.7, .2, .1])
    kw = dict(min_side=3, wall_cells=1, door_min=1, door_max=4)
    plain = build_data(classes, **kw)
    stored = build_data(classes, **kw, store=functools.partial(shared.share, folder=tmp_path))
    for name in plain._fields:
        a, b = getattr(plain, name), getattr(stored, name)
        if isinstance(a, np.ndarray):
            assert a.dtype == b.dtype
            np.testing.assert_array_equal(a, b)
    assert all(isinstance(getattr(stored, n), shared.SharedArray) for n in KERNEL_TABLES)


def test_spread_counts_in_uint16_equal_int32_counts():
    from semmap_pp import world as wm
    from semmap_pp.sampler.diagnostics import SpreadAccumulator
    from semmap_pp.sampler.spread import accumulate, rasterise

    rng = np.random.default_rng(2)
    worlds = []
    for _ in range(30):
        w = wm.empty(3)
        for slot in range(3):
            r0, c0 = int(rng.integers(0, 30)), int(rng.integers(0, 30))
            w = wm.add(w, slot, (r0, c0, r0 + int(rng.integers(4, 12)), c0 + int(rng.integers(4, 12))),
                       type_index=int(rng.integers(0, 4)))
        worlds += [w] * int(rng.integers(1, 400))      # counts over 255 per cell
    acc, box = accumulate(worlds, (50, 50), 1)
    assert acc.wall.dtype == np.uint16
    ref = SpreadAccumulator(acc.shape)
    for w in worlds:
        ref.add(*rasterise(w, box, 1))
    assert ref.wall.dtype == np.int32 and acc.n == ref.n
    np.testing.assert_array_equal(acc.wall, ref.wall)
    np.testing.assert_array_equal(acc.types, ref.types)
    np.testing.assert_array_equal(acc.p_wall(), ref.p_wall())


def test_without_a_folder_to_write_the_arrays_stay_ordinary(tmp_path):
    a = np.arange(12).reshape(3, 4)
    assert shared.share(a, None) is a
    missing = tmp_path / "gone"                    # np.save cannot write there
    assert shared.share(a, missing) is a
    assert not list(tmp_path.iterdir())
