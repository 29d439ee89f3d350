"""The figure of docs/gait.md ("Every one of DM's 17 cycles in two stages"): the knee's
tibiofemoral contact force of FDK in two stages against tracked FDK, one panel per cycle.

    python docs/scripts/two_stages_vs_tracked.py OUT.png BODY_WEIGHT_N LABEL:TWO_STAGES_DIR:TRACKED_DIR ...

Each TWO_STAGES_DIR and TRACKED_DIR is an ``openfdk run`` folder (its forces.csv) of the
same window: ``openfdk run dm_pt.yaml --motion k/coordinates.mot …`` and ``openfdk run
dm_pt.yaml TRIAL_new.trc …``. The force is |F| of the contact ``knee_contact`` over the
body weight (N), against the window's percentage. Prints each cycle's peak and the RMS
difference (BW) at the two-stage run's frames (the tracked run interpolated there).
"""

import csv
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

CONTACT = "knee_contact"


def contact_force(run_dir, body_weight):
    """(t (n,) s, |F| (n,) BW) of the run's tibiofemoral contact; frames without a
    solution (empty or NaN) are left out."""
    t, f = [], []
    for row in csv.DictReader(open(f"{run_dir}/forces.csv")):
        F = [row.get(f"{CONTACT}.F{axis}_N", "") for axis in "xyz"]
        if all(v not in ("", "nan") for v in F):
            t.append(float(row["time"]))
            f.append(np.linalg.norm(np.array(F, float)) / body_weight)
    return np.array(t), np.array(f)


def main(png, body_weight, *pairs):
    body_weight = float(body_weight)
    n = len(pairs)
    cols = min(n, 4)
    rows = -(-n // cols)
    fig, axes = plt.subplots(rows, cols, figsize=(3.2 * cols, 2.5 * rows), sharey=True, squeeze=False)
    for ax, pair in zip(axes.flat, pairs):
        label, two_dir, tracked_dir = pair.split(":")
        t2, f2 = contact_force(two_dir, body_weight)
        t1, f1 = contact_force(tracked_dir, body_weight)
        t0, span = t1[0], t1[-1] - t1[0]
        rms = np.sqrt(np.mean((f2 - np.interp(t2, t1, f1)) ** 2))
        print(f"{label:12s} peak {f2.max():.2f} BW (tracked {f1.max():.2f})  RMS difference {rms:.2f} BW")
        ax.plot(100 * (t1 - t0) / span, f1, color="0.55", lw=3, label="tracked FDK")
        ax.plot(100 * (t2 - t0) / span, f2, color="C3", lw=1.2, label="two stages")
        ax.set_title(f"{label} (RMS {rms:.2f} BW)", fontsize=9)
        ax.grid(alpha=0.3)
    for ax in axes.flat[n:]:
        ax.set_visible(False)
    for ax in axes[-1]:
        ax.set_xlabel("% of the window")
    for ax in axes[:, 0]:
        ax.set_ylabel("tibiofemoral force (BW)")
    axes[0, 0].legend(fontsize=8, loc="upper right")
    fig.suptitle("DM: knee contact force, FDK on a first pass's coordinates against tracked FDK", fontsize=10)
    fig.tight_layout()
    fig.savefig(png, dpi=100)


if __name__ == "__main__":
    if len(sys.argv) < 4:
        sys.exit(__doc__)
    main(*sys.argv[1:])
