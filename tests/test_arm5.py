"""The arm5 benchmark model against closed forms: the driven flexion, exact marker
tracking, and the elbow moment balance of the inverse dynamics."""

import numpy as np
import pytest

from openfdk.analysis.inverse_dynamics import run_inverse_dynamics
from openfdk.bench.arm5 import arm5_marker_trajectories, arm5_models, arm5_times
from openfdk.kinematics.analysis import run_determinate, run_tracking

MASS, I_YY, COM = 1.2, 1.2e-2, 0.15  # forearm: kg, kg m² about its centre of mass, m from the elbow


@pytest.fixture(scope="module")
def arm5():
    model, tracking_model = arm5_models()
    times = arm5_times()
    kin = run_determinate(model, times)
    return model, tracking_model, times, kin


def _flexion(t):
    """θ (rad), θ̇, θ̈ of the driver 30° + 35° sin(2π·0.5 t)."""
    w = np.pi
    a = np.deg2rad(35.0)
    return np.deg2rad(30.0) + a * np.sin(w * t), a * w * np.cos(w * t), -a * w * w * np.sin(w * t)


def test_determinate_kinematics_follow_the_driver(arm5):
    """The forearm rotates about −y through the elbow: its centre of mass is at
    0.15 m (cos θ, 0, sin θ), ω'_y = −θ̇, and r̈ is the circular-motion acceleration."""
    _, _, times, kin = arm5
    assert kin.converged.all() and len(times) == 201
    th, dth, ddth = _flexion(times)
    r = kin.q[:, :3]
    np.testing.assert_allclose(r, COM * np.column_stack([np.cos(th), 0 * th, np.sin(th)]), atol=1e-12)
    np.testing.assert_allclose(kin.v[:, 4], -dth, atol=1e-12)
    np.testing.assert_allclose(kin.vdot[:, 4], -ddth, atol=1e-10)
    # r̈ = d (θ̈ (−sin, cos) − θ̇² (cos, sin)) in the x-z plane
    acc = COM * np.column_stack([-ddth * np.sin(th) - dth**2 * np.cos(th), 0 * th, ddth * np.cos(th) - dth**2 * np.sin(th)])
    np.testing.assert_allclose(kin.vdot[:, :3], acc, atol=1e-10)


def test_tracking_of_exact_markers_recovers_the_motion(arm5):
    _, tracking_model, times, kin = arm5
    res = run_tracking(tracking_model, arm5_marker_trajectories(kin, tracking_model), times)
    assert res.converged.all()
    np.testing.assert_allclose(res.q, kin.q, atol=1e-9)
    # velocities from the interpolated markers: spline error, far below the motion's scale
    np.testing.assert_allclose(res.v[5:-5], kin.v[5:-5], atol=1e-4)


def test_inverse_dynamics_balances_the_elbow_moment(arm5):
    """Σ T_m r_m = I_e θ̈ + m g d cos θ about the elbow (T_m: recruited plus passive
    tension of muscle m), with the moment arms r_m =
    −dl_m/dθ = −l̇_m/θ̇ from the muscle lengthening speeds and I_e = I_yy + m d²."""
    model, _, times, kin = arm5
    dyn = run_inverse_dynamics(model, kin)
    assert dyn.converged.all()
    th, dth, ddth = _flexion(times)
    moving = np.abs(dth) > 0.3  # moment arms from speeds where the elbow moves
    f = dyn.forces[:, :5]
    tension = f + dyn.muscle_passive  # recruited (active) plus parallel-elastic force
    assert dyn.muscle_passive.max() > 1.0  # the passive part is exercised
    arms = -dyn.muscle_speed / dth[:, None]
    lhs = np.sum(tension * arms, axis=1)
    rhs = (I_YY + MASS * COM**2) * ddth + MASS * 9.81 * COM * np.cos(th)
    assert np.abs(rhs[moving]).min() > 0.5  # a real load
    np.testing.assert_allclose(lhs[moving], rhs[moving], rtol=1e-8, atol=1e-8)
    assert np.all(f >= -1e-9) and np.all(f <= dyn.muscle_strength + 1e-6)
