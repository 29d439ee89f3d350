"""Plot a knee example's results (docs/tutorial-knee.md).

    python examples/knee/plot_knee.py OUT_DIR [OUT_DIR_2 ...]    ->  OUT_DIR/knee.png

OUT_DIR is the output folder of ``openfdk run examples/knee/knee_*.yaml --out OUT_DIR``.
Three panels against knee flexion (deg): the quadriceps force (N), the two FDK knee
translations (mm, in the thigh's knee frame), and the quadriceps length (mm). Several
folders are drawn on the same axes (e.g. the springs and the contact version).
"""

from __future__ import annotations

import csv
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402


def read(out_dir):
    rows = list(csv.DictReader(open(Path(out_dir) / "forces.csv")))
    col = lambda k: np.array([float(r[k]) for r in rows])  # noqa: E731
    # the example drives flexion linearly from 0 to 90 deg over 1 s
    flexion = 90.0 * col("time")
    return flexion, col("quadriceps.force_N"), col("fdk.knee_x.alpha") * 1e3, col("fdk.knee_y.alpha") * 1e3, \
        col("quadriceps.length_m") * 1e3


def main(dirs):
    fig, ax = plt.subplots(1, 3, figsize=(12, 3.6))
    for d in dirs:
        flex, force, ax_mm, si_mm, length = read(d)
        label = Path(d).name
        ax[0].plot(flex, force, label=label)
        ax[1].plot(flex, ax_mm, label=f"{label}: x (anterior)")
        ax[1].plot(flex, si_mm, "--", label=f"{label}: y (proximal)")
        ax[2].plot(flex, length, label=label)
    ax[0].set(xlabel="knee flexion (deg)", ylabel="quadriceps force (N)")
    ax[1].set(xlabel="knee flexion (deg)", ylabel="knee translation α (mm)")
    ax[2].set(xlabel="knee flexion (deg)", ylabel="quadriceps length (mm)")
    for a in ax:
        a.grid(alpha=0.3)
        a.legend(fontsize=7)
    fig.tight_layout()
    target = Path(dirs[0]) / "knee.png"
    fig.savefig(target, dpi=120)
    print(target)


if __name__ == "__main__":
    if len(sys.argv) < 2:
        sys.exit("usage: python examples/knee/plot_knee.py OUT_DIR [OUT_DIR_2 ...]")
    main(sys.argv[1:])
