"""Make docs/figures/synthetic_wings.png: three synthetic floors of wings, their truth drawn over.

Two wings at 30°, two at 45°, three at angles drawn from the seed; each map in the map_server
greys (254 free, 205 unknown, 0 occupied), each true unit's outline (``corners_px``) in its wing's
colour, the link corridors in black, and the doors as dots. Run from the repository root:

    .venv/bin/python docs/figures/make_synthetic_wings.py
"""

from __future__ import annotations

import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from semmap_pp.synth import generate_floor  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
OUT = ROOT / "docs" / "figures" / "synthetic_wings.png"
# (seed, generate_floor arguments)
FLOORS = ((2, dict(wings=2, wing_angle_deg=30.0, rotation_deg=0.0)),
          (4, dict(wings=2, wing_angle_deg=45.0, rotation_deg=0.0)),
          (0, dict(wings=3, rotation_deg=0.0)))
COLOURS = {0: "black", 1: "tab:blue", 2: "tab:orange", 3: "tab:green"}


def main() -> int:
    floors = [(seed, generate_floor(seed, **kw)) for seed, kw in FLOORS]
    widths = [f.image.shape[1] * f.resolution for _, f in floors]
    height = max(f.image.shape[0] * f.resolution for _, f in floors)
    scale = 0.12  # inches per metre
    fig, axes = plt.subplots(1, len(floors), figsize=(scale * sum(widths) + 1.0, scale * height + 1.2),
                             gridspec_kw={"width_ratios": widths})
    for ax, (seed, f) in zip(axes, floors):
        t, res = f.truth, f.resolution
        h, w = f.image.shape
        ax.imshow(f.image, cmap="gray", vmin=0, vmax=255, interpolation="nearest",
                  extent=(0, w * res, h * res, 0))
        for u in t["units"]:
            c = np.asarray(u["corners_px"] + u["corners_px"][:1]) * res
            ax.plot(c[:, 0], c[:, 1], color=COLOURS[u["wing"]], lw=1.0)
        doors = np.asarray([d["center_px"] for d in t["doors"]]) * res
        ax.plot(doors[:, 0], doors[:, 1], ".", color="tab:red", ms=3)
        angles = ", ".join(f"{a['angle_deg']:g}°" for a in t["links"])
        ax.set_title(f"seed {seed}: {len(t['wings'])} wings ({t['layout']}), turned {angles}",
                     fontsize=9)
        ax.set_xlabel("m", fontsize=8)
        ax.tick_params(labelsize=7)
    fig.tight_layout()
    fig.savefig(OUT, dpi=100)
    print(f"wrote {OUT}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
