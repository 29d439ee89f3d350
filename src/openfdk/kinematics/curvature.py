"""The tracking Lagrangian's Hessian at a solved pose, and its second-order terms.

The marker tracking of Eqs. 4–5 minimises ½ (Ψ − x)ᵀ W (Ψ − x) subject to Φ = 0. Its
Lagrangian's Hessian is

    H = Ψ_q̂ᵀ W Ψ_q̂ + S,      S = Σ_k w_k r_k ∇²Ψ_k + Σ_r λ_r ∇²Φ_r      (n, n)

with r = Ψ − x the residuals. Gauss–Newton steps with Ψ_q̂ᵀ W Ψ_q̂ alone converge
linearly, at a rate that grows with the residuals: 0.2 per step on the DM knee, but on a
model whose markers fit to 13 mm RMS (jam-resources' full_body_healthy_knee.osim with its
overground_17.trc) about 0.6, 38 steps a frame. Steps with S from a nearby pose
(:meth:`~openfdk.kinematics.tracking.MarkerTracker.solve_positions`, ``second_order``)
are Newton's, and converge in 3–5. The optimum is the same: S changes the path to the
stationary point, not the point.

H is differenced forward from the gradient g = Ψ_q̂ᵀ W r + Φ_q̂ᵀ λ along groups of
columns whose rows do not overlap (:func:`~openfdk.kinematics.kkt.hessian_pattern`), in
one compiled call (:mod:`.tracking_hessian`), or through Python when the tracker has
coordinate tasks. The FDK Jacobian's kinematic sensitivity
(:func:`openfdk.fdk.jacobian.kinematic_sensitivity`) and the tracking of a trial
(:class:`openfdk.kinematics.analysis.TrackingStep`) both take it from here.
"""

from __future__ import annotations

import numpy as np

from ..numerics.numdiff import column_groups, manifold_jacobian
from .kkt import hessian_pattern
from .tracking_hessian import OK as HESSIAN_OK
from .tracking_hessian import group_arrays, tracking_hessian

#: the forward differences' step of H (m or rad; relative error ~1e-7)
HESSIAN_STEP = 1e-7


class HessianPattern:
    """H's sparsity pattern and column groups for a constraint Jacobian's structure,
    kept while the constraints touch the same bodies (built again if A (m, n) touches a
    body the kept pattern did not)."""

    def __init__(self):
        self._kept = None

    def get(self, A):
        """(pattern (n, n) bool, groups, group_ptr, group_cols) for Φ_q̂ = A (m, n)."""
        kept = self._kept
        m, n = A.shape
        if kept is not None and kept[2].shape == (m, n // 6):
            if not np.any((A != 0.0).reshape(m, n // 6, 6).any(axis=2) & ~kept[2]):
                return kept[0], kept[1], *kept[3]
        pattern, touched = hessian_pattern(A)
        groups = column_groups(pattern)
        self._kept = (pattern, groups, touched, group_arrays(groups))
        return pattern, groups, *self._kept[3]


def _soft_rows(tracker, state, p_M, J_M):
    """(p (3 nm + nt,), J (3 nm + nt, n)): the markers' rows p_M, J_M at ``state``, then
    the coordinate tasks' rows evaluated there (rad or m)."""
    if not tracker.tasks:
        return p_M, J_M
    tv, tJ, _ = tracker.task_program.evaluate(state, 1)
    return np.concatenate([p_M, tv]), np.vstack([J_M, tJ])


def lagrangian_hessian(tracker, state, t, alpha, visible, x_WM, lam, p_M, J_M, A, patterns):
    """H (n, n) of the tracking Lagrangian (module docstring) at ``state``.

    tracker : the MarkerTracker; t (s); alpha (n_fdk,) the FDK DOFs (or the model's
    inputs) the constraints are evaluated with; visible (n_markers,) bool; x_WM
    (n_markers, 3) m measured (NaN where occluded); lam (m,) the constraints'
    multipliers at the pose; p_M (3 n_markers,) m and J_M (3 n_markers, n) the markers'
    positions and Jacobian there; A (m, n) Φ_q̂ there; patterns : a HessianPattern.
    The coordinate tasks' rows (rad or m) count as the markers' do. Raises (naming the
    measure) when a constraint measure fails at a displaced pose."""
    system = tracker.system
    w = tracker._weights(visible)
    x = np.where(visible[:, None], x_WM, 0.0).ravel()
    if tracker.tasks:
        x = np.concatenate([x, tracker.task_targets(t)[0]])
    n = A.shape[1]

    def gradient(s):
        p, J, _ = tracker.markers.evaluate(s, 1)
        p, J = _soft_rows(tracker, s, p, J)
        _, As, _, _ = system.evaluate(s, t, alpha, order=1)
        return J.T @ (w * (p - x)) + As.T @ lam

    p, J = _soft_rows(tracker, state, p_M, J_M)
    g0 = J.T @ (w * (p - x)) + A.T @ lam
    # a task row couples the bodies it touches, as a constraint row does
    pattern, groups, group_ptr, group_cols = patterns.get(np.vstack([A, J[J_M.shape[0]:]]) if tracker.tasks else A)
    if not tracker.tasks:
        # one compiled call; the coordinate tasks' rows are differenced through Python below
        H = np.empty((n, n))
        prog = system.program
        status, _, _ = tracking_hessian(*prog.program, prog.n_node_rows, state.p_WB, state.quat_WB, state.R_WB,
                                        state.w_BB, state.v_WB, state.column, state.moving, tracker.markers.body,
                                        tracker.markers.p_BM, w, x, lam, g0, group_ptr, group_cols, pattern,
                                        HESSIAN_STEP, H)
        if status == HESSIAN_OK:
            return H
    # (a measure that fails at a displaced pose raises here, naming it)
    return manifold_jacobian(gradient, state, eps=HESSIAN_STEP, central=False, f0=g0, pattern=pattern,
                             groups=groups)


def second_order_terms(tracker, state, H, J_M, visible):
    """S = H − Ψ_q̂ᵀ W Ψ_q̂ (n, n): what the Gauss–Newton matrix leaves out of H (the
    coordinate tasks' rows, evaluated at ``state``, in Ψ with the markers')."""
    w = tracker._weights(visible)
    _, J = _soft_rows(tracker, state, np.zeros(J_M.shape[0]), J_M)
    return H - J.T @ (w[:, None] * J)
