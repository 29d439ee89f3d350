"""The small compiled per-frame kernels that replaced Python loops in the trial steps:
pose extrapolation, pose/velocity packing, residual rates (Eq. 7), the assembly of
C f = d (Eq. 12) and the recruitment's input checks — against closed forms and the
NumPy formulas they replaced."""

import numpy as np
import pytest

from openfdk.dynamics.equilibrium import _assemble
from openfdk.kinematics.tracking import residual_rates
from openfdk.model.kernels import extrapolate_poses, get_poses, get_velocities, set_poses, set_velocities
from openfdk.recruitment.result import RecruitmentInputError, check_problem
from openfdk.numerics.spatial import quat_from_rotvec, quat_multiply, rotation_matrix


def _poses(rng, nb=4, moving=(1, 3)):
    p = rng.normal(size=(nb, 3))
    quat = np.array([quat_from_rotvec(rng.normal(size=3)) for _ in range(nb)])
    R = np.array([rotation_matrix(x) for x in quat])
    return p, quat, R, np.array(moving, dtype=np.int64)


def test_extrapolation_is_exact_for_constant_body_rates():
    """A body moving with constant velocity and constant body-frame angular velocity:
    from the poses at t − Δt and t the kernel predicts the pose at t + Δt exactly
    (r(t) = r0 + u t, p(t) = p0 ⊗ exp(½ ω' t))."""
    rng = np.random.default_rng(3)
    r0, u = rng.normal(size=3), rng.normal(size=3)
    p0, w = quat_from_rotvec(rng.normal(size=3)), rng.normal(size=3)

    def pose(t):
        return r0 + u * t, quat_multiply(p0, quat_from_rotvec(w * t))

    dt = 0.01
    r_prev, p_prev = pose(-dt)
    r_now, p_now = pose(0.0)
    r_next, p_next = pose(dt)
    p_WB = np.array([np.zeros(3), r_now])
    quat_WB = np.array([[1.0, 0, 0, 0], p_now])
    R_WB = np.array([np.eye(3), rotation_matrix(p_now)])
    q_prev = np.concatenate([r_prev, p_prev])
    extrapolate_poses(p_WB, quat_WB, R_WB, np.array([1], dtype=np.int64), q_prev)
    np.testing.assert_allclose(p_WB[1], r_next, atol=1e-14)
    np.testing.assert_allclose(quat_WB[1], p_next * np.sign(p_next[0]), atol=1e-14)
    np.testing.assert_allclose(R_WB[1], rotation_matrix(p_next), atol=1e-14)
    assert np.linalg.norm(p_WB[1] - r_now) > 1e-3  # the prediction moved the body
    np.testing.assert_array_equal(p_WB[0], 0.0)  # the fixed body is untouched


def test_pose_and_velocity_packing_round_trip():
    """get_poses / get_velocities invert set_poses / set_velocities (layout of
    BodyStates.get_q, get_v: [r, p] and [ṙ, ω'] per moving body)."""
    rng = np.random.default_rng(4)
    p, quat, R, moving = _poses(rng)
    column = np.array([-1, 0, -1, 6], dtype=np.int64)
    q = np.empty(14)
    get_poses(p, quat, moving, q)
    np.testing.assert_array_equal(q.reshape(2, 7), np.hstack([p[moving], quat[moving]]))
    p2, quat2, R2 = np.zeros_like(p), np.zeros_like(quat), np.zeros_like(R)
    set_poses(q, moving, p2, quat2, R2)
    np.testing.assert_allclose(p2[moving], p[moving], atol=0)
    np.testing.assert_allclose(R2[moving], R[moving], atol=1e-15)
    v = rng.normal(size=12)
    v_WB, w_BB = np.zeros((4, 3)), np.zeros((4, 3))
    set_velocities(v, column, moving, v_WB, w_BB)
    out = np.empty(12)
    get_velocities(v_WB, w_BB, column, moving, out)
    np.testing.assert_array_equal(out, v)


def test_residual_rates_closed_form_and_one_sided():
    """δ(t) = a t² + b t + c sampled at −Δt, 0, Δt: central differences give δ̇(0) = b
    and δ̈(0) = 2a exactly; with a neighbour missing (None) or NaN, the one-sided
    difference and δ̈ = 0, also for every marker when a neighbour's visible set differs;
    a NaN residual gives 0 rates."""
    rng = np.random.default_rng(5)
    a, b, c = rng.normal(size=(3, 4, 3))
    dt = 0.01
    prev, cur, nxt = (a * t * t + b * t + c for t in (-dt, 0.0, dt))
    d1, d2 = residual_rates(prev, cur, nxt, dt)
    np.testing.assert_allclose(d1, b, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(d2, 2 * a, rtol=1e-6, atol=1e-6)
    d1, d2 = residual_rates(None, cur, nxt, dt)
    np.testing.assert_allclose(d1, (nxt - cur) / dt, atol=1e-12)
    np.testing.assert_array_equal(d2, 0.0)
    # marker 1 hidden in the next frame: another visible set, so the next frame counts as
    # missing for every marker (tests/test_tracking_gap.py): backward differences, δ̈ = 0
    gap = nxt.copy()
    gap[1] = np.nan
    d1, d2 = residual_rates(prev, cur, gap, dt)
    np.testing.assert_allclose(d1, (cur - prev) / dt, atol=1e-12)
    np.testing.assert_array_equal(d2, 0.0)
    # a NaN residual in this frame (and in its neighbours: the same visible set) → 0 there,
    # central differences elsewhere
    prev_gap, cur_gap, nxt_gap = prev.copy(), cur.copy(), nxt.copy()
    for arr in (prev_gap, cur_gap, nxt_gap):
        arr[2] = np.nan
    d1, d2 = residual_rates(prev_gap, cur_gap, nxt_gap, dt)
    assert np.all(d1[2] == 0.0) and np.all(d2[2] == 0.0)
    np.testing.assert_allclose(d1[[0, 1, 3]], b[[0, 1, 3]], rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(d2[[0, 1, 3]], 2 * a[[0, 1, 3]], rtol=1e-6, atol=1e-6)


def test_assemble_kernel_matches_the_numpy_formula():
    """C = [−L[:, rows]ᵀ, (sign ∘ A[sel])[:, rows]ᵀ], d = d_full[rows] (Eq. 12)."""
    rng = np.random.default_rng(6)
    n, m, nm = 12, 9, 5
    A, L, d_full = rng.normal(size=(m, n)), rng.normal(size=(nm, n)), rng.normal(size=n)
    rows = np.array([6, 7, 8, 9, 10, 11], dtype=np.int64)
    sel = np.array([2, 0, 5, 8], dtype=np.int64)
    sign = np.array([-1.0, 1.0, 1.0, 1.0])
    C, d = np.empty((6, nm + 4)), np.empty(6)
    _assemble(L, A, rows, sel, sign, d_full, C, d)
    np.testing.assert_array_equal(C[:, :nm], -L[:, rows].T)
    np.testing.assert_array_equal(C[:, nm:], (A[sel] * sign[:, None])[:, rows].T)
    np.testing.assert_array_equal(d, d_full[rows])


@pytest.mark.parametrize("where", ["C", "d", "s_nan", "s_negative"])
def test_recruitment_value_checks_name_the_entry(where):
    """The compiled finiteness/sign checks reject NaN in C or d and a NaN or negative
    strength, naming the column."""
    C, d, s = np.ones((2, 3)), np.ones(2), np.array([1.0, 2.0])
    check_problem(C, d, 2, s)  # valid input passes
    if where == "C":
        C[1, 2] = np.inf
    elif where == "d":
        d[0] = np.nan
    elif where == "s_nan":
        s[1] = np.nan
    else:
        s[1] = -1.0
    match = "finite" if where in ("C", "d") else "column 'b'"
    with pytest.raises(RecruitmentInputError, match=match):
        check_problem(C, d, 2, s, column_names=("a", "b", "c"))
