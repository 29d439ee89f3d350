"""kinematics.envelope_lu: LU with partial pivoting over the rows' envelopes, the reverse
Cuthill–McKee order, and the permuted solves of the marker tracking's KKT systems,
against LAPACK's getrf (scipy.linalg.lu_factor) and numpy.linalg.solve."""

import numpy as np
import pytest
import scipy.linalg

from openfdk.kinematics.envelope_lu import (envelope_order, factor_permuted, lu_factor_envelope, lu_solve_envelope,
                                            solve_permuted)


def _sparse(rng, n, band, scattered):
    """(n, n) matrix: a random band of half-width ``band`` plus ``scattered`` entries
    anywhere, rows scaled over six decades (so that partial pivoting swaps rows)."""
    A = np.zeros((n, n))
    for i in range(n):
        lo, hi = max(0, i - band), min(n, i + band + 1)
        A[i, lo:hi] = rng.normal(size=hi - lo)
    r, c = rng.integers(0, n, scattered), rng.integers(0, n, scattered)
    A[r, c] = rng.normal(size=scattered)
    return A * 10.0 ** rng.uniform(-3, 3, size=(n, 1))


@pytest.mark.parametrize("seed", range(4))
def test_the_envelope_lu_is_lapacks_lu(seed):
    """The factors and pivots of getrf (scipy.linalg.lu_factor): the envelope only skips
    operations on exact zeros. The envelopes bound the factors: L's row i is zero left of
    first[i], U's right of last[i]."""
    rng = np.random.default_rng(seed)
    n = 60
    A = _sparse(rng, n, 3, 40)
    LU, piv = A.copy(), np.empty(n, np.int64)
    first, last = np.empty(n, np.int64), np.empty(n, np.int64)
    assert lu_factor_envelope(LU, piv, 0, n, first, last)
    LU_ref, piv_ref = scipy.linalg.lu_factor(A)
    np.testing.assert_array_equal(piv, piv_ref)
    np.testing.assert_allclose(LU, LU_ref, rtol=0, atol=1e-12 * np.abs(LU_ref).max())
    cols = np.arange(n)
    assert not np.any(LU[(cols[None, :] < first[:, None]) & (cols[None, :] < cols[:, None])])
    assert not np.any(LU[(cols[None, :] > last[:, None])])
    assert np.mean(last - cols) < n / 2  # the envelope is narrower than the dense loop's rows
    b = rng.normal(size=n)
    x = lu_solve_envelope(LU, piv, first, last, b.copy())
    np.testing.assert_allclose(A @ x, b, rtol=0, atol=1e-9 * np.abs(b).max())


def test_a_diagonal_block_is_factorized_alone():
    """lo, hi: the block A[lo:hi, lo:hi] is factorized as getrf factorizes it alone; the
    rows outside are left unchanged."""
    rng = np.random.default_rng(5)
    A = _sparse(rng, 30, 2, 20)
    LU, piv = A.copy(), np.zeros(30, np.int64)
    first, last = np.zeros(30, np.int64), np.zeros(30, np.int64)
    assert lu_factor_envelope(LU, piv, 10, 22, first, last)
    LU_ref, piv_ref = scipy.linalg.lu_factor(A[10:22, 10:22])
    np.testing.assert_allclose(LU[10:22, 10:22], LU_ref, rtol=0, atol=1e-12 * np.abs(LU_ref).max())
    np.testing.assert_array_equal(piv[10:22] - 10, piv_ref)
    np.testing.assert_array_equal(LU[:10], A[:10])
    np.testing.assert_array_equal(LU[22:], A[22:])
    assert np.all((first[10:22] >= 10) & (last[10:22] < 22))


def test_an_exactly_zero_pivot_is_reported():
    """A zero column: singular, False (as getrf's info > 0)."""
    A = np.eye(5)
    A[:, 2] = 0.0
    n = 5
    assert not lu_factor_envelope(A, np.empty(n, np.int64), 0, n, np.empty(n, np.int64), np.empty(n, np.int64))


def test_reverse_cuthill_mckee_recovers_a_shuffled_band():
    """A tridiagonal pattern renumbered at random has a bandwidth near n; RCM's order
    gives it back its bandwidth of 1 (a path graph: its only orders of bandwidth 1 are
    the path and its reverse)."""
    rng = np.random.default_rng(1)
    n = 40
    P = np.eye(n, dtype=bool) | np.eye(n, k=1, dtype=bool) | np.eye(n, k=-1, dtype=bool)
    shuffle = rng.permutation(n)
    Q = P[np.ix_(shuffle, shuffle)]
    r, c = np.nonzero(Q)
    assert np.abs(r - c).max() > 10
    perm = envelope_order(Q)
    r, c = np.nonzero(Q[np.ix_(perm, perm)])
    assert np.abs(r - c).max() == 1
    assert sorted(perm) == list(range(n))


def test_the_permuted_solve_is_the_solve():
    """factor_permuted + solve_permuted in the RCM order of a shuffled sparse matrix's
    pattern, and in any order: numpy.linalg.solve's solution (to rounding); the
    right-hand side is left unchanged."""
    rng = np.random.default_rng(3)
    n = 50
    A = _sparse(rng, n, 2, 10)
    shuffle = rng.permutation(n)
    M = A[np.ix_(shuffle, shuffle)]
    b = rng.normal(size=n)
    x_ref = np.linalg.solve(M, b)
    for perm in (envelope_order(M != 0.0), rng.permutation(n).astype(np.int64)):
        LU, piv = np.empty((n, n)), np.empty(n, np.int64)
        first, last = np.empty(n, np.int64), np.empty(n, np.int64)
        assert factor_permuted(M, perm, LU, piv, first, last)
        b0 = b.copy()
        x = solve_permuted(LU, piv, first, last, perm, b)
        np.testing.assert_array_equal(b, b0)
        np.testing.assert_allclose(x, x_ref, rtol=1e-9, atol=1e-12 * np.abs(x_ref).max())


def test_solve_in_order_solves_every_column_and_refuses_a_singular_matrix():
    """solve_in_order: numpy.linalg.solve's X for a block of right-hand sides, in the RCM
    order of the matrix's pattern; numpy's LinAlgError for an exactly singular matrix."""
    from openfdk.kinematics.envelope_lu import solve_in_order

    rng = np.random.default_rng(11)
    n = 45
    M = _sparse(rng, n, 3, 15)
    B = rng.normal(size=(n, 7))
    X = solve_in_order(M, envelope_order(M != 0.0), B)
    np.testing.assert_allclose(X, np.linalg.solve(M, B), rtol=1e-9, atol=1e-12 * np.abs(X).max())
    M[:, 4] = 0.0
    with pytest.raises(np.linalg.LinAlgError):
        solve_in_order(M, envelope_order(M != 0.0), B)
