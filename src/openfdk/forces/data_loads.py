"""Measured external loads (ground reactions) as one force set (:mod:`.forceset`):
OpenSim's ExternalForce applied exactly as OpenSim applies it.

A load on body B is a force F, a point P where it acts and a torque T, each a sampled
time series (s -> N, m, N m) whose components are expressed in the ground (world) or in
B itself (OpenSim's ``force_expressed_in_body`` and ``point_expressed_in_body``; the
torque is expressed like the force). With F_W, T_W the world components and d_W = p_WP −
r_WB (r_WB the centre of mass), the generalised forces on B's 6 columns
(q̂ = [δr_W; δπ_B], docs/design.md §1) are

    Q = [F_W ; d_B × F_B + T_B]        (N, N m),   x_B = R_WBᵀ x_W.

Stiffness (for the analytic FDK Jacobian). A rotation δπ_B changes a world-fixed vector
seen in B by x̃_B δπ (and leaves a B-fixed one), and a translation δr moves d_W by −δr
when P is given in the ground:

    ∂Q_r/∂δπ = −R_WB F̃_B (force in B) or 0;
    ∂Q_π/∂δπ = −F̃_B D + d̃_B G + H,   D = d̃_B (point in ground) or 0,
               G = F̃_B (force in ground) or 0, H = T̃_B (torque in ground) or 0;
    ∂Q_π/∂δr = F̃_B R_WBᵀ (point in ground) or 0.

Where the data have no point (OpenSim's point_identifier empty), OpenSim applies the
force at B's origin: the section loader passes a constant point 0 in B's OpenSim frame.

Per frame. A trial's analysis knows its frame times, so :meth:`DataLoadForces.prepare`
samples every load's force, point and torque at all of them at once (a spline
evaluated over an array of times, :meth:`openfdk.numerics.cubic_spline.NotAKnotSpline.values`);
a frame then costs a dictionary look-up and one compiled call
(:func:`apply_data_loads`: the frames' rotations, r × F and Q for every load). Times
not prepared (a single frame, an FDK trial) are sampled when asked, as before.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from ..model.timefunctions import Constant, SplineThroughData, TimeFunction, sampled_time_range
from ..numerics.spatial import skew


@dataclass(frozen=True, eq=False)
class DataLoad:
    """A measured load on ``body`` (index): ``force``, ``point`` and ``torque`` time
    functions of 3 components (N; m; N m), ``force_frame`` and ``point_frame`` "world" or
    "body" (the torque is in the force's frame); ``p_BF (3,) m`` and ``R_BF (3, 3)``: the
    frame F of the "body" components in openfdk's body frame (OpenSim gives them in its
    body frame, whose origin is not the centre of mass); ``invalid``: ((t0 s, t1 s,
    reason), …) intervals where the load is not known (a force plate struck by both
    feet): frames there fail with the reason (:func:`invalid_reason`)."""

    name: str
    body: int
    force: TimeFunction
    point: TimeFunction
    torque: TimeFunction
    force_frame: str = "world"
    point_frame: str = "world"
    p_BF: np.ndarray = None
    R_BF: np.ndarray = None
    invalid: tuple = ()


def invalid_reason(loads, t):
    """The reason why the loads are not known at time t (s), or '' (frames whose
    ground reaction cannot be assigned fail, never silently without it)."""
    for load in loads:
        for t0, t1, reason in load.invalid:
            if t0 - 1e-9 <= t <= t1 + 1e-9:
                return reason
    return ""


def load_record(model):
    """For summary.json's ``input``: ``external_loads`` {load name: {"body": its body's
    name}} and ``gravity_W_m_s2`` (3,) m/s², which say which foot each measured load acts
    on and which way is up (``openfdk cycles`` finds heel strikes from them); {} without
    measured loads."""
    loads = getattr(model, "external_loads", ())
    if not loads:
        return {}
    return {"external_loads": {load.name: {"body": model.bodies[load.body].name} for load in loads},
            "gravity_W_m_s2": [float(g) for g in model.gravity_W]}


def data_time_range(loads):
    """(first, last) s over which every sampled (spline, not extrapolated) time function
    of ``loads`` (DataLoad) has data, or (−inf, inf) when none is sampled."""
    return sampled_time_range(f for load in loads for f in (load.force, load.point, load.torque))


def sample(function, times):
    """(nf, 3) values of a load's time function at ``times`` (nf,) s, or None where one
    cannot be given at once: a spline's times outside its data (its per-frame call then
    raises the message naming them)."""
    times = np.asarray(times, dtype=float)
    if isinstance(function, Constant):
        return np.broadcast_to(function.derivatives(0.0)[0], (len(times), 3)).copy()
    if isinstance(function, SplineThroughData):
        lo, hi = function.t_range
        if not function.extrapolate and not np.all((lo - 1e-12 <= times) & (times <= hi + 1e-12)):
            return None
        return function._s.values(times)
    return np.array([function.derivatives(float(t))[0] for t in times]).reshape(len(times), 3)


@njit(cache=True)
def apply_data_loads(body, column, in_body, p_BF, R_BF, p_WB, R_WB, S, Q, W):
    """Q (n,) += every load's generalised forces (module docstring), in place.

    body (nl,) int the loads' bodies; column (nb,) their first q̂ columns (−1: fixed,
    skipped); in_body (nl, 2) bool: force (and torque), point given in the body frame F;
    p_BF (nl, 3) m, R_BF (nl, 3, 3) the frame F in the body; p_WB (nb, 3) m, R_WB (nb, 3,
    3) the poses; S (nl, 9) the samples [F (N), P (m), T (N m)] as given. Output W (nl,
    9): [F_W, p_WP, T_W] in the world (N, m, N m)."""
    for k in range(body.shape[0]):
        i = body[k]
        c = column[i]
        if c < 0:
            continue
        R = R_WB[i]
        R_WF = np.empty((3, 3))
        for a in range(3):
            for b in range(3):
                R_WF[a, b] = R[a, 0] * R_BF[k, 0, b] + R[a, 1] * R_BF[k, 1, b] + R[a, 2] * R_BF[k, 2, b]
        for a in range(3):
            if in_body[k, 0]:  # x_W = R_WB R_BF x_F
                W[k, a] = R_WF[a, 0] * S[k, 0] + R_WF[a, 1] * S[k, 1] + R_WF[a, 2] * S[k, 2]
                W[k, 6 + a] = R_WF[a, 0] * S[k, 6] + R_WF[a, 1] * S[k, 7] + R_WF[a, 2] * S[k, 8]
            else:
                W[k, a] = S[k, a]
                W[k, 6 + a] = S[k, 6 + a]
            if in_body[k, 1]:  # p_W = r_WB + R_WB p_BF + R_WF p_F
                W[k, 3 + a] = (p_WB[i, a] + R[a, 0] * p_BF[k, 0] + R[a, 1] * p_BF[k, 1] + R[a, 2] * p_BF[k, 2]
                               + R_WF[a, 0] * S[k, 3] + R_WF[a, 1] * S[k, 4] + R_WF[a, 2] * S[k, 5])
            else:
                W[k, 3 + a] = S[k, 3 + a]
        d0, d1, d2 = W[k, 3] - p_WB[i, 0], W[k, 4] - p_WB[i, 1], W[k, 5] - p_WB[i, 2]
        f0, f1, f2 = W[k, 0], W[k, 1], W[k, 2]
        # Q = [F_W ; R_WBᵀ (d_W × F_W + T_W)]
        m0 = d1 * f2 - d2 * f1 + W[k, 6]
        m1 = d2 * f0 - d0 * f2 + W[k, 7]
        m2 = d0 * f1 - d1 * f0 + W[k, 8]
        for a in range(3):
            Q[c + a] += W[k, a]
            Q[c + 3 + a] += R[0, a] * m0 + R[1, a] * m1 + R[2, a] * m2


class DataLoadForces:
    """The measured external loads (``model.external_loads``). Outputs: dict load name ->
    (F_W (3,) N, p_WP (3,) m, T_W (3,) N m) at the frame's time."""

    kind = "external_loads"

    def __init__(self, loads):
        self.loads = tuple(loads)
        nl = len(self.loads)
        self._body = np.array([load.body for load in self.loads], np.int64)
        self._in_body = np.array([[load.force_frame == "body", load.point_frame == "body"] for load in self.loads],
                                 bool).reshape(nl, 2)
        self._p_BF = np.array([np.zeros(3) if load.p_BF is None else load.p_BF for load in self.loads],
                              float).reshape(nl, 3)
        self._R_BF = np.array([np.eye(3) if load.R_BF is None else load.R_BF for load in self.loads],
                              float).reshape(nl, 3, 3)
        self._samples = {}  # t (s) -> (nl, 9) [F, P, T] of every load at t (prepare)
        self._last = None  # (t s, (nl, 9)): the last time sampled that was not prepared

    def prepare(self, times):
        """Sample every load at the trial's frame times (nf,) s at once; a frame at one
        of them then needs no spline evaluation (module docstring)."""
        times = np.asarray(times, dtype=float).reshape(-1)
        table = self.table(times)
        if table is not None:
            self._samples = {float(t): table[i] for i, t in enumerate(times)}

    def table(self, times):
        """(nf, n_loads, 9) [F, P, T] of every load at ``times`` (nf,) s, components as
        given (what :func:`apply_data_loads` takes per frame), or None when a time is
        outside a load's data (its per-frame call then raises the message)."""
        times = np.asarray(times, dtype=float).reshape(-1)
        table = np.empty((len(times), len(self.loads), 9))
        for k, load in enumerate(self.loads):
            for j, function in enumerate((load.force, load.point, load.torque)):
                values = sample(function, times)
                if values is None:
                    return None
                table[:, k, 3 * j : 3 * j + 3] = values
        return table

    @property
    def kernel_args(self):
        """(body, in_body, p_BF, R_BF): the loads' arrays in :func:`apply_data_loads`'s order."""
        return self._body, self._in_body, self._p_BF, self._R_BF

    def _sampled(self, t, column):
        """(nl, 9) [F, P, T] of every load at t (s), components as given (zero for a load
        on a body that does not move, which is not applied). A time not prepared is
        sampled once and kept until another one is asked: FDK evaluates a frame's
        residual at one t 3–5 times, and its lead-in's frames are not prepared."""
        S = self._samples.get(float(t))
        if S is None and self._last is not None and self._last[0] == float(t):
            S = self._last[1]
        if S is None:
            S = np.zeros((len(self.loads), 9))
            for k, load in enumerate(self.loads):
                if column[load.body] >= 0:
                    for j, function in enumerate((load.force, load.point, load.torque)):
                        S[k, 3 * j : 3 * j + 3] = function.derivatives(t)[0]
            self._last = (float(t), S)
        return S

    def accumulate(self, state, t, Q, K=None):
        W = np.zeros((len(self.loads), 9))
        apply_data_loads(self._body, state.column, self._in_body, self._p_BF, self._R_BF, state.p_WB, state.R_WB,
                         self._sampled(t, state.column), Q, W)
        out = {}
        for k, load in enumerate(self.loads):
            c = state.column[load.body]
            if c < 0:
                continue
            F_W, p_W, T_W = W[k, :3], W[k, 3:6], W[k, 6:]
            out[load.name] = (F_W, p_W, T_W)
            if K is not None:
                self._add_stiffness(load, c, state.R_WB[load.body], F_W, T_W, p_W - state.p_WB[load.body], K)
        return out

    def stiffness(self, state, out, K):
        for load in self.loads:
            if load.name in out:
                c = state.column[load.body]
                F_W, p_W, T_W = out[load.name]
                self._add_stiffness(load, c, state.R_WB[load.body], F_W, T_W, p_W - state.p_WB[load.body], K)

    @staticmethod
    def _add_stiffness(load, c, R, F_W, T_W, d_W, K):
        """K += ∂Q/∂q̂ on the body's columns (module docstring)."""
        F_B, T_B, d_B = R.T @ F_W, R.T @ T_W, R.T @ d_W
        Fx, dx = skew(F_B), skew(d_B)
        rot = np.zeros((3, 3))
        if load.point_frame == "world":
            rot -= Fx @ dx
            K[c + 3 : c + 6, c : c + 3] += Fx @ R.T
        if load.force_frame == "world":
            rot += dx @ Fx + skew(T_B)
        else:
            K[c : c + 3, c + 3 : c + 6] -= R @ Fx
        K[c + 3 : c + 6, c + 3 : c + 6] += rot
