"""A whole trial in one pass of the trial driver: kinematics then inverse dynamics
frame by frame, or FDK. This is what ``openfdk run`` and chunked runs execute.

Each finished frame carries its kinematics and forces, so checkpoints
(:mod:`openfdk.trial.checkpoint`) and an interrupted run's partial result hold whole
frames. The numbers are those of :func:`openfdk.kinematics.analysis.run_tracking` (or
``run_determinate``) followed by :func:`openfdk.analysis.inverse_dynamics.run_inverse_dynamics`:
the same per-frame solves in the same order with the same warm starts. A determinate
run of a tree of OpenSim-style joints driven by its coordinates takes the compiled path
of :mod:`openfdk.analysis.tree_trial` (forward kinematics, whole chunks of frames per
call; the same values), when it covers the model; every other run the trial driver's.
"""

from __future__ import annotations

import time as _time

import numpy as np

from ..dynamics.inverse import InverseDynamics
from ..dynamics.results import forces_result
from ..kinematics.analysis import (DeterminateStep, TrackingStep, alpha_inputs, kinematics_result, tracking_times)
from ..trial import drive
from .inverse_dynamics import DynamicsStep
from .tree_trial import tree_trial


class KinematicsDynamicsStep:
    """Trial-driver step: a kinematics step, then inverse dynamics of every frame it
    finishes (warm-started from the previous converged frame's recruitment)."""

    def __init__(self, kinematics, dynamics):
        self.kinematics, self.dynamics = kinematics, dynamics

    def fields(self):
        return {**self.kinematics.fields(), **self.dynamics.fields()}

    def _forces(self, finished):
        for j, values in finished:
            data = self.kinematics.frame_data.pop(j, None)  # Φ_q̂ of the position stage
            values.update(self.dynamics.frame(j, values.get("kin.q"), values.get("kin.v"), values.get("kin.vdot"),
                                              values["kin.report"], None if data is None else data.Phi_q))
        return finished

    def step(self, k):
        return self._forces(self.kinematics.step(k))

    def finish(self):
        return self._forces(self.kinematics.finish())

    def carry(self):
        return self.kinematics.carry(), self.dynamics.carry()

    def restore(self, carry):
        self.kinematics.restore(carry[0])
        self.dynamics.restore(carry[1])


def run_trial(model, trajectories, times, *, settings=None, progress=False, checkpoints=None, resume=False):
    """Kinematics + inverse dynamics (or FDK when the model has FDK DOFs) over ``times``
    (nf,) s; ``trajectories`` None means determinate kinematics; settings :
    AnalysisSettings (recruitment, ``fdk``; default: the defaults).

    checkpoints, resume : see :func:`openfdk.trial.drive`. Returns (KinematicsResult,
    InverseDynamicsResult, FDKResult or None). Ctrl-C raises
    :class:`openfdk.trial.TrialInterrupted` whose ``partial`` is that triple for the
    frames finished.
    """
    t0 = _time.perf_counter()
    times = np.asarray(times, dtype=float)
    if model.fdk_dofs:
        from ..fdk.analysis import fdk_result, fdk_step

        step = fdk_step(model, trajectories, times, settings)
        ctx, solver_settings = step.ctx, step.settings

        def build(rec):
            res = fdk_result(rec, model, ctx, solver_settings, times[: rec.n_frames], _time.perf_counter() - t0)
            return res.kinematics, res.forces, res

        return drive(step, len(times), build, progress=progress, desc="FDK", checkpoints=checkpoints, resume=resume)
    alpha = alpha_inputs(model, None)
    if trajectories is None:
        kin_step, mode = DeterminateStep(model, times, alpha), "determinate"
    else:
        if model.markers.size == 0:
            raise ValueError(f"model {model.name!r} has no markers to track")
        times = tracking_times(trajectories, times)
        kin_step, mode = TrackingStep(model, trajectories, times, alpha), "tracking"
    # the kinematics' constraint program serves the equilibrium too (compiled once per run)
    solver = InverseDynamics(model, system=getattr(kin_step, "system", None), settings=settings)

    def build(rec):
        n, wall = rec.n_frames, _time.perf_counter() - t0
        kin = kinematics_result(rec, model, times[:n], alpha, wall, mode)
        return kin, forces_result(rec, solver, times[:n], wall), None

    if mode == "determinate":  # a tree driven by its coordinates: whole chunks of frames per compiled call
        trial, _ = tree_trial(model, kin_step.system, solver, times, alpha)
        if trial is not None:
            if checkpoints is not None and not resume:
                checkpoints.clear()  # (no warm start: a resumed run computes every frame again)
            result = trial.run(build, progress)
            if result is not None:
                return result  # else a frame failed: the frame-by-frame path below names it
    step = KinematicsDynamicsStep(kin_step, DynamicsStep(model, solver, times, None, None, None, None, alpha))
    return drive(step, len(times), build, progress=progress, desc="kinematics + inverse dynamics",
                 checkpoints=checkpoints, resume=resume)
