"""Kinematic stages of a frame (DESIGN.md §3, :mod:`openfdk.model.framedata`).

* :func:`position_stage` — Φ, Φ_q̂ and ν (and the marker positions and Jacobian) at the
  solved pose, evaluated once and kept in the frame data;
* :func:`velocity_stage_determinate` — Eqs. 2–3 with one LU factorisation of Φ_q̂;
* :func:`velocity_stage_tracking` — Eqs. 8–10 with the KKT matrix of the last
  Gauss–Newton step.

Later stages (equilibrium, the analytic FDK Jacobian) read Φ_q̂ from the data.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg as sla

from .frame_kernels import lu_factor, lu_solve


def position_stage(system, data, state, t, alpha=None, markers=None):
    """Fill data.Phi (m,), data.Phi_q (m, n), data.nu (m,) at ``state`` and time t (s)
    for FDK inputs α (n_fdk,); with ``markers`` (MarkerSet) also data.p_M (3 n_markers,)
    m and data.J_M (3 n_markers, n)."""
    data.t, data.alpha = t, alpha
    data.Phi, data.Phi_q, data.nu, _ = system.evaluate(state, t, alpha, order=1)
    if markers is not None:
        data.p_M, data.J_M, _ = markers.evaluate(state, 1)
    return data


def velocity_stage_determinate(system, data, state):
    """Φ_q̂ v = ν (Eq. 2), then γ at (q, v) and Φ_q̂ v̇ = γ (Eq. 3), with one LU
    factorisation of data.Phi_q. Sets the state's velocities; fills data.v, data.gamma,
    data.vdot (n,) [m/s, rad/s; m/s², rad/s²]."""
    # The small square Φ_q̂ is factorised by the compiled partial-pivoting LU (no BLAS
    # call, whose thread start-up dominates at this size); LAPACK only if singular, so
    # that its warning and inf/nan results stay as they were.
    LU = np.array(data.Phi_q, dtype=float, order="C")
    piv = np.empty(LU.shape[0], np.int64)
    if LU.shape[0] == LU.shape[1] and lu_factor(LU, piv):
        def solve(rhs):
            return lu_solve(LU, piv, np.array(rhs, dtype=float))
    else:
        lu = sla.lu_factor(data.Phi_q, check_finite=False)

        def solve(rhs):
            return sla.lu_solve(lu, rhs, check_finite=False)
    data.v = solve(data.nu)
    state.set_v(data.v)
    data.gamma = system.bias(state, data.t, data.alpha)
    data.vdot = solve(data.gamma)
    return data


def velocity_stage_tracking(tracker, data, state, xdot, xddot, d_delta, dd_delta):
    """Eqs. 8–10 with data.kkt and the position stage's marker Jacobian and ν.

    xdot, xddot : (n_markers, 3) measured marker velocity (m/s) and acceleration (m/s²),
    0 where occluded; d_delta, dd_delta : (n_markers, 3) residual rates δ̇, δ̈ (Eq. 7).
    Sets the state's velocities; fills data.v, data.vdot (n,)."""
    data.v, data.vdot = tracker.solve_velocities_accelerations(
        state, data.t, data.kkt, data.visible, xdot, xddot, d_delta, dd_delta, data.alpha, J=data.J_M, nu=data.nu)
    return data
