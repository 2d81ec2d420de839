"""Every output file of ``semmap map``, written from one :class:`~semmap_pp.run.results.MapRun`.

Each file is written atomically (:mod:`semmap_pp.atomic`): a reader, or a crash, sees the previous
complete file or the new one. world.json, labels.png, trace.nc and diagnostics.txt come first, so
they exist even if a figure fails; report.html comes last and embeds the figures' PNG bytes.
docs/outputs.md describes every file.
"""

from __future__ import annotations

import glob
import os
import shutil
from pathlib import Path
from typing import NamedTuple

import numpy as np
from scipy import ndimage

from semmap_pp import atomic
from semmap_pp.errors import printable
from semmap_pp.outputs import figures as fig
from semmap_pp.outputs.geojson import geojson_dict, write_geojson
from semmap_pp.outputs.graphml import world_graph, write_graphml
from semmap_pp.outputs.report import FILES, report_html, write_report
from semmap_pp.outputs.ros2 import write_run_bag
from semmap_pp.outputs.types_layer import write_types_layer
from semmap_pp.sampler.diagnostics import to_datatree, write_trace
from semmap_pp.sampler.marginals import door_marginals, unit_marginals
from semmap_pp.sampler.spread import accumulate
from semmap_pp.semantic.regions import join_regions, passage_pairs, regions_image, write_regions_png
from semmap_pp.semantic.world_json import with_posterior, world_dict, write_labels_png, write_world_json

#: Sampled worlds drawn in posterior.png and counted in posterior_cells.png (paper Fig. 7: 1000).
N_SAMPLED_WORLDS = 1000


def diagnostics_text(run, rules_path) -> str:
    """diagnostics.txt: provenance, timing, W* in one line, then the convergence table."""
    inputs, settings, sm = run.inputs, run.settings, run.semantic
    text = (f"map: {inputs.grid.source}\nrules: {rules_path}\nmodel: {inputs.model.path}\n"
            f"seed: {settings.seed}; sampling took {run.timing_text()}\n"
            f"W*: {sm.units_text()}, log posterior {sm.log_posterior:.2f}, "
            f"CPR {sm.cpr:.4f} (ROI {inputs.roi_name})\n\n{run.report.to_text()}\n")
    if getattr(run, "spread", None) is not None:
        text += f"\n{run.spread.text()}\n\n{run.spread.report.to_text()}\n"
    return text


def posterior_doc(doc: dict, run, worlds: list) -> dict:
    """world.json's content with the posterior marginals of W*'s units and doors over the typed
    sampled ``worlds`` (:mod:`semmap_pp.sampler.marginals`); ``doc`` itself without worlds."""
    if not worlds:
        return doc
    sm = run.semantic
    doors = dict(zip(sm.derived.doors, door_marginals(sm.frame, sm.derived.doors, worlds)))
    return with_posterior(doc, sm, unit_marginals(sm.world, worlds), doors, worlds=len(worlds),
                          source="the sample around W*" if getattr(run, "spread", None) is not None
                          else "the search's draws")


def write_core(out: Path, run, *, rules_name: str, rules_path, worlds=None) -> tuple[list[Path], dict]:
    """world.json (with the posterior marginals over ``worlds``, the typed sampled worlds, when
    given), labels.png, trace.nc, diagnostics.txt; returns the paths and the world.json content."""

    inputs, settings, sm = run.inputs, run.settings, run.semantic
    doc = posterior_doc(world_dict(sm, rules=rules_name, model=inputs.model.path.name, seed=settings.seed,
                                   roi_name=inputs.roi_name), run, worlds)
    written = [write_world_json(out / "world.json", doc), write_labels_png(out / "labels.png", sm.labels_image)]
    tree = to_datatree(run.summaries, sample_stats=run.sample_stats,
                       attrs={"map": printable(inputs.grid.source), "rules": rules_name, "seed": settings.seed,
                              "chains": settings.chains, "tune": settings.tune, "draws": settings.draws,
                              "n_inner": settings.n_inner})
    written.append(write_trace(tree, out / "trace.nc"))
    spread_nc = out / "spread.nc"
    if getattr(run, "spread", None) is not None:
        sp = run.spread
        attrs = {"map": printable(inputs.grid.source), "rules": rules_name, "seed": settings.seed + 1,
                 "chains": settings.chains, "tune": 0, "draws": sp.draws, "n_inner": sp.n_inner,
                 "start": "W*"}
        t = sp.tempering
        if t.on:    # opt-in (--tempered): the ladder the cold chains were drawn under
            attrs |= {"likelihood_exponent": t.ladder[0], "correlation_area": t.area,
                      "rungs": len(t.ladder), "ladder": ", ".join(f"{b:.6g}" for b in t.ladder),
                      "swaps": t.swaps, "other_chains_start": "dispersed" if t.dispersed else "W*",
                      "temperatures": ", ".join(f"{v:.6g}" for v in t.temperatures)}
        written.append(write_trace(to_datatree(sp.summaries, sample_stats=sp.sample_stats, attrs=attrs),
                                   spread_nc))
    elif spread_nc.exists():      # an earlier run's, in a directory written again with --force
        spread_nc.unlink()
    atomic.write_text(out / "diagnostics.txt", diagnostics_text(run, rules_path))
    written.append(out / "diagnostics.txt")
    return written, doc


def remove_stale_temps(out_dir: str | os.PathLike) -> list[Path]:
    """Delete the temporary files an earlier, killed run left in ``out_dir``; return them.

    :mod:`semmap_pp.atomic` writes ``NAME`` through ``.NAME.XXXXXXXX.tmp`` and renames it; a run
    killed (SIGKILL) while writing leaves that file behind. Only temporaries of the output files
    (:data:`semmap_pp.outputs.report.FILES`) are removed; any other file is left alone. Call it
    only while holding ``out_dir``'s lock (:func:`semmap_pp.run.outdir.lock_out_dir`): a run that
    writes into the folder holds it, so no temporary removed here is a live run's.

    >>> import tempfile
    >>> d = Path(tempfile.mkdtemp())
    >>> for n in (".world.json.k2j4h1x0.tmp", ".notes.tmp", "world.json"): _ = (d / n).write_text("")
    >>> [p.name for p in remove_stale_temps(d)], sorted(p.name for p in d.iterdir())
    (['.world.json.k2j4h1x0.tmp'], ['.notes.tmp', 'world.json'])
    """
    out = Path(out_dir)
    gone = []
    for name in FILES:
        for p in out.glob(f".{glob.escape(name)}.*.tmp"):
            try:
                if p.is_dir() and not p.is_symlink():     # a folder's (atomic.atomic_dir: rosbag2/)
                    shutil.rmtree(p)
                else:
                    p.unlink()
                gone.append(p)
            except OSError:
                continue
    return gone


#: The figures of :func:`write_plan`: overlay.png and graph.png.
PLAN_FIGURES = ("overlay", "graph")


def plan_graph(sm, doc: dict):
    """``(graph, regions)``: graph.graphml's graph of ``doc`` (world.json's content) and the
    regions of ``sm`` (units joined by open walls)."""
    passages = passage_pairs(sm)
    regions = join_regions(sm.unit_ids, passages)
    return world_graph(sm, doc, regions, passages), regions


def plan_pngs(sm, doc: dict, figures: tuple[str, ...] = PLAN_FIGURES, graph=None) -> dict[str, bytes]:
    """The PNG bytes of the plan's figures named in ``figures`` (overlay.png, graph.png) of
    ``doc`` (world.json's content); ``graph``: its :func:`plan_graph` graph, made here if needed."""
    if "graph" in figures and graph is None:
        graph = plan_graph(sm, doc)[0]
    drawn = {"overlay": lambda: fig.overlay_png(sm, doc), "graph": lambda: fig.graph_png(sm, graph)}
    return {name: drawn[name]() for name in PLAN_FIGURES if name in figures}


def write_plan(out: Path, sm, doc: dict, figures: tuple[str, ...] = PLAN_FIGURES) -> tuple[list[Path], dict, dict]:
    """The files of one world, the plan a planner or a person uses: world.geojson, graph.graphml,
    regions.png, rooms.png, the types layer, the ROS 2 bag rosbag2/, and of overlay.png and
    graph.png those named in ``figures`` (world.json and labels.png are the caller's; ``semmap
    map`` draws graph.png elsewhere meanwhile: :func:`posterior_pngs`). Returns the paths, the
    figures' PNG bytes and the regions."""
    graph, regions = plan_graph(sm, doc)
    region_img = regions_image(sm, regions)
    written = [write_geojson(out / "world.geojson", geojson_dict(sm, doc, regions)),
               write_graphml(out / "graph.graphml", graph),
               write_regions_png(out / "regions.png", region_img),
               write_labels_png(out / "rooms.png", sm.rooms.labels)]
    written.extend(write_types_layer(out, sm, doc))
    written.append(write_run_bag(out, sm, doc))
    pngs = plan_pngs(sm, doc, figures, graph)
    for name, data in pngs.items():
        atomic.write_bytes(out / f"{name}.png", data)
        written.append(out / f"{name}.png")
    return written, pngs, regions


class WstarFiles(NamedTuple):
    """What :func:`write_wstar` wrote and :func:`write_posterior` needs: the paths, the world.json
    document, the figures' PNG bytes so far and the regions."""

    written: list
    doc: dict
    pngs: dict
    regions: dict


def write_wstar(out_dir: str | os.PathLike, run, *, rules_name: str, rules_path=None,
                worlds=None, figures: tuple[str, ...] = PLAN_FIGURES) -> WstarFiles:
    """The files of W* (world.json, labels.png, trace.nc, spread.nc, diagnostics.txt and the plan
    files of :func:`write_plan`, of its figures those named in ``figures``) into ``out_dir``,
    created if missing; world.json with the posterior marginals over ``worlds`` (the typed
    sampled worlds) when given. The first half of :func:`write_all`."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    remove_stale_temps(out)
    sm = run.semantic
    written, doc = write_core(out, run, rules_name=rules_name,
                              rules_path=rules_path if rules_path is not None else rules_name, worlds=worlds)

    plan, pngs, regions = write_plan(out, sm, doc, figures)
    written += plan
    return WstarFiles(written, doc, pngs, regions)


class SpreadImages:
    """Per-cell p(wall) and p(type) of typed ``worlds`` in the input image's frame, from their counts
    on the lattice box they lie in (:func:`~semmap_pp.sampler.spread.accumulate`), made
    (:meth:`~semmap_pp.lattice.frame.Frame.box_to_image`, 0 outside the box) only for the pixels a
    panel of posterior_cells.png shows (:func:`~semmap_pp.outputs.figures.posterior_cells_png`):
    the values of :func:`~semmap_pp.sampler.spread.cell_probabilities` resampled by ``to_image``,
    without a lattice-sized or image-sized float64 array."""

    def __init__(self, frame, worlds: list):
        self.frame = frame
        self.acc, self.box = accumulate(worlds, frame.shape, frame.cells.wall)
        self.n = max(self.acc.n, 1)

    def image(self, counts: np.ndarray, window=None, step: int = 1) -> np.ndarray:
        """``counts / n`` in the image frame: the pixels ``window[y0:y1:step, x0:x1:step]``."""
        return self.frame.box_to_image(counts / self.n, self.box, fill=0.0, window=window, step=step)

    def type_panel(self, k: int, box, step: int) -> np.ndarray:
        return self.image(self.acc.types[k], box, step)

    def wall_panel(self, box, block: int, step: int) -> np.ndarray:
        """``maximum_filter(p_wall[y0:y1, x0:x1], size=block)[::step, ::step]``, in bands of
        rows each with ``block`` rows of margin (the filter reads ``block // 2`` of them)."""
        y0, y1, x0, x1 = box
        if block <= 1:
            return self.image(self.acc.wall, box, step)
        rows = np.arange(y0, y1, step)
        out = []
        for i in range(0, len(rows), PANEL_BAND_ROWS):
            want = rows[i:i + PANEL_BAND_ROWS]
            a0, a1 = max(int(want[0]) - block, y0), min(int(want[-1]) + block + 1, y1)
            part = ndimage.maximum_filter(self.image(self.acc.wall, (a0, a1, x0, x1)), size=block)
            out.append(part[want - a0, ::step])
        return np.concatenate(out) if out else np.zeros((0, len(range(x0, x1, step))))


#: Output rows of :meth:`SpreadImages.wall_panel` per band.
PANEL_BAND_ROWS = 64


def posterior_pngs(run, worlds: list, graph: bool = False) -> dict[str, bytes]:
    """The figures of report.html that need neither world.json nor the plan files, as PNG bytes:
    posterior.png and posterior_cells.png (of the typed sampled ``worlds``) and the previews of
    regions.png, rooms.png and the region of interest; with ``graph`` graph.png too (of W*'s
    world.json content without the posterior marginals, which it does not draw). ``semmap map``
    draws them in a forked process while it writes the other files (:mod:`semmap_pp.forked`)."""
    sm = run.semantic
    drawn = plan_pngs(sm, world_dict(sm), ("graph",)) if graph else {}
    images = SpreadImages(sm.frame, worlds)
    source = run.spread if run.spread is not None else run   # the draws the worlds come from
    mode = source.report.within_mode
    ess = mode.ess if mode is not None else None      # NaN when nothing moved: no ESS is given
    cells_png = fig.posterior_cells_png(sm, images, len(worlds), ess)
    del images   # the counts: not kept through the other figures
    return drawn | {"posterior": fig.posterior_png(sm, worlds, ess), "posterior_cells": cells_png,
                    "regions": fig.regions_preview_png(sm, regions_image(sm)),
                    "rooms": fig.regions_preview_png(sm, sm.rooms.labels),
                    "roi": fig.roi_png(sm, run.inputs.roi_name)}


def write_posterior(out_dir: str | os.PathLike, run, worlds: list, wstar: WstarFiles, *, rules_name: str,
                    other_files: tuple[str, ...] = (), figures=None) -> list[Path]:
    """posterior.png, posterior_cells.png and report.html, after :func:`write_wstar`; the paths
    written, those of ``wstar`` first. ``figures``: a callable that returns
    :func:`posterior_pngs` (drawn elsewhere meanwhile); by default they are drawn here. The plan's
    figures that ``wstar`` left out (:func:`write_plan`) are written too, from ``figures`` or drawn
    here. The second half of :func:`write_all`."""
    out = Path(out_dir)
    written, doc, pngs, regions = list(wstar.written), wstar.doc, dict(wstar.pngs), wstar.regions
    left = [name for name in PLAN_FIGURES if name not in pngs]
    pngs |= figures() if figures is not None else posterior_pngs(run, worlds)
    pngs |= plan_pngs(run.semantic, doc, tuple(name for name in left if name not in pngs))   # drawn here
    for name in left + ["posterior", "posterior_cells"]:
        atomic.write_bytes(out / f"{name}.png", pngs[name])
        written.append(out / f"{name}.png")
    names = [p.name for p in written] + ["report.html"] + list(other_files)
    files = [n for n in FILES if n in names] + [n for n in names if n not in FILES]
    written.append(write_report(out / "report.html",
                                report_html(run, doc, pngs, regions, rules_name=rules_name, files=files)))
    return written


def write_all(out_dir: str | os.PathLike, run, worlds: list, *, rules_name: str, rules_path=None,
              other_files: tuple[str, ...] = ()) -> list[Path]:
    """Write every output of ``run`` into ``out_dir`` (created if missing); return the paths written:
    :func:`write_wstar`, then :func:`write_posterior`.

    Parameters
    ----------
    out_dir : path
    run : MapRun
    worlds : list of World
        The typed sampled worlds of posterior.png and posterior_cells.png, from the run's sample
        around W* when it has one (:func:`semmap_pp.run.spread.posterior_worlds`, usually
        :data:`N_SAMPLED_WORLDS` of them): the run hands them over typed, outputs only draw them.
    rules_name : str
        The rule file's name (world.json, trace.nc, report).
    rules_path : path, optional
        Its path as given (diagnostics.txt); ``rules_name`` when omitted.
    other_files : tuple of str
        Names of files the caller writes into ``out_dir`` itself (``semmap map``: ``resume.npz``,
        before this call); the report lists them with the others.

    Every file goes through :func:`semmap_pp.atomic.write_bytes`: a full disk stops the writing
    with a :class:`~semmap_pp.errors.WriteError` naming the file, and each file written before it
    stays complete. The caller holds ``out_dir``'s lock (:func:`semmap_pp.run.outdir.lock_out_dir`):
    the temporaries this removes first (:func:`remove_stale_temps`) are then a dead run's.
    """
    wstar = write_wstar(out_dir, run, rules_name=rules_name, rules_path=rules_path, worlds=worlds)
    return write_posterior(out_dir, run, worlds, wstar, rules_name=rules_name, other_files=other_files)


__all__ = ["N_SAMPLED_WORLDS", "WstarFiles", "write_all", "write_wstar", "write_posterior", "posterior_pngs",
           "write_core", "posterior_doc", "write_plan", "plan_graph", "plan_pngs", "PLAN_FIGURES", "diagnostics_text"]
