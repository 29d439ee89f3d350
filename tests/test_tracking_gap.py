"""Accelerations across a marker gap (paper Eq. 10 with the residual rates of Eq. 7).

When a marker drops out, the least-squares pose moves by a step (the remaining markers
weigh a model–marker mismatch differently), so every other marker's residual δ steps too.
Its central second difference (δ_{k+1} − 2δ_k + δ_{k−1})/Δt² then gives ±step/Δt² spikes on
the two frames at the gap edge. Rates are therefore not differenced across a change of
the visible marker set."""

import numpy as np

from openfdk.kinematics.analysis import run_tracking
from openfdk.kinematics.tracking import residual_rates
from openfdk.model.builder import ModelBuilder

P_BM = np.array([[0.05, 0, 0], [0, 0.04, 0], [0, 0, 0.06], [0.03, 0.03, -0.02], [-0.04, 0.01, 0.02]])
MISMATCH = np.array([0.004, -0.003, 0.002])  # model's M0 is 5.4 mm off the real marker
GAP = (3, 0.80, 0.95)  # marker M3 hidden from 0.80 s to 0.95 s


class TranslatingBody:
    """Exact markers of a body translating as r(t) = r0 + c sin(ω t) (no rotation), marker
    M3 hidden in GAP. With a constant model–marker mismatch the least-squares pose is the
    true pose times a constant rigid offset on each side of the gap; with R constant its
    accelerations are exactly [r̈(t); 0] on both sides."""

    time = np.linspace(0.0, 2.0, 201)
    r0, c, omega = np.array([0.1, -0.2, 0.3]), np.array([0.05, 0.02, -0.03]), 3.0

    def evaluate(self, t):
        w = self.omega
        x = self.r0 + self.c * np.sin(w * t) + P_BM
        xd = np.tile(self.c * w * np.cos(w * t), (len(P_BM), 1))
        xdd = np.tile(-self.c * w**2 * np.sin(w * t), (len(P_BM), 1))
        vis = np.ones(len(P_BM), dtype=bool)
        m, t0, t1 = GAP
        if t0 - 1e-9 <= t <= t1 + 1e-9:
            vis[m] = False
            x[m] = xd[m] = xdd[m] = np.nan
        return x, xd, xdd, vis


def _model():
    b = ModelBuilder("free body")
    b.add_body("box", 1.0, [1e-3, 1e-3, 1e-3])
    for k, p in enumerate(P_BM):
        b.add_marker(f"M{k}", "box", p + (MISMATCH if k == 0 else 0.0))
    return b.build()


def test_accelerations_continuous_across_a_marker_gap():
    traj = TranslatingBody()
    res = run_tracking(_model(), traj, traj.time)
    assert res.converged.all()
    t = traj.time
    rdd = -traj.c * traj.omega**2 * np.sin(traj.omega * t)[:, None]
    # the pose does step at the gap edges (the mechanism is present, not vacuous)
    edge = np.searchsorted(t, GAP[1] - 1e-9)  # first frame without M3
    true_step = traj.c * (np.sin(traj.omega * t[edge]) - np.sin(traj.omega * t[edge - 1]))
    assert np.abs(res.q[edge, :3] - res.q[edge - 1, :3] - true_step).max() > 1e-4  # m
    np.testing.assert_allclose(res.vdot[:, :3], rdd, atol=1e-6)  # m/s²
    np.testing.assert_allclose(res.vdot[:, 3:], 0.0, atol=1e-5)  # rad/s²
    np.testing.assert_allclose(res.v[:, :3], traj.c * traj.omega * np.cos(traj.omega * t)[:, None], atol=1e-5)


def test_residual_rates_not_differenced_across_a_visible_set_change():
    dt = 0.01
    prev = np.array([[0.0, 0, 0], [np.nan, np.nan, np.nan]])
    cur = np.array([[1e-4, 0, 0], [2e-4, 0, 0]])  # marker 1 reappears: a new least-squares problem
    nxt = np.array([[3e-4, 0, 0], [3e-4, 0, 0]])
    d1, d2 = residual_rates(prev, cur, nxt, dt)
    np.testing.assert_allclose(d1[:, 0], [(3e-4 - 1e-4) / dt, (3e-4 - 2e-4) / dt])  # forward, both
    np.testing.assert_allclose(d2, 0.0)
    same = np.array([[0.0, 0, 0], [1e-4, 0, 0]])
    d1, d2 = residual_rates(same, cur, nxt, dt)  # same visible set: central differences
    np.testing.assert_allclose(d1[:, 0], [(3e-4 - 0.0) / (2 * dt), (3e-4 - 1e-4) / (2 * dt)])
    np.testing.assert_allclose(d2[:, 0], [(3e-4 - 2e-4 + 0.0) / dt**2, (3e-4 - 4e-4 + 1e-4) / dt**2])


def test_initial_guess_moves_bodies_without_their_own_fit_with_the_model():
    """A lab-frame trial far from the reference pose: the thigh (3 markers) is fitted by
    itself, and the shank (1 marker: no fit of its own) moves with the whole model's
    rigid fit instead of staying at the reference pose — a metre from its joint, where
    Gauss–Newton diverged on the knee Grand Challenge model. Closed form: the markers
    are the reference markers moved by one known rigid transform (R, p), so every body
    must land at R X_ref + p."""
    from openfdk.io.modelfile import model_from_dict
    from openfdk.kinematics.system import ConstraintSystem
    from openfdk.kinematics.tracking import MarkerTracker
    from openfdk.numerics.spatial import rotation_matrix_xyz

    model = model_from_dict({
        "openfdk": 1, "units": {"length": "m", "angle": "rad"},
        "bodies": {
            "thigh": {"mass": 1.0, "inertia": [0.1, 0.1, 0.1], "position": [0, 0.8, 0],
                      "frames": {"knee": [0, -0.2, 0]},
                      "markers": {"T1": [0.05, 0.1, 0], "T2": [-0.04, 0.0, 0.03], "T3": [0.0, -0.1, -0.05]}},
            "shank": {"mass": 1.0, "inertia": [0.1, 0.1, 0.1], "position": [0, 0.4, 0],
                      "frames": {"knee": [0, 0.2, 0]}, "markers": {"S1": [0.05, -0.1, 0.0]}},
        },
        "joints": {"knee": {"type": "revolute", "parent": "thigh.knee", "child": "shank.knee"}},
    }, source="leg.yaml")
    tracker = MarkerTracker(ConstraintSystem(model))
    state = model.initial_state()
    ref = tracker.markers.evaluate(state, 0)[0].reshape(-1, 3)
    R, p = rotation_matrix_xyz(np.array([0.3, -1.2, 2.0])), np.array([1.5, 0.2, -0.7])
    x = ref @ R.T + p
    p0, R0 = state.p_WB.copy(), state.R_WB.copy()
    tracker.initial_guess(state, x, np.ones(len(x), bool))
    for i in state.moving:
        np.testing.assert_allclose(state.R_WB[i], R @ R0[i], atol=1e-12)
        np.testing.assert_allclose(state.p_WB[i], R @ p0[i] + p, atol=1e-12)
    # a thigh marker placed 0.5 m off in the trial: the thigh's own fit (RMS > 2 cm) is not
    # used, and it keeps the whole model's pose
    x_bad = x.copy()
    x_bad[0] += [0.5, 0.0, 0.0]
    state = model.initial_state()
    tracker.initial_guess(state, x_bad, np.ones(len(x), bool))
    # the whole model's least-squares rigid fit, computed independently (scipy)
    from scipy.spatial.transform import Rotation

    rot, _ = Rotation.align_vectors(x_bad - x_bad.mean(0), ref - ref.mean(0))
    R_fit = rot.as_matrix()
    p_fit = x_bad.mean(0) - R_fit @ ref.mean(0)
    for i in state.moving:  # the thigh's own fit (RMS ≈ 0.2 m) was not used: every body moved as one
        np.testing.assert_allclose(state.R_WB[i], R_fit @ R0[i], atol=1e-9)
        np.testing.assert_allclose(state.p_WB[i], R_fit @ p0[i] + p_fit, atol=1e-9)
