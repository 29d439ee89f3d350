"""Inverse dynamics of one frame: equilibrium and muscle recruitment (paper Eqs. 11–14).

Per frame (DESIGN.md §3 data flow): kinematic state (q, v, v̇) → muscle lengths, speeds,
strengths s and passive forces → passive elements and external loads → C f = d →
recruitment (min G(f^M) s.t. C f = d, 0 ≤ f^M ≤ s) → muscle, reaction and FDK residual
forces. Infeasible frames are flagged with the solver's message naming the rows that
cannot be balanced. The loop over a trial is :mod:`openfdk.analysis.inverse_dynamics`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..model.framedata import FrameData
from .equilibrium import assemble, equilibrium_layout, inertial_minus_gravity
from .stages import equilibrium_stage, recruitment_stage
from ..forces.elements import RecruitmentSettings
from ..forces.passive import PassiveElements
from ..forces.pathset import PathSet
from ..kinematics.system import ConstraintSystem

#: strengths below this (N) are raised to it so that the recruitment stays defined; a
#: muscle shorter than its tendon slack length thus delivers (numerically) nothing.
MIN_STRENGTH = 1e-6


@dataclass
class FrameForces:
    """Forces of one frame. f : (n_columns,) N (columns: layout.column_names);
    muscle_* : (n_muscles,); converged, status, message, iterations; recruitment result."""

    f: np.ndarray
    muscle_length: np.ndarray
    muscle_speed: np.ndarray
    muscle_strength: np.ndarray
    muscle_passive: np.ndarray
    passive: object
    converged: bool
    status: str
    message: str
    iterations: int
    recruitment: object = None
    C: np.ndarray = None
    d: np.ndarray = None
    s: np.ndarray = None


class InverseDynamics:
    """Per-frame inverse dynamics of a model (holds the layout and solver settings).

    The model is not modified; all per-frame data live in the returned FrameForces.
    """

    def __init__(self, model, system=None):
        from ..forces.hill import MuscleSet

        self.model = model
        self.system = system or ConstraintSystem(model)
        self.layout = equilibrium_layout(model, self.system)
        muscles = self.layout.muscles
        self.muscle_set = MuscleSet([m.law for m in muscles]) if muscles else None
        self.paths = PathSet(muscles) if muscles else None
        self.passive = PassiveElements(model)
        self.settings = model.settings.recruitment or RecruitmentSettings()
        self.unilateral_strength = np.array([u[2] for u in self.layout.unilateral], dtype=float)
        if self.settings.criterion == "minmax":
            from ..recruitment import solve_minmax as solve
        else:
            from ..recruitment.polynomial import solve_polynomial as solve
        self._solve = solve  # the recruitment solver of the model's criterion (Eq. 11)
        if len(self.layout.eq_coords) == 0:
            raise ValueError(f"model {model.name!r}: no body has equilibrium: true; nothing to solve")

    def muscle_states(self, state):
        """Muscle lengths l (nm,) m, path Jacobians L (nm, n), speeds L v (nm,) m/s."""
        if self.paths is None:
            return np.zeros(0), np.zeros((0, state.n_coords)), np.zeros(0)
        l, L = self.paths.evaluate(state)
        return l, L, L @ state.get_v()

    def equilibrium(self, state, vdot, t, alpha=None, A=None, elements=True):
        """C, d, strengths s (n_bounded,), and the muscle/passive states of the frame.
        A : Φ_q̂ (m, n) at this pose when the position stage has it (else evaluated);
        elements : include the passive elements in d (False: only external loads and
        passive muscle tension, for the analytic FDK Jacobian)."""
        if A is None:
            A = self.system.jacobian(state)
        l, L, speed = self.muscle_states(state)
        if self.muscle_set is not None:
            s_m, f_p = self.muscle_set.evaluate(l, speed)
            s_m = np.maximum(s_m, MIN_STRENGTH)
        else:
            s_m = f_p = np.zeros(0)
        Q, passive_out, _ = self.passive.generalized_forces(state, t, elements=elements)
        if len(f_p):
            Q -= L.T @ f_p  # passive muscle tension is an applied load
        d_full = inertial_minus_gravity(self.model, state, vdot) - Q
        C, d = assemble(self.layout, A, L, d_full)
        s = np.concatenate([s_m, self.unilateral_strength])
        return C, d, s, (l, speed, s_m, f_p, passive_out)

    def recruit(self, C, d, s, warm=None):
        """Solve the recruitment problem with the model's criterion (C (n_eq, n_cols),
        d (n_eq,) [N, N m], s (n_bounded,) N; warm: a previous RecruitmentResult)."""
        lay, st = self.layout, self.settings
        if st.criterion == "minmax":
            return self._solve(C, d, lay.n_bounded, s, row_names=lay.row_names, column_names=lay.column_names)
        return self._solve(C, d, lay.n_bounded, s, st.power, x0=warm, tol=st.tolerance, row_names=lay.row_names,
                           column_names=lay.column_names)

    def frame(self, state, vdot, t, alpha=None, warm=None, A=None, data=None):
        """Inverse dynamics of one frame; ``state`` holds q and v, ``vdot`` (n,);
        A : Φ_q̂ (m, n) at this pose if known; data : the frame's FrameData (its
        equilibrium and recruitment stages are filled)."""
        if data is None:
            data = FrameData(t=t, alpha=alpha, Phi_q=A)
        data.vdot = vdot
        equilibrium_stage(self, data, state)
        recruitment_stage(self, data, warm)
        res = data.recruitment
        return FrameForces(res.f, data.muscle_length, data.muscle_speed, data.muscle_strength, data.muscle_passive,
                           data.passive, bool(res.converged), res.status, "" if res.converged else res.message,
                           int(res.iterations), res, data.C, data.d, data.s)
