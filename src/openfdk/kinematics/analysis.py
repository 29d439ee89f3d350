"""Kinematic analysis over a trial: the time loop, results and per-frame diagnostics.

Two modes:

* determinate (no marker data): Eqs. 1–3 at each time;
* marker tracking: Eqs. 4–5 at every frame (warm-started from the previous frame),
  then the residual history δ(t) gives δ̇ and δ̈ by central differences over the frame
  spacing Δt (Eq. 7 and its second-order analogue; at a window's ends with the poses
  solved at the trial's samples just outside it, one-sided only at the trial's ends and
  next to failed frames), then Eqs. 8–10. Because α is the same at every frame, the position
  solves at t ± Δt that Eq. 7 needs are exactly the neighbouring frames' solutions.

A frame that fails is flagged with its reason and its outputs are NaN; the analysis
continues (warm start from the last good frame).

Both run on the trial driver (:mod:`openfdk.trial`) as steps: :class:`DeterminateStep`
and :class:`TrackingStep`. Marker tracking finishes frame k − 1 (velocities and
accelerations) once frame k's pose is known, since Eq. 7 needs the residuals at t ± Δt;
the arithmetic is that of a first pass over all positions followed by a second pass
over all rates.
"""

from __future__ import annotations

import time as _time
from dataclasses import dataclass, field

import numpy as np

from ..model.framedata import FrameData
from ..model.kernels import displace_by_rates, extrapolate_poses
from ..trial import drive, restored
from ..trial.status import Reason, frame_messages
from .coordinate_bounds import CoordinateBounds, solve_bounded
from .curvature import HessianPattern, lagrangian_hessian, second_order_terms
from .determinate import FrameSolve, check_square, solve_positions, solve_velocities_accelerations
from .stages import marker_stage, velocity_stage_tracking
from .seeded_start import seed_start
from .system import ConstraintSystem
from .tracking import MarkerTracker, TrackingSettings, residual_rates, window_spacing


@dataclass(frozen=True)
class KinematicsResult:
    """Kinematics of every frame.

    time : (nf,) s; q : (nf, 7 n_moving) [r (m), quaternion] per body;
    v, vdot : (nf, 6 n_moving) [m/s, rad/s] and [m/s², rad/s²] (body-frame ω');
    marker_residual : (nf, n_markers, 3) m, model minus measured (NaN if not visible);
    constraint_violation : (nf,) max |Φ| (m or rad); iterations : (nf,) int;
    converged : (nf,) bool; reports : FrameReport per frame; messages : per-frame text
    from the reports ('' if converged);
    alpha : (n_fdk,) the FDK inputs used; wall_time : s.
    """

    model_name: str
    body_names: tuple
    marker_names: tuple
    time: np.ndarray
    q: np.ndarray
    v: np.ndarray
    vdot: np.ndarray
    marker_residual: np.ndarray
    constraint_violation: np.ndarray
    iterations: np.ndarray
    converged: np.ndarray
    reports: tuple
    alpha: np.ndarray
    wall_time: float = 0.0
    mode: str = "tracking"
    extra: dict = field(default_factory=dict)
    #: (n_markers,) the tracking's marker weights, or None; the summary's RMS residual
    #: counts the tracked markers (weight > 0) only, as OpenSim's IK reports its error
    marker_weights: np.ndarray = None

    @property
    def messages(self):
        return frame_messages(self.reports, self.time)

    @property
    def n_frames(self):
        return len(self.time)

    def failed_frames(self):
        """[(frame index, time, message)] of frames that did not converge."""
        msgs = self.messages
        return [(i, float(self.time[i]), msgs[i]) for i in np.flatnonzero(~self.converged)]

    def summary(self):
        """dict for summary.json."""
        return {
            "model": self.model_name,
            "mode": self.mode,
            "frames": int(self.n_frames),
            "converged_frames": int(np.sum(self.converged)),
            "failed_frames": [
                {"frame": int(i), "time": t, "reason": m} for i, t, m in self.failed_frames()
            ],
            "max_constraint_violation": float(np.nanmax(self.constraint_violation))
            if np.any(np.isfinite(self.constraint_violation)) else (None if self.n_frames else 0.0),
            "rms_marker_residual_m": rms_marker_residual(self.marker_residual, self.marker_weights),
            "wall_time_s": self.wall_time,
            "frames_per_second": self.n_frames / self.wall_time if self.wall_time > 0 else None,
        }



def rms_marker_residual(residual, weights=None):
    """RMS (m) of the marker residuals (nf, n_markers, 3) m over the visible samples of
    the tracked markers (weight > 0 in ``weights`` (n_markers,); None: all), or None
    when there are none. A marker the tracking leaves out (an IK task with ``apply``
    false, e.g. the arms' markers when the arms are locked) can sit decimetres from its
    model marker and would swamp the fit's error."""
    if weights is not None and residual.ndim == 3 and residual.shape[1] == len(weights):
        residual = residual[:, np.asarray(weights) > 0.0]
    if not residual.size or not np.any(np.isfinite(residual)):
        return None
    return float(np.sqrt(np.nanmean(np.sum(residual**2, axis=2))))


#: a converged frame that took more Gauss–Newton steps than this gets the tracking
#: Lagrangian's second-order terms at its pose (kinematics/curvature.py), and the next
#: frames take Newton's steps with them until one needs more steps again. On
#: jam-resources' full_body_healthy_knee.osim with overground_17.trc (13 mm RMS): 38.5 →
#: 10 steps a frame, 71 → 3.3 s of CPU for 515 frames; on the DM knee (380 frames):
#: 12.9 → 9.4 steps, three refreshes, 1.7 → 1.3 s. Refreshing the terms sooner (when a
#: frame needs 3 steps more than the first solved with them: 7.9 and 8.7 steps) cost
#: more than the steps it saved (2.1 and 4.6 s); a Hessian costs about 20 chord steps.
CURVATURE_ITERATIONS = 12


def analysis_times(t_start, t_end, n_frames):
    """Uniform analysis times (n_frames,) s."""
    if n_frames < 1 or not t_end >= t_start:
        raise ValueError(f"invalid analysis interval [{t_start}, {t_end}] s with {n_frames} frames")
    return np.linspace(t_start, t_end, n_frames)


def alpha_inputs(model, alpha):
    if alpha is None:
        return np.array([d.initial for d in model.fdk_dofs])
    alpha = np.asarray(alpha, dtype=float)
    if alpha.shape != (len(model.fdk_dofs),):
        raise ValueError(f"alpha must have {len(model.fdk_dofs)} entries (one per FDK DOF), got {alpha.shape}")
    return alpha


def _extrapolate(state, q_prev):
    """state ← state ⊕ (state ⊖ q_prev): first-order prediction of the next frame's pose
    (translations linearly, rotations by the same body-frame increment; one kernel,
    :func:`openfdk.model.kernels.extrapolate_poses`). q_prev (7 n_moving,) [m, -]."""
    extrapolate_poses(state.p_WB, state.quat_WB, state.R_WB, state.moving,
                      np.ascontiguousarray(q_prev, dtype=float).reshape(-1))


def kinematics_fields(model, n_markers, prefix="kin."):
    """Declared per-frame fields {name: (shape, dtype, fill)} of a kinematic analysis."""
    n = model.n_coords
    return {prefix + "q": ((7 * n // 6,), float, np.nan), prefix + "v": ((n,), float, np.nan),
            prefix + "vdot": ((n,), float, np.nan), prefix + "marker_residual": ((n_markers, 3), float, np.nan),
            prefix + "constraint_violation": ((), float, np.nan), prefix + "iterations": ((), int, 0),
            prefix + "report": ((), object, None)}


def kinematics_result(rec, model, times, alpha, wall_time, mode, prefix="kin."):
    """The KinematicsResult of a Recording (frames in ``times`` (nf,) s)."""
    reports = rec.objects(prefix + "report")
    converged = np.array([r.converged for r in reports], dtype=bool)
    converged.setflags(write=False)
    return KinematicsResult(
        model.name, tuple(b.name for b in model.moving_bodies), model.markers.names, np.asarray(times, float),
        rec.array(prefix + "q"), rec.array(prefix + "v"), rec.array(prefix + "vdot"),
        rec.array(prefix + "marker_residual"), rec.array(prefix + "constraint_violation"),
        rec.array(prefix + "iterations"), converged, reports, alpha, wall_time, mode,
        marker_weights=np.array(model.markers.weight, dtype=float),
    )


class DeterminateStep:
    """Trial-driver step of determinate kinematics (Eqs. 1–3): Newton–Raphson from the
    previous frame's pose carried forward by a Taylor step on the manifold,
    q ⊕ (v Δt + ½ v̇ Δt² + ⅙ j Δt³), j = (v̇_{k−1} − v̇_{k−2}) / Δt_{k−1} the jerk of the
    two previous converged frames (left out after a failure or at the first frames; the
    last converged pose after a failure). The third-order term makes the start's error
    O(Δt⁴): on the bench's full-body gait (100 Hz) Newton needs 2 iterations per frame
    instead of 2.9."""

    def __init__(self, model, times, alpha, prefix="kin."):
        self.model, self.times, self.alpha, self.prefix = model, times, alpha, prefix
        self.system = ConstraintSystem(model)
        check_square(self.system)
        self.state = model.initial_state()
        if len(times):  # the first pose, a closed loop's on its near root (kinematics/seeded_start.py)
            seed_start(self.system, self.state, times[0], alpha)
        self.last_good = self.state.copy()
        self.rates = None  # (t, v, v̇, j or None) of the previous converged frame: the warm start's Taylor step
        self.frame_data = {}  # frame -> FrameData of the frame just finished (for the dynamics)

    def fields(self):
        return kinematics_fields(self.model, 0, self.prefix)

    def step(self, k):
        t, P = self.times[k], self.prefix
        self.frame_data = {}
        data = FrameData()
        if self.rates is not None:
            st, (t0, v0, a0, j0) = self.state, self.rates
            # ½ (v̇ + j Δt / 3) Δt² = ½ v̇ Δt² + ⅙ j Δt³
            a = a0 if j0 is None else a0 + j0 * ((t - t0) / 3.0)
            displace_by_rates(st.p_WB, st.quat_WB, st.R_WB, st.moving, st.column, v0, a, t - t0)
        res = solve_positions(self.system, self.state, t, self.alpha, data=data)
        values = {P + "iterations": res.iterations, P + "constraint_violation": res.residual,
                  P + "report": res.report()}
        if res.converged:
            v, vd = solve_velocities_accelerations(self.system, self.state, t, self.alpha, data)
            self.frame_data = {k: data}
            values.update({P + "q": self.state.get_q(), P + "v": v, P + "vdot": vd})
            self.last_good = self.state.copy()
            prev = self.rates
            self.rates = (t, v, vd, None if prev is None or not t > prev[0] else (vd - prev[2]) / (t - prev[0]))
        else:
            self.state = self.last_good.copy()
            self.rates = None
        return [(k, values)]

    def finish(self):
        return []

    def carry(self):
        return self.state.copy(), self.last_good.copy(), self.rates

    def restore(self, carry):
        """The carry of a checkpoint (untrusted: the poses and the rates checked against
        the model, :mod:`openfdk.trial.restored`)."""
        reference = self.model.initial_state()
        self.state = restored.states(carry[0], reference, "state").copy()
        self.last_good = restored.states(carry[1], reference, "last good state").copy()
        rates = carry[2] if len(carry) > 2 else None
        if rates is not None:
            rates = (tuple(rates) + (None,))[:4]  # (a checkpoint without the jerk)
            n = reference.n_coords
            restored.number(rates[0], "rates: time")
            for a, name in zip(rates[1:], ("velocities", "accelerations", "jerk")):
                if a is not None or name != "jerk":
                    restored.array(a, (n,), f"rates: {name}")
        self.rates = rates


class TrackingStep:
    """Trial-driver step of marker tracking (Eqs. 4–10).

    step(k) solves frame k's positions (Eqs. 4–5, warm-started by linear extrapolation
    of the two previous poses on the manifold), then finishes frame k − 1: residual
    rates from frames k − 2, k − 1, k (Eq. 7) and velocities and accelerations
    (Eqs. 8–10) with the KKT matrix of its last Gauss–Newton step.
    """

    def __init__(self, model, trajectories, times, alpha, settings=None, prefix="kin."):
        self.model, self.traj, self.times, self.alpha, self.prefix = model, trajectories, times, alpha, prefix
        spacing = window_spacing(times, trajectories)
        # the edge frames' neighbours are the trial's samples outside the window (_edge_neighbour)
        self.edges = spacing is not None
        self.dt = spacing if spacing is not None else 1.0
        self.tracker = MarkerTracker(ConstraintSystem(model), settings or TrackingSettings())
        # clamped coordinates bounded as OpenSim's IK bounds them (kinematics/coordinate_bounds.py)
        self.bounds = CoordinateBounds(model, self.tracker)
        self.active = ()  # the last solved frame's active bounds: the next frame's first set
        self.state = model.initial_state()
        self.last_good = self.state.copy()
        self.q_prev = None
        self.guessed = False
        self.pending = {}  # frame -> positions of the last frames not yet finished
        self.frame_data = {}  # frame -> FrameData of the frame just finished (for the dynamics)
        # the Lagrangian's second-order terms S (n, n) at an earlier frame's pose, or None:
        # the position solves' Newton steps (kinematics/curvature.py)
        self.curvature = None
        self.patterns = HessianPattern()

    def fields(self):
        return kinematics_fields(self.model, self.model.markers.size, self.prefix)

    def step(self, k):
        t = self.times[k]
        self.frame_data = {}
        x, xd, xdd, vis = self.traj.evaluate(t)
        tracker, state = self.tracker, self.state
        if not self.guessed and np.any(vis):
            tracker.initial_guess(state, x, vis)
            self.guessed = True
        res, K, lam, active = self._solve(state, t, x, vis, self.active)
        tracker = self.bounds.tracker_for(active) if active else tracker
        frame = {"res": res, "meas": (xd, xdd), "q": None, "state": None, "data": None,
                 "delta": np.full((self.model.markers.size, 3), np.nan), "active": [list(b) for b in active]}
        if res.converged:
            # the position stage at the solved pose, once: the markers' p_WM and Ψ_q̂ give
            # δ = p_WM − x (Eq. 7) now and the velocity stage (Eqs. 8–10) at frame k + 1
            data = marker_stage(tracker.markers, FrameData(t=t, alpha=self.alpha, kkt=K, visible=vis), state)
            data.delta = np.where(vis[:, None], data.p_M.reshape(-1, 3) - x, np.nan)
            misfit = tracker.fit_message(data.delta, vis)
            if misfit:  # a least-squares pose, but not one of these markers
                res = frame["res"] = FrameSolve(False, res.iterations, res.residual, misfit, Reason.FAILED)
        if res.converged:
            if res.iterations > CURVATURE_ITERATIONS:
                self._refresh_curvature(tracker, state, t, x, vis, lam, data)
            frame.update(q=state.get_q(), state=state.copy(), data=data, delta=data.delta)
            self.last_good = state.copy()
            self.active = active
            # warm start of the next frame: linear extrapolation on the manifold
            if self.q_prev is not None:
                _extrapolate(state, self.q_prev)
            self.q_prev = frame["q"]
        else:
            self.state = self.last_good.copy()
            self.q_prev = None
        self.pending[k] = frame
        if k == 0 and self.edges and frame["state"] is not None:
            self._edge_neighbour(-1, t - self.dt, frame["state"])
        done = [(k - 1, self._finish_frame(k - 1))] if k >= 1 else []
        self.pending.pop(k - 2, None)  # frame k − 1 was its last user
        return done

    def finish(self):
        self.frame_data = {}
        last = len(self.times) - 1
        if last not in self.pending:
            return []
        if self.pending[last]["state"] is not None and self.edges:
            self._edge_neighbour(last + 1, self.times[last] + self.dt, self.pending[last]["state"])
        return [(last, self._finish_frame(last))]

    def _solve(self, state, t, x, vis, active):
        """(FrameSolve, K, λ, active bounds) of frame t's positions from ``state``: the
        tracker's solve, within the clamped coordinates' ranges when the model has any
        (:func:`.coordinate_bounds.solve_bounded`, from the active set ``active``)."""
        if not self.bounds:
            return self.tracker.solve_positions(state, t, x, vis, self.alpha, second_order=self.curvature) + ((),)
        return solve_bounded(self.bounds, state, t, x, vis, self.alpha, active, second_order=self.curvature)

    def _refresh_curvature(self, tracker, state, t, x, vis, lam, data):
        """S at the solved pose of a frame that took more than CURVATURE_ITERATIONS
        steps (its fit's residuals slow Gauss–Newton down), for the next frames' solves;
        None (Gauss–Newton's steps) where a constraint measure fails at a displaced pose.
        tracker : the one that solved the frame (its rows are λ's)."""
        A = tracker.system.evaluate(state, t, self.alpha, order=1)[1]
        try:
            H = lagrangian_hessian(tracker, state, t, self.alpha, vis, x, lam, data.p_M, data.J_M, A, self.patterns)
        except ArithmeticError:  # (FloatingPointError: a measure undefined at a displaced pose)
            self.curvature = None
            return
        self.curvature = second_order_terms(tracker, state, H, data.J_M, vis)

    def _edge_neighbour(self, j, t, start):
        """The residuals δ at the trial's sample t (s) just outside the window (frame j =
        −1 or nf) where the trial has markers there, solved from the pose ``start`` of
        the window's edge frame: the edge frames' residual rates (Eq. 7) are then central
        differences, as at every other frame and as FDK's (fdk/residual.py,
        window_measurements), and a frame's v and v̇ do not depend on where the window
        starts or ends. Outside the trial (or not solved) they stay one-sided."""
        span = getattr(self.traj, "time", None)
        if span is None or len(span) == 0 or not (span[0] - 1e-9 <= t <= span[-1] + 1e-9):
            return  # outside the trial (or its span unknown): one-sided
        x, _, _, vis = self.traj.evaluate(t)
        if not np.any(vis):
            return
        state = start.copy()
        res = self._solve(state, t, x, vis, self.active)[0]
        if not res.converged:
            return
        delta = np.where(vis[:, None], self.tracker.markers.positions(state) - x, np.nan)
        if self.tracker.fit_message(delta, vis):
            return
        self.pending[j] = {"delta": delta}

    def _finish_frame(self, j):
        """Velocities and accelerations of frame j (its neighbours' residuals known)."""
        P, fr = self.prefix, self.pending[j]
        res = fr["res"]
        values = {P + "iterations": res.iterations, P + "constraint_violation": res.residual,
                  P + "report": res.report(), P + "marker_residual": fr["delta"]}
        if not res.converged:
            return values
        prev, nxt = self.pending.get(j - 1), self.pending.get(j + 1)
        d1, d2 = residual_rates(None if prev is None else prev["delta"], fr["delta"],
                                None if nxt is None else nxt["delta"], self.dt)
        xd, xdd = fr["meas"]
        state, data = fr["state"], fr["data"]  # the solved pose of frame j (its own copy: the stage sets v)
        active = self.bounds.check_active(fr.get("active", ())) if self.bounds else ()
        # occluded markers' NaN ẋ, ẍ are masked out of the targets by the stage (weight 0);
        # with active bounds, their rows hold u̇ = ü = 0, then drop out of Φ, Φ_q̂, ν
        velocity_stage_tracking(self.bounds.tracker_for(active) if active else self.tracker, data, state, xd, xdd,
                                d1, d2)
        if active:
            data.Phi, data.Phi_q, data.nu = (self.bounds.model_rows(active, a) for a in (data.Phi, data.Phi_q, data.nu))
        self.frame_data[j] = data
        values.update({P + "q": fr["q"], P + "v": data.v, P + "vdot": data.vdot})
        return values

    def carry(self):
        return self.state.copy(), self.last_good.copy(), self.q_prev, self.guessed, dict(self.pending)

    def restore(self, carry):
        """The carry of a checkpoint (untrusted: every array the kernels index is checked
        against the model, :mod:`openfdk.trial.restored`)."""
        state, last_good, q_prev, self.guessed, pending = carry
        reference = self.model.initial_state()
        nq = np.shape(reference.get_q())
        if q_prev is not None and np.shape(q_prev) != nq:
            raise ValueError(f"previous pose of shape {np.shape(q_prev)}, the model's {nq}")
        restored.optional(q_prev, nq, "previous pose")
        if not isinstance(pending, dict):
            raise ValueError(f"pending frames: expected a mapping, got {type(pending).__name__}")
        self.q_prev = q_prev
        self.state = restored.states(state, reference, "state").copy()
        self.last_good = restored.states(last_good, reference, "last good state").copy()
        self.pending = {j: self._checked_pending(j, f, reference) for j, f in pending.items()}
        # the next frame starts from the last solved frame's active bounds (checked)
        last = [f for _, f in sorted(self.pending.items()) if f.get("state") is not None]
        self.active = self.bounds.check_active(last[-1].get("active", ())) if last and self.bounds else ()

    def _checked_pending(self, j, frame, reference):
        """A restored pending frame ``frame`` (see :meth:`step`), its arrays checked."""
        what = f"pending frame {j}"
        if not isinstance(j, (int, np.integer)) or isinstance(j, bool) or not isinstance(frame, dict):
            raise ValueError(f"{what}: expected a frame number and a mapping")
        nm, n = self.model.markers.size, reference.n_coords
        restored.array(frame.get("delta"), (nm, 3), f"{what}: marker residuals", finite=False)
        if "res" not in frame:  # a window's edge neighbour: its residuals only
            return frame
        meas = frame.get("meas")
        if not isinstance(meas, (tuple, list)) or len(meas) != 2:
            raise ValueError(f"{what}: expected the markers' velocities and accelerations")
        for a, name in zip(meas, ("velocities", "accelerations")):
            restored.array(a, (nm, 3), f"{what}: marker {name}", finite=False)
        restored.optional(frame.get("q"), np.shape(reference.get_q()), f"{what}: pose")
        if frame.get("state") is not None:
            restored.states(frame["state"], reference, f"{what}: state")
            active = self.bounds.check_active(frame.get("active", ())) if self.bounds else ()
            tracker = self.bounds.tracker_for(active) if active else self.tracker
            restored.frame_data_tracking(frame.get("data"), n, tracker.system.n_rows, nm, len(self.model.fdk_dofs),
                                         f"{what}: data")
        return frame


def run_determinate(model, times, alpha=None, progress=False):
    """Determinate kinematics (Eqs. 1–3) at ``times`` (nf,) s. Returns KinematicsResult."""
    t0 = _time.perf_counter()
    alpha = alpha_inputs(model, alpha)
    times = np.asarray(times, float)
    step = DeterminateStep(model, times, alpha)

    def build(rec):
        return kinematics_result(rec, model, times[: rec.n_frames], alpha, _time.perf_counter() - t0,
                                 "determinate")

    return drive(step, len(times), build, progress=progress, desc="kinematics")


def tracking_times(trajectories, times):
    """The analysed times (nf,) s: ``times`` or the trial's samples; checked uniform.
    Times rounded in the file (spacing within the markers' tolerance,
    :data:`openfdk.io.markers.UNIFORM_SPACING_TOLERANCE`) become the uniform grid over
    the same span, where the marker splines are evaluated."""
    if times is None:
        times = trajectories.time
    times = np.asarray(times, dtype=float)
    if len(times) > 2:
        from ..io.markers import UNIFORM_SPACING_TOLERANCE

        dt = (times[-1] - times[0]) / (len(times) - 1)
        if dt > 0 and np.max(np.abs(np.diff(times) / dt - 1.0)) <= UNIFORM_SPACING_TOLERANCE:
            times = np.linspace(times[0], times[-1], len(times))
    nf = len(times)
    dt = float(times[1] - times[0]) if nf > 1 else 1.0
    if nf > 2 and np.max(np.abs(np.diff(times) - dt)) > 1e-9 * max(1.0, abs(dt)):
        raise ValueError("marker tracking needs uniformly spaced analysis times")
    return times


def run_tracking(model, trajectories, times=None, alpha=None, settings=None, progress=False):
    """Marker-tracking kinematics (Eqs. 4–10).

    trajectories : an object with ``evaluate(t) -> (x (nm, 3) m, ẋ, ẍ, visible (nm,))``
        whose markers are in the model's marker order (see
        :class:`openfdk.io.markers.MarkerTrajectories` and ``select``);
    times : (nf,) s, uniformly spaced (default: the trial's sample times).
    Returns KinematicsResult.
    """
    t0 = _time.perf_counter()
    if model.markers.size == 0:
        raise ValueError(f"model {model.name!r} has no markers to track")
    times = tracking_times(trajectories, times)
    alpha = alpha_inputs(model, alpha)
    step = TrackingStep(model, trajectories, times, alpha, settings)

    def build(rec):
        return kinematics_result(rec, model, times[: rec.n_frames], alpha, _time.perf_counter() - t0, "tracking")

    return drive(step, len(times), build, progress=progress, desc="kinematics")
