"""``semmap rules check FILE...``, ``semmap rules query FILE --evidence FACTS.lp``, ``semmap rules
evidence MAP WORLD_JSON`` (a world's evidence as such a facts file, to try rule files on it) and
``semmap rules list`` (the rule files and the model file that ship with the package, and where
they are: an installed package keeps them inside itself)."""

from __future__ import annotations

import json
import re
import sys
import textwrap
from pathlib import Path

from semmap_pp.cells import UNIT_TYPES
from semmap_pp.cli.options import add_map_options, map_options
from semmap_pp.errors import EvidenceError, OutputError, SemmapError


def register(subparsers) -> None:
    parser = subparsers.add_parser("rules", help="check rule files and query the knowledge engine")
    sub = parser.add_subparsers(dest="rules_command", metavar="ACTION")
    sub.required = True
    _add_check(sub)
    _add_evidence(sub)
    _add_label(sub)
    _add_label_synth(sub)
    _add_learn(sub)
    _add_list(sub)


def _add_check(sub) -> None:
    """The parser of ``rules check`` and ``rules query``."""
    check = sub.add_parser("check", help="validate rule files (prints ok and how the engine will "
                                         "run them, or the errors)")
    check.add_argument("files", nargs="+", metavar="FILE")
    check.set_defaults(func=_check)
    query = sub.add_parser("query", help="marginals and MAP types for an evidence file")
    query.add_argument("file", metavar="FILE", help="rule file (.lp)")
    query.add_argument("--evidence", required=True, metavar="FACTS.lp",
                       help='evidence facts: unit(1). rolike(1). adj(1,2). soft(muldoor(1), "0.7").')
    query.add_argument("--method", choices=("auto", "exact", "lbp", "mcsat"), default="auto",
                       help="marginals: auto (exact junction tree when small, else loopy BP), "
                            "exact, lbp (loopy belief propagation) or mcsat (default: auto)")
    query.add_argument("--map", dest="map_method", choices=("jt", "clingo", "rc2"), default="jt",
                       help="MAP (types and SaLe, soft evidence summed out) by junction-tree "
                            "max-product, RC2, or clingo optimisation (no soft evidence)")
    query.add_argument("--json", action="store_true", help="print one JSON object")
    query.set_defaults(func=_query)


def _add_evidence(sub) -> None:
    """The parser of ``rules evidence``."""
    evid = sub.add_parser("evidence", help="the evidence of a world.json as a facts file for `rules query`",
                          description="Write the evidence the knowledge engine gets for a world.json "
                                      "(geometry classes, MulDoor, adjacency; its units numbered as "
                                      "the file numbers them) as a facts file that `semmap rules query "
                                      "RULES --evidence FILE` reads: try a rule file on a real map's "
                                      "world without sampling.")
    evid.add_argument("map", metavar="MAP", help="the map the world.json was written for")
    evid.add_argument("world", metavar="WORLD_JSON", type=Path, help="a world.json written for MAP")
    evid.add_argument("--out", type=Path, metavar="FILE", help="write the facts here (default: stdout)")
    evid.add_argument("--model", metavar="FILE", default=None,
                      help="model file (default models/default.toml): the evidence thresholds")
    add_map_options(evid)
    evid.set_defaults(func=_evidence)


def _add_label(sub) -> None:
    """The parser of ``rules label``."""
    label = sub.add_parser("label", help="a world's evidence with true types: a labelled example "
                                         "for `rules learn`",
                           description="Write a labelled example for `semmap rules learn`: the "
                                       "evidence of a world.json (as `semmap rules evidence` writes "
                                       "it) and the true type of each unit, label(U, T). The types "
                                       "come from a per-cell type image (--truth: each unit takes "
                                       "the majority type of its labelled cells, and the cell "
                                       "counts are kept for per-cell scores) or, without --truth, "
                                       "from the world.json's own type fields (correct them first).")
    label.add_argument("map", metavar="MAP", help="the map the world.json was written for")
    label.add_argument("world", metavar="WORLD_JSON", type=Path, help="a world.json written for MAP")
    label.add_argument("--out", type=Path, metavar="FILE.lp", required=True,
                       help="the labelled example to write")
    label.add_argument("--truth", type=Path, metavar="IMAGE", default=None,
                       help="a per-cell type image of the map's size (default: the world.json's "
                            "types); the units' cells are read from labels.png beside the "
                            "world.json")
    label.add_argument("--truth-values", default=None, metavar="GREY=TYPE,...",
                       help="the grey value of each type in --truth, several types joined by | "
                            "(the cell is of one of them; default 77=room|hall|other,115=corridor: "
                            "the ipa place-type images, whose rooms are room-like places)")
    label.add_argument("--model", metavar="FILE", default=None,
                       help="model file (default models/default.toml): the evidence thresholds")
    add_map_options(label)
    label.set_defaults(func=_label)


def _add_label_synth(sub) -> None:
    """The parser of ``rules label-synth``."""
    synth = sub.add_parser("label-synth", help="labelled examples of synthetic floors (their truth)",
                           description="Write one labelled example per synthetic floor "
                                       "(semmap synth's generator): the seen true units as the "
                                       "world, the evidence the engine computes for it, the true "
                                       "types as labels.")
    synth.add_argument("--floors", type=int, default=10, metavar="N", help="number of floors (10)")
    synth.add_argument("--first", type=int, default=0, metavar="SEED", help="first seed (0)")
    synth.add_argument("--out", type=Path, required=True, metavar="DIR",
                       help="folder for synth-SEED.lp")
    synth.add_argument("--model", metavar="FILE", default=None, help="model file")
    synth.set_defaults(func=_label_synth)


def _add_learn(sub) -> None:
    """The parser of ``rules learn``."""
    learn = sub.add_parser("learn", help="learn the soft rules' weights from labelled examples",
                           description="Learn the weights of a rule file's soft rules by maximum "
                                       "likelihood of the labelled types (pseudo-likelihood where a "
                                       "network is too dense), with a Gaussian prior on each weight, "
                                       "and write the file with the learned weights, each with its "
                                       "standard error in a comment (docs/rules.md, 'Learning "
                                       "weights').")
    learn.add_argument("file", metavar="RULES", help="rule file (.lp) whose soft weights to learn")
    learn.add_argument("--data", nargs="+", required=True, metavar="FILE_OR_DIR",
                       help="labelled examples (.lp, as `semmap rules label` writes them), or "
                            "folders of them")
    learn.add_argument("--out", type=Path, metavar="FILE.lp", default=None,
                       help="the learned rule file to write (needed unless --cv)")
    learn.add_argument("--sigma", type=float, default=None, metavar="S",
                       help="standard deviation of the Gaussian prior on each weight, in MLN units "
                            "(default 1.0: semmap_pp.knowledge.learn.SIGMA)")
    learn.add_argument("--prior-mean", choices=("file", "zero"), default="file",
                       help="centre of the prior: the file's weights (default) or 0")
    learn.add_argument("--objective", choices=("auto", "exact", "pseudo"), default="auto",
                       help="exact likelihood, pseudo-likelihood, or auto: exact unless an "
                            "example's junction tree is too large (default auto)")
    learn.add_argument("--cv", action="store_true",
                       help="leave each example out in turn, learn on the rest and score the "
                            "left-out one (per-cell accuracy when it has cell counts)")
    learn.add_argument("--json", action="store_true", help="print one JSON object")
    learn.set_defaults(func=_learn)


def _add_list(sub) -> None:
    """The parser of ``rules list``."""
    listing = sub.add_parser("list", help="the shipped rule files and model file, and where they are",
                             description="List the rule files and the model file that ship with "
                                         "semmap_pp, with their paths and what each is: copy one, edit "
                                         "the copy, and pass it with --rules FILE or --model FILE.")
    listing.set_defaults(func=_list)


def _check(args) -> int:
    from semmap_pp.knowledge import load_rules
    from semmap_pp.knowledge.local import pairwise_obstacle

    failed = 0
    for f in args.files:
        try:
            rs = load_rules(f)
        except SemmapError as exc:
            print(f"{exc}", file=sys.stderr)
            failed += 1
            continue
        print(f"{f}: ok ({rs.n_hard} hard, {rs.n_soft} soft rules"
              + (f", helpers {', '.join(rs.helpers)}" if rs.helpers else "") + ")")
        obstacle = pairwise_obstacle(rs)
        print("  inference: " + ("unit and pair templates (the rules are pairwise-local)"
                                 if obstacle is None else
                                 "the general path, every evidence grounded whole (several times "
                                 "slower than unit and pair templates; docs/rules.md): "
                                 + obstacle))
        if obstacle is not None:    # templates ground one unit or one pair at a time
            print("  grounding: " + _grounding_line(rs))
    return 1 if failed else 0


def _grounding_line(rs) -> str:
    """How large the file's grounding can get (:mod:`semmap_pp.knowledge.size`)."""
    from semmap_pp.knowledge.size import FLOOR_UNITS, MAX_GROUND_STATEMENTS, NEIGHBOURS, Sizes

    floor = Sizes.floor(FLOOR_UNITS)
    text = (f"up to {rs.bound.total(floor):,.0f} ground statements for a floor of {FLOOR_UNITS} "
            f"units with up to {NEIGHBOURS} neighbours each; ")
    at = rs.bound.limit_units()
    if at is None:
        return text + f"within the limit of {MAX_GROUND_STATEMENTS:,} up to 100,000 units"
    st = rs.bound.largest(Sizes.floor(at))
    try:
        where = Path(st.path).relative_to(Path.cwd())
    except ValueError:
        where = st.path
    return text + (f"the limit of {MAX_GROUND_STATEMENTS:,} is reached at {at:,} units (worlds "
                   f"that large stop with an error), most of it from {where}:{st.line}:{st.col}")


def shipped_listing() -> list[str]:
    """The lines of ``semmap rules list``: each shipped rule file and evidence example with the
    first sentence of its leading comment, then the model file."""
    from semmap_pp.resources import DEFAULT_MODEL, DEFAULT_RULES, evidence_files, rule_files, shipped

    root = shipped("rules")
    rules, examples = rule_files(), evidence_files()
    width = max((len(f.relative_to(root).as_posix()) for f in rules + examples), default=0)

    def row(f: Path) -> str:
        mark = " (the default of --rules)" if f == DEFAULT_RULES else ""
        lines = textwrap.wrap(leading_sentence(f) + mark, max(40, 96 - width)) or [""]
        pad = " " * (width + 4)
        return f"  {f.relative_to(root).as_posix():<{width}}  " + f"\n{pad}".join(lines)

    return ([f"rule files in {root}:"] + [row(f) for f in rules]
            + ["evidence examples (semmap rules query FILE --evidence EXAMPLE):"]
            + [row(f) for f in examples]
            + [f"model file: {DEFAULT_MODEL} (the default of --model)",
               "copy one, edit the copy, pass it with --rules FILE or --model FILE"])


def leading_sentence(path: Path, limit: int = 400) -> str:
    """The first sentence of the comment lines that open a rule file (at most ``limit``
    characters), or "" when it opens with none.

    >>> import tempfile
    >>> f = Path(tempfile.mkdtemp()) / "r.lp"
    >>> _ = f.write_text("% Rooms are small (Fig. 5b). Halls are big.\\n% more\\nroom(1).\\n")
    >>> leading_sentence(f)
    'Rooms are small (Fig. 5b).'
    """
    words = []
    for line in path.read_text(encoding="utf-8").splitlines():
        if not line.startswith("%"):
            break
        words.extend(line.lstrip("%").split())
    text = " ".join(words)
    end = re.search(r"\.\s+(?=[A-Z])", text)     # a full stop before a capital: "Fig. 5b" goes on
    text = text if end is None else text[:end.start() + 1]
    return text if len(text) <= limit else text[:limit - 3].rstrip() + "..."


def _list(args) -> int:
    print("\n".join(shipped_listing()))
    return 0


def _query(args) -> int:
    from semmap_pp.knowledge import KnowledgeEngine, evidence_from_facts

    try:
        text = Path(args.evidence).read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise EvidenceError(args.evidence, f"cannot read evidence: {exc}") from None
    ev = evidence_from_facts(text, args.evidence)
    engine = KnowledgeEngine.from_file(args.file, method=args.method, map_method=args.map_method)
    r = engine.infer(ev)
    if args.json:
        out = {"rules": args.file, "evidence": args.evidence, "method": r.method,
               "map_method": r.map_method,
               "types": {str(u): dict(zip(UNIT_TYPES, map(float, p))) for u, p in r.types.items()},
               "sale": {f"{p},{q}": v for (p, q), v in r.sale.items()},
               "map_types": {str(u): t for u, t in r.map_types.items()},
               "map_cost": r.map_cost, "log_z": r.log_z}
        print(json.dumps(out))
        return 0
    print(f"rules {args.file}, evidence {args.evidence}, method {r.method} (MAP by "
          f"{r.map_method})")
    print("unit  " + "  ".join(f"{t:>8}" for t in UNIT_TYPES) + "  MAP")
    for u, p in r.types.items():
        print(f"{u:<4}  " + "  ".join(f"{v:8.4f}" for v in p) + f"  {r.map_types[u]}")
    for (p, q), v in r.sale.items():
        print(f"P(SaLe({p},{q})) = {v:.4f}")
    extra = f", log Z = {r.log_z:.4f}" if r.log_z is not None else ""
    print(f"MAP cost = {r.map_cost:.3f}{extra}")
    return 0


def world_evidence_facts(inputs, world_path) -> str:
    """The evidence of the world.json at ``world_path`` on ``inputs``' lattice as a facts file
    (:func:`semmap_pp.knowledge.evidence.evidence_to_facts`) with a comment per unit. Units keep
    their world.json ids; exterior unit ``Xk`` becomes ``n + k`` (``n``: the largest unit id),
    as clingo ids are integers."""
    from semmap_pp.knowledge import Evidence
    from semmap_pp.knowledge.dialect import SOFT_PREDICATES
    from semmap_pp.knowledge.evidence import evidence_to_facts
    from semmap_pp.target.posterior import Posterior
    from semmap_pp.plans.world_file import pack_world, read_world_units

    units = read_world_units(world_path, inputs.frame, inputs.grid)
    world = pack_world([r for _, r in units], inputs.model.prior.k_max, world_path)
    ev = Posterior(inputs.frame, inputs.model, None).knowledge_evidence(world)
    top = max((int(k) for k, _ in units if not k.startswith("X")), default=0)
    label = {slot: int(k) if not k.startswith("X") else top + int(k[1:]) for slot, (k, _) in enumerate(units)}
    relabel = {name: {label[u]: p for u, p in ev.unary(name)} for name in SOFT_PREDICATES}
    out = Evidence.build([label[u] for u in ev.units], adj=[(label[p], label[q]) for p, q in ev.adj], **relabel)
    listed = json.loads(Path(world_path).read_text(encoding="utf-8"))   # read_world_units checked it
    types = {str(u.get("id")): u.get("type") for u in listed.get("units", []) if isinstance(u, dict)}
    res = inputs.frame.resolution
    head = [f"% the evidence of {world_path} on {inputs.grid.source} (model {inputs.model.path.name}),",
            "% as the knowledge engine gets it: Table 4 geometry classes (soft near a threshold), MulDoor,",
            "% adjacency. Try a rule file on it: semmap rules query RULES --evidence THIS_FILE"]
    for slot, (k, (r0, c0, r1, c1)) in enumerate(units):
        name = f"exterior unit X{k[1:]}" if k.startswith("X") else f"unit {k} ({types.get(k) or 'no type'})"
        long, short = sorted(((r1 - r0) * res, (c1 - c0) * res), reverse=True)
        head.append(f"% {label[slot]}: {name} of the file, {long:.2f} x {short:.2f} m")
    return "\n".join(head) + "\n" + evidence_to_facts(out)


def _evidence(args) -> int:
    from semmap_pp import atomic
    from semmap_pp.run.inputs import load_inputs

    if args.out is not None:
        _check_out_file(args.out, "facts file")
    inputs = load_inputs(args.map, model_path=args.model, rules_path=None, map_options=map_options(args))
    text = world_evidence_facts(inputs, args.world)
    if args.out is None:
        sys.stdout.write(text)
        return 0
    atomic.write_text(args.out, text)
    print(args.out)
    return 0


def _label(args) -> int:
    from semmap_pp import atomic
    from semmap_pp.studies.labelled import parse_values
    from semmap_pp.run.inputs import load_inputs

    _check_out_file(args.out)
    inputs = load_inputs(args.map, model_path=args.model, rules_path=None, map_options=map_options(args))
    values = parse_values(args.truth_values) if args.truth_values else None
    text = labelled_example_text(inputs, args.world, args.truth, values)
    atomic.write_text(args.out, text)
    print(args.out)
    return 0


def labelled_example_text(inputs, world_path, truth=None, values=None) -> str:
    """A labelled example (:mod:`semmap_pp.studies.labelled`) of the world.json at
    ``world_path`` on ``inputs``' map: its evidence (:func:`world_evidence_facts`) and labels,
    from the per-cell type image ``truth`` (grey values ``values``, default the ipa ones; the
    units' cells from labels.png beside the world.json) or else from the world.json's types."""
    import numpy as np
    from PIL import Image

    from semmap_pp.errors import MapError
    from semmap_pp.studies.labelled import (IPA_VALUES, cell_counts, label_facts,
                                              majority_labels, read_truth_image, world_labels)

    world_path = Path(world_path)
    text = world_evidence_facts(inputs, world_path)
    if truth is None:
        labels = world_labels(world_path)
        if not labels:
            raise EvidenceError(world_path, "no unit has a type; give --truth IMAGE")
        return text + label_facts(labels, comment=f"the types of {world_path}")
    values = values or IPA_VALUES
    labels_png = world_path.parent / "labels.png"
    try:
        unit_image = np.asarray(Image.open(labels_png))
    except (OSError, ValueError) as exc:
        raise MapError(labels_png, f"cannot read the units' cells (labels.png beside the "
                                   f"world.json): {exc}") from None
    grid_truth = read_truth_image(truth, values, unit_image.shape)
    counts, uncovered = cell_counts(unit_image, grid_truth, sorted(_unit_ids(world_path)))
    return text + label_facts(majority_labels(counts, values), counts, uncovered,
                              comment=f"the majority type of each unit's cells in {truth}")


def _unit_ids(world_path) -> set:
    doc = json.loads(Path(world_path).read_text(encoding="utf-8"))
    return {u["id"] for u in doc.get("units", []) if isinstance(u, dict) and isinstance(u.get("id"), int)}


def _check_out_file(out, what: str = "file") -> None:
    if out.is_dir() or str(out).endswith(("/", "\\")):
        raise OutputError(out, f"is a directory; --out names the {what} to write")


def _label_synth(args) -> int:
    from semmap_pp import atomic
    from semmap_pp.studies.labelled import synthetic_example
    from semmap_pp.model import load_model

    if args.floors < 1 or args.first < 0:
        raise SemmapError(None, "--floors must be at least 1 and --first at least 0")
    if args.out.exists() and not args.out.is_dir():
        raise OutputError(args.out, "is not a directory; --out names the folder to write into")
    model = load_model(args.model)
    for seed in range(args.first, args.first + args.floors):
        path = args.out / f"synth-{seed}.lp"
        atomic.write_text(path, synthetic_example(seed, model))
        print(path)
    return 0


def _learn(args) -> int:
    from semmap_pp import atomic
    from semmap_pp.knowledge import learn as lm

    if args.out is None and not args.cv:
        raise SemmapError(None, "semmap rules learn needs --out FILE.lp (or --cv)")
    if args.out is not None:
        _check_out_file(args.out)
    sigma = lm.SIGMA if args.sigma is None else args.sigma
    sr = lm.soft_rules(args.file)
    files = lm.data_files(args.data)
    examples = [lm.read_example(f) for f in files]
    settings = dict(sigma=sigma, prior_mean=args.prior_mean, objective=args.objective)
    out: dict = {"rules": args.file, "data": [str(f) for f in files], "sigma": sigma}
    if args.cv:
        out["cv"] = lm.cross_validate(sr, examples, **settings)
    if args.out is not None:
        result = lm.learn(sr, examples, **settings)
        desc = ", ".join(str(d) for d in args.data)
        atomic.write_text(args.out, lm.learned_text(result, desc))
        out["weights"] = [
            {"name": p.name, "file": int(p.value), "learned": int(round(v * 1000)),
             "se": None if se != se else round(float(se), 4), "ground_tuples": int(g),
             "learned_here": p.learnable, "at_bound": b}
            for p, v, se, g, b in zip(sr.params, result.values, result.se, result.groundings,
                                       result.at_bound)]
        out["log_likelihood"] = {"file": result.start_log_likelihood, "learned": result.log_likelihood}
        out["methods"] = sorted(set(result.methods.values()))
        out["out"] = str(args.out)
    if args.json:
        print(json.dumps(out))
        return 0
    if "weights" in out:
        print(f"{len(examples)} examples, {sum(len(e.labels) for e in examples)} labelled units, "
              f"{'/'.join(out['methods'])} likelihood, prior sigma {sigma:g} around the "
              f"{'file' if args.prior_mean == 'file' else 'zero'} weights")
        width = max(len(w["name"]) for w in out["weights"])
        print(f"{'weight':<{width}}  {'file':>6}  {'learned':>7}  {'s.e.':>6}  ground tuples")
        for w in out["weights"]:
            se = "-" if w["se"] is None else f"{w['se'] * 1000:6.0f}"
            note = "" if w["learned_here"] else "  (in an included file: kept)"
            note += "  (at the bound)" if w["at_bound"] else ""
            print(f"{w['name']:<{width}}  {w['file']:>6}  {w['learned']:>7}  {se:>6}  "
                  f"{w['ground_tuples']}{note}")
        ll = out["log_likelihood"]
        print(f"log likelihood {ll['file']:.3f} -> {ll['learned']:.3f}; wrote {args.out}")
    if "cv" in out:
        print("leave one out: each example typed by the weights learned without it")
        for row in out["cv"]["rows"]:
            kind = "cells" if "cell_accuracy_file" in row else "units"
            a, b = (row["cell_accuracy_file"], row["cell_accuracy_learned"]) if kind == "cells" \
                else (row["unit_accuracy_file"], row["unit_accuracy_learned"])
            print(f"  {row['example']}: {kind} accuracy {a:.4f} with the file's weights, "
                  f"{b:.4f} learned without it")
    return 0
