"""The natural spline of degree 1, 3, 5 through many points and columns
(openfdk.numerics.natural_spline), its evaluation (openfdk.numerics.spline_columns) and
OpenSim's processing of a coordinate file (openfdk.io.opensim.coordinate_filter).

Oracles: the defining conditions (interpolation, C^{2m−2} at the knots, vanishing end
derivatives m … 2m−2), scipy's B-spline interpolation with the same end conditions,
OpenSim's own GCVSpline, scipy's Butterworth design, and the filter's recursion written
out here sample by sample.
"""

from __future__ import annotations

from math import factorial

import numpy as np
import pytest

from openfdk.io.opensim.coordinate_filter import iir3_coefficients, lowpass_iir3, pad_odd
from openfdk.model.timefunctions import SplineThroughData
from openfdk.numerics.natural_spline import natural_spline_coefficients
from openfdk.numerics.spline_columns import SplineColumns


def _knots(rng, n):
    steps = rng.uniform(0.2, 1.0, n - 1)
    steps[n // 3] *= 0.01  # one step 100 times shorter than its neighbours
    return np.concatenate([[0.3], 0.3 + np.cumsum(steps)])


def _derivative(coef, j, tau):
    """j-th derivative of Σ_k coef[k] τ^k at τ (coef (w, k))."""
    return sum(factorial(k) / factorial(k - j) * coef[k] * tau ** (k - j) for k in range(j, coef.shape[0]))


@pytest.mark.parametrize("degree", [1, 3, 5])
def test_the_spline_meets_its_defining_conditions(degree):
    rng = np.random.default_rng(degree)
    n = 400
    x = _knots(rng, n)
    Y = rng.normal(size=(n, 3))
    coef = natural_spline_coefficients(x, Y, degree)
    m = (degree + 1) // 2
    assert coef.shape == (n - 1, 2 * m, 3)
    h = np.diff(x)
    scale = np.max(np.abs(Y))
    np.testing.assert_allclose(coef[:, 0], Y[:-1], atol=1e-12 * scale)
    np.testing.assert_allclose(_derivative(coef.transpose(1, 0, 2), 0, h[:, None]), Y[1:], atol=1e-9 * scale)
    for j in range(1, 2 * m - 1):  # continuity at the interior knots, relative to the derivative's size
        left = _derivative(coef[:-1].transpose(1, 0, 2), j, h[:-1, None])
        right = _derivative(coef[1:].transpose(1, 0, 2), j, 0.0)
        assert np.max(np.abs(left - right)) <= 1e-8 * np.max(np.abs(right)), j
    for j in range(m, 2 * m - 1):  # natural ends
        at_start = _derivative(coef[0], j, 0.0)
        at_end = _derivative(coef[-1], j, h[-1])
        typical = np.max(np.abs(_derivative(coef.transpose(1, 0, 2), j, 0.0)))
        assert np.max(np.abs(at_start)) <= 1e-9 * typical and np.max(np.abs(at_end)) <= 1e-9 * typical, j


def test_the_quintic_equals_scipys_interpolating_b_spline_with_the_same_ends():
    from scipy.interpolate import make_interp_spline

    rng = np.random.default_rng(2)
    n = 3000
    x = np.sort(rng.uniform(0, 30, n))
    y = np.sin(x) + 0.01 * rng.normal(size=n)
    natural = [(3, 0.0), (4, 0.0)]
    ref = make_interp_spline(x, y, k=5, bc_type=(natural, natural))
    s = SplineColumns(x, natural_spline_coefficients(x, y, 5))
    t = np.sort(rng.uniform(x[0], x[-1], 500))
    f, df, ddf = s.derivatives_over(t)
    np.testing.assert_allclose(f[:, 0], ref(t), atol=1e-9)
    np.testing.assert_allclose(df[:, 0], ref(t, 1), atol=1e-7 * np.max(np.abs(ref(t, 1))))
    np.testing.assert_allclose(ddf[:, 0], ref(t, 2), atol=1e-6 * np.max(np.abs(ref(t, 2))))


def test_columns_are_independent_and_both_evaluations_agree_bit_for_bit():
    rng = np.random.default_rng(3)
    x = _knots(rng, 50)
    Y = rng.normal(size=(50, 4))
    together = natural_spline_coefficients(x, Y, 5)
    for c in range(4):
        np.testing.assert_allclose(natural_spline_coefficients(x, Y[:, c], 5)[:, :, 0], together[:, :, c], rtol=1e-12,
                                   atol=1e-12 * np.max(np.abs(together[:, :, c])))
    s = SplineColumns(x, together)
    times = np.concatenate([x[:5], rng.uniform(x[0] - 0.5, x[-1] + 0.5, 40)])
    over = s.derivatives_over(times)
    rows = np.arange(4)
    for k, t in enumerate(times):
        f, df, ddf = np.empty(4), np.empty(4), np.empty(4)
        s.derivatives_into(t, rows, f, df, ddf)
        for a, b in zip((f, df, ddf), over):
            assert np.array_equal(a, b[k])


def test_the_derivatives_are_those_of_the_values():
    rng = np.random.default_rng(4)
    x = _knots(rng, 30)
    s = SplineThroughData(x, rng.normal(size=(30, 2)), natural=5)
    eps = 1e-5
    for t in rng.uniform(x[0] + 0.01, x[-1] - 0.01, 20):
        f, df, ddf = s.derivatives(t)
        fp, dfp, _ = s.derivatives(t + eps)
        fm, dfm, _ = s.derivatives(t - eps)
        np.testing.assert_allclose(df, (fp - fm) / (2 * eps), atol=1e-6 * (1 + np.max(np.abs(df))))
        np.testing.assert_allclose(ddf, (dfp - dfm) / (2 * eps), atol=1e-5 * (1 + np.max(np.abs(ddf))))
        assert np.max(np.abs(ddf)) > 0.0


def test_the_quintic_equals_opensims_gcvspline():
    osim = pytest.importorskip("opensim")
    rng = np.random.default_rng(5)
    x = np.arange(151) / 60.0  # a coordinate file's samples
    y = 0.6 + 0.05 * np.sin(4 * x) + 0.001 * rng.normal(size=151)
    gcv = osim.GCVSpline()
    gcv.setDegree(5)
    for a, b in zip(x, y):
        gcv.addPoint(float(a), float(b))
    s = SplineThroughData(x, y, natural=5)
    for t in np.concatenate([x[[0, 1, 75, -2, -1]], rng.uniform(x[0], x[-1], 30)]):
        v = osim.Vector(1, float(t))
        theirs = gcv.calcValue(v), gcv.calcDerivative([0], v), gcv.calcDerivative([0, 0], v)
        ours = [float(a[0]) for a in s.derivatives(t)]
        np.testing.assert_allclose(ours, theirs, rtol=1e-9, atol=1e-9 * 300.0)  # |f″| ≤ 300


def test_bad_spline_input_is_refused():
    with pytest.raises(ValueError, match="degree must be 1, 3 or 5"):
        natural_spline_coefficients(np.arange(10.0), np.arange(10.0), 7)
    with pytest.raises(ValueError, match="at least 6 knots"):
        natural_spline_coefficients(np.arange(5.0), np.arange(5.0), 5)
    with pytest.raises(ValueError, match="increase strictly"):
        natural_spline_coefficients(np.array([0, 1, 1, 2, 3, 4.0]), np.arange(6.0), 5)


# OpenSim's processing of a coordinate file ------------------------------------------------

def test_the_filter_is_the_third_order_butterworth():
    from scipy.signal import butter

    for fc, dt in ((6.0, 0.01), (6.0, 1 / 60), (15.0, 0.001), (40.0, 0.01)):
        b, a = iir3_coefficients(fc, dt)
        b_ref, a_ref = butter(3, fc, fs=1.0 / dt)
        np.testing.assert_allclose(b, b_ref, rtol=1e-12)
        np.testing.assert_allclose(a, a_ref, rtol=1e-12, atol=1e-14)


def test_the_filter_runs_the_recursion_forward_then_backward():
    rng = np.random.default_rng(6)
    x = rng.normal(size=(80, 2))
    b, a = iir3_coefficients(6.0, 0.01)

    def recursion(s):
        y = s.copy()  # the first three outputs are the inputs
        for i in range(3, len(s)):
            y[i] = b @ s[i - 3:i + 1][::-1] - a[1:] @ y[i - 3:i][::-1]
        return y

    expected = recursion(recursion(x)[::-1])[::-1]
    np.testing.assert_allclose(lowpass_iir3(x, 6.0, 0.01), expected, atol=1e-13)


def test_the_filter_keeps_a_constant_and_halves_a_sine_at_its_cutoff():
    dt, fc = 0.001, 10.0
    t = np.arange(4000) * dt
    np.testing.assert_allclose(lowpass_iir3(np.full(200, 3.7), fc, dt), 3.7, rtol=1e-10)
    out = lowpass_iir3(np.sin(2 * np.pi * fc * t), fc, dt)[:, 0]
    middle = slice(1000, 3000)
    # |H|² = 1/2 at the cut-off for one pass of a Butterworth; forward and backward: 1/2
    assert abs(np.max(np.abs(out[middle])) - 0.5) < 2e-3


def test_padding_reflects_about_the_end_samples():
    t = np.arange(10) * 0.1
    y = np.column_stack([2.0 + 3.0 * t, t ** 2])
    tp, yp = pad_odd(t, y, 4)
    np.testing.assert_allclose(np.diff(tp), 0.1, atol=1e-12)  # the time grid continues
    np.testing.assert_allclose(yp[:, 0], 2.0 + 3.0 * tp, atol=1e-12)  # a line stays the line
    np.testing.assert_allclose(yp[:4, 1], 2 * y[0, 1] - t[4:0:-1] ** 2)
    np.testing.assert_allclose(yp[-4:, 1], 2 * y[-1, 1] - t[-2:-6:-1] ** 2)
    with pytest.raises(ValueError, match="padding"):
        pad_odd(t, y, 10)


def test_a_kept_factorization_serves_only_its_own_knots():
    """The banded LU is kept per knots and degree: a second column set on the same knots
    is solved with it, and knots that differ in one value are factored anew."""
    from openfdk.numerics import natural_spline as ns

    rng = np.random.default_rng(8)
    x = np.cumsum(rng.uniform(0.5, 1.0, 40))
    Y1, Y2 = rng.normal(size=(40, 2)), rng.normal(size=(40, 3))
    ns._FACTORS.clear()
    a = natural_spline_coefficients(x, Y1, 5)
    b = natural_spline_coefficients(x, Y2, 5)
    assert len(ns._FACTORS) == 1
    x2 = x.copy()
    x2[20] += 0.1
    c = natural_spline_coefficients(x2, Y1, 5)
    assert len(ns._FACTORS) == 2
    for coef, knots, Y in ((a, x, Y1), (b, x, Y2), (c, x2, Y1)):  # each interpolates its own data
        h = np.diff(knots)
        np.testing.assert_allclose(coef[:, 0], Y[:-1], atol=1e-12)
        np.testing.assert_allclose(np.sum(coef * (h[:, None] ** np.arange(6))[:, :, None], axis=1), Y[1:], atol=1e-9)
    for k in range(6):
        natural_spline_coefficients(x + k, Y1, 3)
    assert len(ns._FACTORS) == ns._KEEP
