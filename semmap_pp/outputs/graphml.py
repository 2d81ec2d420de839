"""graph.graphml: the abstract model of W* (paper Fig. 5b) as a graph for networkx, Gephi or yEd.

Nodes (``kind`` says which; ``id`` is the id of world.json):

- ``u<id>`` unit: ``type``, ``label`` (R/C/H/E + id), ``p_room`` ... ``p_other``, ``length_m``,
  ``width_m``, ``area_m2``, ``region``, ``seen_share`` and ``walls_seen_share`` (as world.json),
  centre ``x_m, y_m`` (map frame) and ``x_px, y_px`` (image).
- ``o<id>`` object: ``unit``, ``extent_m``, ``cells``, centre.
- ``n<id>`` unexplored area: ``area_m2``, centre.
- ``x<id>`` exterior unit (free space seen outside the building, docs/model.md): ``label`` (X +
  id), ``length_m``, ``width_m``, ``area_m2``, centre.

Edges (``relation``): ``door`` between units connected by one or more doors (``doors``: their ids,
comma-separated; ``n_doors``; ``width_m`` of the widest), ``adjacent`` between units adjacent
without a door (on both, ``passage``: True when the wall between them is open, see
:mod:`semmap_pp.semantic.regions`), ``passage`` between units that do not touch but face each other
across a strip of free floor (world.json's passages; ``passage`` True), ``contains`` from a unit to each of its objects, and ``next_to``
from an unexplored area to every unit whose rectangle its bounding box touches (grown by the
adjacency dilation) and from an exterior unit to every unit it is adjacent to. GraphML holds scalars only, so id lists are comma-separated strings.
"""

from __future__ import annotations

import io
import os
from pathlib import Path

import networkx as nx
import numpy as np

from semmap_pp import atomic
from semmap_pp.cells import TYPE_LETTER, UNIT_TYPES
from semmap_pp.semantic.regions import join_regions, passage_pairs, unit_pairs
from semmap_pp.semantic.world_json import world_dict


def _ids(values) -> str:
    return ",".join(str(int(v)) for v in values)


def _centre_px(vertices_px) -> tuple[float, float]:
    x, y = np.asarray(vertices_px, float).mean(axis=0)
    return round(float(x), 3), round(float(y), 3)


def unexplored_neighbours(sm) -> dict[int, list[int]]:
    """Unexplored-area id -> unit ids whose rectangle its bounding box touches.

    The box is grown by the adjacency dilation plus one cell (an unexplored area lies outside every
    unit, so it touches a unit at best one cell away). Ids follow world.json (areas sorted by box).
    """
    d, c = sm.derived, sm.frame.cells
    grow = int(c.adjacency_dilation) + 1
    out = {}
    for i, un in enumerate(sorted(d.unexplored, key=lambda o: o.box), 1):
        r0, c0, r1, c1 = un.box
        near = []
        for s, uid in sm.slot_ids.items():
            a0, b0, a1, b1 = (int(v) for v in sm.world.rects[s])
            if r0 - grow < a1 and a0 < r1 + grow and c0 - grow < b1 and b0 < c1 + grow:
                near.append(uid)
        out[i] = sorted(near)
    return out


def world_graph(sm, doc: dict | None = None, regions: dict[int, int] | None = None,
                passages=None) -> nx.Graph:
    """The abstract model of a semantic map as an undirected networkx graph.

    Parameters
    ----------
    sm : SemanticMap
    doc : dict, optional
        Its world.json content, so ids agree (computed when omitted).
    regions : dict, optional
        Unit id -> region id; ``passages`` the unit-id pairs with an open wall
        (:mod:`semmap_pp.semantic.regions`; computed when omitted).
    """

    doc = world_dict(sm) if doc is None else doc
    passages = set(map(tuple, passage_pairs(sm) if passages is None else passages))
    regions = join_regions(sm.unit_ids, passages) if regions is None else regions
    g = nx.Graph(name=f"semantic map of {doc['map']['yaml'] or doc['map']['image'] or 'map'}",
                 frame="map", units="m")
    for u in doc["units"]:
        x, y = _centre_px(u["vertices_px"])
        length, width = u["size_m"]
        g.add_node(f"u{u['id']}", kind="unit", id=u["id"], type=u["type"],
                   label=f"{TYPE_LETTER[u['type']]}{u['id']}",
                   **{f"p_{t}": float(u["type_marginals"][t]) for t in UNIT_TYPES},
                   length_m=float(length), width_m=float(width), area_m2=round(length * width, 4),
                   region=int(regions.get(u["id"], 0)), seen_share=float(u["seen_share"]),
                   walls_seen_share=float(u["walls_seen_share"]), x_m=float(u["center_m"][0]),
                   y_m=float(u["center_m"][1]), x_px=x, y_px=y)
    for o in doc["objects"]:
        g.add_node(f"o{o['id']}", kind="object", id=o["id"], unit=o["unit"], extent_m=float(o["extent_m"]),
                   cells=int(o["cells"]), x_m=float(o["center_m"][0]), y_m=float(o["center_m"][1]),
                   x_px=float(o["center_px"][0]), y_px=float(o["center_px"][1]))
        g.add_edge(f"u{o['unit']}", f"o{o['id']}", relation="contains")
    for n in doc["unexplored"]:
        g.add_node(f"n{n['id']}", kind="unexplored", id=n["id"], label=f"N{n['id']}",
                   area_m2=float(n["area_m2"]), x_m=float(n["center_m"][0]), y_m=float(n["center_m"][1]),
                   x_px=float(n["center_px"][0]), y_px=float(n["center_px"][1]))
    for nid, units in unexplored_neighbours(sm).items():
        for uid in units:
            g.add_edge(f"n{nid}", f"u{uid}", relation="next_to")
    for e in doc.get("exterior", []):
        x, y = _centre_px(e["vertices_px"])
        length, width = e["size_m"]
        g.add_node(f"x{e['id']}", kind="exterior", id=e["id"], label=f"X{e['id']}",
                   length_m=float(length), width_m=float(width), area_m2=round(length * width, 4),
                   x_m=float(e["center_m"][0]), y_m=float(e["center_m"][1]), x_px=x, y_px=y)
        for uid in e["units"]:
            g.add_edge(f"x{e['id']}", f"u{uid}", relation="next_to")
    doors_of: dict[tuple, list] = {}
    for d in doc["doors"]:
        doors_of.setdefault(tuple(d["units"]), []).append(d)
    for a, b in doc["adjacency"]:
        ds = doors_of.get((a, b), [])
        if ds:
            g.add_edge(f"u{a}", f"u{b}", relation="door", doors=_ids(d["id"] for d in ds), n_doors=len(ds),
                       width_m=max(float(d["width_m"]) for d in ds), passage=(a, b) in passages)
        else:
            g.add_edge(f"u{a}", f"u{b}", relation="adjacent", passage=(a, b) in passages)
    for a, b in unit_pairs(sm, sm.derived.gap_passages):   # across free floor: never adjacent
        g.add_edge(f"u{a}", f"u{b}", relation="passage", passage=True)
    return g


def write_graphml(path: str | os.PathLike, graph: nx.Graph) -> Path:
    """Write ``graph`` as GraphML atomically (made in memory, then :func:`semmap_pp.atomic.write_bytes`)."""
    buf = io.BytesIO()
    nx.write_graphml(graph, buf, encoding="utf-8", prettyprint=True)
    atomic.write_bytes(path, buf.getvalue())
    return Path(path)


__all__ = ["unexplored_neighbours", "world_graph", "write_graphml"]
