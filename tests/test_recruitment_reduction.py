"""The elimination of the free forces (recruitment/reduction.py): its QR factors against
numpy's least squares and singular values, and its rank test on matrices whose triangular
factor hides a rank deficiency (Kahan's matrix) or sits just above the threshold."""

from __future__ import annotations

import numpy as np
import pytest

from openfdk.recruitment.reduction import (
    RANK_MARGIN,
    REDUCE_OK,
    REDUCE_RANK_DEFICIENT_FREE,
    free_forces,
    reduce_problem,
)

RANK_RTOL, CONSISTENCY_RTOL = 1e-11, 1e-9


def kahan(n, theta):
    """Kahan's upper triangular matrix (n, n): its diagonal sin(θ)^k is far from zero while
    its smallest singular value is (Golub & Van Loan, "Matrix Computations", §5.4.2)."""
    c, s = np.cos(theta), np.sin(theta)
    return np.diag(s ** np.arange(n)) @ (np.eye(n) - c * np.triu(np.ones((n, n)), 1))


def problem(C_F, n_bounded=3, seed=0):
    """C = [C_B C_F] (m, n_bounded + n_free) with random bounded columns, d = C z (a
    consistent right-hand side) and s."""
    rng = np.random.default_rng(seed)
    m = C_F.shape[0]
    C = np.hstack([rng.normal(size=(m, n_bounded)), C_F])
    return C, C @ rng.normal(size=C.shape[1]), np.full(n_bounded, 10.0)


def test_free_forces_are_the_least_squares_solution_and_q2_the_left_null_space():
    rng = np.random.default_rng(3)
    C_F = rng.normal(size=(40, 31))
    C, d, s = problem(C_F)
    status, A_full, A_r, b_r, L, Q1, R_F, Sigma_r, Q2U_r = reduce_problem(C, d, 3, s, RANK_RTOL, CONSISTENCY_RTOL)
    assert status == REDUCE_OK
    rhs = rng.normal(size=40)
    expected = np.linalg.lstsq(C_F, rhs, rcond=None)[0]
    np.testing.assert_allclose(free_forces(Q1, R_F, rhs), expected, rtol=1e-10, atol=1e-12)
    assert np.abs(expected).max() > 0.1  # (a non-trivial solution)
    # the reduced rows are orthonormal and orthogonal to the free columns' span
    np.testing.assert_allclose(A_r @ A_r.T, np.eye(A_r.shape[0]), atol=1e-12)
    np.testing.assert_allclose(Q2U_r.T @ C_F, 0.0, atol=1e-12)
    # every x with A_r x = b_r balances C f = d with the free forces back-substituted
    x = np.linalg.lstsq(A_r, b_r, rcond=None)[0]
    f = np.concatenate([s * x, free_forces(Q1, R_F, d - A_full @ x)])
    np.testing.assert_allclose(C @ f, d, atol=1e-10)


def test_rank_deficiency_hidden_from_the_diagonal_is_found():
    K = kahan(100, 1.2)
    sigma = np.linalg.svd(K, compute_uv=False)
    threshold = RANK_RTOL * np.abs(K).max()
    assert np.abs(np.diag(K)).min() > 1e6 * threshold  # the diagonal does not show it
    assert sigma[-1] < threshold  # numpy's singular values do
    C, d, s = problem(np.vstack([K, np.zeros((5, 100))]))
    assert reduce_problem(C, d, 3, s, RANK_RTOL, CONSISTENCY_RTOL)[0] == REDUCE_RANK_DEFICIENT_FREE


def test_exact_dependence_and_a_zero_column_are_rank_deficient():
    rng = np.random.default_rng(5)
    C_F = rng.normal(size=(12, 6))
    C_F[:, 4] = 2.0 * C_F[:, 1] - C_F[:, 2]
    C, d, s = problem(C_F)
    assert reduce_problem(C, d, 3, s, RANK_RTOL, CONSISTENCY_RTOL)[0] == REDUCE_RANK_DEFICIENT_FREE
    C_F[:, 4] = 0.0
    C, d, s = problem(C_F)
    assert reduce_problem(C, d, 3, s, RANK_RTOL, CONSISTENCY_RTOL)[0] == REDUCE_RANK_DEFICIENT_FREE


@pytest.mark.parametrize("factor", [10.0, 0.1 * RANK_MARGIN, 10.0 * RANK_MARGIN])
def test_a_small_singular_value_above_the_threshold_is_full_rank(factor):
    """σ_min a few times the threshold, within and beyond the margin where the singular
    values decide: full rank, and the free forces still solve C_F f = rhs."""
    rng = np.random.default_rng(7)
    U, _ = np.linalg.qr(rng.normal(size=(20, 20)))
    V, _ = np.linalg.qr(rng.normal(size=(15, 15)))
    sigma = np.linspace(1.0, 0.5, 15)
    C_F = U[:, :15] @ np.diag(sigma) @ V.T
    C, d, s = problem(C_F)
    scale = np.abs(C * np.concatenate([s, np.ones(15)])).max()
    sigma[-1] = factor * RANK_RTOL * scale
    C[:, 3:] = U[:, :15] @ np.diag(sigma) @ V.T
    d = C @ np.ones(18)
    out = reduce_problem(C, d, 3, s, RANK_RTOL, CONSISTENCY_RTOL)
    assert out[0] == REDUCE_OK
    rhs = C[:, 3:] @ np.arange(1.0, 16.0)
    np.testing.assert_allclose(free_forces(out[5], out[6], rhs), np.arange(1.0, 16.0), rtol=1e-4)
