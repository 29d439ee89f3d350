"""Figures (matplotlib, Agg backend: works without a display)."""

from __future__ import annotations

import numpy as np


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def plot_tracking(result, path, truth=None, title=""):
    """Kinematics overview of a marker-tracking result: each body's position (mm) over
    time (with the truth dashed when given), marker residual norms (mm), and shaded
    failed frames. truth : optional dict body -> (p_W (nf, 3) m, R_W (nf, 3, 3))."""
    plt = _plt()
    nb = len(result.body_names)
    fig, axes = plt.subplots(nb + 1, 1, figsize=(8, 2.4 * (nb + 1)), sharex=True)
    t = result.time
    for k, name in enumerate(result.body_names):
        ax = axes[k]
        for j, c in enumerate("xyz"):
            line, = ax.plot(t, 1e3 * result.q[:, 7 * k + j], label=f"{c}")
            if truth and name in truth:
                ax.plot(t, 1e3 * truth[name][0][:, j], "--", color=line.get_color(), lw=1)
        ax.set_ylabel(f"{name} COM (mm)")
        ax.legend(loc="upper right", ncol=3, fontsize=8)
    ax = axes[-1]
    if result.marker_residual.size:
        res = 1e3 * np.linalg.norm(result.marker_residual, axis=2)
        for m, name in enumerate(result.marker_names):
            ax.plot(t, res[:, m], lw=0.8, label=name)
        ax.legend(loc="upper right", ncol=4, fontsize=7)
    ax.set_ylabel("marker residual (mm)")
    ax.set_xlabel("time (s)")
    for a in axes:
        for i in np.flatnonzero(~result.converged):
            a.axvspan(t[i] - 0.5 * (t[1] - t[0]), t[i] + 0.5 * (t[1] - t[0]), color="red", alpha=0.2, lw=0)
    fig.suptitle(title or f"{result.model_name}: marker tracking (dashed: truth; red: failed frames)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
