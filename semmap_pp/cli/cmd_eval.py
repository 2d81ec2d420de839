"""``semmap eval DIR --truth T [--json]``: score a run's world.json and labels.png against a truth.

``semmap eval DIR --segmentation GT.png [--format rose2|ipa] [--of FILE]`` scores the run's
rooms.png (``--of``: another of its label images, or any segmentation image) by the published room
segmentation protocol: ``rose2`` (default) reads GT.png as one colour per room (ROSE2's
``gt.png``; rooms of more than 200 cells, every predicted segment counts), ``ipa`` as white rooms
(Bormann et al.'s ``*_gt_segmentation.png``; rooms and segments of more than 100 cells). Segments
are taken whole (a segment's cells outside every room lower its precision). A colour image given
to ``--of`` (ROSE2's ``rose2.png``) is read as one segment per colour.

``T`` is recognised by name, then by content:

* a synthetic floor (``semmap synth``): its folder, or its ``truth.json`` — units matched by polygon
  IoU (unit precision / recall / F1), type accuracy over matched units, adjacency and door
  precision / recall (:func:`semmap_pp.evaluate.score_world`), the same with each L-shaped space
  cut whichever way the prediction cut it (``*_either_l``, when the truth has L-shapes;
  :func:`semmap_pp.evaluate.score_world_either_l`), the CPR of W* from world.json, and,
  when ``truth_labels.png`` sits beside it, room segmentation of labels.png against it;
* an ipa ground-truth segmentation (``*_gt_segmentation.png``, white rooms): precision / recall
  ("micro" and "macro") and mean IoU of ``labels.png``, and of ``regions.png`` when the run wrote
  one (:func:`semmap_pp.evaluate.segmentation_scores`);
* an ipa place-type image (``training_*.png``, grey 77 room / 115 corridor / 179 doorway): per-cell
  room / corridor accuracy of the unit types painted over labels.png
  (:func:`semmap_pp.evaluate.type_accuracy`).

Any other PNG is read as place types when it holds nothing but the ipa type grey levels (0, 77,
115, 179, 255), else as a segmentation when it has white (room) cells. Prints a table, or one JSON object with ``--json``. docs/evaluation.md
defines every score.

Against a synthetic truth, ``--figure PNG`` also writes the reliability diagram of the run's
posterior marginals (:func:`semmap_pp.outputs.figures.reliability_png`) and ``--report`` adds it,
with the reliability table, to DIR/report.html as its calibration section
(:func:`semmap_pp.outputs.report.with_calibration`); both written atomically, before anything is
printed, and their paths printed after the table.
"""

from __future__ import annotations

import contextlib
import json
import math
from pathlib import Path

import numpy as np

from semmap_pp.errors import MapError, OutputError

KINDS = ("synthetic", "ipa-segmentation", "ipa-types")
SEGMENTATION_FORMATS = ("rose2", "ipa")      # semmap_pp.evaluate.io.SEGMENTATION_FORMATS


def register(subparsers) -> None:
    p = subparsers.add_parser("eval", help="score a run against ground truth (synthetic or ipa)",
                              description=__doc__.splitlines()[0])
    p.add_argument("dir", metavar="DIR", type=Path, help="output folder of `semmap map`")
    which = p.add_mutually_exclusive_group(required=True)
    which.add_argument("--truth", type=Path, metavar="T",
                       help="synthetic floor folder or truth.json, ipa *_gt_segmentation.png or training_*.png")
    which.add_argument("--segmentation", type=Path, metavar="GT",
                       help="a room ground truth (colour per room, or ipa white rooms: --format); scores "
                            "rooms.png by the published protocol")
    p.add_argument("--format", choices=SEGMENTATION_FORMATS, default="rose2",
                   help="with --segmentation: how GT is drawn (rose2: a colour per room; ipa: white rooms)")
    p.add_argument("--of", type=Path, metavar="FILE", default=None,
                   help="with --segmentation: the segmentation to score (default DIR/rooms.png; a name is "
                        "looked for in DIR first)")
    p.add_argument("--kind", choices=KINDS, default=None, help="say what T is instead of detecting it")
    p.add_argument("--published", action="store_true",
                   help="segmentation: the published ipa protocol (segments taken whole, not cut to the rooms)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument("--figure", type=Path, metavar="PNG", default=None,
                   help="with a synthetic truth: also write the reliability diagram of the run's posterior "
                        "marginals to this PNG file")
    p.add_argument("--report", action="store_true",
                   help="with a synthetic truth: add the calibration section (the reliability diagram and "
                        "table) to DIR/report.html, rewritten atomically (replacing an earlier one)")
    p.set_defaults(func=run)


def detect_kind(truth: Path) -> str:
    """Which kind of truth ``truth`` is (see the module docstring)."""
    from semmap_pp.evaluate.io import IPA_TYPE_PIXELS, IPA_WHITE_ABOVE, read_image

    IPA_TYPE_LEVELS = set(IPA_TYPE_PIXELS) | {255}

    if truth.is_dir():
        if (truth / "truth.json").is_file():
            return "synthetic"
        raise MapError(truth, "folder holds no truth.json (expected a `semmap synth` folder)")
    if not truth.exists():
        raise MapError(truth, "truth file does not exist")
    name = truth.name.lower()
    if name.endswith(".json"):
        return "synthetic"
    if name.endswith("_gt_segmentation.png"):
        return "ipa-segmentation"
    if name.startswith("training_"):
        return "ipa-types"
    image = np.asarray(read_image(truth))
    grey = image if image.ndim == 2 else image[..., :3].mean(axis=-1)
    values = set(np.unique(grey).tolist())
    if values <= IPA_TYPE_LEVELS and values & {77, 115}:
        return "ipa-types"           # nothing but the place-type grey levels
    if (grey > IPA_WHITE_ABOVE).any():
        return "ipa-segmentation"    # white rooms (anti-aliased edges give other greys)
    raise MapError(truth, "cannot tell what this truth is (expected truth.json, *_gt_segmentation.png "
                          "or training_*.png; use --kind)")


def _read_run(run_dir: Path) -> tuple[dict, np.ndarray]:
    from semmap_pp.evaluate import read_label_image
    from semmap_pp.plans.world_file import read_world_doc

    if not run_dir.is_dir():
        raise MapError(run_dir, "not a run folder (expected the --out folder of `semmap map`)")
    world, labels = run_dir / "world.json", run_dir / "labels.png"
    for f in (world, labels):
        if not f.is_file():
            raise MapError(f, "missing (expected the output of `semmap map`)")
    return read_world_doc(world), read_label_image(labels)     # bounded as every world.json read is


def _same_shape(pred: np.ndarray, truth: np.ndarray, pred_path: Path, truth_path: Path) -> None:
    if pred.shape != truth.shape:
        raise MapError(truth_path, f"truth is {truth.shape[1]}x{truth.shape[0]} cells but {pred_path.name} is "
                                   f"{pred.shape[1]}x{pred.shape[0]}: not the same map")


def _seg(prefix: str, s) -> dict:
    return {f"{prefix}precision": s.precision, f"{prefix}recall": s.recall,
            f"{prefix}precision_macro": s.precision_macro, f"{prefix}recall_macro": s.recall_macro,
            f"{prefix}iou": s.iou, f"{prefix}iou_best": s.iou_best, f"{prefix}rooms": s.n_rooms,
            f"{prefix}segments": s.n_segments}


def evaluate_run(run_dir: Path, truth: Path, kind: str | None = None, *, published: bool = False) -> dict:
    """Scores of the run in ``run_dir`` against ``truth``: ``{"kind", "scores": {name: value}}``."""
    from semmap_pp.evaluate import (read_ipa_gt, read_ipa_types, read_json, read_label_image, score_world,
                                    score_world_either_l, segmentation_scores, type_accuracy,
                                    type_map_from_labels)

    kind = kind or detect_kind(truth)
    world, labels = _read_run(run_dir)
    calibration = {}
    scores: dict = {"units_predicted": len(world.get("units", [])),
                    "units_exterior": len(world.get("exterior", [])), "cpr": world.get("cpr")}
    if kind == "synthetic":
        truth_json = truth / "truth.json" if truth.is_dir() else truth
        t = read_json(truth_json)
        names = dict(pred_source=str(run_dir / "world.json"), truth_source=str(truth_json))
        if t.get("l_shapes"):
            e, s, recut = score_world_either_l(world, t, **names)     # s: the strict score
        else:
            s = score_world(world, t, **names)
        scores.update({"units_true": s.n_true_units, "unit_precision": s.unit_precision,
                       "unit_recall": s.unit_recall, "unit_f1": s.unit_f1, "type_accuracy": s.type_accuracy,
                       "adjacency_precision": s.adjacency_precision, "adjacency_recall": s.adjacency_recall,
                       "door_precision": s.door_precision, "door_recall": s.door_recall})
        if t.get("l_shapes"):
            scores.update({"l_shapes": len(t["l_shapes"]), "l_shapes_recut": len(recut),
                           "unit_f1_either_l": e.unit_f1, "type_accuracy_either_l": e.type_accuracy,
                           "door_precision_either_l": e.door_precision,
                           "door_recall_either_l": e.door_recall})
        calibration = _calibration(world, t, s)
        if calibration:
            scores.update({f"ece_{k}": v["ece"] for k, v in calibration.items()})
        truth_labels = truth_json.parent / "truth_labels.png"
        if truth_labels.is_file():
            gt = read_label_image(truth_labels)
            _same_shape(labels, gt, run_dir / "labels.png", truth_labels)
            scores.update(_seg("segmentation_", segmentation_scores(gt, labels, restrict_to_gt=not published)))
    elif kind == "ipa-segmentation":
        gt = read_ipa_gt(truth)
        _same_shape(labels, gt, run_dir / "labels.png", truth)
        scores.update(_seg("", segmentation_scores(gt, labels, restrict_to_gt=not published)))
        regions = run_dir / "regions.png"
        if regions.is_file():
            scores.update(_seg("regions_", segmentation_scores(gt, read_label_image(regions),
                                                               restrict_to_gt=not published)))
    elif kind == "ipa-types":
        t = read_ipa_types(truth)
        _same_shape(labels, t, run_dir / "labels.png", truth)
        types = {int(u["id"]): u["type"] for u in world.get("units", [])}
        s = type_accuracy(type_map_from_labels(labels, types), t)
        scores.update({"type_accuracy": s.accuracy, "recall_room": s.recall_room,
                       "recall_corridor": s.recall_corridor, "balanced_accuracy": s.balanced_accuracy,
                       "coverage": s.coverage, "accuracy_covered": s.accuracy_covered, "cells": s.n_cells})
    else:  # pragma: no cover - argparse restricts --kind
        raise MapError(truth, f"unknown truth kind {kind!r}")
    return {"run": str(run_dir), "truth": str(truth), "kind": kind, "protocol":
            "published" if published else "restricted to ground-truth rooms", "scores": scores,
            **({"calibration": calibration} if calibration else {})}


def _calibration(world: dict, truth: dict, score) -> dict:
    """The reliability of the run's posterior marginals against the synthetic truth
    (:func:`semmap_pp.evaluate.calibration.calibration_summary`); ``{}`` when world.json has none
    (a run that drew no worlds)."""
    from semmap_pp.evaluate.calibration import calibration_summary, posterior_claims
    if "posterior_marginals" not in world:
        return {}
    return calibration_summary([posterior_claims(world, truth, score)])


def _clean(v):
    if isinstance(v, (float, np.floating)):
        v = float(v)
        return v if math.isfinite(v) else None
    if isinstance(v, np.integer):
        return int(v)
    return v


def format_text(result: dict) -> str:
    lines = [f"run {result['run']} against {result['kind']} truth {result['truth']}", f"{'score':<28}{'value':>10}"]
    for k, v in result["scores"].items():
        if v is None or (isinstance(v, float) and not math.isfinite(v)):
            text = "n/a"
        elif isinstance(v, (int, np.integer)):
            text = str(v)
        else:
            text = f"{v:.4f}"
        lines.append(f"{k:<28}{text:>10}")
    for kind, c in result.get("calibration", {}).items():
        lines.append(f"reliability of the posterior marginals, {kind}: {c['claims']} claims"
                     + (f", ECE {c['ece']:.4f}" if c["ece"] is not None else ""))
        lines += [f"  p in [{lo:.1f}, {hi:.1f}{']' if hi == 1.0 else ')'}: {n:5d} claims, mean p {conf:.3f}, "
                  f"right {acc:.3f}" for lo, hi, n, conf, acc in c["bins"]]
    return "\n".join(lines)


def segmentation_of(run_dir: Path, of: Path | None) -> Path:
    """The segmentation file ``--of`` names: DIR/rooms.png by default; a bare name in DIR first."""
    if of is None:
        path = run_dir / "rooms.png"
    elif not of.is_absolute() and (run_dir / of).is_file():
        path = run_dir / of
    else:
        path = of
    if not path.exists():      # a FIFO or device: read_image refuses it without opening it
        raise MapError(path, "missing (expected a segmentation image"
                             + (", the rooms.png of `semmap map`)" if of is None else ")"))
    return path


def evaluate_segmentation(run_dir: Path, truth: Path, fmt: str = "rose2", of: Path | None = None) -> dict:
    """Published-protocol precision / recall of a run's rooms.png (or ``of``) against ``truth``."""
    from semmap_pp.evaluate import protocol_scores, read_segmentation, read_segmentation_truth

    if of is None and not run_dir.is_dir():
        raise MapError(run_dir, "not a run folder (expected the --out folder of `semmap map`)")
    pred_path = segmentation_of(run_dir, of)
    gt = read_segmentation_truth(truth, fmt)
    pred = read_segmentation(pred_path)
    _same_shape(pred, gt, pred_path, truth)
    s = protocol_scores(gt, pred, fmt)
    return {"run": str(run_dir), "truth": str(truth), "kind": f"{fmt} segmentation",
            "segmentation": str(pred_path), "protocol": "published", "scores": _seg("", s)}


def _check_figure(path: Path) -> None:
    """Refuse a ``--figure`` path that names a folder or lies under a file, in one line."""
    if path.is_dir() or str(path).endswith(("/", "\\")):
        raise OutputError(path, "is a directory; --figure names the PNG file to write")
    above = path.absolute().parent
    while not above.exists() and above.parent != above:
        above = above.parent
    if not above.is_dir():
        raise OutputError(path, f"cannot be written: {above} is a file, not a folder")


def _calibration_of(result: dict, where: Path) -> dict:
    """The run's reliability tables, or the one-line error saying why there are none."""
    if result["kind"] != "synthetic":
        raise OutputError(where, f"the reliability diagram needs a synthetic truth (a `semmap synth` folder); "
                                 f"{result['truth']} is {result['kind']}")
    if not result.get("calibration"):
        raise OutputError(where, f"{result['run']}/world.json holds no posterior marginals (a run that drew "
                                 "no worlds): no reliability diagram")
    return result["calibration"]


def report_with(run_dir: Path, section: str) -> tuple[Path, str]:
    """DIR/report.html and its text with ``section`` as its calibration section
    (:func:`semmap_pp.outputs.report.with_calibration`), or the one-line error why not."""
    from semmap_pp.outputs.report import with_calibration

    path = run_dir / "report.html"
    if not path.is_file():
        raise OutputError(path, "missing (`semmap map` writes it last; `semmap edit` writes none)")
    try:
        page = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise OutputError(path, f"cannot read it: {getattr(exc, 'strerror', None) or exc}") from None
    try:
        return path, with_calibration(page, section)
    except ValueError as exc:
        raise OutputError(path, str(exc)) from None


def write_calibration(result: dict, figure: Path | None, report: bool) -> list[Path]:
    """``--figure`` and ``--report``: the reliability diagram of ``result`` (:func:`evaluate_run`'s)
    written to ``figure`` and into the run's report.html (under the run folder's lock: a
    `semmap map` writing into it is refused, as a second run is); the paths written. The report
    is read and checked before anything is written."""
    from semmap_pp import atomic
    from semmap_pp.outputs.figures import reliability_png
    from semmap_pp.outputs.report import calibration_section
    from semmap_pp.run.outdir import lock_out_dir

    run_dir = Path(result["run"])
    calibration = _calibration_of(result, figure if figure is not None else run_dir / "report.html")
    if figure is not None:
        _check_figure(figure)
    png = reliability_png(calibration, f"Reliability of the posterior marginals of {result['run']} "
                                       f"against {result['truth']}")
    written = []
    with contextlib.ExitStack() as held:
        if report:
            held.enter_context(lock_out_dir(run_dir))
            path, page = report_with(run_dir, calibration_section(calibration, png, run=result["run"],
                                                                  truth=result["truth"]))
        if figure is not None:
            atomic.write_bytes(figure, png)
            written.append(figure)
        if report:
            atomic.write_text(path, page)
            written.append(path)
    return written


def run(args) -> int:
    if args.segmentation is not None:
        if args.figure is not None or args.report:
            raise OutputError(args.figure or args.dir / "report.html", "--figure and --report go with --truth")
        result = evaluate_segmentation(args.dir, args.segmentation, args.format, args.of)
    else:
        if args.of is not None:
            raise MapError(args.of, "--of goes with --segmentation")
        if args.figure is not None:
            _check_figure(args.figure)         # before the scoring: a wrong path costs nothing
        result = evaluate_run(args.dir, args.truth, args.kind, published=args.published)
    # written first: a figure or report that cannot be written prints nothing
    written = write_calibration(result, args.figure, args.report) if args.figure is not None or args.report else []
    if args.json:
        result = dict(result, scores={k: _clean(v) for k, v in result["scores"].items()})
        print(json.dumps(result))
    else:
        print(format_text(result))
        for path in written:
            print(path)
    return 0
