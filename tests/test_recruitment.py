"""Tests of the muscle recruitment solvers (paper Eq. 11).

Reference numbers come from closed forms derived in the comments, from independent
general-purpose solvers (Clarabel conic IPM, scipy's SLSQP, HiGHS), from finite
differences, and from the optimality conditions. All randomness is seeded.
"""

from __future__ import annotations

import clarabel
import numpy as np
import pytest
import scipy.sparse as sp
from scipy.optimize import linprog, minimize

from openfdk.bench.recruitment import random_body_problem
from openfdk.recruitment import (
    RankDeficientFreeColumnsError,
    RecruitmentInputError,
    recruitment_sensitivity,
    solve_minmax,
    solve_polynomial,
    solve_quadratic_daqp,
)

# ---------------------------------------------------------------------------------------
# problem generators


def generic_problem(rng, loaded=False):
    """Random C (m × n) with 0–3 free columns; d from admissible activities.

    loaded=True uses activities 0.5–1 on few muscles, so that upper bounds become active.
    """
    m = int(rng.integers(2, 9))
    n_free = int(rng.integers(0, min(3, m - 1) + 1))
    if loaded:
        n_bounded = int(m - n_free + rng.integers(2, 6))
    else:
        n_bounded = int(rng.integers(m - n_free + 1, 40))
    C = rng.normal(size=(m, n_bounded + n_free))
    s = rng.uniform(20.0, 300.0, n_bounded)
    if loaded:
        activity = rng.uniform(0.5, 1.0, n_bounded)
    else:
        activity = rng.uniform(0.0, rng.uniform(0.2, 0.9), n_bounded)
    weak = rng.choice(n_bounded, size=int(rng.integers(0, 3)), replace=False)
    s[weak] = rng.uniform(1.0, 5.0, weak.size)
    d = C[:, :n_bounded] @ (s * activity) + C[:, n_bounded:] @ rng.normal(0.0, 100.0, n_free)
    return C, d, n_bounded, s


def mixed_problems(seed, count):
    """Generic, loaded-generic and rigid-body problems (muscles + free joint forces)."""
    rng = np.random.default_rng(seed)
    problems = []
    for k in range(count):
        if k % 3 == 0:
            problems.append(generic_problem(rng))
        elif k % 3 == 1:
            problems.append(generic_problem(rng, loaded=True))
        else:
            problems.append(random_body_problem(rng, n_unilateral=0,
                                                load=rng.uniform(0.2, 0.9),
                                                weak_muscles=int(rng.integers(0, 4))))
    return problems


# ---------------------------------------------------------------------------------------
# independent reference solvers


def _clarabel_settings(tight):
    """Clarabel settings; ``tight`` (QP, LP) asks for 1e-12, the cone programme 1e-10 (at
    1e-12 Clarabel stops with "InsufficientProgress" on the cubic cones)."""
    settings = clarabel.DefaultSettings()
    settings.verbose = False
    settings.max_iter = 400
    settings.tol_gap_abs = 1e-16
    settings.tol_gap_rel = 1e-12 if tight else 1e-10
    settings.tol_feas = 1e-12 if tight else 1e-10
    if tight:
        settings.tol_ktratio = 1e-10
    return settings


def _scaled(C, n_bounded, s):
    """Columns of C in the activities x = f_B/s (bounded) and the free forces."""
    return np.hstack([C[:, :n_bounded] * s, C[:, n_bounded:]])


def clarabel_quadratic(C, d, n_bounded, s):
    """min Σ x² s.t. [C_B diag(s), C_F] v = d, 0 ≤ x ≤ 1 as a Clarabel QP. Returns f."""
    n_eq, n_var = C.shape
    n_free = n_var - n_bounded
    P = sp.diags(np.concatenate([2.0 * np.ones(n_bounded), np.zeros(n_free)])).tocsc()
    select = np.hstack([np.eye(n_bounded), np.zeros((n_bounded, n_free))])
    # Clarabel: A v + slack = b, slack ∈ cone
    A = sp.csc_matrix(np.vstack([_scaled(C, n_bounded, s), -select, select]))
    b = np.concatenate([d, np.zeros(n_bounded), np.ones(n_bounded)])
    cones = [clarabel.ZeroConeT(n_eq), clarabel.NonnegativeConeT(2 * n_bounded)]
    solution = clarabel.DefaultSolver(P, np.zeros(n_var), A, b, cones,
                                      _clarabel_settings(tight=True)).solve()
    assert str(solution.status) == "Solved"
    v = np.array(solution.x)
    return np.concatenate([v[:n_bounded] * s, v[n_bounded:]])


def clarabel_cubic(C, d, n_bounded, s):
    """min Σ x³ as a second-order-cone programme (Clarabel). Returns (f, status).

    Epigraph t_i ≥ x_i³ for x_i ≥ 0, derived: introduce u_i ≥ x_i²; then
    x³ ≤ t ⇔ x⁴ ≤ t x ⇐ u² ≤ t x (and u = x² attains it), so
        x² ≤ u·1   and   u² ≤ t·x,
    two rotated cones. A rotated cone c² ≤ a b (a, b ≥ 0) is the second-order cone
    ‖(2c, a − b)‖ ≤ a + b, since (a + b)² − (a − b)² = 4ab. Hence
        (u + 1, u − 1, 2x) ∈ SOC₃   and   (t + x, t − x, 2u) ∈ SOC₃.
    Variables v = [x (n_B), f_F, t (n_B), u (n_B)]; minimise Σ t.
    """
    n_eq, n_var = C.shape
    N = n_var + 2 * n_bounded
    i_t, i_u = n_var, n_var + n_bounded
    cost = np.concatenate([np.zeros(n_var), np.ones(n_bounded), np.zeros(n_bounded)])
    select = np.zeros((n_bounded, N))
    select[:, :n_bounded] = np.eye(n_bounded)
    rows = [np.hstack([_scaled(C, n_bounded, s), np.zeros((n_eq, 2 * n_bounded))]),
            select, -select]
    b = [d, np.ones(n_bounded), np.zeros(n_bounded)]
    cones = [clarabel.ZeroConeT(n_eq), clarabel.NonnegativeConeT(2 * n_bounded)]
    for i in range(n_bounded):
        # slack = b − A v = (u + 1, u − 1, 2x)
        R = np.zeros((3, N))
        R[0, i_u + i] = R[1, i_u + i] = -1.0
        R[2, i] = -2.0
        rows.append(R)
        b.append(np.array([1.0, -1.0, 0.0]))
        cones.append(clarabel.SecondOrderConeT(3))
        # slack = (t + x, t − x, 2u)
        R = np.zeros((3, N))
        R[0, i_t + i] = R[1, i_t + i] = -1.0
        R[0, i] = -1.0
        R[1, i] = 1.0
        R[2, i_u + i] = -2.0
        rows.append(R)
        b.append(np.zeros(3))
        cones.append(clarabel.SecondOrderConeT(3))
    solution = clarabel.DefaultSolver(sp.csc_matrix((N, N)), cost, sp.csc_matrix(np.vstack(rows)),
                                      np.concatenate(b), cones, _clarabel_settings(tight=False)).solve()
    v = np.array(solution.x)
    return np.concatenate([v[:n_bounded] * s, v[n_bounded:n_var]]), str(solution.status)


def clarabel_minmax(C, d, n_bounded, s):
    """min β s.t. equilibrium, 0 ≤ x ≤ 1, x ≤ β, as a Clarabel LP. Returns β."""
    n_eq, n_var = C.shape
    n_free = n_var - n_bounded
    N = n_var + 1
    cost = np.zeros(N)
    cost[-1] = 1.0
    select = np.zeros((n_bounded, N))
    select[:, :n_bounded] = np.eye(n_bounded)
    x_minus_beta = select.copy()
    x_minus_beta[:, -1] = -1.0
    A = np.vstack([np.hstack([_scaled(C, n_bounded, s), np.zeros((n_eq, 1))]),
                   -select, select, x_minus_beta])
    b = np.concatenate([d, np.zeros(n_bounded), np.ones(n_bounded), np.zeros(n_bounded)])
    cones = [clarabel.ZeroConeT(n_eq), clarabel.NonnegativeConeT(3 * n_bounded)]
    solution = clarabel.DefaultSolver(sp.csc_matrix((N, N)), cost, sp.csc_matrix(A), b, cones,
                                      _clarabel_settings(tight=True)).solve()
    assert str(solution.status) == "Solved"
    assert n_free >= 0
    return float(solution.x[-1])


def slsqp_polynomial(C, d, n_bounded, s, p):
    """min Σ x^p with scipy's SLSQP (sequential quadratic programming). Returns f."""
    n_var = C.shape[1]
    Cs = _scaled(C, n_bounded, s)
    v0 = np.linalg.lstsq(Cs, d, rcond=None)[0]
    v0[:n_bounded] = np.clip(v0[:n_bounded], 0.0, 1.0)
    result = minimize(
        lambda v: np.sum(v[:n_bounded] ** p), v0,
        jac=lambda v: np.concatenate([p * v[:n_bounded] ** (p - 1.0), np.zeros(n_var - n_bounded)]),
        constraints=[{"type": "eq", "fun": lambda v: Cs @ v - d, "jac": lambda v: Cs}],
        bounds=[(0.0, 1.0)] * n_bounded + [(None, None)] * (n_var - n_bounded),
        method="SLSQP", options={"ftol": 1e-16, "maxiter": 1000},
    )
    v = result.x
    return np.concatenate([v[:n_bounded] * s, v[n_bounded:]])


def objective(f, n_bounded, s, p):
    return float(np.sum((f[:n_bounded] / s) ** p))


def assert_admissible(result, C, d, s, rtol=1e-9):
    """Equilibrium and bounds hold for the returned forces."""
    n_bounded = result.n_bounded
    scale = np.max(np.abs(d)) + np.max(np.abs(C) @ np.abs(result.f))
    assert np.max(np.abs(C @ result.f - d)) <= rtol * scale
    assert np.all(result.f[:n_bounded] >= 0.0)
    assert np.all(result.f[:n_bounded] <= s * (1.0 + 1e-12))


# ---------------------------------------------------------------------------------------
# cross-checks against independent solvers


def test_quadratic_matches_clarabel_qp_on_random_problems():
    problems = mixed_problems(seed=11, count=210)
    n_active_upper = 0
    for C, d, n_bounded, s in problems:
        result = solve_polynomial(C, d, n_bounded, s, p=2.0)
        assert result.converged, result.message
        assert_admissible(result, C, d, s)
        f_ref = clarabel_quadratic(C, d, n_bounded, s)
        G_ref = objective(f_ref, n_bounded, s, 2.0)
        assert abs(result.objective - G_ref) <= 1e-6 * G_ref
        assert np.max(np.abs(result.f - f_ref)) <= 1e-6 * np.max(np.abs(f_ref))
        n_active_upper += int(result.active_upper.any())
    assert n_active_upper >= 25  # the set exercises saturated muscles


def test_cubic_objective_matches_clarabel_second_order_cone():
    problems = mixed_problems(seed=12, count=210)
    n_compared = 0
    n_active_upper = 0
    for C, d, n_bounded, s in problems:
        result = solve_polynomial(C, d, n_bounded, s, p=3.0)
        assert result.converged, result.message
        assert_admissible(result, C, d, s)
        f_ref, status = clarabel_cubic(C, d, n_bounded, s)
        G_ref = objective(f_ref, n_bounded, s, 3.0)
        # openfdk's optimum is never worse than the reference's (both are admissible)
        assert result.objective <= G_ref * (1.0 + 1e-9)
        if status == "Solved":
            assert abs(result.objective - G_ref) <= 1e-6 * G_ref
            n_compared += 1
        n_active_upper += int(result.active_upper.any())
    assert n_compared >= 200  # Clarabel reports "AlmostSolved" on very few of them
    assert n_active_upper >= 10


@pytest.mark.parametrize("p", [3.0, 4.0])
def test_polynomial_forces_match_slsqp(p):
    # Clarabel's forces near x = 0 are limited by the cone apex (u = x² = 0) to ~1e-5, so
    # the forces are compared with an SQP active-set solver that identifies bounds exactly
    # (SLSQP needs ~0.1–0.3 s per problem at ftol 1e-16, hence the smaller set)
    problems = mixed_problems(seed=13, count=15 if p == 3.0 else 6)
    rng = np.random.default_rng(14)
    problems += [random_body_problem(rng, load=rng.uniform(0.2, 1.0)) for _ in range(5)]
    for C, d, n_bounded, s in problems:
        result = solve_polynomial(C, d, n_bounded, s, p=p)
        assert result.converged, result.message
        f_ref = slsqp_polynomial(C, d, n_bounded, s, p)
        G_ref = objective(f_ref, n_bounded, s, p)
        assert result.objective <= G_ref * (1.0 + 1e-9)
        assert abs(result.objective - G_ref) <= 1e-6 * G_ref
        assert np.max(np.abs(result.f - f_ref)) <= 1e-6 * np.max(np.abs(f_ref))


def test_minmax_matches_clarabel_lp_on_random_problems():
    problems = mixed_problems(seed=15, count=150)
    for C, d, n_bounded, s in problems:
        result = solve_minmax(C, d, n_bounded, s)
        assert result.converged, result.message
        beta_ref = clarabel_minmax(C, d, n_bounded, s)
        assert abs(result.objective - beta_ref) <= 1e-6 * beta_ref
        # the forces are not unique: check admissibility and that β bounds every activity
        assert_admissible(result, C, d, s)
        assert np.max(result.f[:n_bounded] / s) <= result.objective * (1.0 + 1e-9)


def test_daqp_quadratic_path_matches_polynomial_p2():
    for C, d, n_bounded, s in mixed_problems(seed=16, count=60):
        reference = solve_polynomial(C, d, n_bounded, s, p=2.0)
        result = solve_quadratic_daqp(C, d, n_bounded, s)
        assert result.converged
        assert np.max(np.abs(result.f - reference.f)) <= 1e-6 * np.max(np.abs(reference.f))
        assert abs(result.objective - reference.objective) <= 1e-6 * reference.objective
        assert np.allclose(result.multipliers, reference.multipliers, rtol=1e-5,
                           atol=1e-8 * np.max(np.abs(reference.multipliers)))


def test_unilateral_20kN_reactions_satisfy_kkt_conditions():
    # body problems with 5 compressive-only 20 kN reactions (the paper's TMJ elements):
    # check the optimality conditions directly (stationarity on interior forces with
    # λ from a least-squares fit, correct signs of the bound multipliers)
    rng = np.random.default_rng(17)
    for _ in range(60):
        C, d, n_bounded, s = random_body_problem(rng, load=rng.uniform(0.05, 1.0),
                                                 weak_muscles=int(rng.integers(0, 4)))
        for p in (2.0, 3.0):
            result = solve_polynomial(C, d, n_bounded, s, p=p)
            assert result.converged
            assert_admissible(result, C, d, s)
            f_B = result.f[:n_bounded]
            grad = p * f_B ** (p - 1.0) / s**p  # ∂G/∂f_i
            at_zero = f_B == 0.0
            at_strength = f_B == s
            interior = ~(at_zero | at_strength)
            # stationarity: ∇G_I = C_Iᵀ λ, C_Fᵀ λ = 0 (least squares for λ)
            M = np.vstack([C[:, :n_bounded][:, interior].T, C[:, n_bounded:].T])
            rhs = np.concatenate([grad[interior], np.zeros(C.shape[1] - n_bounded)])
            lam = np.linalg.lstsq(M, rhs, rcond=None)[0]
            assert np.max(np.abs(M @ lam - rhs)) <= 1e-8 * np.max(np.abs(grad))
            reduced_cost = grad - C[:, :n_bounded].T @ lam
            assert np.all(reduced_cost[at_zero] >= -1e-8 * np.max(np.abs(grad)))
            assert np.all(reduced_cost[at_strength] <= 1e-8 * np.max(np.abs(grad)))


# ---------------------------------------------------------------------------------------
# closed forms


@pytest.mark.parametrize("p", [2.0, 3.0])
def test_two_muscles_one_equation_closed_form(p):
    # f1 + f2 = F, minimise (f1/s1)^p + (f2/s2)^p. Stationarity: p f_i^(p−1)/s_i^p = λ,
    # so f_i = s_i^(p/(p−1)) (λ/p)^(1/(p−1)) ∝ s_i^(p/(p−1)), i.e.
    # f1/f2 = (s1/s2)^(p/(p−1)) (p = 3: f ∝ s^(3/2); p = 2: f ∝ s²) and
    # f_i = F s_i^(p/(p−1)) / Σ_j s_j^(p/(p−1)).
    s = np.array([40.0, 250.0])
    F = 120.0
    result = solve_polynomial(np.array([[1.0, 1.0]]), np.array([F]), 2, s, p=p)
    q = p / (p - 1.0)
    expected = F * s**q / np.sum(s**q)
    assert result.converged
    np.testing.assert_allclose(result.f, expected, rtol=1e-10)
    # λ = ∂G/∂f_i = p f_i^(p−1)/s_i^p
    np.testing.assert_allclose(result.multipliers, [p * expected[0] ** (p - 1) / s[0] ** p],
                               rtol=1e-9)


@pytest.mark.parametrize("solver", ["polynomial", "daqp", "minmax"])
def test_zero_strength_muscle_carries_nothing(solver):
    # a muscle with s = 0 is fixed at f = 0; the others share F as in the closed forms
    # (p = 3: f ∝ s^(3/2); p = 2: f ∝ s²; min/max: f ∝ s)
    s = np.array([40.0, 0.0, 250.0])
    C = np.array([[1.0, 1.0, 1.0]])
    F = 120.0
    if solver == "polynomial":
        result, q = solve_polynomial(C, [F], 3, s, p=3.0), 1.5
    elif solver == "daqp":
        result, q = solve_quadratic_daqp(C, [F], 3, s), 2.0
    else:
        result, q = solve_minmax(C, [F], 3, s), 1.0
    assert result.converged
    expected = F * s**q / np.sum(s**q)
    np.testing.assert_allclose(result.f, expected, rtol=1e-9, atol=1e-12)
    assert result.f[1] == 0.0 and result.active_lower[1]


def test_minmax_two_muscles_closed_form():
    # min max(f1/s1, f2/s2) with f1 + f2 = F: equal activities β, f_i = β s_i,
    # β = F / (s1 + s2)
    s = np.array([40.0, 250.0])
    F = 120.0
    result = solve_minmax(np.array([[1.0, 1.0]]), np.array([F]), 2, s)
    np.testing.assert_allclose(result.f, F * s / s.sum(), rtol=1e-12)
    assert result.objective == pytest.approx(F / s.sum(), rel=1e-12)


@pytest.mark.parametrize("p", [2.0, 3.0])
def test_upper_bound_becomes_active(p):
    # Activities x_i = f_i/s_i ∝ s_i^(1/(p−1)) (from the closed form above): the stronger
    # muscle has the higher activity and saturates first. s = (10, 100), F = 105:
    # unconstrained f2 = F s2^q/(s1^q + s2^q) > 100 for p = 2 and 3, so f2 = s2 = 100 and
    # the weak muscle takes the rest, f1 = 5 (< s1, interior).
    s = np.array([10.0, 100.0])
    result = solve_polynomial(np.array([[1.0, 1.0]]), np.array([105.0]), 2, s, p=p)
    assert result.converged
    np.testing.assert_allclose(result.f, [5.0, 100.0], rtol=1e-12)
    assert result.active_upper.tolist() == [False, True]
    assert result.active_lower.tolist() == [False, False]
    # λ = ∂G/∂f_1 of the interior muscle
    assert result.multipliers[0] == pytest.approx(p * 5.0 ** (p - 1) / 10.0**p, rel=1e-9)


def test_free_reaction_is_determined_exactly():
    # body on a line: a muscle at lever arm r and a free joint force R at the origin,
    # rows: force f_m + R = F, moment r f_m = M  →  f_m = M/r, R = F − M/r
    r, F, M = 0.04, 50.0, 1.2
    C = np.array([[1.0, 1.0], [r, 0.0]])
    for p in (2.0, 3.0):
        result = solve_polynomial(C, np.array([F, M]), 1, np.array([100.0]), p=p)
        assert result.converged
        np.testing.assert_allclose(result.f, [M / r, F - M / r], rtol=1e-12)
    # with two muscles and one free force the free force takes what the muscles leave
    C = np.array([[1.0, 1.0, 1.0], [r, -r, 0.0]])
    result = solve_polynomial(C, np.array([F, 0.0]), 2, np.array([100.0, 100.0]), p=3.0)
    # moment balance f1 = f2; cost is minimal with f1 = f2 = 0 and R = F (a degenerate
    # optimum: the bound multipliers are zero too, so only the tolerance is guaranteed)
    assert result.converged
    np.testing.assert_allclose(result.f, [0.0, 0.0, F], atol=1e-8 * F)


def test_multipliers_are_derivative_of_optimal_objective():
    # envelope theorem: λ_k = ∂G*/∂d_k, checked by central differences of G*
    rng = np.random.default_rng(18)
    for p in (2.0, 3.0):
        C, d, n_bounded, s = random_body_problem(rng, load=0.5, weak_muscles=0)
        result = solve_polynomial(C, d, n_bounded, s, p=p)
        eps = 1e-4 * np.max(np.abs(d))
        for k in range(C.shape[0]):
            e_k = np.zeros_like(d)
            e_k[k] = eps
            G_plus = solve_polynomial(C, d + e_k, n_bounded, s, p=p, tol=1e-13).objective
            G_minus = solve_polynomial(C, d - e_k, n_bounded, s, p=p, tol=1e-13).objective
            derivative = (G_plus - G_minus) / (2 * eps)
            assert result.multipliers[k] == pytest.approx(derivative, rel=1e-5,
                                                          abs=1e-9 * np.max(np.abs(result.multipliers)))
        assert np.max(np.abs(result.multipliers)) > 0.0


# ---------------------------------------------------------------------------------------
# infeasible frames and errors


@pytest.mark.parametrize("solver", ["polynomial", "daqp", "minmax"])
def test_not_enough_strength_is_reported_with_row_name(solver):
    C = np.array([[1.0, 1.0], [0.0, 0.0]])
    C[1] = [0.05, -0.05]
    s = np.array([10.0, 20.0])
    # Fz needs 40 N, the muscles give at most 30 N; My = 0.05·10 − 0.05·20 is met at full
    # strength, so the least ℓ1 residual is 10 N in row Fz alone (at f = s)
    d = np.array([40.0, -0.5])
    solve = {
        "polynomial": lambda: solve_polynomial(C, d, 2, s, row_names=["mandible.Fz", "My"]),
        "daqp": lambda: solve_quadratic_daqp(C, d, 2, s, row_names=["mandible.Fz", "My"]),
        "minmax": lambda: solve_minmax(C, d, 2, s, row_names=["mandible.Fz", "My"]),
    }[solver]
    result = solve()
    assert not result.converged
    assert result.status == "infeasible"
    assert result.infeasible_rows == (0,)
    assert "not enough strength for row 'mandible.Fz'" in result.message
    assert np.all(np.isnan(result.multipliers))
    # the forces returned are the phase-1 point: within bounds, residual reported
    assert np.all(result.f[:2] <= s + 1e-9) and np.all(result.f[:2] >= -1e-9)
    np.testing.assert_allclose(result.residual, C @ result.f - d, atol=1e-9)
    np.testing.assert_allclose(result.f[:2], s, rtol=1e-9)
    assert result.residual[0] == pytest.approx(-10.0, rel=1e-9)


def test_pull_only_muscles_cannot_push():
    result = solve_polynomial(np.array([[1.0, 1.0]]), np.array([-5.0]), 2,
                              np.array([10.0, 20.0]), row_names=["Fx"])
    assert result.status == "infeasible"
    assert "row 'Fx'" in result.message


@pytest.mark.parametrize("solver", [solve_polynomial, solve_minmax, solve_quadratic_daqp])
def test_row_nothing_can_balance_is_named(solver):
    C = np.array([[1.0, 1.0, 0.0], [0.0, 0.0, 0.0], [0.0, 1.0, 1.0]])
    d = np.array([5.0, 2.0, 1.0])
    result = solver(C, d, 2, np.array([10.0, 20.0]), row_names=["Fx", "Fy", "Mz"])
    assert not result.converged
    assert result.infeasible_rows == (1,)
    assert "row 'Fy' cannot be balanced" in result.message


@pytest.mark.parametrize("solver", [solve_polynomial, solve_minmax, solve_quadratic_daqp])
def test_rank_deficient_free_columns_raise(solver):
    C = np.array([[1.0, 1.0, 1.0, 2.0, 0.0], [0.0, 1.0, 0.5, 1.0, 1.0]])
    with pytest.raises(RankDeficientFreeColumnsError) as info:
        solver(C, np.array([1.0, 1.0]), 2, np.array([10.0, 10.0]),
               column_names=["m1", "m2", "R1", "R2", "R3"])
    assert "column 'R1'" in str(info.value) and "column 'R2'" in str(info.value)
    assert "R3" not in str(info.value)
    assert info.value.columns == (2, 3)


def test_invalid_input_raises_named_errors():
    C = np.array([[1.0, 1.0]])
    with pytest.raises(RecruitmentInputError, match="column 'weak'"):
        solve_polynomial(C, [1.0], 2, [10.0, -1.0], column_names=["m", "weak"])
    with pytest.raises(RecruitmentInputError, match="shape"):
        solve_polynomial(C, [1.0, 2.0], 2, [10.0, 10.0])
    with pytest.raises(RecruitmentInputError, match="p must"):
        solve_polynomial(C, [1.0], 2, [10.0, 10.0], p=1.5)
    with pytest.raises(RecruitmentInputError, match="finite"):
        solve_polynomial(C, [np.nan], 2, [10.0, 10.0])


# ---------------------------------------------------------------------------------------
# warm start


def test_warm_start_gives_the_cold_solution_in_fewer_iterations():
    rng = np.random.default_rng(19)
    C, d, n_bounded, s = random_body_problem(rng)
    previous = solve_polynomial(C, d, n_bounded, s, p=3.0)
    for k in range(1, 30):
        d_k = d * (1.0 + 0.2 * np.sin(0.05 * k))
        cold = solve_polynomial(C, d_k, n_bounded, s, p=3.0)
        warm = solve_polynomial(C, d_k, n_bounded, s, p=3.0, x0=previous)
        warm_from_forces = solve_polynomial(C, d_k, n_bounded, s, p=3.0, x0=previous.f)
        for result in (warm, warm_from_forces):
            assert result.converged
            np.testing.assert_allclose(result.f, cold.f, rtol=0,
                                       atol=1e-8 * np.max(np.abs(cold.f)))
            assert result.iterations < cold.iterations
        previous = warm


# ---------------------------------------------------------------------------------------
# sensitivity


def _central_difference(C, d, n_bounded, s, p, dC, dd, eps):
    f_plus = solve_polynomial(C + eps * dC, d + eps * dd, n_bounded, s, p=p, tol=1e-14).f
    f_minus = solve_polynomial(C - eps * dC, d - eps * dd, n_bounded, s, p=p, tol=1e-14).f
    return (f_plus - f_minus) / (2 * eps)


@pytest.mark.parametrize("p", [2.0, 3.0])
def test_sensitivity_matches_central_differences(p):
    rng = np.random.default_rng(20)
    for _ in range(8):
        C, d, n_bounded, s = random_body_problem(rng, load=rng.uniform(0.1, 0.8))
        result = solve_polynomial(C, d, n_bounded, s, p=p, tol=1e-14)
        dC = 0.05 * rng.normal(size=C.shape)
        dd = 0.1 * np.max(np.abs(d)) * rng.normal(size=d.shape)
        df = recruitment_sensitivity(result, C, d, s, p, dC, dd)
        fd = _central_difference(C, d, n_bounded, s, p, dC, dd, eps=1e-6)
        assert np.max(np.abs(df)) > 1e-3 * np.max(np.abs(result.f))  # not trivially zero
        assert np.max(np.abs(df - fd)) <= 1e-5 * np.max(np.abs(df))
        # bounded forces at a bound do not move
        at_bound = result.active_lower | result.active_upper
        assert np.all(df[at_bound] == 0.0)


@pytest.mark.parametrize("p", [2.0, 3.0])
def test_sensitivity_with_active_upper_bounds(p):
    rng = np.random.default_rng(21)
    checked = 0
    while checked < 5:
        C, d, n_bounded, s = generic_problem(rng, loaded=True)
        result = solve_polynomial(C, d, n_bounded, s, p=p, tol=1e-14)
        if not (result.converged and result.active_upper.any()):
            continue
        dC = 0.02 * rng.normal(size=C.shape)
        dd = 0.02 * np.max(np.abs(d)) * rng.normal(size=d.shape)
        df = recruitment_sensitivity(result, C, d, s, p, dC, dd)
        fd = _central_difference(C, d, n_bounded, s, p, dC, dd, eps=1e-7)
        assert np.max(np.abs(df)) > 1e-3 * np.max(np.abs(result.f))
        assert np.max(np.abs(df - fd)) <= 1e-5 * np.max(np.abs(df))
        assert np.all(df[result.active_upper] == 0.0)
        checked += 1


def test_sensitivity_batch_equals_single_directions():
    rng = np.random.default_rng(22)
    C, d, n_bounded, s = random_body_problem(rng)
    result = solve_polynomial(C, d, n_bounded, s, p=3.0)
    dCs = rng.normal(size=(4, *C.shape))
    dds = rng.normal(size=(4, d.size))
    batch = recruitment_sensitivity(result, C, d, s, 3.0, dCs, dds)
    as_list = recruitment_sensitivity(result, C, d, s, 3.0, list(dCs), list(dds))
    assert batch.shape == (4, C.shape[1])
    for k in range(4):
        single = recruitment_sensitivity(result, C, d, s, 3.0, dCs[k], dds[k])
        np.testing.assert_allclose(batch[k], single, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(as_list[k], single, rtol=1e-12, atol=1e-12)
    # linear in the direction: df(dC, dd) = df(dC, 0) + df(0, dd)
    split = (recruitment_sensitivity(result, C, d, s, 3.0, dCs[0], np.zeros_like(d))
             + recruitment_sensitivity(result, C, d, s, 3.0, np.zeros_like(C), dds[0]))
    np.testing.assert_allclose(batch[0], split, rtol=1e-9, atol=1e-9 * np.abs(split).max())


@pytest.mark.parametrize("p", [2.0, 3.0])
def test_sensitivity_to_d_alone_matches_central_differences_in_d(p):
    """dC = None: a change of the applied loads alone (the FDK step with the contacts
    exact, fdk/contact_step.py); checked against central differences of the solution in d
    and against the same directions with an explicit zero dC."""
    rng = np.random.default_rng(23)
    for _ in range(4):
        C, d, n_bounded, s = random_body_problem(rng, load=rng.uniform(0.1, 0.8))
        result = solve_polynomial(C, d, n_bounded, s, p=p, tol=1e-14)
        dd = 0.1 * np.max(np.abs(d)) * rng.normal(size=(3, d.size))
        df = recruitment_sensitivity(result, C, d, s, p, None, dd)
        assert df.shape == (3, C.shape[1])
        for k in range(3):
            fd = _central_difference(C, d, n_bounded, s, p, np.zeros_like(C), dd[k], eps=1e-6)
            assert np.max(np.abs(df[k])) > 1e-3 * np.max(np.abs(result.f))  # not trivially zero
            assert np.max(np.abs(df[k] - fd)) <= 1e-5 * np.max(np.abs(df[k]))
            zero_dC = recruitment_sensitivity(result, C, d, s, p, np.zeros_like(C), dd[k])
            assert np.max(np.abs(df[k] - zero_dC)) <= 1e-9 * np.max(np.abs(df[k]))
        single = recruitment_sensitivity(result, C, d, s, p, None, dd[0])
        assert single.shape == (C.shape[1],)
        assert np.max(np.abs(single - df[0])) <= 1e-9 * np.max(np.abs(df[0]))
    with pytest.raises(RecruitmentInputError, match="dd must have shape"):
        recruitment_sensitivity(result, C, d, s, p, None, np.zeros(d.size + 1))


def test_one_factorisation_serves_several_direction_sets_and_each_matches_central_differences():
    """RecruitmentSensitivity factors the KKT system once; the FDK Jacobian's directions
    (dC, dd, ds) and the contact split's (d alone) are then solved with it
    (fdk/jacobian.py). Each set matches central differences of the solution, and equals
    recruitment_sensitivity called on its own to the last bit (the same factors, the same
    per-column solves)."""
    from openfdk.recruitment import RecruitmentSensitivity

    rng = np.random.default_rng(24)
    C, d, n_bounded, s = random_body_problem(rng, load=0.5)
    result = solve_polynomial(C, d, n_bounded, s, p=3.0, tol=1e-14)
    sens = RecruitmentSensitivity(result, C, d, s, 3.0)
    dC = 0.05 * rng.normal(size=(2, *C.shape))
    dd = 0.1 * np.max(np.abs(d)) * rng.normal(size=(2, d.size))
    loads = 0.1 * np.max(np.abs(d)) * rng.normal(size=(3, d.size))
    geometric, applied = sens.along(dC, dd), sens.along(None, loads)
    for k in range(2):
        fd = _central_difference(C, d, n_bounded, s, 3.0, dC[k], dd[k], eps=1e-6)
        assert np.max(np.abs(geometric[k])) > 1e-3 * np.max(np.abs(result.f))
        assert np.max(np.abs(geometric[k] - fd)) <= 1e-5 * np.max(np.abs(geometric[k]))
    for k in range(3):
        fd = _central_difference(C, d, n_bounded, s, 3.0, np.zeros_like(C), loads[k], eps=1e-6)
        assert np.max(np.abs(applied[k])) > 1e-3 * np.max(np.abs(result.f))
        assert np.max(np.abs(applied[k] - fd)) <= 1e-5 * np.max(np.abs(applied[k]))
    assert np.array_equal(geometric, recruitment_sensitivity(result, C, d, s, 3.0, dC, dd))
    assert np.array_equal(applied, recruitment_sensitivity(result, C, d, s, 3.0, None, loads))


def test_sensitivity_rejects_minmax_and_failed_results():
    C = np.array([[1.0, 1.0]])
    s = np.array([10.0, 20.0])
    minmax = solve_minmax(C, np.array([5.0]), 2, s)
    with pytest.raises(RecruitmentInputError, match="polynomial"):
        recruitment_sensitivity(minmax, C, [5.0], s, 3.0, np.zeros_like(C), [1.0])
    failed = solve_polynomial(C, np.array([50.0]), 2, s)
    with pytest.raises(RecruitmentInputError, match="converged"):
        recruitment_sensitivity(failed, C, [50.0], s, 3.0, np.zeros_like(C), [1.0])


# ---------------------------------------------------------------------------------------
# benchmark module


def test_benchmark_records():
    from openfdk.bench import recruitment as bench

    records = bench.run(quick=True)
    names = {record["name"] for record in records}
    assert {"recruitment_polynomial_p3_24m8r_ms", "recruitment_polynomial_p2_24m8r_ms",
            "recruitment_minmax_24m8r_ms"} <= names
    for record in records:
        assert record["unit"] == "ms" and record["value"] > 0.0


def test_benchmark_problem_is_feasible_and_nontrivial():
    rng = np.random.default_rng(23)
    C, d, n_bounded, s = random_body_problem(rng)
    assert C.shape == (6, 32) and n_bounded == 29
    result = solve_polynomial(C, d, n_bounded, s)
    assert result.converged
    assert np.count_nonzero(result.f[:24]) >= 3  # the muscles carry load
    # HiGHS independently confirms feasibility of the muscles-within-bounds problem
    lp = linprog(np.zeros(C.shape[1]), A_eq=C, b_eq=d,
                 bounds=[(0, si) for si in s] + [(None, None)] * 3, method="highs")
    assert lp.status == 0


def test_sensitivity_with_strength_change_matches_finite_differences():
    """ds enters through the criterion (interior forces) and the bounds (saturated
    forces): compare with central differences of the solver along (dC, dd, ds)."""
    from openfdk.recruitment import recruitment_sensitivity, solve_polynomial

    rng = np.random.default_rng(11)
    n_eq, n_m = 3, 8
    saturated = 0
    for trial in range(40):
        C = np.hstack([rng.normal(size=(n_eq, n_m)), rng.normal(size=(n_eq, 1))])
        # one strong muscle among weak ones saturates first under the cubic criterion
        s = np.r_[rng.uniform(300, 600), rng.uniform(10, 40, n_m - 1)]
        d = C[:, :n_m] @ s * rng.uniform(0.6, 0.95)
        res = solve_polynomial(C, d, n_m, s, 3.0, tol=1e-13)
        if not res.converged:
            continue
        saturated += res.active_upper.any()
        dC, dd, ds = rng.normal(size=C.shape), rng.normal(size=n_eq), rng.normal(size=n_m) * 5
        df = recruitment_sensitivity(res, C, d, s, 3.0, dC, dd, ds)
        h = 1e-6
        fp = solve_polynomial(C + h * dC, d + h * dd, n_m, s + h * ds, 3.0, tol=1e-13).f
        fm = solve_polynomial(C - h * dC, d - h * dd, n_m, s - h * ds, 3.0, tol=1e-13).f
        assert np.max(np.abs(df)) > 1e-3
        np.testing.assert_allclose(df, (fp - fm) / (2 * h), rtol=1e-4, atol=1e-4 * np.max(np.abs(df)))
    assert saturated >= 3  # the bound term was exercised


@pytest.mark.parametrize("solver", [solve_polynomial, solve_minmax, solve_quadratic_daqp])
def test_a_row_beyond_any_force_is_named_without_an_lp(solver):
    """A wild pose's equilibrium (DM's patella at a lead-in iterate: d = −2.7e30 N, from the
    contact's logarithmic law near full depth): HiGHS refuses |d| ≥ 1e20 as a model error.
    The row is named as one no finite force balances; nothing is raised."""
    C = np.array([[1.0, 1.0, 0.0], [0.5, -0.5, 1.0]])
    s = np.array([10.0, 20.0])
    result = solver(C, np.array([-2.65e30, 1.0]), 2, s, row_names=["patella_r.Fy", "Mz"])
    assert not result.converged and result.status == "infeasible" and result.infeasible_rows == (0,)
    assert "no finite force balances row 'patella_r.Fy' (d = -2.65e+30)" in result.message, result.message
    # below the LP's infinity the phase-1 LP names the row as it always did
    result = solver(C, np.array([1e19, 1.0]), 2, s, row_names=["patella_r.Fy", "Mz"])
    assert result.status == "infeasible" and "not enough strength for row 'patella_r.Fy'" in result.message


def test_a_failed_phase_1_lp_is_reported_not_raised(monkeypatch):
    """Should HiGHS fail on finite data, the frame is reported as not converged with the
    LP's message, never a traceback."""
    from types import SimpleNamespace

    import scipy.optimize

    monkeypatch.setattr(scipy.optimize, "linprog",
                        lambda *a, **k: SimpleNamespace(status=4, x=None, message="numerical difficulties", nit=3))
    C = np.array([[1.0, 1.0], [0.05, -0.05]])
    result = solve_polynomial(C, np.array([40.0, -0.5]), 2, np.array([10.0, 20.0]))
    assert not result.converged and result.status == "not_converged"
    assert "phase-1 LP failed (numerical difficulties)" in result.message


@pytest.mark.parametrize("scale", [1e4, 1e6])
def test_reserves_far_beyond_their_optimal_force_converge_to_the_kkt_point(scale):
    """Reserves (optimal force 1 N, no limit) carrying 10⁴–10⁶ N, as at a pose far from
    equilibrium: the activities' residuals' round-off exceeds an absolute 1e-10 and the
    solve failed although feasible. With the tolerance relative to the activities it
    converges; the forces meet C f = d and the KKT conditions of min Σ (f/s)³, checked
    with multipliers λ fitted independently (least squares) to the free columns
    (C_Fᵀ λ = 0) and the interior bounded ones (3 f²/s³ = C_iᵀ λ): residual small,
    the columns at f = 0 with C_iᵀ λ ≤ 0, the muscles at their strength with
    C_iᵀ λ ≥ 3/s_i."""
    rng = np.random.default_rng(19)
    C, d, nb, s = random_body_problem(rng)
    m = C.shape[0]
    E = np.eye(m)
    C = np.hstack([C[:, :nb], E, -E, C[:, nb:]])
    s = np.concatenate([s, np.ones(2 * m)])
    n_b = nb + 2 * m
    upper = np.concatenate([np.ones(nb), np.full(2 * m, np.inf)])
    d = d * scale
    result = solve_polynomial(C, d, n_b, s, p=3.0, upper=upper, lower=np.zeros(n_b))
    assert result.converged, result.message
    f = result.f
    assert np.abs(f[nb:n_b]).max() > 1e3  # the reserves carry the load
    np.testing.assert_allclose(C @ f, d, rtol=0, atol=1e-9 * np.abs(d).max())
    x = f[:n_b] / s
    interior = (x > 1e-9) & (x < upper * (1 - 1e-9))
    rows = np.vstack([C[:, n_b:].T, C[:, :n_b][:, interior].T])
    rhs = np.concatenate([np.zeros(C.shape[1] - n_b), 3 * x[interior] ** 2 / s[interior]])
    lam = np.linalg.lstsq(rows, rhs, rcond=None)[0]
    assert np.abs(rows @ lam - rhs).max() <= 1e-6 * np.abs(rhs).max()
    dual = C[:, :n_b].T @ lam
    scale_dual = np.abs(rhs).max()
    assert np.all(dual[x <= 1e-9] <= 1e-6 * scale_dual)
    at_upper = x >= upper * (1 - 1e-9)
    assert np.all(dual[at_upper] >= 3 / s[at_upper] - 1e-6 * scale_dual)
