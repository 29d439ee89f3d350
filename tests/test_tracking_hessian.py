"""The tracking Lagrangian's Hessian: by compressed differences
(kinematics.kkt.hessian_pattern, numerics.numdiff.column_groups; the analytic FDK
Jacobian's kinematic sensitivity differences the gradient Ψ_q̂ᵀ W Ψ + Φ_q̂ᵀ λ once per
group of coordinates whose rows do not overlap, instead of once per coordinate), and its
second-order terms as the position solves' Newton steps (MarkerTracker.solve_positions,
``second_order``)."""

import numpy as np

from openfdk.kinematics.kkt import hessian_pattern
from openfdk.kinematics.tracking_hessian import OK, group_arrays, tracking_hessian
from openfdk.kinematics.system import ConstraintSystem
from openfdk.fixtures.synthetic import hanging_chain
from openfdk.kinematics.tracking import MarkerTracker
from openfdk.numerics.numdiff import column_groups, manifold_jacobian

L, N_SEG = 0.3, 5


def _chain():
    """N_SEG segments hanging from the ground by spherical joints, three markers each."""
    return hanging_chain(N_SEG, L, name="chain5")


def _lagrangian_gradient(seed=0, parts=False):
    """(gradient(state) -> (n,), state, Φ_q̂ (m, n)) of the tracking Lagrangian at a
    displaced pose, random measured markers and multipliers λ; with ``parts`` also
    (system, tracker, w (3 nm,), x (3 nm,) m, λ (m,))."""
    rng = np.random.default_rng(seed)
    model = _chain()
    system = ConstraintSystem(model)
    tracker = MarkerTracker(system)
    state = model.initial_state()
    state.displace(rng.normal(0.0, 0.05, state.n_coords))
    n_m = len(model.markers.names) if hasattr(model.markers, "names") else 3 * N_SEG
    x = tracker.markers.positions(state) + rng.normal(0.0, 0.01, (n_m, 3))
    w = tracker._weights(np.ones(n_m, dtype=bool))
    _, A, _, _ = system.evaluate(state, 0.0, None, order=1)
    lam = rng.normal(0.0, 10.0, A.shape[0])

    def gradient(s):
        p, J, _ = tracker.markers.evaluate(s, 1)
        _, As, _, _ = system.evaluate(s, 0.0, None, order=1)
        return J.T @ (w * (p - x.ravel())) + As.T @ lam

    if parts:
        return gradient, state, A, (system, tracker, w, x.ravel(), lam)
    return gradient, state, A


def test_the_pattern_of_a_chain_couples_neighbouring_segments_only():
    _, state, A = _lagrangian_gradient()
    pattern, touched = hessian_pattern(A)
    assert touched.shape == (A.shape[0], N_SEG)
    body = np.arange(state.n_coords) // 6
    expected = np.abs(body[:, None] - body[None, :]) <= 1  # joint k couples s_{k−1} and s_k
    np.testing.assert_array_equal(pattern, expected)


def test_compressed_differences_equal_one_coordinate_at_a_time():
    gradient, state, A = _lagrangian_gradient()
    pattern, _ = hessian_pattern(A)
    groups = column_groups(pattern)
    assert len(groups) == 6 * 3  # three colours of a chain's segments (distance 2), six coordinates each
    calls = []

    def counted(s):
        calls.append(1)
        return gradient(s)

    g0 = gradient(state)
    H_full = manifold_jacobian(gradient, state, eps=1e-7, central=False, f0=g0)
    H = manifold_jacobian(counted, state, eps=1e-7, central=False, f0=g0, pattern=pattern, groups=groups)
    assert len(calls) == len(groups) < state.n_coords
    scale = np.abs(H_full).max()
    assert scale > 1.0 and np.count_nonzero(H_full[pattern]) > 0.5 * pattern.sum()
    assert np.abs(H_full[~pattern]).max() <= 1e-12 * scale  # nothing outside the pattern
    np.testing.assert_allclose(H, H_full, rtol=0, atol=1e-12 * scale)
    # the state is restored
    np.testing.assert_array_equal(gradient(state), g0)


def test_the_compiled_hessian_equals_the_differenced_python_gradient():
    """kinematics/tracking_hessian.py: the marker rows' gradient in closed form and the
    compiled constraint program, differenced in one call, against the gradient through
    the Python marker and constraint evaluations (forward, the same groups and step) and
    against central differences one coordinate at a time (O(ε²), ε = 1e-5)."""
    gradient, state, A, (system, tracker, w, x, lam) = _lagrangian_gradient(seed=3, parts=True)
    pattern, _ = hessian_pattern(A)
    groups = column_groups(pattern)
    ptr, cols = group_arrays(groups)
    g0 = gradient(state)
    poses = (state.p_WB.copy(), state.quat_WB.copy(), state.R_WB.copy())
    H = np.full((state.n_coords, state.n_coords), np.nan)
    prog = system.program
    status, _, _ = tracking_hessian(*prog.program, prog.n_node_rows, state.p_WB, state.quat_WB, state.R_WB,
                                    state.w_BB, state.v_WB, state.column, state.moving, tracker.markers.body,
                                    tracker.markers.p_BM, w, x, lam, g0, ptr, cols, pattern, 1e-7, H)
    assert status == OK
    for before, after in zip(poses, (state.p_WB, state.quat_WB, state.R_WB)):
        np.testing.assert_array_equal(before, after)  # the poses are left as they were
    H_py = manifold_jacobian(gradient, state, eps=1e-7, central=False, f0=g0, pattern=pattern, groups=groups)
    scale = np.abs(H_py).max()
    assert scale > 1.0 and np.count_nonzero(H[pattern]) > 0.5 * pattern.sum()
    np.testing.assert_allclose(H, H_py, rtol=0, atol=1e-7 * scale)
    H_central = manifold_jacobian(gradient, state, eps=1e-5, central=True)
    np.testing.assert_allclose(H, H_central, rtol=0, atol=2e-5 * scale)


def test_column_groups_of_a_tridiagonal_pattern_are_the_residues_mod_3():
    n = 10
    pattern = np.abs(np.arange(n)[:, None] - np.arange(n)[None, :]) <= 1
    groups = column_groups(pattern)
    assert [g.tolist() for g in groups] == [list(range(r, n, 3)) for r in range(3)]
    for g in groups:  # no row shared within a group
        assert pattern[:, g].sum(axis=1).max() <= 1


def _noisy_fit(rng):
    """(model, system, tracker, visible, start, x (n_markers, 3) m): the chain assembled at
    a pose 1 cm / 10 mrad from its initial one, and its markers there with 1 cm noise (a
    large-residual fit)."""
    model = _chain()
    system = ConstraintSystem(model)
    tracker = MarkerTracker(system)
    n_m = 3 * N_SEG
    visible = np.ones(n_m, dtype=bool)
    start = model.initial_state()
    start.displace(rng.normal(0.0, 0.01, start.n_coords))
    assert tracker.solve_positions(start, 0.0, tracker.markers.positions(start), visible)[0].converged  # assembled
    x = tracker.markers.positions(start) + rng.normal(0.0, 0.01, (n_m, 3))
    return model, system, tracker, visible, start, x


def test_newton_steps_with_nearby_curvature_reach_the_same_pose_in_fewer_iterations():
    """A large-residual fit (1 cm marker noise) of the chain: Gauss–Newton converges
    linearly; with the Lagrangian Hessian's second-order terms S = H − Ψ_q̂ᵀ W Ψ_q̂ (H
    differenced at a pose 1 mm away) the steps are Newton's. Both reach the same pose to
    the tolerance, and the KKT matrix handed on (Eqs. 8–10) is Gauss–Newton's either way."""
    rng = np.random.default_rng(4)
    model, system, tracker, visible, start, x = _noisy_fit(rng)

    plain = start.copy()
    res_gn, K_gn, lam = tracker.solve_positions(plain, 0.0, x, visible)
    assert res_gn.converged and res_gn.iterations >= 10  # linear convergence

    # S at a pose 1 mm / 1 mrad from the solution, with the solution's multipliers
    near = plain.copy()
    near.displace(rng.normal(0.0, 1e-3, near.n_coords))
    w = tracker._weights(visible)

    def gradient(s):
        p, J, _ = tracker.markers.evaluate(s, 1)
        _, As, _, _ = system.evaluate(s, 0.0, None, order=1)
        return J.T @ (w * (p - x.ravel())) + As.T @ lam

    H = manifold_jacobian(gradient, near, eps=1e-7, central=True)
    _, J_near, _ = tracker.markers.evaluate(near, 1)
    S = H - J_near.T @ (w[:, None] * J_near)
    assert np.abs(S).max() > 1e-3 * np.abs(H).max()  # the terms Gauss–Newton leaves out are not negligible

    newton = start.copy()
    res_n, K_n, _ = tracker.solve_positions(newton, 0.0, x, visible, second_order=S)
    assert res_n.converged and res_n.iterations <= res_gn.iterations - 2
    np.testing.assert_allclose(newton.p_WB, plain.p_WB, rtol=0, atol=1e-8)
    np.testing.assert_allclose(newton.R_WB, plain.R_WB, rtol=0, atol=1e-8)
    scale = np.abs(K_gn).max()
    np.testing.assert_allclose(K_n, K_gn, rtol=0, atol=1e-6 * scale)  # K at poses 1e-9 apart, without S


def test_chord_steps_with_a_nearby_factorization_reach_the_same_optimum():
    """kinematics.kkt.kkt_chord_step: the stationarity residual F = [Ψ_q̂ᵀ W (p − x) +
    Φ_q̂ᵀ λ; Φ] at the current pose, solved with the factors of the KKT matrix of a pose
    1 mm / 1 mrad away (kkt_step there, with the second-order terms S: Newton's matrix).
    From 0.1 mm off the chain's 1 cm-noise fit the
    steps contract at least fourfold each (linearly: the matrix is not the current one),
    and reach the fit's pose and multipliers of the plain solve to 1e-10. A chord step
    assembles no K; the tracking kernel, whose last step is a chord step, returns K
    assembled at that step's pose, equal to kkt_step's there (it is handed to Eqs. 8–10)."""
    from openfdk.kinematics.kkt import kkt_chord_step, kkt_pattern, kkt_step

    rng = np.random.default_rng(7)
    model, system, tracker, visible, start, x = _noisy_fit(rng)
    x = x.ravel()
    tight = MarkerTracker(system, type(tracker.settings)(tol_step=1e-13, tol_constraint=1e-13, max_iter=200))
    fit = start.copy()
    res, _, lam_fit = tight.solve_positions(fit, 0.0, x.reshape(-1, 3), visible)
    assert res.converged
    w = tracker._weights(visible)
    n, m = fit.n_coords, system.n_rows

    def kkt_inputs(s):
        p, J, _ = tracker.markers.evaluate(s, 1)
        Phi, A, _, _ = system.evaluate(s, 0.0, None, order=1)
        return np.ascontiguousarray(J), w, p, x, np.ascontiguousarray(A), Phi

    far = fit.copy()
    far.displace(rng.normal(0.0, 1e-3, n))

    def gradient(s):
        J, _, p, _, A, _ = kkt_inputs(s)
        return J.T @ (w * (p - x)) + A.T @ lam_fit

    J_far = kkt_inputs(far)[0]
    S = manifold_jacobian(gradient, far, eps=1e-7, central=True) - J_far.T @ (w[:, None] * J_far)
    LU, piv, K = np.empty((n + m, n + m)), np.empty(n + m, np.int64), np.empty((n + m, n + m))
    # factorized in the tracker's reverse Cuthill–McKee order (kinematics/envelope_lu.py)
    perm, first, last = tracker.kkt_order, np.empty(n + m, np.int64), np.empty(n + m, np.int64)
    assert np.any(perm != np.arange(n + m))
    _, _, _ = kkt_step(*kkt_inputs(far), K, S, True, LU, piv, perm, first, last)  # Newton's matrix, 1 mm away
    # the structural pattern the order came from holds every non-zero of K and S
    J_f, _, _, _, A_f, _ = kkt_inputs(far)
    pattern = kkt_pattern(J_f, A_f)
    assert not np.any((K != 0.0) & ~pattern) and not np.any((S != 0.0) & ~pattern[:n, :n])
    assert not pattern[n:, n:].any() and not pattern.all()
    state = fit.copy()
    state.displace(rng.normal(0.0, 1e-4, n))
    lam = lam_fit * (1.0 + 1e-3 * rng.normal(size=m))
    steps = []
    for _ in range(12):
        sol, step, _ = kkt_chord_step(*kkt_inputs(state), lam, LU, piv, perm, first, last)
        state.displace(sol[:n])
        lam = lam + sol[n:]
        steps.append(step)
        if step < 1e-12:
            break
    assert steps[0] > 1e-6 and all(b <= 0.25 * a for a, b in zip(steps, steps[1:]) if a > 1e-11), steps
    assert len(steps) >= 3  # linear, not one Newton step
    np.testing.assert_allclose(state.p_WB, fit.p_WB, rtol=0, atol=1e-10)
    np.testing.assert_allclose(state.R_WB, fit.R_WB, rtol=0, atol=1e-10)
    np.testing.assert_allclose(lam, lam_fit, rtol=0, atol=1e-8 * np.abs(lam_fit).max())
    # the kernel from 0.1 mm off: a factorized step, then chord steps to the end
    state = fit.copy()
    state.displace(rng.normal(0.0, 1e-4, n))
    before = state.copy()
    res, K_out, _ = tracker.solve_positions(state, 0.0, x.reshape(-1, 3), visible)
    assert res.converged and res.iterations >= 3
    # K at the pose where the last step started: that step was below 1e-12 (chord), so
    # K equals kkt_step's at the final pose to that step's size
    K_step = np.empty_like(K)
    kkt_step(*kkt_inputs(state), K_step, np.zeros((n, n)), False, np.empty_like(LU), piv.copy(), perm, first.copy(),
             last.copy())
    np.testing.assert_allclose(K_out, K_step, rtol=0, atol=1e-9 * np.abs(K_step).max())
    K_start = np.empty_like(K)
    kkt_step(*kkt_inputs(before), K_start, np.zeros((n, n)), False, np.empty_like(LU), piv.copy(), perm, first.copy(),
             last.copy())
    assert np.abs(K_start - K_step).max() > 1e3 * np.abs(K_out - K_step).max()  # not the first step's K


def test_a_solve_on_carried_factors_reaches_the_same_optimum_without_factorizing():
    """kinematics.tracking.KKTFactors: the factors a position solve leaves serve the next
    solve of a nearby pose (FDK's evaluations of one frame). From 0.1 mm off the chain's
    fit of markers with 0.1 mm noise, a solve (to the default 1e-9 step) on the factors
    of another such solve reaches the tight fit's pose to 1e-9 and its multipliers with
    chord steps only: the factors are not touched. Factors of a pose 0.2 rad away stop
    contracting; the solve then factorizes at its own pose and reaches the same optimum."""
    from openfdk.kinematics.tracking import KKTFactors

    rng = np.random.default_rng(11)
    model, system, tracker, visible, start, _ = _noisy_fit(rng)
    x = tracker.markers.positions(start) + rng.normal(0.0, 1e-4, (3 * N_SEG, 3))
    settings = type(tracker.settings)(tol_step=1e-13, tol_constraint=1e-13, max_iter=200)
    tight = MarkerTracker(system, settings)
    fit = start.copy()
    res, _, lam_fit = tight.solve_positions(fit, 0.0, x, visible)
    assert res.converged
    n, m = fit.n_coords, system.n_rows

    def near_fit():
        s = fit.copy()
        s.displace(rng.normal(0.0, 1e-4, n))
        return s

    factors = KKTFactors(n + m)
    assert not factors.held[0]
    first = near_fit()
    res, _, _ = tracker.solve_positions(first, 0.0, x, visible, factors=factors)
    assert res.converged and factors.held[0]  # the first solve factorized
    LU = factors.LU.copy()
    state = near_fit()
    res, K_out, lam = tracker.solve_positions(state, 0.0, x, visible, factors=factors)
    assert res.converged and res.iterations >= 2
    np.testing.assert_array_equal(factors.LU, LU)  # chord steps only
    np.testing.assert_allclose(state.p_WB, fit.p_WB, rtol=0, atol=1e-9)
    np.testing.assert_allclose(state.R_WB, fit.R_WB, rtol=0, atol=1e-9)
    np.testing.assert_allclose(lam, lam_fit, rtol=0, atol=1e-6 * np.abs(lam_fit).max())
    # the KKT matrix handed on (Eqs. 8–10) is the one at the solved pose, as without factors
    K_plain = tracker.solve_positions(near_fit(), 0.0, x, visible)[1]
    np.testing.assert_allclose(K_out, K_plain, rtol=0, atol=1e-7 * np.abs(K_plain).max())
    # factors of a pose far away: the solve factorizes again and reaches the same optimum
    far = fit.copy()
    far.displace(rng.normal(0.0, 0.2, n))
    far_factors = KKTFactors(n + m)
    tracker.solve_positions(far.copy(), 0.0, tracker.markers.positions(far), visible, factors=far_factors)
    LU_far = far_factors.LU.copy()
    state = near_fit()
    res, _, lam = tracker.solve_positions(state, 0.0, x, visible, factors=far_factors)
    assert res.converged and not np.allclose(far_factors.LU, LU_far, rtol=1e-3, atol=0)
    np.testing.assert_allclose(state.p_WB, fit.p_WB, rtol=0, atol=1e-9)
    np.testing.assert_allclose(lam, lam_fit, rtol=0, atol=1e-6 * np.abs(lam_fit).max())


def test_saved_factors_round_trip_and_a_checkpoint_s_are_checked_before_use():
    """KKTFactors.saved / from_saved: a checkpoint carries the factors as plain arrays
    and gets the same factors back; from an untrusted checkpoint, factors of another size,
    pivots or envelope ends outside the matrix (the compiled solves do not check bounds)
    or multipliers of another length are a ValueError (the resume refuses the
    checkpoint), not an out-of-bounds read."""
    import pytest

    from openfdk.kinematics.tracking import KKTFactors

    rng = np.random.default_rng(3)
    model, system, tracker, visible, start, x = _noisy_fit(rng)
    n, m = start.n_coords, system.n_rows
    factors = KKTFactors(n + m)
    assert tracker.solve_positions(start.copy(), 0.0, x, visible, factors=factors)[0].converged
    back = KKTFactors.from_saved(factors.saved(), n + m, m)
    for a, b in ((back.LU, factors.LU), (back.piv, factors.piv), (back.first, factors.first),
                 (back.last, factors.last), (back.lam, factors.lam), (back.held, factors.held)):
        np.testing.assert_array_equal(a, b)
    LU, piv, first, last, held, lam = factors.saved()
    bad = [((LU[:-1, :-1], piv, first, last, held, lam), "another size"),
           ((LU, piv[:-1], first, last, held, lam), "another size"),
           ((LU, np.where(np.arange(n + m) == 3, n + m, piv), first, last, held, lam), "outside 0"),
           ((LU, piv, first - 1, last, held, lam), "outside 0"),
           ((LU, piv, first, last.astype(float), held, lam), "outside 0"),
           ((LU, piv, first, last, held, lam[:-1]), "multipliers")]
    for saved, message in bad:
        with pytest.raises(ValueError, match=message):
            KKTFactors.from_saved(saved, n + m, m)
