"""A bounded column the free forces absorb gets exactly zero force (recruitment.reduction).

Two equilibrium rows, a muscle m1 on both, a muscle m2 and a free force F on row 0 only:

    f1 + f2 + F = d0,    f1 + ε f2 = d1    (ε = 1e-15, round-off of a projected column)

m2's column [1, ε] lies in the span of F's [1, 0] to round-off: F takes any load m2
could carry at no cost, so the optimum of Σ (f/s)³ has f2 = 0, f1 = d1, F = d0 − d1.
Before the reduction zeroed such columns, the polynomial criterion's activity √(u/3) made
the round-off u = ε μ a force of s √(ε μ / 3), about 1e-5 N here (a few mN on the DM-size
knee, docs/fdk.md "The noise floor of f^FDK").
"""

import numpy as np
import pytest

from openfdk.recruitment.polynomial import solve_polynomial

S = np.array([1000.0, 2000.0])  # N, strengths of m1, m2
D = np.array([300.0, 120.0])  # N


@pytest.mark.parametrize("eps", [0.0, 1e-15, -1e-15, 1e-12])
def test_an_absorbed_column_carries_exactly_zero_force(eps):
    C = np.array([[1.0, 1.0, 1.0], [1.0, eps, 0.0]])
    res = solve_polynomial(C, D, 2, S, 3.0)
    assert res.converged
    f1, f2, F = res.f
    assert f2 == 0.0
    assert f1 == pytest.approx(D[1], rel=1e-9)  # (the solver tolerance, 1e-10 in activity)
    assert F == pytest.approx(D[0] - D[1], rel=1e-9)


def test_a_column_outside_the_free_span_is_recruited():
    """The same rows with m2 acting on row 1 by 0.5: no longer absorbed, and the optimum
    of f1³/s1³ + f2³/s2³ with f1 + 0.5 f2 = d1 in closed form: the stationarity
    3 f1²/s1³ = λ, 3 f2²/s2³ = 0.5 λ gives f2 = f1 √0.5 (s2/s1)^{3/2}."""
    C = np.array([[1.0, 1.0, 1.0], [1.0, 0.5, 0.0]])
    res = solve_polynomial(C, D, 2, S, 3.0)
    ratio = np.sqrt(0.5) * (S[1] / S[0]) ** 1.5
    f1 = D[1] / (1.0 + 0.5 * ratio)
    np.testing.assert_allclose(res.f[:2], [f1, ratio * f1], rtol=1e-8)
    assert res.f[2] == pytest.approx(D[0] - res.f[0] - res.f[1], rel=1e-10)
