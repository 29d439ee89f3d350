"""The non-linear elastic-foundation law (openfdk.contact.pressure_law; Bei & Fregly
2004): its slope and energy are the derivative and integral of its pressure (central
differences, trapezoidal quadrature), two equal layers in series are one layer of twice
the thickness, the law is the linear one for small depths, and beyond the cap it
continues along its tangent."""

from __future__ import annotations

import numpy as np
import pytest

from openfdk.contact.pressure_law import CAP_FRACTION, layer_modulus, nonlinear_pressures


def _law(depth, layers):
    depth = np.ascontiguousarray(depth, dtype=float)
    P, dP, W = (np.empty_like(depth) for _ in range(3))
    nonlinear_pressures(depth, np.asarray(layers, float), P, dP, W)
    return P, dP, W


@pytest.mark.parametrize("layers", [[[2.0e7, 4e-3]], [[2.0e7, 4e-3], [6.0e7, 1e-3]]])
def test_slope_and_energy_are_consistent(layers):
    total = sum(h for _, h in layers)
    d = np.linspace(0.01, 0.95, 40) * total
    P, dP, W = _law(d, layers)
    e = 1e-7 * total
    fd = (_law(d + e, layers)[0] - _law(d - e, layers)[0]) / (2 * e)
    assert np.allclose(dP, fd, rtol=1e-6) and np.all(np.diff(dP) > 0)  # stiffens
    fine = np.linspace(0.0, d[-1], 200001)
    Pf = _law(fine, layers)[0]
    integral = np.sum(0.5 * (Pf[1:] + Pf[:-1]) * np.diff(fine))
    assert W[-1] == pytest.approx(integral, rel=1e-8)
    # small depths: the linear law 1/Σ h/K
    k = 1.0 / sum(h / K for K, h in layers)
    assert _law([1e-9 * total], layers)[0][0] == pytest.approx(k * 1e-9 * total, rel=1e-8)


def test_two_equal_layers_are_one_layer_of_twice_the_thickness():
    K, h = layer_modulus(1e7, 0.45), 2e-3
    d = np.linspace(0.0, 3.5e-3, 30)
    two = _law(d, [[K, h], [K, h]])
    one = _law(d, [[K, 2 * h]])
    for a, b in zip(two, one):
        np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-9)
    # the closed form of one layer
    np.testing.assert_allclose(one[0], -K * np.log(1 - d / (2 * h)), rtol=1e-13)


def test_beyond_the_cap_the_pressure_is_linear_and_finite():
    K, h = 1e7, 1e-3
    d_cap = CAP_FRACTION * h
    P, dP, W = _law([d_cap, d_cap + 0.5 * h, 3 * h], [[K, h]])
    assert np.all(np.isfinite(P)) and dP[1] == dP[2] == pytest.approx(K / (h - d_cap))
    assert P[1] == pytest.approx(P[0] + dP[0] * 0.5 * h)
