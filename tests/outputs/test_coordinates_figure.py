"""The kinematics figure of a model with joint coordinates (an OpenSim model): its
coordinates grouped by joint, in degrees and millimetres, drawn from coordinates.csv.

The project's full-body ``.osim`` is driven along analytic trajectories
q(t) = a + b sin(2π f t + φ) (every frame's pose is exact), the back held still, and the
figure's lines must be those trajectories in display units."""

from __future__ import annotations

import numpy as np
import pytest
import yaml

from openfdk.cli import main
from openfdk.fixtures.full_body_osim import COORDINATES, sine_drivers, sine_trajectories, write_full_body_osim
from openfdk.plots.run import coordinate_panels, figure_plan
from openfdk.results.run import read_results

N_FRAMES = 9
START, STEP = 0.1, 0.02
STILL = ("lumbar_extension", "lumbar_bending", "lumbar_rotation")  # the back's joint


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    folder = tmp_path_factory.mktemp("coordinates_figure")
    write_full_body_osim(folder / "full_body.osim")
    q = sine_trajectories(np.random.default_rng(11), still=STILL)
    drivers = sine_drivers(q)
    (folder / "overlay.yaml").write_text(yaml.safe_dump({
        "opensim": "full_body.osim", "drivers": drivers,
        "analysis": {"start": START, "end": START + (N_FRAMES - 1) * STEP, "frames": N_FRAMES}}))
    out = folder / "run"
    assert main(["run", str(folder / "overlay.yaml"), "--out", str(out), "--no-plots", "-q"]) == 0
    return out, q


def test_panels_are_the_joints_in_the_models_order_with_short_ones_shared(run):
    out, _ = run
    panels, constant = coordinate_panels(read_results(out))
    # hand-derived from the model: the pelvis' three rotations and three translations, a
    # hip's three angles, then a knee, an ankle and a subtalar joint of one angle each in
    # one panel (3 lines), the toes alone (the next hip has 3); the back does not move
    assert [(joints, unit, [c for c, _ in coords]) for joints, unit, coords in panels] == [
        (["ground_pelvis"], "deg", ["pelvis_tilt", "pelvis_list", "pelvis_rotation"]),
        (["ground_pelvis"], "mm", ["pelvis_tx", "pelvis_ty", "pelvis_tz"]),
        *[item for s in "rl" for item in (
            ([f"hip_{s}"], "deg", [f"hip_flexion_{s}", f"hip_adduction_{s}", f"hip_rotation_{s}"]),
            ([f"knee_{s}", f"ankle_{s}", f"subtalar_{s}"], "deg",
             [f"knee_angle_{s}", f"ankle_angle_{s}", f"subtalar_angle_{s}"]),
            ([f"mtp_{s}"], "deg", [f"mtp_angle_{s}"]))]]
    assert constant == ["back"]


def test_lines_are_the_driven_trajectories_in_degrees_and_millimetres(run):
    out, q = run
    results = read_results(out)
    (name, build, weight), *_ = figure_plan(results)
    assert name == "kinematics" and weight == 8  # one axis per panel
    fig = build()
    t = START + STEP * np.arange(N_FRAMES)
    np.testing.assert_allclose(results.time, t, atol=1e-12)
    drawn = {}
    for ax in fig.axes:
        unit = ax.get_ylabel().rpartition("(")[2].rstrip(")")
        for line in ax.get_lines():
            drawn[line.get_label()] = (unit, np.asarray(line.get_xdata(), float), np.asarray(line.get_ydata(), float))
    assert set(drawn) == set(COORDINATES) - set(STILL)
    for coordinate, (unit, x, y) in drawn.items():
        a, b, f, phi = q[coordinate]
        exact = a + b * np.sin(2 * np.pi * f * t + phi)  # SI
        scale = 1e3 if coordinate in ("pelvis_tx", "pelvis_ty", "pelvis_tz") else np.degrees(1.0)
        assert unit == ("mm" if scale == 1e3 else "deg"), coordinate
        np.testing.assert_allclose(x, t, atol=1e-12)
        np.testing.assert_allclose(y, scale * exact, atol=1e-6 * scale, err_msg=coordinate)
        assert np.ptp(y) > 0.01 * scale * b  # the trajectory moves in the figure
    caption = fig.texts[-1].get_text().replace("\n", " ")
    assert "Constant throughout, not drawn: back." in caption


def test_a_model_without_coordinates_keeps_the_body_poses(tmp_path):
    from pathlib import Path

    root = Path(__file__).resolve().parents[2]
    out = tmp_path / "slider"
    assert main(["run", str(root / "examples/slider_crank.yaml"), "--out", str(out), "--no-plots", "-q",
                 "--end", "0.05"]) == 0
    results = read_results(out)
    assert results.coordinates is None and coordinate_panels(results) == ([], [])
    (name, build, weight), *_ = figure_plan(results)
    assert name == "kinematics" and weight == 2 * len(results.bodies())
    assert build().texts[0].get_text().endswith("body poses")


def test_a_joint_that_only_turns_is_named_with_its_still_translations():
    """A joint whose rotations move and whose translations do not: the rotations get a
    panel, and the caption names "joint (translations)", not the whole joint; a joint
    that does not move at all is named alone."""
    from types import SimpleNamespace

    import pandas as pd

    from openfdk.results.run import RunResults

    t = np.linspace(0.0, 1.0, 11)
    table = pd.DataFrame({"time": t, "flex_rad": 0.5 * t, "slide_m": np.full(t.size, 0.02),
                          "wrist_rad": np.full(t.size, 0.1)}).set_index("time")
    model = SimpleNamespace(coordinates=[SimpleNamespace(name="flex", joint="knee"),
                                         SimpleNamespace(name="slide", joint="knee"),
                                         SimpleNamespace(name="wrist", joint="hand")])
    kinematics = pd.DataFrame({"time": t, "converged": np.ones(t.size)}).set_index("time")
    results = RunResults(kinematics, None, {}, model, coordinates=table)
    panels, constant = coordinate_panels(results)
    assert [(joints, unit, [c for c, _ in coords]) for joints, unit, coords in panels] == [(["knee"], "deg", ["flex"])]
    assert constant == ["knee (translations)", "hand"]
