"""report.html: one self-contained page about a run of ``semmap map``.

Every figure is embedded as a ``data:image/png;base64`` URI, the style sheet is inline, and nothing
is loaded from the network, so the page opens offline and can be mailed on its own. Every string
that comes from the inputs (file names, paths, notes) goes through :func:`html.escape`.
"""

from __future__ import annotations

import base64
import html
import math
import os
from collections import Counter
from pathlib import Path

from semmap_pp import __version__, atomic
from semmap_pp.cells import UNIT_TYPES
from semmap_pp.sampler.diagnostics import chains_phrase, format_rhat

#: What each output file holds (name -> one line), in the order the report lists them.
FILES = {
    "world.json": "W*: units (type, type marginals, corners in pixels and metres), doors, objects, "
                  "adjacency, unexplored areas, CPR (schema: docs/world.schema.json)",
    "labels.png": "16-bit unit id per pixel of the input image (walls included), 0 = none",
    "regions.png": "16-bit region id per pixel: units joined through open walls, whole rectangles",
    "rooms.png": "16-bit room id per pixel (world.json's rooms): every free cell of the building in its room, "
                 "doors between rooms 0 (the convention of room segmenters)",
    "types.yaml": "the place types as a map layer for ROS map_server (mode raw; codes: 0 none, "
                  "1 room, 2 corridor, 3 hall, 4 other, 5 door), the input map's resolution and origin",
    "types.pgm": "its image: the input image's size, one code per pixel",
    "rosbag2": "a ROS 2 bag (MCAP) of the types layer as an OccupancyGrid and the units, doors and graph as "
               "MarkerArrays, in the input map's frame and stamp, for ros2 bag play, RViz 2 and Foxglove",
    "world.geojson": "W* as GeoJSON in the map's local metric frame (metres, ROS map frame, not WGS84)",
    "graph.graphml": "the abstract model (paper Fig. 5b) for networkx, Gephi or yEd",
    "overlay.png": "W* on the classified map (paper Fig. 5c)",
    "graph.png": "the abstract model drawn at the unit centres (paper Fig. 5b)",
    "posterior.png": "sampled worlds drawn thin on the classified map (paper Fig. 7)",
    "posterior_cells.png": "per-cell probability of wall and of each unit type over the sampled worlds",
    "trace.nc": "ArviZ trace of the label-invariant summaries and sampler statistics (open with arviz)",
    "spread.nc": "the same for the sample around W* (the draws posterior.png and posterior_cells.png hold)",
    "diagnostics.txt": "R-hat, ESS and the convergence verdict as text",
    "report.html": "this page",
    "resume.npz": "what `semmap map --resume DIR` needs to continue the run (written first)",
}

CSS = """
body{font-family:system-ui,-apple-system,"Segoe UI",Helvetica,Arial,sans-serif;margin:1.5em auto;
max-width:1400px;padding:0 1em;color:#222;line-height:1.4}
h1{font-size:1.6em;margin-bottom:.2em}h2{border-bottom:2px solid #ddd;padding-bottom:.2em;margin-top:1.6em}
table{border-collapse:collapse;margin:.5em 0;font-size:.92em}
th,td{border:1px solid #ccc;padding:.25em .6em;text-align:left;vertical-align:top}
th{background:#f2f2f2}td.num{text-align:right;font-variant-numeric:tabular-nums}
tr.fail td{background:#fde2e2}tr.ok td.v{color:#17692c;font-weight:600}tr.fail td.v{color:#a40000;font-weight:600}
figure{margin:1em 0}figure img{max-width:100%;height:auto;border:1px solid #ccc}
figcaption{font-size:.9em;color:#555;margin-top:.3em}h3{margin:1.2em 0 .2em}
nav{position:sticky;top:0;background:#fff;padding:.4em 0;border-bottom:1px solid #ddd;z-index:1}
nav a{margin-right:1em;color:#1a4f8b;text-decoration:none;font-weight:600}
.cols{display:flex;flex-wrap:wrap;gap:2em;align-items:flex-start}.muted{color:#666}code{background:#f4f4f4;padding:0 .2em}
.verdict{display:inline-block;padding:.15em .6em;border-radius:.3em;font-weight:700}
.verdict.ok{background:#d8f3dc;color:#17692c}.verdict.fail{background:#fde2e2;color:#a40000}
"""


def e(value) -> str:
    """HTML-escaped text of any value."""
    return html.escape(str(value), quote=True)


def data_uri(png: bytes) -> str:
    return "data:image/png;base64," + base64.b64encode(png).decode("ascii")


def _num(v, fmt: str) -> str:
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "–"
    return format(v, fmt)


def _table(header, rows, classes=None) -> str:
    head = "".join(f"<th>{e(h)}</th>" for h in header)
    body = []
    for i, row in enumerate(rows):
        cls = f' class="{classes[i]}"' if classes else ""
        body.append(f"<tr{cls}>" + "".join(row) + "</tr>")
    return f"<table><thead><tr>{head}</tr></thead><tbody>{''.join(body)}</tbody></table>"


def _td(v, num: bool = False, cls: str = "") -> str:
    c = " ".join(x for x in ("num" if num else "", cls) if x)
    return f'<td class="{c}">{e(v)}</td>' if c else f"<td>{e(v)}</td>"


def _figure(png: bytes | None, title: str, caption: str) -> str:
    if png is None:
        return ""
    return (f'<h3>{e(title)}</h3><figure><img src="{data_uri(png)}" alt="{e(title)}">'
            f"<figcaption>{e(caption)}</figcaption></figure>")


def _kv(pairs) -> str:
    return "<table><tbody>" + "".join(f"<tr><th>{e(k)}</th>{_td(v)}</tr>" for k, v in pairs) + "</tbody></table>"


def units_table(doc: dict, regions: dict[int, int]) -> str:
    """The W* table: one row per unit."""
    door_units = {d["id"]: d["units"] for d in doc["doors"]}
    passage_units = {d["id"]: d["units"] for d in doc.get("passages", [])}

    def to(u, key, units) -> str:
        n = Counter(b if a == u["id"] else a for d in u.get(key, []) for a, b in [units[d]])
        return ", ".join(f"{k} (×{c})" if c > 1 else str(k) for k, c in sorted(n.items())) or "–"

    rows = []
    for u in doc["units"]:
        m = u["type_marginals"]
        rows.append([_td(u["id"], True), _td(u["type"])] + [_td(f"{m[t]:.2f}", True) for t in UNIT_TYPES] +
                    [_td(f"{u['size_m'][0]:.2f} × {u['size_m'][1]:.2f}", True),
                     _td(f"{u['size_m'][0] * u['size_m'][1]:.1f}", True),
                     _td(f"{u['seen_share']:.2f} / {u['walls_seen_share']:.2f}", True),
                     _td(regions.get(u["id"], ""), True),
                     _td(to(u, "doors", door_units)), _td(to(u, "passages", passage_units)),
                     _td(len(u["objects"]), True)])
    header = ["id", "type"] + [f"p({t})" for t in UNIT_TYPES] + ["size (m)", "area (m²)",
                                                                  "seen (inside / walls)", "region",
                                                                  "doors to units", "passages to units",
                                                                  "objects"]
    return _table(header, rows)


def convergence_table(report) -> str:

    rows, classes = [], []
    for q in report.quantities:
        rows.append([_td(q.name), _td(_num(q.mean, ".4g"), True),
                     _td(" / ".join(_num(m, ".4g") for m in q.chain_means), True), _td(_num(q.sd, ".3g"), True),
                     _td(format_rhat(q.rhat) if math.isfinite(q.rhat) else "–", True),
                     _td(_num(q.ess_bulk, ".0f"), True),
                     _td(_num(q.ess_tail, ".0f"), True), _td("ok" if q.ok else q.reason, cls="v")])
        classes.append("ok" if q.ok else "fail")
    return _table(["quantity", "mean", "mean per chain", "sd", "R-hat", "ESS bulk", "ESS tail", "verdict"],
                  rows, classes)


def mode_section(rep) -> str:
    """The diagnostics within the best chain's mode (:class:`semmap_pp.sampler.diagnostics.ModeReport`), when
    they say more than the main table; "" otherwise."""
    if not rep.shows_mode():
        return ""
    m = rep.within_mode
    heading = m.heading(rep.n_chains)
    return (f"<h3>{e(heading[0].upper() + heading[1:])}</h3>"
            + (convergence_table(m) if m.quantities else "") + f"<p>{e(m.verdict())}.</p>")


def spread_text(rep) -> str:
    """Which chains' draws the spread figures hold (:func:`semmap_pp.run.results.spread_chains`).

    >>> import numpy as np
    >>> from semmap_pp.sampler.diagnostics import convergence
    >>> lp = np.tile(np.arange(50.0) % 5, (3, 1)); lp[1] -= 100.0
    >>> spread_text(convergence({"log_posterior": lp}, rhat_max=1.01, ess_min=10))
    "Drawn from chains 1, 3, the best chain's mode; chain 2 left out: its mean log posterior lies far below (Convergence)."
    """

    mode = rep.mode_chains()
    left = [c for c in range(1, rep.n_chains + 1) if c not in mode]
    first = rep.within_mode.first_draw if rep.within_mode is not None else 0
    since = f" from draw {first + 1} on (the draws before it still settling)" if first else ""
    if not left:
        return (f"Drawn from {'all ' + str(rep.n_chains) + ' chains' if rep.n_chains > 1 else 'the one chain'}"
                f"{since}.")
    return (f"Drawn from {chains_phrase(mode)}, the best chain's mode{since}; {chains_phrase(left)} left out: "
            f"{'their mean log posteriors lie' if left[1:] else 'its mean log posterior lies'} far below "
            f"(Convergence).")


def spread_section(run) -> str:
    """Where the spread figures come from: the sample around W* with its own R-hat and ESS
    (:class:`semmap_pp.run.results.SpreadSample`), or the search's draws."""
    sp = getattr(run, "spread", None)
    if sp is None:
        return f"<p>{e(spread_text(run.report))}</p>"
    rep, line = sp.report, sp.text()
    verdict = "converged" if rep.ok else "NOT converged"
    return (f"<p>{e(line[0].upper() + line[1:])}. {e(spread_text(rep))}</p>"
            f"<p>Its chains: {verdict} ({rep.n_chains} chains × {rep.n_draws} draws, spread.nc).</p>"
            + failure_text(rep) + convergence_table(rep) + mode_section(rep))


def posterior_marginals_section(doc: dict) -> str:
    """The posterior marginals over the sampled worlds (world.json's ``posterior_exists``,
    ``posterior_type``; :mod:`semmap_pp.sampler.marginals`) beside the knowledge engine's type
    marginals given W* (``type_marginals``); "" when world.json has none."""
    pm = doc.get("posterior_marginals")
    if pm is None:
        return ""
    rows = []
    for u in doc["units"]:
        pt, tm = u.get("posterior_type"), u["type_marginals"]
        rows.append([_td(u["id"], True), _td(u["type"]), _td(f"{tm[u['type']]:.2f}", True),
                     _td(f"{u['posterior_exists']:.2f}", True)]
                    + [_td("–" if pt is None else f"{pt[t]:.2f}", True) for t in UNIT_TYPES])
    units = _table(["unit", "type (W*)", "engine p(type | W*)", "p(exists)"]
                   + [f"posterior p({t})" for t in UNIT_TYPES], rows)
    doors = _table(["door", "units", "width (m)", "p(there)"],
                   [[_td(d["id"], True), _td(" – ".join(map(str, d["units"]))), _td(f"{d['width_m']:.2f}", True),
                     _td(f"{d['posterior_exists']:.2f}", True)] for d in doc["doors"]]) if doc["doors"] else ""
    return (f"<h3>Posterior marginals of W*'s units and doors</h3><p>Counted over the {pm['worlds']} "
            f"sampled worlds ({e(pm['source'])}): a unit exists where {e(pm['unit_exists'])}; its "
            f"posterior type is {e(pm['unit_type'])} (– when none has one); a door is there where "
            f"{e(pm['door_exists'])}. The knowledge engine's type marginals (the W* table) are "
            f"conditional on W*'s geometry; these are over the sampled worlds, and rest on as many "
            f"independent worlds as the ESS above says.</p>" + units + doors)


#: Where report.html holds its calibration section (``semmap eval DIR --truth T --report``): between
#: these two comments, which :func:`report_html` writes empty, before the convergence section.
CALIBRATION_BEGIN, CALIBRATION_END = "<!-- calibration -->", "<!-- /calibration -->"
CONVERGENCE_HEADING = '<h2 id="convergence">'


def calibration_section(calibration: dict, png: bytes, *, run: str, truth: str) -> str:
    """report.html's calibration section: the reliability diagram (``png``,
    :func:`semmap_pp.outputs.figures.reliability_png`) and the reliability table of the run's
    posterior marginals against ``truth`` (``calibration``:
    :func:`semmap_pp.evaluate.calibration.calibration_summary`)."""
    rows = []
    for kind, c in calibration.items():
        rows += [[_td(kind), _td(f"[{lo:.1f}, {hi:.1f}{']' if hi == 1.0 else ')'}"), _td(n, True),
                  _td(f"{conf:.3f}", True), _td(f"{acc:.3f}", True), _td(f"{acc - conf:+.3f}", True)]
                 for lo, hi, n, conf, acc in c["bins"]]
    kinds = _table(["claim", "claims", "mean p", "right", "ECE"],
                   [[_td(kind), _td(c["claims"], True), _td(_num(c["mean_p"], ".3f"), True),
                     _td(_num(c["right"], ".3f"), True), _td(_num(c["ece"], ".4f"), True)]
                    for kind, c in calibration.items()])
    return (f'<h2 id="calibration">Calibration against the truth</h2><p>The posterior marginals of '
            f"W*'s units and doors (Posterior spread) scored against the truth <code>{e(truth)}</code> "
            f"by <code>semmap eval {e(run)} --truth {e(truth)} --report</code>. A claim made with "
            "probability p should be right a fraction p of the time: <i>units</i>, a unit of W* exists "
            "(right when it matches a true unit); <i>types</i>, a matched unit is of its most probable "
            "posterior type; <i>doors</i>, a door of W* is there (right when it matches a true door). "
            "The claims are put in ten bins of p; the expected calibration error (ECE) is the mean over "
            "the bins, weighted by their claims, of |right − mean p| (docs/evaluation.md).</p>"
            + kinds + _figure(png, "Reliability diagram", "Per kind of claim, each bin's fraction right "
                              "against its mean probability (marker area: its claims) over the diagonal of "
                              "calibrated claims; below, the claims per bin; the ECE in each title.")
            + "<h3>Reliability table</h3>"
            + _table(["claim", "p in", "claims", "mean p", "right", "right − mean p"], rows))


def with_calibration(page: str, section: str) -> str:
    """report.html's text ``page`` with ``section`` (:func:`calibration_section`) as its calibration
    section: in place of an earlier one, else in the empty place :func:`report_html` leaves, else
    (a page written without that place) before the convergence section; and a link to it in the
    page's navigation. ValueError when ``page`` has no convergence section (not a report of
    ``semmap map``)."""
    block = f"{CALIBRATION_BEGIN}\n{section}\n{CALIBRATION_END}"
    i = page.find(CALIBRATION_BEGIN)
    j = page.find(CALIBRATION_END, i) if i >= 0 else -1
    if j >= 0:
        page = page[:i] + block + page[j + len(CALIBRATION_END):]
    elif (k := page.find(CONVERGENCE_HEADING)) >= 0:
        page = page[:k] + block + "\n" + page[k:]
    else:
        raise ValueError("no convergence section: not a report.html of `semmap map`")
    if 'href="#calibration"' not in page:
        page = page.replace('<a href="#convergence">', '<a href="#calibration">Calibration</a><a href="#convergence">', 1)
    return page


def failure_text(rep) -> str:
    """A failing verdict's paragraph: which summaries failed by which quantity, and what would fix
    it (:meth:`~semmap_pp.sampler.diagnostics.ConvergenceReport.failed`, ``remedy``); "" if it passed."""
    if rep.ok:
        return ""
    return f"<p>Failed: {e(rep.failed())}.<br>To fix: {e(rep.remedy())}.</p>"


def report_html(run, doc: dict, figures: dict[str, bytes], regions: dict[int, int], *, rules_name: str,
                files: list[str] | None = None) -> str:
    """The page.

    Parameters
    ----------
    run : MapRun
    doc : dict
        The world.json content.
    figures : dict
        PNG bytes by name: ``overlay``, ``graph``, ``posterior``, ``posterior_cells``, ``regions``,
        ``roi`` (any may be missing).
    regions : dict
        Unit id -> region id.
    rules_name : str
        The rule file's name.
    files : list of str, optional
        Output file names to describe (default: every file of :data:`FILES`).
    """
    inputs, sm, rep = run.inputs, run.semantic, run.report
    grid = inputs.grid
    map_name = doc["map"]["yaml"] or doc["map"]["image"] or str(grid.source)
    cpr = "–" if doc["cpr"] is None else f"{100 * doc['cpr']:.1f} %"
    verdict = ('<span class="verdict ok">converged</span>' if rep.ok else
               '<span class="verdict fail">NOT converged</span>')
    summary = _run_summary(run, doc, rules_name)
    world = _world_summary(doc, regions, sm.log_posterior, cpr, inputs.roi_name)
    names = files if files is not None else list(FILES)
    listing = "".join(f'<li><a href="{e(n)}"><code>{e(n)}</code></a> — {e(FILES.get(n, ""))}</li>' for n in names)
    f = figures.get
    parts = [
        "<!DOCTYPE html>", '<html lang="en"><head><meta charset="utf-8">',
        '<meta name="viewport" content="width=device-width, initial-scale=1">',
        f"<title>semmap: {e(map_name)}</title><style>{CSS}</style></head><body>",
        f"<h1>Semantic map of <code>{e(map_name)}</code></h1>",
        f'<p class="muted">{len(doc["units"])} units, CPR {e(cpr)}, chains {verdict}</p>',
        '<nav><a href="#run">Run</a><a href="#world">W*</a><a href="#spread">Posterior spread</a>'
        '<a href="#convergence">Convergence</a><a href="#cpr">CPR</a><a href="#files">Files</a></nav>',
        '<div class="cols"><div><h2 id="run">Run</h2>', summary, '</div>',
        '<div><h2 id="world">The most probable world W*</h2>', world, "</div></div>",
        _figure(f("overlay"), "W* on the classified map (overlay.png)",
                "Black occupied, gray unknown, white free; blue wall (light blue where the map shows none: "
                "inferred), cyan door, green object. Unit type and "
                "id at each centre: R room, C corridor, H hall, E other; magenta N: unexplored area "
                "(paper Fig. 5c)."),
        "<h3>Units</h3>", units_table(doc, regions),
        _figure(f("graph"), "Abstract model (graph.png, graph.graphml)",
                "Paper Fig. 5b: ellipses are units at their centres, solid edges doors, dashed edges "
                "adjacency without a door, blue squares objects, magenta squares unexplored areas."),
        _figure(f("regions"), "Regions (regions.png)",
                "Units joined where the wall between them is open (wider than a door), one colour each, "
                "whole rectangles."),
        _figure(f("rooms"), "Rooms (rooms.png)",
                "Every free cell of the building in its room, one colour each; doors between rooms are "
                "left out. A room no unit covers was seen through its door alone (world.json's rooms)."),
        '<h2 id="spread">Posterior spread</h2>',
        spread_section(run) + posterior_marginals_section(doc),
        _figure(f("posterior"), "Sampled worlds (posterior.png)",
                "Each sampled world drawn with very thin lines on the map (paper Fig. 7)."),
        _figure(f("posterior_cells"), "Per-cell probabilities (posterior_cells.png)",
                "Probability over the sampled worlds that a cell is wall, and that it belongs to a unit of "
                "each type."),
        CALIBRATION_BEGIN + CALIBRATION_END,
        CONVERGENCE_HEADING + "Convergence</h2>",
        f"<p>{verdict} — {rep.n_chains} chains × {rep.n_draws} draws; a label-invariant summary passes when "
        f"R-hat ≤ {e(rep.rhat_max)} and bulk and tail ESS ≥ {e(rep.ess_min)} (Vehtari et al. 2021; "
        f"NaN fails).</p>",
        failure_text(rep) + convergence_table(rep),
        f"<p>{e(note)}.</p>" if (note := rep.separation_note()) else "",
        mode_section(rep),
        '<h2 id="cpr">Cell prediction rate</h2>',
        f"<p>CPR = <b>{e(cpr)}</b>: the share of cells in the region of interest "
        f"(<code>{e(inputs.roi_name)}</code>) that W* explains correctly (free as free, occupied as wall "
        "or object, unknown as object or outside every unit).</p>",
        _figure(f("roi"), "Region of interest", "The region of interest of the CPR, magenta dashed "
                "(paper Fig. 5a)."),
        '<h2 id="files">Files</h2>', f"<ul>{listing}</ul>",
        "</body></html>",
    ]
    return "\n".join(p for p in parts if p) + "\n"


def _run_summary(run, doc: dict, rules_name: str) -> str:
    """The page's Run table: the map, the rules and model, the run's settings and notes."""
    inputs, s, grid = run.inputs, run.settings, run.inputs.grid
    return _kv([
        ("map", grid.source), ("image", f"{grid.width} × {grid.height} cells at {grid.resolution} m/cell"),
        ("building orientation", ", ".join(f"{a:.1f}°" for a in doc["map"].get(
            "orientations_deg", [doc["map"]["orientation_deg"]])) + (
            " (a lattice each)" if "orientations_deg" in doc["map"] else "")),
        ("rules", rules_name), ("model", inputs.model.path.name), ("seed", s.seed),
        ("chains", f"{s.chains} on {s.cores} core(s)"),
        ("draws", f"{s.tune} burn-in + {s.draws} recorded per chain, {s.n_inner} kernels per draw"),
        ("sampling time", run.timing_text()),
        ("W* from chain", run.best_chain + 1), ("generator", f"semmap_pp {__version__}"),
    ] + ([("stopped early", getattr(run, "stopped"))] if getattr(run, "stopped", None) else [])
      + [("note", n) for n in run.notes])


def _world_summary(doc: dict, regions: dict, log_posterior: float, cpr: str, roi_name: str) -> str:
    """The page's W* table: units by type, regions, doors, passages, objects, log posterior, CPR."""
    counts = {t: sum(1 for u in doc["units"] if u["type"] == t) for t in UNIT_TYPES}
    return _kv([
        ("units", f"{len(doc['units'])} (" + ", ".join(f"{counts[t]} {t}" for t in UNIT_TYPES) + ")"),
        ("regions", len(set(regions.values()))), ("doors", len(doc["doors"])),
        ("passages", f"{len(doc.get('passages', []))} (open walls, and free floor between units that do "
                     "not touch)"), ("objects", len(doc["objects"])),
        ("unexplored areas", len(doc["unexplored"])),
        ("exterior units", f"{len(doc.get('exterior', []))} (free space seen outside the building; "
                           "not in the units, labels or graph)"),
        ("log posterior", f"{log_posterior:.2f}"),
        ("cell prediction rate", f"{cpr} over the region of interest “{roi_name}”"),
    ])


def write_report(path: str | os.PathLike, text: str) -> Path:
    atomic.write_text(path, text)
    return Path(path)


__all__ = ["FILES", "report_html", "calibration_section", "with_calibration", "spread_section", "failure_text", "posterior_marginals_section", "write_report", "units_table", "convergence_table", "data_uri"]
