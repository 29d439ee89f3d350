"""The figures of a model with many lines (DM: 149 ligament strands, 107 constraint
rows): the legends name the largest, and the ligaments' figure sums the strands of each
bundle (<bundle><k>) — the force a knee's MCL or patellar tendon carries."""

from __future__ import annotations

import numpy as np
import pandas as pd

from openfdk.plots.run import MAX_LEGEND, figure_plan, ligament_bundles
from openfdk.results.run import RunResults


def test_bundles_are_the_strands_that_share_a_stem():
    assert ligament_bundles(["MCLd1", "MCLd2", "ITB_r", "PT1", "pCAP1", "pCAP2", "pCAP10", "ACL"]) == {
        "MCLd": ["MCLd1", "MCLd2"], "ITB_r": ["ITB_r"], "PT1": ["PT1"], "pCAP": ["pCAP1", "pCAP2", "pCAP10"],
        "ACL": ["ACL"]}
    assert ligament_bundles([]) == {}


def _results(n_extra):
    t = np.linspace(0.0, 1.0, 11)
    strands = {"MCL1": 10 + 5 * t, "MCL2": 20 * t, "ACL": 50 * np.sin(np.pi * t), "PT1": np.full(t.size, 3.0)}
    strands.update({f"x{k}_a": np.full(t.size, 0.01 * k) for k in range(n_extra)})  # small, unbundled
    cols = {"time": t, "converged": np.ones(t.size), "status": ["optimal"] * t.size, "message": [""] * t.size}
    for n, v in strands.items():
        cols[f"{n}.force_N"], cols[f"{n}.strain"] = v, 0.01 * v
    kinematics = pd.DataFrame({"time": t, "converged": np.ones(t.size)}).set_index("time")
    return RunResults(kinematics, pd.DataFrame(cols).set_index("time"), {}), strands


def _figure(results):
    (build,) = [b for name, b, _ in figure_plan(results, measures=[]) if name == "ligaments"]
    return build()


def test_bundle_panel_sums_its_strands_and_the_legends_start_with_the_largest():
    results, strands = _results(n_extra=12)
    fig = _figure(results)
    assert len(fig.axes) == 3 and f"16 ligament strands; legends: the {MAX_LEGEND} largest" in fig._suptitle.get_text()
    labels = [line.get_label() for line in fig.axes[0].get_lines()]
    assert labels[:3] == ["ACL", "MCL2", "MCL1"]  # peaks 50, 20, 15 N
    bundles = {line.get_label(): line.get_ydata() for line in fig.axes[2].get_lines()}
    np.testing.assert_allclose(bundles["MCL (2 strands)"], strands["MCL1"] + strands["MCL2"], rtol=1e-12)
    np.testing.assert_allclose(bundles["ACL"], strands["ACL"], rtol=1e-12)
    assert list(bundles)[:2] == ["ACL", "MCL (2 strands)"]  # peaks 50 and 30 N
    assert len(bundles) == 15  # the 16 strands, MCL's two as one


def test_without_shared_stems_no_bundle_panel_and_a_short_title():
    t = np.linspace(0.0, 1.0, 5)
    cols = {"time": t, "converged": np.ones(5), "status": ["optimal"] * 5, "message": [""] * 5,
            "ACL.force_N": t, "ACL.strain": t, "PCL.force_N": 2 * t, "PCL.strain": t}
    kinematics = pd.DataFrame({"time": t, "converged": np.ones(5)}).set_index("time")
    fig = _figure(RunResults(kinematics, pd.DataFrame(cols).set_index("time"), {}))
    assert len(fig.axes) == 2 and fig._suptitle.get_text().endswith("ligaments and springs")


def test_reaction_legends_start_with_the_largest_rows():
    """The reactions' figure of a model with many constraint rows (DM: 107) names the
    largest in its legend, whatever the rows' order in the model."""
    t = np.linspace(0.0, 1.0, 6)
    peaks = {f"j{k}.t1": float(k) for k in range(20)}  # the model's order: smallest first
    cols = {"time": t, "converged": np.ones(6), "status": ["optimal"] * 6, "message": [""] * 6}
    cols.update({f"{n}.reaction": p * np.sin(np.pi * t / 2) for n, p in peaks.items()})  # peak p at t = 1
    kinematics = pd.DataFrame({"time": t, "converged": np.ones(6)}).set_index("time")
    results = RunResults(kinematics, pd.DataFrame(cols).set_index("time"), {})
    (build,) = [b for name, b, _ in figure_plan(results, measures=[]) if name == "reactions"]
    fig = build()
    assert f"20 rows; legends: the {MAX_LEGEND} largest" in fig._suptitle.get_text()
    legend = [text.get_text() for text in fig.axes[0].get_legend().get_texts()]
    assert legend == [f"j{k}.t1" for k in range(19, 19 - MAX_LEGEND, -1)]
    lines = {line.get_label(): line.get_ydata() for line in fig.axes[0].get_lines()}
    np.testing.assert_allclose(lines["j7.t1"], 7 * np.sin(np.pi * t / 2), rtol=1e-12)
