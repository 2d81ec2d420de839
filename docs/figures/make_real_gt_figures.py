"""docs/figures/real_gt_<map>.png: for each floor of bench/data/real-gt, the hand-drawn truth,
ROSE2's published output and semmap_pp's rooms.png side by side, each with its ROSE2-protocol
precision / recall (semmap_pp.evaluate.protocol_scores).

    python docs/figures/make_real_gt_figures.py RUNS

RUNS holds one `semmap map` output folder per floor, named as the floor
(`semmap map bench/data/real-gt/NAME/map.yaml --out RUNS/NAME`).
"""

import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from semmap_pp.evaluate import protocol_scores, read_segmentation, read_segmentation_truth  # noqa: E402
from semmap_pp.evaluate.io import read_image  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
DATA = ROOT / "bench" / "data" / "real-gt"


def coloured(labels: np.ndarray) -> np.ndarray:
    rng = np.random.default_rng(7)
    palette = rng.integers(70, 250, (int(labels.max()) + 1, 3)).astype(np.uint8)
    palette[0] = 0
    return palette[labels]


def main(runs: Path) -> None:
    for folder in sorted(p for p in DATA.iterdir() if (p / "gt.png").is_file()):
        gt = read_segmentation_truth(folder / "gt.png", "rose2")
        rose2 = read_segmentation(folder / "rose2.png")
        ours = read_segmentation(runs / folder.name / "rooms.png")
        panels = [("truth", np.asarray(read_image(folder / "gt.png"))[..., :3], None),
                  ("ROSE2", np.asarray(read_image(folder / "rose2.png"))[..., :3], protocol_scores(gt, rose2)),
                  ("semmap_pp rooms.png", coloured(ours), protocol_scores(gt, ours))]
        ys, xs = np.nonzero(gt > 0)
        box = (slice(max(ys.min() - 10, 0), ys.max() + 10), slice(max(xs.min() - 10, 0), xs.max() + 10))
        h, w = gt[box].shape
        fig, axes = plt.subplots(1, 3, figsize=(12, 12 * h / w / 3 + 0.6))
        for ax, (title, img, s) in zip(axes, panels):
            ax.imshow(img[box], interpolation="nearest")
            ax.set_title(title if s is None else f"{title}: P {100 * s.precision:.1f} / R {100 * s.recall:.1f}",
                         fontsize=10)
            ax.axis("off")
        fig.tight_layout()
        fig.savefig(ROOT / "docs" / "figures" / f"real_gt_{folder.name}.png", dpi=110)
        plt.close(fig)


if __name__ == "__main__":
    main(Path(sys.argv[1]))
