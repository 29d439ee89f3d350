"""Elimination of the free forces and of redundant equilibrium rows (numba).

The recruitment problem (paper Eq. 11) in the scaled bounded unknowns x = f_B / s
(dimensionless activity, 0 ≤ x ≤ 1) reads

    minimise Σ x_i^p   s.t.   A x + C_F f_F = d,   0 ≤ x ≤ 1,   A = C_B diag(s).

With the singular value decomposition C_F = [Q1 Q2] [Σ_F; 0] V_Fᵀ of the free columns
(full column rank required), the free forces drop out:

    Q2ᵀ A x = Q2ᵀ d                         (equilibrium the bounded forces must meet)
    f_F = V_F Σ_F⁻¹ Q1ᵀ (d − A x)            (free forces, back-substituted).

The reduced matrix Â = Q2ᵀ A is decomposed once more, Â = U Σ Vᵀ; directions with a
negligible singular value are redundant rows (dropped when Q2ᵀ d has no component along
them) or rows nothing can balance (an inconsistent component: infeasible). What remains
is the well-scaled problem

    A_r x = b_r,   A_r = V_rᵀ (orthonormal rows),   b_r = Σ_r⁻¹ U_rᵀ Q2ᵀ d,

whose equality multipliers μ map back to the multipliers of C f = d by
λ = Q2 U_r Σ_r⁻¹ μ (=: L μ). This is the null-space method of Nocedal & Wright,
"Numerical Optimization" (2nd ed., 2006), §15.3 / §16.2, applied to the free forces.

A bounded column that lies in the span of the free columns (its projection Q2ᵀ a_j is
below :data:`ABSORBED_RTOL` of its norm: a muscle absorbed by the FDK residual forces,
:mod:`openfdk.fdk.absorbed`) is set to exactly zero in Â and A_r. Its projection is then
round-off, and with the polynomial criterion (activity √(u_j / 3) for p = 3 in its dual
u_j = a_jᵀμ, |μ| ~ 10³) round-off of ±3e-12 became a force of ±2 mN that changed from one
evaluation of f^FDK to the next at the same α (measured on the synthetic DM-size knee,
docs/fdk.md "The noise floor"). Exactly zero, its force is exactly zero, as the optimum's.
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = [
    "REDUCE_OK",
    "REDUCE_RANK_DEFICIENT_FREE",
    "REDUCE_INCONSISTENT_ROWS",
    "reduce_problem",
    "ABSORBED_RTOL",
    "multiplier_to_reduced",
]

REDUCE_OK = 0
REDUCE_RANK_DEFICIENT_FREE = 1
REDUCE_INCONSISTENT_ROWS = 2
#: a bounded column whose part outside the free columns' span is below this fraction of
#: its norm is absorbed by the free forces (zeroed in the reduced problem)
ABSORBED_RTOL = 1e-8


@njit(cache=True, error_model="numpy")
def reduce_problem(C, d, n_bounded, s, rank_rtol, consistency_rtol):
    """Eliminate the free forces and redundant rows of C f = d.

    Parameters
    ----------
    C : (m, n) equilibrium matrix; d : (m,) N or N·m; n_bounded : int;
    s : (n_bounded,) N strengths; rank_rtol : relative singular-value threshold;
    consistency_rtol : relative threshold on the unbalanceable part of d.

    Returns
    -------
    status : int (REDUCE_*)
    A_full : (m, n_bounded) N, C_B diag(s)
    A_r : (r, n_bounded) dimensionless, orthonormal rows
    b_r : (r,) dimensionless
    L : (m, r) 1/N — λ = L μ
    free_back : (n_free, m) — f_F = free_back (d − A_full x)
    Sigma_r : (r,) N — kept singular values (μ = Σ_r U_rᵀ Q2ᵀ λ, see multiplier_to_reduced)
    Q2U_r : (m, r) orthonormal columns Q2 U_r
    """
    m, n = C.shape
    n_free = n - n_bounded
    A_full = np.empty((m, n_bounded))
    scale = 0.0
    for i in range(m):
        for j in range(n_bounded):
            A_full[i, j] = C[i, j] * s[j]
            if abs(A_full[i, j]) > scale:
                scale = abs(A_full[i, j])
        for j in range(n_bounded, n):
            if abs(C[i, j]) > scale:
                scale = abs(C[i, j])
    if scale == 0.0:
        scale = 1.0
    d_max = 0.0
    for i in range(m):
        if abs(d[i]) > d_max:
            d_max = abs(d[i])

    empty_r = np.zeros((0, n_bounded))
    # C_F = U_F diag(σ_F) V_Fᵀ; Q1 = U_F[:, :n_free], Q2 = U_F[:, n_free:]
    if n_free > 0:
        if n_free > m:
            return (REDUCE_RANK_DEFICIENT_FREE, A_full, empty_r, np.zeros(0),
                    np.zeros((m, 0)), np.zeros((n_free, m)), np.zeros(0), np.zeros((m, 0)))
        C_F = np.ascontiguousarray(C[:, n_bounded:])
        U_F, sigma_F, VT_F = np.linalg.svd(C_F, True)
        if sigma_F[n_free - 1] <= rank_rtol * scale:
            return (REDUCE_RANK_DEFICIENT_FREE, A_full, empty_r, np.zeros(0),
                    np.zeros((m, 0)), np.zeros((n_free, m)), np.zeros(0), np.zeros((m, 0)))
        # free_back = V_F Σ_F⁻¹ Q1ᵀ, one matrix product (as a triple loop it took half of
        # the reduction: 2.1 of 3.8 ms on the DM knee's 138 × 117 free columns)
        W = np.ascontiguousarray(VT_F.T)
        for k in range(n_free):
            for a in range(n_free):
                W[a, k] /= sigma_F[k]
        free_back = W @ np.ascontiguousarray(U_F[:, :n_free].T)
        Q2 = np.ascontiguousarray(U_F[:, n_free:])
    else:
        free_back = np.zeros((0, m))
        Q2 = np.eye(m)
    k_rows = m - n_free

    # Â = Q2ᵀ A, b̂ = Q2ᵀ d
    A_hat = Q2.T @ A_full
    b_hat = Q2.T @ d
    absorbed = np.zeros(n_bounded, dtype=np.bool_)
    if n_free > 0:
        for j in range(n_bounded):
            full, kept = 0.0, 0.0
            for i in range(m):
                full += A_full[i, j] * A_full[i, j]
            for i in range(k_rows):
                kept += A_hat[i, j] * A_hat[i, j]
            if kept <= ABSORBED_RTOL * ABSORBED_RTOL * full:
                absorbed[j] = True
                for i in range(k_rows):
                    A_hat[i, j] = 0.0
    if k_rows == 0 or n_bounded == 0:
        inconsistency = 0.0
        for i in range(k_rows):
            if abs(b_hat[i]) > inconsistency:
                inconsistency = abs(b_hat[i])
        status = REDUCE_OK
        if inconsistency > consistency_rtol * (d_max + scale):
            status = REDUCE_INCONSISTENT_ROWS
        return (status, A_full, empty_r, np.zeros(0), np.zeros((m, 0)), free_back,
                np.zeros(0), np.zeros((m, 0)))

    # Â = U Σ Vᵀ (thin); keep σ > rank_rtol · scale
    U2, sigma2, VT2 = np.linalg.svd(A_hat, False)
    r = 0
    for i in range(sigma2.shape[0]):
        if sigma2[i] > rank_rtol * scale:
            r += 1
    # component of b̂ outside range(Â): b̂ − U_r U_rᵀ b̂
    coef = np.zeros(r)
    for a in range(r):
        acc = 0.0
        for i in range(k_rows):
            acc += U2[i, a] * b_hat[i]
        coef[a] = acc
    inconsistency = 0.0
    for i in range(k_rows):
        acc = b_hat[i]
        for a in range(r):
            acc -= U2[i, a] * coef[a]
        if abs(acc) > inconsistency:
            inconsistency = abs(acc)
    status = REDUCE_OK
    if inconsistency > consistency_rtol * (d_max + scale):
        status = REDUCE_INCONSISTENT_ROWS

    A_r = np.ascontiguousarray(VT2[:r, :])
    for j in range(n_bounded):
        if absorbed[j]:
            for a in range(r):
                A_r[a, j] = 0.0
    b_r = np.empty(r)
    Sigma_r = np.empty(r)
    for a in range(r):
        b_r[a] = coef[a] / sigma2[a]
        Sigma_r[a] = sigma2[a]
    Q2U_r = Q2 @ np.ascontiguousarray(U2[:, :r])
    L = np.empty((m, r))
    for i in range(m):
        for a in range(r):
            L[i, a] = Q2U_r[i, a] / sigma2[a]
    return status, A_full, A_r, b_r, L, free_back, Sigma_r, Q2U_r


@njit(cache=True, error_model="numpy")
def multiplier_to_reduced(lam, Sigma_r, Q2U_r):
    """Reduced multipliers μ = Σ_r (Q2 U_r)ᵀ λ of given equality multipliers λ (m,)."""
    r = Sigma_r.shape[0]
    mu = np.zeros(r)
    for a in range(r):
        acc = 0.0
        for i in range(lam.shape[0]):
            acc += Q2U_r[i, a] * lam[i]
        mu[a] = Sigma_r[a] * acc
    return mu
