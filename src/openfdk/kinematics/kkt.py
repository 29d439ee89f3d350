"""One Gauss–Newton SQP step of marker tracking (paper Eqs. 4–5) as a numba kernel.

The KKT system of :mod:`openfdk.kinematics.tracking`,

    [ Ψ_q̂ᵀ W Ψ_q̂   Φ_q̂ᵀ ] [ Δq̂ ]   [ −Ψ_q̂ᵀ W (p − x) ]
    [ Φ_q̂           0    ] [ λ  ] = [ −Φ              ],

is assembled and solved in one call: for the few tens of rows of a joint model the
NumPy products, slices and LAPACK dispatch cost more than the arithmetic.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .block_triangular import lu_factor, lu_solve

__all__ = ["kkt_assemble", "kkt_rhs", "kkt_step", "kkt_chord_step"]


@njit(cache=True)
def kkt_rhs(J, w, p, x, A, Phi, rhs):
    """The right-hand side rhs (n + m,) = [−Ψ_q̂ᵀ W (p − x); −Φ] of :func:`kkt_assemble`
    in place, without K (a chord step needs only this). Returns max |Φ| (0 when empty)."""
    n = J.shape[1]
    m = A.shape[0]
    for i in range(n):
        rhs[i] = 0.0
    for k in range(J.shape[0]):
        wk = w[k]
        if wk == 0.0:
            continue
        rk = wk * (p[k] - x[k])
        for i in range(n):
            a = J[k, i]
            if a != 0.0:
                rhs[i] -= a * rk
    res = 0.0
    for a in range(m):
        rhs[n + a] = -Phi[a]
        res = max(res, abs(Phi[a]))
    return res


@njit(cache=True)
def kkt_assemble(J, w, p, x, A, Phi, K, rhs):
    """Assemble K (n + m, n + m) and the right-hand side rhs (n + m,) = [−Ψ_q̂ᵀ W (p − x); −Φ]
    in place (arguments as :func:`kkt_step`). Returns max |Φ| (0 when empty)."""
    n = J.shape[1]
    m = A.shape[0]
    res = kkt_rhs(J, w, p, x, A, Phi, rhs)
    # Ψ_q̂ᵀ W Ψ_q̂ row by row (J is row-major): a marker row has nonzeros in its body's 6
    # columns only, so zero entries are skipped
    for i in range(n):
        for j in range(n):
            K[i, j] = 0.0
    for k in range(J.shape[0]):
        wk = w[k]
        if wk == 0.0:
            continue
        for i in range(n):
            a = J[k, i]
            if a == 0.0:
                continue
            a *= wk
            for j in range(i, n):
                K[i, j] += a * J[k, j]
    for i in range(n):
        for j in range(i + 1, n):
            K[j, i] = K[i, j]
    for a in range(m):
        for j in range(n):
            K[n + a, j] = A[a, j]
            K[j, n + a] = A[a, j]
        for b in range(m):
            K[n + a, n + b] = 0.0
    return res


@njit(cache=True)
def kkt_step(J, w, p, x, A, Phi, K, S, use_S, LU, piv):
    """Assemble K and solve for [Δq̂; λ].

    J : (3 n_markers, n) marker Jacobian Ψ_q̂; w : (3 n_markers,) row weights (0 for
    occluded markers); p, x : (3 n_markers,) m model and measured marker positions
    (x finite where w > 0); A : (m, n) Φ_q̂; Phi : (m,) constraint values (m or rad);
    K : (n + m, n + m) output, the KKT matrix (reused by Eqs. 8–10). S : (n, n) the
    Hessian's second-order terms (Σ w r ∇²p + Σ λ ∇²Φ) added to Ψ_q̂ᵀ W Ψ_q̂ for the
    step when ``use_S`` (a Newton step instead of Gauss–Newton's), not to K. LU
    (n + m, n + m), piv (n + m,) int: output, the factors of the step's matrix (K, or K
    with S), for chord steps (:func:`kkt_chord_step`).

    Returns sol (n + m,) = [Δq̂; λ], max |Δq̂|, max |Φ| (0 when empty). Raises
    ``np.linalg.LinAlgError`` when K is singular.
    """
    n = J.shape[1]
    m = A.shape[0]
    rhs = np.empty(n + m)
    res = kkt_assemble(J, w, p, x, A, Phi, K, rhs)
    # the compiled LU skips zero multipliers: K is about 4 % non-zeros on the DM knee
    # (255 × 255), where it is faster than LAPACK's
    LU[:, :] = K
    if use_S:
        for i in range(n):
            for j in range(n):
                LU[i, j] += S[i, j]
    if not lu_factor(LU, piv):
        raise np.linalg.LinAlgError("singular matrix")
    sol = lu_solve(LU, piv, rhs)
    step = 0.0
    for i in range(n):
        step = max(step, abs(sol[i]))
    return sol, step, res


@njit(cache=True)
def kkt_chord_step(J, w, p, x, A, Phi, lam, LU, piv):
    """A chord step: the stationarity residual F = [Ψ_q̂ᵀ W (p − x) + Φ_q̂ᵀ λ; Φ] at the
    current pose and multipliers λ (m,), and [Δq̂; Δλ] = −M⁻¹ F with the factors LU, piv
    of an earlier step's matrix M (:func:`kkt_step`). F = 0 is the same optimum whatever
    M, so only the rate changes: from a pose a Newton step away, M's error is of that
    step's size. K is not assembled (the step needs only F): a caller that hands K on
    (Eqs. 8–10) assembles it at the pose of its last step (:func:`kkt_assemble`).
    Returns ([Δq̂; Δλ] (n + m,), max |Δq̂|, max |Φ|)."""
    n = J.shape[1]
    m = A.shape[0]
    rhs = np.empty(n + m)
    res = kkt_rhs(J, w, p, x, A, Phi, rhs)
    for j in range(n):  # −F: rhs holds −Ψ_q̂ᵀ W (p − x) and −Φ
        s = 0.0
        for a in range(m):
            s += A[a, j] * lam[a]
        rhs[j] -= s
    sol = lu_solve(LU, piv, rhs)
    step = 0.0
    for i in range(n):
        step = max(step, abs(sol[i]))
    return sol, step, res
