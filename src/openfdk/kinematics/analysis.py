"""Kinematic analysis over a trial: the time loop, results and per-frame diagnostics.

Two modes:

* determinate (no marker data): Eqs. 1–3 at each time;
* marker tracking: Eqs. 4–5 at every frame (warm-started from the previous frame),
  then the residual history δ(t) gives δ̇ and δ̈ by central differences over the frame
  spacing Δt (Eq. 7 and its second-order analogue; one-sided at the trial ends and next
  to failed frames), then Eqs. 8–10. Because α is the same at every frame, the position
  solves at t ± Δt that Eq. 7 needs are exactly the neighbouring frames' solutions.

A frame that fails is flagged with its reason and its outputs are NaN; the analysis
continues (warm start from the last good frame).
"""

from __future__ import annotations

import time as _time
from dataclasses import dataclass, field

import numpy as np

from .determinate import check_square, solve_positions, solve_velocities_accelerations
from .system import ConstraintSystem
from .tracking import MarkerTracker, TrackingSettings


@dataclass(frozen=True)
class KinematicsResult:
    """Kinematics of every frame.

    time : (nf,) s; q : (nf, 7 n_moving) [r (m), quaternion] per body;
    v, vdot : (nf, 6 n_moving) [m/s, rad/s] and [m/s², rad/s²] (body-frame ω');
    marker_residual : (nf, n_markers, 3) m, model minus measured (NaN if not visible);
    constraint_violation : (nf,) max |Φ| (m or rad); iterations : (nf,) int;
    converged : (nf,) bool; messages : per-frame reason ('' if converged);
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
    messages: tuple
    alpha: np.ndarray
    wall_time: float = 0.0
    mode: str = "tracking"
    extra: dict = field(default_factory=dict)

    @property
    def n_frames(self):
        return len(self.time)

    def failed_frames(self):
        """[(frame index, time, message)] of frames that did not converge."""
        return [(i, float(self.time[i]), self.messages[i]) for i in np.flatnonzero(~self.converged)]

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
            "max_constraint_violation": float(np.nanmax(self.constraint_violation)) if self.n_frames else 0.0,
            "rms_marker_residual_m": float(np.sqrt(np.nanmean(np.sum(self.marker_residual**2, axis=2))))
            if self.marker_residual.size and np.any(np.isfinite(self.marker_residual))
            else None,
            "wall_time_s": self.wall_time,
            "frames_per_second": self.n_frames / self.wall_time if self.wall_time > 0 else None,
        }


def _progress(total, enabled, desc):
    if not enabled:
        return None
    from ..progress import progress

    return progress(total, desc, "frame")


def analysis_times(t_start, t_end, n_frames):
    """Uniform analysis times (n_frames,) s."""
    if n_frames < 1 or not t_end >= t_start:
        raise ValueError(f"invalid analysis interval [{t_start}, {t_end}] s with {n_frames} frames")
    return np.linspace(t_start, t_end, n_frames)


def run_determinate(model, times, alpha=None, progress=False):
    """Determinate kinematics (Eqs. 1–3) at ``times`` (nf,) s. Returns KinematicsResult."""
    t0 = _time.perf_counter()
    system = ConstraintSystem(model)
    check_square(system)
    alpha = _alpha(model, alpha)
    state = model.initial_state()
    nf, n = len(times), model.n_coords
    q = np.full((nf, 7 * n // 6), np.nan)
    v = np.full((nf, n), np.nan)
    vd = np.full((nf, n), np.nan)
    viol = np.full(nf, np.nan)
    iters = np.zeros(nf, dtype=int)
    ok = np.zeros(nf, dtype=bool)
    msgs = [""] * nf
    last_good = state.copy()
    bar = _progress(nf, progress, "kinematics")
    for k, t in enumerate(times):
        res = solve_positions(system, state, t, alpha)
        iters[k], viol[k] = res.iterations, res.residual
        if res.converged:
            v[k], vd[k] = solve_velocities_accelerations(system, state, t, alpha)
            q[k] = state.get_q()
            ok[k] = True
            last_good = state.copy()
        else:
            msgs[k] = res.message
            state = last_good.copy()
        if bar:
            bar.update()
    if bar:
        bar.close()
    return KinematicsResult(
        model.name, tuple(b.name for b in model.moving_bodies), model.markers.names, np.asarray(times, float),
        q, v, vd, np.zeros((nf, 0, 3)), viol, iters, ok, tuple(msgs), alpha,
        _time.perf_counter() - t0, "determinate",
    )


def _alpha(model, alpha):
    if alpha is None:
        return np.array([d.initial for d in model.fdk_dofs])
    alpha = np.asarray(alpha, dtype=float)
    if alpha.shape != (len(model.fdk_dofs),):
        raise ValueError(f"alpha must have {len(model.fdk_dofs)} entries (one per FDK DOF), got {alpha.shape}")
    return alpha


def _extrapolate(state, q_prev):
    """state ← state ⊕ (state ⊖ q_prev): first-order prediction of the next frame's pose
    (translations linearly, rotations by the same body-frame increment)."""
    from ..spatial import quat_conjugate, quat_multiply, normalize_quat, rotation_matrix

    qp = np.asarray(q_prev).reshape(-1, 7)
    for k, i in enumerate(state.moving):
        state.p_WB[i] = 2 * state.p_WB[i] - qp[k, :3]
        dq = quat_multiply(quat_conjugate(qp[k, 3:]), state.quat_WB[i])
        state.quat_WB[i] = normalize_quat(quat_multiply(state.quat_WB[i], dq))
        state.R_WB[i] = rotation_matrix(state.quat_WB[i])


def _rates(delta, ok, dt):
    """δ̇ and δ̈ (nf, nm, 3) from the residual history δ (nf, nm, 3) by central
    differences (Eq. 7), one-sided where a neighbour is missing or failed."""
    nf = len(delta)
    d1 = np.zeros_like(delta)
    d2 = np.zeros_like(delta)
    good = ok[:, None, None] & np.isfinite(delta)
    D = np.where(good, delta, 0.0)
    for k in range(nf):
        has_prev = k > 0
        has_next = k < nf - 1
        cur = good[k]
        prev = good[k - 1] if has_prev else np.zeros_like(cur)
        nxt = good[k + 1] if has_next else np.zeros_like(cur)
        both = cur & prev & nxt
        d1[k] = np.where(both, (D[min(k + 1, nf - 1)] - D[max(k - 1, 0)]) / (2 * dt), 0.0)
        d2[k] = np.where(both, (D[min(k + 1, nf - 1)] - 2 * D[k] + D[max(k - 1, 0)]) / dt**2, 0.0)
        fwd = cur & nxt & ~prev
        d1[k] = np.where(fwd, (D[min(k + 1, nf - 1)] - D[k]) / dt, d1[k])
        bwd = cur & prev & ~nxt
        d1[k] = np.where(bwd, (D[k] - D[max(k - 1, 0)]) / dt, d1[k])
    return d1, d2


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
    if times is None:
        times = np.asarray(trajectories.time, dtype=float)
    times = np.asarray(times, dtype=float)
    nf = len(times)
    dt = float(times[1] - times[0]) if nf > 1 else 1.0
    if nf > 2 and np.max(np.abs(np.diff(times) - dt)) > 1e-9 * max(1.0, abs(dt)):
        raise ValueError("marker tracking needs uniformly spaced analysis times")
    alpha = _alpha(model, alpha)
    system = ConstraintSystem(model)
    tracker = MarkerTracker(system, settings or TrackingSettings())
    nm, n = model.markers.size, model.n_coords
    state = model.initial_state()
    q = np.full((nf, 7 * n // 6), np.nan)
    v = np.full((nf, n), np.nan)
    vd = np.full((nf, n), np.nan)
    delta = np.full((nf, nm, 3), np.nan)
    viol = np.full(nf, np.nan)
    iters = np.zeros(nf, dtype=int)
    ok = np.zeros(nf, dtype=bool)
    msgs = [""] * nf
    meas = []
    bar = _progress(2 * nf, progress, "kinematics")
    guessed = False
    last_good = state.copy()
    kkt = [None] * nf
    q_prev = None
    # -- pass 1: positions (Eqs. 4-5) ------------------------------------------------
    for k, t in enumerate(times):
        x, xd, xdd, vis = trajectories.evaluate(t)
        meas.append((x, xd, xdd, vis))
        if not guessed and np.any(vis):
            tracker.initial_guess(state, x, vis)
            guessed = True
        res, K, _ = tracker.solve_positions(state, t, x, vis, alpha)
        iters[k], viol[k] = res.iterations, res.residual
        if res.converged:
            ok[k] = True
            kkt[k] = K
            q[k] = state.get_q()
            delta[k] = np.where(vis[:, None], tracker.residuals(state, x), np.nan)
            last_good = state.copy()
            # warm start of the next frame: linear extrapolation on the manifold
            if q_prev is not None:
                _extrapolate(state, q_prev)
            q_prev = q[k]
        else:
            msgs[k] = f"frame {k} (t = {t:.4f} s): {res.message}"
            state = last_good.copy()
            q_prev = None
        if bar:
            bar.update()
    # -- pass 2: velocities and accelerations (Eqs. 6-10) ---------------------------
    d1, d2 = _rates(delta, ok, dt)
    for k, t in enumerate(times):
        if ok[k]:
            state.set_q(q[k])
            x, xd, xdd, vis = meas[k]
            v[k], vd[k] = tracker.solve_velocities_accelerations(
                state, t, kkt[k], vis, np.nan_to_num(xd), np.nan_to_num(xdd), d1[k], d2[k], alpha
            )
        if bar:
            bar.update()
    if bar:
        bar.close()
    return KinematicsResult(
        model.name, tuple(b.name for b in model.moving_bodies), model.markers.names, times,
        q, v, vd, delta, viol, iters, ok, tuple(msgs), alpha, _time.perf_counter() - t0, "tracking",
    )
