"""Kinematic analysis against closed forms (paper Eqs. 1–10)."""

import numpy as np
import pytest

from models import slider_crank, slider_crank_closed_form
from openfdk.kinematics.analysis import run_determinate, run_tracking
from openfdk.model.builder import ModelBuilder
from openfdk.numerics.spatial import quat_from_rotvec, rotation_matrix


def test_slider_crank_matches_closed_form():
    """Positions, velocities and accelerations of the slider and the rod angle against
    the hand-derived slider–crank formulas, over a full revolution (angle wrap at π)."""
    a, L, omega = 0.1, 0.3, 2 * np.pi
    model = slider_crank(a, L, omega)
    times = np.linspace(0.0, 1.0, 201)
    res = run_determinate(model, times)
    assert res.converged.all(), res.failed_frames()[:3]
    x, xd, xdd, phi = slider_crank_closed_form(times, a, L, omega)
    slider = model.body("slider").column // 6
    np.testing.assert_allclose(res.q[:, 7 * slider], x, atol=1e-9)
    np.testing.assert_allclose(res.q[:, 7 * slider + 1 : 7 * slider + 3], 0.0, atol=1e-9)
    np.testing.assert_allclose(res.v[:, 6 * slider], xd, atol=1e-9)
    np.testing.assert_allclose(res.vdot[:, 6 * slider], xdd, atol=1e-9)
    # rod: its orientation is a rotation φ about z; ω'_z = φ̇ checked via the quaternion
    rod = model.body("rod").column // 6
    quat = res.q[:, 7 * rod + 3 : 7 * rod + 7]
    phi_model = 2 * np.arctan2(quat[:, 3], quat[:, 0])
    np.testing.assert_allclose(np.sin(phi_model), np.sin(phi), atol=1e-9)
    # crank angular velocity = ω, angular acceleration 0
    crank = model.body("crank").column // 6
    np.testing.assert_allclose(res.v[:, 6 * crank + 5], omega, atol=1e-9)
    np.testing.assert_allclose(res.vdot[:, 6 * crank + 3 : 6 * crank + 6], 0.0, atol=1e-8)


class AnalyticFreeBody:
    """Exact marker trajectories of a free body: r(t) = r0 + c sin(ω t) (world),
    R(t) = R0 Exp(n θ(t)), θ = θ0 sin(ω t); then ω' = n θ̇ and ω̇' = n θ̈ (body frame)."""

    def __init__(self, p_BM, omega=3.0):
        self.p_BM = p_BM
        self.omega = omega
        self.r0 = np.array([0.1, -0.2, 0.3])
        self.c = np.array([0.05, 0.02, -0.03])
        self.R0 = rotation_matrix(quat_from_rotvec([0.3, -0.2, 0.5]))
        self.n = np.array([1.0, 2.0, 2.0]) / 3.0
        self.theta0 = 0.8
        self.time = np.linspace(0.0, 2.0, 201)

    def pose(self, t):
        w = self.omega
        r = self.r0 + self.c * np.sin(w * t)
        rd = self.c * w * np.cos(w * t)
        rdd = -self.c * w**2 * np.sin(w * t)
        th = self.theta0 * np.sin(w * t)
        thd = self.theta0 * w * np.cos(w * t)
        thdd = -self.theta0 * w**2 * np.sin(w * t)
        R = self.R0 @ rotation_matrix(quat_from_rotvec(self.n * th))
        return r, R, rd, rdd, self.n * thd, self.n * thdd

    def evaluate(self, t):
        r, R, rd, rdd, w, wd = self.pose(t)
        x = r + self.p_BM @ R.T
        wx = np.cross(w, self.p_BM)
        xd = rd + wx @ R.T
        xdd = rdd + (np.cross(wd, self.p_BM) + np.cross(w, wx)) @ R.T
        return x, xd, xdd, np.ones(len(self.p_BM), dtype=bool)


def test_free_body_tracking_recovers_pose_velocity_acceleration():
    p_BM = np.array([[0.05, 0, 0], [0, 0.04, 0], [0, 0, 0.06], [0.03, 0.03, -0.02]])
    b = ModelBuilder("free body")
    b.add_body("box", 1.0, [1e-3, 1e-3, 1e-3])
    for k, p in enumerate(p_BM):
        b.add_marker(f"M{k}", "box", p)
    model = b.build()
    traj = AnalyticFreeBody(p_BM)
    res = run_tracking(model, traj, traj.time)
    assert res.converged.all()
    for k in (0, 37, 100, 200):
        r, R, rd, rdd, w, wd = traj.pose(traj.time[k])
        np.testing.assert_allclose(res.q[k, :3], r, atol=1e-10)
        np.testing.assert_allclose(rotation_matrix(res.q[k, 3:7]), R, atol=1e-10)
        np.testing.assert_allclose(res.v[k], np.r_[rd, w], atol=1e-8)
        np.testing.assert_allclose(res.vdot[k], np.r_[rdd, wd], atol=1e-7)
    assert np.nanmax(np.abs(res.marker_residual)) < 1e-10


def _plane_model(p_BM):
    b = ModelBuilder("plane")
    b.add_body("box", 1.0, [1e-3, 1e-3, 1e-3], position=[0, 0, 0.05])
    b.add_frame("box", "foot", [0, 0, -0.05])
    for k, p in enumerate(p_BM):
        b.add_marker(f"M{k}", "box", p)
    b.add_joint("floor", "point_on_plane", parent="ground.origin", child="box.foot")
    return b.build()


class LiftedMarkers:
    """Markers of a body sliding on the floor, each lifted by its own h_k(t) along z:
    not rigid-body compatible with the floor constraint, so Ψ ≠ 0 (Eqs. 4–10)."""

    time = np.linspace(0, 1, 101)
    p_BM = np.array([[0.05, 0, 0], [0, 0.04, 0], [0, 0, 0.06], [0.03, 0.03, -0.02]])
    lift = np.array([0.004, -0.002, 0.006, 0.001])

    def evaluate(self, t):
        th = 0.5 * np.sin(2 * t)
        R = rotation_matrix(quat_from_rotvec([0, 0, th]))
        r = np.array([0.1 * t, 0.05 * t**2, 0.05])
        p = self.p_BM
        w = np.array([0, 0, np.cos(2 * t)])
        wd = np.array([0, 0, -2 * np.sin(2 * t)])
        wx = np.cross(w, p)
        x = r + p @ R.T
        xd = np.array([0.1, 0.1 * t, 0]) + wx @ R.T
        xdd = np.array([0, 0.1, 0]) + (np.cross(wd, p) + np.cross(w, wx)) @ R.T
        h = np.outer(self.lift * np.sin(3 * t), [0, 0, 1])
        hd = np.outer(3 * self.lift * np.cos(3 * t), [0, 0, 1])
        hdd = np.outer(-9 * self.lift * np.sin(3 * t), [0, 0, 1])
        return x + h, xd + hd, xdd + hdd, np.ones(4, bool)


def _independent_pose(traj, t, guess):
    """min Σ|p_WM(q) − x|² s.t. foot on the floor, by SLSQP over (r, rotation vector)."""
    from scipy.optimize import minimize

    x = traj.evaluate(t)[0]

    def markers(z):
        R = rotation_matrix(quat_from_rotvec(z[3:]))
        return z[:3] + traj.p_BM @ R.T

    def foot_height(z):
        R = rotation_matrix(quat_from_rotvec(z[3:]))
        return (z[:3] + R @ np.array([0, 0, -0.05]))[2]

    sol = minimize(lambda z: np.sum((markers(z) - x) ** 2), guess, method="SLSQP",
                   constraints=[{"type": "eq", "fun": foot_height}], options={"ftol": 1e-16, "maxiter": 500})
    return sol.x


def test_tracking_positions_match_independent_constrained_least_squares():
    traj = LiftedMarkers()
    model = _plane_model(traj.p_BM)
    res = run_tracking(model, traj, traj.time)
    assert res.converged.all()
    assert np.nanmax(np.abs(res.marker_residual)) > 1e-3  # the problem is over-determinate
    for k in (10, 55, 90):
        z = _independent_pose(traj, traj.time[k], np.r_[res.q[k, :3], 0, 0, 0])
        np.testing.assert_allclose(res.q[k, :3], z[:3], atol=1e-7)
        np.testing.assert_allclose(rotation_matrix(res.q[k, 3:7]), rotation_matrix(quat_from_rotvec(z[3:])), atol=1e-6)


def test_tracking_velocity_acceleration_are_derivatives_of_the_least_squares_pose():
    """Eqs. 6–10: with δ̇, δ̈ from central differences, v and v̇ are the time derivatives
    of the least-squares pose q*(t) to O(Δt²); compared with derivatives of independent
    solves on a fine time step."""
    from openfdk.kinematics.system import ConstraintSystem
    from openfdk.kinematics.tracking import MarkerTracker

    traj = LiftedMarkers()
    model = _plane_model(traj.p_BM)
    res = run_tracking(model, traj, traj.time)
    tracker = MarkerTracker(ConstraintSystem(model))
    k = 40
    t, h = traj.time[k], 1e-3
    states = []
    for tt in (t - h, t, t + h):
        s = model.initial_state()
        s.set_q(res.q[k])
        x, _, _, vis = traj.evaluate(tt)
        assert tracker.solve_positions(s, tt, x, vis)[0].converged
        states.append(s)
    r_m, r_0, r_p = (s.p_WB[1] for s in states)
    # body-frame rotation increments R_0ᵀ R_± -> rotation vectors
    from openfdk.numerics.spatial import quat_from_matrix, rotvec_from_quat

    phi_p = rotvec_from_quat(quat_from_matrix(states[1].R_WB[1].T @ states[2].R_WB[1]))
    phi_m = rotvec_from_quat(quat_from_matrix(states[1].R_WB[1].T @ states[0].R_WB[1]))
    v_fd = np.r_[(r_p - r_m) / (2 * h), (phi_p - phi_m) / (2 * h)]
    a_fd = (r_p - 2 * r_0 + r_m) / h**2
    assert np.linalg.norm(v_fd) > 0.05
    np.testing.assert_allclose(res.v[k], v_fd, atol=2e-4)
    np.testing.assert_allclose(res.vdot[k, :3], a_fd, atol=5e-3)


class _Displaced(AnalyticFreeBody):
    """The free body's exact markers, the last one measured ``offset`` (3,) m away."""

    def __init__(self, p_BM, offset):
        super().__init__(p_BM)
        self.offset = np.asarray(offset, float)

    def evaluate(self, t):
        x, xd, xdd, vis = super().evaluate(t)
        x = x.copy()
        x[-1] += self.offset
        return x, xd, xdd, vis


def test_the_summarys_rms_marker_residual_counts_the_tracked_markers_only():
    """Four exact markers tracked and a fifth (weight 0, an IK task with apply false)
    measured 0.3 m from its model marker: the pose is the exact one, the fifth's residual
    is the 0.3 m offset (kinematics.csv keeps it), and the summary's RMS, as OpenSim's IK
    reports its error, is that of the four tracked markers: zero, not √(0.3²/5) = 0.134 m."""
    p_BM = np.array([[0.05, 0, 0], [0, 0.04, 0], [0, 0, 0.06], [0.03, 0.03, -0.02], [0.1, 0.0, 0.1]])
    b = ModelBuilder("free body")
    b.add_body("box", 1.0, [1e-3, 1e-3, 1e-3])
    for k, p in enumerate(p_BM):
        b.add_marker(f"M{k}", "box", p, weight=0.0 if k == 4 else 1.0)
    model = b.build()
    offset = np.array([0.0, 0.3, 0.0])
    traj = _Displaced(p_BM, offset)
    res = run_tracking(model, traj, traj.time[:20])
    assert res.converged.all()
    np.testing.assert_allclose(res.marker_residual[:, 4], np.broadcast_to(-offset, (20, 3)), atol=1e-10)
    assert res.summary()["rms_marker_residual_m"] < 1e-10
    unweighted = float(np.sqrt(np.nanmean(np.sum(res.marker_residual**2, axis=2))))
    assert unweighted == pytest.approx(0.3 / np.sqrt(5), rel=1e-9)


def test_a_tracked_marker_far_off_its_model_marker_is_named_once():
    """Six markers tracked, the sixth measured 0.2 m from its model marker (a mislabelled
    marker): the fit spreads its pull over the others, yet the sixth keeps by far the
    largest residual, above OUTLIER_FACTOR × the median and OUTLIER_MIN, so the run's
    warning names it and no other. With exact markers (every residual ~1e-12 m), and with
    the offset marker's weight 0 (left out of the fit), nothing is flagged."""
    import warnings

    from openfdk.model.plausibility import OUTLIER_FACTOR, OUTLIER_MIN, PlausibilityWarning, outlier_markers, \
        warn_outlier_markers

    p_BM = np.array([[0.05, 0, 0], [0, 0.04, 0], [0, 0, 0.06], [0.03, 0.03, -0.02], [-0.04, 0.02, 0.01],
                     [0.1, 0.0, 0.1]])

    def run(offset, weight):
        b = ModelBuilder("free body")
        b.add_body("box", 1.0, [1e-3, 1e-3, 1e-3])
        for k, p in enumerate(p_BM):
            b.add_marker(f"M{k}", "box", p, weight=weight if k == 5 else 1.0)
        traj = _Displaced(p_BM, offset)
        return run_tracking(b.build(), traj, traj.time[:10])

    kin = run([0.0, 0.2, 0.0], 1.0)
    found = outlier_markers(kin)
    assert [n for n, _, _ in found] == ["M5"]
    (name, rms, median), = found
    assert rms > OUTLIER_FACTOR * median and rms > OUTLIER_MIN
    per_marker = np.sqrt(np.nanmean(np.sum(kin.marker_residual**2, axis=2), axis=0))
    assert rms == pytest.approx(per_marker.max()) and median == pytest.approx(np.median(per_marker))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        warn_outlier_markers(kin)
    assert len(caught) == 1 and issubclass(caught[0].category, PlausibilityWarning) and "M5 " in str(caught[0].message)
    assert outlier_markers(run([0.0, 0.0, 0.0], 1.0)) == []
    assert outlier_markers(run([0.0, 0.2, 0.0], 0.0)) == []
