"""Inverse dynamics of one frame: equilibrium and muscle recruitment (paper Eqs. 11–14).

Per frame (docs/design.md §3 data flow): kinematic state (q, v, v̇) → muscle lengths, speeds,
strengths s and passive tension → every force set's applied loads
(:mod:`openfdk.forces.forceset`) → C f = d →
recruitment (min G(f^M) s.t. C f = d, 0 ≤ f^M ≤ s) → muscle, reaction and FDK residual
forces. Infeasible frames are flagged with the solver's message naming the rows that
cannot be balanced. The loop over a trial is :mod:`openfdk.analysis.inverse_dynamics`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..model.framedata import FrameData
from .determinate_reactions import determinate_reactions, reactions_form
from .equilibrium import assemble, equilibrium_layout, inertial_minus_gravity
from .stages import equilibrium_stage, recruitment_stage
from ..forces.actuators import ActuatorColumns, expand_columns, fold_result
from ..forces.elements import RecruitmentSettings
from ..recruitment.result import RecruitmentResult
from ..forces.forceset import ForceElements
from ..forces.muscle_forces import MIN_STRENGTH, MuscleOutputs
from ..kinematics.system import ConstraintSystem


@dataclass
class FrameForces:
    """Forces of one frame. f : (n_columns,) N (columns: layout.column_names);
    muscle_* : (n_muscles,); forces : the force sets' outputs by kind; converged, status, message, iterations; recruitment result."""

    f: np.ndarray
    muscle_length: np.ndarray
    muscle_speed: np.ndarray
    muscle_strength: np.ndarray
    muscle_passive: np.ndarray
    forces: dict
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
    settings : AnalysisSettings (its ``recruitment``; default: the default criterion).
    """

    def __init__(self, model, system=None, settings=None):
        self.model = model
        self.system = system or ConstraintSystem(model)
        self.layout = equilibrium_layout(model, self.system)
        #: the RecruitmentSettings used
        self.settings = (settings.recruitment if settings is not None else None) or RecruitmentSettings()
        self.forces = ForceElements(model, self.settings.static_optimization)
        self.muscles = self.forces.by_kind.get("muscles")  # MuscleForces or None
        self.unilateral_strength = np.array([u[2] for u in self.layout.unilateral], dtype=float)
        self.actuators = ActuatorColumns(model.actuators)
        # activity bounds l ≤ f/s ≤ u of the bounded columns [muscles, actuators, unilateral]
        opensim = self.settings.static_optimization == "opensim"
        nm = self.layout.n_muscles
        self.lower = np.zeros(self.layout.n_bounded)
        self.upper = np.ones(self.layout.n_bounded)
        if opensim:
            self.lower[:nm] = [m.min_control for m in model.muscles]
            self.upper[:nm] = [m.max_control for m in model.muscles]
        if self.actuators and self.settings.criterion != "polynomial":
            raise ValueError(f"model {model.name!r}: actuators ({', '.join(self.actuators.names[:3])}"
                             f"{', …' if len(self.actuators) > 3 else ''}) are weighted by their optimal force in the "
                             f"polynomial criterion; the {self.settings.criterion} criterion has no such weight "
                             "(recruitment: criterion: polynomial)")
        if self.settings.criterion == "minmax":
            from ..recruitment import solve_minmax as solve
        else:
            from ..recruitment.polynomial import solve_polynomial as solve
        self._solve = solve  # the recruitment solver of the model's criterion (Eq. 11)
        # statically determinate frames (no recruited column, square C): one block solve
        self._determinate = reactions_form(self.system, self.layout) if self.settings.criterion == "polynomial" \
            else None
        if len(self.layout.eq_coords) == 0:
            raise ValueError(f"model {model.name!r}: no body has equilibrium: true; nothing to solve")

    def equilibrium(self, state, vdot, t, alpha=None, A=None, forces=True, muscles=None):
        """C, d, strengths s (n_bounded,), the muscles' MuscleOutputs and the force
        sets' outputs by kind. A : Φ_q̂ (m, n) at this pose when the position stage has
        it (else evaluated); forces : include the applied loads of every force set in d
        (False: inertial terms only, muscles' C and s kept; for the analytic FDK
        Jacobian, which takes the sets' part from their stiffness); muscles : with
        forces False, the MuscleOutputs to use at this pose (else evaluated)."""
        if A is None:
            A = self.system.jacobian(state)
        n = state.n_coords
        Q = np.zeros(n)
        if forces:
            outputs = self.forces.accumulate(state, t, Q)  # forces stage (Eq. 13)
            muscles = outputs.get("muscles")
        else:
            if muscles is None and self.muscles is not None:
                muscles = self.muscles.states(state)
            outputs = {}
        if muscles is None:
            muscles = MuscleOutputs.empty(n)
        d_full = inertial_minus_gravity(self.model, state, vdot) - Q
        C, d = assemble(self.layout, A, muscles.L, d_full, self.actuators.jacobian(state))
        s = np.concatenate([muscles.strength, self.actuators.optimal_force, self.unilateral_strength])
        return C, d, s, muscles, outputs

    def recruit(self, C, d, s, warm=None):
        """Solve the recruitment problem with the model's criterion (C (n_eq, n_cols),
        d (n_eq,) [N, N m], s (n_bounded,) N; warm: a previous RecruitmentResult)."""
        lay, st = self.layout, self.settings
        if self._determinate is not None:
            res = determinate_reactions(C, d, self._determinate, st.power)
            if res is not None:
                return res
        if st.criterion == "minmax":
            return self._solve(C, d, lay.n_bounded, s, row_names=lay.row_names, column_names=lay.column_names)
        if self.actuators:
            # each actuator as τ⁺ and τ⁻ columns (forces/actuators.py), folded back after
            first, na = lay.n_muscles, lay.n_actuators
            C_x, s_x, upper, nb = expand_columns(C, s, lay.n_bounded, first, self.actuators)
            lower = np.concatenate([self.lower, np.zeros(na)])
            upper[:first] = self.upper[:first]
            names = lay.column_names[:lay.n_bounded] + tuple(f"{a}(-)" for a in self.actuators.names) + \
                lay.column_names[lay.n_bounded:]
            if warm is not None and not (isinstance(warm, RecruitmentResult) and warm.converged):
                warm = None  # (a converged result's multipliers are all a warm start uses)
            res = self._solve(C_x, d, nb, s_x, st.power, x0=warm, tol=st.tolerance, row_names=lay.row_names,
                              column_names=names, upper=upper, lower=lower)
            return fold_result(res, lay.n_bounded, first, na)
        return self._solve(C, d, lay.n_bounded, s, st.power, x0=warm, tol=st.tolerance, row_names=lay.row_names,
                           column_names=lay.column_names, upper=self.upper, lower=self.lower)

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
                           data.forces, bool(res.converged), res.status, "" if res.converged else res.message,
                           int(res.iterations), res, data.C, data.d, data.s)
