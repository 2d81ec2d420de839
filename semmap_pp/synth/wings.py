"""Floors of several wings: each wing a plan in its own building frame, turned by an angle against
the wing before it and joined to it by a link corridor with a door at each end.

Every part of such a floor (a wing or a link) is a :class:`~semmap_pp.synth.topology.FloorPlan`
in its own frame with a *site transform* ``site = R(angle) (x, y) + shift`` (``R`` as in
:class:`~semmap_pp.synth.render.Placement`); the site frame is the first wing's frame. A link is a
one-unit corridor plan drawn along the outward normal of an exterior wall of wing ``k`` and cut
off at the exterior wall of wing ``k + 1``, which is turned by the wing angle against the wall it
leaves: the link's true outline is a trapezoid whose far side lies on the second wing's wall.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from semmap_pp.synth.layout import cells
from semmap_pp.synth.params import SynthParams
from semmap_pp.synth.render import Placement, lookup, resample
from semmap_pp.synth.topology import FloorPlan, exterior_intervals
from semmap_pp.synth.truth import _pt, _r

MAX_WINGS = 4
_DIRS = {(1, 0): 0.0, (0, -1): 90.0, (-1, 0): 180.0, (0, 1): 270.0}   # R(angle) (1, 0) = key


@dataclass
class Part:
    """One wing or link: its plan, the openings cut for the joints, and its site transform."""

    plan: FloorPlan
    angle: float                  # degrees, counter-clockwise as displayed
    shift: tuple                  # (x, y) in site cells
    kind: str = "wing"            # "wing" or "link"
    wing: int = 0                 # wing number (1-based); for a link the wing it leaves
    cuts: list = None             # extra (unit, orient, coord, s0, s1) openings drawn in its walls
    polygon: np.ndarray = None    # a link's true outline in its own frame (4 x 2)
    joint: dict = None            # a link's ends: units joined, door centres, door width

    def site(self, xy) -> np.ndarray:
        """Site coordinates of points in the part's frame."""
        return Placement(self.angle, *self.shift).apply(xy)

    def drawn(self) -> FloorPlan:
        """The plan with the joints' openings as exits (what is rasterised)."""
        return replace(self.plan, exits=list(self.plan.exits) + list(self.cuts or []))


def rot(deg: float) -> np.ndarray:
    """The matrix of :class:`Placement` for ``deg``."""
    return Placement(deg, 0.0, 0.0).matrix()


def _segments(plan: FloorPlan, need: int) -> list:
    """Exterior wall pieces at least ``need`` cells long: (prefer, unit, orient, coord, s0, s1,
    outward normal); corridors and halls first, then entered rooms, longest first."""
    rects = plan.rects.tolist()
    out = []
    for i in range(len(rects)):
        if not plan.entered[i]:
            continue
        x0, y0, x1, y1 = rects[i]
        for o, c, s0, s1 in exterior_intervals(rects, plan.shared, i):
            if s1 - s0 < need:
                continue
            normal = ((-1, 0) if c == x0 else (1, 0)) if o == "v" else ((0, -1) if c == y0 else (0, 1))
            prefer = 0 if plan.types[i] in ("corridor", "hall") else 1
            out.append((prefer, i, o, c, s0, s1, normal))
    out.sort(key=lambda s: (s[0], -(s[5] - s[4]), s[1], s[2], s[3], s[4]))
    return out


def _point(o: str, c: float, s: float) -> np.ndarray:
    return np.array([c, s], float) if o == "v" else np.array([s, c], float)


def polygon_of(rect, pad: float = 0.0) -> np.ndarray:
    x0, y0, x1, y1 = (float(v) for v in rect)
    return np.array([[x0 - pad, y0 - pad], [x1 + pad, y0 - pad], [x1 + pad, y1 + pad],
                     [x0 - pad, y1 + pad]])


def overlap(a: np.ndarray, b: np.ndarray) -> bool:
    """Whether two convex polygons overlap with positive area (separating axes).

    >>> sq = polygon_of([0, 0, 2, 2])
    >>> diamond = sq @ rot(45.0).T                    # corners (0, 0), (1.41, -1.41), ...
    >>> overlap(sq, sq + 1.0), overlap(sq, sq + 2.0), overlap(sq, diamond + 1.0)
    (True, False, True)
    >>> overlap(sq, diamond + [1.5, 2.9])            # bounding boxes overlap, the shapes do not
    False
    """
    for poly in (a, b):
        edges = np.roll(poly, -1, axis=0) - poly
        for nx, ny in np.stack([-edges[:, 1], edges[:, 0]], 1):
            pa, pb = a @ (nx, ny), b @ (nx, ny)
            if pa.max() <= pb.min() + 1e-9 or pb.max() <= pa.min() + 1e-9:
                return False
    return True


def _clashes(polys: list, others: list) -> bool:
    return any(overlap(p, q) for p in polys for q in others)


def _crossing(S, n, t, half: float, M, w) -> list:
    """Where the two sides ``S +- half t + l n`` of a link meet the wall line ``M + m w``:
    ``[(l, point)]`` for the side at ``-half`` and at ``+half``."""
    out = []
    for sign in (-1.0, 1.0):
        a = np.array([n, -w]).T
        lam, _ = np.linalg.solve(a, M - (S + sign * half * t))
        out.append((float(lam), S + sign * half * t + lam * n))
    return out


def join(rng: np.random.Generator, a: Part, plan_b: FloorPlan, alpha: float, placed: list,
         p: SynthParams, res: float, wing_b: int):
    """Place ``plan_b`` turned by ``alpha`` against ``a`` and a link corridor between them.

    Returns ``(wing part, link part)``, or ``None`` when no pair of exterior walls gives a link
    that clears ``placed`` (site polygons of every unit placed so far, padded).
    """
    margin = cells(p.door_margin, res)
    wall = cells(p.wall_outer_max, res) + 1
    cos_a = abs(float(np.cos(np.deg2rad(alpha))))
    narrow = cells(p.door_min, res) + 2 * margin
    seg_a, seg_b = _segments(a.plan, narrow + 2), _segments(plan_b, int(np.ceil(narrow / cos_a)) + 2)
    pairs = [(x, y) for x in seg_a[:12] for y in seg_b[:12]]
    draw = rng.random(len(pairs))          # corridors and halls joined first, else at random
    order = sorted(range(len(pairs)), key=lambda j: (pairs[j][0][0] + pairs[j][1][0], draw[j]))
    for k in order[:40]:
        sa, sb = pairs[k]
        got = _try_pair(rng, a, plan_b, alpha, sa, sb, placed, p, res, margin, wall, cos_a, wing_b)
        if got is not None:
            return got
    return None


def _try_pair(rng, a: Part, plan_b, alpha, sa, sb, placed, p, res, margin, wall, cos_a, wing_b):
    _, ia, oa, ca, a0, a1, na = sa
    _, ib, ob, cb, b0, b1, nb = sb
    width_max = min(a1 - a0 - 2 * margin, int((b1 - b0 - 2 * margin) * cos_a))
    drawn = cells(rng.uniform(p.corridor_width_min, p.corridor_width_max), res)
    wl = 2 * (min(drawn, width_max) // 2)
    door = cells(rng.uniform(p.door_min, p.door_max), res)
    door = min(door, wl - 2 * margin)
    if door < cells(p.door_min, res):
        return None
    s_a = int(np.floor(rng.uniform(a0 + margin + wl / 2, a1 - margin - wl / 2 + 1)))
    span_b = wl / cos_a
    lo_b, hi_b = b0 + margin + span_b / 2, b1 - margin - span_b / 2
    s_b = float(np.floor(rng.uniform(lo_b, max(lo_b, hi_b) + 1e-9))) if hi_b > lo_b else (b0 + b1) / 2
    n = np.array(na, float)
    t = np.array([-n[1], n[0]])
    S = _point(oa, ca, s_a)                               # in a's frame
    phi = (alpha + _DIRS[(-na[0], -na[1])] - _DIRS[nb]) % 360.0
    w = rot(alpha) @ t                                    # b's wall direction in a's frame
    c_b = _point(ob, cb, s_b)
    link_min = cells(2.0, res)
    for length in range(link_min, cells(60.0, res), cells(1.0, res)):
        M = S + length * n
        sides = _crossing(S, n, t, wl / 2, M, w)
        if min(lam for lam, _ in sides) < link_min:
            continue
        u = M - rot(phi) @ c_b
        wing = Part(plan_b, (a.angle + phi) % 360.0, tuple(a.site([u])[0]), "wing", wing_b)
        quad = np.array([S - wl / 2 * t, S + wl / 2 * t, sides[1][1], sides[0][1]])
        # the link 0.5 m short of both walls: each end pulled back along the link's sides
        inner = quad + 0.0
        inner[:2] += cells(0.5, res) * n
        inner[2:] -= cells(0.5, res) * n
        mine = [wing.site(polygon_of(r, wall)) for r in plan_b.rects.tolist()]
        if _clashes(mine, placed) or _clashes([a.site(inner)], placed + [
                m for j, m in enumerate(mine) if j != ib]):
            continue
        reach = int(np.ceil(max(lam for lam, _ in sides))) + 2
        link = _link(a, S, n, wl, reach, quad, p, res, rng)
        a.cuts = (a.cuts or []) + [(ia, oa, ca, s_a - door // 2, s_a - door // 2 + door)]
        wing.cuts = [(ib, ob, cb, int(s_b) - door // 2, int(s_b) - door // 2 + door)]
        link.wing = a.wing
        link.joint = dict(units=(ia, ib), doors=(_point(oa, ca, s_a - door // 2 + door / 2),
                                                 _point(ob, cb, int(s_b) - door // 2 + door / 2)),
                          door_width=door, wall=(M, w, n))
        return wing, link
    return None


def _link(a: Part, S, n, wl: int, reach: int, quad, p: SynthParams, res: float, rng) -> Part:
    """The link corridor: a rectangle ``[0, reach] x [-wl/2, wl/2]`` along ``n`` from ``S`` (in
    ``a``'s frame), walls along both sides, entered by the robot."""
    half = wl // 2
    t_out = cells(rng.uniform(p.wall_outer_min, p.wall_outer_max), res)
    plan = FloorPlan(rects=np.array([[0, -half, reach, half]], dtype=np.int64), types=["corridor"],
                     layout="link", open_pairs=[], l_pairs=[], shared={}, doors=[],
                     walls=[("h", -half, 0, reach, t_out), ("h", half, 0, reach, t_out)],
                     windows=[], exits=[], explored=np.ones(1, bool), entered=np.ones(1, bool))
    d = _DIRS[(int(n[0]), int(n[1]))]
    polygon = Placement(d, float(S[0]), float(S[1])).invert(quad)
    return Part(plan, (a.angle + d) % 360.0, tuple(a.site([S])[0]), "link", polygon=polygon)


def clip_link(part: Part, labels: np.ndarray, solid: np.ndarray, glass: np.ndarray, offset) -> None:
    """Cut a link's rasters (its frame) at its far wall: nothing of it lies beyond the far side
    of its true outline, which is on the next wing's wall centre line."""
    q = part.polygon
    far0, far1 = q[3], q[2]
    edge = far1 - far0
    inward = np.array([-edge[1], edge[0]])
    if np.dot(q[0] - far0, inward) < 0:
        inward = -inward                       # points back towards the link's start
    ox, oy = offset
    rows, cols = np.mgrid[0:labels.shape[0], 0:labels.shape[1]]
    x, y = cols + ox + 0.5, rows + oy + 0.5
    beyond = (x - far0[0]) * inward[0] + (y - far0[1]) * inward[1] < 0
    labels[beyond] = 0
    solid[beyond] = False
    glass[beyond] = False


def compose(parts: list, rasters: list, rotation_deg: float, margin: int):
    """The image of every part turned by ``rotation_deg``: ``(placements, shape, layers)``.

    ``rasters[k]`` is ``(BuildingRasters, solid)`` of ``parts[k]``; ``placements[k]`` maps the
    part's frame into the image. Links are laid first, wings over them, so a wing's walls close a
    link's ends. ``layers`` holds ``owner`` (part index, -1 none), ``labels`` (the part's own unit
    index + 1), ``solid``, ``glass`` and ``inside``.
    """
    g = rot(rotation_deg)
    pts = []
    for part, (br, _) in zip(parts, rasters):
        ox, oy = br.offset
        hb, wb = br.solid.shape
        box = np.array([[ox, oy], [ox + wb, oy], [ox + wb, oy + hb], [ox, oy + hb]], float)
        pts.append(part.site(box) @ g.T)
    pts = np.concatenate(pts)
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    shift = np.array([margin - np.floor(lo[0]), margin - np.floor(lo[1])])
    shape = (int(np.ceil(hi[1]) - np.floor(lo[1])) + 2 * margin,
             int(np.ceil(hi[0]) - np.floor(lo[0])) + 2 * margin)
    placements = []
    for part in parts:
        t = g @ np.asarray(part.shift, float) + shift
        placements.append(Placement((rotation_deg + part.angle) % 360.0, float(t[0]), float(t[1])))
    owner = np.full(shape, -1, np.int32)
    labels = np.zeros(shape, np.uint16)
    solid = np.zeros(shape, bool)
    glass = np.zeros(shape, bool)
    order = [k for k, q in enumerate(parts) if q.kind == "link"] + \
            [k for k, q in enumerate(parts) if q.kind == "wing"]
    for k in order:
        br, solid_k = rasters[k]
        index = lookup(br, placements[k], shape)
        lab = resample(br.labels, index, fill=0)
        mine = lab > 0
        owner[mine] = k
        labels[mine] = lab[mine]
        solid[mine] = resample(solid_k, index, fill=False)[mine]
        glass[mine] = resample(br.glass, index, fill=False)[mine]
    return placements, shape, {"owner": owner, "labels": labels, "solid": solid, "glass": glass,
                               "inside": owner >= 0}


def unit_ids(parts: list) -> list:
    """Offset of each part's unit ids: the wings' units first (wing by wing), then the links."""
    offsets, n = [0] * len(parts), 0
    for kind in ("wing", "link"):
        for k, q in enumerate(parts):
            if q.kind == kind:
                offsets[k] = n
                n += len(q.plan.rects)
    return offsets


def wings_truth(parts: list, placements: list, alphas: list, base: dict, wing_docs: list) -> dict:
    """The ``truth.json`` document of a floor of wings.

    ``wing_docs[k]`` is :func:`~semmap_pp.synth.truth.build_truth` of part ``k`` (``None`` for a
    link) and ``base`` holds the top-level fields. Ids are renumbered (:func:`unit_ids`); every unit
    gains ``wing`` and ``orientation_deg``; the links' units, doors and adjacency are added.
    """
    offsets = unit_ids(parts)
    units, doors, exits, adjacency, open_b, l_sh, wings, links = [], [], [], [], [], [], [], []
    wing_part = {q.wing: k for k, q in enumerate(parts) if q.kind == "wing"}
    for k, (q, doc) in enumerate(zip(parts, wing_docs)):
        if q.kind != "wing":
            continue
        off = offsets[k]
        ids = []
        for u in doc["units"]:
            units.append(dict(u, id=u["id"] + off, wing=q.wing,
                              orientation_deg=_r(placements[k].rotation_deg)))
            ids.append(u["id"] + off)
        doors += [dict(d, units=[v + off for v in d["units"]]) for d in doc["doors"]]
        exits += [dict(e, unit=e["unit"] + off) for e in doc["exits"]]
        for src, dst in ((doc["adjacency"], adjacency), (doc["open_boundaries"], open_b),
                         (doc["l_shapes"], l_sh)):
            dst += [[a + off, b + off] for a, b in src]
        wings.append({"wing": q.wing, "layout": doc["layout"],
                      "orientation_deg": _r(placements[k].rotation_deg), "units": ids})
    for k, q in enumerate(parts):
        if q.kind != "link":
            continue
        lid = offsets[k] + 1
        ka, kb = wing_part[q.wing], wing_part[q.wing + 1]
        corners = placements[k].apply(q.polygon)
        sides = np.linalg.norm(q.polygon[3] - q.polygon[0]), np.linalg.norm(q.polygon[2] - q.polygon[1])
        width = np.linalg.norm(q.polygon[1] - q.polygon[0])
        res = base["resolution"]
        units.append({"id": lid, "type": "corridor", "corners_px": [_pt(c) for c in corners],
                      "center_px": _pt(corners.mean(axis=0)),
                      "size_m": [_r(max(np.mean(sides), width) * res), _r(min(np.mean(sides), width) * res)],
                      "explored": True, "entered": True, "wing": 0,
                      "orientation_deg": _r(placements[k].rotation_deg)})
        ends = ((ka, q.joint["units"][0], q.joint["doors"][0]), (kb, q.joint["units"][1], q.joint["doors"][1]))
        for kw, unit, centre in ends:
            other = offsets[kw] + unit + 1
            doors.append({"units": sorted([other, lid]), "center_px": _pt(placements[kw].apply([centre])[0]),
                          "width_m": _r(q.joint["door_width"] * res), "open": True})
            adjacency.append(sorted([other, lid]))
        links.append({"unit": lid, "wings": [q.wing, q.wing + 1], "angle_deg": _r(alphas[q.wing - 1])})
    return dict(base, units=units, doors=doors, exits=exits, adjacency=sorted(adjacency),
                open_boundaries=sorted(open_b), l_shapes=sorted(l_sh), wings=wings, links=links)
