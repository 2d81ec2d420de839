"""Figures of a semantic map as PNG bytes: the paper's Fig. 5b (graph), Fig. 5c (overlay), Fig. 7
(posterior), per-cell probability maps, the region of interest and the regions.

Every figure is drawn in the input image's continuous pixel frame (x = column, y = row, y down, as
:mod:`semmap_pp.cells`), cropped to the known part of the map, with matplotlib's Agg backend on
``Figure`` objects (no pyplot state, nothing left open). Each function returns PNG bytes, so the
same bytes are written to a file and embedded in report.html.
"""

from __future__ import annotations

import functools
import gc
import io
import itertools
import math

import matplotlib

matplotlib.use("Agg")  # headless; also set before any pyplot import elsewhere in the process

import networkx as nx  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.backends.backend_agg import FigureCanvasAgg  # noqa: E402
from matplotlib.collections import LineCollection  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402
from matplotlib.lines import Line2D  # noqa: E402
from matplotlib.patches import Patch, Polygon  # noqa: E402
from matplotlib.ticker import MaxNLocator  # noqa: E402
from scipy import ndimage  # noqa: E402

from semmap_pp.cells import FREE, OCCUPIED, TYPE_LETTER, UNIT_TYPES, UNKNOWN, W_OBJECT, W_WALL  # noqa: E402
from semmap_pp.errors import printable  # noqa: E402

# Colours of the paper's Fig. 5 (classified map: black occupied, gray unknown, white free).
RGB = {"free": (255, 255, 255), "unknown": (160, 160, 160), "occupied": (0, 0, 0),
       "wall": (0, 0, 255), "door": (0, 230, 230), "object": (0, 170, 0),
       "inferred wall": (150, 175, 255)}
MAGENTA = "#e000e0"
EXTERIOR = "#d35400"   # exterior units (free space seen outside the building): dashed orange
TYPE_FACE = {"room": "#fff3b0", "corridor": "#bde0ff", "hall": "#ffd1a6", "other": "#e4e4e4"}
LONG_SIDE_PX = 1400     # a figure's longer side on screen, in pixels (at DPI)
MIN_SIDE_PX = 400       # its shorter side at least: a map of 1 x 2000 cells still draws (and reads)
DPI = 100


def png(fig: Figure) -> bytes:
    """PNG bytes of a figure (then the figure is dropped).

    The figure is cleared once saved and unreachable cycles collected: a figure's artists refer to
    each other, so without this its images (copies of arrays of the input's size, float64 for the
    probability panels) waited for the garbage collector, and on a campus map the report's figures
    piled up to several GB. ``semmap map`` makes its figures inside
    :func:`semmap_pp.run.memory.young_heap`, so that this collection reads only the objects the
    outputs made."""
    buf = io.BytesIO()
    FigureCanvasAgg(fig)
    fig.savefig(buf, format="png", dpi=DPI)
    fig.clear()
    gc.collect()
    return buf.getvalue()


def classified_rgb(classes: np.ndarray, light: bool = False) -> np.ndarray:
    """(H, W, 3) uint8 picture of input classes; ``light`` greys it so drawings on top stand out."""
    colours = {FREE: RGB["free"], UNKNOWN: (215, 215, 215) if light else RGB["unknown"],
               OCCUPIED: (110, 110, 110) if light else RGB["occupied"]}
    lut = np.zeros((256, 3), np.uint8)   # any other code black, as before
    for code, rgb in colours.items():
        lut[code] = rgb
    return lut[np.asarray(classes, dtype=np.uint8)]


def overlay_rgb(sm) -> np.ndarray:
    """(H, W, 3) uint8: the classified map with W*'s walls (blue; light blue where the map shows
    nothing there: an inferred wall, e.g. the far side of a room glimpsed through its door), doors
    (cyan) and objects (green)."""
    rgb = classified_rgb(sm.grid.classes)
    wall = sm.states_image == W_WALL
    rgb[wall] = RGB["wall"]
    rgb[wall & (sm.grid.classes == UNKNOWN)] = RGB["inferred wall"]
    rgb[sm.states_image == W_OBJECT] = RGB["object"]
    rgb[sm.door_image()] = RGB["door"]
    return rgb


def crop_box(sm, margin_px: int = 10) -> tuple[int, int, int, int]:
    """``(y0, y1, x0, x1)``: the known part of the map and every unit, plus a margin, in the image."""
    keep = (sm.grid.classes != UNKNOWN) | (sm.labels_image > 0)
    if not keep.any():
        return 0, sm.grid.classes.shape[0], 0, sm.grid.classes.shape[1]
    rows, cols = np.flatnonzero(keep.any(axis=1)), np.flatnonzero(keep.any(axis=0))
    h, w = keep.shape
    return (max(rows[0] - margin_px, 0), min(rows[-1] + 1 + margin_px, h),
            max(cols[0] - margin_px, 0), min(cols[-1] + 1 + margin_px, w))


def side_by_side(sms, *, extra_h: float, panel_px: int = 700):
    """One panel per semantic map, side by side, all showing the union of their :func:`crop_box`
    with the longer side of a panel ``panel_px`` pixels; returns ``(fig, axes, box)``."""
    boxes = [crop_box(sm) for sm in sms]
    y0, y1 = min(b[0] for b in boxes), max(b[1] for b in boxes)
    x0, x1 = min(b[2] for b in boxes), max(b[3] for b in boxes)
    n = len(sms)
    panel = panel_px / max(y1 - y0, x1 - x0)
    fig = Figure(figsize=(n * max((x1 - x0) * panel, MIN_SIDE_PX) / DPI,
                          max((y1 - y0) * panel, MIN_SIDE_PX) / DPI + extra_h), dpi=DPI)
    axes = fig.subplots(1, n, squeeze=False).ravel()
    return fig, axes, (y0, y1, x0, x1)


def _axes(box, *, extra_h: float = 0.0, ncols: int = 1, nrows: int = 1, long_side: int = LONG_SIDE_PX):
    """A figure whose panels show ``box`` at a readable scale; returns (fig, axes list)."""
    y0, y1, x0, x1 = box
    h, w = (y1 - y0) * nrows, (x1 - x0) * ncols
    scale = long_side / max(h, w)
    fig = Figure(figsize=(max(w * scale, MIN_SIDE_PX) / DPI, max(h * scale, MIN_SIDE_PX) / DPI + extra_h),
                 dpi=DPI)
    axes = fig.subplots(nrows, ncols, squeeze=False).ravel().tolist()
    for ax in axes:
        ax.set_xlim(x0, x1)
        ax.set_ylim(y1, y0)
        ax.set_aspect("equal")
        ax.set_xticks([])
        ax.set_yticks([])
    return fig, axes


#: A picture of more cells than this is shown from every ``step``-th cell (:func:`display_step`).
DECIMATE_MIN_CELLS = 4_000_000


def display_step(ax, box) -> int:
    """1, or for a ``box`` of more than :data:`DECIMATE_MIN_CELLS` cells the whole cells per screen
    pixel of the panel ``ax`` (its share of the figure, rounded down): the step between the cells
    a picture is drawn from. Matplotlib resamples an image through float copies of tens of bytes
    per cell; on a campus canvas of 24 M cells one figure took 1-3 GB, for a panel of a few
    hundred thousand pixels. The maps of the paper and the benchmarks (up to 1.5 M cells) are
    drawn from every cell."""
    y0, y1, x0, x1 = box
    if (y1 - y0) * (x1 - x0) <= DECIMATE_MIN_CELLS:
        return 1
    fig = ax.get_figure()
    nrows, ncols = ax.get_subplotspec().get_gridspec().get_geometry()
    per_px = max((x1 - x0) / (fig.get_figwidth() * DPI / ncols), (y1 - y0) / (fig.get_figheight() * DPI / nrows))
    return max(1, int(per_px))


def _show(ax, rgb, box, step: int | None = None, **kw):
    """``rgb[y0:y1, x0:x1]`` on ``ax`` (every ``step``-th cell: :func:`display_step`); ``rgb`` may
    be a function of a slice pair, called for the cells shown only."""
    y0, y1, x0, x1 = box
    step = display_step(ax, box) if step is None else step
    rows, cols = slice(y0, y1, step), slice(x0, x1, step)
    part = rgb(rows, cols) if callable(rgb) else rgb[rows, cols]
    ax.imshow(part, extent=(x0, x0 + part.shape[1] * step, y0 + part.shape[0] * step, y0),
              interpolation="nearest", **kw)


def _unit_centres(doc) -> dict[int, tuple[float, float]]:
    return {u["id"]: tuple(np.asarray(u["vertices_px"], float).mean(axis=0)) for u in doc["units"]}


def _legend(fig, handles, ncol=None):
    fig.legend(handles=handles, loc="lower center", ncol=ncol or len(handles), frameon=False, fontsize=9)


def overlay_png(sm, doc: dict) -> bytes:
    """overlay.png (paper Fig. 5c): W* on the classified map (walls the map does not show in light
    blue), type letter and id at each unit's centre (R room, C corridor, H hall, E other), magenta
    N at unexplored areas, exterior units (free space seen outside the building) dashed with X and
    their id."""
    box = crop_box(sm)
    fig, (ax,) = _axes(box, extra_h=0.4)
    _show(ax, overlay_rgb(sm), box)
    for uid, (x, y) in _unit_centres(doc).items():
        ax.text(x, y, f"{TYPE_LETTER[sm.type_of(uid)]}{uid}", ha="center", va="center", fontsize=11,
                fontweight="bold", bbox=dict(boxstyle="round,pad=0.15", fc="white", ec="none", alpha=0.85))
    for n in doc["unexplored"]:
        ax.text(*n["center_px"], f"N{n['id']}", ha="center", va="center", color=MAGENTA, fontsize=11,
                fontweight="bold")
    for e in doc.get("exterior", []):
        v = np.asarray(e["vertices_px"], float)
        ax.add_patch(Polygon(v, closed=True, fill=False, ec=EXTERIOR, lw=2.0, ls="--", zorder=4))
        ax.text(*v.mean(axis=0), f"X{e['id']}", ha="center", va="center", color=EXTERIOR, fontsize=11,
                fontweight="bold", bbox=dict(boxstyle="round,pad=0.15", fc="white", ec="none", alpha=0.85))
    handles = [Patch(fc=np.array(RGB[k]) / 255, ec="0.5", label=k) for k in
               ("occupied", "unknown", "free", "wall", "inferred wall", "door", "object")]
    if doc.get("exterior"):
        handles.append(Patch(fc="none", ec=EXTERIOR, ls="--", lw=2.0, label="exterior (X)"))
    _legend(fig, handles)
    fig.subplots_adjust(0.005, 0.4 / fig.get_figheight(), 0.995, 0.995)
    return png(fig)


def graph_png(sm, graph, *, max_object_nodes: int = 40) -> bytes:
    """graph.png (paper Fig. 5b): units as ellipses at their centres, doors solid, adjacency without
    a door dashed, passages across free floor between units that do not touch dash-dotted, objects
    blue squares, unexplored areas magenta squares, exterior units orange
    squares.

    Objects are drawn one node each when there are at most ``max_object_nodes`` of them; otherwise
    one node per unit holding its object count (a map with hundreds of objects would bury the graph).
    """

    box = crop_box(sm)
    fig, (ax,) = _axes(box, extra_h=0.4)
    _show(ax, classified_rgb(sm.grid.classes, light=True), box, alpha=0.35)
    pos = {n: (a["x_px"], a["y_px"]) for n, a in graph.nodes(data=True)}
    kind = nx.get_node_attributes(graph, "kind")
    rel = nx.get_edge_attributes(graph, "relation")
    units = [n for n in graph if kind[n] == "unit"]
    objects = [n for n in graph if kind[n] == "object"]
    common = dict(pos=pos, ax=ax, edge_color="black")
    nx.draw_networkx_edges(graph, edgelist=[e for e, r in rel.items() if r == "door"], width=1.8, **common)
    nx.draw_networkx_edges(graph, edgelist=[e for e, r in rel.items() if r == "adjacent"], width=1.2,
                           style="dashed", **common)
    across = [e for e, r in rel.items() if r == "passage"]
    nx.draw_networkx_edges(graph, edgelist=across, width=1.2, style="dashdot", **common)
    nx.draw_networkx_edges(graph, pos=pos, ax=ax, edgelist=[e for e, r in rel.items() if r == "next_to"],
                           width=0.8, style="dotted", edge_color=MAGENTA)
    square = dict(boxstyle="square,pad=0.2", lw=0.8)
    if len(objects) <= max_object_nodes:
        nx.draw_networkx_edges(graph, pos=pos, ax=ax, edge_color="tab:blue", width=0.6,
                               edgelist=[e for e, r in rel.items() if r == "contains"])
        for n in objects:
            ax.text(*pos[n], str(graph.nodes[n]["id"]), ha="center", va="center", fontsize=6, color="white",
                    bbox=dict(fc="tab:blue", ec="navy", **square))
    else:
        for u in units:
            count = sum(1 for v in graph[u] if kind[v] == "object")
            if count:
                ax.annotate(f"{count} obj", pos[u], xytext=(0, -22), textcoords="offset points", ha="center",
                            va="center", fontsize=7, color="white", bbox=dict(fc="tab:blue", ec="navy", **square),
                            arrowprops=dict(arrowstyle="-", color="tab:blue", lw=0.8, shrinkA=0, shrinkB=0))
    for n, a in graph.nodes(data=True):
        if a["kind"] in ("unexplored", "exterior"):
            face, edge = (MAGENTA, "purple") if a["kind"] == "unexplored" else (EXTERIOR, "black")
            ax.text(*pos[n], a["label"], ha="center", va="center", fontsize=7, color="white",
                    bbox=dict(fc=face, ec=edge, **square))
    for u in units:
        a = graph.nodes[u]
        ax.text(*pos[u], a["label"], ha="center", va="center", fontsize=9, fontweight="bold", zorder=5,
                bbox=dict(boxstyle="ellipse,pad=0.35", fc=TYPE_FACE[a["type"]], ec="black", lw=1.0))
    handles = [Line2D([], [], color="black", lw=1.8, label="door"),
               Line2D([], [], color="black", lw=1.2, ls="--", label="adjacent, no door")]
    if across:
        handles.append(Line2D([], [], color="black", lw=1.2, ls="-.", label="passage across free floor"))
    handles += [Patch(fc="tab:blue", label="objects" if len(objects) <= max_object_nodes else "objects per unit"),
                Patch(fc=MAGENTA, label="unexplored (N)")]
    if any(a["kind"] == "exterior" for _, a in graph.nodes(data=True)):
        handles.append(Patch(fc=EXTERIOR, label="exterior (X)"))
    handles += [Patch(fc=TYPE_FACE[t], ec="black", label=f"{TYPE_LETTER[t]} = {t}") for t in UNIT_TYPES]
    _legend(fig, handles, ncol=len(handles))
    fig.subplots_adjust(0.005, 0.4 / fig.get_figheight(), 0.995, 0.995)
    return png(fig)


def world_outlines(frame, worlds) -> np.ndarray:
    """(n, 5, 2) closed outlines ``[x, y]`` in the image of every unit of every world."""
    lines = [frame.rect_vertices_px(w.rects[s]) for w in worlds for s in np.flatnonzero(w.active)]
    if not lines:
        return np.zeros((0, 5, 2))
    v = np.stack(lines)
    return np.concatenate([v, v[:, :1]], axis=1)


def outline_counts(worlds) -> tuple[np.ndarray, np.ndarray]:
    """The distinct unit rectangles of ``worlds`` (n, 4), in order of first appearance, and in how
    many of the worlds each appears (n,).

    >>> from semmap_pp import world as wm
    >>> a = wm.add(wm.add(wm.empty(3), 0, (0, 0, 9, 9)), 1, (0, 8, 9, 20))
    >>> b = wm.replace(a, 1, (0, 8, 9, 22))
    >>> rects, n = outline_counts([a, a, b])
    >>> rects.tolist(), n.tolist()
    ([[0, 0, 9, 9], [0, 8, 9, 20], [0, 8, 9, 22]], [3, 2, 1])
    """
    counts: dict[tuple, int] = {}
    for w in worlds:
        for r in w.rects[w.active]:
            key = tuple(int(v) for v in r)
            counts[key] = counts.get(key, 0) + 1
    return np.array(list(counts), dtype=int).reshape(-1, 4), np.array(list(counts.values()), dtype=int)


def world_alpha(n_worlds: int) -> float:
    """The opacity of one world's line when ``n_worlds`` are drawn: 10 / n, within [0.02, 0.6]."""
    return float(np.clip(10.0 / max(n_worlds, 1), 0.02, 0.6))


def world_lines(frame, worlds) -> LineCollection:
    """The outlines of every unit of ``worlds`` (image frame), thin and translucent: each distinct
    outline once, with the opacity of its ``k`` copies laid over each other, ``1 - (1 - a)^k``,
    ``a`` = :func:`world_alpha` (:func:`outline_counts`)."""
    rects, k = outline_counts(worlds)
    if not len(rects):
        return LineCollection(np.zeros((0, 5, 2)), linewidths=0.5)
    v = np.stack([frame.rect_vertices_px(r) for r in rects])
    colours = np.tile([0.85, 0.0, 0.1, 0.0], (len(rects), 1))
    colours[:, 3] = 1.0 - (1.0 - world_alpha(len(worlds))) ** k
    return LineCollection(np.concatenate([v, v[:, :1]], axis=1), colors=colours, linewidths=0.5)


def independent_text(ess: float | None) -> str:
    """What the figures' worlds are worth, from the smallest ESS of the draws they come from.

    >>> independent_text(2.4), independent_text(None), independent_text(float("nan"))
    ('; smallest ESS 2: about 2 independent worlds', '', '')
    """
    if ess is None or not math.isfinite(ess):
        return ""
    return f"; smallest ESS {ess:.0f}: about {ess:.0f} independent worlds"


def posterior_png(sm, worlds, ess: float | None = None) -> bytes:
    """posterior.png (paper Fig. 7): every sampled world drawn with a very thin, translucent line;
    the caption gives ``ess`` (:func:`independent_text`), the smallest ESS of the draws behind them.

    Each distinct unit outline is drawn once with the opacity of its ``k`` copies laid over each
    other, ``1 - (1 - a)^k`` (a unit that every world shares is as dark as before, at a fraction
    of the lines: 1000 worlds near W* share most of their units)."""
    box = crop_box(sm)
    fig, (ax,) = _axes(box, extra_h=0.35)
    _show(ax, classified_rgb(sm.grid.classes, light=True), box)
    alpha = world_alpha(len(worlds))
    ax.add_collection(world_lines(sm.frame, worlds))
    fig.text(0.5, 0.12 / fig.get_figheight(), f"{len(worlds)} sampled worlds{independent_text(ess)}, each unit "
             f"drawn with a thin line (opacity {alpha:.2f}): where lines pile up, the sampled worlds agree",
             ha="center", fontsize=9)
    fig.subplots_adjust(0.005, 0.35 / fig.get_figheight(), 0.995, 0.995)
    return png(fig)


def posterior_cells_png(sm, images, n_worlds: int, ess: float | None = None) -> bytes:
    """posterior_cells.png: per-cell probability of wall and of each unit type over sampled worlds
    (the colour bar's label gives ``ess``, as :func:`posterior_png`).

    ``images`` gives the panels' pixels in the input image's frame, each only when drawn:
    ``images.wall_panel(box, block, step)``, the largest p(wall) of each ``block``-square of the
    pixels of ``box`` ``(y0, y1, x0, x1)`` (``scipy.ndimage.maximum_filter``), every ``step``-th
    row and column; ``images.type_panel(k, box, step)``, p(type ``k``) at every ``step``-th
    pixel (``outputs.write.SpreadImages``).
    """
    box = crop_box(sm)
    fig, axes = _axes(box, ncols=3, nrows=2, extra_h=0.9, long_side=1500)
    _show(axes[0], classified_rgb(sm.grid.classes), box)
    axes[0].set_title("classified map", fontsize=10)
    y0, y1, x0, x1 = box
    # a wall is 2-3 cells thick: on a panel narrower than the map, nearest-neighbour display drops it,
    # so each screen pixel shows the largest probability of the cells it covers
    block = int(np.ceil((x1 - x0) / (fig.get_figwidth() * DPI / 3)))
    step = display_step(axes[1], box)
    # one panel's pixels at a time, each made when drawn
    panels = itertools.chain([("wall", lambda: images.wall_panel(box, block, step))],
                             ((t, functools.partial(images.type_panel, k, box, step))
                              for k, t in enumerate(UNIT_TYPES)))
    im = None
    for ax, (name, make) in zip(axes[1:], panels):
        p = make()
        im = ax.imshow(p, extent=(x0, x0 + p.shape[1] * step, y0 + p.shape[0] * step, y0), cmap="magma",
                       vmin=0.0, vmax=1.0, interpolation="nearest")
        del p
        ax.set_title(f"p({name})", fontsize=10)
    fig.subplots_adjust(0.005, 0.6 / fig.get_figheight(), 0.995, 1 - 0.3 / fig.get_figheight(), wspace=0.02,
                        hspace=0.3 / (fig.get_figheight() / 2))
    cax = fig.add_axes((0.3, 0.2 / fig.get_figheight(), 0.4, 0.12 / fig.get_figheight()))
    fig.colorbar(im, cax=cax, orientation="horizontal").set_label(
        f"probability over {n_worlds} sampled worlds{independent_text(ess)}", fontsize=9)
    return png(fig)


def roi_png(sm, roi_name: str) -> bytes:
    """The region of interest of the CPR (paper Fig. 5a): magenta dashed outline on the classified map."""
    box = crop_box(sm)
    fig, (ax,) = _axes(box, extra_h=0.3, long_side=900)
    _show(ax, classified_rgb(sm.grid.classes), box)
    h, w = sm.roi.shape
    if sm.roi.any() and not sm.roi.all():
        step = display_step(ax, (0, h, 0, w))   # every step-th cell of a canvas of millions
        ax.contour(np.arange(0, w, step) + 0.5, np.arange(0, h, step) + 0.5,
                   sm.roi[::step, ::step].astype(float), levels=[0.5],
                   colors=[MAGENTA], linewidths=1.5, linestyles="dashed")
    fig.text(0.5, 0.1 / fig.get_figheight(), f"region of interest: {roi_name}", ha="center", fontsize=9)
    fig.subplots_adjust(0.005, 0.3 / fig.get_figheight(), 0.995, 0.995)
    return png(fig)


def regions_preview_png(sm, regions_image: np.ndarray) -> bytes:
    """regions.png made visible: one colour per region, its id at its centre."""
    box = crop_box(sm)
    fig, (ax,) = _axes(box, extra_h=0.1, long_side=900)
    _show(ax, classified_rgb(sm.grid.classes, light=True), box)
    ids = np.unique(regions_image[regions_image > 0])
    if ids.size:
        palette = matplotlib.colormaps["tab20"](np.arange(20))
        colours = np.zeros((int(ids.max()) + 1, 4))
        colours[ids] = palette[(ids - 1) % 20]
        colours[ids, 3] = 0.7
        _show(ax, lambda rows, cols: colours[regions_image[rows, cols]], box)
        # each region's centre from one pass over its cells (sums of whole numbers, exact in float64:
        # the same means as each region's own nonzero(), without a pass over the image per region)
        ys, xs = np.nonzero(regions_image > 0)
        lab = regions_image[ys, xs].astype(np.intp)
        n = np.bincount(lab)
        sx, sy = np.bincount(lab, weights=xs), np.bincount(lab, weights=ys)
        del ys, xs, lab
        for rid in ids:
            ax.text(sx[rid] / n[rid] + 0.5, sy[rid] / n[rid] + 0.5, str(int(rid)), ha="center", va="center",
                    fontsize=8, fontweight="bold")
    fig.subplots_adjust(0.005, 0.1 / fig.get_figheight(), 0.995, 0.995)
    return png(fig)


#: stability.png: a unit found with its type in every other seed's W*, in some or with another
#: type, in none
def _number(v, spec: str) -> str:
    return "nan" if isinstance(v, float) and not math.isfinite(v) else format(v, spec)


def compare_png(runs: list, worlds: list, rows: list) -> bytes:
    """compare.png: the sampled worlds of each run drawn thin on the map, side by side (paper Fig. 7);
    ``rows`` are the runs' :class:`~semmap_pp.studies.compare.RuleSetSummary`."""
    fig, axes, (y0, y1, x0, x1) = side_by_side([r.semantic for r in runs], extra_h=0.6)
    for ax, run, ws, row in zip(axes, runs, worlds, rows):
        ax.imshow(classified_rgb(run.semantic.grid.classes, light=True)[y0:y1, x0:x1],
                  extent=(x0, x1, y1, y0), interpolation="nearest")
        ax.add_collection(world_lines(run.semantic.frame, ws))
        ax.set_xlim(x0, x1)
        ax.set_ylim(y1, y0)
        ax.set_aspect("equal")
        ax.set_xticks([])
        ax.set_yticks([])
        ax.set_title(f"{row.name}: {row.n_worlds} worlds, walls disagree on "
                     f"{_number(row.wall_disagreement_m2, '.2f')} m², defects {_number(row.defects_mean, '.2f')}",
                     fontsize=9)
    fig.subplots_adjust(0.01, 0.01, 0.99, 1 - 0.5 / fig.get_figheight(), wspace=0.03)
    return png(fig)


AGREEMENT_COLOURS = {"every seed": "#1a9850", "some seeds": "#f39c12", "no other seed": "#d73027"}


def agreement_class(u) -> str:
    """The :data:`AGREEMENT_COLOURS` key of a :class:`~semmap_pp.studies.stability.UnitAgreement`."""
    if u.agreed:
        return "every seed"
    return "some seeds" if u.found else "no other seed"


def stability_png(sm, agreement, seeds) -> bytes:
    """stability.png: the reference W* (``sm``) on the light classified map, each unit filled in
    the colour of how many other seeds' W*s hold it (:func:`agreement_class`), with its id and
    ``found/others``; ``agreement`` are :class:`~semmap_pp.studies.stability.UnitAgreement` rows."""
    box = crop_box(sm)
    fig, (ax,) = _axes(box, extra_h=0.7)
    _show(ax, classified_rgb(sm.grid.classes, light=True), box)
    for u in agreement:
        v = sm.frame.rect_vertices_px(sm.world.rects[sm.slot_of(u.id)])
        colour = AGREEMENT_COLOURS[agreement_class(u)]
        ax.add_patch(Polygon(v, closed=True, fc=colour, ec=colour, alpha=0.35, lw=1.5, zorder=3))
        ax.add_patch(Polygon(v, closed=True, fill=False, ec=colour, lw=1.8, zorder=4))
        x, y = np.asarray(v, float).mean(axis=0)
        ax.text(x, y, f"{TYPE_LETTER[u.type]}{u.id}\n{u.found}/{u.others}", ha="center", va="center",
                fontsize=9, fontweight="bold", zorder=5,
                bbox=dict(boxstyle="round,pad=0.15", fc="white", ec="none", alpha=0.85))
    fig.suptitle(f"W* of seed {seeds[0]} against the W*s of seeds {', '.join(map(str, seeds[1:]))}: "
                 "units found (IoU >= 0.5) / other seeds", fontsize=11, y=0.998, va="top")
    _legend(fig, [Patch(fc=c, ec=c, alpha=0.6, label=k) for k, c in AGREEMENT_COLOURS.items()])
    fig.subplots_adjust(0.005, 0.4 / fig.get_figheight(), 0.995, 1 - 0.3 / fig.get_figheight())
    return png(fig)


__all__ = ["png", "classified_rgb", "overlay_rgb", "crop_box", "overlay_png",
           "graph_png", "world_outlines", "outline_counts", "world_alpha", "world_lines", "independent_text", "posterior_png", "posterior_cells_png", "roi_png",
           "regions_preview_png", "compare_png", "AGREEMENT_COLOURS", "agreement_class", "stability_png"]


#: ``semmap diff --png``: the colour of each kind of change.
DIFF_COLOUR = {"unchanged": "#9a9a9a", "moved": "#e67e00", "retyped": "#1f5fd6", "removed": "#d62728",
               "added": "#1a9a3a"}


def diff_png(diff) -> bytes:
    """``semmap diff --png``: two world.json plans in map-frame metres, one over the other. NEW's
    units are drawn solid, coloured by what happened to them (unchanged grey, moved orange, retyped
    blue, added green), OLD's moved and removed units dashed (removed in red), and the doors and
    passages that went (red x) or came (green +); labels are NEW's, OLD's for a removed unit
    (:class:`semmap_pp.plans.diff.WorldDiff`)."""
    def ring(u):
        v = np.asarray(u.corners, float)
        return np.vstack([v, v[:1]])

    drawn = [ring(u) for p in diff.pairs for u in (p.old, p.new)] + [ring(u) for u in diff.removed + diff.added]
    pts = np.vstack(drawn) if drawn else np.zeros((1, 2))
    (x0, y0), (x1, y1) = pts.min(axis=0) - 1.0, pts.max(axis=0) + 1.0
    scale = LONG_SIDE_PX / max(x1 - x0, y1 - y0, 1e-9)
    fig = Figure(figsize=(max((x1 - x0) * scale, 300) / DPI, max((y1 - y0) * scale, 300) / DPI + 0.6), dpi=DPI)
    ax = fig.add_axes((0.01, 0.06, 0.98, 0.9))
    ax.set_xlim(x0, x1)
    ax.set_ylim(y0, y1)                 # map frame: y up
    ax.set_aspect("equal")
    ax.set_xticks([])
    ax.set_yticks([])

    def draw(u, colour, dashed=False, label=True, lw=1.6):
        r = ring(u)
        ax.plot(r[:, 0], r[:, 1], color=colour, lw=lw, ls="--" if dashed else "-")
        if label:
            ax.text(*u.center, u.label, color=colour, ha="center", va="center", fontsize=8, clip_on=True)

    for p in diff.pairs:
        moved = diff.moved(p)
        kind = "retyped" if p.retyped else "moved" if moved else "unchanged"
        if moved:
            draw(p.old, DIFF_COLOUR[kind], dashed=True, label=False, lw=1.0)
        draw(p.new, DIFF_COLOUR[kind], lw=1.0 if kind == "unchanged" else 1.8)
    for u in diff.removed:
        draw(u, DIFF_COLOUR["removed"], dashed=True)
    for u in diff.added:
        draw(u, DIFF_COLOUR["added"])
    for openings, marker, kind in ((diff.openings_removed, "x", "removed"), (diff.openings_added, "+", "added")):
        if openings:
            xy = np.array([o.center for o in openings], float)
            ax.plot(xy[:, 0], xy[:, 1], marker, color=DIFF_COLOUR[kind], ms=8, mew=2, ls="none")
    c = diff.counts()
    handles = [Line2D([], [], color=DIFF_COLOUR[k], lw=1.8, ls="--" if k == "removed" else "-",
                      label=f"{k} ({c[k]})") for k in ("unchanged", "moved", "retyped", "removed", "added")]
    handles += [Line2D([], [], color=DIFF_COLOUR["removed"], marker="x", ls="none", mew=2,
                       label=f"door or passage gone ({c['openings_removed']})"),
                Line2D([], [], color=DIFF_COLOUR["added"], marker="+", ls="none", mew=2,
                       label=f"door or passage new ({c['openings_added']})")]
    _legend(fig, handles, ncol=4)
    fig.suptitle(f"{diff.old.path} -> {diff.new.path}  (old dashed, new solid)", fontsize=9)
    return png(fig)


#: The reliability diagram (``semmap eval --figure``, report.html's calibration section): each kind
#: of claim's colour (:data:`semmap_pp.evaluate.calibration.KINDS`).
RELIABILITY_COLOUR = {"units": "#1f5fd6", "types": "#1a9a3a", "doors": "#e67e00"}


def _plain(text: str) -> str:
    """``text`` (a path, say) as matplotlib shows it literally: ``$`` would start mathtext."""
    return printable(text).replace("$", r"\$")


def _reliability_panel(top, bottom, kind: str, c: dict) -> None:
    """One kind's column of :func:`reliability_figure`: the fraction right against the mean
    probability per bin over the diagonal (``top``; the line's gid ``"reliability"``, its markers'
    area grows with the bin's claims, gid ``"claims"``), the claims per bin as bars (``bottom``)."""
    colour = RELIABILITY_COLOUR.get(kind, "black")
    top.plot([0, 1], [0, 1], ls="--", color="#9a9a9a", lw=1.0)
    bins = np.array(c["bins"], dtype=float).reshape(-1, 5)
    lo, hi, n, conf, acc = bins.T
    if n.size:
        top.vlines(conf, conf, acc, color=colour, alpha=0.35, lw=3)
        top.plot(conf, acc, "-", color=colour, lw=1.4, gid="reliability")
        top.scatter(conf, acc, s=25 + 275 * n / n.max(), color=colour, edgecolors="black", linewidths=0.5,
                    zorder=3, gid="claims", clip_on=False)
        bottom.bar(lo, n, width=hi - lo, align="edge", color=colour, alpha=0.7, edgecolor="white", gid="bins")
        title = f"{kind}: {c['claims']} claims, ECE {c['ece']:.4f}"
    else:
        top.text(0.5, 0.5, "no claims", ha="center", va="center", fontsize=11, color="#666666")
        title = f"{kind}: no claims"
    top.set_gid(kind)
    top.set_title(title, fontsize=10)
    top.set_xlim(-0.02, 1.02)
    top.set_ylim(-0.02, 1.02)
    top.set_ylabel("fraction right", fontsize=9)
    top.tick_params(labelbottom=False, labelsize=8)
    top.grid(alpha=0.3)
    bottom.set_xlabel("probability of the claim", fontsize=9)
    bottom.set_ylabel("claims", fontsize=9)
    bottom.tick_params(labelsize=8)
    bottom.yaxis.set_major_locator(MaxNLocator(nbins=3, integer=True))


def reliability_figure(calibration: dict, title: str = "") -> Figure:
    """The reliability diagram of posterior marginals scored against a truth: one column per kind
    of claim of ``calibration``
    (:func:`semmap_pp.evaluate.calibration.calibration_summary`, ``{kind: {"claims", "ece", "bins":
    [[lo, hi, n, confidence, accuracy]]}}``): above, each bin's fraction right against its mean
    probability on the diagonal of calibrated claims, a marker's area growing with the bin's claims;
    below, the claims per bin; the ECE in each column's title. The figure is returned (its axes
    carry the gid of their kind) for a test to read what it plots; :func:`reliability_png` draws it."""
    kinds = list(calibration)
    fig = Figure(figsize=(4.2 * max(len(kinds), 1), 5.4 + (0.3 if title else 0.0)), dpi=DPI)
    grid = fig.add_gridspec(2, max(len(kinds), 1), height_ratios=(3, 1), hspace=0.08, wspace=0.28)
    for i, kind in enumerate(kinds):
        top = fig.add_subplot(grid[0, i])
        _reliability_panel(top, fig.add_subplot(grid[1, i], sharex=top), kind, calibration[kind])
    if kinds:
        handles = [Line2D([], [], ls="--", color="#9a9a9a", lw=1.0, label="calibrated: right a fraction p"),
                   Line2D([], [], color="black", lw=1.4, marker="o", ms=7, mfc="#9a9a9a",
                          label="fraction right per bin (marker area: its claims)"),
                   Line2D([], [], color="#9a9a9a", alpha=0.6, lw=3,
                          label="gap to the diagonal (the ECE: its mean weighted by the claims)")]
        _legend(fig, handles)
    if title:
        fig.suptitle(_plain(title), fontsize=10)
    top_in = 0.6 if title else 0.35
    fig.subplots_adjust(0.06, 1.0 / fig.get_figheight(), 0.98, 1 - top_in / fig.get_figheight())
    return fig


def reliability_png(calibration: dict, title: str = "") -> bytes:
    """:func:`reliability_figure` as PNG bytes (``semmap eval --figure``, report.html)."""
    return png(reliability_figure(calibration, title))


__all__ += ["RELIABILITY_COLOUR", "reliability_figure", "reliability_png"]
