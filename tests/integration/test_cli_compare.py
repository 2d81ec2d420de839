"""`semmap compare MAP --rules A --rules B --out DIR` on a small real map with tiny settings."""

import json
from pathlib import Path

import pytest
from PIL import Image

from semmap_pp.cli import main

ROOT = Path(__file__).resolve().parents[2]
MAP = ROOT / "tests" / "data" / "maps" / "intel_corner.yaml"
RULES = ROOT / "rules"
TINY = ["--chains", "2", "--cores", "1", "--tune", "2", "--draws", "4", "--n-inner", "5", "--n-worlds", "6",
        "--spread-draws", "6"]


def test_compare_writes_table_json_and_figure(tmp_path, capsys):
    out = tmp_path / "cmp"
    code = main(["compare", str(MAP), "--rules", str(RULES / "table3.lp"), "--rules", str(RULES / "none.lp"),
                 "--out", str(out), "--seed", "4", *TINY])
    assert code == 0
    printed = capsys.readouterr().out
    assert printed.splitlines()[0] == "| quantity | table3 | none |"
    assert "| topological defects in W* |" in printed and "| R-hat log_posterior |" in printed
    md = (out / "compare.md").read_text()
    assert md.startswith("# Knowledge sets compared") and "| wall spread (mean p(1-p) over cells ever wall) |" in md \
        and "| wall disagreement, m² (Σ 2p(1-p) · cell area) |" in md
    doc = json.loads((out / "compare.json").read_text())
    assert [r["name"] for r in doc["rule_sets"]] == ["table3", "none"]
    assert doc["settings"]["seed"] == 4 and doc["settings"]["draws"] == 4
    for r in doc["rule_sets"]:
        assert isinstance(r["defects_best"], int) and r["defects_best"] >= 0
        # the sampled worlds come from the sample around W*: its chains in the best one's mode, 6 draws each
        assert r["around_wstar"] is True
        assert r["spread_chains"] and set(r["spread_chains"]) <= {1, 2}
        assert 1 <= r["spread_first_draw"] <= 4          # MSER cuts at most half the 6 draws
        assert r["n_worlds"] == min(6, (7 - r["spread_first_draw"]) * len(r["spread_chains"]))
        assert 0 <= r["cpr"] <= 1 and 0 <= r["wall_spread"] <= 0.25
        assert set(r["rhat"]) >= {"log_posterior", "n_units", "cpr"}
    # none.lp against table3.lp, unit by unit, as `semmap diff` of the two W*s
    assert "## W* unit by unit (`semmap diff`)" in printed and printed.index("## W* unit by unit") < printed.index(str(out))
    assert "W* of table3 -> W* of none" in md
    (diff,) = doc["wstar_diffs"]
    assert diff["old"] == "W* of table3" and diff["new"] == "W* of none"
    c = diff["counts"]
    assert c["paired"] + c["removed"] == c["units"][0] and c["paired"] + c["added"] == c["units"][1]
    assert {p["new"]["type"] for p in diff["units"]} | {u["type"] for u in diff["added"]} <= {"room", "exterior"}
    assert c["retyped"] == sum(p["old"]["type"] != p["new"]["type"] for p in diff["units"])
    w, h = Image.open(out / "compare.png").size
    assert w > h       # two panels side by side


def test_several_seeds_give_a_table_over_the_seeds_and_each_seeds_own(tmp_path, capsys):
    """``--seeds 4 5``: every rule set is run with each seed; each seed's columns are those of
    ``--seed N`` alone, and the table over the seeds sums them up. Run with ``--jobs 2`` (two
    runs at a time, each in a process of its own), which must change no number."""
    out = tmp_path / "cmp"
    rules = ["--rules", str(RULES / "table3.lp"), "--rules", str(RULES / "none.lp")]
    assert main(["compare", str(MAP), *rules, "--out", str(out), "--seeds", "4", "5", "4", "--jobs", "2",
                 *TINY]) == 0
    printed = capsys.readouterr().out
    assert printed.startswith("## Across seeds\n\n| quantity (seeds 4, 5: mean ± sd (min – max)) | table3 | none |")
    assert printed.index("## Seed 4\n\n| quantity | table3 | none |") < printed.index("## Seed 5\n")
    assert "| W* between seeds: mean unit F1 (IoU >= 0.5) |" in printed
    assert (out / "compare.md").read_text().endswith(printed.split(str(out))[0])
    doc = json.loads((out / "compare.json").read_text())
    assert doc["seeds"] == [4, 5] and [p["seed"] for p in doc["per_seed"]] == [4, 5]
    assert doc["rule_sets"] == doc["per_seed"][0]["rule_sets"] and doc["settings"]["seed"] == 4
    for j, name in enumerate(["table3", "none"]):
        col = doc["across_seeds"][j]
        assert col["name"] == name and col["seeds"] == [4, 5] and 0 <= col["mean_unit_f1"] <= 1
        for field in ("cpr", "defects_best", "n_units"):
            values = [p["rule_sets"][j][field] for p in doc["per_seed"]]
            assert col["quantities"][field]["mean"] == pytest.approx(sum(values) / 2)
            assert col["quantities"][field]["min"] == min(values) and col["quantities"][field]["max"] == max(values)
        assert col["converged"] == sum(p["rule_sets"][j]["converged"] for p in doc["per_seed"])
        assert col["reference_seed"] in (4, 5) and col["stable_units"] <= col["reference_units"]
    alone = tmp_path / "alone"
    assert main(["compare", str(MAP), *rules, "--out", str(alone), "--seed", "5", *TINY]) == 0
    one = json.loads((alone / "compare.json").read_text())
    drop = ("seconds",)
    assert [{k: v for k, v in r.items() if k not in drop} for r in one["rule_sets"]] == \
        [{k: v for k, v in r.items() if k not in drop} for r in doc["per_seed"][1]["rule_sets"]]


def test_seed_and_seeds_exclude_each_other(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["compare", str(MAP), "--rules", "a.lp", "--rules", "b.lp", "--seed", "1", "--seeds", "2", "3"])
    assert exc.value.code == 2 and "not allowed with argument" in capsys.readouterr().err


@pytest.mark.parametrize("rules, needle", [
    (["table3.lp"], "give --rules at least twice"),
    (["table3.lp", "missing.lp"], "missing.lp"),
])
def test_compare_user_errors(tmp_path, capsys, rules, needle):
    args = ["compare", str(MAP), "--out", str(tmp_path / "o"), *TINY]
    for r in rules:
        args += ["--rules", str(RULES / r)]
    assert main(args) == 2
    err = capsys.readouterr().err
    assert needle in err and err.count("\n") == 1
    assert not (tmp_path / "o").exists()


def test_compare_says_once_that_the_outside_was_read_as_unknown(tmp_path, capsys):
    """A map that shows its surroundings as free (tests/integration/test_grid_outside.py's two rooms in a sea):
    the note comes once, before the runs, on stderr."""
    from test_grid_outside import building, grid_of

    from semmap_pp.grid.write import save_grid

    path = save_grid(grid_of(building()), tmp_path / "sea.yaml")
    code = main(["compare", str(path), "--rules", str(RULES / "table3.lp"), "--rules",
                 str(RULES / "none.lp"), "--seed", "1", *TINY])
    assert code == 0
    err = capsys.readouterr().err
    assert err.count("note: ") == 1 and "read as unknown" in err
    assert err.index("note: ") < err.index("--- rules ")


def test_each_rule_set_gets_the_wstar_semmap_map_gives_it(tmp_path):
    """The rule sets share chain 1's start world (built by the first run: it depends on no rules),
    and each W* is still the one `semmap map --rules FILE` finds with the same seed and lengths."""
    out = tmp_path / "cmp"
    assert main(["compare", str(MAP), "--rules", str(RULES / "table3.lp"), "--rules", str(RULES / "none.lp"),
                 "--out", str(out), "--seed", "4", *TINY]) == 0
    doc = json.loads((out / "compare.json").read_text())
    one = tmp_path / "none"
    assert main(["map", str(MAP), "--rules", str(RULES / "none.lp"), "--out", str(one), "--seed", "4",
                 "--progress", "none", *TINY[:TINY.index("--n-worlds")], *TINY[TINY.index("--n-worlds") + 2:]]) == 0
    world = json.loads((one / "world.json").read_text())
    none = next(r for r in doc["rule_sets"] if r["name"] == "none")
    assert none["log_posterior"] == pytest.approx(world["log_posterior"], abs=1e-6)
    assert none["n_units"] == len(world["units"])


def test_a_rule_set_off_the_fast_path_is_named_once_before_the_runs(monkeypatch, capsys):
    """``run_each`` (compare, stability) notes each rule set that takes the knowledge engine's
    general path once, before the first run; a pairwise-local one gets no note."""
    import types

    import semmap_pp.run.pipeline as pipeline
    from semmap_pp.cli.runs import run_each
    from semmap_pp.knowledge import load_rules

    calls = []
    monkeypatch.setattr(pipeline, "run_map",
                        lambda inputs, settings, **kw: calls.append(inputs.rules) or
                        types.SimpleNamespace(starts=[]))
    base = types.SimpleNamespace(notes=(), rules=None)
    table3, halls = load_rules(RULES / "table3.lp"), load_rules(RULES / "halls_to_corridors.lp")
    jobs = [(name, types.SimpleNamespace(**{**vars(base), "rules": rs}), None)
            for name, rs in (("a", table3), ("b", halls), ("c", halls))]
    runs = run_each("compare", base, jobs)
    assert len(runs) == 3 and calls == [table3, halls, halls]
    err = capsys.readouterr().err
    notes = [line for line in err.splitlines() if "not pairwise-local" in line]
    assert len(notes) == 1 and "halls_to_corridors.lp" in notes[0]
    assert err.index(notes[0]) < err.index("--- a ---")
