"""The figure of docs/tutorial-arm26.md: Arm26's six muscle forces, openfdk against OpenSim.

    python docs/scripts/arm26_forces.py RUN_DIR OPENSIM_FORCE_STO OUT.png

RUN_DIR: an ``openfdk run`` folder (its forces.csv); OPENSIM_FORCE_STO: the
``*_StaticOptimization_force.sto`` of OpenSim's AnalyzeTool on the same motion. Prints the
largest and RMS difference per muscle (N) and writes the PNG.
"""

import csv
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from openfdk.io.storage import read_storage  # noqa: E402

MUSCLES = ("TRIlong", "TRIlat", "TRImed", "BIClong", "BICshort", "BRA")


def main(run_dir, sto_path, png):
    rows = list(csv.DictReader(open(f"{run_dir}/forces.csv")))
    t = np.array([float(r["time"]) for r in rows])
    ours = {m: np.array([float(r[f"{m}.force_N"]) for r in rows]) for m in MUSCLES}
    time, theirs, _ = read_storage(sto_path)
    theirs["time"] = time
    fig, axes = plt.subplots(2, 3, figsize=(11, 5.5), sharex=True)
    for ax, m in zip(axes.flat, MUSCLES):
        d = ours[m] - theirs[m]
        print(f"{m:9s} max |diff| {np.abs(d).max():6.2f} N  RMS {np.sqrt(np.mean(d ** 2)):5.2f} N  "
              f"peak {theirs[m].max():6.1f} N")
        ax.plot(theirs["time"], theirs[m], color="0.6", lw=4, label="OpenSim 4.6 StaticOptimization")
        ax.plot(t, ours[m], color="C0", lw=1.5, label="openfdk, static_optimization: opensim")
        ax.set_title(m)
        ax.grid(alpha=0.3)
    for ax in axes[1]:
        ax.set_xlabel("time (s)")
    for ax in axes[:, 0]:
        ax.set_ylabel("muscle force (N)")
    axes[0, 0].legend(fontsize=8, loc="upper left")
    fig.suptitle("Arm26, elbow flexion: muscle forces, openfdk against OpenSim's static optimisation")
    fig.tight_layout()
    fig.savefig(png, dpi=110)


if __name__ == "__main__":
    main(*sys.argv[1:4])
