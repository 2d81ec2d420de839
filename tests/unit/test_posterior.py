"""Tests of semmap_pp.target.posterior: the Tracker agrees with the full evaluation, types included."""

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

from semmap_pp import world as wm
from semmap_pp.cells import UNIT_TYPES
from semmap_pp.target.geometry_evidence import FixedResult, build_evidence
from semmap_pp.lattice.frame import build_frame_from_classes
from semmap_pp.target.posterior import Posterior
from semmap_pp.model import load_model
from semmap_pp.target.prior import log_p_n, log_p_rect_const, log_slots

MODEL = load_model()


class NeighbourProvider:
    """A stand-in engine whose types depend on the neighbours: a unit with two or more
    neighbours is a corridor, else a room; P(SaLe) = 0.9 for every adjacent pair.
    An edit of one unit therefore changes the types of *other* units."""

    needs_doors = False

    def __init__(self):
        self.calls = 0

    def infer(self, ev):
        self.calls += 1
        deg = {u: 0 for u in ev.units}
        for p, q in ev.adj:
            deg[p] += 1
            deg[q] += 1
        names = {u: ("corridor" if deg[u] >= 2 else "room") for u in ev.units}
        eye = np.eye(4)
        return FixedResult({u: eye[UNIT_TYPES.index(n)] for u, n in names.items()},
                           {pq: 0.9 for pq in ev.adj}, names)


def posterior(rng, knowledge=None, shape=(90, 120)):
    cls = rng.choice(3, size=shape, p=[0.6, 0.25, 0.15]).astype(np.uint8)
    cls[shape[0] // 2, :] = 2
    post = Posterior(build_frame_from_classes(cls, 0.05, MODEL, theta=0.0), MODEL, knowledge)
    post.knowledge_on = knowledge is not None
    return post


def random_rect(rng, shape, lo=21):
    h, w = rng.integers(lo, min(70, shape[0])), rng.integers(lo, min(70, shape[1]))
    r0, c0 = rng.integers(0, shape[0] - h + 1), rng.integers(0, shape[1] - w + 1)
    return (int(r0), int(c0), int(r0 + h), int(c0 + w))


def random_proposal(rng, world, shape):
    s = int(rng.integers(world.capacity))
    if world.active[s] and rng.random() < 0.15:
        return wm.remove(world, s), [s]
    if not world.active[s]:
        return wm.add(world, s, random_rect(rng, shape)), [s]
    r = list(world.rects[s])
    r[rng.integers(4)] += int(rng.integers(-8, 9))
    return wm.replace(world, s, r), [s]


@pytest.mark.slow
@pytest.mark.parametrize("with_engine", [False, True])
def test_tracker_equals_full_evaluation(with_engine):
    rng = np.random.default_rng(11)
    provider = NeighbourProvider() if with_engine else None
    post = posterior(rng, provider)
    shape = post.frame.shape
    w = wm.empty(8)
    for s in range(5):
        w = wm.add(w, s, random_rect(rng, shape))
    tr = post.start(w)
    assert tr.logp == pytest.approx(post.evaluate(w).total, rel=1e-12)
    other_type_changes = 0
    for _ in range(600):
        nw, changed = random_proposal(rng, tr.world, shape)
        prop = tr.propose(nw, changed)
        full = post.evaluate(nw)
        assert np.array_equal(prop.world.types, full.world.types)
        if math.isinf(full.total):
            assert prop.logp == full.total
        else:
            assert prop.logp == pytest.approx(full.total, rel=1e-9, abs=0)
        moved = np.flatnonzero(prop.world.types != tr.world.types)
        other_type_changes += int(np.any(~np.isin(moved, changed)))
        if math.isfinite(prop.logp) and rng.random() < 0.7:
            tr.accept(prop)
    if with_engine:
        assert other_type_changes > 0       # the case the tracker must handle did occur
        assert provider.calls > 0


def test_fixed_types_follow_the_geometry_class():
    rng = np.random.default_rng(2)
    post = posterior(rng, shape=(200, 400))
    w = wm.add(wm.add(wm.empty(4), 0, (0, 0, 80, 100)), 1, (100, 0, 140, 400))
    terms = post.evaluate(w)
    assert [UNIT_TYPES[t] for t in terms.world.types[:2]] == ["room", "corridor"]
    assert terms.world.types[2] == wm.NO_TYPE


def test_prior_of_a_world_without_adjacent_pairs():
    rng = np.random.default_rng(3)
    post = posterior(rng)
    w = wm.add(wm.add(wm.empty(6), 0, (0, 0, 30, 30)), 3, (50, 60, 90, 120))
    c = post.cells
    expected = (log_p_n(2, 6, MODEL.prior) - log_slots(2, 6)
                + 2 * log_p_rect_const(post.frame.shape, c.min_side, c.max_side))
    assert post.evaluate(w).logprior == pytest.approx(expected)
    # a unit narrower than the minimum side has prior probability 0
    assert post.evaluate(wm.replace(w, 0, (0, 0, 30, 5))).logprior == -math.inf


def test_coverage_counts_free_cells_under_units():
    cls = np.ones((40, 40), np.uint8)
    cls[0:20, :] = 0
    post = Posterior(build_frame_from_classes(cls, 0.05, MODEL, theta=0.0), MODEL)
    tr = post.start(wm.add(wm.empty(2), 0, (0, 0, 20, 20)))
    assert tr.coverage() == pytest.approx(0.5)


def test_resync_after_switching_knowledge_on():
    rng = np.random.default_rng(9)
    provider = NeighbourProvider()
    post = posterior(rng, provider)
    post.knowledge_on = False
    w = wm.empty(6)
    for s, rect in enumerate([(0, 0, 40, 30), (0, 29, 40, 60), (0, 59, 40, 90)]):
        w = wm.add(w, s, rect)
    tr = post.start(w)
    assert [UNIT_TYPES[t] for t in tr.world.types[:3]] == ["room"] * 3
    post.knowledge_on = True
    tr.resync()
    assert UNIT_TYPES[tr.world.types[1]] == "corridor"      # two neighbours
    assert tr.logp == pytest.approx(post.evaluate(w).total, rel=1e-12)


def knowledge_floor():
    """A 16.5 m x 24.5 m floor at 0.25 m cells: four rooms (4 m x 6 m), a corridor (2 m x 24 m)
    and a hall (9 m x 24 m), doors between them, unknown outside. The true units carry hard
    geometry evidence; the sampler's near-threshold shapes carry soft evidence."""
    c = np.full((68, 100), 1, np.uint8)
    c[1:67, 1:99] = 2                       # walls everywhere ...
    for r0, r1 in ((2, 18), (19, 27), (28, 66)):
        c[r0:r1, 2:98] = 0                  # ... but free rows: rooms, corridor, hall
    c[2:18, [26, 50, 74]] = 2               # room walls
    for col in (8, 32, 56, 80):
        c[18, col:col + 6] = 0              # room doors onto the corridor
    c[27, 44:52] = 0                        # corridor door onto the hall
    return c


@pytest.mark.slow
def test_tracker_equals_full_evaluation_with_knowledge_over_20000_kernels(monkeypatch):
    """20,000 random kernels with the table3.lp engine: the incremental log posterior, its
    types and its knowledge evidence equal a full evaluation along the way and at the end, and so
    does every 50th proposal (accepted or not). The chain runs at temperature 5 so that it moves
    (the property does not depend on the temperature)."""
    from pathlib import Path

    from semmap_pp.sampler.kernels import data_from_frame, default_mix
    from semmap_pp.knowledge import KnowledgeEngine
    from semmap_pp.sampler.mcmc import run_chain

    engine = KnowledgeEngine.from_file(Path(__file__).resolve().parents[2] / "rules/table3.lp")
    # fewer soft units than the default model (each new soft probability costs the engine a
    # grounding), so that 20,000 kernels run in seconds; soft evidence still occurs. A one-cell
    # wall band at 0.25 m a cell, as the floor was drawn for (the default's minimum is two cells)
    model = dataclasses.replace(MODEL, evidence=dataclasses.replace(MODEL.evidence, hard_above=0.75),
                                world=dataclasses.replace(MODEL.world, wall_min_cells=1))
    post = Posterior(build_frame_from_classes(knowledge_floor(), 0.25, model, theta=0.0), model,
                     engine)
    post.knowledge_on = True
    data = data_from_frame(post.frame)
    tr = post.start(wm.empty(6))
    checked = {"proposals": 0, "soft": 0, "other_type_changes": 0}

    class Checked:
        """The tracker, with every 50th proposal compared to a full evaluation."""

        def __init__(self, inner):
            self.inner, self.n = inner, 0

        world = property(lambda self: self.inner.world)
        logp = property(lambda self: self.inner.logp)

        def propose(self, world, changed):
            prop = self.inner.propose(world, changed)
            self.n += 1
            if self.n % 50 == 0:
                full = post.evaluate(world)
                assert np.array_equal(prop.world.types, full.world.types)
                assert prop.logp == pytest.approx(full.total, rel=1e-9, abs=0)
                checked["proposals"] += 1
                moved = np.flatnonzero(prop.world.types != self.inner.world.types)
                checked["other_type_changes"] += int(np.any(~np.isin(moved, changed)))
            return prop

        def accept(self, prop):
            self.inner.accept(prop)

    def check(i, tracker, accepted):
        if (i + 1) % 2500:
            return
        full = post.evaluate(tr.world)
        assert np.array_equal(tr.world.types, full.world.types)
        assert tr.logp == pytest.approx(full.total, rel=1e-9, abs=0)
        typ = post.typing(tr.world)
        slots = wm.active_slots(tr.world)
        rects = tr.world.rects[slots]
        sub = typ.adj[np.ix_(slots, slots)]
        ev = build_evidence(slots, rects, sub, post.cells.resolution, model.evidence,
                            *post.door_counts(rects, sub))
        assert tr._evidence == ev.to_knowledge()      # the incremental evidence is the full one
        checked["soft"] += len(ev.soft)

    # the proposals that keep the current MulDoor flags and corridor pieces (Tracker._same_openings)
    # are among those checked: count them
    kept = []
    same = type(tr)._same_openings
    monkeypatch.setattr(type(tr), "_same_openings", lambda self, *a: kept.append(same(self, *a)) or kept[-1])
    rng = np.random.default_rng(7)
    stats = run_chain(rng, Checked(tr), default_mix(data.settings), 20_000, data, temperature=10.0,
                      callback=check)
    assert sum(kept) > 1000 and len(kept) - sum(kept) > 1000, (sum(kept), len(kept))
    assert stats.attempted.sum() == 20_000 and stats.accepted.sum() > 100
    assert checked["proposals"] >= 250 and checked["soft"] > 0      # 294 with this seed
    assert checked["other_type_changes"] > 0     # knowledge retyped a unit the kernel left alone
    assert wm.n_units(tr.world) >= 2


def test_pair_openings_equal_the_door_detector():
    """The compiled, cached (doors, passages) count of a pair equals the lengths of
    ``openings_between(...)``, in both orders, for pairs around the true rooms of a floor (doors
    and passages present) and random pairs."""
    from semmap_pp.derive.doors import openings_between

    post = Posterior(build_frame_from_classes(knowledge_floor(), 0.25, MODEL, theta=0.0), MODEL)
    rng = np.random.default_rng(12)
    truth = [(1, 1, 19, 27), (1, 25, 19, 51), (18, 1, 28, 99), (26, 1, 67, 99)]
    seen = set()
    for _ in range(400):
        if rng.random() < 0.7:
            i, j = rng.choice(len(truth), 2, replace=False)
            rp = np.array(truth[i]) + rng.integers(-2, 3, 4)
            rq = np.array(truth[j]) + rng.integers(-2, 3, 4)
        else:
            rp, rq = (np.array(random_rect(rng, post.frame.shape, lo=4)) for _ in range(2))
        for a, b in ((rp, rq), (rq, rp)):
            doors, passages = openings_between(post.frame.classes, a, b, post.cells)
            expected = (len(doors), len(passages))
            assert post.pair_openings(a.astype(np.int32), b.astype(np.int32)) == expected
            seen.add(expected)
    assert {d for d, _ in seen} >= {0, 1, 2} and max(p for _, p in seen) >= 1


def recorded_bounds(monkeypatch, name: str = "_type_free_bound") -> list:
    """The bound ``posterior.<name>`` of every proposal that takes it from now on, in order: by
    default the type-free bound (no types, per category the better gain, SaLe factor at most 1);
    ``"_fixed_bound"``: the fixed provider's on a tiled lattice, without the pairs of two tiles."""
    import semmap_pp.target.posterior as P

    seen, bound = [], getattr(P, name)

    def recording(*args):
        value = bound(*args)
        seen.append(float(value))
        return value

    monkeypatch.setattr(P, name, recording)
    return seen


def assert_below_bound(full, bound):
    """``full`` (a full evaluation) is at most the upper ``bound`` (to the skip test's 1e-9)."""
    assert full == -math.inf if bound == -math.inf else full <= bound + 1e-9 * abs(bound), (full, bound)


@pytest.mark.slow
@pytest.mark.parametrize("rule_file", ["table3.lp", "halls_to_corridors.lp"])
def test_floor_skips_the_provider_only_below_the_bound(rule_file, monkeypatch):
    """With a floor (MH with the uniform drawn first), a proposal comes back unevaluated only
    when its true log posterior is below the floor; otherwise it is the full evaluation; and
    both cases occur along a chain with the engine of table3.lp (templates) and of
    halls_to_corridors.lp (the general path, which also gives MAP types
    without marginals); the tracked log posterior stays the full evaluation.

    Mutant class "the knowledge-free bound" (docs/robustness.md, "Mutants"): every skipped
    proposal is evaluated in full (below its floor and below its type-free bound), and the
    type-free bound of every proposal is at least its full evaluation."""
    from pathlib import Path

    from semmap_pp.sampler.kernels import data_from_frame, default_mix
    from semmap_pp.knowledge import KnowledgeEngine

    engine = KnowledgeEngine.from_file(Path(__file__).resolve().parents[2] / "rules" / rule_file)
    assert engine.has_map_only and (engine.local is None) == (rule_file != "table3.lp")
    post = Posterior(build_frame_from_classes(knowledge_floor(), 0.25, MODEL, theta=0.0), MODEL,
                     engine)
    post.knowledge_on = True
    data = data_from_frame(post.frame)
    mix = default_mix(data.settings)
    tr = post.start(wm.empty(6))
    rng = np.random.default_rng(5)
    bounds = recorded_bounds(monkeypatch)
    n_bounded = n_full = 0
    for _ in range(1500):
        _, proposal = mix(rng, tr.world, data)
        if proposal is None:
            continue
        floor = tr.logp + 5.0 * (math.log(rng.random()) - proposal.log_ratio)
        before = len(bounds)
        prop = tr.propose(proposal.world, proposal.changed_slots, floor=floor)
        assert len(bounds) == before + 1
        if prop.bounded:
            n_bounded += 1
            full = post.evaluate(proposal.world).total
            assert full < floor
            assert_below_bound(full, bounds[-1])
            with pytest.raises(ValueError):
                tr.accept(prop)
            continue
        n_full += 1
        assert_below_bound(prop.logp, bounds[-1])
        if n_full % 5 == 0:
            assert prop.logp == pytest.approx(post.evaluate(proposal.world).total, rel=1e-9, abs=0)
        if prop.logp >= floor:
            tr.accept(prop)
    assert n_bounded >= 100 and n_full >= 50 and tr.skipped[0] > 0
    assert tr.logp == pytest.approx(post.evaluate(tr.world).total, rel=1e-9, abs=0)



class MapNeighbourProvider(NeighbourProvider):
    """:class:`NeighbourProvider` that can also give its MAP types alone (as the engine's fast
    path does), counting both kinds of call."""

    has_map_only = True

    def __init__(self):
        super().__init__()
        self.map_calls = 0

    def map_types(self, ev):
        self.map_calls += 1
        return NeighbourProvider.infer(self, ev).map_types


def test_map_types_bound_skips_only_proposals_below_the_floor(monkeypatch):
    """The second bound (MAP types from the provider without its marginals: exact likelihood,
    SaLe factor at most 1) skips a proposal only when its full evaluation is below the floor,
    and skips proposals the type-free bound let through; a chain with floors makes the same
    moves as one without, and asks the provider for marginals less often. Every skipped
    proposal is evaluated in full, and the type-free bound is never below a full evaluation
    (mutant class "the knowledge-free bound")."""
    runs = []
    bounds = recorded_bounds(monkeypatch)
    for use_floor in (True, False):
        rng = np.random.default_rng(21)
        provider = MapNeighbourProvider()
        post = posterior(rng, provider)
        world = wm.empty(6)
        for s in range(4):
            world = wm.add(world, s, random_rect(rng, post.frame.shape))
        tr = post.start(world)
        ref = Posterior(post.frame, MODEL, NeighbourProvider())   # full evaluations, apart
        ref.knowledge_on = True                                   # from the provider's count
        moves, checked, evaluated = [], 0, 0
        for _ in range(600):
            new, changed = random_proposal(rng, tr.world, post.frame.shape)
            floor = tr.logp + math.log(rng.random())
            before, n_bounds = tr.skipped[1], len(bounds)
            prop = tr.propose(new, changed, floor=floor if use_floor else None)
            bound = bounds[-1] if len(bounds) > n_bounds else None
            assert (bound is not None) == use_floor
            if prop.bounded:
                full = ref.evaluate(new).total
                assert full < floor
                assert_below_bound(full, bound)
                checked += tr.skipped[1] > before           # skipped by the MAP-types bound
                continue
            if bound is not None:
                assert_below_bound(prop.logp, bound)
            evaluated += 1
            if evaluated % 10 == 0:
                assert prop.logp == pytest.approx(post.evaluate(new).total, rel=1e-9, abs=0)
            if prop.logp > floor:
                tr.accept(prop)
                moves.append(tr.world.rects.copy())
        if use_floor:
            assert tr.skipped[0] >= 20 and tr.skipped[1] >= 10 and checked >= 10
        assert tr.logp == pytest.approx(post.evaluate(tr.world).total, rel=1e-9, abs=0)
        runs.append((moves, provider.calls))
    (a, calls_floor), (b, calls_full) = runs
    assert len(a) == len(b) >= 20 and all(np.array_equal(x, y) for x, y in zip(a, b))
    assert calls_floor < calls_full


def test_same_evidence_shortcut_is_exact_and_makes_the_same_moves(monkeypatch):
    """Tracker._same_evidence (evidence unchanged, judged on the changed slots alone) says True
    only when the evidence built in full equals the current one, and a chain with the shortcut
    makes exactly the moves of one without it (table3.lp engine, floors passed)."""
    from pathlib import Path

    from semmap_pp.sampler.kernels import data_from_frame, default_mix
    from semmap_pp.knowledge import KnowledgeEngine
    from semmap_pp.sampler.mcmc import run_chain
    from semmap_pp.target.posterior import Tracker

    rules = Path(__file__).resolve().parents[2] / "rules/table3.lp"
    frame = build_frame_from_classes(knowledge_floor(), 0.25, MODEL, theta=0.0)
    same = Tracker._same_evidence
    seen = {True: 0, False: 0}

    def checked(self, world, adj, many, pieces, changed):
        out = same(self, world, adj, many, pieces, changed)
        seen[out] += 1
        if out:
            assert self._knowledge_evidence(world, adj, many, pieces) == self._evidence
        return out

    def chain(check):
        post = Posterior(frame, MODEL, KnowledgeEngine.from_file(rules))
        post.knowledge_on = True
        data = data_from_frame(post.frame)
        tr = post.start(wm.empty(6))
        trace = []
        run_chain(np.random.default_rng(11), tr, default_mix(data.settings), 1500, data, 20.0,
                  callback=lambda i, t, ok: trace.append((ok, t.logp)))
        return trace, tr

    monkeypatch.setattr(Tracker, "_same_evidence", checked)
    with_shortcut, tr = chain(True)
    assert seen[True] >= 50 and seen[False] >= 50
    monkeypatch.setattr(Tracker, "_same_evidence", lambda *a: False)
    without, _ = chain(False)
    assert with_shortcut == without and sum(ok for ok, _ in without) >= 10
    assert tr.logp == pytest.approx(tr.post.evaluate(tr.world).total, rel=1e-9, abs=0)


@pytest.mark.slow
def test_patched_evidence_equals_the_evidence_built_in_full(monkeypatch):
    """Tracker._patched_evidence (the current evidence edited at the changed slots and the
    slots whose MulDoor or corridor-piece flag changed) equals the evidence built in full over
    every unit, on every proposal of a chain that adds, removes and reshapes units (table3.lp
    engine, the corridor-space scopes of the default model)."""
    from pathlib import Path

    from semmap_pp.sampler.kernels import data_from_frame, default_mix
    from semmap_pp.knowledge import KnowledgeEngine
    from semmap_pp.sampler.mcmc import run_chain
    from semmap_pp.target.posterior import Tracker

    rules = Path(__file__).resolve().parents[2] / "rules/table3.lp"
    model = dataclasses.replace(MODEL, world=dataclasses.replace(MODEL.world, wall_min_cells=1))
    frame = build_frame_from_classes(knowledge_floor(), 0.25, model, theta=0.0)
    patched = Tracker._patched_evidence
    seen = {"calls": 0, "units": 0, "adj": 0, "muldoor": 0, "pieces": 0}

    def checked(self, world, adj, many, pieces, changed):
        out = patched(self, world, adj, many, pieces, changed)
        assert out == self._knowledge_evidence(world, adj, many, pieces)
        old = self._evidence
        seen["calls"] += 1
        seen["units"] += out.units != old.units
        seen["adj"] += out.adj != old.adj
        seen["muldoor"] += out.muldoor != old.muldoor
        seen["pieces"] += bool(np.any(pieces != self._pieces))
        return out

    monkeypatch.setattr(Tracker, "_patched_evidence", checked)
    post = Posterior(frame, model, KnowledgeEngine.from_file(rules))
    post.knowledge_on = True
    data = data_from_frame(post.frame)
    tr = post.start(wm.empty(6))
    run_chain(np.random.default_rng(3), tr, default_mix(data.settings), 8000, data, 100.0)
    # this seed: 1086 calls; units added or removed 6 times (births and deaths are mostly
    # bounded below their floor first; tests/unit/test_evidence.py patches those at random)
    assert seen["calls"] >= 500 and seen["units"] >= 3, seen
    assert seen["adj"] >= 100 and seen["muldoor"] >= 50 and seen["pieces"] >= 1, seen
    assert tr.logp == pytest.approx(post.evaluate(tr.world).total, rel=1e-9, abs=0)


def corridor_in_pieces(pieces, **evidence):
    """The knowledge floor's four rooms, hall and corridor, the corridor as the rectangles
    ``pieces``, under table3 with knowledge on and the ``[evidence]`` keys ``evidence``:
    ``(posterior, rects, world)``."""
    from pathlib import Path

    from semmap_pp.knowledge import KnowledgeEngine

    model = dataclasses.replace(MODEL, evidence=dataclasses.replace(MODEL.evidence, **evidence))
    frame = build_frame_from_classes(knowledge_floor(), 0.25, model, theta=0.0)
    engine = KnowledgeEngine.from_file(Path(__file__).resolve().parents[2] / "rules/table3.lp")
    post = Posterior(frame, model, engine)
    post.knowledge_on = True
    rooms = [(1, 1, 19, 27), (1, 25, 19, 51), (1, 49, 19, 75), (1, 73, 19, 99)]
    rects = rooms + [(26, 1, 67, 99)] + list(pieces)
    world = wm.empty(10)
    for s, r in enumerate(rects):
        world = wm.add(world, s, r)
    return post, rects, world


@pytest.mark.parametrize("scope", ["unit", "space"])
def test_a_corridor_in_two_pieces_counts_its_doors_as_one_space(scope):
    """The corridor of the knowledge floor cut in two at column 62, joined by an open passage:
    the west piece has three room doors and the hall door, the east piece one room door. With
    ``muldoor_scope = "unit"`` the east piece has no MulDoor and table3 types it *other* (CoLi and
    not MulDoor); with "space" it counts the corridor's five doors and is typed corridor. The
    tracker agrees with the full evaluation either way, also after the cut moves."""
    post, rects, world = corridor_in_pieces([(18, 1, 28, 63), (18, 61, 28, 99)], muldoor_scope=scope)
    assert post.pair_openings(rects[5], rects[6]) == (0, 1)     # an open passage, no door
    assert post.door_counts(np.array(rects), post.typing(world).adj[:7, :7])[0].tolist()[5:] == \
        ([4, 1] if scope == "unit" else [5, 5])
    types = [UNIT_TYPES[t] for t in post.typing(world).world.types[:7]]
    assert types[:4] == ["room"] * 4 and types[5] == "corridor"
    assert types[6] == ("other" if scope == "unit" else "corridor")
    tr = post.start(world)
    moved = wm.replace(wm.replace(world, 5, (18, 1, 28, 41)), 6, (18, 39, 28, 99))
    tr.accept(tr.propose(moved, (5, 6)))
    assert tr.logp == pytest.approx(post.evaluate(moved).total, rel=1e-12)
    assert np.array_equal(tr.world.types, post.typing(moved).world.types)


@pytest.mark.parametrize("scope", ["unit", "space"])
def test_a_short_piece_of_a_corridor_is_corridor_like_as_part_of_its_space(scope):
    """The knowledge floor's corridor cut near its east end, joined by an open passage: the long
    west piece is corridor-like, the short east square (10 x 18 cells) room-like with one room
    door. With ``colike_scope = "unit"`` table3 types the square *room* (RoLi, not MulDoor); with
    "space" it is a piece of the corridor (its width at most twice the corridor's): corridor-like,
    it counts the corridor's doors, and it is typed corridor. Tracker = full evaluation either
    way, also when a move makes the square wider than twice the corridor (it is a room again)."""
    post, rects, world = corridor_in_pieces([(18, 1, 28, 83), (18, 81, 28, 99)], muldoor_scope="space",
                                            colike_scope=scope, space_width_ratio=2.0)
    assert post.pair_openings(rects[5], rects[6])[1] > 0          # an open passage
    counts, pieces = post.door_counts(np.array(rects), post.typing(world).adj[:7, :7])
    assert pieces.tolist() == [False] * 6 + [scope == "space"]
    types = [UNIT_TYPES[t] for t in post.typing(world).world.types[:7]]
    assert types[5] == "corridor"
    assert types[6] == ("room" if scope == "unit" else "corridor")
    tr = post.start(world)
    assert tr._pieces[:7].tolist() == pieces.tolist()
    # the square grows to 23 x 24 cells: wider than twice the corridor (10): not a piece
    wide = wm.replace(world, 6, (14, 75, 37, 99))
    prop = tr.propose(wide, (6,))
    tr.accept(prop)
    assert tr.logp == pytest.approx(post.evaluate(wide).total, rel=1e-12)
    assert np.array_equal(tr.world.types, post.typing(wide).world.types)
    assert not tr._pieces.any()
    back = tr.propose(world, (6,))
    tr.accept(back)
    assert tr.logp == pytest.approx(post.evaluate(world).total, rel=1e-12)
    assert tr._pieces[6] == (scope == "space")


@pytest.mark.slow
def test_the_map_types_bound_under_a_rule_set_off_the_fast_path(monkeypatch):
    """Under rules that are not pairwise-local (the engine's general path) the tracker asks the
    engine for MAP types alone first: along a chain from the data-driven start world of a small
    real map, every proposal that this second bound skips has a true log posterior below its
    floor, the bound does skip some, and the tracked log posterior stays the full evaluation.
    The type-free bound is at least the log posterior of every proposal evaluated (mutant class
    "the knowledge-free bound"; the proposals it skips, most of the 4,000, are not evaluated
    here, a minute of the general path: the two floor tests above evaluate every one they skip)."""
    from semmap_pp.sampler.kernels import data_from_frame, default_mix
    from semmap_pp.run.inputs import load_inputs
    from semmap_pp.run.pipeline import data_start_world
    from semmap_pp.run.target_factory import run_target

    root = Path(__file__).resolve().parents[2]
    inputs = load_inputs(root / "tests/data/maps/intel_corner.yaml",
                         rules_path=root / "rules/halls_to_corridors.lp")
    post = run_target(inputs)
    assert post.knowledge.local is None and post.knowledge.has_map_only
    post.knowledge_on = True
    data = data_from_frame(post.frame)
    mix = default_mix(data.settings)
    tr = post.start(data_start_world(inputs))
    rng = np.random.default_rng(5)
    bounds = recorded_bounds(monkeypatch)
    for _ in range(4000):
        _, proposal = mix(rng, tr.world, data)
        if proposal is None:
            continue
        floor = tr.logp + math.log(rng.random()) - proposal.log_ratio
        before = tr.skipped[1]
        prop = tr.propose(proposal.world, proposal.changed_slots, floor=floor)
        if not prop.bounded:
            assert_below_bound(prop.logp, bounds[-1])
        if tr.skipped[1] > before:
            assert post.evaluate(proposal.world).total < floor
        if not prop.bounded and prop.logp >= floor:
            tr.accept(prop)
    assert tr.skipped[1] >= 1
    assert tr.logp == pytest.approx(post.evaluate(tr.world).total, rel=1e-9, abs=0)


def _pipeline_target(rules):
    """The target ``semmap map`` builds for tests/data/maps/intel_corner.yaml
    (:func:`semmap_pp.run.target_factory.run_target` of :func:`~semmap_pp.run.inputs.load_inputs`), with the
    rule file ``rules`` (knowledge on) or none (knowledge off)."""
    from semmap_pp.run.inputs import load_inputs
    from semmap_pp.run.target_factory import run_target

    root = Path(__file__).resolve().parents[2]
    kw = {"rules_path": root / "rules" / rules} if rules else {"rules_path": None}
    post = run_target(load_inputs(root / "tests/data/maps/intel_corner.yaml", **kw))
    assert post.knowledge_on == (rules is not None)
    return post


def _reference_log_prior(post, world, typ):
    """:func:`semmap_pp.target.prior.log_prior` of ``world``'s active units, with the adjacency and the
    P(SaLe) of the typing ``typ`` (the fixed table by type when its ``sale`` is None)."""
    from semmap_pp.target.prior import log_prior

    slots = wm.active_slots(world)
    adj = typ.adj[np.ix_(slots, slots)]
    types = typ.world.types[slots]
    sale = (post.fixed.fixed_sale[np.ix_(types, types)] if typ.sale is None
            else typ.sale[np.ix_(slots, slots)])
    c = post.cells
    return log_prior(world.rects[slots], world.capacity, post.frame.shape, c.min_side, c.max_side,
                     adj, sale, c.resolution, post.model.prior)


@pytest.mark.parametrize("rules", [None, "table3.lp"])
def test_the_log_prior_of_every_number_of_units_is_prior_log_prior(rules):
    """Mutant class "the one-unit prior" (docs/robustness.md, "Mutants"): on the target the
    pipeline builds, ``Posterior.prior_n(K)[n]`` equals :func:`semmap_pp.target.prior.log_prior` of ``n``
    units without adjacent pairs for every ``n = 0..K``, ``K`` the model's k_max and twice it (a
    world's capacity doubles when a birth finds no empty slot), under the model's Poisson and a
    geometric p_n; and the log prior of a full evaluation and of the tracker (the compiled hot path)
    equals log_prior, SaLe factor included, for worlds of every size ``n = 0..K``."""
    post = _pipeline_target(rules)
    c = post.cells
    shape = post.frame.shape
    one = (10, 10, 40, 50)
    from semmap_pp.target.prior import log_prior

    for prior in (post.model.prior, dataclasses.replace(post.model.prior, n_prior="geometric", n_mean=4.0)):
        post.model = dataclasses.replace(post.model, prior=prior)
        post._prior_n.clear()
        for K in (post.model.prior.k_max, 2 * post.model.prior.k_max):
            table = post.prior_n(K)
            assert table.shape == (K + 1,)
            for n in range(K + 1):
                rects = np.array([one] * n).reshape(-1, 4)
                expected = log_prior(rects, K, shape, c.min_side, c.max_side, np.zeros((n, n), bool),
                                     np.zeros((n, n)), c.resolution, prior)
                assert table[n] == pytest.approx(expected, rel=1e-12, abs=1e-9), (K, n)
    post.model = dataclasses.replace(post.model, prior=MODEL.prior)
    post._prior_n.clear()
    # worlds of every size: units added one at a time, evaluated in full and by the tracker
    rng = np.random.default_rng(55)
    K = post.model.prior.k_max
    n_max = K if rules is None else 6      # the engine on 64 overlapping units: too slow for a test
    world = wm.empty(K)
    tr = post.start(world)
    assert tr.logprior == pytest.approx(_reference_log_prior(post, world, post.typing(world)))
    sale_terms = 0
    for n in range(1, n_max + 1):
        new = wm.add(tr.world, n - 1, random_rect(rng, shape, lo=c.min_side))
        prop = tr.propose(new, [n - 1])
        typ = post.typing(new)
        expected = _reference_log_prior(post, new, typ)
        assert np.isfinite(expected)
        assert post.evaluate(new).logprior == pytest.approx(expected, rel=1e-12, abs=1e-9), n
        assert prop.logprior == pytest.approx(expected, rel=1e-12, abs=1e-9), n
        tr.accept(prop)
        sale_terms += expected < post.prior_n(K)[n] - 1e-6
    assert sale_terms > 0      # the SaLe factor was part of it
