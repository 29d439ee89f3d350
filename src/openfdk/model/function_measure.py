"""A function of a scalar measure: m = f(u), with u a measure and f a coordinate
function of OpenSim's kinds (:mod:`openfdk.model.coordinate_functions`).

This is how a coupled joint row reads: OpenSim's knee translation "x = spline(knee
flexion)" becomes the row x − f(θ) = 0 with θ the flexion measure, and a
CoordinateCouplerConstraint q_dep = f(q_indep) the row q_dep − f(q_indep) = 0.

Chain rule (docs/design.md §1, ṁ = M v, m̈ = M v̇ + b):

    m = f(u),   M = f'(u) M_u,   b = f''(u) u̇² + f'(u) b_u,   u̇ = M_u v.

The compiled op (:data:`openfdk.model.compiled.OP_FUNCTION`) is the same formula.
"""

from __future__ import annotations

import numpy as np

from .measures import Measure


class FunctionOf(Measure):
    """m = f(u) (1 row). ``function``: a PiecewisePolynomial (y in the row's unit, x in
    u's unit); ``measure``: a scalar measure u; ``units``: the unit of m ("length",
    "angle" or "1")."""

    size = 1

    def __init__(self, function, measure, units="1", name=""):
        if measure.size != 1:
            raise ValueError(f"function of measure {measure.name!r}: the measure must be scalar, it has "
                             f"{measure.size} rows")
        self.function = function
        self.measure = measure
        self.units = (units,)
        self.name = name

    def bodies(self):
        return self.measure.bodies()

    def evaluate(self, state, order=1):
        u, Mu, bu = self.measure.evaluate(state, order)
        f, df, d2f = self.function.evaluate(float(u[0]))
        value = np.array([f])
        if order == 0:
            return value, None, None
        M = df * Mu
        if order == 1:
            return value, M, None
        du = float(Mu[0] @ _velocity_vector(state))
        return value, M, np.array([d2f * du * du + df * bu[0]])


def _velocity_vector(state):
    """v = [ṙ_1; ω'_1; …] (6 n_moving,) of a BodyStates."""
    v = np.zeros(state.n_coords)
    for i, c in enumerate(state.column):
        if c >= 0:
            v[c : c + 3] = state.v_WB[i]
            v[c + 3 : c + 6] = state.w_BB[i]
    return v
