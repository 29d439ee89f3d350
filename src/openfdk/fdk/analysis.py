"""FDK over a trial: per frame, Newton on f^FDK(α) = 0, warm-started across frames.

Warm start: α of frame k starts from the extrapolation of the converged predecessors
(:mod:`.warm_start`: linear from two, quadratic from three where that predicted the
last frame better; or α_{k−1}, or the DOFs' initial values), and the poses of the
previous frame's solution. A frame that fails from there, after a converged frame, is
solved again after marching to it through sub-steps from that frame (:mod:`.approach`),
then from α_{k−1} and from the DOFs' initial values; after a failed frame, from the last
converged frame's α and the initial values (the window's first frame is solved by
pseudo-transient continuation from the initial values, :mod:`.transient`, and reached
through a lead-in when that fails, :mod:`.approach`) (on DM's six gait trials, 12
of the 45 frames that failed from their warm starts converged only through the
sub-steps, after both other starts had failed: 129 evaluations per frame; with the
sub-steps first the trials took 13 484 residual evaluations and 6 006 Jacobians
instead of 14 135 and 6 769, docs/fdk.md). Then from α_{k−1} moved along one DOF at a
time by ±2 and ±4 max_steps, nearest first (setting ``restart``, :func:`~.newton.solve_restarts`;
:func:`scan_starts`): where the branch the previous frames followed ends (a fold of
f^FDK(α) = 0, e.g. a weakly held medio-lateral DOF snapping across the joint), the
remaining root can lie millimetres away, beyond the basin of α_{k−1}; the nearest such
start that converges is the continuation's choice, and the frame counts its restarts.
Last, when every start failed but the best iterate of all came within
:data:`NEAR_SCAN_RANGE` tolerances of the root, from that iterate moved along one DOF at
a time by ±:data:`NEAR_SCAN_STEP` max_step (:func:`near_starts`): such a stall is a kink
of f^FDK(α) next to the root, not a far branch (DM og4 3.117 s: Newton stalls at 11 mN
where the patella engages the trochlear groove, pf_tx's slope growing 400-fold within a
twentieth of the Newton step; from the stall moved by 0.1 max_step, 3 of the 20 starts
converge, from α_{k−1} moved by 2 max_steps none).
A *cold* frame — one whose previous frame did not converge, the first frame among them —
starts from the previous frame's best iterate (when that frame failed) or from the DOFs'
initial values, far from its root, and its first start gets ``cold_max_iterations``
Newton iterations instead of ``max_iterations``: measured on the DM knee (with a patellar
tendon constraint, docs/tutorial-knee-gait.md), a first frame from the initial values
needs 30–60 iterations and every frame after it 3–6.
Sweeping back: when a frame converges after failed ones, the failed frames just before
it are solved again backward from it, warm-started as a forward frame is but from the
frames after it (frame k − 1 from frame k's solution, poses, recruitment and Jacobian, α
extrapolated back), while they converge; the sweep stops at the first that does not, and
each failed frame is tried so at most once (part of the setting ``restart``). The
equilibrium of a frame does not depend on the direction it is reached from; only the
warm start does, and a converged frame's is near. Measured on DM og3 from 3.108 s, a
cold start in terminal stance where every lead-in left the first 7 frames at the
iteration limit (127 evaluations each after the first's 2 409) and frame 3.167 s
converged (132 evaluations): the sweep back solved all 7 in 4–5 evaluations each, 0.5 s
in all; og3 in 2 chunks (its second segment starting there) converges 250 of 250 frames
instead of 246, and the 4 frames solved backward equal the serial run's, solved forward,
to 1.3e-8 rad and 2.9e-10 m (contact forces 6 µN). A frame solved backward is recorded
again (``fdk.backward``, the driver keeps the later record), its counts the failed
solve's plus the sweep's, one more restart. The first failed frame the sweep cannot
solve is recorded again too, its forward best iterate kept, its message ending "solved
backward from the converged frame at t s, not converged either" and its counts
including the sweep's (not after a resume from a checkpoint, which keeps no failed
frame's values).
Every frame reports converged, Newton iterations, residual evaluations (each a
recruitment solve), final max |f^FDK| and α; a frame that does not converge keeps its
best iterate, is flagged with the reason, and the run goes on.

The loop is the trial driver's (:mod:`openfdk.trial`); :class:`FDKStep` is one frame.
"""

from __future__ import annotations

import time as _time
from dataclasses import dataclass, replace

import numpy as np

from ..dynamics.inverse import InverseDynamics
from ..dynamics.results import forces_failure, forces_fields, forces_result, forces_values
from ..kinematics.analysis import KinematicsResult, kinematics_fields, kinematics_result
from ..kinematics.seeded_start import seed_start
from ..kinematics.system import ConstraintSystem
from ..kinematics.tracking import KKTFactors, MarkerTracker, TrackingSettings, window_spacing
from ..trial import drive, restored
from ..trial.status import FrameReport, Reason, frame_messages
from ..model.plausibility import warn_plausibility
from .contact_step import ContactSplit, checked_split
from .absorbed import absorbed_message, fdk_absorbed_muscles
from .approach import approach_for
from .newton import combined, solve_frame, solve_restarts
from .residual import FDKContext, FrameWorkspace, window_measurements
from .settings import fdk_settings
from .warm_start import HISTORY, extrapolated


@dataclass(frozen=True)
class FDKResult:
    """kinematics : KinematicsResult at the final α of each frame; forces :
    InverseDynamicsResult; alpha, f_fdk : (nf, n_fdk) SI; converged (nf,); iterations,
    evaluations (residual evaluations), jacobians (Jacobians computed), restarts (further
    starting α solved after the warm start failed, fdk/newton.py) (nf,) int;
    reports : FrameReport per frame (reasons, messages: their codes and texts);
    dof_names; settings."""

    kinematics: KinematicsResult
    forces: object
    dof_names: tuple
    alpha: np.ndarray
    f_fdk: np.ndarray
    converged: np.ndarray
    iterations: np.ndarray
    evaluations: np.ndarray
    reports: tuple
    settings: object
    wall_time: float
    jacobians: np.ndarray = None  # (nf,) int: Jacobians computed per frame
    restarts: np.ndarray = None  # (nf,) int: restarts per frame (0: solved from the warm start)
    backward: np.ndarray = None  # (nf,) int: 1 where a failed frame was solved again backward (FDKStep)

    @property
    def reasons(self):
        """Per-frame reason codes ('converged', 'line_search', …)."""
        return tuple(r.reason.value for r in self.reports)

    @property
    def messages(self):
        return frame_messages(self.reports, self.kinematics.time)

    def summary(self):
        nf = len(self.converged)
        reasons, messages = self.reasons, self.messages
        return {
            "frames": int(nf),
            "converged_frames": int(self.converged.sum()),
            "convergence_rate": float(self.converged.mean()) if nf else 0.0,
            "mean_residual_evaluations_per_frame": float(self.evaluations.mean()) if nf else 0.0,
            "mean_newton_iterations_per_frame": float(self.iterations.mean()) if nf else 0.0,
            "mean_jacobians_per_frame": (float(self.jacobians.mean()) if nf and self.jacobians is not None
                                         else None),
            "reuse_jacobian": self.settings.reuse_jacobian,
            "restarted_frames": int(np.count_nonzero(self.restarts)) if self.restarts is not None else 0,
            "backward_frames": int(np.count_nonzero(self.backward)) if self.backward is not None else 0,
            "max_final_residual": float(np.nanmax(np.abs(self.f_fdk))) if nf else 0.0,
            "jacobian": self.settings.jacobian,
            "tolerance": self.settings.tolerance,
            "failed_frames": [
                {"frame": int(i), "time": float(self.kinematics.time[i]), "reason": reasons[i], "message": messages[i]}
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
        if self.restarts is not None:
            cols["fdk_restarts"] = self.restarts
        if self.backward is not None:
            cols["fdk_backward"] = self.backward
        cols["fdk_reason"] = list(self.reasons)
        return cols


#: multiples of a DOF's max_step by which :func:`scan_starts` moves α_{k−1}
SCAN_STEPS = (2.0, 4.0)
#: the fraction of a DOF's max_step by which :func:`near_starts` moves a stalled iterate
NEAR_SCAN_STEP = 0.1
#: a frame whose starts all failed is scanned around its best iterate when that came
#: within this many tolerances of the root (module docstring)
NEAR_SCAN_RANGE = 100.0


def axis_starts(centre, max_step, multiples):
    """Restart points (list of (n_fdk,) α): ``centre`` (n_fdk,) SI with each DOF in turn
    moved by −m·max_step and +m·max_step, for each m in ``multiples`` in order (nearest
    first); ``max_step`` (n_fdk,) SI."""
    starts = []
    for m in multiples:
        for i, step in enumerate(np.asarray(max_step, dtype=float)):
            for sign in (-1.0, 1.0):
                a = np.array(centre, dtype=float)
                a[i] += sign * m * step
                starts.append(a)
    return starts


def scan_starts(previous, max_step):
    """Restart points around the previous frame's α (n_fdk,) SI: each DOF moved by
    ±m·max_step for m in :data:`SCAN_STEPS` (:func:`axis_starts`; module docstring)."""
    return axis_starts(previous, max_step, SCAN_STEPS)


def near_starts(best, max_step):
    """Restart points around a stalled best iterate (n_fdk,) SI: each DOF moved by
    ±:data:`NEAR_SCAN_STEP` · max_step (:func:`axis_starts`; module docstring)."""
    return axis_starts(best, max_step, (NEAR_SCAN_STEP,))


class FDKStep:
    """Trial-driver step of FDK: Newton on f^FDK(α) = 0 at frame k (fdk/newton.py).

    Warm starts carried from frame to frame: the last frame's poses, α of the two most
    recent converged frames, the recruitment solution and the Jacobian (reuse_jacobian).
    """

    def __init__(self, model, ctx, settings, approach=None, scan=True, sweep_back=True):
        self.model, self.ctx, self.settings = model, ctx, settings
        self.approach = approach  # (step, k) -> FrameSolution, or None (:mod:`.approach`)
        self.scan = scan  # the last restarts: α_{k−1} moved along each DOF (scan_starts)
        #: failed frames are solved again backward from the next converged frame (sweep_back)
        self.sweep_back = sweep_back
        self.system = ctx.system
        state0 = model.initial_state()
        if ctx.tracker is not None:
            nf = len(ctx.times)
            first = next((j for j in range(nf) if np.any(ctx.meas[j][3])), 0)
            ctx.tracker.initial_guess(state0, ctx.meas[first][0], ctx.meas[first][3])
        self.a_init = np.array([d.initial for d in model.fdk_dofs])
        if ctx.tracker is None and len(ctx.times):
            # determinate kinematics: the first pose with the driven coordinates and the
            # DOFs at their targets, a closed loop's on its near root (kinematics/seeded_start.py)
            seed_start(self.system, state0, ctx.times[0], self.a_init)
        self.last_state = state0
        self.history = []  # (frame, α) of the most recent converged frames
        self.warm = None
        self.J_carry = None  # the last converged frame's FDK Jacobian (settings.reuse_jacobian)
        self.dq_dalpha = None  # its kinematic sensitivity dq̂/dα (FrameWorkspace.predict)
        self.last_failed = None  # (frame, best α) of the previous frame when it did not converge
        self.solved = None  # (frame, FrameWorkspace) of the last frame's solution when it converged
        #: the failed frames since the last converged one, (frame, iterations, evaluations,
        #: Jacobians, restarts) each: a sweep back from the next converged frame solves them
        self.unswept = []
        #: their recorded values by frame, for the sweep's account of the first it cannot
        #: solve (not carried over a checkpoint: a resumed run's sweep re-records none)
        self.failed_values = {}

    def fields(self):
        n_fdk = len(self.model.fdk_dofs)
        nm = self.model.markers.size if self.ctx.tracker is not None else 0
        out = kinematics_fields(self.model, nm)
        out.update(forces_fields(self.ctx.solver))
        out.update({"fdk.alpha": ((n_fdk,), float, np.nan), "fdk.f_fdk": ((n_fdk,), float, np.nan),
                    "fdk.iterations": ((), int, 0), "fdk.evaluations": ((), int, 0),
                    "fdk.jacobians": ((), int, 0), "fdk.restarts": ((), int, 0),
                    "fdk.backward": ((), int, 0), "fdk.report": ((), object, None)})
        return out

    def step(self, k):
        ctx, settings, history = self.ctx, self.settings, self.history
        t = ctx.times[k]
        warm_frame = bool(history) and history[-1][0] == k - 1
        # the previous frame's poses, at its α, moved along its dq̂/dα to the warm start
        ws = self._workspace(k, warm_frame)
        failed = self.last_failed if self.last_failed is not None and self.last_failed[0] == k - 1 else None
        a0 = extrapolated(history, k, settings.max_step) if settings.extrapolate else None
        if a0 is None and (warm_frame or (history and failed is None)):
            a0 = history[-1][1].copy()
        elif a0 is None and failed is not None:
            a0 = failed[1].copy()  # the previous frame's best iterate: nearer than an older solution
        elif a0 is None:
            a0 = self.a_init.copy()
        # a cold frame (no converged previous frame) starts far from its root: a larger
        # iteration limit for its first start (settings.cold_max_iterations)
        cold = None if warm_frame else settings.cold()
        ws0 = ws.copy()
        # the window's first frame: by the transient start, else from the lead-in's warm
        # start when the trial has frames before it (fdk/approach.py), else cold from the
        # initial values; the frame after the transient start's, which has no velocity to
        # extrapolate: by the transient solver from α_{k−1}, else through sub-steps
        approach = self.approach is not None and settings.restart and (
            (k == 0 and not history) or (warm_frame and self.approach.without_velocity(self, k)))
        lead = self.approach(self, k) if approach else None
        first = lead or solve_frame(ctx, k, a0, ws, cold or settings, self.warm, self.J_carry, not warm_frame)
        later = []
        if not first.converged and settings.restart:
            later = self._restarted(k, first, lead, approach, a0, ws0, cold, warm_frame)
        sol = combined(first, later)
        if not sol.converged:
            sol = replace(sol, message=sol.message + self._lost(k))
        self.J_carry = sol.jacobian if sol.converged else None
        self.dq_dalpha = sol.workspace.dq_dalpha if sol.converged and sol.workspace is not None else None
        self.solved = (k, sol.workspace) if sol.converged and sol.workspace is not None else None
        ev = sol.best
        self.last_failed = None if sol.converged or not ev.ok else (k, ev.alpha.copy())
        values = self._values(sol)
        if ev.state is not None:
            self.last_state = ev.state
        out = [(k, values)]
        if sol.converged:
            history.append((k, ev.alpha.copy()))
            self.history = history[-HISTORY:]
            self.warm = ev.frame.recruitment
            if self.unswept and self.sweep_back and settings.restart:
                out += self._swept_back(k, sol)
            self.unswept = []
            self.failed_values = {}
        else:
            self.unswept.append((k, sol.iterations, sol.evaluations, sol.jacobians, sol.restarts))
            self.failed_values[k] = values
        return out

    def _restarted(self, k, first, lead, approach, a0, ws0, cold, warm_frame):
        """The further solves of frame k after its first one, ``first``, failed (the
        module docstring's order): [FrameSolution]. ``lead``: the lead-in's solution when
        the first solve was one; ``approach``: the frame is the window's first or has no
        velocity; a0, ws0: the warm start and its poses; cold: the cold settings or None;
        warm_frame: frame k − 1 converged."""
        ctx, settings, history = self.ctx, self.settings, self.history
        tried = [] if lead else [a0]
        # after a converged frame: through sub-steps first (fdk/approach.py), then from
        # α_{k−1} and the initial values; after a failed one (or a failed lead-in),
        # from the last converged α and the initial values (no frames lead to it)
        sub_steps = warm_frame and self.approach is not None and lead is None
        approached = self.approach(self, k) if sub_steps else None
        if approach and lead is None and k == 0 and self.approach.trajectories is None:
            # determinate kinematics (drivers, a --motion file) have no lead-in: the
            # transient start from the initial values (fdk/approach.py)
            approached = self.approach.transient_start(self, k)
        later = [approached] if approached is not None else []
        if not any(s.converged for s in later):
            # (after a failed lead-in the initial values get the cold limit the first start had)
            later += solve_restarts(ctx, k, ([history[-1][1]] if history else []) + [self.a_init], ws0,
                                    (cold or settings) if lead else settings, self.warm, tried, not warm_frame)
        if not any(s.converged for s in later) and history and self.scan:
            later += solve_restarts(ctx, k, scan_starts(history[-1][1], settings.max_step), ws0, settings,
                                    self.warm, tried, not warm_frame)
        stalled = min([first] + later, key=lambda s: s.best.norm).best
        if (not any(s.converged for s in later) and self.scan and stalled.ok
                and stalled.norm < NEAR_SCAN_RANGE * settings.tolerance):
            # a stall next to the root, at a kink of f^FDK: from the stall moved a little
            later += solve_restarts(ctx, k, near_starts(stalled.alpha, settings.max_step), ws0, settings,
                                    self.warm, tried, not warm_frame)
        return later

    def _lost(self, k):
        """'' or the failed frame k's account of its sub-step march
        (:func:`~.approach.lost_between`): where the equilibrium followed from the
        converged frame k − 1 was found last and where not. Past such a time the FDK
        DOFs' equilibrium has folded away or jumped, and FDK's assumption of small, slow
        movements of its DOFs does not hold there (docs/fdk.md, "A wrapped path's way
        round")."""
        lost = None if self.approach is None else self.approach.lost
        if lost is None or lost[0] != k:
            return ""
        t_a, t_b = lost[1]
        return (f"; the equilibrium followed from the converged frame at {self.ctx.times[k - 1]:.4f} s "
                f"is found in sub-steps up to {t_a:.4f} s and not at {t_b:.4f} s")

    def _values(self, sol, spent=(0, 0, 0, 0), backward=False):
        """The recorded values of a frame's FrameSolution ``sol``; ``spent``: the
        (iterations, evaluations, Jacobians, restarts) of its earlier, failed solve (a
        frame solved again backward, ``backward``), added to its counts."""
        ctx = self.ctx
        ev = sol.best
        iterations, evaluations, jacobians, restarts = (a + b for a, b in zip(
            (sol.iterations, sol.evaluations, sol.jacobians, sol.restarts + int(backward)), spent))
        if sol.converged:
            report = FrameReport.ok(iterations, ev.norm)
        else:
            report = FrameReport.failed(Reason(sol.reason), f"FDK not converged: {sol.message}", iterations,
                                        ev.norm)
        values = {"fdk.alpha": ev.alpha, "fdk.iterations": iterations, "fdk.evaluations": evaluations,
                  "fdk.jacobians": jacobians, "fdk.restarts": restarts, "fdk.backward": int(backward),
                  "fdk.report": report}
        if ev.ok:
            values["fdk.f_fdk"] = ev.f_fdk
        if ev.state is not None:
            viol = float(np.max(np.abs(ev.data.Phi)))  # position stage at the final pose
            values.update({"kin.q": ev.state.get_q(), "kin.v": ev.state.get_v(), "kin.vdot": ev.vdot,
                           "kin.constraint_violation": viol, "kin.report": FrameReport.ok(0, viol)})
            if ctx.tracker is not None and ev.delta is not None:
                values["kin.marker_residual"] = ev.delta
        else:
            values["kin.report"] = FrameReport.failed(Reason.KINEMATICS, sol.message)
        status = None if sol.converged else "fdk_" + sol.reason
        if ev.frame is not None:
            values.update(forces_values(ev.frame, report=None if sol.converged else report, status=status))
        else:
            values.update(forces_failure(report, status))
        return values

    def _workspace(self, k, warm_frame):
        """The FrameWorkspace frame k's evaluations start from. After a converged frame
        k − 1 (marker tracking): its workspace's poses at α_{k−1} of the frames both need
        (t_{k−1}, and t_k, its neighbour), t_{k+1}'s carried on from t_k by the velocity
        of frame k − 1's solution over Δt, each with the KKT factors of its last solve
        (:class:`~openfdk.kinematics.tracking.KKTFactors`; t_{k+1} a copy of t_k's);
        moved along dq̂/dα from α_{k−1} (:meth:`FrameWorkspace.predict`). Else every pose
        starts from the last solution's (the DM knee's first evaluation of a warm frame
        took 7–8 Gauss–Newton steps at t_k and t_{k+1} so, a frame's motion away)."""
        ctx = self.ctx
        alpha, dq = (self.history[-1][1], self.dq_dalpha) if warm_frame else (None, None)
        solved = self.solved if warm_frame and self.solved is not None and self.solved[0] == k - 1 else None
        if solved is None or ctx.tracker is None:
            return FrameWorkspace({j: self.last_state for j in ctx.frames_needed(k)}, alpha, dq)
        prev = solved[1]
        states, factors = {}, {}
        for j in ctx.frames_needed(k):
            if j in prev.states:
                states[j] = prev.states[j]
                if j in prev.factors:
                    factors[j] = prev.factors[j]
            elif j - 1 in prev.states:
                state = prev.states[j - 1].copy()
                state.displace((ctx.time_of(j) - ctx.time_of(j - 1)) * self.last_state.get_v())
                states[j] = state
                if j - 1 in prev.factors:
                    factors[j] = prev.factors[j - 1].copy()
            else:
                states[j] = self.last_state
        return FrameWorkspace(states, alpha, dq, factors)

    def _swept_back(self, k, sol):
        """[(j, values)] of the failed frames just before frame k, solved again backward
        from it: frame k − 1 warm-started from frame k's solution (its poses moved along
        its dq̂/dα, its recruitment and Jacobian), α extrapolated back from the frames
        after it (:func:`~.warm_start.extrapolated` with the frame order mirrored), then
        k − 2 from k − 1, … while they converge; each with the ordinary iteration limit and
        no restarts (module docstring, "Sweeping back"). The forward march's state is not
        touched: frame k + 1 starts as it would without the sweep."""
        ctx, settings = self.ctx, self.settings
        curvature = ctx.tracking_curvature
        back = [(-k, sol.best.alpha.copy())]  # the converged frames after j, as frames −(j+1), −(j+2), …
        state, warm, J, dq = sol.best.state, sol.best.frame.recruitment, sol.jacobian, \
            sol.workspace.dq_dalpha if sol.workspace is not None else None
        out = []
        for j, *spent in reversed(self.unswept):
            if j != -back[-1][0] - 1:
                break
            a0 = extrapolated(back, -j, settings.max_step)
            ws = FrameWorkspace({i: state for i in ctx.frames_needed(j)}, back[-1][1], dq)
            s = solve_frame(ctx, j, back[-1][1].copy() if a0 is None else a0, ws, settings, warm, J, False)
            if not s.converged:
                if j in self.failed_values:
                    out.append((j, self._unswept_account(j, s, ctx.times[-back[-1][0]])))
                break
            out.append((j, self._values(s, spent, backward=True)))
            back = (back + [(-j, s.best.alpha.copy())])[-HISTORY:]
            state, warm, J = s.best.state, s.best.frame.recruitment, s.jacobian
            dq = s.workspace.dq_dalpha if s.workspace is not None else None
        ctx.tracking_curvature = curvature
        return out

    def _unswept_account(self, j, s, t_from):
        """The recorded values of failed frame j again, its report's message ending with
        the sweep's account (solved backward from the converged frame at ``t_from`` s,
        the FrameSolution ``s``, not converged either) and its counts including the
        sweep's; its best iterate stays the forward solve's."""
        values = dict(self.failed_values[j])
        note = f"; solved backward from the converged frame at {t_from:.4f} s, not converged either " \
               f"(max |f^FDK| = {s.best.norm:.4g})"
        for key in ("fdk.report", "dyn.report"):
            if key in values:
                values[key] = replace(values[key], message=values[key].message + note)
        for key, extra in (("fdk.iterations", s.iterations), ("fdk.evaluations", s.evaluations),
                           ("fdk.jacobians", s.jacobians), ("fdk.restarts", 1)):
            values[key] = values[key] + extra
        return values

    def finish(self):
        return []

    def carry(self):
        return (self.last_state.copy(), list(self.history), self.warm, self.J_carry, self.last_failed, self.dq_dalpha,
                self.ctx.tracking_curvature, [tuple(u) for u in self.unswept], self._solved_carry())

    def _solved_carry(self):
        """``self.solved`` as plain data for a checkpoint, or None: (frame, {j: BodyStates},
        {j: (LU, piv, first, last, factors held, λ or None)}) — a resumed run starts its
        next frame from the same poses and factors, and writes the same files."""
        if self.solved is None:
            return None
        k, ws = self.solved
        return (k, {j: state.copy() for j, state in ws.states.items()}, {j: f.saved() for j, f in ws.factors.items()})

    def restore(self, carry):
        """The carry of a checkpoint (untrusted: every array the kernels index is checked
        against the model, :mod:`openfdk.trial.restored`)."""
        last_state, history, warm, J_carry, last_failed, *sensitivity = carry
        reference = self.model.initial_state()
        n, n_fdk = reference.n_coords, len(self.model.fdk_dofs)
        # (a checkpoint of an earlier version has no sensitivity, or no curvature)
        dq_dalpha = sensitivity[0] if sensitivity else None
        curvature = sensitivity[1] if len(sensitivity) > 1 else None
        if isinstance(J_carry, ContactSplit):
            checked_split(J_carry, self.ctx.solver.forces.by_kind.get("contacts"), reference, n_fdk)
        else:
            restored.optional(J_carry, (n_fdk, n_fdk), "FDK Jacobian")
        restored.optional(dq_dalpha, (n, n_fdk), "kinematic sensitivity")
        if curvature is not None:
            if not isinstance(curvature, (tuple, list)) or len(curvature) != 2:
                raise ValueError("tracking curvature: expected (S, t)")
            restored.array(curvature[0], (n, n), "tracking curvature")
            curvature = (curvature[0], restored.number(curvature[1], "tracking curvature: time"))
        if not isinstance(history, (list, tuple)) or not all(isinstance(h, (list, tuple)) and len(h) == 2
                                                             for h in history):
            raise ValueError("FDK history: expected (frame, α) pairs")
        history = [(int(k), restored.array(a, (n_fdk,), f"FDK history: α of frame {k}")) for k, a in history]
        if last_failed is not None:
            if not isinstance(last_failed, (list, tuple)) or len(last_failed) != 2:
                raise ValueError("last failed frame: expected (frame, α)")
            last_failed = (int(last_failed[0]), restored.array(last_failed[1], (n_fdk,), "last failed frame: α"))
        self.warm, self.J_carry, self.last_failed, self.dq_dalpha = warm, J_carry, last_failed, dq_dalpha
        self.ctx.tracking_curvature = curvature
        self.unswept = [tuple(int(x) for x in u) for u in sensitivity[2]] if len(sensitivity) > 2 else []
        self.failed_values = {}  # (their values are the checkpoint's records, not carried)
        self.last_state, self.history = restored.states(last_state, reference, "state").copy(), history
        saved = sensitivity[3] if len(sensitivity) > 3 else None
        self.solved = None if saved is None else _solved_from(saved, self.ctx.system, reference)


def _solved_from(saved, system, reference):
    """(frame, FrameWorkspace) from :meth:`FDKStep._solved_carry`'s data (a checkpoint's:
    the poses checked against the model's initial state ``reference``, the factors
    against the tracking's KKT size n + m of ``system``, ValueError)."""
    k, states, factors = saved
    size = system.n_coords + system.n_rows
    return int(k), FrameWorkspace({int(j): restored.states(state, reference, f"solved pose of frame {j}")
                                   for j, state in states.items()},
                                  factors={int(j): KKTFactors.from_saved(f, size, system.n_rows)
                                           for j, f in factors.items()})


def fdk_context(model, trajectories, times, tracking=None, settings=None):
    """The FDKContext of a trial (system with FDK rows, inverse dynamics with the
    recruitment of ``settings`` (AnalysisSettings), tracker and the measured markers at
    ``times`` (nf,) s, or determinate kinematics)."""
    system = ConstraintSystem(model)
    solver = InverseDynamics(model, system, settings)
    tracker, meas = None, None
    if trajectories is not None:
        tracker = MarkerTracker(system, tracking or TrackingSettings())
        meas = window_measurements(trajectories, times)
    return FDKContext(model, solver, tracker, meas, times, window_spacing(times, trajectories))


def fdk_result(rec, model, ctx, settings, times, wall_time):
    """The FDKResult (with its kinematics and forces) of a Recording."""
    reports = rec.objects("fdk.report")
    ok = np.array([r.converged for r in reports], dtype=bool)
    ok.setflags(write=False)
    alpha = rec.array("fdk.alpha")
    a_init = np.array([d.initial for d in model.fdk_dofs])
    kin = kinematics_result(rec, model, times, alpha[0] if len(times) else a_init, wall_time,
                            "fdk-tracking" if ctx.tracker is not None else "fdk-determinate")
    names = tuple(d.name for d in model.fdk_dofs)
    args = (names, alpha, rec.array("fdk.f_fdk"), ok, rec.array("fdk.iterations"), rec.array("fdk.evaluations"),
            reports, settings, wall_time, rec.array("fdk.jacobians"), rec.array("fdk.restarts"),
            rec.array("fdk.backward"))
    forces = forces_result(rec, ctx.solver, times, wall_time, extra_columns=FDKResult(kin, None, *args).columns())
    return FDKResult(kin, forces, *args)


def fdk_step(model, trajectories, times, settings=None, tracking=None, **overrides):
    """The FDKStep of a trial, as ``run_fdk`` and ``openfdk run`` (:func:`openfdk.analysis.run.run_trial`)
    both drive it: its context at ``times`` (nf,) s, the solver settings of ``settings``
    (AnalysisSettings) with ``overrides``, and the approach; warns (PlausibilityWarning)
    about muscles FDK can never recruit. One construction for both, so that the two give
    the same frames bit for bit (the check evaluates the paths at the initial pose, which
    leaves the wrapping's warm starts where the run then starts from)."""
    solver_settings = fdk_settings(model, settings, **overrides)
    ctx = fdk_context(model, trajectories, times, tracking, settings)
    absorbed = fdk_absorbed_muscles(ctx.solver, model.initial_state())
    if absorbed:
        warn_plausibility(absorbed_message(absorbed))
    return FDKStep(model, ctx, solver_settings, approach_for(model, trajectories))


def run_fdk(model, trajectories=None, times=None, settings=None, progress=False, tracking=None, **overrides):
    """Force-dependent kinematics over a trial.

    trajectories : marker trajectories (``evaluate(t)``) in model marker order, or None
    for determinate kinematics (drivers); times : (nf,) s, uniform (default: the trial's
    sample times); settings : AnalysisSettings (recruitment and the ``fdk`` section;
    default: AnalysisSettings(), the defaults), e.g. the model file's
    (:func:`openfdk.io.modelfile.load_model_and_settings`); overrides : FDKSettings
    fields (``jacobian="central"``, …). The model is not modified.
    """
    t0 = _time.perf_counter()
    if not model.fdk_dofs:
        raise ValueError(f"model {model.name!r} declares no FDK DOFs (section fdk_dofs)")
    if times is None:
        times = np.asarray(trajectories.time, dtype=float)
    times = np.asarray(times, dtype=float)
    step = fdk_step(model, trajectories, times, settings, tracking, **overrides)
    ctx, settings = step.ctx, step.settings

    def build(rec):
        return fdk_result(rec, model, ctx, settings, times[: rec.n_frames], _time.perf_counter() - t0)

    return drive(step, len(times), build, progress=progress, desc="FDK")
