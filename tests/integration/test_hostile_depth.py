"""Inputs nested or sized to break a parser (issue 55's F9, F10, F11, F12 and --n-inner): each is
one line naming the file (or the option), exit 2, no traceback."""

import json
from pathlib import Path

import pytest

from semmap_pp.cli import main

ROOT = Path(__file__).resolve().parents[2]
INTEL = ROOT / "tests" / "data" / "maps" / "intel_corner.yaml"
RULES = ROOT / "rules" / "table3.lp"


def _err(capsys) -> str:
    err = capsys.readouterr().err.strip()
    assert "Traceback" not in err and "\n" not in err and len(err) < 400, err[:500]
    return err


@pytest.mark.parametrize("depth", [3_000, 100_000])
def test_json_nested_too_deep_is_one_line(tmp_path, capsys, depth):
    f = tmp_path / "w.json"
    f.write_text("[" * depth + "]" * depth)
    for argv in (["where", str(f), "1", "1"], ["diff", str(f), str(f)], ["score", str(INTEL), str(f)]):
        assert main(argv) == 2
        err = _err(capsys)
        assert "w.json" in err and ("nested too deeply" in err or "not a world.json" in err)


@pytest.mark.parametrize("digits", [4_400, 20_000])
def test_json_with_an_integer_of_thousands_of_digits_is_one_line(tmp_path, capsys, digits):
    f = tmp_path / "w.json"
    f.write_text('{"format": "semmap_pp.world/1", "units": [{"id": ' + "7" * digits + "}]}")
    assert main(["where", str(f), "1", "1"]) == 2
    assert "digits" in _err(capsys)


@pytest.mark.parametrize("rule", [
    "p(X) :- unit(X), q({}).",                          # a term nested 5,000 deep
    ":~ unit(U). [{}@0, U]",                            # a weight that is a sum of 20,000 terms
])
def test_rules_nested_too_deep_are_one_line(tmp_path, capsys, rule):
    inner = ("f(" * 5000 + "X" + ")" * 5000) if rule.startswith("p(") else "+".join(["1"] * 20000)
    f = tmp_path / "deep.lp"
    f.write_text(rule.format(inner) + "\n")
    assert main(["rules", "check", str(f)]) in (1, 2)
    out = _err(capsys)
    # how deep Python's stack goes differs between processes: past it, "nested too deeply";
    # short of it, the file's own error (q/1 is no predicate; a sum is no weight). Either way one
    # line naming the file.
    assert "deep.lp" in out and ("nested too deeply" in out or "unknown predicate" in out
                                 or "weight" in out)


@pytest.mark.parametrize("where", ["rule", "evidence"])
def test_a_nul_byte_is_refused_with_its_place(tmp_path, capsys, where):
    f = tmp_path / "x.lp"
    if where == "rule":
        f.write_bytes(b"rolike(U) :- unit(U).\n:~ unit(U).\x00 [1@0, U]\n")
        assert main(["rules", "check", str(f)]) in (1, 2)
    else:
        f.write_bytes(b"unit(1).\nunit(2).\x00 adj(1,2).\n")
        assert main(["rules", "query", str(RULES), "--evidence", str(f)]) == 2
    err = _err(capsys)
    assert "x.lp:2:" in err and "NUL byte" in err


@pytest.mark.parametrize("argv, what", [
    (["--seed", str(2 ** 64)], "--seed: must be at most 4294967295"),
    (["--n-inner", "999999999999"], "--n-inner: must be at most 1,000,000"),
])
def test_seed_and_kernels_per_draw_are_bounded(tmp_path, capsys, argv, what):
    with pytest.raises(SystemExit) as exc:
        main(["map", str(INTEL), "--out", str(tmp_path / "o"), *argv])
    assert exc.value.code == 2
    assert what in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


# ---- a resume.npz holding what semmap map would refuse (issue 55's F9) ------------------------------
# --seed is bounded on the command line; a resume file brings its own settings, and a seed of 2^64
# reached the HDF5 writer of trace.nc after sampling (TypeError). Every value is checked when the
# file is read, before anything is loaded or sampled.

@pytest.fixture(scope="module")
def finished_run(tmp_path_factory):
    import numpy as np
    from semmap_pp.grid import write_map

    d = tmp_path_factory.mktemp("resumable")
    yaml = write_map(d / "m.yaml", np.pad(np.full((36, 46), 254, np.uint8), 2), 0.05)
    assert main(["map", str(yaml), "--out", str(d / "run"), "--chains", "2", "--cores", "1", "--tune", "2",
                 "--draws", "4", "--n-inner", "5", "--spread-draws", "0", "--progress", "none"]) == 0
    return d / "run"


def _edited_resume(run, tmp_path, edit):
    import io
    import shutil

    import numpy as np

    d = tmp_path / "copy"
    shutil.copytree(run, d)
    with np.load(d / "resume.npz", allow_pickle=False) as z:
        arrays = {k: z[k] for k in z.files}
    meta = json.loads(str(arrays["meta"]))
    edit(meta, arrays)
    arrays["meta"] = np.array(json.dumps(meta))
    buf = io.BytesIO()
    np.savez_compressed(buf, **arrays)
    (d / "resume.npz").write_bytes(buf.getvalue())
    return d


def _settings(**kw):
    return lambda meta, arrays: meta["settings"].update(kw)


@pytest.mark.parametrize("edit, what", [
    (_settings(seed=2 ** 64), "settings.seed must be an integer from 0 to 4294967295, got 18446744073709551616"),
    (_settings(seed=2 ** 32), "settings.seed must be an integer from 0 to 4294967295, got 4294967296"),
    (_settings(seed=-1), "settings.seed must be an integer from 0 to 4294967295, got -1"),
    (_settings(seed="7"), "settings.seed must be an integer from 0 to 4294967295, got '7'"),
    (_settings(seed=7.0), "settings.seed must be an integer from 0 to 4294967295, got 7.0"),
    (_settings(n_inner=10 ** 7), "settings.n_inner must be an integer from 1 to 1000000"),
    (_settings(draws=True), "settings.draws must be an integer from 1 to 1000000000, got True"),
    (_settings(anneal="hot"), "settings.anneal must be a number of at least 1, got 'hot'"),
    (_settings(colour=1), "settings.colour is not a setting of this version"),
    (lambda m, a: m["settings"].pop("tune"), "settings.tune is missing"),
    (lambda m, a: m.update(capacity=10 ** 12), "capacity must be an integer from 1 to 100000"),
    (lambda m, a: m["chains"].pop(), "chains must list one entry per chain (settings.chains = 2), got 1"),
    (lambda m, a: m["chains"][1].update(draw=-3), "chains[1].draw must be an integer"),
    (lambda m, a: m["chains"][0]["rng_state"]["state"].update(state=2 ** 130),
     "chains[0].rng_state is not a random state numpy takes"),
    (lambda m, a: m["chains"][0].update(rng_state="random"), "chains[0].rng_state is not a random state"),
    (lambda m, a: m["inputs"].update(map=["m.yaml"]), "inputs.map must be the map's file name"),
    (lambda m, a: m["inputs"]["map_options"].update(max_cells="many"), "inputs.map_options.max_cells must be int"),
    (lambda m, a: m["inputs"]["map_options"].update(at=-2.0), "inputs.map_options.at must be float"),
    (lambda m, a: m["inputs"]["map_options"].update(at="soon"), "inputs.map_options.at must be float"),
    (lambda m, a: m["inputs"]["map_options"].update(topic=7), "inputs.map_options.topic must be str"),
    (lambda m, a: a.update(rects_1=a["rects_1"].astype("float64")),
     "the array rects_1 is float64 of shape (6, 64, 4); expected integers of shape n x 64 x 4"),
    (lambda m, a: a.update(active_0=a["active_0"][:, :10]), "the array active_0 is bool of shape (6, 10)"),
    (lambda m, a: a.pop("best_rects_0"), "the array best_rects_0 is missing"),
    (lambda m, a: a.update(stat_0_logp=a["stat_0_logp"].astype("U8")), "the array stat_0_logp is <U8"),
    (lambda m, a: a["start_rects_0"].__setitem__((0, 2), 10 ** 6) or a["start_active_0"].__setitem__(0, True),
     "start_rects_0 holds a unit that is not a rectangle of the run's lattice"),
])
def test_a_resume_file_out_of_range_or_of_the_wrong_type_is_one_line(finished_run, tmp_path, capsys, edit, what):
    d = _edited_resume(finished_run, tmp_path, edit)
    assert main(["map", "--resume", str(d), "--draws", "4", "--progress", "none"]) == 2
    err = _err(capsys)
    assert err.startswith(f"semmap: error: {d / 'resume.npz'}: ") and what in err, err


def test_an_unedited_copy_resumes(finished_run, tmp_path, capsys):
    d = _edited_resume(finished_run, tmp_path, lambda m, a: None)
    assert main(["map", "--resume", str(d), "--draws", "4", "--progress", "none"]) == 0
    capsys.readouterr()


@pytest.mark.parametrize("at", ["last", 1.5, 0])
def test_a_bags_topic_and_time_in_a_resume_file_are_read(finished_run, tmp_path, at):
    """A run from a bag stores its --topic and --at (docs/cli.md): the checks take them."""
    from semmap_pp.sampler.resume import read_resume

    d = _edited_resume(finished_run, tmp_path,
                       lambda m, a: m["inputs"]["map_options"].update(topic="/map", at=at))
    state = read_resume(d, extra_draws=4)
    assert state is not None
