"""Frame data: the workspace of one frame's analysis (Pinocchio's *Data*, MuJoCo's
stages; docs/design.md §3).

The model (:class:`~openfdk.model.model.Model`) is never modified by an analysis.
Everything a frame computes at one pose lives in a :class:`FrameData`, filled by stage
functions ``stage(model_parts, data, …)`` in this order, each field once per pose:

1. position — the Newton kernel's check (determinate) or
   :func:`openfdk.kinematics.stages.marker_stage` (tracking; Φ, Φ_q̂ then come with
   the velocity kernel's one evaluation of the rows);
2. velocity and acceleration — ``velocity_stage_determinate`` / ``velocity_stage_tracking``;
3. forces and 4. equilibrium — :func:`openfdk.dynamics.stages.equilibrium_stage`;
5. recruitment — :func:`openfdk.dynamics.stages.recruitment_stage`;
6. FDK — :mod:`openfdk.fdk.residual` (f^FDK) and :mod:`openfdk.fdk.jacobian` (J), which
   reads what the stages above left (Φ_q̂, the KKT matrix and multipliers, C, d, s and
   the recruitment solution) instead of evaluating them again.

Shapes: n = 6 n_moving (virtual displacements q̂), m = constraint rows (joints, drivers,
FDK rows), n_markers, n_muscles, n_cols = columns of C.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class FrameData:
    """Workspace of one frame at one pose (fields None until their stage ran)."""

    # -- inputs ---------------------------------------------------------------------
    t: float = 0.0  #: time (s)
    alpha: np.ndarray = None  #: (n_fdk,) FDK inputs α, m or rad (held: α̇ = α̈ = 0)

    # -- 1. position stage (kinematics.stages; see the module docstring) -------------
    Phi: np.ndarray = None  #: (m,) Φ(q, t), m or rad (Eq. 1)
    Phi_q: np.ndarray = None  #: (m, n) Φ_q̂ at the solved pose
    nu: np.ndarray = None  #: (m,) ν = −Φ_t (Eq. 2)
    p_M: np.ndarray = None  #: (3 n_markers,) m, model marker positions (tracking)
    J_M: np.ndarray = None  #: (3 n_markers, n) marker Jacobian Ψ_q̂ (tracking)
    kkt: np.ndarray = None  #: (n + m, n + m) KKT matrix of the last Gauss–Newton step (tracking, Eqs. 4–5, 8–10)
    lam: np.ndarray = None  #: (m,) constraint multipliers λ of that step (tracking)
    x_M: np.ndarray = None  #: (n_markers, 3) m measured marker positions (tracking)
    visible: np.ndarray = None  #: (n_markers,) bool (tracking)
    delta: np.ndarray = None  #: (n_markers, 3) m residual δ = Ψ (NaN where not visible; Eq. 7)

    # -- 2. velocity / acceleration stage -------------------------------------------
    v: np.ndarray = None  #: (n,) [m/s, rad/s] (Eqs. 2, 8–9)
    vdot: np.ndarray = None  #: (n,) [m/s², rad/s²] (Eqs. 3, 10)
    gamma: np.ndarray = None  #: (m,) γ, Φ_q̂ v̇ = γ (Eq. 3)

    # -- 3. forces stage (dynamics.stages.equilibrium_stage) -------------------------
    muscle_length: np.ndarray = None  #: (n_muscles,) m, path lengths l
    L: np.ndarray = None  #: (n_muscles, n) path Jacobians ∂l/∂q̂ (moment arms)
    muscle_speed: np.ndarray = None  #: (n_muscles,) m/s, L v
    muscle_strength: np.ndarray = None  #: (n_muscles,) N, s of the Hill model
    muscle_passive: np.ndarray = None  #: (n_muscles,) N, parallel-element force
    forces: dict = None  #: outputs of the model's force sets by kind (:mod:`openfdk.forces.forceset`)

    # -- 4. equilibrium stage --------------------------------------------------------
    C: np.ndarray = None  #: (n_eq, n_cols) coefficient matrix (Eq. 12)
    d: np.ndarray = None  #: (n_eq,) right-hand side [N, N m] (Eq. 13)
    s: np.ndarray = None  #: (n_bounded,) N, strengths of the bounded columns

    # -- 5. recruitment stage --------------------------------------------------------
    recruitment: object = None  #: RecruitmentResult (f, multipliers, active set; Eq. 11)

    # -- 6. FDK ----------------------------------------------------------------------
    f_fdk: np.ndarray = None  #: (n_fdk,) FDK residual forces [N, N m] (Eq. 14)
    J: np.ndarray = None  #: (n_fdk, n_fdk) ∂f^FDK/∂α
