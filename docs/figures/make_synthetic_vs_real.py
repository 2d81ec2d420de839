"""Make docs/figures/synthetic_vs_real.png: three synthetic floors beside the real cartesium map.

All four maps are drawn in the same map_server greys (254 free, 205 unknown, 0 occupied) and at the
same scale (metres on the axes). Run from the repository root:

    .venv/bin/python docs/figures/make_synthetic_vs_real.py
"""

from __future__ import annotations

import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from semmap_pp.grid import classes_to_image, load_map  # noqa: E402
from semmap_pp.synth import generate_floor  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
OUT = ROOT / "docs" / "figures" / "synthetic_vs_real.png"
REAL = ROOT / "data" / "maps" / "ubremen-cartesium.yaml"
# (seed, units, rotation): a hall floor as drawn, a grid of corridors at the seed's own
# rotation, a corridor spine turned like the cartesium building
FLOORS = ((48, None, None), (49, None, None), (40, None, 20.0))


def main() -> int:
    panels = []
    for seed, units, rotation in FLOORS:
        f = generate_floor(seed, units=units, rotation_deg=rotation)
        t = f.truth
        panels.append((f.image, f.resolution,
                       f"synthetic: seed {seed}, {t['layout']}, {len(t['units'])} units, "
                       f"rotated {t['rotation_deg']:g}°"))
    real = load_map(REAL)
    panels.append((classes_to_image(real.classes), real.resolution,
                   "real: ubremen-cartesium (GMapping), same greys"))

    # one metre is the same length in every panel: panel sizes follow the maps' sizes in metres
    widths = [img.shape[1] * res for img, res, _ in panels]
    heights = [img.shape[0] * res for img, res, _ in panels]
    col_w = [max(widths[0], widths[2]), max(widths[1], widths[3])]
    row_h = [max(heights[0], heights[1]), max(heights[2], heights[3])]
    scale = 0.16  # inches per metre
    fig, axes = plt.subplots(2, 2, figsize=(scale * sum(col_w) + 1.0, scale * sum(row_h) + 1.2),
                             gridspec_kw={"width_ratios": col_w, "height_ratios": row_h})
    for ax, (img, res, title) in zip(axes.ravel(), panels):
        h, w = img.shape
        ax.imshow(img, cmap="gray", vmin=0, vmax=255, interpolation="nearest",
                  extent=(0, w * res, h * res, 0))
        ax.set_title(title, fontsize=10)
        ax.set_xlabel("m", fontsize=8)
        ax.tick_params(labelsize=7)
    fig.tight_layout()
    fig.savefig(OUT, dpi=110)
    print(f"wrote {OUT}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
