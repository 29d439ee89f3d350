"""The tracking of a trial whose markers fit the model poorly (kinematics/curvature.py,
TrackingStep): Gauss–Newton converges linearly at a rate that grows with the residuals
(jam-resources' full_body_healthy_knee.osim with its overground_17.trc: 13 mm RMS, 38
steps a frame, 15 frames/s); after a slow frame the Lagrangian's second-order terms at
its pose make the next frames' steps Newton's. The optimum is checked against an
independent least-squares solve of the same fit, written here in minimal coordinates."""

import numpy as np
import pytest
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

import openfdk.kinematics.analysis as kinematics_analysis
from openfdk.kinematics.analysis import run_tracking
from openfdk.fixtures.synthetic import CHAIN_MARKERS, hanging_chain

L, N_SEG = 0.3, 4
#: markers in each segment's frame (m), and where the subject's markers really are: the
#: model's placed 15–25 mm off (a large-residual fit)
P_SM = np.array(CHAIN_MARKERS)
MISPLACED = np.array([[0.015, -0.01, 0.02], [-0.02, 0.015, 0.0], [0.01, 0.02, -0.015]])
TIMES = np.linspace(0.0, 0.5, 26)


def _chain():
    """N_SEG segments hanging from the ground by spherical joints; segment k's origin at
    its middle, its top at (0, 0, L/2) and its tip at (0, 0, −L/2) in its frame."""
    return hanging_chain(N_SEG, L)


def _markers(rotvecs, offsets):
    """(N_SEG·3, 3) m: the chain's markers (each at P_SM + offset in its segment) for the
    segments' world rotation vectors rotvecs (N_SEG, 3)."""
    out, tip = [], np.zeros(3)
    for k in range(N_SEG):
        R = Rotation.from_rotvec(rotvecs[k]).as_matrix()
        origin = tip - R @ np.array([0.0, 0.0, L / 2])
        out.extend(origin + R @ (P_SM[i] + offsets[i]) for i in range(len(P_SM)))
        tip = origin - R @ np.array([0.0, 0.0, L / 2])
    return np.array(out)


def _rotvecs(t):
    """(N_SEG, 3) rad: the subject's segments swinging in time t (s)."""
    k = np.arange(N_SEG)[:, None]
    return np.c_[0.4 * np.sin(2.0 * t + k), 0.3 * np.cos(1.5 * t + 0.5 * k), 0.5 * np.sin(t - k)]


class MisplacedMarkers:
    """The subject's markers: the chain's pose at _rotvecs(t) with every marker
    MISPLACED from where the model has it. Their rates are differenced (they only enter
    Eqs. 8–10, not the poses compared here)."""

    time = TIMES

    def evaluate(self, t):
        x = _markers(_rotvecs(t), MISPLACED)
        h = 1e-5
        xd = (_markers(_rotvecs(t + h), MISPLACED) - _markers(_rotvecs(t - h), MISPLACED)) / (2 * h)
        xdd = (_markers(_rotvecs(t + h), MISPLACED) - 2 * x + _markers(_rotvecs(t - h), MISPLACED)) / h ** 2
        return x, xd, xdd, np.ones(len(x), dtype=bool)


def _independent_fit(t, start):
    """The rotation vectors (N_SEG, 3) minimising Σ |model marker − measured|² at time t:
    scipy's least squares in minimal coordinates from ``start``, to 1e-15."""
    x = MisplacedMarkers().evaluate(t)[0]
    zero = np.zeros_like(MISPLACED)
    sol = least_squares(lambda r: (_markers(r.reshape(N_SEG, 3), zero) - x).ravel(), start.ravel(),
                        xtol=1e-15, ftol=1e-15, gtol=1e-15, method="lm")
    return sol.x.reshape(N_SEG, 3)


@pytest.fixture(scope="module")
def runs():
    """The window tracked with the second-order terms (the default) and with Gauss–Newton
    steps alone (the threshold out of reach)."""
    model = _chain()
    out = {"newton": run_tracking(model, MisplacedMarkers(), TIMES)}
    keep = kinematics_analysis.CURVATURE_ITERATIONS
    kinematics_analysis.CURVATURE_ITERATIONS = 10 ** 9
    try:
        out["gauss_newton"] = run_tracking(model, MisplacedMarkers(), TIMES)
    finally:
        kinematics_analysis.CURVATURE_ITERATIONS = keep
    return out


def test_the_fit_is_a_large_residual_one_that_gauss_newton_converges_slowly_on(runs):
    gn = runs["gauss_newton"]
    assert gn.converged.all()
    assert np.median(gn.iterations) > kinematics_analysis.CURVATURE_ITERATIONS  # linear convergence


def test_newton_steps_after_a_slow_frame_take_fewer_iterations(runs):
    newton, gn = runs["newton"], runs["gauss_newton"]
    assert newton.converged.all()
    assert newton.iterations[0] == gn.iterations[0]  # the first frame: no curvature yet
    # (210 against 338 steps: the terms age as the chain swings away from the pose they
    # were taken at, until a frame needs more than CURVATURE_ITERATIONS steps again)
    assert newton.iterations[1:].sum() <= 0.7 * gn.iterations[1:].sum(), (newton.iterations, gn.iterations)


def test_both_reach_the_independent_least_squares_optimum(runs):
    """Every frame's segment rotations equal scipy's minimiser of the same fit to 1e-7
    rad, with and without the second-order terms."""
    model = _chain()
    rotvecs = {}
    for name, res in runs.items():
        q = res.q.reshape(len(TIMES), N_SEG, 7)  # per body: r (m), quaternion (w, x, y, z)
        rotvecs[name] = np.array([[Rotation.from_quat(np.r_[qk[4:7], qk[3]]).as_rotvec() for qk in frame]
                                  for frame in q])
    assert len(model.bodies) == N_SEG + 1
    worst = 0.0
    for j, t in enumerate(TIMES):
        ref = _independent_fit(t, rotvecs["newton"][j])
        R_ref = Rotation.from_rotvec(ref)
        for name in runs:
            err = (Rotation.from_rotvec(rotvecs[name][j]) * R_ref.inv()).magnitude()
            worst = max(worst, float(err.max()))
    assert worst < 1e-7, worst
    # and the fit is not the subject's pose: the misplaced markers moved it
    moved = (Rotation.from_rotvec(rotvecs["newton"][0]) * Rotation.from_rotvec(_rotvecs(TIMES[0])).inv()).magnitude()
    assert moved.max() > 1e-2
