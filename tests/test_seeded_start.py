"""The seeded start of a cold determinate position solve (openfdk.kinematics.seeded_start)
on the knee of :mod:`test_knee_jam_fdk` with a closed loop: a distance between a femur
point a_F and a tibia point b_T held at L, the only row that sets ``knee_tz``.

With the femur welded to the ground and ``knee_tz`` a translation along the femur's z
axis, the distance is |a_F − w(q) − tz e_z|, w the tibia point at tz = 0: its square is
a quadratic in tz with the vertex v = a_z − w_z and the two roots v ± √(L² − ρ²), ρ the
distance in the xy plane. The reference pose has tz = 0 below the vertex, so the near
root is v − √(L² − ρ²), found here in closed form.

* The seed: the driven coordinates and the FDK DOFs at their targets, ``knee_tz`` at
  its value in the given pose (the coordinates read back by their measures).
* A first frame at 69° of flexion from the extended reference pose: Newton's method from
  the reference lands on the far root (the DM knee's patellar tendon in crouch,
  docs/gait.md), and from the seed on the near one, at every frame.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

pytest.importorskip("opensim")

from test_knee_jam_fdk import _knee_model, tibia_pose  # noqa: E402
from test_motion_fdk import TIMES, _reach_overlay, _write_motion  # noqa: E402

import openfdk.kinematics.analysis as kinematics_analysis  # noqa: E402
from openfdk.io.modelfile import load_model_and_settings  # noqa: E402
from openfdk.kinematics.analysis import run_determinate  # noqa: E402
from openfdk.kinematics.seeded_start import seed_start  # noqa: E402
from openfdk.kinematics.system import ConstraintSystem  # noqa: E402

A_F = np.array([0.03, 0.02, 0.01])  # m, on the femur (= ground)
B_T = np.array([0.02, -0.04, 0.0])  # m, on the tibia
LENGTH = 0.05  # m
FLEXION = 1.2 + 0.2 * TIMES  # rad: 69° at the first frame, from the extended reference
ADDUCTION, ROTATION = 0.02 * np.sin(4 * TIMES), -0.03 * TIMES
TX, TY = 0.001 * TIMES, 0.004 * TIMES


def _loop_overlay(folder, fdk=""):
    _knee_model(folder)
    _write_motion(folder, {"knee_flex": FLEXION, "knee_add": ADDUCTION, "knee_rot": ROTATION, "knee_tx": TX,
                           "knee_ty": TY, "knee_tz": np.zeros(TIMES.size)})
    return _reach_overlay(folder, "loop.yaml", fdk, A_F, B_T, LENGTH)


def _roots(q5):
    """(near, far) roots (m) of the distance in tz at the other five coordinates q5."""
    R, p = tibia_pose(np.r_[q5, 0.0])
    w = p + R @ B_T
    rho = np.hypot(A_F[0] - w[0], A_F[1] - w[1])
    vertex, half = A_F[2] - w[2], np.sqrt(LENGTH**2 - rho**2)
    return vertex - half, vertex + half


def _coordinates(model, state):
    return {c.name: float(c.measure.evaluate(state, 0)[0][0]) for c in model.coordinates}


@pytest.mark.filterwarnings("ignore::openfdk.model.plausibility.PlausibilityWarning")
def test_the_seed_sets_the_coordinates_with_rows_and_keeps_the_others(tmp_path):
    overlay = _loop_overlay(tmp_path, "fdk_dofs: [knee_tx, knee_ty]\n")
    model, _ = load_model_and_settings(overlay)
    system = ConstraintSystem(model)
    state = model.initial_state()
    state.set_q(state.get_q())
    before = _coordinates(model, state)
    k, alpha = 4, np.array([0.0031, -0.0017])
    assert seed_start(system, state, TIMES[k], alpha)
    after = _coordinates(model, state)
    # the file's samples (its spline passes through them) and α, to round-off
    assert after["knee_flex"] == pytest.approx(FLEXION[k], abs=1e-12)
    assert after["knee_add"] == pytest.approx(ADDUCTION[k], abs=1e-12)
    assert after["knee_rot"] == pytest.approx(ROTATION[k], abs=1e-12)
    assert (after["knee_tx"], after["knee_ty"]) == pytest.approx(tuple(alpha), abs=1e-12)
    assert after["knee_tz"] == pytest.approx(before["knee_tz"], abs=1e-12)  # no row of its own: kept
    assert abs(after["knee_flex"] - before["knee_flex"]) > 1.0  # the seed moved the knee
    # the loop's row is left to Newton's method: not satisfied by the seed
    Phi = system.evaluate(state, TIMES[k], alpha, order=0)[0]
    assert abs(Phi[system.row_names.index("reach_held")]) > 1e-3


@pytest.mark.filterwarnings("ignore::openfdk.model.plausibility.PlausibilityWarning")
def test_a_closed_loop_starts_on_its_near_root(tmp_path, monkeypatch):
    model, _ = load_model_and_settings(_loop_overlay(tmp_path))

    def knee_tz(result):
        out = []
        for q in result.q:
            state = model.initial_state()
            state.set_q(q)
            out.append(_coordinates(model, state)["knee_tz"])
        return np.array(out)

    seeded = run_determinate(model, TIMES)
    assert seeded.converged.all()
    ours = knee_tz(seeded)
    for k in range(TIMES.size):
        near, far = _roots(np.array([FLEXION[k], ADDUCTION[k], ROTATION[k], TX[k], TY[k]]))
        assert far - near > 0.03  # two distinct roots
        assert ours[k] == pytest.approx(near, abs=1e-9)
    # Newton's method from the extended reference pose alone: the far root at the first
    # frame (the later frames start from the one before)
    monkeypatch.setattr(kinematics_analysis, "seed_start", lambda *args: False)
    plain = run_determinate(model, TIMES[:1])
    assert plain.converged.all()
    near, far = _roots(np.array([FLEXION[0], ADDUCTION[0], ROTATION[0], TX[0], TY[0]]))
    assert knee_tz(plain)[0] == pytest.approx(far, abs=1e-9)


@pytest.mark.filterwarnings("ignore::openfdk.model.plausibility.PlausibilityWarning")
def test_a_model_without_opensim_joints_is_not_seeded(tmp_path):
    model, _ = load_model_and_settings(_loop_overlay(tmp_path))
    bare = replace(model, joints=())
    state = bare.initial_state()
    q = state.get_q().copy()
    assert not seed_start(ConstraintSystem(bare), state, TIMES[0])
    np.testing.assert_array_equal(state.get_q(), q)
