"""Jacobians ∂f^FDK/∂α (n_fdk, n_fdk) of the FDK residual of one frame.

* :func:`central_jacobian` — the paper's central differences: 2 n_fdk residual
  evaluations (each a kinematic analysis and a recruitment solve).
* :func:`analytic_jacobian` — the chain rule (the paper's stated future work), with no
  recruitment solve:

  1. kinematic sensitivity dq̂/dα from the optimality conditions of the kinematic problem:
     determinate: Φ_q̂ dq̂ = E dα (E selects the FDK rows Φ^FDK − α);
     tracking: [[H, Φ_q̂ᵀ], [Φ_q̂, 0]] [dq̂; dλ] = [0; E] dα with H = ∂/∂q̂ (Ψ_q̂ᵀ W Ψ +
     Φ_q̂ᵀ λ) the Hessian of the Lagrangian of Eqs. 4–5;
  2. along each u_j = dq̂/dα_j: the applied loads' stiffness dQ = K u_j (every force
     set of the model — muscles' passive tension, ligaments, springs, loads, contacts —
     through one interface, :mod:`openfdk.forces.forceset`), and the change of the
     coefficient matrix C, of the inertial terms (v, v̇ held) and of the muscle
     strengths s;
  3. the sensitivity of the recruitment solution at its active set (KKT of Eq. 11,
     :func:`openfdk.recruitment.recruitment_sensitivity`), whose FDK columns give
     ∂f^FDK/∂α_j.

  The second derivatives of the geometry that steps 1–2 need (H, and the change of the
  Jacobian columns in C) are differences of analytic first derivatives on the manifold
  (forward for H, relative error ~1e-7; central along the few directions u_j for C,
  the inertial terms, s and the muscles' Q — and the contacts' in exact mode), with no
  recruitment solve. The
  dependence of v and v̇ on α through the neighbouring frames' positions is neglected:
  α̇ = α̈ = 0 by definition and the inertial forces of jaw-sized bodies are small next to
  joint stiffness.
"""

from __future__ import annotations

import numpy as np

from ..kinematics.frame_kernels import small_solve
from ..kinematics.envelope_lu import solve_in_order
from ..kinematics.curvature import lagrangian_hessian, second_order_terms
from ..recruitment import RecruitmentSensitivity
from .contact_step import contact_split
from .residual import FrameWorkspace


#: force kinds whose stiffness the analytic Jacobian takes by central differences of Q
#: along each u_j when their set's K is not exact (``exact_stiffness`` False): the
#: elastic-foundation contacts in exact mode, whose K omits the change of the surface
#: normal with the pose (curvature; 10–40 % of a column on the DM knee implants). In grid
#: mode the contacts' K is exact and is used.
DIRECTIONAL_KINDS = ("contacts",)
#: kinds whose set K the analytic Jacobian never uses: the muscles, whose passive Q is
#: differenced from the muscle states the geometry terms evaluate anyway (their K would
#: difference the wrapped paths over every touched body again)
DIFFERENCED_KINDS = ("muscles",)


def differenced_kinds(forces):
    """(kinds whose Q the analytic Jacobian differences along u_j besides the muscles',
    all kinds whose set K it leaves out) of a model's ForceElements ``forces``."""
    directional = tuple(fs.kind for fs in forces.sets
                        if fs.kind in DIRECTIONAL_KINDS and not getattr(fs, "exact_stiffness", False))
    return directional, directional + DIFFERENCED_KINDS

#: the central differences' step along each u_j: STEP / max |u_j| (m or rad of the
#: largest coordinate change)
STEP = 1e-6


def central_jacobian(ctx, k, ev, ws, steps):
    """Central differences: column j = (f(α + h_j e_j) − f(α − h_j e_j)) / 2h_j.

    Returns (J, n_evaluations, message) — message non-empty if an evaluation failed."""
    n = len(ev.alpha)
    J = np.zeros((n, n))
    evaluations = 0
    for j in range(n):
        cols = []
        for sign in (1.0, -1.0):
            a = ev.alpha.copy()
            a[j] += sign * steps[j]
            e = ctx.evaluate(k, a, ws.copy(), ev.frame.recruitment if ev.frame is not None else None)
            evaluations += 1
            if not e.ok:
                return None, evaluations, f"Jacobian evaluation at α ± h failed: {e.message}"
            cols.append(e.f_fdk)
        J[:, j] = (cols[0] - cols[1]) / (2 * steps[j])
    return J, evaluations, ""


def kinematic_sensitivity(ctx, ev):
    """dq̂/dα (n, n_fdk) at the evaluation's pose (Φ_q̂, marker Jacobian and multipliers
    read from the evaluation's FrameData)."""
    system, state, t, data = ctx.system, ev.state, ev.time, ev.data
    n_fdk = len(ev.alpha)
    A = data.Phi_q  # position stage: Φ_q̂ at this pose
    m, n = A.shape
    E = np.zeros((m, n_fdk))
    E[m - n_fdk :, :] = np.eye(n_fdk)
    if ctx.tracker is None:
        return small_solve(A, E)
    tracker = ctx.tracker
    H = lagrangian_hessian(tracker, state, t, ev.alpha, ev.visible, ev.x, ev.lam, data.p_M, data.J_M, A,
                           ctx.hessian_patterns)
    # the second-order terms, for the position solves that follow (FDKContext.tracking_curvature)
    ctx.tracking_curvature = (second_order_terms(tracker, state, H, data.J_M, ev.visible), float(t))
    K = np.zeros((n + m, n + m))
    K[:n, :n] = H
    K[:n, n:] = A.T
    K[n:, :n] = A
    rhs = np.zeros((n + m, n_fdk))
    rhs[n:] = E
    # K has the tracking's KKT structure: factorized in the tracker's order (0.7 → 0.2 ms
    # on the DM knee; kinematics/envelope_lu.py)
    return solve_in_order(K, tracker.kkt_order, rhs)[:n]


def _geometry_terms(ctx, state, vdot, t, alpha, moved):
    """C, the right-hand side without the applied loads (inertial terms only), the
    strengths s and the muscles' passive Q (n,) [N, N m] at ``state`` (velocities held);
    ``moved`` (state → MuscleOutputs or None): the muscles there."""
    C, d, s, muscles, _ = ctx.solver.equilibrium(state, vdot, t, alpha, forces=False, muscles=moved(state))
    return C, d, s, -(muscles.L.T @ muscles.passive)


def _moved_muscles(ctx, ev):
    """state → the muscles' MuscleOutputs at a pose near the evaluation's: the paths
    evaluated there, the strengths and passive tensions carried along l and l̇ to first
    order from the evaluation's (:meth:`~openfdk.forces.muscle_forces.MuscleForces.moved`;
    their central differences are those of the strength models to O(ε²), which the
    models' fibre equilibria then need not be solved again for: 2 n_fdk solves of every
    muscle per Jacobian, 2.9 of 28 ms on the DM knee); None without muscles."""
    muscles = ctx.solver.muscles
    base = ev.data.forces.get("muscles") if ev.data.forces else None
    if muscles is None or base is None:
        return lambda state: None
    slopes = muscles.slopes(base)
    return lambda state: muscles.moved(state, base, slopes)


def refreshed_split(ctx, ev, split):
    """``split`` (a ContactSplit carried from earlier frames) with its U = dq̂/dα and R
    taken again at the evaluation ``ev`` (sets ``ev.dq_dalpha``); its J_s, the other
    parts' Jacobian, is kept. None when the recruitment or the split is not available.

    Measured on DM's bench window (og1 from 2.57 s, 16 warm frames): the step from a
    frame's warm start with the carried J_s, U and R leaves 3.9–20 N of 82–184 N; with U
    and R taken again 0.05–3.8 N, as with a fresh Jacobian (0.05–3.2 N). U moves with
    the knee's flexion and R with the recruitment's forces; J_s changes less (3–7 %)."""
    fr = ev.frame
    if fr is None or fr.recruitment is None or fr.recruitment.criterion == "minmax":
        return None
    ev.dq_dalpha = kinematic_sensitivity(ctx, ev)
    fresh = contact_split(ctx, ev, ev.dq_dalpha, ctx.solver.settings.power)
    if fresh is None:
        return None
    fresh.J_s, fresh.gain = split.J_s, split.gain
    return fresh


def analytic_jacobian(ctx, k, ev):
    """Chain-rule Jacobian (module docstring). Returns (J, 0 evaluations, message)."""
    t = ctx.times[k]
    fr = ev.frame
    if fr.recruitment is None or fr.recruitment.criterion == "minmax":
        return None, 0, "analytic FDK Jacobian needs the polynomial recruitment criterion"
    u_all = kinematic_sensitivity(ctx, ev)  # (n, n_fdk)
    ev.dq_dalpha = u_all
    rows = ctx.solver.layout.eq_coords
    # the force sets' stiffness from what the forces stage left at this pose (path and
    # measure Jacobians are not evaluated again); the muscles' and exact-mode contacts'
    # by central differences of their Q along each u_j (differenced_kinds)
    forces = ctx.solver.forces
    directional, left_out = differenced_kinds(forces)
    KU = forces.stiffness_along(ev.state, ev.data.forces, u_all, exclude=left_out)
    n_fdk = len(ev.alpha)
    moved = _moved_muscles(ctx, ev)
    dC, dd, ds = [], [], []
    for j in range(n_fdk):
        u = u_all[:, j]
        eps = STEP / max(np.max(np.abs(u)), 1e-12)
        # the geometry's change by central differences: forward ones (n_fdk + 1 path
        # evaluations instead of 2 n_fdk) err by O(eps) in C, and the recruitment
        # amplifies that error ~1e8-fold into f^FDK along a soft mode (DM knee, og9
        # 4.042 s: the patella's rotations; J·Δα 6× off, the frame never converged)
        ends = []
        for sign in (1.0, -1.0):
            sx = ev.state.copy()
            sx.displace(sign * eps * u)
            Qc = forces.generalized_forces_of(directional, sx, t) if directional else 0.0
            ends.append((*_geometry_terms(ctx, sx, ev.vdot, t, ev.alpha, moved), Qc))
        (Cp, dp, s_p, Qm_p, Qc_p), (Cm, dm, s_m, Qm_m, Qc_m) = ends
        dC.append((Cp - Cm) / (2 * eps))
        # d = d_inertial − Q: the applied loads' part by their stiffness (Eq. 13)
        dQ = KU[:, j] + (Qm_p - Qm_m + Qc_p - Qc_m) / (2 * eps)
        dd.append((dp - dm) / (2 * eps) - dQ[rows])
        ds.append((s_p - s_m) / (2 * eps))
    p = ctx.solver.settings.power
    # the recruitment's KKT system at this solution, factored once for J's directions and
    # the contact split's (fdk/contact_step.py)
    sensitivity = RecruitmentSensitivity(fr.recruitment, fr.C, fr.d, fr.s, p)
    df = sensitivity.along(np.array(dC), np.array(dd), np.array(ds))
    # the contacts' part of the model, for the step with the contacts exact (fdk/contact_step.py)
    ev.contact_split = contact_split(ctx, ev, u_all, p, sensitivity)
    return df[:, ctx.fdk_columns].T, 0, ""


__all__ = ["central_jacobian", "analytic_jacobian", "kinematic_sensitivity", "differenced_kinds", "hessian_pattern",
           "FrameWorkspace"]
