"""FDK over a trial: per frame, Newton on f^FDK(α) = 0, warm-started across frames.

Warm start: α of frame k starts from the linear extrapolation 2 α_{k−1} − α_{k−2} of two
converged predecessors (or α_{k−1}, or the DOFs' initial values), and the poses of the
previous frame's solution. Every frame reports converged, Newton iterations, residual
evaluations (each a recruitment solve), final max |f^FDK| and α; a frame that does not
converge keeps its best iterate, is flagged with the reason, and the run goes on.
"""

from __future__ import annotations

import time as _time
from dataclasses import dataclass

import numpy as np

from ..analysis.inverse_dynamics import ForcesRecorder, InverseDynamics
from ..kinematics.analysis import KinematicsResult
from ..kinematics.system import ConstraintSystem
from ..kinematics.tracking import MarkerTracker, TrackingSettings
from .newton import solve_frame
from .residual import FDKContext, FrameWorkspace
from .settings import fdk_settings


@dataclass(frozen=True)
class FDKResult:
    """kinematics : KinematicsResult at the final α of each frame; forces :
    InverseDynamicsResult; alpha, f_fdk : (nf, n_fdk) SI; converged (nf,); iterations,
    evaluations (residual evaluations), jacobians (Jacobians computed) (nf,) int; reasons, messages : per frame; dof_names; settings."""

    kinematics: KinematicsResult
    forces: object
    dof_names: tuple
    alpha: np.ndarray
    f_fdk: np.ndarray
    converged: np.ndarray
    iterations: np.ndarray
    evaluations: np.ndarray
    reasons: tuple
    messages: tuple
    settings: object
    wall_time: float
    jacobians: np.ndarray = None  # (nf,) int: Jacobians computed per frame

    def summary(self):
        nf = len(self.converged)
        return {
            "frames": int(nf),
            "converged_frames": int(self.converged.sum()),
            "convergence_rate": float(self.converged.mean()) if nf else 0.0,
            "mean_residual_evaluations_per_frame": float(self.evaluations.mean()) if nf else 0.0,
            "mean_newton_iterations_per_frame": float(self.iterations.mean()) if nf else 0.0,
            "mean_jacobians_per_frame": (float(self.jacobians.mean()) if nf and self.jacobians is not None
                                         else None),
            "reuse_jacobian": self.settings.reuse_jacobian,
            "max_final_residual": float(np.nanmax(np.abs(self.f_fdk))) if nf else 0.0,
            "jacobian": self.settings.jacobian,
            "tolerance": self.settings.tolerance,
            "failed_frames": [
                {"frame": int(i), "time": float(self.kinematics.time[i]), "reason": self.reasons[i], "message": self.messages[i]}
                for i in np.flatnonzero(~self.converged)
            ],
            "wall_time_s": self.wall_time,
            "frames_per_second": nf / self.wall_time if self.wall_time > 0 else None,
        }

    def columns(self):
        """Extra forces.csv columns: α, f^FDK and FDK diagnostics per frame."""
        cols = {}
        for j, name in enumerate(self.dof_names):
            cols[f"fdk.{name}.alpha"] = self.alpha[:, j]
            cols[f"fdk.{name}.residual"] = self.f_fdk[:, j]
        cols["fdk_converged"] = self.converged.astype(int)
        cols["fdk_iterations"] = self.iterations
        cols["fdk_evaluations"] = self.evaluations
        if self.jacobians is not None:
            cols["fdk_jacobians"] = self.jacobians
        cols["fdk_reason"] = list(self.reasons)
        return cols


def run_fdk(model, trajectories=None, times=None, settings=None, progress=False, tracking=None, **overrides):
    """Force-dependent kinematics over a trial.

    trajectories : marker trajectories (``evaluate(t)``) in model marker order, or None
    for determinate kinematics (drivers); times : (nf,) s, uniform (default: the trial's
    sample times); settings : FDKSettings (default: the model's ``fdk`` section).
    """
    t0 = _time.perf_counter()
    if not model.fdk_dofs:
        raise ValueError(f"model {model.name!r} declares no FDK DOFs (section fdk_dofs)")
    settings = settings or fdk_settings(model, **overrides)
    if times is None:
        times = np.asarray(trajectories.time, dtype=float)
    times = np.asarray(times, dtype=float)
    nf, n_fdk = len(times), len(model.fdk_dofs)
    system = ConstraintSystem(model)
    solver = InverseDynamics(model, system)
    tracker, meas = None, None
    if trajectories is not None:
        tracker = MarkerTracker(system, tracking or TrackingSettings())
        meas = [trajectories.evaluate(t) for t in times]
    ctx = FDKContext(model, solver, tracker, meas, times)

    n = model.n_coords
    q = np.full((nf, 7 * n // 6), np.nan)
    v = np.full((nf, n), np.nan)
    vd = np.full((nf, n), np.nan)
    nm = model.markers.size
    resid = np.full((nf, nm if tracker else 0, 3), np.nan)
    viol = np.full(nf, np.nan)
    kin_ok = np.zeros(nf, dtype=bool)
    kin_msgs = [""] * nf
    alpha = np.full((nf, n_fdk), np.nan)
    f_fdk = np.full((nf, n_fdk), np.nan)
    ok = np.zeros(nf, dtype=bool)
    iters = np.zeros(nf, dtype=int)
    evals = np.zeros(nf, dtype=int)
    jacobians = np.zeros(nf, dtype=int)
    reasons, msgs = [""] * nf, [""] * nf
    rec = ForcesRecorder(solver, nf)

    state0 = model.initial_state()
    if tracker is not None:
        first = next((j for j in range(nf) if np.any(meas[j][3])), 0)
        tracker.initial_guess(state0, meas[first][0], meas[first][3])
    last_state = state0
    a_init = np.array([d.initial for d in model.fdk_dofs])
    history = []  # α of the most recent converged frames
    warm = None
    J_carry = None  # the last converged frame's FDK Jacobian (settings.reuse_jacobian)
    bar = None
    if progress:
        from ..progress import progress as _display

        bar = _display(nf, "FDK", "frame")
    for k in range(nf):
        ws = FrameWorkspace({j: last_state for j in ctx.frames_needed(k)})
        if settings.extrapolate and len(history) >= 2 and history[-1][0] == k - 1 and history[-2][0] == k - 2:
            a0 = 2 * history[-1][1] - history[-2][1]
        elif history:
            a0 = history[-1][1].copy()
        else:
            a0 = a_init.copy()
        sol = solve_frame(ctx, k, a0, ws, settings, warm, J_carry)
        J_carry = sol.jacobian if sol.converged else None
        jacobians[k] = sol.jacobians
        ev = sol.best
        iters[k], evals[k], reasons[k] = sol.iterations, sol.evaluations, sol.reason
        ok[k] = sol.converged
        if not sol.converged:
            msgs[k] = f"frame {k} (t = {times[k]:.4f} s): FDK not converged: {sol.message}"
        alpha[k] = ev.alpha
        if ev.ok:
            f_fdk[k] = ev.f_fdk
        if ev.state is not None:
            kin_ok[k] = True
            q[k], v[k], vd[k] = ev.state.get_q(), ev.state.get_v(), ev.vdot
            viol[k] = float(np.max(np.abs(system.evaluate(ev.state, times[k], ev.alpha, order=0)[0])))
            if tracker is not None and ev.delta is not None:
                resid[k] = ev.delta
            last_state = ev.state
        else:
            kin_msgs[k] = sol.message
        if ev.frame is not None:
            rec.record(k, ev.frame, times[k])
            if not sol.converged:
                rec.fail(k, "fdk_" + sol.reason, msgs[k])
        else:
            rec.fail(k, "fdk_" + sol.reason, msgs[k])
        if sol.converged:
            history.append((k, ev.alpha.copy()))
            history = history[-2:]
            warm = ev.frame.recruitment
        if bar:
            bar.update()
            bar.set_postfix(converged=f"{ok[: k + 1].mean():.0%}")
    if bar:
        bar.close()
    wall = _time.perf_counter() - t0
    kin = KinematicsResult(
        model.name, tuple(b.name for b in model.moving_bodies), model.markers.names, times, q, v, vd, resid, viol,
        np.zeros(nf, dtype=int), kin_ok, tuple(kin_msgs), alpha[0] if nf else a_init, wall,
        "fdk-tracking" if tracker else "fdk-determinate",
    )
    res = FDKResult(kin, None, tuple(d.name for d in model.fdk_dofs), alpha, f_fdk, ok, iters, evals,
                    tuple(reasons), tuple(msgs), settings, wall, jacobians)
    forces = rec.result(times, wall, res.columns())
    return FDKResult(kin, forces, res.dof_names, alpha, f_fdk, ok, iters, evals, tuple(reasons), tuple(msgs), settings, wall,
                     jacobians)
