"""openfdk with OpenSim's static-optimisation choices (``recruitment: {power: 2,
static_optimization: opensim}``) against OpenSim 4.6's StaticOptimization, on a
multi-muscle model with reserve actuators (issue: "muscle forces within 1 N").

The model is the two-joint arm of test_opensim_muscles (three Thelen2003Muscles with
non-default parameters, 2–4 path points) plus a CoordinateActuator (optimal force 1 N m)
on each coordinate, built with OpenSim's API; the motion is a smooth .mot. What makes the
two agree: OpenSim overrides each muscle's force with a · F_opt, F_opt its active fibre
force at full activation with a rigid tendon and Thelen's force–velocity curve, no
passive force, a within [min_control, max_control] = [0.01, 1], criterion Σ a²
(openfdk.forces.rigid_tendon). The remaining difference (≤ 0.26 N of 382 N measured) is
the coordinates' accelerations: OpenSim differentiates a quintic GCV spline of the
samples, openfdk a cubic spline, and OpenSim's IPOPT stops at its own tolerance.
"""

from __future__ import annotations

import numpy as np
import pytest

opensim = pytest.importorskip("opensim")

from openfdk.cli import main  # noqa: E402
from openfdk.io.results import read_table  # noqa: E402
import opensim_models as om  # noqa: E402  (tests/opensim_models.py)
from test_opensim_muscles import arm_model  # noqa: E402

MUSCLES = {"biceps.long": "biceps_long", "triceps": "triceps", "delt": "delt"}


def _setup(folder):
    return om.arm_static_optimization(arm_model(folder / "arm.osim"), folder)


def _run(folder, model, motion, rule, capsys):
    (folder / f"{rule}.yaml").write_text(f"recruitment: {{power: 2, static_optimization: {rule}}}\n")
    code = main(["run", str(model), "--motion", str(motion), "--with", str(folder / f"{rule}.yaml"),
                 "--out", str(folder / rule), "--no-plots", "-q"])
    assert code == 0, capsys.readouterr().err
    return read_table(folder / rule / "forces.csv")


@pytest.mark.slow
def test_muscle_forces_equal_opensims_static_optimization(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    model, motion, (t, theirs) = _setup(tmp_path)
    ours = _run(tmp_path, model, motion, "opensim", capsys)
    worst = {}
    for name, mine in MUSCLES.items():
        f = np.interp(t, ours["time"], ours[f"{mine}.force_N"])
        worst[name] = float(np.max(np.abs(f - theirs[name])))
        assert np.max(theirs[name]) > 15.0  # every muscle works
    for name in ("reserve_q_shoulder", "reserve_q_elbow"):
        f = np.interp(t, ours["time"], ours[f"{name}.actuator"])
        worst[name] = float(np.max(np.abs(f - theirs[name])))
    print("largest differences from OpenSim's StaticOptimization (N, N m):", worst)
    assert max(worst.values()) < 1.0
    # the activation floor is OpenSim's (min_control 0.01): every activation ≥ 0.01
    act = np.column_stack([ours[f"{m}.activation"] for m in MUSCLES.values()])
    assert act.min() >= 0.01 - 1e-9 and np.isclose(act.min(), 0.01)
    # the motion makes muscles lengthen under load (Thelen's eccentric branch is used)
    lengths = np.column_stack([ours[f"{m}.length_m"] for m in MUSCLES.values()])
    lengthening = np.gradient(lengths, ours["time"], axis=0) > 0.01
    forces = np.column_stack([ours[f"{m}.force_N"] for m in MUSCLES.values()])
    assert np.any(lengthening & (forces > 5.0))
    # openfdk's own rule (compliant tendon, passive force applied, no floor) is another
    # answer: the setting is what reproduces OpenSim
    own = _run(tmp_path, model, motion, "openfdk", capsys)
    differs = max(float(np.max(np.abs(np.interp(t, own["time"], own[f"{m}.force_N"]) - theirs[n])))
                  for n, m in MUSCLES.items())
    assert differs > 5.0
