"""Measured external loads (ground reactions) as one force set (:mod:`.forceset`):
OpenSim's ExternalForce applied exactly as OpenSim applies it.

A load on body B is a force F, a point P where it acts and a torque T, each a sampled
time series (s -> N, m, N m) whose components are expressed in the ground (world) or in
B itself (OpenSim's ``force_expressed_in_body`` and ``point_expressed_in_body``; the
torque is expressed like the force). With F_W, T_W the world components and d_W = p_WP −
r_WB (r_WB the centre of mass), the generalised forces on B's 6 columns
(q̂ = [δr_W; δπ_B], DESIGN.md §1) are

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
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..model.timefunctions import TimeFunction
from ..spatial import skew


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


class DataLoadForces:
    """The measured external loads (``model.external_loads``). Outputs: dict load name ->
    (F_W (3,) N, p_WP (3,) m, T_W (3,) N m) at the frame's time."""

    kind = "external_loads"

    def __init__(self, loads):
        self.loads = tuple(loads)

    def _vectors(self, load, state, t):
        i = load.body
        R, r = state.R_WB[i], state.p_WB[i]
        F = load.force.derivatives(t)[0]
        T = load.torque.derivatives(t)[0]
        P = load.point.derivatives(t)[0]
        R_WF = R @ load.R_BF
        F_W = F if load.force_frame == "world" else R_WF @ F
        T_W = T if load.force_frame == "world" else R_WF @ T
        p_W = P if load.point_frame == "world" else r + R @ load.p_BF + R_WF @ P
        return R, F_W, T_W, p_W - r, p_W

    def accumulate(self, state, t, Q, K=None):
        out = {}
        for load in self.loads:
            c = state.column[load.body]
            if c < 0:
                continue
            R, F_W, T_W, d_W, p_W = self._vectors(load, state, t)
            Q[c : c + 3] += F_W
            Q[c + 3 : c + 6] += R.T @ (np.cross(d_W, F_W) + T_W)
            out[load.name] = (F_W, p_W, T_W)
            if K is not None:
                self._add_stiffness(load, c, R, F_W, T_W, d_W, K)
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
