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

from .envelope_lu import lu_factor_envelope, permute_into, solve_permuted

__all__ = ["kkt_assemble", "kkt_rhs", "kkt_step", "kkt_chord_step", "hessian_pattern", "kkt_pattern"]


def _bodies_touched(rows):
    """(k, n_moving) bool: the bodies each row of ``rows`` (k, n = 6 n_moving) involves (a
    body whose 6 columns are not all zero)."""
    k, n = rows.shape
    return (rows != 0.0).reshape(k, n // 6, 6).any(axis=2)


def hessian_pattern(A):
    """The entries of the tracking Lagrangian's Hessian ∂/∂q̂ (Ψ_q̂ᵀ W Ψ + Φ_q̂ᵀ λ) (n, n)
    that can be non-zero, from the structure of Φ_q̂ = A (m, n = 6 n_moving): a marker
    lies on one body, so its terms couple that body's 6 coordinates only; a constraint
    row couples every pair of the bodies it touches (a body whose 6 columns of A are not
    all zero). Returns (pattern (n, n) bool, touched (m, n_moving) bool)."""
    m, n = A.shape
    touched = _bodies_touched(A)
    T = touched.astype(np.int64)
    coupled = np.eye(n // 6, dtype=bool) | ((T.T @ T) > 0)
    return np.kron(coupled, np.ones((6, 6), dtype=bool)), touched


def kkt_pattern(J, A):
    """The entries (n + m, n + m) bool of the KKT matrix of :func:`kkt_step` that can be
    non-zero, the Hessian's second-order terms included, body by body: J (k, n) the soft
    rows' Jacobian (markers and coordinate tasks, a task coupling the bodies it
    involves), A (m, n) Φ_q̂, at any pose."""
    m, n = A.shape
    H, touched = hessian_pattern(A)
    T = _bodies_touched(J).astype(np.int64)
    H = H | np.kron((T.T @ T) > 0, np.ones((6, 6), dtype=bool))
    rows = np.repeat(touched, 6, axis=1)
    pattern = np.zeros((n + m, n + m), dtype=bool)
    pattern[:n, :n] = H
    pattern[n:, :n] = rows
    pattern[:n, n:] = rows.T
    return pattern


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
def kkt_step(J, w, p, x, A, Phi, K, S, use_S, LU, piv, perm, first, last):
    """Assemble K and solve for [Δq̂; λ].

    J : (3 n_markers, n) marker Jacobian Ψ_q̂; w : (3 n_markers,) row weights (0 for
    occluded markers); p, x : (3 n_markers,) m model and measured marker positions
    (x finite where w > 0); A : (m, n) Φ_q̂; Phi : (m,) constraint values (m or rad);
    K : (n + m, n + m) output, the KKT matrix (reused by Eqs. 8–10). S : (n, n) the
    Hessian's second-order terms (Σ w r ∇²p + Σ λ ∇²Φ) added to Ψ_q̂ᵀ W Ψ_q̂ for the
    step when ``use_S`` (a Newton step instead of Gauss–Newton's), not to K. perm
    (n + m,) int: the order the step's matrix is factorized in (:mod:`.envelope_lu`:
    its reverse Cuthill–McKee order; any permutation gives the same solution). LU
    (n + m, n + m), piv, first, last (n + m,) int: output, the factors of the step's
    matrix (K, or K with S) in that order, for chord steps (:func:`kkt_chord_step`).

    Returns sol (n + m,) = [Δq̂; λ], max |Δq̂|, max |Φ| (0 when empty). Raises
    ``np.linalg.LinAlgError`` when K is singular.
    """
    n = J.shape[1]
    m = A.shape[0]
    rhs = np.empty(n + m)
    res = kkt_assemble(J, w, p, x, A, Phi, K, rhs)
    # the compiled LU visits the envelope of the renumbered matrix only: K is about 4 %
    # non-zeros on the DM knee (255 × 255), where it is faster than LAPACK's
    permute_into(K, perm, LU)
    if use_S:
        for i in range(n + m):
            pi = perm[i]
            if pi < n:
                for j in range(n + m):
                    pj = perm[j]
                    if pj < n:
                        LU[i, j] += S[pi, pj]
    if not lu_factor_envelope(LU, piv, np.int64(0), n + m, first, last):
        raise np.linalg.LinAlgError("singular matrix")
    sol = solve_permuted(LU, piv, first, last, perm, rhs)
    step = 0.0
    for i in range(n):
        step = max(step, abs(sol[i]))
    return sol, step, res


@njit(cache=True)
def kkt_chord_step(J, w, p, x, A, Phi, lam, LU, piv, perm, first, last):
    """A chord step: the stationarity residual F = [Ψ_q̂ᵀ W (p − x) + Φ_q̂ᵀ λ; Φ] at the
    current pose and multipliers λ (m,), and [Δq̂; Δλ] = −M⁻¹ F with the factors LU, piv,
    first, last in the order perm of an earlier step's matrix M (:func:`kkt_step`). F = 0
    is the same optimum whatever M, so only the rate changes: from a pose a Newton step
    away, M's error is of that step's size. K is not assembled (the step needs only F):
    a caller that hands K on (Eqs. 8–10) assembles it at the pose of its last step
    (:func:`kkt_assemble`). Returns ([Δq̂; Δλ] (n + m,), max |Δq̂|, max |Φ|)."""
    n = J.shape[1]
    m = A.shape[0]
    rhs = np.empty(n + m)
    res = kkt_rhs(J, w, p, x, A, Phi, rhs)
    for j in range(n):  # −F: rhs holds −Ψ_q̂ᵀ W (p − x) and −Φ
        s = 0.0
        for a in range(m):
            s += A[a, j] * lam[a]
        rhs[j] -= s
    sol = solve_permuted(LU, piv, first, last, perm, rhs)
    step = 0.0
    for i in range(n):
        step = max(step, abs(sol[i]))
    return sol, step, res
