"""Tests of weight learning (`semmap rules learn`, semmap_pp.knowledge.learn) and of labelled
examples (semmap_pp.studies.labelled)."""

from __future__ import annotations

import itertools
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from semmap_pp.cells import UNIT_TYPES
from semmap_pp.errors import EvidenceError, RuleError, SemmapError
from semmap_pp.knowledge import Evidence, KnowledgeEngine, load_rules
from semmap_pp.knowledge import learn as lm
from semmap_pp.studies import labelled

ROOT = Path(__file__).resolve().parents[2]
DATA = ROOT / "tests" / "data" / "learn"
TABLE3 = ROOT / "rules" / "table3.lp"
PLANTED = DATA / "planted.lp"


def run_cli(*args: str) -> subprocess.CompletedProcess:
    env = dict(os.environ, PYTHONWARNINGS="error")
    return subprocess.run([sys.executable, "-m", "semmap_pp", *args], capture_output=True,
                          text=True, timeout=300, env=env, cwd=ROOT)


def _floor():
    """Four units with hard and soft geometry, soft MulDoor and a cycle of adjacencies."""
    return Evidence.build([1, 2, 3, 4], rolike={2: 1.0, 3: 0.7}, colike={1: 1.0, 3: 0.2},
                          halike={4: 1.0}, muldoor={1: 1.0, 4: 0.6},
                          adj=[(1, 2), (1, 3), (1, 4), (2, 3)])


def _labellings(sr, ev, values):
    """Every labelling of ``ev``'s units with its probability under parameter ``values``."""
    net = lm._Network(sr, lm.Example("x", ev, {}))
    w = sr.weights(values)
    logz = lm._Term(net, {}, 1 << 22).value(w)[0]
    labs = list(itertools.product(range(4), repeat=len(ev.units)))
    p = np.array([np.exp(lm._Term(net, {i: (t,) for i, t in enumerate(lab)}, 1 << 22).value(w)[0]
                         - logz) for lab in labs])
    return labs, p


def test_the_likelihood_is_the_engines_distribution():
    """The probabilities of all 4^4 labellings sum to 1, and their sums per unit are the
    engine's type marginals."""
    sr = lm.soft_rules(TABLE3)
    ev = _floor()
    values = np.array([p.value / 1000 for p in sr.params])
    labs, p = _labellings(sr, ev, values)
    assert p.sum() == pytest.approx(1.0, abs=1e-9)
    marg = KnowledgeEngine.from_file(TABLE3, method="exact", template_store=False).infer(ev).types
    for i, u in enumerate(ev.units):
        mine = [p[[lab[i] == t for lab in labs]].sum() for t in range(4)]
        np.testing.assert_allclose(mine, marg[u], atol=1e-9)
    # and the likelihood of one labelling is its probability
    obj = lm.Objective(sr, [lm.Example("x", ev, dict(zip(ev.units, labs[37])))])
    assert np.exp(obj.log_likelihood(values)[0]) == pytest.approx(p[37], rel=1e-9)


def test_a_label_set_is_the_sum_of_its_types():
    sr = lm.soft_rules(TABLE3)
    ev = _floor()
    values = np.array([p.value / 1000 for p in sr.params])

    def lik(label):
        obj = lm.Objective(sr, [lm.Example("x", ev, {2: label, 4: (2,)})])
        return np.exp(obj.log_likelihood(values)[0])

    assert lik((0, 2, 3)) == pytest.approx(lik(0) + lik(2) + lik(3), rel=1e-9)


@pytest.mark.parametrize("objective", ["exact", "pseudo"])
def test_the_gradient_equals_a_finite_difference(objective):
    """Expected minus observed counts (exact, from the junction tree) against a central
    difference of the log posterior, for a labelling with a latent unit and a label set."""
    sr = lm.soft_rules(TABLE3)
    ev = _floor()
    ex = lm.Example("x", ev, {1: 1, 2: (0, 3), 4: 2})
    obj = lm.Objective(sr, [ex], sigma=0.7, objective=objective)
    rng = np.random.default_rng(3)
    x = obj.start + rng.uniform(-0.5, 0.5, len(obj.start))
    f, g = obj(x)
    h = 1e-5
    for j in range(len(x)):
        e = np.zeros(len(x))
        e[j] = h
        fd = (obj(x + e)[0] - obj(x - e)[0]) / (2 * h)
        assert g[j] == pytest.approx(fd, abs=1e-6), sr.params[j].name


def test_planted_weights_are_recovered():
    """Labelled worlds drawn from the exact distribution of a known weighting give the weights
    back.

    Tolerance: the learned weights maximise the log posterior; for n independent examples they
    are asymptotically normal around the planted weights with the inverse Fisher information as
    covariance, whose diagonal the learner reports as standard errors (from the Hessian). The
    prior (sigma 10 around the file's 1.0) moves an estimate by about (1.0 - w) SE^2 / sigma^2,
    under 0.001 here. So each weight is within 4 SE with probability 1 - 6e-5 (the draws are
    seeded: the test is deterministic), and n = 16000 draws make 4 SE at most 0.3 for every
    weight (asserted: the weakest, room_room_sale, is seen only through the latent SaLe atoms;
    its SE is 0.117 at n = 4000 and shrinks as 1/sqrt(n))."""
    sr = lm.soft_rules(PLANTED)
    assert [p.name for p in sr.params] == ["roli_room", "coli_corr", "muldoor_other",
                                           "corr_corr", "room_room_sale"]
    planted = np.array([1.5, 2.0, 0.8, 1.2, 1.0])
    rng = np.random.default_rng(0)
    pool = []
    for _ in range(16):
        n = int(rng.integers(1, 4))
        units = list(range(1, n + 1))
        ro, co, md = {}, {}, {}
        for u in units:
            k = rng.integers(3)
            if k == 0:
                ro[u] = 1.0
            elif k == 1:
                co[u] = 1.0
            else:
                co[u] = float(np.round(rng.uniform(0.2, 0.8), 2))
            if rng.random() < 0.4:
                md[u] = 1.0
        adj = [(p, q) for p in units for q in units if p < q and rng.random() < 0.7]
        pool.append(Evidence.build(units, rolike=ro, colike=co, muldoor=md, adj=adj))
    dists = [_labellings(sr, ev, planted) for ev in pool]
    n = 16000
    examples = []
    for i in range(n):
        k = int(rng.integers(len(pool)))
        labs, p = dists[k]
        j = rng.choice(len(p), p=p / p.sum())
        examples.append(lm.Example(f"draw{i}", pool[k], dict(zip(pool[k].units, labs[j]))))
    fit = lm.learn(sr, examples, sigma=10.0)
    assert np.all(4 * fit.se <= 0.3), fit.se
    assert np.all(np.abs(fit.values - planted) <= 4 * fit.se), (fit.values, fit.se)
    assert np.all(np.abs(fit.values - planted) <= 0.3)
    assert fit.methods == {f"draw{i}": "exact" for i in range(n)}


def test_the_pseudo_likelihood_recovers_the_weights_too():
    """On the same kind of draws (fewer, so a looser check) the pseudo-likelihood's estimate is
    within 4 of its standard errors of the planted weights."""
    sr = lm.soft_rules(PLANTED)
    planted = np.array([1.5, 2.0, 0.8, 1.2, 1.0])
    rng = np.random.default_rng(5)
    ev = Evidence.build([1, 2, 3], rolike={1: 1.0}, colike={2: 1.0, 3: 0.5}, muldoor={2: 1.0},
                        adj=[(1, 2), (2, 3), (1, 3)])
    ev2 = Evidence.build([1, 2], rolike={1: 1.0, 2: 1.0}, muldoor={1: 1.0}, adj=[(1, 2)])
    examples = []
    for k, e in enumerate((ev, ev2)):
        labs, p = _labellings(sr, e, planted)
        for i in range(4000):
            j = rng.choice(len(p), p=p)
            examples.append(lm.Example(f"{k}-{i}", e, dict(zip(e.units, labs[j]))))
    fit = lm.learn(sr, examples, sigma=10.0, objective="pseudo")
    assert set(fit.methods.values()) == {"pseudo"}
    ok = np.abs(fit.values - planted) <= 4 * fit.se + 1e-3
    assert ok.all(), (fit.values, fit.se)


def test_a_rule_file_without_a_soft_rule_is_an_error(tmp_path):
    f = tmp_path / "hard.lp"
    f.write_text(":- hall(U), rolike(U).\n")
    with pytest.raises(RuleError, match="has no soft rule"):
        lm.soft_rules(f)
    r = run_cli("rules", "learn", str(f), "--data", str(DATA / "synth"), "--out",
                str(tmp_path / "o.lp"))
    assert r.returncode == 2
    assert r.stderr.strip().count("\n") == 0
    assert f"{f}: has no soft rule" in r.stderr
    assert not (tmp_path / "o.lp").exists()


def test_soft_rules_sharing_an_id_are_refused(tmp_path):
    f = tmp_path / "dup.lp"
    f.write_text(":~ rolike(U), not room(U). [1000@0, same, U]\n"
                 ":~ colike(U), not corr(U). [1000@0, same, U]\n")
    with pytest.raises(RuleError, match="share the id 'same'"):
        lm.soft_rules(f)


def test_a_const_weight_is_one_parameter_of_its_rules(tmp_path):
    f = tmp_path / "c.lp"
    f.write_text("#const w = 1500.\n:~ rolike(U), not room(U). [w@0, a, U]\n"
                 ":~ colike(U), not corr(U). [w@0, b, U]\n:~ halike(U), room(U). [700@0, c, U]\n")
    sr = lm.soft_rules(f)
    assert [(p.name, p.value, p.rules, p.const) for p in sr.params] == [
        ("w", 1500, [0, 1], True), ("c", 700, [2], False)]
    text = lm.rewritten_text(sr, [2.25, 0.125])
    assert text.splitlines()[:4] == ["#const w = 2250.", ":~ rolike(U), not room(U). [w@0, a, U]",
                                     ":~ colike(U), not corr(U). [w@0, b, U]",
                                     ":~ halike(U), room(U). [125@0, c, U]"]


@pytest.mark.parametrize("text, message", [
    ("unit(1). rolike(1). label(1, kitchen).", "a type is one of room, corridor, hall, other"),
    ("unit(1). label(2, room).", "unit 2 is labelled but is not a unit of the evidence"),
    ("unit(1). rolike(1). cells(1, room, -3). label(1, room).", "a cell count is an integer"),
    ("unit(1). rolike(1).", "labels no unit"),
    ("unit(1). bogus(1). label(1, room).", "unknown evidence predicate bogus/1"),
    ("unit(1) label(1, room).", "syntax error"),
])
def test_bad_labelled_examples_are_one_line_errors(tmp_path, text, message):
    f = tmp_path / "ex.lp"
    f.write_text(text + "\n")
    with pytest.raises(EvidenceError, match=message) as info:
        lm.read_example(f)
    assert str(info.value).startswith(str(f))
    assert "\n" not in str(info.value)


def test_labels_that_break_the_hard_rules_are_an_error(tmp_path):
    f = tmp_path / "ex.lp"
    f.write_text("unit(1). rolike(1). label(1, hall).\n")     # planted.lp: no hall unless HaLi
    with pytest.raises(EvidenceError, match="the labels break the hard rules"):
        lm.learn(PLANTED, [lm.read_example(f)])


def test_data_paths_missing_or_empty_are_errors(tmp_path):
    with pytest.raises(EvidenceError, match="no such file or directory"):
        lm.data_files([tmp_path / "nope"])
    (tmp_path / "empty").mkdir()
    with pytest.raises(EvidenceError, match="holds no labelled evidence file"):
        lm.data_files([tmp_path / "empty"])
    r = run_cli("rules", "learn", str(TABLE3), "--data", str(tmp_path / "empty"), "--out",
                str(tmp_path / "o.lp"))
    assert r.returncode == 2 and r.stderr.count("\n") == 1
    assert "holds no labelled evidence file" in r.stderr


def test_the_cli_learns_writes_and_cross_validates(tmp_path):
    """End to end on the bundled synthetic examples: the learned file keeps every rule's text
    and only changes weights, each learned weight has its standard error in a comment, the
    file loads, and learning from it again replaces the comments instead of adding more."""
    out = tmp_path / "learned.lp"
    r = run_cli("rules", "learn", str(TABLE3), "--data", str(DATA / "synth"), "--out", str(out),
                "--json")
    assert r.returncode == 0, r.stderr
    doc = json.loads(r.stdout)
    assert doc["methods"] == ["exact"]
    assert len(doc["weights"]) == 19
    assert doc["log_likelihood"]["learned"] >= doc["log_likelihood"]["file"]
    rs, base = load_rules(out), load_rules(TABLE3)
    assert (rs.n_hard, rs.n_soft) == (base.n_hard, base.n_soft)
    strip = lambda t: [ln.split("[")[0] for ln in t.splitlines() if not ln.startswith("%")]
    assert strip(out.read_text()) == strip(TABLE3.read_text())
    notes = [ln for ln in out.read_text().splitlines() if "% learned: w = " in ln]
    assert len(notes) == 19
    for w in doc["weights"]:
        line = next(ln for ln in notes if f", {w['name']}," in ln)
        assert f"[{w['learned']}@0" in line
        assert f"+- {w['se']:.3f} s.e." in line
    again = tmp_path / "again.lp"
    r = run_cli("rules", "learn", str(out), "--data", str(DATA / "synth"), "--out", str(again))
    assert r.returncode == 0, r.stderr
    text = again.read_text()
    assert text.count("% learned:") == 19 and text.count(lm.HEADER) == 1
    r = run_cli("rules", "learn", str(TABLE3), "--data", str(DATA / "synth"), "--cv", "--json")
    assert r.returncode == 0, r.stderr
    cv = json.loads(r.stdout)["cv"]
    assert [Path(row["example"]).name for row in cv["rows"]] == ["synth-0.lp", "synth-1.lp",
                                                                "synth-2.lp"]
    for row in cv["rows"]:
        assert 0.0 <= row["cell_accuracy_learned"] <= 1.0 and row["cells"] > 0


def test_cell_counts_and_majority_labels():
    units = np.array([[1, 1, 2, 0], [1, 2, 2, 3]])
    truth = np.array([[0, 1, 1, 0], [0, -1, 1, 1]])   # room, corridor, none
    counts, uncovered = labelled.cell_counts(units, truth, [1, 2])   # id 3 is no unit here
    assert counts[1].tolist() == [2, 1, 0, 0] and counts[2].tolist() == [0, 2, 0, 0]
    assert uncovered.tolist() == [1, 1, 0, 0]
    values = labelled.IPA_VALUES
    assert labelled.majority_labels(counts, values) == {1: (0, 2, 3), 2: (1,)}
    ex = lm.Example("x", Evidence.build([1, 2]), {1: 0, 2: 1}, counts, uncovered)
    s = lm.score(ex, {1: 3, 2: 1})    # other counts as room, as the ipa score reads it
    # 7 truth cells: unit 1 holds 2 room + 1 corridor, unit 2 2 corridor, 1 + 1 in no unit
    assert s["cells"] == 7 and s["cell_accuracy"] == pytest.approx(4 / 7)
    assert s["recall_room"] == pytest.approx(2 / 3) and s["recall_corridor"] == pytest.approx(2 / 4)


def test_truth_values_are_checked():
    assert labelled.parse_values("10=hall,20=room|other") == {10: ("hall",), 20: ("room", "other")}
    for bad in ("77=kitchen", "x=room", "77", "77=room|room", ""):
        with pytest.raises(SemmapError):
            labelled.parse_values(bad)


def test_a_synthetic_example_is_the_truth_plan():
    text = labelled.synthetic_example(1)
    assert text == (DATA / "synth" / "synth-1.lp").read_text()
    ex = lm.example_from_text(text, "synth-1.lp")
    assert len(ex.labels) == len(ex.evidence.units) == 6
