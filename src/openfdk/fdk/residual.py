"""The FDK residual f^FDK(α) of one frame (paper Fig. 1, Eqs. 1–14).

For given FDK inputs α (held fixed, α̇ = α̈ = 0): kinematic analysis at α — marker
tracking (positions at t − Δt, t, t + Δt with the same α, so that the residual rates of
Eq. 7 exist, then velocities and accelerations, Eqs. 8–10) or determinate (Eqs. 1–3) —
then the force elements, the equilibrium C f = d with one free residual-force column per
FDK DOF (Eq. 14), and the recruitment (Eq. 11). f^FDK is the FDK columns of f.

A :class:`FrameWorkspace` keeps the poses of the frame and its neighbours from the last
evaluation as the warm start of the next one; it belongs to one frame's solve.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..kinematics.curvature import HessianPattern
from ..kinematics.determinate import solve_positions
from ..kinematics.stages import marker_stage, velocity_stage_determinate, velocity_stage_tracking
from ..kinematics.tracking import KKTFactors, residual_rates, window_spacing
from ..model.framedata import FrameData


@dataclass
class Evaluation:
    """One residual evaluation at α (n_fdk,). ok : kinematics and recruitment succeeded;
    f_fdk : (n_fdk,) N or N m; message : reason when not ok; state : BodyStates at t with
    velocities; vdot : (n,); frame : FrameForces; kkt : the kinematic KKT matrix (tracking)
    and lam : its multipliers; x, visible : the measured markers at t (tracking);
    data : the FrameData of the pose (every stage once; the analytic Jacobian reads it)."""

    alpha: np.ndarray
    ok: bool
    f_fdk: np.ndarray
    message: str = ""
    stage: str = ""
    state: object = None
    vdot: np.ndarray = None
    frame: object = None
    kkt: np.ndarray = None
    lam: np.ndarray = None
    delta: np.ndarray = None
    x: np.ndarray = None
    visible: np.ndarray = None
    time: float = 0.0
    data: FrameData = None
    dq_dalpha: np.ndarray = None  # (n, n_fdk) dq̂/dα, set by the analytic Jacobian
    contact_split: object = None  # the contacts' part of the model (fdk.contact_step), likewise

    @property
    def norm(self):
        return float(np.max(np.abs(self.f_fdk))) if self.ok else np.inf


class FrameWorkspace:
    """Warm-start poses of frame k and its neighbours (BodyStates copies).

    alpha : (n_fdk,) the α the poses were solved at (None: not known); dq_dalpha :
    (n, n_fdk) the kinematic sensitivity dq̂/dα of frame k's pose
    (:func:`openfdk.fdk.jacobian.kinematic_sensitivity`, set where a Jacobian was
    computed) or None. With both, the next evaluation at α' first moves every pose by
    dq̂/dα (α' − alpha): the marker tracking then starts within second-order terms of its
    solution instead of |α' − alpha| from it (DM knee: 6–7 Gauss–Newton iterations per
    pose without, from a warm pose a few µm off)."""

    def __init__(self, states, alpha=None, dq_dalpha=None, factors=None):
        self.states = {j: s.copy() for j, s in states.items()}
        self.alpha, self.dq_dalpha = alpha, dq_dalpha
        #: {frame: KKTFactors} of the position solves (tracking): each evaluation's solve of
        #: a pose starts with chord steps on the factors its last solve left. Shared by
        #: copies: any nearby pose's factors serve (the solves converge to the same optimum)
        self.factors = dict(factors or {})

    def copy(self):
        return FrameWorkspace(self.states, self.alpha, self.dq_dalpha, self.factors)

    def factors_of(self, j, size):
        """The KKTFactors (size n + m) of frame j's position solves, made on first use."""
        if j not in self.factors:
            self.factors[j] = KKTFactors(size)
        return self.factors[j]

    def predict(self, alpha):
        """Move the poses by dq̂/dα (α − self.alpha) when both are known; the poses are then
        those of α (``self.alpha`` = α)."""
        if self.dq_dalpha is not None and self.alpha is not None:
            dq = self.dq_dalpha @ (np.asarray(alpha, dtype=float) - self.alpha)
            for state in self.states.values():
                state.displace(dq)
        self.alpha = np.array(alpha, dtype=float)


#: frames from the one whose Jacobian gave the tracking curvature within which the
#: position solves use it (FDKContext._curvature_at): that frame's poses and the next
#: frame's (its neighbours t ± Δt)
CURVATURE_REACH = 2
#: the position solves at t ± Δt stop at this many times the tracking's step tolerance
#: (``settings.tol_step``, 1e-9 m or rad by default: their chord steps then stop below
#: 1e-9 instead of 1e-12). Those poses enter f^FDK only through the residual rates of
#: Eq. 7: an error e there moves δ̈ by e / Δt² (1.4e-5 m/s² for e = 1e-9 m at 120 Hz),
#: where frame k's own pose moves the implant contacts' forces by their stiffness (about
#: 1e6 N/m) times e, so frame k keeps the tracking's tolerance. Measured on DM og1 at
#: 2.617 s: f^FDK moves by 2.6e-7 N (the tolerance is 1e-3 N), and the neighbours' solves
#: of the bench window's warm frames take 3.57 Gauss–Newton iterations instead of 5.03.
NEIGHBOUR_TOLERANCE = 1e3


class FDKContext:
    """Everything the residual needs that does not change within a trial.

    model; solver : InverseDynamics (its system has the FDK rows); tracker : MarkerTracker
    or None (determinate); measurements : per-frame (x, ẋ, ẍ, visible), a list over the
    frames or a dict by frame that may also hold the trial's samples just outside the
    window (frames −1 and nf, :func:`window_measurements`), or None; times : (nf,) s,
    uniform.
    """

    def __init__(self, model, solver, tracker, measurements, times, dt=None):
        self.model = model
        self.solver = solver
        self.system = solver.system
        self.tracker = tracker
        self.meas = None if measurements is None else (
            dict(measurements) if isinstance(measurements, dict) else dict(enumerate(measurements)))
        self.times = np.asarray(times, dtype=float)
        # the frame spacing: the window's, or a one-frame window's trial sample interval (dt)
        if dt is None:
            dt = float(self.times[1] - self.times[0]) if len(self.times) > 1 else 1.0
        self.dt = float(dt)
        names = solver.layout.column_names
        self.fdk_columns = np.array([names.index(f"fdk.{d.name}") for d in model.fdk_dofs], dtype=int)
        self._rates_frame, self._rates_k = None, None  # _measured_rates of the frame in work
        self.hessian_patterns = HessianPattern()  # the tracking Hessian's (kinematics/curvature.py)
        self._kkt_size = self.system.n_coords + self.system.n_rows  # n + m of the tracking's KKT matrix
        #: (S (n, n), t s): the tracking Lagrangian Hessian's second-order terms at the last
        #: analytic Jacobian's pose and that frame's time (fdk.jacobian.kinematic_sensitivity),
        #: or None: the position solves within CURVATURE_REACH frames of t take Newton steps
        #: with S (MarkerTracker.solve_positions)
        self.tracking_curvature = None

    def at_times(self, times, trajectories=None):
        """The same trial's context at other ``times`` (nf,) s — the same solver and
        tracker, the markers of ``trajectories`` (``evaluate(t)``) at those times — for
        the frames an approach solves (:mod:`openfdk.fdk.approach`)."""
        meas = None if trajectories is None else window_measurements(trajectories, times)
        return FDKContext(self.model, self.solver, self.tracker, meas, times, window_spacing(times, trajectories))

    def frames_needed(self, k):
        """Frame k and (tracking) its neighbours that have markers: the window's, and at
        its ends the trial's samples outside it (frames −1 and nf)."""
        if self.tracker is None:
            return [k]
        return [j for j in (k - 1, k, k + 1) if j in self.meas]

    def time_of(self, j):
        """The time (s) of frame j, also of the samples just outside the window."""
        return float(self.times[j]) if 0 <= j < len(self.times) else float(self.times[0] + j * self.dt)

    def evaluate(self, k, alpha, ws: FrameWorkspace, warm_recruitment=None) -> Evaluation:
        """f^FDK(α) at frame k; ``ws`` is updated in place with the new poses."""
        ev = self._evaluate(k, alpha, ws, warm_recruitment)
        ev.time = float(self.times[k])
        return ev

    def _evaluate(self, k, alpha, ws, warm_recruitment):
        alpha = np.asarray(alpha, dtype=float)
        try:
            return self._kinematics_and_dynamics(k, alpha, ws, warm_recruitment)
        except FloatingPointError as exc:
            # a pose where the kinematics are undefined: a rotation-angle measure at gimbal
            # lock (DM's patella, xyz at −90°, reached by a trial step of the elastic-tendon
            # overlay's sub-steps) — a failed evaluation, refused like any other, never an
            # exception out of the run
            return Evaluation(alpha, False, np.full(len(alpha), np.nan), f"kinematics failed: {exc}", "kinematics")

    def _kinematics_and_dynamics(self, k, alpha, ws, warm_recruitment):
        t = self.times[k]
        data = FrameData(t=t, alpha=alpha)
        if self.tracker is None:
            state = ws.states[k]
            res = solve_positions(self.system, state, t, alpha, data=data)  # + position stage
            if not res.converged:
                return Evaluation(alpha, False, np.full(len(alpha), np.nan), f"kinematics failed: {res.message}", "kinematics")
            velocity_stage_determinate(self.system, data, state)
            return self._dynamics(k, alpha, state, data, warm_recruitment)
        # marker tracking: positions at t - Δt, t, t + Δt with the same α (Eq. 7), from
        # the workspace's poses moved along dq̂/dα (FrameWorkspace.predict)
        ws.predict(alpha)
        delta = {}
        for j in self.frames_needed(k):
            x, _, _, vis = self.meas[j]
            t_j = self.time_of(j)
            tol = None if j == k else NEIGHBOUR_TOLERANCE * self.tracker.settings.tol_step  # (Eq. 7 only)
            res, K, lm = self.tracker.solve_positions(ws.states[j], t_j, x, vis, alpha, self._curvature_at(t_j), tol,
                                                      ws.factors_of(j, self._kkt_size))
            if res.converged:
                if j == k:  # marker stage at the solved pose; δ from its positions
                    data.kkt, data.lam = K, lm
                    marker_stage(self.tracker.markers, data, ws.states[k])
                    p_M = data.p_M.reshape(-1, 3)
                else:
                    p_M = self.tracker.markers.positions(ws.states[j])
                delta[j] = np.where(vis[:, None], p_M - x, np.nan)
            elif j == k:
                return Evaluation(alpha, False, np.full(len(alpha), np.nan), f"kinematics failed: {res.message}", "kinematics")
        d1, d2 = self._rates(k, delta)
        x, xd, xdd, vis = self.meas[k]
        state = ws.states[k]
        data.x_M, data.visible, data.delta = x, vis, delta[k]
        velocity_stage_tracking(self.tracker, data, state, *self._measured_rates(k), d1, d2)
        ev = self._dynamics(k, alpha, state, data, warm_recruitment)
        ev.kkt, ev.lam, ev.delta, ev.x, ev.visible = data.kkt, data.lam, delta[k], x, vis
        return ev

    def _curvature_at(self, t):
        """S (n, n) of ``tracking_curvature`` if it was taken within CURVATURE_REACH frames
        of time ``t`` (s), else None: a pose further on has other curvature, and Newton
        steps with the wrong one can take longer than Gauss–Newton's (the mandible model,
        whose Jacobian is carried for ten frames and more: 3–10 % slower with S from
        any earlier frame)."""
        if self.tracking_curvature is None:
            return None
        S, t_ref = self.tracking_curvature
        return S if abs(t - t_ref) <= CURVATURE_REACH * self.dt * (1 + 1e-9) else None

    def _measured_rates(self, k):
        """(ẋ, ẍ) (n_markers, 3) [m/s, m/s²] of frame k with occluded markers' NaN set to
        0: the same for every α, so built once per frame (the last frame's kept)."""
        if self._rates_frame != k:
            _, xd, xdd, _ = self.meas[k]
            self._rates_frame, self._rates_k = k, (_zero_nan(xd), _zero_nan(xdd))
        return self._rates_k

    def _rates(self, k, delta):
        """δ̇, δ̈ (n_markers, 3) at frame k from the residuals of k and its neighbours
        (Eq. 7; :func:`openfdk.kinematics.tracking.residual_rates`, as in marker
        tracking: central, one-sided per marker where a neighbour is missing)."""
        return residual_rates(delta.get(k - 1), delta[k], delta.get(k + 1), self.dt)


    def _dynamics(self, k, alpha, state, data, warm):
        """Equilibrium and recruitment stages from the data's Φ_q̂ and v̇; f^FDK."""
        state = state.copy()  # the workspace moves on with later evaluations
        try:
            fr = self.solver.frame(state, data.vdot, self.times[k], alpha, warm, data=data)
        except FloatingPointError as exc:  # a pose where a measure or a path is undefined (e.g. inside a wrap)
            return Evaluation(alpha, False, np.full(len(alpha), np.nan), str(exc), "failed", state, data.vdot,
                              data=data)
        if not fr.converged:
            return Evaluation(alpha, False, np.full(len(alpha), np.nan), f"recruitment failed: {fr.message}",
                              "recruitment", state, data.vdot, fr, data=data)
        data.f_fdk = fr.f[self.fdk_columns].copy()
        return Evaluation(alpha, True, data.f_fdk, "", "", state, data.vdot, fr, data=data)


def window_measurements(trajectories, times):
    """{frame: (x, ẋ, ẍ, visible)} of the markers at the window's ``times`` (nf,) s
    (frames 0 … nf − 1), and at t_0 − Δt (frame −1) and t_{nf−1} + Δt (frame nf) where
    the trial has markers there. With those, the residual rates of the window's first
    and last frames (Eq. 7) are central differences, as at every other frame, and a
    frame's result does not depend on where the window starts (one-sided rates at a
    window's first frame changed its α enough that DM's next frame took 67 evaluations
    and two restarts instead of 5). A one-frame window's neighbours are the trial's
    samples one sample interval away (:func:`~openfdk.kinematics.tracking.window_spacing`)."""
    times = np.asarray(times, dtype=float)
    meas = {j: trajectories.evaluate(t) for j, t in enumerate(times)}
    dt = window_spacing(times, trajectories)
    if dt is not None:
        for j, t in ((-1, times[0] - dt), (len(times), times[-1] + dt)):
            m = trajectories.evaluate(t)
            if np.any(m[3]):
                meas[j] = m
    return meas


def _zero_nan(a):
    """a with its non-finite entries (occluded markers' rates) set to 0."""
    return np.where(np.isfinite(a), a, 0.0)
