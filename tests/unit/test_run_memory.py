"""The estimated peak memory of a run, `semmap map --max-memory`, and the heap set aside from the
garbage collector while a stage runs (semmap_pp/run/memory.py)."""

from __future__ import annotations

import gc
import weakref
from pathlib import Path

import pytest

from semmap_pp.cli import main
from semmap_pp.errors import MapError
from semmap_pp.run import memory
from semmap_pp.run.inputs import load_inputs

TINY = Path(__file__).resolve().parents[1] / "data" / "maps" / "tiny.yaml"


def test_the_estimate_grows_with_each_size():
    base = memory.estimate_peak_bytes(lattice_cells=10**6, image_cells=10**6, known_cells=10**5)
    for key in ("lattice_cells", "image_cells", "known_cells"):
        sizes = {"lattice_cells": 10**6, "image_cells": 10**6, "known_cells": 10**5}
        sizes[key] *= 2
        assert memory.estimate_peak_bytes(**sizes) > base


@pytest.mark.parametrize("text,n", [("2G", 2 * 2**30), ("1.5GB", 3 * 2**29), ("800M", 800 * 2**20),
                                    ("800MiB", 800 * 2**20), ("64k", 65536), ("123", 123)])
def test_sizes_are_read_in_binary_units(text, n):
    assert memory.parse_size(text) == n


@pytest.mark.parametrize("text", ["", "two gigabytes", "-1G", "1X"])
def test_a_size_that_is_none_is_refused(text):
    with pytest.raises(ValueError):
        memory.parse_size(text)


def test_a_map_over_the_limit_is_refused_with_the_estimate():
    inputs = load_inputs(TINY)
    need = memory.check_memory(inputs, 2**40)       # within the limit: the estimate is returned
    assert need >= memory.BASE_BYTES
    with pytest.raises(MapError) as err:
        memory.check_memory(inputs, need - 1)
    text = str(err.value)
    assert "tiny.yaml" in text and "would need about" in text and "--max-memory" in text


def test_semmap_map_refuses_before_sampling(tmp_path, capsys):
    out = tmp_path / "run"
    assert main(["map", str(TINY), "--out", str(out), "--max-memory", "1M", "--progress", "none"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("semmap: error: ") and "would need about" in err[0]
    assert not (out / "world.json").exists()


def test_semmap_map_rejects_a_malformed_size(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["map", str(TINY), "--out", "x", "--max-memory", "lots"])
    assert exc.value.code == 2
    assert "--max-memory" in capsys.readouterr().err


class _Node:
    """An object in a reference cycle (only the cycle collector frees it), weakly referable."""

    def __init__(self):
        self.me = self


def test_young_heap_collects_a_stages_garbage_and_sets_the_older_heap_aside():
    old = _Node()
    old_ref = weakref.ref(old)
    with memory.young_heap():
        assert gc.get_freeze_count() > 0
        young = _Node()
        young_ref = weakref.ref(young)
        del young, old
        gc.collect()
        assert young_ref() is None          # a cycle made inside: collected
        assert old_ref() is not None        # one made before: set aside, not read again
    assert gc.get_freeze_count() == 0
    gc.collect()
    assert old_ref() is None                # handed back to the collector at the end

    with pytest.raises(KeyboardInterrupt):  # Ctrl-C (or any error) inside hands it back too
        with memory.young_heap():
            raise KeyboardInterrupt
    assert gc.get_freeze_count() == 0


def test_a_young_heap_inside_another_hands_the_heap_back_only_at_the_outer_end():
    with memory.young_heap():
        middle = _Node()
        middle_ref = weakref.ref(middle)
        with memory.young_heap():            # the outputs' stage inside the run's
            del middle
            gc.collect()
            assert middle_ref() is not None  # made before the inner stage: set aside by it
        assert gc.get_freeze_count() > 0     # the inner end leaves the outer stage's heap aside
        gc.collect()
        assert middle_ref() is not None
    assert gc.get_freeze_count() == 0
    gc.collect()
    assert middle_ref() is None
