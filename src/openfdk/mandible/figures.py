"""Figures 5–7 of the mandible study: TMJ kinematics and forces over a normalised cycle.

Layout (docs/mandible-study-outputs.md, "Figures"): a 3 × 2 grid of panels, rows AP /
ML / SI, columns left / right TMJ, x = normalised cycle 0–100 %. Each model is drawn as
its mean curve over the cycles with a ±1 SD band (sample SD, ddof = 1): measured in
black, POP in green, FDK in blue (the paper's colours for the models). An optional
parameter-study ``band`` — ``dict[side -> (n_variants, n_points, 3)]``, each variant's
mean curve — is drawn behind everything as a grey (hatched) min–max envelope.
Kinematics are plotted in mm as given (displacements from a reference pose, or positions
in the skull frame), forces in N; every panel has its own y range. Matplotlib's Agg
backend is used (no display needed).

Inputs follow :mod:`openfdk.mandible.tables`: ``dict[model -> dict[side ->
(n_cycles, n_points, 3)]]`` in m (kinematics) or N (forces). Models may have different
numbers of cycles but must share n_points with each other and with the band.
"""

from __future__ import annotations

import os

import numpy as np

from .tables import DIRECTIONS, SIDES, ReportInputError, check_series, task_title

__all__ = ["MODEL_STYLE", "forces_figure", "kinematics_figure", "plot_forces",
           "plot_kinematics", "plot_task", "task_figure"]

#: colour and draw order of the known models; others get the next matplotlib colours
MODEL_STYLE = {
    "measured": {"color": "black", "label": "Measured"},
    "POP": {"color": "#1a9641", "label": "POP"},
    "FDK": {"color": "#2166ac", "label": "FDK"},
}
_OTHER_COLORS = ("#d95f02", "#7570b3", "#e7298a", "#66a61e")
_BAND = {"facecolor": "0.86", "edgecolor": "0.62", "hatch": "////",
         "label": "FDK parameter study (min–max)"}


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _checked(kind: str, series: dict, band: dict | None) -> tuple[dict, dict | None, int]:
    """Validate model series and band; returns float arrays and the common n_points."""
    if not isinstance(series, dict) or not series:
        raise ReportInputError(f"{kind}: expected dict[model -> dict[side -> array]], "
                               f"got {type(series).__name__}")
    out, n_points = {}, None
    for model, sides in series.items():
        out[model] = {}
        for side in SIDES:
            if not isinstance(sides, dict) or side not in sides:
                raise ReportInputError(f"{kind}, model {model!r}: side {side!r} missing")
            a = check_series(f"{kind}, model {model!r}, side {side!r}", sides[side])
            if n_points is None:
                n_points = a.shape[1]
            elif a.shape[1] != n_points:
                raise ReportInputError(f"{kind}, model {model!r}, side {side!r}: {a.shape[1]} "
                                       f"points per cycle but other series have {n_points}")
            out[model][side] = a
    if band is None:
        return out, None, n_points
    checked_band = {}
    for side in SIDES:
        if side not in band:
            raise ReportInputError(f"{kind} parameter-study band: side {side!r} missing")
        b = np.asarray(band[side], dtype=float)
        if b.ndim != 3 or b.shape[1:] != (n_points, 3):
            raise ReportInputError(f"{kind} parameter-study band, side {side!r}: expected "
                                   f"(n_variants, {n_points}, 3); got {b.shape}")
        checked_band[side] = b
    return out, checked_band, n_points


def _style(model: str, k: int) -> dict:
    return MODEL_STYLE.get(model, {"color": _OTHER_COLORS[k % len(_OTHER_COLORS)],
                                   "label": model})


def _ordered(models) -> list[str]:
    known = [m for m in MODEL_STYLE if m in models]
    return known + [m for m in models if m not in MODEL_STYLE]


def _draw_grid(axes, kind: str, series: dict, band: dict | None, scale: float,
               unit: str, quantity: str) -> list:
    """Draw a (3, 2) block of panels; returns legend handles and labels."""
    series, band, n_points = _checked(kind, series, band)
    x = np.linspace(0.0, 100.0, n_points)
    handles = {}
    for col, side in enumerate(SIDES):
        for row, direction in enumerate(DIRECTIONS):
            ax = axes[row, col]
            if band is not None:
                lo = np.nanmin(scale * band[side][:, :, row], axis=0)
                hi = np.nanmax(scale * band[side][:, :, row], axis=0)
                patch = ax.fill_between(x, lo, hi, facecolor=_BAND["facecolor"],
                                        edgecolor=_BAND["edgecolor"], hatch=_BAND["hatch"],
                                        lw=0, zorder=1)
                handles["band"] = (patch, _BAND["label"])
            for k, model in enumerate(_ordered(series)):
                style = _style(model, k)
                y = scale * series[model][side][:, :, row]           # (n_cycles, n_points)
                mean = np.nanmean(y, axis=0)
                sd = np.nanstd(y, axis=0, ddof=1) if y.shape[0] > 1 else np.zeros(n_points)
                shade = ax.fill_between(x, mean - sd, mean + sd, color=style["color"],
                                        alpha=0.18, lw=0, zorder=2 + k)
                line, = ax.plot(x, mean, color=style["color"], lw=1.6, zorder=10 + k)
                handles[model] = ((shade, line), style["label"])
            ax.set_xlim(0.0, 100.0)
            y_lo, y_hi = ax.get_ylim()
            if y_lo < 0.0 < y_hi:                                    # zero line if in range
                ax.axhline(0.0, color="0.75", lw=0.6, zorder=0)
            ax.grid(True, color="0.92", lw=0.6)
            ax.tick_params(labelsize=8)
            if col == 0:
                ax.set_ylabel(f"{direction} {quantity} ({unit})", fontsize=9)
    return [handles[k] for k in handles]


def _finish(fig, axes, handles, title: str):
    for col, side in enumerate(SIDES):
        axes[0, col].set_title(f"{side.capitalize()} TMJ", fontsize=10)
        axes[-1, col].set_xlabel("Cycle (%)", fontsize=9)
    fig.suptitle(title, fontsize=12)
    fig.text(0.5, 0.005, "Lines: mean over cycles; coloured shading: ±1 SD across cycles",
             ha="center", va="bottom", fontsize=7.5, color="0.35")
    band = [h for h in handles if h[1] == _BAND["label"]]
    order = [h for h in handles if h[1] != _BAND["label"]] + band
    fig.legend([h for h, _ in order], [label for _, label in order], loc="lower center",
               bbox_to_anchor=(0.5, 0.02), ncol=len(order), fontsize=8.5, frameon=False,
               handlelength=2.4, columnspacing=1.4)
    fig.tight_layout(rect=(0, 0.06, 1, 0.98), h_pad=0.6)
    return fig


def kinematics_figure(task: str, kinematics: dict, band: dict | None = None, *,
                      quantity: str = "displacement"):
    """Figure (3 × 2 panels) of condyle kinematics; arguments as :func:`plot_kinematics`.
    Returns: the matplotlib Figure (close it with ``plt.close(fig)``)."""
    plt = _plt()
    fig, axes = plt.subplots(3, 2, figsize=(7.5, 7.2), sharex=True)
    handles = _draw_grid(axes, "kinematics", kinematics, band, 1e3, "mm", quantity)
    return _finish(fig, axes, handles, f"{task_title(task)}: TMJ kinematics (condyle in skull frame)")


def forces_figure(task: str, forces: dict, band: dict | None = None):
    """Figure (3 × 2 panels) of TMJ reaction forces; arguments as :func:`plot_forces`.
    Returns: the matplotlib Figure."""
    plt = _plt()
    fig, axes = plt.subplots(3, 2, figsize=(7.5, 7.2), sharex=True)
    handles = _draw_grid(axes, "forces", forces, band, 1.0, "N", "force")
    return _finish(fig, axes, handles, f"{task_title(task)}: TMJ reaction force on the mandible")


def task_figure(task: str, kinematics: dict, forces: dict, kinematics_band: dict | None = None,
                force_band: dict | None = None, *, quantity: str = "displacement"):
    """Both blocks in one figure like the paper's Figs. 5–7: kinematics (rows 1–3) above
    forces (rows 4–6). Returns: the matplotlib Figure."""
    plt = _plt()
    fig, axes = plt.subplots(6, 2, figsize=(7.5, 12.5), sharex=True)
    h1 = _draw_grid(axes[:3], "kinematics", kinematics, kinematics_band, 1e3, "mm", quantity)
    h2 = _draw_grid(axes[3:], "forces", forces, force_band, 1.0, "N", "force")
    seen = {label for _, label in h1}
    return _finish(fig, axes, h1 + [h for h in h2 if h[1] not in seen],
                   f"{task_title(task)}: TMJ kinematics and reaction forces")


def _save(fig, path) -> str:
    plt = _plt()
    fig.savefig(path, dpi=150)
    plt.close(fig)
    return os.fspath(path)


def plot_kinematics(task: str, kinematics: dict, path, band: dict | None = None, *,
                    quantity: str = "displacement") -> str:
    """Paper-style figure of the condyle kinematics of one task.

    Args:
        task : task name for the title ("chewing", "protrusion", "open_close").
        kinematics : dict[model -> dict[side -> (n_cycles, n_points, 3) m]], AP/ML/SI of
            the condyle point in the skull frame, cycle-normalised; plotted in mm.
        path : output image file (format from the suffix, e.g. .png, .pdf).
        band : optional dict[side -> (n_variants, n_points, 3) m], the parameter-study
            variants' mean curves, drawn as a grey min–max envelope.
        quantity : y-label word, "displacement" (from a reference pose) or "position".
    Returns: the path.
    """
    return _save(kinematics_figure(task, kinematics, band, quantity=quantity), path)


def plot_forces(task: str, forces: dict, path, band: dict | None = None) -> str:
    """Paper-style figure of the TMJ reaction forces of one task.

    Args:
        task : task name for the title.
        forces : dict[model -> dict[side -> (n_cycles, n_points, 3) N]] (POP, FDK), the
            TMJ reaction force on the mandible in the skull frame (AP, ML, SI).
        path : output image file.
        band : optional dict[side -> (n_variants, n_points, 3) N] of variant mean curves.
    Returns: the path.
    """
    return _save(forces_figure(task, forces, band), path)


def plot_task(task: str, kinematics: dict, forces: dict, path,
              kinematics_band: dict | None = None, force_band: dict | None = None, *,
              quantity: str = "displacement") -> str:
    """Kinematics and forces of one task in one figure (the paper's Figs. 5–7 layout).

    Args: as :func:`plot_kinematics` (kinematics m, kinematics_band m) and
    :func:`plot_forces` (forces N, force_band N); path : output file. Returns: the path.
    """
    return _save(task_figure(task, kinematics, forces, kinematics_band, force_band,
                             quantity=quantity), path)
