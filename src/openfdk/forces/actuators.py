"""Actuators: recruitment columns weighted by their optimal force (OpenSim's
CoordinateActuator, PointActuator and TorqueActuator: the reserve and residual actuators
of its static optimisation).

An actuator j applies the generalised force Q = G_jᵀ τ_j, τ_j = a_j F_j,
min_control ≤ a_j ≤ max_control, where G_j is the virtual-work row of a unit τ_j:

* a coordinate actuator, along a scalar measure u_j (a joint coordinate, or any named
  scalar measure of the model): G_j = ∂u_j/∂q̂;
* a point actuator, a force τ d at a point p of a body: G_j = dᵀ ∂p/∂q̂;
* a torque actuator, τ n on one body and −τ n on another: G_j = n · (∂θ/∂q̂ of the first
  − of the second), θ the small rotations in the world.

F_j is its optimal force (N or N m) and a_j its control. Its column of C f = d (paper
Eq. 12) is +G_jᵀ, and it enters the recruitment criterion (Eq. 11) as |τ_j / F_j|^p,
exactly as OpenSim's static optimisation weighs an actuator (Σ |a_j|^p): F_j is the
weight, a small optimal force makes a costly actuator.

The polynomial recruitment bounds its columns below by 0, so each actuator is solved as
two columns, τ = τ⁺ − τ⁻ with 0 ≤ τ⁺ ≤ max_control F and 0 ≤ τ⁻ ≤ −min_control F, both
of strength F (:func:`expand_columns`), and folded back into one signed column of the
result (:func:`fold_result`). Because G is strictly convex for p ≥ 2, at most one of
the pair is non-zero at the optimum (shrinking both lowers G and keeps C f = d), so
the fold is exact.

In a model with actuators, the drivers of joint coordinates (a ``--motion``) carry no
reaction (see :mod:`openfdk.dynamics.equilibrium`): the muscles and actuators balance the
motion, as in OpenSim's static optimisation.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

__all__ = ["CoordinateActuator", "PointActuator", "TorqueActuator", "ActuatorColumns", "expand_columns",
           "fold_result"]


@dataclass(frozen=True)
class CoordinateActuator:
    """A generalised force along a scalar coordinate (OpenSim's CoordinateActuator).
    name; coordinate : name of the scalar measure it acts along; measure : that
    Measure; optimal_force : F > 0 (N or N m, the weight); min_control ≤ 0 ≤ max_control :
    the bounds of a = τ/F (±inf: none)."""

    name: str
    coordinate: str
    measure: object
    optimal_force: float
    min_control: float = -np.inf
    max_control: float = np.inf


@dataclass(frozen=True)
class PointActuator:
    """A force τ d at a point of a body (OpenSim's PointActuator). body : index;
    point : (3,) m, in the body's frame, or in the world when ``point_is_global`` (then
    the force acts on the body's material point at that world position, as OpenSim's);
    direction : (3,) unit, in the world (``force_is_global``) or the body's frame."""

    name: str
    body: int
    point: np.ndarray
    point_is_global: bool
    direction: np.ndarray
    force_is_global: bool
    optimal_force: float
    min_control: float = -np.inf
    max_control: float = np.inf


@dataclass(frozen=True)
class TorqueActuator:
    """A torque τ n on ``body`` and −τ n on ``reaction_body`` (OpenSim's TorqueActuator,
    bodyA and bodyB; indices, 0 the ground). axis : (3,) unit, in the world
    (``torque_is_global``) or the frame of ``body``."""

    name: str
    body: int
    reaction_body: int
    axis: np.ndarray
    torque_is_global: bool
    optimal_force: float
    min_control: float = -np.inf
    max_control: float = np.inf


class ActuatorColumns:
    """The actuators of a model as recruitment columns (built once per model).

    ``jacobian(state)`` : (n_act, n) rows G with Q = Gᵀ τ, the generalised force of a unit
    actuator force on q̂ = [δr; δπ'] per body (r the body origin in the world, δπ' the
    small rotation in the body frame): a coordinate actuator ∂u/∂q̂ (compiled measures);
    a point actuator dᵀ ∂p/∂q̂ with ∂p/∂δr = I, ∂p/∂δπ' = −R [p_B]×; a torque actuator
    Rᵀ n on the rotation of ``body`` and −Rᵀ n on that of ``reaction_body``.
    ``optimal_force`` (n_act,) N or N m; ``upper`` (2 n_act,) the activity bounds of the
    expanded columns [τ⁺…, τ⁻…] (+inf: none; 0: that sign is not allowed)."""

    def __init__(self, actuators):
        from ..model.compiled import CompiledMeasures

        self.actuators = tuple(actuators)
        self.names = tuple(a.name for a in self.actuators)
        coords = [k for k, a in enumerate(self.actuators) if isinstance(a, CoordinateActuator)]
        self._coordinate_rows = np.array(coords, np.int64)
        self.program = CompiledMeasures([self.actuators[k].measure for k in coords]) if coords else None
        self._others = [(k, a) for k, a in enumerate(self.actuators) if not isinstance(a, CoordinateActuator)]
        self.optimal_force = np.array([a.optimal_force for a in self.actuators], float)
        self.upper = np.concatenate([[a.max_control for a in self.actuators],
                                     [-a.min_control for a in self.actuators]]).astype(float)

    def __len__(self):
        return len(self.actuators)

    def jacobian(self, state):
        """(n_act, n) G of the actuators at ``state`` (class docstring)."""
        G = np.zeros((len(self.actuators), state.n_coords))
        if self.program is not None:
            G[self._coordinate_rows] = self.program.evaluate(state, 1)[1]
        for k, a in self._others:
            if isinstance(a, PointActuator):
                _point_row(a, state, G[k])
            else:
                _torque_row(a, state, G[k])
        return G


def _point_row(a, state, row):
    """dᵀ ∂p/∂q̂ of a point actuator (see ActuatorColumns)."""
    R, p_WB, c = state.R_WB[a.body], state.p_WB[a.body], state.column[a.body]
    p_B = R.T @ (a.point - p_WB) if a.point_is_global else a.point
    d_W = a.direction if a.force_is_global else R @ a.direction
    if c < 0:
        return
    row[c:c + 3] = d_W
    row[c + 3:c + 6] = np.cross(p_B, R.T @ d_W)  # dᵀ(−R [p]×) = ([p]× Rᵀd)ᵀ = p × Rᵀd


def _torque_row(a, state, row):
    """Rᵀ n on the rotation of ``body``, −Rᵀ n on that of ``reaction_body``."""
    n_W = a.axis if a.torque_is_global else state.R_WB[a.body] @ a.axis
    for body, sign in ((a.body, 1.0), (a.reaction_body, -1.0)):
        c = state.column[body]
        if c >= 0:
            row[c + 3:c + 6] += sign * (state.R_WB[body].T @ n_W)


def expand_columns(C, s, n_bounded, first, columns: ActuatorColumns):
    """The recruitment problem with each actuator split into τ⁺, τ⁻ columns.

    C : (n_eq, n_var) with the actuators' columns at ``first … first + n_act − 1`` (among
    the bounded ones); s : (n_bounded,) strengths (the actuators': F). Returns (C_x
    (n_eq, n_var + n_act), s_x (n_bounded + n_act,), upper (n_bounded + n_act,),
    n_bounded + n_act): the τ⁻ columns −C_act are appended after the bounded ones; a sign
    whose control bound is 0 gets strength 0 (the solver fixes it at 0)."""
    na = len(columns)
    act = slice(first, first + na)
    C_x = np.concatenate([C[:, :n_bounded], -C[:, act], C[:, n_bounded:]], axis=1)
    s_x = np.concatenate([s, s[act]])
    upper = np.ones(n_bounded + na)
    u_plus, u_minus = columns.upper[:na], columns.upper[na:]
    upper[act] = np.where(u_plus > 0.0, u_plus, 1.0)
    upper[n_bounded:] = np.where(u_minus > 0.0, u_minus, 1.0)
    s_x[act] = np.where(u_plus > 0.0, s_x[act], 0.0)
    s_x[n_bounded:] = np.where(u_minus > 0.0, s_x[n_bounded:], 0.0)
    return C_x, s_x, upper, n_bounded + na


def fold_result(result, n_bounded, first, na):
    """The expanded problem's RecruitmentResult folded back to the layout's columns:
    τ = τ⁺ − τ⁻ per actuator; an actuator at a control bound is ``active_upper`` (held
    there, for the sensitivity analysis), one at exactly 0 ``active_lower``."""
    f = result.f
    act = slice(first, first + na)
    neg = slice(n_bounded, n_bounded + na)
    tau = f[act] - f[neg]
    keep = np.r_[np.arange(n_bounded), np.arange(n_bounded + na, f.shape[0])]
    f_out = f[keep].copy()
    f_out[act] = tau
    upper = result.active_upper[keep].copy()
    lower = result.active_lower[keep].copy()
    upper[act] = result.active_upper[act] | result.active_upper[neg]
    lower[act] = (tau == 0.0) & ~upper[act]
    return replace(result, f=f_out, active_upper=upper, active_lower=lower, n_bounded=n_bounded)
