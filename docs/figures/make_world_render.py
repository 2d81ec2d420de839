"""Render a hand-placed world over the cartesium map (docs/figures/world_over_cartesium.png).

Colours as in the paper's Fig. 5c: black = occupied, blue = wall, gray = unknown, white = free,
cyan = door, green = object, magenta N = unexplored area; each unit is labelled with its type
(R room, C corridor, H hall, E other) and slot. The rectangles below were placed by hand on the
building lattice (θ0 ≈ -24°), then every side was moved to the best position of the posterior
within ±6 cells (coordinate ascent, 3 rounds), so the picture shows what the model makes of them.

Run: ``.venv/bin/python docs/figures/make_world_render.py``.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from semmap_pp import world as wm  # noqa: E402
from semmap_pp.atomic import atomic_path, write_text  # noqa: E402
from semmap_pp.cells import OCCUPIED, UNIT_TYPES, UNKNOWN, W_FREE, W_OBJECT, W_WALL  # noqa: E402
from semmap_pp.derive import derive_world  # noqa: E402
from semmap_pp.lattice.frame import build_frame  # noqa: E402
from semmap_pp.grid import load_map  # noqa: E402
from semmap_pp.model import load_model  # noqa: E402
from semmap_pp.target.posterior import Posterior  # noqa: E402

# (r0, c0, r1, c1) on the lattice, read off a gridded picture of the lattice map.
HAND_WORLD = [
    (532, 185, 570, 1280),   # the long corridor
    (452, 198, 537, 300), (452, 298, 537, 410), (452, 408, 537, 578), (452, 576, 537, 632),
    (452, 630, 537, 742), (452, 740, 537, 855), (452, 853, 537, 900),
    (565, 252, 628, 352), (565, 408, 670, 628), (668, 425, 752, 610), (665, 612, 752, 745),
    (562, 770, 630, 900), (562, 938, 630, 1055), (627, 740, 752, 1060), (627, 1058, 752, 1278),
]
SNAP, ROUNDS = 6, 3
LETTER = {"room": "R", "corridor": "C", "hall": "H", "other": "E"}
# colour indices of the render
C_FREE, C_UNKNOWN, C_OCC, C_WALL, C_DOOR, C_OBJECT = range(6)
PALETTE = np.array([[255, 255, 255], [160, 160, 160], [0, 0, 0], [40, 80, 230],
                    [0, 230, 230], [40, 180, 60]], np.uint8)


def snap(post, world):
    """Coordinate ascent on each side of each unit within ±SNAP cells."""
    tr = post.start(world)
    for _ in range(ROUNDS):
        for s in wm.active_slots(tr.world):
            for side in range(4):
                best, best_w = tr.logp, None
                for step in range(-SNAP, SNAP + 1):
                    if step == 0:
                        continue
                    r = tr.world.rects[s].copy()
                    r[side] += step
                    prop = tr.propose(wm.replace(tr.world, s, r), [s])
                    if prop.logp > best:
                        best, best_w = prop.logp, prop
                if best_w is not None:
                    tr.accept(best_w)
    return tr


def main() -> int:
    model = load_model()
    grid = load_map(ROOT / "data/maps/ubremen-cartesium.yaml")
    frame = build_frame(grid, model)
    post = Posterior(frame, model)
    world = wm.empty(model.prior.k_max)
    for s, rect in enumerate(HAND_WORLD):
        world = wm.add(world, s, rect)
    start = post.evaluate(world).total
    tr = snap(post, world)
    world = tr.world
    d = derive_world(frame, world)

    idx = np.full(frame.shape, C_FREE, np.uint8)
    idx[frame.classes == UNKNOWN] = C_UNKNOWN
    idx[frame.classes == OCCUPIED] = C_OCC
    inside = d.states != 3
    idx[inside & (d.states == W_FREE)] = C_FREE
    idx[d.states == W_OBJECT] = C_OBJECT
    idx[d.states == W_WALL] = C_WALL
    for door in d.doors:
        r0, c0, r1, c1 = door.box
        idx[r0:r1, c0:c1] = C_DOOR
    img = PALETTE[frame.to_image(idx, fill=C_UNKNOWN)]

    known = np.nonzero(grid.classes != UNKNOWN)
    y0, y1 = max(known[0].min() - 20, 0), min(known[0].max() + 20, grid.height)
    x0, x1 = max(known[1].min() - 20, 0), min(known[1].max() + 20, grid.width)
    fig, ax = plt.subplots(figsize=((x1 - x0) / 100, (y1 - y0) / 100), dpi=150)
    ax.imshow(img[y0:y1, x0:x1], extent=(x0 - 0.5, x1 - 0.5, y1 - 0.5, y0 - 0.5),
              interpolation="nearest")
    for s in d.slots:
        v = frame.rect_vertices_px(world.rects[s])
        cx, cy = v.mean(axis=0) - 0.5   # pixel frame -> imshow's centre-of-pixel coordinates
        t = UNIT_TYPES[world.types[s]]
        ax.text(cx, cy, f"{LETTER[t]}{s}", ha="center", va="center", fontsize=7,
                color="darkred", weight="bold")
    for a in d.unexplored:
        x, y = frame.lattice_to_image(*a.centroid)
        if x0 <= x < x1 and y0 <= y < y1:
            ax.text(x, y, "N", ha="center", va="center", fontsize=6, color="magenta", weight="bold")
    ax.set_axis_off()
    fig.tight_layout(pad=0)
    out = ROOT / "docs/figures/world_over_cartesium.png"
    with atomic_path(out) as tmp:
        fig.savefig(tmp, format="png")
    plt.close(fig)
    summary = {"theta_deg": float(np.degrees(frame.theta)), "units": len(d.slots),
               "log_posterior_hand": start, "log_posterior_snapped": tr.logp,
               "doors": len(d.doors), "objects": len(d.objects), "unexplored": len(d.unexplored),
               "adjacent_pairs": int(np.triu(d.adjacency, 1).sum()),
               "types": {int(s): UNIT_TYPES[world.types[s]] for s in d.slots},
               "rects": {int(s): world.rects[s].tolist() for s in d.slots}}
    write_text(ROOT / "docs/figures/world_over_cartesium.json", json.dumps(summary, indent=1) + "\n")
    print(json.dumps({k: v for k, v in summary.items() if k != "rects"}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
