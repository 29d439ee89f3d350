"""Tiny dense linear-algebra kernels (numba) for the recruitment solvers.

The Newton systems of the recruitment solvers are symmetric positive definite with at most
a handful of rows (≤ 6 per body), so a hand-written Cholesky factorisation is faster than
a LAPACK call through numba (no allocation of work arrays, no call overhead) and handles
the empty (0 × 0) case.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from openfdk.numerics.triangular import upper_solve, upper_transpose_solve

__all__ = ["cholesky_in_place", "cholesky_solve", "power", "weighted_gram"]


@njit(cache=True, error_model="numpy")
def weighted_gram(A, weight, K):
    """K ← A diag(weight) Aᵀ.

    A : (r, n), weight : (n,), K : (r, r) output (overwritten). Units follow the inputs.
    """
    r, n = A.shape
    for i in range(r):
        for j in range(i + 1):
            acc = 0.0
            for k in range(n):
                acc += A[i, k] * weight[k] * A[j, k]
            K[i, j] = acc
            K[j, i] = acc


@njit(cache=True, error_model="numpy")
def cholesky_in_place(K, relative_shift):
    """Factor K = L Lᵀ in place (lower triangle holds L); returns True on success.

    A diagonal shift ``relative_shift · max(diag K)`` is added first (Levenberg-style
    safeguard against a numerically singular K, e.g. when fewer free variables than rows
    remain interior). K : (r, r) symmetric.
    """
    r = K.shape[0]
    diag_max = 0.0
    for i in range(r):
        if K[i, i] > diag_max:
            diag_max = K[i, i]
    shift = relative_shift * diag_max + 1e-300
    for i in range(r):
        K[i, i] += shift
    for j in range(r):
        acc = K[j, j]
        for k in range(j):
            acc -= K[j, k] * K[j, k]
        if not acc > 0.0:
            return False
        L_jj = np.sqrt(acc)
        K[j, j] = L_jj
        for i in range(j + 1, r):
            acc = K[i, j]
            for k in range(j):
                acc -= K[i, k] * K[j, k]
            K[i, j] = acc / L_jj
    return True


@njit(cache=True, error_model="numpy")
def cholesky_solve(L, rhs, out):
    """Solve (L Lᵀ) out = rhs with the factor from :func:`cholesky_in_place`.

    L : (r, r) (lower triangle used), rhs : (r,), out : (r,) output.
    """
    # L y = rhs and Lᵀ out = y: the triangular solves with U = Lᵀ (numerics/triangular.py)
    U = L.T
    for i in range(L.shape[0]):
        out[i] = rhs[i]
    upper_transpose_solve(U, out)
    upper_solve(U, out)


@njit(cache=True, error_model="numpy")
def power(x, e):
    """x**e for x ≥ 0, with fast paths for the exponents of the p = 2 and p = 3 criteria."""
    if e == 2.0:
        return x * x
    if e == 1.0:
        return x
    if e == 3.0:
        return x * x * x
    if e == 0.5:
        return np.sqrt(x)
    if e == 0.0:
        return 1.0
    return x**e
