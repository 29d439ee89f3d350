"""The contact figure's force by region (a knee's medial and lateral compartments,
``<contact>.<region>_N`` of forces.csv): the whole contact's |F| and each region's force
drawn from the table, with their peaks in body weights when the run records the body
weight."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from openfdk.plots.run import body_weight, contact_regions, figure_plan
from openfdk.results.run import RunResults


def _results(regions=True, weight=700.0):
    t = np.linspace(0.0, 1.0, 21)
    F = np.column_stack([100 * np.sin(3 * t), -800 - 600 * np.sin(np.pi * t) ** 2, 30 * t])
    cols = {"time": t, "converged": np.ones(t.size), "status": ["optimal"] * t.size, "message": [""] * t.size}
    for c, v in zip("xyz", F.T):
        cols[f"knee.F{c}_N"] = v
    for c in "xyz":
        cols[f"knee.cop_{c}_m"] = 0.01 * t
    cols["knee.area_m2"] = np.full(t.size, 3e-4)
    norm = np.linalg.norm(F, axis=1)
    if regions:
        cols["knee.medial_N"], cols["knee.lateral_N"] = 0.65 * norm, 0.35 * norm
    forces = pd.DataFrame(cols).set_index("time")
    kinematics = pd.DataFrame({"time": t, "converged": np.ones(t.size)}).set_index("time")
    summary = {"residuals": {"body_weight_N": weight}} if weight else {}
    return RunResults(kinematics, forces, summary), t, norm


def _contact_figure(results):
    (build,) = [b for name, b, _ in figure_plan(results, measures=[]) if name == "contact"]
    return build()


def test_regions_are_drawn_beside_the_whole_force_with_peaks_in_body_weights():
    results, t, norm = _results()
    assert contact_regions(results, "knee") == [("medial", "knee.medial_N"), ("lateral", "knee.lateral_N")]
    assert body_weight(results) == 700.0
    fig = _contact_figure(results)
    assert len(fig.axes) == 4
    ax = fig.axes[3]
    assert ax.get_ylabel().replace("\n", " ") == "contact force by region (N; 1 BW = 700 N)"
    lines = {line.get_label(): line.get_ydata() for line in ax.get_lines()}
    peak = np.max(norm)  # at t = 0.5 s, where Fy = −1400 N: 2.01 BW
    assert peak == pytest.approx(np.sqrt((100 * np.sin(1.5)) ** 2 + 1400 ** 2 + 15 ** 2), rel=1e-12)
    expected = {f"knee |F| (peak {peak / 700:.2f} BW)": norm,
                f"knee medial (peak {0.65 * peak / 700:.2f} BW)": 0.65 * norm,
                f"knee lateral (peak {0.35 * peak / 700:.2f} BW)": 0.35 * norm}
    assert set(lines) == set(expected)
    for label, values in expected.items():
        np.testing.assert_allclose(lines[label], values, rtol=1e-12)
    assert "BW: the body weight, 700.0 N." in fig.texts[-1].get_text().replace("\n", " ")


def test_without_regions_three_panels_and_without_body_weight_newtons_only():
    fig = _contact_figure(_results(regions=False)[0])
    assert len(fig.axes) == 3  # force, centre of pressure, area, as before
    results, _, norm = _results(weight=None)
    assert body_weight(results) is None
    ax = _contact_figure(results).axes[3]
    assert ax.get_ylabel().replace("\n", " ") == "contact force by region (N)"
    assert sorted(line.get_label() for line in ax.get_lines()) == ["knee lateral", "knee medial", "knee |F|"]
