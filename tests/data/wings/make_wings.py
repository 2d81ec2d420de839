"""Draw the hand-made plans of tests/data/wings: buildings with a wing at another angle than the
main one, and fans of rays through windows outside them (issue 48).

    python tests/data/wings/make_wings.py      # rewrites wing30, wing45 and pentagon (.png, .yaml, _gt.png)

A plan is drawn at 0.05 m per cell from rectangles in each wing's own frame (metres): walls
(occupied) first, then floors, doors and windows (free), then the rays beyond the windows (free
lines ending in nothing). Everything else is unknown, as in a SLAM map of a building whose outside
the robot saw only through its windows. The main wing runs along the image axes; the second wing
joins the main corridor's east end at ``angle`` degrees.

``NAME_gt.png`` is each plan's room truth, as a room segmenter's truth is drawn: a 16-bit image,
one label per room on its free cells (the main and the second wing's corridor one room; a doorway
takes the room or corridor it lies in; the rays beyond the windows none), for
``bench/run.py quality --subset wings``.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from PIL import Image

RES = 0.05
T = 0.15                         # wall thickness, metres
HERE = Path(__file__).parent


def _local(shape, origin, angle_deg):
    """(u, v) metres of every cell centre in the frame at ``origin`` (x, y metres) turned by
    ``angle_deg`` (image y down: positive angles turn clockwise on screen)."""
    rows, cols = np.mgrid[0:shape[0], 0:shape[1]]
    x, y = (cols + 0.5) * RES - origin[0], (rows + 0.5) * RES - origin[1]
    a = math.radians(angle_deg)
    return x * math.cos(a) + y * math.sin(a), -x * math.sin(a) + y * math.cos(a)


def _box(uv, u0, v0, u1, v1):
    u, v = uv
    return (u >= u0) & (u < u1) & (v >= v0) & (v < v1)


def wing(uv, length, rooms, depth=5.0, width=2.0, room_from=0.0):
    """(walls, floors) masks of a corridor u in [0, length], |v| <= width / 2, with rooms of the
    widths ``rooms`` on both sides (from ``room_from`` on) and a 1 m door into each."""
    h = width / 2
    spaces = _spaces(length, rooms, depth, width, room_from)
    doors = []
    u = room_from
    for w in rooms:
        doors += [(u + w / 2 - 0.5, -h - T, u + w / 2 + 0.5, -h + T),
                  (u + w / 2 - 0.5, h - T, u + w / 2 + 0.5, h + T)]
        u += w
    walls = np.zeros(uv[0].shape, bool)
    floors = np.zeros(uv[0].shape, bool)
    for u0, v0, u1, v1 in spaces:
        walls |= _box(uv, u0 - T / 2, v0 - T / 2, u1 + T / 2, v1 + T / 2)
        floors |= _box(uv, u0 + T / 2, v0 + T / 2, u1 - T / 2, v1 - T / 2)
    for d in doors:
        floors |= _box(uv, *d)
    return walls, floors


def fan(c, x, y, heading_deg, spread_deg=70.0, length=8.0, rays=40):
    """Free rays from (x, y) metres spreading around ``heading_deg`` over unknown cells."""
    for a in np.linspace(heading_deg - spread_deg / 2, heading_deg + spread_deg / 2, rays):
        t = np.arange(0.0, length, RES / 2)
        cols = ((x + t * math.cos(math.radians(a))) / RES).astype(int)
        rows = ((y + t * math.sin(math.radians(a))) / RES).astype(int)
        ok = (rows >= 0) & (rows < c.shape[0]) & (cols >= 0) & (cols < c.shape[1])
        rows, cols = rows[ok], cols[ok]
        unknown = c[rows, cols] == 205
        c[rows[unknown], cols[unknown]] = 254


def _to_xy(origin, angle_deg, u, v):
    a = math.radians(angle_deg)
    return origin[0] + u * math.cos(a) - v * math.sin(a), origin[1] + u * math.sin(a) + v * math.cos(a)


def plan(angle: float) -> np.ndarray:
    """The plan with its second wing at ``angle`` degrees, as map_server grey values: a main
    wing (a 22 m corridor, five 4 x 5 m rooms on each side) and a second wing (an 18 m corridor,
    three 4.5 x 5 m rooms on each side) joined at the main corridor's east end."""
    shape = (int(42 / RES), int(50 / RES))
    o1, o2 = (4.0, 16.0), (4.0 + 22.0, 16.0)       # the corridors' west ends, on their centre lines
    main, other = _local(shape, o1, 0.0), _local(shape, o2, angle)
    w1, f1 = wing(main, 22.0, [4.0] * 5)
    w2, f2 = wing(other, 18.0, [4.5] * 3, room_from=4.5)
    joint = _box(main, 20.0, -1.6, 24.0, 1.6) | _box(other, -2.0, -1.6, 2.0, 1.6)
    c = np.full(shape, 205, np.uint8)
    c[w1 | w2 | joint] = 0
    c[f1 | f2 | _box(main, 20.0, -0.9, 23.0, 0.9) | _box(other, -1.0, -0.9, 2.0, 0.9)] = 254
    # windows with rays beyond them: the second north room of the main wing (its far wall
    # v = -6), the last room on the far side of the other wing (its far wall v = 6)
    c[_box(main, 5.5, -6.1, 6.5, -5.9)] = 254
    fan(c, *_to_xy(o1, 0.0, 6.0, -6.15), -90.0)
    u_w = 4.5 + 2 * 4.5 + 2.25
    c[_box(other, u_w - 0.5, 5.9, u_w + 0.5, 6.1)] = 254
    fan(c, *_to_xy(o2, angle, u_w, 6.15), angle + 90.0)
    return c


def pentagon() -> np.ndarray:
    """A pentagonal plan: a ring corridor (2 m wide, sides of 16 m) with three 4 x 5 m rooms on
    the outer side of each of its five sides, each side at its own angle, 72 degrees apart; a
    window with a fan of rays beyond it in one outer room."""
    shape = (int(44 / RES), int(44 / RES))
    centre, radius = np.array([22.0, 22.0]), 13.6           # the corridor's centre line corners
    corners = [centre + radius * np.array([math.cos(math.radians(-90 + 72 * k)),
                                            math.sin(math.radians(-90 + 72 * k))]) for k in range(5)]
    walls = np.zeros(shape, bool)
    floors = np.zeros(shape, bool)
    rows, cols = np.mgrid[0:shape[0], 0:shape[1]]
    x, y = (cols + 0.5) * RES, (rows + 0.5) * RES
    for k in range(5):
        a, b = corners[k], corners[(k + 1) % 5]
        angle = math.degrees(math.atan2(b[1] - a[1], b[0] - a[0]))
        length = float(np.hypot(*(b - a)))
        uv = _local(shape, tuple(a), angle)
        # rooms on the outer side (v < 0: the ring turns clockwise on screen, its outside is left)
        spaces = [(-1.0, -1.0, length + 1.0, 1.0)]
        doors = []
        u0 = (length - 12.0) / 2
        for i in range(3):
            spaces.append((u0 + 4 * i, -6.0, u0 + 4 * i + 4, -1.0))
            doors.append((u0 + 4 * i + 1.5, -1.0 - T, u0 + 4 * i + 2.5, -1.0 + T))
        for su0, sv0, su1, sv1 in spaces:
            walls |= _box(uv, su0 - T / 2, sv0 - T / 2, su1 + T / 2, sv1 + T / 2)
        for su0, sv0, su1, sv1 in spaces:
            floors |= _box(uv, su0 + T / 2, sv0 + T / 2, su1 - T / 2, sv1 - T / 2)
        for d in doors:
            floors |= _box(uv, *d)
        # the corner: a disc of corridor floor in its walls
        near = np.hypot(x - a[0], y - a[1])
        walls |= near <= 1.0 + T
        floors |= near <= 1.0 - T / 2
    c = np.full(shape, 205, np.uint8)
    c[walls] = 0
    c[floors] = 254
    # a window in the far wall of the middle room of the side from corner 0 to corner 1
    a, b = corners[0], corners[1]
    angle = math.degrees(math.atan2(b[1] - a[1], b[0] - a[0]))
    uv = _local(shape, tuple(a), angle)
    u_w = float(np.hypot(*(b - a))) / 2
    c[_box(uv, u_w - 0.5, -6.1, u_w + 0.5, -5.9)] = 254
    fan(c, *_to_xy(tuple(a), angle, u_w, -6.15), angle - 90.0)
    return c


def _spaces(length, rooms, depth=5.0, width=2.0, room_from=0.0):
    """The corridor and the rooms of :func:`wing` as ``(u0, v0, u1, v1)`` rectangles, metres."""
    h = width / 2
    spaces = [(0.0, -h, length, h)]
    u = room_from
    for w in rooms:
        spaces += [(u, -h - depth, u + w, -h), (u, h, u + w, h + depth)]
        u += w
    return spaces


def plan_truth(angle: float) -> np.ndarray:
    """(H, W) int32 room labels of :func:`plan`: the two corridors (and the joint) one room, label
    1; every room its own label."""
    shape = (int(42 / RES), int(50 / RES))
    o1, o2 = (4.0, 16.0), (4.0 + 22.0, 16.0)
    main, other = _local(shape, o1, 0.0), _local(shape, o2, angle)
    lab = np.zeros(shape, np.int32)
    lab[_box(main, 20.0, -0.9, 23.0, 0.9) | _box(other, -1.0, -0.9, 2.0, 0.9)] = 1
    k = 2
    for uv, spaces in ((main, _spaces(22.0, [4.0] * 5)), (other, _spaces(18.0, [4.5] * 3, room_from=4.5))):
        for i, (u0, v0, u1, v1) in enumerate(spaces):
            m = _box(uv, u0, v0, u1, v1) & (lab == 0)
            if i == 0:
                lab[m] = 1
            else:
                lab[m] = k
                k += 1
    return lab


def pentagon_truth() -> np.ndarray:
    """(H, W) int32 room labels of :func:`pentagon`: the ring corridor label 1, every room its own."""
    shape = (int(44 / RES), int(44 / RES))
    centre, radius = np.array([22.0, 22.0]), 13.6
    corners = [centre + radius * np.array([math.cos(math.radians(-90 + 72 * k)),
                                            math.sin(math.radians(-90 + 72 * k))]) for k in range(5)]
    lab = np.zeros(shape, np.int32)
    rows, cols = np.mgrid[0:shape[0], 0:shape[1]]
    x, y = (cols + 0.5) * RES, (rows + 0.5) * RES
    k = 2
    for s in range(5):
        a, b = corners[s], corners[(s + 1) % 5]
        angle = math.degrees(math.atan2(b[1] - a[1], b[0] - a[0]))
        length = float(np.hypot(*(b - a)))
        uv = _local(shape, tuple(a), angle)
        lab[_box(uv, -1.0, -1.0, length + 1.0, 1.0)] = 1
        u0 = (length - 12.0) / 2
        for i in range(3):
            lab[_box(uv, u0 + 4 * i, -6.0, u0 + 4 * i + 4, -1.0) & (lab == 0)] = k
            k += 1
        lab[np.hypot(x - a[0], y - a[1]) <= 1.0] = 1
    return lab


def truth_on_floor(labels: np.ndarray, grey: np.ndarray) -> np.ndarray:
    """``labels`` on the plan's free cells (grey 254), as a truth is drawn: the rays beyond the
    windows, in no room, are none."""
    return np.where((grey == 254) & (labels > 0), labels, 0).astype(np.uint16)


def write(name: str, grey: np.ndarray, truth: np.ndarray | None = None) -> None:
    Image.fromarray(grey).save(HERE / f"{name}.png", optimize=True)
    (HERE / f"{name}.yaml").write_text(
        f"image: {name}.png\nresolution: {RES}\norigin: [0.0, 0.0, 0.0]\nnegate: 0\n"
        "occupied_thresh: 0.65\nfree_thresh: 0.196\n")
    if truth is not None:
        Image.fromarray(truth_on_floor(truth, grey)).save(HERE / f"{name}_gt.png", optimize=True)


if __name__ == "__main__":
    for angle in (30, 45):
        write(f"wing{angle}", plan(float(angle)), plan_truth(float(angle)))
    write("pentagon", pentagon(), pentagon_truth())
