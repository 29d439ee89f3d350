"""Inverse dynamics with muscle recruitment over a trial (paper Eqs. 11–14).

Per frame (DESIGN.md §3 data flow): kinematic state (q, v, v̇) → muscle lengths, speeds,
strengths s and passive forces → passive elements and external loads → C f = d →
recruitment (min G(f^M) s.t. C f = d, 0 ≤ f^M ≤ s) → muscle, reaction and FDK residual
forces. Infeasible frames are flagged with the solver's message naming the rows that
cannot be balanced; the analysis continues.
"""

from __future__ import annotations

import time as _time
from dataclasses import dataclass, field

import numpy as np

from ..dynamics.equilibrium import assemble, equilibrium_layout, inertial_minus_gravity
from ..forces.elements import RECRUITMENT, RecruitmentSettings
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
        self.settings = model.elements.get(RECRUITMENT, RecruitmentSettings())
        self.unilateral_strength = np.array([u[2] for u in self.layout.unilateral], dtype=float)
        if len(self.layout.eq_coords) == 0:
            raise ValueError(f"model {model.name!r}: no body has equilibrium: true; nothing to solve")

    def muscle_states(self, state):
        """Muscle lengths l (nm,) m, path Jacobians L (nm, n), speeds L v (nm,) m/s."""
        if self.paths is None:
            return np.zeros(0), np.zeros((0, state.n_coords)), np.zeros(0)
        l, L = self.paths.evaluate(state)
        return l, L, L @ state.get_v()

    def equilibrium(self, state, vdot, t, alpha=None):
        """C, d, strengths s (n_bounded,), and the muscle/passive states of the frame."""
        A = self.system.jacobian(state)
        l, L, speed = self.muscle_states(state)
        if self.muscle_set is not None:
            s_m, f_p = self.muscle_set.evaluate(l, speed)
            s_m = np.maximum(s_m, MIN_STRENGTH)
        else:
            s_m = f_p = np.zeros(0)
        Q, passive_out, _ = self.passive.generalized_forces(state, t)
        if len(f_p):
            Q -= L.T @ f_p  # passive muscle tension is an applied load
        d_full = inertial_minus_gravity(self.model, state, vdot) - Q
        C, d = assemble(self.layout, A, L, d_full)
        s = np.concatenate([s_m, self.unilateral_strength])
        return C, d, s, (l, speed, s_m, f_p, passive_out)

    def recruit(self, C, d, s, warm=None):
        """Solve the recruitment problem with the model's criterion."""
        lay, st = self.layout, self.settings
        kw = dict(row_names=lay.row_names, column_names=lay.column_names)
        if st.criterion == "minmax":
            from ..recruitment import solve_minmax

            return solve_minmax(C, d, lay.n_bounded, s, **kw)
        from ..recruitment.polynomial import solve_polynomial

        return solve_polynomial(C, d, lay.n_bounded, s, st.power, x0=warm, tol=st.tolerance, **kw)

    def frame(self, state, vdot, t, alpha=None, warm=None):
        """Inverse dynamics of one frame; ``state`` holds q and v, ``vdot`` (n,)."""
        C, d, s, (l, speed, s_m, f_p, passive_out) = self.equilibrium(state, vdot, t, alpha)
        res = self.recruit(C, d, s, warm)
        return FrameForces(res.f, l, speed, s_m, f_p, passive_out, bool(res.converged), res.status,
                           "" if res.converged else res.message, int(res.iterations), res, C, d, s)


@dataclass(frozen=True)
class InverseDynamicsResult:
    """Forces over a trial. forces : (nf, n_columns) N; column_names;
    muscle_length/speed/strength/passive : (nf, n_muscles); ligament_* and spring_* :
    (nf, n); converged (nf,) bool; status; messages; iterations (nf,)."""

    time: np.ndarray
    column_names: tuple
    muscle_names: tuple
    n_bounded: int
    forces: np.ndarray
    muscle_length: np.ndarray
    muscle_speed: np.ndarray
    muscle_strength: np.ndarray
    muscle_passive: np.ndarray
    ligament_names: tuple
    ligament_length: np.ndarray
    ligament_strain: np.ndarray
    ligament_force: np.ndarray
    spring_names: tuple
    spring_force: np.ndarray
    converged: np.ndarray
    status: tuple
    messages: tuple
    iterations: np.ndarray
    wall_time: float = 0.0
    extra: dict = field(default_factory=dict)

    def failed_frames(self):
        return [(int(i), float(self.time[i]), self.messages[i]) for i in np.flatnonzero(~self.converged)]

    def summary(self):
        return {
            "frames": int(len(self.time)),
            "converged_frames": int(np.sum(self.converged)),
            "failed_frames": [{"frame": i, "time": t, "reason": m} for i, t, m in self.failed_frames()],
            "mean_recruitment_iterations": float(np.mean(self.iterations)) if len(self.iterations) else 0.0,
            "wall_time_s": self.wall_time,
        }


class ForcesRecorder:
    """Collects FrameForces of a trial into the arrays of an InverseDynamicsResult."""

    def __init__(self, solver, nf):
        lay = solver.layout
        self.solver, self.nf = solver, nf
        nm, nl, ns = lay.n_muscles, len(solver.passive.ligaments), len(solver.passive.springs)
        self.F = np.full((nf, lay.n_columns), np.nan)
        self.ml, self.mv, self.ms, self.mp = (np.full((nf, nm), np.nan) for _ in range(4))
        self.ll, self.ls, self.lf = (np.full((nf, nl), np.nan) for _ in range(3))
        self.sf = np.full((nf, ns), np.nan)
        self.ok = np.zeros(nf, dtype=bool)
        self.status, self.msgs = ["kinematics_failed"] * nf, [""] * nf
        self.iters = np.zeros(nf, dtype=int)
        self.contact_cols = {}

    def record(self, k, fr, t):
        """Store frame k's forces (fr: FrameForces) at time t (s)."""
        self.F[k], self.ml[k], self.mv[k] = fr.f, fr.muscle_length, fr.muscle_speed
        self.ms[k], self.mp[k] = fr.muscle_strength, fr.muscle_passive
        self.ll[k], self.ls[k], self.lf[k] = fr.passive.ligament_length, fr.passive.ligament_strain, fr.passive.ligament_force
        self.sf[k] = fr.passive.spring_force
        self.ok[k], self.status[k], self.iters[k] = fr.converged, fr.status, fr.iterations
        if not fr.converged:
            self.msgs[k] = f"frame {k} (t = {t:.4f} s): {fr.message}"
        _collect_contacts(self.contact_cols, fr.passive.contact, k, self.nf)

    def fail(self, k, status, message):
        self.ok[k], self.status[k], self.msgs[k] = False, status, message

    def result(self, time, wall_time, extra_columns=None):
        lay, p = self.solver.layout, self.solver.passive
        cols = dict(self.contact_cols)
        cols.update(extra_columns or {})
        return InverseDynamicsResult(
            np.asarray(time), lay.column_names, tuple(m.name for m in lay.muscles), lay.n_bounded, self.F,
            self.ml, self.mv, self.ms, self.mp, tuple(x.name for x in p.ligaments), self.ll, self.ls, self.lf,
            tuple(x.name for x in p.springs), self.sf, self.ok, tuple(self.status), tuple(self.msgs),
            self.iters, wall_time, {"columns": cols},
        )


def run_inverse_dynamics(model, kin, progress=False, solver=None):
    """Inverse dynamics for every frame of a KinematicsResult ``kin``.

    Frames whose kinematics failed are flagged ("kinematics failed: ...") with NaN forces.
    """
    t0 = _time.perf_counter()
    solver = solver or InverseDynamics(model)
    nf = len(kin.time)
    rec = ForcesRecorder(solver, nf)
    state = model.initial_state()
    warm = None
    bar = None
    if progress:
        from ..progress import progress as _display

        bar = _display(nf, "inverse dynamics", "frame")
    for k in range(nf):
        if not kin.converged[k]:
            rec.fail(k, "kinematics_failed", f"kinematics failed: {kin.messages[k]}")
        else:
            state.set_q(kin.q[k])
            state.set_v(kin.v[k])
            fr = solver.frame(state, kin.vdot[k], kin.time[k], kin.alpha, warm)
            rec.record(k, fr, kin.time[k])
            warm = fr.recruitment if fr.converged else None
        if bar:
            bar.update()
    if bar:
        bar.close()
    return rec.result(kin.time, _time.perf_counter() - t0)


def _collect_contacts(cols, contacts, k, nf):
    """Per-contact outputs of frame k into columns (force on the vertex body, world, N;
    centre of pressure m; area m²; peak pressure Pa; vertices in contact)."""
    for name, res in contacts.items():
        values = {
            f"{name}.Fx_N": res.force_W[0], f"{name}.Fy_N": res.force_W[1], f"{name}.Fz_N": res.force_W[2],
            f"{name}.cop_x_m": res.cop_W[0], f"{name}.cop_y_m": res.cop_W[1], f"{name}.cop_z_m": res.cop_W[2],
            f"{name}.area_m2": res.area, f"{name}.peak_pressure_Pa": res.peak_pressure,
            f"{name}.n_contact": res.n_contact,
        }
        for key, v in values.items():
            cols.setdefault(key, np.full(nf, np.nan))[k] = v
