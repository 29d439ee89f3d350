"""Inverse dynamics with muscle recruitment over a trial (paper Eqs. 11–14).

The per-frame equilibrium and recruitment live in :mod:`openfdk.dynamics.inverse`; this
module runs them over the frames of a KinematicsResult with the trial driver
(:mod:`openfdk.trial`), warm-starting each frame's recruitment from the previous
converged frame. Frames whose kinematics failed are flagged (reason ``kinematics``)
with NaN forces; the analysis continues.
"""

from __future__ import annotations

import time as _time

from ..dynamics.inverse import MIN_STRENGTH, FrameForces, InverseDynamics
from ..dynamics.results import InverseDynamicsResult, forces_failure, forces_fields, forces_result, forces_values
from ..trial import drive
from ..trial.status import FrameReport, Reason

__all__ = ["run_inverse_dynamics", "InverseDynamics", "InverseDynamicsResult", "FrameForces", "MIN_STRENGTH",
           "DynamicsStep"]


class DynamicsStep:
    """Trial-driver step: inverse dynamics of frame k of a given kinematic history.

    solver : InverseDynamics; time (nf,) s; q (nf, 7 n_moving); v, vdot (nf, n);
    kin_reports : FrameReport per frame; alpha : (n_fdk,) FDK inputs. Warm start: the
    previous converged frame's recruitment.
    """

    def __init__(self, model, solver, time, q, v, vdot, kin_reports, alpha):
        self.model, self.solver = model, solver
        self.time, self.q, self.v, self.vdot = time, q, v, vdot
        self.kin_reports, self.alpha = kin_reports, alpha
        self.state = model.initial_state()
        self.warm = None
        solver.forces.prepare(time)  # measured loads sampled at every frame time at once

    def fields(self):
        return forces_fields(self.solver)

    def frame(self, k, q, v, vdot, kin_report, Phi_q=None):
        """Values of frame k from its kinematics (q, v, v̇) or its failed report;
        Phi_q (m, n) : Φ_q̂ at q when the kinematic position stage has it."""
        if not kin_report.converged:
            return forces_failure(FrameReport.failed(Reason.KINEMATICS, f"kinematics failed: {kin_report.message}"),
                                  "kinematics_failed")
        if self.model.external_loads:
            from ..forces.data_loads import invalid_reason

            reason = invalid_reason(self.model.external_loads, self.time[k])
            if reason:
                return forces_failure(FrameReport.failed(Reason.FAILED, reason), "loads_unknown")
        self.state.set_q(q)
        self.state.set_v(v)
        try:
            fr = self.solver.frame(self.state, vdot, self.time[k], self.alpha, self.warm, A=Phi_q)
        except FloatingPointError as exc:  # a pose where a path or measure is undefined (e.g. inside a wrap)
            self.warm = None
            return forces_failure(FrameReport.failed(Reason.FAILED, str(exc)),
                                  "failed")
        self.warm = fr.recruitment if fr.converged else None
        return forces_values(fr)

    def step(self, k):
        return [(k, self.frame(k, self.q[k], self.v[k], self.vdot[k], self.kin_reports[k]))]

    def finish(self):
        return []

    def carry(self):
        return self.warm

    def restore(self, carry):
        self.warm = carry


def run_inverse_dynamics(model, kin, progress=False, solver=None, settings=None):
    """Inverse dynamics for every frame of a KinematicsResult ``kin``; settings :
    AnalysisSettings (its recruitment; default: the default criterion), or a ready
    ``solver`` (InverseDynamics).

    Frames whose kinematics failed are flagged ("kinematics failed: ...") with NaN forces.
    """
    t0 = _time.perf_counter()
    solver = solver or InverseDynamics(model, settings=settings)
    step = DynamicsStep(model, solver, kin.time, kin.q, kin.v, kin.vdot, kin.reports, kin.alpha)

    def build(rec):
        n = rec.n_frames
        return forces_result(rec, solver, kin.time[:n], _time.perf_counter() - t0)

    return drive(step, len(kin.time), build, progress=progress, desc="inverse dynamics")
