"""Assembly of a pose far from the marker optimum: damped, feasible-path least squares.

The per-frame tracking solve (:mod:`openfdk.kinematics.tracking`, paper Eqs. 4–5) is a
full Gauss–Newton SQP step on the KKT system, which converges quadratically from a
pose near the optimum: the previous frame's, extrapolated.  The first frame of a trial
(or the frame after a failed one) starts from a rigid fit of the markers, which can be
far off: a model whose markers sit differently from the subject's, a body with markers
that fit it badly, or a coordinate that the markers barely see (an arm's rotation about
its long axis), whose near-zero curvature makes a full Gauss–Newton step metres long.

Here the same problem, min ½ Ψᵀ W Ψ subject to Φ = 0, is solved by a feasible-path
Levenberg–Marquardt method:

1. **Projection.**  Φ(q̂) = 0 is restored by minimum-norm Gauss–Newton,
   Δq̂ = −Φ_q̂⁺ Φ, so every trial pose satisfies the joints.
2. **Damped step.**  The KKT system with the Hessian approximation damped,

       [ Ψ_q̂ᵀ W Ψ_q̂ + μ I   Φ_q̂ᵀ ] [ Δq̂ ]   [ −Ψ_q̂ᵀ W Ψ ]
       [ Φ_q̂                 0    ] [ λ  ] = [ 0         ],

   a step in the tangent space of the constraints, then projected back (1).  The step is
   accepted when the cost falls, and μ shrinks (×⅓); otherwise μ grows (×4) and the
   pose is restored.  Large μ is a short gradient step, μ → 0 Gauss–Newton, so the
   damping only shapes the path, not the optimum.

It has converged when an accepted step changes the cost by less than ``rtol_cost`` of
the cost or moves no coordinate by more than ``tol_step``, or when no damping finds a
lower cost at a feasible pose (a minimum to rounding).  The tracking solve calls it when
its Gauss–Newton kernel fails from the warm start (:meth:`MarkerTracker.solve_positions
<openfdk.kinematics.tracking.MarkerTracker.solve_positions>`): tens of milliseconds on a
full-body model, for the frames that need it only.  The velocities and accelerations
(Eqs. 8–10) of such a frame use the KKT matrix with the final damping μ I, so that a
coordinate the markers barely see does not get a velocity of 1/√curvature.
"""

from __future__ import annotations

import numpy as np

__all__ = ["assemble"]


def _project(system, state, t, alpha, tol, max_iter=20):
    """Restore Φ = 0 in place by minimum-norm Gauss–Newton; returns max |Φ| (m, rad)."""
    for _ in range(max_iter):
        Phi, A, _, _ = system.evaluate(state, t, alpha, order=1)
        res = float(np.max(np.abs(Phi))) if Phi.size else 0.0
        if res <= tol or not np.isfinite(res):
            return res
        dq, *_ = np.linalg.lstsq(A, -Phi, rcond=None)
        state.displace(dq)
    Phi = system.evaluate(state, t, alpha, order=0)[0]
    return float(np.max(np.abs(Phi))) if Phi.size else 0.0


def _cost(tracker, state, x, w):
    """½ Ψᵀ W Ψ (m²) with Ψ the marker (and task) residuals, and (Ψ (3 nm + nt,),
    Ψ_q̂ (3 nm + nt, n))."""
    p, J, _ = tracker.markers.evaluate(state, 1)
    if tracker.tasks:
        tv, tJ, _ = tracker.task_program.evaluate(state, 1)
        p, J = np.concatenate([p, tv]), np.vstack([J, tJ])
    r = p - x
    return 0.5 * float(np.sum(w * r * r)), r, J


def assemble(tracker, state, t, x_WM, visible, alpha=None, *, max_iter=200, rtol_cost=1e-12, tol_step=1e-9,
             tol_constraint=1e-9):
    """Bring ``state`` (in place) to the constrained marker optimum at time t (s).

    tracker : :class:`~openfdk.kinematics.tracking.MarkerTracker`; x_WM (n_markers, 3) m
    measured (NaN where not visible); visible (n_markers,) bool; alpha (n_fdk,) m or rad.
    Returns (converged, iterations, final cost ½ Ψᵀ W Ψ in m², max |Φ| in m or rad,
    final damping μ in the Hessian's units).
    """
    system = tracker.system
    w = tracker._weights(visible)
    x = np.where(visible[:, None], x_WM, 0.0).ravel()
    if tracker.tasks:
        x = np.concatenate([x, tracker.task_targets(t)[0]])
    res = _project(system, state, t, alpha, tol_constraint)
    cost, r, J = _cost(tracker, state, x, w)
    n = system.n_coords
    mu = None
    it = 0
    converged = False
    for it in range(1, max_iter + 1):
        _, A, _, _ = system.evaluate(state, t, alpha, order=1)
        H = J.T @ (w[:, None] * J)
        g = J.T @ (w * r)
        if mu is None:
            mu = 1e-3 * max(float(np.trace(H)) / n, 1e-12)
        m = A.shape[0]
        improved = False
        for _ in range(30):  # damping grown until a step lowers the cost
            K = np.zeros((n + m, n + m))
            K[:n, :n] = H + mu * np.eye(n)
            K[:n, n:] = A.T
            K[n:, :n] = A
            try:
                sol = np.linalg.solve(K, np.concatenate([-g, np.zeros(m)]))
            except np.linalg.LinAlgError:
                mu *= 4.0
                continue
            trial = state.copy()
            trial.displace(sol[:n])
            trial_res = _project(system, trial, t, alpha, tol_constraint)
            trial_cost, trial_r, trial_J = _cost(tracker, trial, x, w)
            if np.isfinite(trial_cost) and trial_cost < cost and trial_res <= max(10 * tol_constraint, res):
                drop = cost - trial_cost
                _copy_pose(trial, state)
                cost, r, J, res = trial_cost, trial_r, trial_J, trial_res
                mu = max(mu / 3.0, 1e-15)
                improved = True
                break
            mu *= 4.0
        if not improved:  # no damping lowers the cost: a minimum to rounding, if feasible
            converged = res <= tol_constraint
            break
        if drop <= rtol_cost * max(cost, 1e-300) or np.max(np.abs(sol[:n])) < tol_step:
            converged = res <= tol_constraint
            break
    return converged, it, cost, res, mu


def _copy_pose(src, dst):
    """Copy the poses of ``src`` into ``dst`` (same model; arrays in place)."""
    dst.p_WB[...] = src.p_WB
    dst.quat_WB[...] = src.quat_WB
    dst.R_WB[...] = src.R_WB
