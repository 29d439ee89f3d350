"""openfdk.numerics.cubic_spline: the not-a-knot cubic spline, checked against closed forms (it
reproduces any cubic, and three points give their parabola), its defining invariants (C²
at every knot, C³ at the second and second-last knots, interpolation) and
scipy.interpolate.CubicSpline (an independent implementation, LAPACK's banded solver)."""

import numpy as np
import pytest
from scipy.interpolate import CubicSpline

from openfdk.numerics.cubic_spline import NotAKnotSpline, not_a_knot_coefficients
from openfdk.model.timefunctions import SplineThroughData


def _knots(n, kind, rng):
    if kind == "uniform":
        return 0.25 + 0.01 * np.arange(n)
    if kind == "random":
        return np.cumsum(rng.uniform(0.05, 1.0, n))
    return np.cumsum(np.where(np.arange(n) % 2, 100.0, 1.0))       # steps 1 and 100 alternating


def _piece_values(coef, x, t):
    """Value and first three derivatives at t from the piece starting at the knot
    left of t (index clipped to the pieces)."""
    i = min(max(np.searchsorted(x, t, side="right") - 1, 0), len(x) - 2)
    tau = t - x[i]
    c0, c1, c2, c3 = coef[i]
    return (c0 + tau * (c1 + tau * (c2 + tau * c3)), c1 + tau * (2 * c2 + 3 * tau * c3),
            2 * c2 + 6 * tau * c3, 6 * c3)


@pytest.mark.parametrize("kind", ["uniform", "random", "stretched"])
@pytest.mark.parametrize("n", [4, 5, 7, 30])
def test_reproduces_a_cubic_exactly(n, kind):
    """A not-a-knot spline through samples of a cubic is that cubic (the cubic satisfies
    every row of the system, which has one solution)."""
    rng = np.random.default_rng(n)
    x = _knots(n, kind, rng)
    a = rng.normal(size=(4, 2))
    x0 = x.mean()
    y = sum(a[j] * (x[:, None] - x0) ** j for j in range(4))
    coef = not_a_knot_coefficients(x, y)
    scale = np.abs(y).max()
    for t in np.linspace(x[0], x[-1], 37):
        f, df, ddf, dddf = _piece_values(coef, x, t)
        u = t - x0
        assert np.allclose(f, a[0] + a[1] * u + a[2] * u ** 2 + a[3] * u ** 3, atol=1e-10 * scale)
        assert np.allclose(df, a[1] + 2 * a[2] * u + 3 * a[3] * u ** 2, atol=1e-9 * scale)
        assert np.allclose(ddf, 2 * a[2] + 6 * a[3] * u, atol=1e-8 * scale)
        assert np.allclose(dddf, 6 * a[3], atol=1e-7 * scale)


def test_three_points_give_their_parabola_and_two_a_line():
    x = np.array([0.0, 0.3, 1.1])
    y = np.array([1.0, -2.0, 0.5])
    # parabola through the three points (Lagrange form), its slope and curvature
    A = np.vstack([np.ones(3), x, x ** 2]).T
    p0, p1, p2 = np.linalg.solve(A, y)
    spline = NotAKnotSpline(x, y)
    for t in (0.0, 0.1, 0.3, 0.7, 1.1, 1.5):
        f, df, ddf = spline.derivatives(t)
        assert f[0] == pytest.approx(p0 + p1 * t + p2 * t * t, abs=1e-12)
        assert df[0] == pytest.approx(p1 + 2 * p2 * t, abs=1e-12)
        assert ddf[0] == pytest.approx(2 * p2, abs=1e-12)
    f, df, ddf = NotAKnotSpline([2.0, 4.0], [[1.0, 5.0], [2.0, 1.0]]).derivatives(3.5)
    assert np.allclose(f, [1.75, 2.0]) and np.allclose(df, [0.5, -2.0]) and np.allclose(ddf, 0.0)


@pytest.mark.parametrize("kind", ["uniform", "random", "stretched"])
@pytest.mark.parametrize("n", [5, 12, 200])
def test_interpolates_is_C2_and_not_a_knot(n, kind):
    rng = np.random.default_rng(100 + n)
    x = _knots(n, kind, rng)
    y = rng.normal(size=(n, 3))
    coef = not_a_knot_coefficients(x, y)
    h = np.diff(x)[:, None, None]
    powers = h ** np.arange(4)[None, :, None]
    end = (coef * powers).sum(axis=1)                                 # p_i(h_i)
    d_end = (coef[:, 1:] * np.arange(1, 4)[None, :, None] * powers[:, :3]).sum(axis=1)
    dd_end = 2 * coef[:, 2] + 6 * coef[:, 3] * h[:, 0]
    assert np.allclose(coef[:, 0], y[:-1], atol=1e-14) and np.allclose(end, y[1:], atol=1e-10)
    assert np.allclose(d_end[:-1], coef[1:, 1], rtol=1e-9, atol=1e-9)       # C¹
    assert np.allclose(dd_end[:-1], 2 * coef[1:, 2], rtol=1e-8, atol=1e-8)  # C²
    # not-a-knot: the third derivative does not jump at x_1 and x_{n−2}
    assert np.allclose(coef[0, 3], coef[1, 3], rtol=1e-8, atol=1e-8 * np.abs(coef[:, 3]).max())
    assert np.allclose(coef[-1, 3], coef[-2, 3], rtol=1e-8, atol=1e-8 * np.abs(coef[:, 3]).max())
    # and it does jump at the other knots (random data): the conditions are not vacuous
    assert np.abs(coef[2, 3] - coef[1, 3]).max() > 1e-6 * np.abs(coef[:, 3]).max()


@pytest.mark.parametrize("kind", ["uniform", "random", "stretched"])
@pytest.mark.parametrize("n", [2, 3, 4, 5, 9, 101])
def test_same_as_scipy_cubicspline(n, kind):
    rng = np.random.default_rng(7 * n)
    x = _knots(n, kind, rng)
    y = rng.normal(size=(n, 3))
    ref = CubicSpline(x, y, axis=0, bc_type="not-a-knot")
    coef = not_a_knot_coefficients(x, y)
    assert np.allclose(coef, np.transpose(ref.c[::-1], (1, 0, 2)), rtol=1e-11, atol=1e-11 * np.abs(ref.c).max())
    ours = NotAKnotSpline(x, y)
    for t in np.concatenate([x, np.linspace(x[0] - 0.5, x[-1] + 0.5, 23)]):   # knots and extrapolation
        for got, order in zip(ours.derivatives(t), range(3)):
            want = ref(t, order)
            assert np.allclose(got, want, rtol=1e-10, atol=1e-10 * np.abs(want).max(initial=1.0))
    one = not_a_knot_coefficients(x, y[:, 0])                             # 1-D values: one column
    assert one.shape == (n - 1, 4, 1) and np.allclose(one[:, :, 0], coef[:, :, 0])


def test_derivatives_match_finite_differences():
    rng = np.random.default_rng(3)
    x = np.cumsum(rng.uniform(0.1, 0.5, 9))
    spline = NotAKnotSpline(x, rng.normal(size=(9, 2)))
    t, e = 0.37 * x[0] + 0.63 * x[-1], 1e-6
    f_plus, df_plus, _ = spline.derivatives(t + e)
    f_minus, df_minus, _ = spline.derivatives(t - e)
    _, df, ddf = spline.derivatives(t)
    assert np.all(np.abs(df) > 1e-3) and np.all(np.abs(ddf) > 1e-3)
    assert np.allclose((f_plus - f_minus) / (2 * e), df, atol=1e-7)
    assert np.allclose((df_plus - df_minus) / (2 * e), ddf, atol=1e-6)


def test_spline_driver_uses_it():
    x = np.array([0.0, 0.1, 0.25, 0.4, 0.6])
    y = np.sin(3 * x)
    drv = SplineThroughData(x, y)
    ref = CubicSpline(x, y)
    assert np.allclose(drv.derivatives(0.33)[1], ref(0.33, 1), atol=1e-12)
    with pytest.raises(ValueError, match="outside its data"):
        drv.derivatives(0.7)


@pytest.mark.parametrize("x, y, message", [
    ([0.0], [1.0], "at least 2 knots"),
    ([0.0, 1.0, 1.0], [1.0, 2.0, 3.0], "increase strictly"),
    ([0.0, 2.0, 1.0], [1.0, 2.0, 3.0], "increase strictly"),
    ([0.0, 1.0], [1.0, 2.0, 3.0], "2 knots but values"),
    ([0.0, 1.0], 2.0, "2 knots but values of shape"),
    ([0.0, 1.0], np.zeros((2, 3, 1)), "2 knots but values of shape"),
])
def test_bad_knots_are_refused(x, y, message):
    with pytest.raises(ValueError, match=message):
        not_a_knot_coefficients(x, y)
