"""The figure of ``openfdk cycles`` (cycles.png): a run's results over % of the gait
cycle, the mean across the cycles with a band of ± one standard deviation and each
cycle as a thin line.

Takes the :class:`openfdk.analysis.gait_cycles.Cycles` (read through its attributes;
this module imports no analysis). A plain matplotlib ``Figure``, like a run's figures
(:mod:`openfdk.plots.run`).
"""

from __future__ import annotations

import numpy as np

from .run import _finish

__all__ = ["cycles_figure"]

#: kind -> (factor from SI, unit) of a panel; forces in BW when the body weight is known
_UNITS = {"length": (1e3, "mm"), "angle": (180.0 / np.pi, "deg"), "1": (1.0, "")}


def _panels(cycles, body_weight):
    """[(title, unit, factor, [names])]: the contacts' forces, the FDK DOFs' angles and
    lengths, the foot's vertical load."""
    force = (1.0 / body_weight, "BW") if body_weight else (1.0, "N")
    load = f"{cycles.foot}.vertical_load_N"
    names = list(cycles.per_cycle)
    panels = []
    contacts = [n for n in names if cycles.kinds[n] == "force" and n != load]
    if contacts:
        panels.append(("contact forces", force[1], force[0], contacts))
    for kind, title in (("angle", "FDK DOFs (rotations)"), ("length", "FDK DOFs (translations)"),
                        ("1", "FDK DOFs")):
        dofs = [n for n in names if cycles.kinds[n] == kind]
        if dofs:
            panels.append((title, _UNITS[kind][1], _UNITS[kind][0], dofs))
    panels.append((f"vertical load on {cycles.foot}", force[1], force[0], [load]))
    return panels


def _label(name):
    """A legend's name: the quantity without its unit suffix (the axis gives the unit)."""
    if name.startswith("fdk.") and name.endswith(".alpha"):
        return name[4:-6]
    for suffix in (".|F|_N", "_N", "_rad", "_m"):
        if name.endswith(suffix):
            return name[: -len(suffix)] + (" |F|" if suffix == ".|F|_N" else "")
    return name


def cycles_figure(cycles, body_weight=None, title="", width=11.0, row_height=2.6):
    """cycles.png: one panel per group (contact forces in BW when ``body_weight`` (N) is
    given, else N; FDK rotations in degrees; FDK translations in mm; the foot's vertical
    load): per quantity the mean over the cycles (line), ± one SD (band) and each cycle
    (thin lines, for the first quantity of a panel)."""
    from matplotlib.figure import Figure

    panels = _panels(cycles, body_weight)
    fig = Figure(figsize=(width, 0.9 + row_height * len(panels)))
    axes = list(fig.subplots(len(panels), 1, sharex=True, squeeze=False)[:, 0])
    n = cycles.n_cycles
    fig.suptitle(f"{title + ': ' if title else ''}{n} gait cycle{'s' if n != 1 else ''} of {cycles.foot}",
                 fontsize=11)
    p = np.arange(101, dtype=float)
    for ax, (name, unit, factor, quantities) in zip(axes, panels):
        for k, q in enumerate(quantities):
            colour = f"C{k % 10}"
            table = cycles.per_cycle[q] * factor
            if k == 0:
                for row in table:
                    ax.plot(p, row, color=colour, lw=0.4, alpha=0.35)
            mean, sd = cycles.mean(q) * factor, cycles.sd(q) * factor
            ax.plot(p, mean, color=colour, lw=1.6, label=_label(q))
            ax.fill_between(p, mean - sd, mean + sd, color=colour, alpha=0.18, lw=0)
        ax.set_ylabel(f"{name}\n({unit})" if unit else name, fontsize=8)
    stance = cycles.stance_percent
    stance = float(np.mean(stance[np.isfinite(stance)])) if np.any(np.isfinite(stance)) else None
    if stance is not None:  # the mean toe-off: stance | swing
        for ax in axes:
            ax.axvline(stance, color="grey", ls="--", lw=0.8)
            ax.text(stance / 2, 0.97, "stance", transform=ax.get_xaxis_transform(), ha="center", va="top",
                    fontsize=7, color="grey")
            ax.text((stance + 100) / 2, 0.97, "swing", transform=ax.get_xaxis_transform(), ha="center", va="top",
                    fontsize=7, color="grey")
    axes[-1].set_xlim(0, 100)
    axes[-1].set_xlabel("gait cycle (%)")
    failed = int(np.sum(cycles.failed))
    text = (f"Cycles from one heel strike of {cycles.foot} to the next: its vertical measured load rising through "
            f"{cycles.threshold_N:g} N"
            + (f"; dashed: the mean toe-off, where it falls through that load ({stance:.1f} %)" if stance else "")
            + f". Lines: the mean over the {n} cycles; bands: ± one standard deviation; thin "
            "lines: each cycle (the panel's first quantity). Failed frames are left out (no value is interpolated "
            f"across them): {failed} within the cycles."
            + (f" BW: the body weight, {body_weight:.1f} N." if body_weight else ""))
    _finish(fig, axes, np.zeros(0), np.zeros(0, dtype=bool), text)
    return fig
