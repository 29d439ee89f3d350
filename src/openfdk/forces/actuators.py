"""Coordinate actuators: recruitment columns weighted by their optimal force (OpenSim's
CoordinateActuator, and the reserve and residual actuators of its static optimisation).

An actuator j applies a generalised force τ_j along a scalar measure u_j (a joint
coordinate, or any named scalar measure of the model):

    Q = (∂u_j/∂q̂)ᵀ τ_j,     τ_j = a_j F_j,     min_control ≤ a_j ≤ max_control,

with F_j its optimal force (N for a translation, N m for a rotation) and a_j its
control. Its column of C f = d (paper Eq. 12) is +(∂u_j/∂q̂)ᵀ, and it enters the
recruitment criterion (Eq. 11) as |τ_j / F_j|^p, exactly as OpenSim's static
optimisation weighs an actuator (Σ |a_j|^p): F_j is the weight, a small optimal force
makes a costly actuator.

The polynomial recruitment bounds its columns below by 0, so each actuator is solved as
two columns, τ = τ⁺ − τ⁻ with 0 ≤ τ⁺ ≤ max_control F and 0 ≤ τ⁻ ≤ −min_control F, both
of strength F (:func:`expand_columns`), and folded back into one signed column of the
result (:func:`fold_result`). Because G is strictly convex for p ≥ 2, at most one of
the pair is non-zero at the optimum (shrinking both lowers G and keeps C f = d), so
the fold is exact.

A motion driver on a coordinate that an actuator acts on carries no reaction (see
:mod:`openfdk.dynamics.equilibrium`): the actuators and muscles balance it.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

__all__ = ["CoordinateActuator", "ActuatorColumns", "expand_columns", "fold_result"]


@dataclass(frozen=True)
class CoordinateActuator:
    """One actuator. name; coordinate : name of the scalar measure it acts along;
    measure : that Measure; optimal_force : F > 0 (N or N m, the weight);
    min_control ≤ 0 ≤ max_control : the bounds of a = τ/F (±inf: none)."""

    name: str
    coordinate: str
    measure: object
    optimal_force: float
    min_control: float = -np.inf
    max_control: float = np.inf


class ActuatorColumns:
    """The actuators of a model as recruitment columns (built once per model).

    ``jacobian(state)`` : (n_act, n) rows ∂u_j/∂q̂ at the state (m/m or rad/m …, the
    measures' units per q̂ unit); ``optimal_force`` (n_act,) N or N m; ``upper`` (2 n_act,)
    the activity bounds of the expanded columns [τ⁺…, τ⁻…] (+inf: none; 0: that sign is
    not allowed, strength 0 there)."""

    def __init__(self, actuators):
        from ..model.compiled import CompiledMeasures

        self.actuators = tuple(actuators)
        self.names = tuple(a.name for a in self.actuators)
        self.program = CompiledMeasures([a.measure for a in self.actuators]) if self.actuators else None
        self.optimal_force = np.array([a.optimal_force for a in self.actuators], float)
        self.upper = np.concatenate([[a.max_control for a in self.actuators],
                                     [-a.min_control for a in self.actuators]]).astype(float)

    def __len__(self):
        return len(self.actuators)

    def jacobian(self, state):
        """(n_act, n) ∂u/∂q̂ of the actuators' measures at ``state``."""
        if self.program is None:
            return np.zeros((0, state.n_coords))
        return self.program.evaluate(state, 1)[1]


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
