"""world.geojson: W* as a GeoJSON FeatureCollection in the map's local metric frame.

GeoJSON (RFC 7946) assumes WGS84 longitude/latitude. A robot map has no geographic position, so the
coordinates here are metres in the ROS ``map`` frame of the input map (``origin`` is the image's
bottom-left corner), and the file says so in a top-level ``properties`` member (a foreign member that
readers keep or ignore): ``{"frame": "map", "units": "m", "crs": "local", ...}``. A GIS program will
still draw it, but as if the metres were degrees: do not combine it with geographic layers.

Features (``properties.kind`` says which; ``properties.id`` is the id of world.json):

- ``unit``: Polygon, one closed counter-clockwise ring (first vertex repeated last); ``type``, the
  type marginals ``p_room`` ... ``p_other``, ``length_m``, ``width_m``, ``area_m2``, ``region``
  (regions.png id), ``seen_share`` and ``walls_seen_share`` (as world.json), ``doors``,
  ``passages`` and ``objects`` (id lists).
- ``door``: LineString across the opening, from one end to the other; ``units``, ``width_m``.
- ``passage``: the same for an open stretch of a shared wall (world.json ``passages``).
- ``object``: Point at its centre; ``unit``, ``extent_m``, ``cells``.
- ``unexplored``: Point at its centre; ``area_m2``.
- ``exterior``: Polygon like a unit's (free space seen outside the building through its windows
  and exits, docs/model.md); ``length_m``, ``width_m``, ``area_m2``, ``units`` (the building's
  units it is adjacent to).
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np

from semmap_pp import atomic
from semmap_pp.cells import UNIT_TYPES
from semmap_pp.semantic.regions import unit_regions
from semmap_pp.semantic.world_json import world_dict

FORMAT = "semmap_pp.geojson/1"


def ring_area(ring) -> float:
    """Signed area of a closed or open ring of ``[x, y]`` (positive = counter-clockwise).

    >>> ring_area([[0, 0], [1, 0], [1, 1], [0, 1]])
    1.0
    """
    p = np.asarray(ring, float)
    x, y = p[:, 0], p[:, 1]
    return float(0.5 * (np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1))))


def closed_ccw(vertices) -> list[list[float]]:
    """A closed counter-clockwise ring (first vertex repeated last) of a polygon's vertices."""
    v = [list(map(float, p)) for p in vertices]
    if ring_area(v) < 0:
        v = v[::-1]
    return v + [v[0]]


def _point(xy) -> dict:
    return {"type": "Point", "coordinates": [float(xy[0]), float(xy[1])]}


def _feature(kind: str, fid: int, geometry: dict, props: dict) -> dict:
    return {"type": "Feature", "id": f"{kind}/{fid}", "geometry": geometry,
            "properties": {"kind": kind, "id": fid, **props}}


def geojson_dict(sm, doc: dict | None = None, regions: dict[int, int] | None = None) -> dict:
    """The GeoJSON of a semantic map.

    Parameters
    ----------
    sm : SemanticMap
    doc : dict, optional
        Its world.json content (:func:`~semmap_pp.semantic.world_json.world_dict`), so ids agree.
    regions : dict, optional
        Unit id -> region id (:func:`~semmap_pp.semantic.regions.unit_regions`).
    """
    doc = world_dict(sm) if doc is None else doc
    if regions is None:
        regions = unit_regions(sm)
    features = []
    for u in doc["units"]:
        length, width = u["size_m"]
        props = {"type": u["type"],
                 **{f"p_{t}": u["type_marginals"][t] for t in UNIT_TYPES},
                 "length_m": length, "width_m": width, "area_m2": round(length * width, 4),
                 "center": u["center_m"], "region": regions.get(u["id"]),
                 "seen_share": u["seen_share"], "walls_seen_share": u["walls_seen_share"],
                 "doors": u["doors"], "passages": u.get("passages", []), "objects": u["objects"]}
        geom = {"type": "Polygon", "coordinates": [closed_ccw(u["vertices_m"])]}
        features.append(_feature("unit", u["id"], geom, props))
    for kind, key in (("door", "doors"), ("passage", "passages")):
        for d in doc.get(key, []):
            ends = np.asarray(d["endpoints_px"], float)
            x, y = sm.frame.image_to_metres(ends[:, 0], ends[:, 1])
            line = [[round(float(a), 4), round(float(b), 4)] for a, b in zip(x, y)]
            features.append(_feature(kind, d["id"], {"type": "LineString", "coordinates": line},
                                     {"units": d["units"], "width_m": d["width_m"]}))
    for o in doc["objects"]:
        features.append(_feature("object", o["id"], _point(o["center_m"]),
                                 {"unit": o["unit"], "extent_m": o["extent_m"], "cells": o["cells"]}))
    for n in doc["unexplored"]:
        features.append(_feature("unexplored", n["id"], _point(n["center_m"]), {"area_m2": n["area_m2"]}))
    for e in doc.get("exterior", []):
        length, width = e["size_m"]
        features.append(_feature("exterior", e["id"], {"type": "Polygon",
                                                       "coordinates": [closed_ccw(e["vertices_m"])]},
                                 {"length_m": length, "width_m": width,
                                  "area_m2": round(length * width, 4), "units": e["units"]}))
    m = doc["map"]
    name = m["yaml"] or m["image"] or "map"
    return {
        "type": "FeatureCollection",
        "name": f"semantic map of {name}",
        "properties": {
            "format": FORMAT, "frame": "map", "units": "m", "crs": "local",
            "note": ("coordinates are metres in the ROS map frame of the input map "
                     "(origin = bottom-left image corner), not WGS84 longitude/latitude"),
            "map": {"image": m["image"], "yaml": m["yaml"], "resolution": m["resolution"],
                    "origin": m["origin"], "width": m["width"], "height": m["height"]},
            "adjacency": doc["adjacency"], "cpr": doc["cpr"], "log_posterior": doc["log_posterior"],
            "generator": doc["generator"],
        },
        "features": features,
    }


def write_geojson(path: str | os.PathLike, collection: dict) -> Path:
    """Write the FeatureCollection atomically (UTF-8, deterministic key order)."""
    atomic.write_text(path, json.dumps(collection, indent=1, ensure_ascii=False, allow_nan=False) + "\n")
    return Path(path)


__all__ = ["FORMAT", "ring_area", "closed_ccw", "geojson_dict", "write_geojson"]
