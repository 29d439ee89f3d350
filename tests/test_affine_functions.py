"""Which coordinate functions are one line (model.coordinate_joint.affine): a joint's
coordinate is measured from an axis it moves through an affine function, and OpenSim
models write such lines as splines too (jam-resources' full_body_healthy_knee.osim: the
left knee's rotation1 a SimmSpline through (−2π, 2π) and (2π, −2π))."""

import numpy as np
import pytest

from openfdk.model.coordinate_functions import function_from_spec
from openfdk.model.coordinate_joint import affine


def _fn(spec):
    def error(path, message):
        return ValueError(message)

    return function_from_spec(spec, "", error)


@pytest.mark.parametrize("kind", ["simm_spline", "natural_cubic_spline", "piecewise_linear"])
def test_a_spline_through_two_points_is_the_line_through_them(kind):
    f = _fn({"type": kind, "x": [-2 * np.pi, 2 * np.pi], "y": [2 * np.pi, -2 * np.pi]})
    slope, intercept = affine(f)
    assert slope == pytest.approx(-1.0, rel=1e-14) and intercept == pytest.approx(0.0, abs=1e-14)


@pytest.mark.parametrize("kind", ["simm_spline", "piecewise_linear", "gcv_spline"])
def test_a_spline_through_collinear_points_is_their_line_and_evaluates_on_it(kind):
    x = np.array([-1.0, -0.2, 0.3, 0.9, 1.7, 2.4])
    spec = {"type": kind, "x": x.tolist(), "y": (0.35 * x - 0.02).tolist()}
    if kind == "gcv_spline":
        spec["degree"] = 3
    f = _fn(spec)
    slope, intercept = affine(f)
    assert slope == pytest.approx(0.35, rel=1e-12) and intercept == pytest.approx(-0.02, rel=1e-10)
    # the line is the function, inside and outside the points (the extrapolation too)
    xs = np.linspace(-3.0, 4.0, 71)
    value, slope_x, curvature = f.evaluate(xs)
    assert np.allclose(value, 0.35 * xs - 0.02, rtol=0, atol=1e-13)
    assert np.allclose(slope_x, 0.35, rtol=0, atol=1e-12) and np.allclose(curvature, 0.0, atol=1e-10)


@pytest.mark.parametrize("y", [
    [0.0, 0.1, 0.2, 0.31],           # a kink of 0.01 at the last point
    [0.0, 0.1, 0.2, 0.3 + 1e-9],     # one part in 3e8: a curve, not a line
])
def test_a_spline_off_the_line_is_not_affine(y):
    f = _fn({"type": "simm_spline", "x": [0.0, 1.0, 2.0, 3.0], "y": y})
    assert affine(f) is None


def test_lines_and_polynomials_without_pieces():
    assert affine(_fn({"type": "linear", "slope": 2.0, "intercept": 0.5})) == (2.0, 0.5)
    assert affine(_fn({"type": "constant", "value": 0.3})) == (0.0, 0.3)
    assert affine(_fn({"type": "polynomial", "coefficients": [1.0, 0.0, 0.0]})) is None
