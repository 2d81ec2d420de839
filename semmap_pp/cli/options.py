"""Options more than one subcommand takes, each added by one function and read by another.

- the map options (:func:`add_map_options`, read by :func:`map_options` into
  :func:`~semmap_pp.grid.load_map` keywords): thresholds, resolution, mode, cell limit, a bag's
  topic and time;
- the target options (:func:`add_target_options`, read by :func:`target_inputs`): rule file,
  model file, region of interest;
- the run lengths (:func:`add_run_length_options`): chains, cores, burn-in, draws, kernels per draw.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from semmap_pp.cli.argtypes import bag_time as _bag_time
from semmap_pp.cli.argtypes import n_inner as n_inner_type
from semmap_pp.cli.argtypes import non_negative_int as _non_negative_int
from semmap_pp.cli.argtypes import positive_int as _positive_int
from semmap_pp.grid import MAX_CELLS
from semmap_pp.grid.pixels import MODES


def add_map_options(parser: argparse.ArgumentParser) -> None:
    """Add the options that override or complete a map's map_server parameters."""
    group = parser.add_argument_group("map parameters (override the YAML, complete a bare image)")
    group.add_argument("--occupied-thresh", type=float, metavar="P",
                       help="occupancy above P is occupied (map_server default 0.65)")
    group.add_argument("--free-thresh", type=float, metavar="P",
                       help="occupancy below P is free (map_server default 0.196)")
    group.add_argument("--negate", type=int, choices=(0, 1),
                       help="1: dark pixels are free, light ones occupied")
    group.add_argument("--resolution", type=float, metavar="M",
                       help="metres per cell (bare images default to 0.05, with a note)")
    group.add_argument("--mode", choices=MODES, help="map_server mode (default trinary)")
    group.add_argument("--max-cells", type=_positive_int, default=MAX_CELLS, metavar="N",
                       help=f"refuse larger images (default {MAX_CELLS})")
    group.add_argument("--allow-outside", action="store_true",
                       help="let the YAML's image: be outside the YAML's folder (absolute or ../ path)")
    bag = parser.add_argument_group("a bag's map (ROS 1 .bag, ROS 2 bag folder, .mcap; other maps ignore these)")
    bag.add_argument("--topic", metavar="TOPIC", default=None,
                     help="the nav_msgs/OccupancyGrid topic (default: the bag's one such topic)")
    bag.add_argument("--at", type=_bag_time, metavar="TIME|last", default=None,
                     help="the last map message at or before TIME seconds after the bag's start "
                          "(default: last, the bag's last map message)")


def map_options(args: argparse.Namespace) -> dict:
    """:func:`load_map` keyword arguments from the options of :func:`add_map_options`."""
    return {"occupied_thresh": args.occupied_thresh, "free_thresh": args.free_thresh,
            "negate": args.negate, "resolution": args.resolution, "mode": args.mode,
            "max_cells": args.max_cells, "allow_outside": args.allow_outside,
            "topic": getattr(args, "topic", None), "at": getattr(args, "at", None)}


def add_target_options(p: argparse.ArgumentParser) -> None:
    """``--rules``, ``--model``, ``--roi``: what the target of a run on a map is made of (``map``,
    ``score``, ``edit``, ``stability``; read by :func:`target_inputs`)."""
    p.add_argument("--rules", metavar="FILE", default=None,
                   help="rule file (default rules/table3.lp; rules/none.lp = no knowledge; "
                        "`semmap rules list` shows where the shipped ones are)")
    p.add_argument("--model", metavar="FILE", default=None, help="model file (default models/default.toml)")
    p.add_argument("--roi", metavar="MASK", default=None,
                   help="region-of-interest mask image for the CPR (default: the known part, closed)")


def add_run_length_options(p: argparse.ArgumentParser, draws_help: str = "recorded draws per chain") -> None:
    """``--chains``, ``--cores``, ``--tune``, ``--draws``, ``--n-inner`` (None: the model file's
    ``[sampler]`` values), as ``semmap map``, ``compare`` and ``stability`` take them."""
    p.add_argument("--chains", type=_positive_int, default=None, help="chains (model file default)")
    p.add_argument("--cores", type=_positive_int, default=None, help="processes (model file default)")
    p.add_argument("--tune", type=_non_negative_int, default=None, help="burn-in draws per chain")
    p.add_argument("--draws", type=_positive_int, default=None, help=draws_help)
    p.add_argument("--n-inner", type=n_inner_type, default=None, help="kernels per draw")


def target_inputs(args: argparse.Namespace):
    """The rule file and the loaded inputs (map, model, rules, ROI) that ``args`` name: MAP, the
    options of :func:`add_target_options` and the map options."""
    from semmap_pp.resources import DEFAULT_RULES
    from semmap_pp.run.inputs import load_inputs

    rules = Path(args.rules) if args.rules else DEFAULT_RULES
    return rules, load_inputs(args.map, model_path=args.model, rules_path=rules, roi_path=args.roi,
                              map_options=map_options(args))


__all__ = ["add_map_options", "map_options", "add_target_options", "add_run_length_options",
           "target_inputs"]
