"""Triangular solves in place (numba), for the small dense factors of the hot loop: the
QR factor of the recruitment's free columns (:mod:`openfdk.recruitment.reduction`) and
its dense solves (:mod:`openfdk.recruitment.dense`). The kinematics' LU solves visit
their envelopes (:mod:`openfdk.kinematics.envelope_lu`)."""

from __future__ import annotations

from numba import njit


@njit(cache=True)
def upper_solve(U, x):
    """x (n,) ← U⁻¹ x for U (n, n) upper triangular (back substitution); returns x."""
    n = U.shape[0]
    for i in range(n - 1, -1, -1):
        s = x[i]
        for j in range(i + 1, n):
            s -= U[i, j] * x[j]
        x[i] = s / U[i, i]
    return x


@njit(cache=True)
def upper_transpose_solve(U, x):
    """x (n,) ← U⁻ᵀ x for U (n, n) upper triangular (forward substitution with Uᵀ); returns x."""
    n = U.shape[0]
    for i in range(n):
        s = x[i]
        for j in range(i):
            s -= U[j, i] * x[j]
        x[i] = s / U[i, i]
    return x


__all__ = ["upper_solve", "upper_transpose_solve"]
