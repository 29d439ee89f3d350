"""Dual Newton method for the box-constrained power objective (numba).

Same reduced problem as :mod:`openfdk.recruitment.interior_point`:

    minimise Σ_i x_i^p   s.t.   A x = b,   l ≤ x ≤ ū,   A (r, n) with orthonormal rows,

with lower bounds l_i ≥ 0 and upper bounds ū_i > l_i (1 for muscles; an actuator's
control limit, possibly +∞). The objective is separable, so the Lagrangian dual is
explicit. For multipliers μ let u = Aᵀμ; each x_i minimises x^p − u_i x on [l_i, ū_i]:

    x_i(u_i) = clip((max(u_i, 0) / p)^(1/(p−1)), l_i, ū_i)            (stationarity)
    h(μ) = Σ_i [x_i^p − u_i x_i] + μᵀ b                               (dual function)
    ∇h = b − A x(μ),   ∇²h = −A D Aᵀ,
    D_ii = dx_i/du_i = x_i / ((p − 1) u_i) for l_i < x_i < ū_i, else 0.

h is concave and C¹; we maximise it by (semismooth) Newton steps
(A D Aᵀ + δ I) Δμ = b − A x with a Levenberg shift δ ∝ ‖∇h‖ and an Armijo backtracking
line search on h (Nocedal & Wright, "Numerical Optimization", 2nd ed., §3.1 and §3.4;
dual methods for separable convex programmes: Bertsekas, "Nonlinear Programming",
§6.1). Every iterate x(μ) lies within the bounds and satisfies stationarity and
complementarity exactly; only the equilibrium residual A x − b is driven to the
tolerance. That gives solutions whose active sets are exact (needed by the sensitivity
analysis), and warm starts are natural: the multipliers of the previous frame are
usually within one or two Newton steps of the new ones.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from openfdk.recruitment.dense import cholesky_in_place, cholesky_solve, power

__all__ = ["DUAL_CONVERGED", "DUAL_MAX_ITER", "DUAL_FAILED", "power_box_dual_newton",
           "multipliers_from_primal"]

DUAL_CONVERGED = 0
DUAL_MAX_ITER = 1
DUAL_FAILED = 2


@njit(cache=True, error_model="numpy")
def _primal_from_dual(A, mu, p, lower, upper, x, D):
    """x(μ) and D = dx/du (see module docstring); lower, upper (n,) the bounds l, ū (+∞
    allowed); returns h(μ) − μᵀb = Σ x^p − u x."""
    r, n = A.shape
    exponent = 1.0 / (p - 1.0)
    value = 0.0
    for i in range(n):
        u = 0.0
        for a in range(r):
            u += A[a, i] * mu[a]
        if u <= 0.0:
            x[i] = lower[i]
            D[i] = 0.0
        else:
            x[i] = power(u / p, exponent)
            D[i] = x[i] * exponent / u
            if x[i] >= upper[i]:
                x[i] = upper[i]
                D[i] = 0.0
            elif x[i] <= lower[i]:
                x[i] = lower[i]
                D[i] = 0.0
        value += power(x[i], p) - u * x[i]
    return value


@njit(cache=True, error_model="numpy")
def power_box_dual_newton(A, b, p, lower, upper, mu_start, tol, max_iter):
    """Maximise the dual h(μ) from ``mu_start`` (see module docstring).

    Parameters
    ----------
    A : (r, n) orthonormal rows; b : (r,); p : float ≥ 2; lower, upper : (n,) bounds
    0 ≤ l < ū (+∞ allowed); mu_start : (r,);
    tol : tolerance on ‖A x − b‖∞ / max(1, ‖x‖∞); max_iter : int.

    Returns
    -------
    x : (n,), mu : (r,), status : int (DUAL_*), iterations : int
    """
    r, n = A.shape
    mu = mu_start.copy()
    x = np.empty(n)
    D = np.empty(n)
    x_trial = np.empty(n)
    D_trial = np.empty(n)
    grad = np.empty(r)
    step = np.empty(r)
    mu_trial = np.empty(r)
    K = np.empty((r, r))

    value = _primal_from_dual(A, mu, p, lower, upper, x, D)
    for a in range(r):
        value += mu[a] * b[a]
    status = DUAL_MAX_ITER
    iteration = 0
    while True:
        # ∇h = b − A x(μ)
        grad_max = 0.0
        x_max = 1.0
        for a in range(r):
            acc = b[a]
            for i in range(n):
                acc -= A[a, i] * x[i]
            grad[a] = acc
            if abs(acc) > grad_max:
                grad_max = abs(acc)
        for i in range(n):
            x_max = max(x_max, abs(x[i]))
        if grad_max <= tol * x_max:  # relative where activities exceed 1 (as the interior point's)
            status = DUAL_CONVERGED
            break
        if iteration >= max_iter:
            break
        iteration += 1
        # (A D Aᵀ + δ I) Δμ = ∇h, δ = 1e-2 ‖∇h‖∞ (Levenberg shift)
        for a in range(r):
            for c in range(a + 1):
                acc = 0.0
                for i in range(n):
                    acc += A[a, i] * D[i] * A[c, i]
                K[a, c] = acc
                K[c, a] = acc
            K[a, a] += 1e-2 * grad_max
        if not cholesky_in_place(K, 1e-13):
            status = DUAL_FAILED
            break
        cholesky_solve(K, grad, step)
        slope = 0.0
        for a in range(r):
            slope += grad[a] * step[a]
        # Armijo backtracking on the concave dual: h(μ + αΔ) ≥ h(μ) + 1e-4 α ∇hᵀΔ.
        # Near the solution the predicted increase falls below the round-off of h; there
        # the step must decrease ‖∇h‖∞ (the equilibrium residual) instead.
        roundoff_level = slope <= 1e-10 * (1.0 + abs(value))
        alpha = 1.0
        accepted = False
        for _ in range(60):
            for a in range(r):
                mu_trial[a] = mu[a] + alpha * step[a]
            trial = _primal_from_dual(A, mu_trial, p, lower, upper, x_trial, D_trial)
            for a in range(r):
                trial += mu_trial[a] * b[a]
            if not roundoff_level and trial >= value + 1e-4 * alpha * slope:
                accepted = True
                break
            if roundoff_level:
                trial_grad_max = 0.0
                for a in range(r):
                    acc = b[a]
                    for i in range(n):
                        acc -= A[a, i] * x_trial[i]
                    trial_grad_max = max(trial_grad_max, abs(acc))
                if trial_grad_max < grad_max:
                    accepted = True
                    break
            alpha *= 0.5
        if not accepted:
            # no ascent possible in floating point
            status = DUAL_FAILED
            break
        value = trial
        for a in range(r):
            mu[a] = mu_trial[a]
        for i in range(n):
            x[i] = x_trial[i]
            D[i] = D_trial[i]
    return x, mu, status, iteration


@njit(cache=True, error_model="numpy")
def multipliers_from_primal(A, x0, p, lower, upper):
    """Least-squares multipliers μ with (Aᵀμ)_i ≈ p x0_i^(p−1) on the interior x0_i ∈ (l_i, ū_i).

    A : (r, n); x0 : (n,) dimensionless guess; lower, upper : (n,) bounds (+∞ allowed). Returns μ (r,) — a warm start for the
    dual Newton method when only a previous primal solution is known.
    """
    r, n = A.shape
    K = np.zeros((r, r))
    rhs = np.zeros(r)
    for i in range(n):
        if lower[i] < x0[i] < upper[i] and x0[i] > 0.0:
            g = p * power(x0[i], p - 1.0)
            for a in range(r):
                rhs[a] += A[a, i] * g
                for c in range(r):
                    K[a, c] += A[a, i] * A[c, i]
    for a in range(r):
        K[a, a] += 1e-9
    mu = np.zeros(r)
    if cholesky_in_place(K, 1e-12):
        cholesky_solve(K, rhs, mu)
    return mu
