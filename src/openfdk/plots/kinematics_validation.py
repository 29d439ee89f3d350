"""The figure of ``openfdk validate-kinematics`` (validation.png): one panel per DOF, the
model against the measured reference over % of the gait cycle, in mm or degrees, with
the stance/swing split at toe-off when it is known.

Takes the :class:`openfdk.analysis.kinematics_validation.ValidationResult` (read through
its attributes; this module imports no analysis). Like the figures of a run
(:mod:`openfdk.plots.run`) it is a plain matplotlib ``Figure``: no display or backend.
"""

from __future__ import annotations

import numpy as np

from .run import _finish

__all__ = ["validation_figure"]

REFERENCE_COLOUR = "black"
MODEL_COLOUR = "tab:blue"


def validation_figure(result, caption="", width=9.0, row_height=2.1):
    """validation.png: per DOF (rows), the reference (black, its samples within 0–100 %
    of the cycle) and the model (blue: the run's converged frames; dots: the values
    compared at the reference's samples), the agreement in the panel's title
    (RMSD, RMSD with the mean offset removed, r², mean offset = model − reference);
    toe-off as a dashed line with "stance" and "swing" either side."""
    from matplotlib.figure import Figure

    n = len(result.dofs)
    fig = Figure(figsize=(width, 0.9 + row_height * max(n, 1)))
    axes = list(fig.subplots(max(n, 1), 1, sharex=True, squeeze=False)[:, 0])
    fig.suptitle(f"{result.run_dir.name}: model vs {result.reference_path.name}", fontsize=11)
    toe = result.toe_off_percent
    for k, (ax, c) in enumerate(zip(axes, result.dofs)):
        s = c.stats
        label = (lambda text: text) if k == 0 else (lambda text: "_nolegend_")  # one legend, on the first panel
        ax.plot(c.reference_percent_all, c.reference_all, color=REFERENCE_COLOUR, lw=1.4, label=label("reference"))
        inside = (c.run_percent >= -1e-9) & (c.run_percent <= 100 + 1e-9)
        ax.plot(c.run_percent[inside], c.model_curve[inside], color=MODEL_COLOUR, lw=1.2, label=label("model"))
        ax.plot(c.percent, c.model, ".", color=MODEL_COLOUR, ms=2.5, label=label("model at the compared samples"))
        ax.set_ylabel(f"{c.entry.name} ({c.unit})", fontsize=8)
        if s["n"]:
            r2 = "–" if not np.isfinite(s["r2"]) else f"{s['r2']:.2f}"
            ax.set_title(f"{c.entry.name}: RMSD {s['rmsd']:.2f} {c.unit}, offset removed {s['rmsd_offset_removed']:.2f}"
                         f" {c.unit}, r² {r2}, mean offset {s['mean_offset']:+.2f} {c.unit} (n = {s['n']})",
                         fontsize=8, loc="left")
        else:
            ax.set_title(f"{c.entry.name}: no compared sample", fontsize=8, loc="left")
        if toe is not None:
            ax.axvline(toe, color="grey", ls="--", lw=0.8)
            ax.text(toe / 2, 0.97, "stance", transform=ax.get_xaxis_transform(), ha="center", va="top", fontsize=7,
                    color="grey")
            ax.text((toe + 100) / 2, 0.97, "swing", transform=ax.get_xaxis_transform(), ha="center", va="top",
                    fontsize=7, color="grey")
    axes[-1].set_xlim(0, 100)
    axes[-1].set_xlabel("gait cycle (%)")
    text = (caption + " " if caption else "") + (
        "Black: reference; blue: model (converged frames, gaps at failed ones); offset = model − reference; "
        "lengths in mm, angles in degrees.")
    _finish(fig, axes, np.zeros(0), np.zeros(0, dtype=bool), text)
    return fig
