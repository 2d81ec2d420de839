"""Render W* of the quality benchmark over its input map (docs/figures/quality_<map>.png).

Reads the ``world.json`` that ``python bench/run.py quality --subset real --save DIR`` wrote for each
real map (``DIR/<map>/world.json``) and draws every unit's rectangle in the input image frame over
the map (white free, grey unknown, black occupied), coloured by type (R room red, C corridor blue,
H hall green, E other orange), with the doors as cyan dots.

Run: ``.venv/bin/python docs/figures/make_quality_figures.py DIR``.
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

from semmap_pp.atomic import atomic_path  # noqa: E402
from semmap_pp.cells import FREE, OCCUPIED  # noqa: E402
from semmap_pp.grid import load_map  # noqa: E402

COLOURS = {"room": "tab:red", "corridor": "tab:blue", "hall": "tab:green", "other": "tab:orange"}
LETTER = {"room": "R", "corridor": "C", "hall": "H", "other": "E"}


def render(map_yaml: Path, world: dict, out: Path, title: str) -> None:
    grid = load_map(map_yaml)
    img = np.full(grid.shape, 200, np.uint8)
    img[grid.classes == FREE] = 255
    img[grid.classes == OCCUPIED] = 0
    h, w = grid.shape
    fig, ax = plt.subplots(figsize=(12, 12 * h / w + 0.6))
    ax.imshow(img, cmap="gray", vmin=0, vmax=255, interpolation="nearest")
    for u in world["units"]:
        v = np.asarray(u["vertices_px"], float)
        v = np.vstack([v, v[:1]])
        c = COLOURS.get(u.get("type"), "k")
        ax.plot(v[:, 0], v[:, 1], "-", color=c, lw=1.2)
        ax.text(v[:-1, 0].mean(), v[:-1, 1].mean(), LETTER.get(u.get("type"), "?") + str(u["id"]),
                color=c, fontsize=6, ha="center", va="center")
    for d in world.get("doors", []):
        x, y = d["center_px"]
        ax.plot([x], [y], "o", color="c", ms=3)
    ax.set_title(title, fontsize=9)
    ax.axis("off")
    fig.tight_layout()
    with atomic_path(out) as tmp:
        fig.savefig(tmp, dpi=90, format="png")
    plt.close(fig)


def main(save_dir: str) -> None:
    for name in ("ubremen-cartesium", "intel-lab"):
        wj = Path(save_dir) / name / "world.json"
        if not wj.exists():
            print(f"{wj}: missing, skipped")
            continue
        world = json.loads(wj.read_text())
        n = len(world["units"])
        render(ROOT / "data" / "maps" / f"{name}.yaml", world, ROOT / "docs" / "figures" / f"quality_{name}.png",
               f"W* on {name}: {n} units (model defaults; R room, C corridor, H hall, E other; cyan: doors)")
        print(f"docs/figures/quality_{name}.png")


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else "out/quality")
