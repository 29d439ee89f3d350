"""Kinematic stages of a frame (docs/design.md §3, :mod:`openfdk.model.framedata`).

Each stage evaluates the constraint rows at most once per pose (the compiled kernels of
:mod:`.frame_kernels` hand their evaluations back):

* position — determinate: the Newton kernel's check at the solved pose gives Φ, Φ_q̂
  (:func:`openfdk.kinematics.determinate.solve_positions` with ``data``); tracking:
  :func:`marker_stage` (marker positions and Jacobian), the rows come with the velocity
  stage's one order-2 evaluation; :func:`position_stage` evaluates them in Python for
  callers with no kernel;
* :func:`velocity_stage_determinate` — Eqs. 2–3 with one LU factorisation of the
  position stage's Φ_q̂ (one order-2 evaluation for γ, which needs v);
* :func:`velocity_stage_tracking` — Eqs. 8–10 with the KKT matrix of the last
  Gauss–Newton step; fills Φ, Φ_q̂ from the same evaluation that gives the bias.

Later stages (equilibrium, the analytic FDK Jacobian) read Φ_q̂ from the data.
"""

from __future__ import annotations

from .determinate import solve_velocities_accelerations


def position_stage(system, data, state, t, alpha=None, markers=None):
    """Fill data.Phi (m,), data.Phi_q (m, n), data.nu (m,) at ``state`` and time t (s)
    for FDK inputs α (n_fdk,); with ``markers`` (MarkerSet) also data.p_M (3 n_markers,)
    m and data.J_M (3 n_markers, n)."""
    data.t, data.alpha = t, alpha
    data.Phi, data.Phi_q, data.nu, _ = system.evaluate(state, t, alpha, order=1)
    if markers is not None:
        data.p_M, data.J_M, _ = markers.evaluate(state, 1)
    return data


def marker_stage(markers, data, state):
    """data.p_M (3 n_markers,) m and data.J_M (3 n_markers, n) at ``state`` (tracking)."""
    data.p_M, data.J_M, _ = markers.evaluate(state, 1)
    return data


def velocity_stage_determinate(system, data, state):
    """Φ_q̂ v = ν (Eq. 2), then γ at (q, v) and Φ_q̂ v̇ = γ (Eq. 3), with one LU
    factorisation of data.Phi_q, in one kernel. Sets the state's velocities; fills
    data.v, data.gamma, data.vdot (n,) [m/s, rad/s; m/s², rad/s²]."""
    solve_velocities_accelerations(system, state, data.t, data.alpha, data)
    return data


def velocity_stage_tracking(tracker, data, state, xdot, xddot, d_delta, dd_delta):
    """Eqs. 8–10 with data.kkt and the marker stage's Jacobian data.J_M.

    xdot, xddot : (n_markers, 3) measured marker velocity (m/s) and acceleration (m/s²),
    0 where occluded; d_delta, dd_delta : (n_markers, 3) residual rates δ̇, δ̈ (Eq. 7).
    Sets the state's velocities; fills data.v, data.vdot (n,) and, from the rows' one
    evaluation in the kernel, data.Phi (m,), data.Phi_q (m, n), data.nu (m,)."""
    data.v, data.vdot, data.Phi, data.Phi_q, data.nu = tracker.solve_velocities_accelerations(
        state, data.t, data.kkt, data.visible, xdot, xddot, d_delta, dd_delta, data.alpha, J=data.J_M, rows=True)
    return data
