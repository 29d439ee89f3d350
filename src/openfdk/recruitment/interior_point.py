"""Primal–dual interior-point method for the box-constrained power objective (numba).

Solves the reduced recruitment problem (see :mod:`openfdk.recruitment.reduction`)

    minimise G(x) = Σ_i x_i^p   s.t.   A x = b,   l ≤ x ≤ u,            (p ≥ 2)

with A (r, n) having orthonormal rows, lower bounds l_i ≥ 0 (0, or a muscle's minimum
activation in OpenSim's static optimisation) and upper bounds u_i > l_i (1 for muscles
and one-sided reactions; an actuator's control limit, possibly +∞). KKT conditions, with
equality multipliers μ and bound multipliers z (x ≥ l), w (x ≤ u):

    r_d = ∇G(x) − Aᵀμ − z + w = 0,   r_p = A x − b = 0,
    (x_i − l_i) z_i = 0,   (u_i − x_i) w_i = 0,   z, w ≥ 0.

A variable without an upper bound (u_i = +∞) has w_i = 0 throughout, and its terms of
the upper bound drop out of Σ, ρ and the complementarity.

Algorithm: Mehrotra's predictor–corrector primal–dual path-following method (Mehrotra,
SIAM J Optim 2(4), 1992; S. J. Wright, "Primal-Dual Interior-Point Methods", SIAM 1997,
ch. 10; Nocedal & Wright, "Numerical Optimization", 2nd ed., Alg. 16.4 for the QP case and
§19.3 for the nonlinear Newton step). Each Newton step eliminates the bound multipliers,

    Σ = ∇²G + Z (X − L)⁻¹ + W (U − X)⁻¹         (diagonal, > 0)
    (A Σ⁻¹ Aᵀ) Δμ = −r_p − A Σ⁻¹ ρ,   Δx = Σ⁻¹ (ρ + Aᵀ Δμ),

so the only factorisation is an r × r Cholesky (r ≤ 6 for one body). Predictor and
corrector share it. Primal (x) and dual (μ, z, w) step lengths are chosen separately
with fraction-to-boundary 0.995 (Wright 1997, ch. 11; a common step length stalled on
problems whose solution has interior activities of order 1e-5 — the 20 kN unilateral
reactions); the residuals are re-evaluated at every iterate. For p > 2 a safeguard halves
the primal step while it would more than triple the dual residual (see the comment in the
loop). The safeguard and the separate step lengths are heuristics without a global
convergence proof; the tests and the fuzzing behind them (hundreds of random problems,
p = 2 … 5) found no failure, and a failure is reported, never hidden (see
:mod:`openfdk.recruitment.polynomial`).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from openfdk.recruitment.dense import cholesky_in_place, cholesky_solve, power, weighted_gram

__all__ = ["IPM_CONVERGED", "IPM_MAX_ITER", "IPM_FAILED", "ipm_starting_point", "power_box_ipm"]

IPM_CONVERGED = 0
IPM_MAX_ITER = 1
IPM_FAILED = 2


@njit(cache=True, error_model="numpy")
def _max_primal_step(x, dx, lo, u):
    """Largest α ≤ 1 keeping l ≤ x + αΔx ≤ u (u_i may be +∞)."""
    alpha = 1.0
    for i in range(x.shape[0]):
        if dx[i] < 0.0:
            alpha = min(alpha, (lo[i] - x[i]) / dx[i])
        elif dx[i] > 0.0:
            alpha = min(alpha, (u[i] - x[i]) / dx[i])
    return alpha


@njit(cache=True, error_model="numpy")
def _max_dual_step(z, dz, w, dw):
    """Largest α ≤ 1 keeping z + αΔz ≥ 0 and w + αΔw ≥ 0."""
    alpha = 1.0
    for i in range(z.shape[0]):
        if dz[i] < 0.0:
            alpha = min(alpha, -z[i] / dz[i])
        if dw[i] < 0.0:
            alpha = min(alpha, -w[i] / dw[i])
    return alpha


@njit(cache=True, error_model="numpy")
def _newton_direction(A, L_K, Sigma, rho, r_p, dx, dmu, rhs_r):
    """Δμ, Δx of the reduced Newton system for a given ρ (see module docstring)."""
    r, n = A.shape
    # rhs = −r_p − A Σ⁻¹ ρ
    for a in range(r):
        acc = -r_p[a]
        for i in range(n):
            acc -= A[a, i] * rho[i] / Sigma[i]
        rhs_r[a] = acc
    cholesky_solve(L_K, rhs_r, dmu)
    # Δx = Σ⁻¹ (ρ + Aᵀ Δμ)
    for i in range(n):
        acc = rho[i]
        for a in range(r):
            acc += A[a, i] * dmu[a]
        dx[i] = acc / Sigma[i]


@njit(cache=True, error_model="numpy")
def ipm_starting_point(A, b, p, lo, u):
    """Starting point (x, z, w, μ) of :func:`power_box_ipm`.

    x = least-norm solution Aᵀb of A x = b (A Aᵀ = I) clipped to l + [0.05, 0.5] ·
    min(u − l, 1) — typical activities are small, so this starts closer to the solution
    than the box centre; z = 0.1, w = 0.1 (0 without an upper bound); μ = A(∇G(x) − z +
    w), the least-squares fit of r_d = 0. lo, u : (n,) bounds, 0 ≤ l < u (+∞ allowed).
    Returns x (n,), z (n,), w (n,), μ (r,).
    """
    r, n = A.shape
    x = np.empty(n)
    z = np.full(n, 0.1)
    w = np.full(n, 0.1)
    for i in range(n):
        acc = 0.0
        for a in range(r):
            acc += A[a, i] * b[a]
        scale = min(u[i] - lo[i], 1.0)
        x[i] = min(max(acc, lo[i] + 0.05 * scale), lo[i] + 0.5 * scale)
        if np.isinf(u[i]):
            w[i] = 0.0
    mu = np.zeros(r)
    for a in range(r):
        acc = 0.0
        for i in range(n):
            acc += A[a, i] * (p * power(x[i], p - 1.0) - z[i] + w[i])
        mu[a] = acc
    return x, z, w, mu


@njit(cache=True, error_model="numpy")
def power_box_ipm(A, b, p, lo, u, x, z, w, mu, tol, max_iter):
    """Mehrotra predictor–corrector IPM for min Σ x^p s.t. A x = b, l ≤ x ≤ u.

    Iterates in place from (x, z, w, μ) — use :func:`ipm_starting_point`, or the state
    left by a previous call with a looser tolerance to continue.

    Parameters
    ----------
    A : (r, n) dimensionless, orthonormal rows; b : (r,); p : float ≥ 2;
    lo : (n,) lower bounds ≥ 0; u : (n,) upper bounds > l (+∞: none; then w_i = 0);
    x, z, w : (n,) strictly inside their bounds; mu : (r,) (all modified in place);
    tol : tolerance on ‖r_p‖∞/max(1, ‖x‖∞), ‖r_d‖∞/(1+‖∇G‖∞) and the mean
    complementarity/max(1, ‖∇G‖∞) (relative where activities exceed 1: reserves of 1 N
    carrying 10³ N far from equilibrium, whose residuals' round-off exceeds an absolute
    1e-10);
    max_iter : int.

    Returns
    -------
    status : int (IPM_*), iterations : int
    """
    r, n = A.shape
    g = np.empty(n)
    hess = np.empty(n)
    r_d = np.empty(n)
    r_p = np.empty(r)
    Sigma = np.empty(n)
    inv_Sigma = np.empty(n)
    rho = np.empty(n)
    dx = np.empty(n)
    dz = np.empty(n)
    dw = np.empty(n)
    dx_aff = np.empty(n)
    dz_aff = np.empty(n)
    dw_aff = np.empty(n)
    dmu = np.empty(r)
    rhs_r = np.empty(r)
    K = np.empty((r, r))
    # 1/(u − x) of the upper bounds, 0 where there is none (u = +∞, w = 0)
    bounded = np.empty(n, dtype=np.bool_)
    n_pairs = n
    for i in range(n):
        bounded[i] = not np.isinf(u[i])
        if bounded[i]:
            n_pairs += 1

    status = IPM_MAX_ITER
    iteration = 0
    while iteration < max_iter:
        # gradient and Hessian of G = Σ x^p
        g_max = 0.0
        for i in range(n):
            x_pow = power(x[i], p - 2.0)
            g[i] = p * x_pow * x[i]
            hess[i] = p * (p - 1.0) * x_pow
            if g[i] > g_max:
                g_max = g[i]
        # residuals r_d = ∇G − Aᵀμ − z + w, r_p = A x − b, complementarity τ
        rd_max = 0.0
        tau = 0.0
        for i in range(n):
            acc = g[i] - z[i] + w[i]
            for a in range(r):
                acc -= A[a, i] * mu[a]
            r_d[i] = acc
            if abs(acc) > rd_max:
                rd_max = abs(acc)
            tau += (x[i] - lo[i]) * z[i]
            if bounded[i]:
                tau += (u[i] - x[i]) * w[i]
        tau /= n_pairs
        rp_max = 0.0
        x_max = 1.0
        for a in range(r):
            acc = -b[a]
            for i in range(n):
                acc += A[a, i] * x[i]
            r_p[a] = acc
            if abs(acc) > rp_max:
                rp_max = abs(acc)
        for i in range(n):
            x_max = max(x_max, abs(x[i]))
        # the primal residual relative to the activities, the complementarity to the
        # gradient, where those exceed 1 (an absolute 1e-10 is below their round-off)
        if rp_max <= tol * x_max and rd_max <= tol * (1.0 + g_max) and tau <= tol * max(1.0, g_max):
            status = IPM_CONVERGED
            break
        if not (np.isfinite(tau) and np.isfinite(rd_max)):
            status = IPM_FAILED
            break
        iteration += 1

        # Σ = ∇²G + Z X⁻¹ + W (U − X)⁻¹, K = A Σ⁻¹ Aᵀ
        for i in range(n):
            Sigma[i] = hess[i] + z[i] / (x[i] - lo[i])
            if bounded[i]:
                Sigma[i] += w[i] / (u[i] - x[i])
            inv_Sigma[i] = 1.0 / Sigma[i]
        weighted_gram(A, inv_Sigma, K)
        if not cholesky_in_place(K, 1e-14):
            status = IPM_FAILED
            break

        # predictor (affine scaling, σ = 0): ρ = −r_d − z + w
        for i in range(n):
            rho[i] = -r_d[i] - z[i] + w[i]
        _newton_direction(A, K, Sigma, rho, r_p, dx_aff, dmu, rhs_r)
        for i in range(n):
            dz_aff[i] = -z[i] - z[i] * dx_aff[i] / (x[i] - lo[i])
            dw_aff[i] = (-w[i] + w[i] * dx_aff[i] / (u[i] - x[i])) if bounded[i] else 0.0
        alpha_p = _max_primal_step(x, dx_aff, lo, u)
        alpha_d = _max_dual_step(z, dz_aff, w, dw_aff)
        tau_aff = 0.0
        for i in range(n):
            tau_aff += (x[i] - lo[i] + alpha_p * dx_aff[i]) * (z[i] + alpha_d * dz_aff[i])
            if bounded[i]:
                tau_aff += (u[i] - x[i] - alpha_p * dx_aff[i]) * (w[i] + alpha_d * dw_aff[i])
        tau_aff /= n_pairs
        sigma = (tau_aff / tau) ** 3
        target = sigma * tau

        # corrector: r_l = (x−l) z + Δx_a Δz_a − στ, r_u = (u−x) w − Δx_a Δw_a − στ
        for i in range(n):
            r_l = (x[i] - lo[i]) * z[i] + dx_aff[i] * dz_aff[i] - target
            rho[i] = -r_d[i] - r_l / (x[i] - lo[i])
            r_u = 0.0
            if bounded[i]:
                r_u = (u[i] - x[i]) * w[i] - dx_aff[i] * dw_aff[i] - target
                rho[i] += r_u / (u[i] - x[i])
            # keep r_l, r_u for Δz, Δw below (stored in dz, dw temporarily)
            dz[i] = r_l
            dw[i] = r_u
        _newton_direction(A, K, Sigma, rho, r_p, dx, dmu, rhs_r)
        for i in range(n):
            dz[i] = (-dz[i] - z[i] * dx[i]) / (x[i] - lo[i])
            dw[i] = ((-dw[i] + w[i] * dx[i]) / (u[i] - x[i])) if bounded[i] else 0.0
        alpha_p = min(1.0, 0.995 * _max_primal_step(x, dx, lo, u))
        alpha_d = min(1.0, 0.995 * _max_dual_step(z, dz, w, dw))
        for i in range(n):
            z[i] += alpha_d * dz[i]
            w[i] += alpha_d * dw[i]
        for a in range(r):
            mu[a] += alpha_d * dmu[a]
        if p > 2.0:
            # safeguard for p > 2: the quadratic model of x^p underestimates the growth of
            # ∇G, and a variable with a nearly flat objective and vanishing bound
            # multipliers (a 20 kN unilateral reaction) can be thrown across the box.
            # Halve α_p until the new dual residual ‖∇G(x⁺) − Aᵀμ⁺ − z⁺ + w⁺‖∞ is at most
            # 3 · max(‖r_d‖∞, στ, tol).
            limit = 3.0 * max(rd_max, target, tol)
            for i in range(n):
                acc = -z[i] + w[i]
                for a in range(r):
                    acc -= A[a, i] * mu[a]
                rho[i] = acc  # ρ reused to hold −Aᵀμ⁺ − z⁺ + w⁺
            for _ in range(40):
                worst = 0.0
                for i in range(n):
                    worst = max(worst, abs(p * power(x[i] + alpha_p * dx[i], p - 1.0) + rho[i]))
                if worst <= limit:
                    break
                alpha_p *= 0.5
        for i in range(n):
            x[i] += alpha_p * dx[i]
        if max(alpha_p, alpha_d) < 1e-12:
            status = IPM_FAILED
            break
    return status, iteration
