"""OpenSim coordinate functions (openfdk.model.coordinate_functions and
openfdk.io.opensim.functions) against OpenSim 4.6 itself.

Each function is built in OpenSim (its Python API, or an XML file OpenSim reads), written
by OpenSim (``printToXML``), read back through ``function_element``/``function_spec`` +
``function_from_spec``, and both are evaluated at ≥ 300 points inside the knots, beyond
both ends and at the knots. Tolerances: value 1e-12, derivatives 1e-9, relative to
max(|OpenSim's value|, the largest |value| inside the knot range) — the floor keeps a
zero crossing from turning round-off into a huge relative error.
"""

import subprocess
import sys
from fractions import Fraction
from math import factorial, pi

import numpy as np
import pytest
from lxml import etree
from numba import njit

from openfdk.io.opensim.errors import OsimError
from openfdk.io.opensim.functions import function_element, function_spec
from openfdk.model.coordinate_functions import (
    FUNCTION_TYPES, PiecewisePolynomial, function_from_spec, polynomial, pp_evaluate,
    pp_params_size, simm_spline,
)
from openfdk.model.errors import ModelError

RTOL_VALUE = 1e-12
RTOL_DERIV = 1e-9


def spec_error(path, message):
    return ModelError(f"model.yaml: {path}: {message}")


def build(spec, path="joints.knee.function"):
    return function_from_spec(spec, path, spec_error)


# --------------------------------------------------------------------------------------
# OpenSim helpers
# --------------------------------------------------------------------------------------

_KEEP = []          # OpenSim objects made from files stay alive for the whole session


def _osim():
    return pytest.importorskip("opensim")


def _numbers(values):
    return " ".join(repr(float(v)) for v in values)


def _opensim_from_xml(tmp_path, body, version="40000", name="f.xml"):
    """The OpenSim Function OpenSim reads from ``<OpenSimDocument>body</…>``."""
    osim = _osim()
    path = tmp_path / name
    path.write_text(f'<?xml version="1.0" encoding="UTF-8" ?>\n'
                    f'<OpenSimDocument Version="{version}">\n{body}\n</OpenSimDocument>\n')
    obj = osim.OpenSimObject.makeObjectFromFile(str(path))
    _KEEP.append(obj)
    f = osim.Function.safeDownCast(obj)
    assert f is not None, body
    return f


def _ours_from_file(path):
    root = etree.parse(str(path)).getroot()
    element = [c for c in root if isinstance(c.tag, str)][0]
    return function_from_spec(function_spec(element, path.name), "f", spec_error), element


def _roundtrip(f, tmp_path, name="printed.xml"):
    """OpenSim writes ``f``; openfdk and OpenSim read what it wrote: (ours, the function
    element, OpenSim's function). OpenSim writes the number lists of SimmSpline,
    GCVSpline, PiecewiseLinearFunction and LinearFunction with 6 significant digits, so
    the tests draw their data with 6 digits (``_r6``) where they compare with ``f``."""
    path = tmp_path / name
    assert f.printToXML(str(path))
    ours, element = _ours_from_file(path)
    osim = _osim()
    obj = osim.OpenSimObject.makeObjectFromFile(str(path))
    _KEEP.append(obj)
    return ours, element, osim.Function.safeDownCast(obj)


def _r6(values):
    """``values`` rounded to the 6 significant digits OpenSim writes number lists with."""
    return np.array([float(f"{v:.6g}") for v in np.ravel(values)])


def _opensim_eval(f, xs):
    osim = _osim()
    # plain lists: SWIG converts them to std::vector<int> (osim.StdVectorInt is the class of
    # whichever of OpenSim's modules was imported last, which another test may change)
    one, two = [0], [0, 0]
    out = np.empty((3, len(xs)))
    for k, x in enumerate(xs):
        v = osim.Vector(1, float(x))
        out[:, k] = f.calcValue(v), f.calcDerivative(one, v), f.calcDerivative(two, v)
    return out


def _sample(lo, hi, rng, n_inside=200, n_out=50, knots=()):
    span = hi - lo
    return np.concatenate([rng.uniform(lo, hi, n_inside),
                           rng.uniform(lo - span, lo, n_out),
                           rng.uniform(hi, hi + span, n_out),
                           np.asarray(knots, dtype=float)])


def _assert_matches(ours, theirs, xs, lo, hi, what):
    ref = _opensim_eval(theirs, xs)
    got = np.array(ours.evaluate(xs))
    inside = (xs >= lo) & (xs <= hi)
    for row, rtol, name in ((0, RTOL_VALUE, "f"), (1, RTOL_DERIV, "f'"), (2, RTOL_DERIV, "f''")):
        floor = np.max(np.abs(ref[row][inside])) if inside.any() else 0.0
        scale = np.maximum(np.abs(ref[row]), max(floor, 1e-300))
        err = np.abs(got[row] - ref[row]) / scale
        worst = int(np.argmax(err))
        assert err[worst] <= rtol, (f"{what}: {name} at x = {xs[worst]!r}: openfdk {got[row][worst]!r}, "
                                    f"OpenSim {ref[row][worst]!r} (relative error {err[worst]:.2e})")


def _knots(rng, n, lo=-1.5):
    """n strictly increasing knots with steps between 0.2 and 1.2 (uneven), 6 digits."""
    return _r6(lo + np.concatenate([[0.0], np.cumsum(rng.uniform(0.2, 1.2, n - 1))]))


# --------------------------------------------------------------------------------------
# against OpenSim, function by function
# --------------------------------------------------------------------------------------

def test_constant_linear_polynomial_match_opensim(tmp_path):
    osim = _osim()
    rng = np.random.default_rng(1)
    xs = _sample(-2.0, 2.0, rng)
    cases = [("constant", osim.Constant(0.7318)), ("linear", osim.LinearFunction(-1.25, 0.031))]
    for k in range(1, 7):                                      # degree 0 … 5
        cases.append((f"polynomial{k}", osim.PolynomialFunction(osim.Vector(list(rng.normal(size=k))))))
    for name, f in cases:
        ours, element, reread = _roundtrip(f, tmp_path, f"{name}.xml")
        assert ours.n_pieces == 0
        _assert_matches(ours, f, xs, -2.0, 2.0, name)
        _assert_matches(ours, reread, xs, -2.0, 2.0, name)
    # the XML order of PolynomialFunction is highest power first
    spec = function_spec(etree.fromstring("<PolynomialFunction><coefficients>1 2 3</coefficients>"
                                          "</PolynomialFunction>"), "p.xml")
    assert spec == {"type": "polynomial", "coefficients": [1.0, 2.0, 3.0]}
    assert build(spec).evaluate(2.0) == (11.0, 6.0, 2.0)


@pytest.mark.parametrize("n", [2, 3, 4, 5, 9, 17])
def test_simm_spline_matches_opensim(tmp_path, n):
    osim = _osim()
    rng = np.random.default_rng(10 + n)
    x, y = _knots(rng, n), _r6(rng.normal(size=n))
    f = osim.SimmSpline()
    for a, b in zip(x, y):
        f.addPoint(float(a), float(b))
    ours, element, reread = _roundtrip(f, tmp_path)
    assert element.tag == "SimmSpline" and function_spec(element, "f.xml")["type"] == "simm_spline"
    xs = _sample(x[0], x[-1], rng, knots=x)
    _assert_matches(ours, f, xs, x[0], x[-1], f"SimmSpline n={n}")
    _assert_matches(ours, reread, xs, x[0], x[-1], f"SimmSpline n={n} as read by OpenSim")
    if n >= 3:                                   # beyond the ends: the tangent, f'' = 0
        _, df, d2f = ours.evaluate(np.array([x[0] - 1.0, x[-1] + 1.0]))
        assert np.all(d2f == 0.0) and np.all(df != 0.0)


def test_simm_spline_tiny_step_as_opensim(tmp_path):
    """Steps below 1e-7 are replaced by 1e-7 in OpenSim's coefficients (TINY_NUMBER)."""
    x = [0.0, 1.0, 1.0 + 4e-8, 2.0, 3.5]
    y = [0.0, 0.4, 0.41, -0.2, 1.0]
    f = _opensim_from_xml(tmp_path, f"<SimmSpline><x>{_numbers(x)}</x><y>{_numbers(y)}</y></SimmSpline>",
                          name="tiny.xml")
    ours, _ = _ours_from_file(tmp_path / "tiny.xml")
    rng = np.random.default_rng(3)
    xs = np.concatenate([_sample(0.0, 3.5, rng), rng.uniform(1.0, 1.0 + 4e-8, 20)])
    _assert_matches(ours, f, xs, 0.0, 3.5, "SimmSpline with a 4e-8 step")


def test_natural_cubic_spline_is_read_as_simm_spline(tmp_path):
    """OpenSim renames NaturalCubicSpline (and natCubicSpline) to SimmSpline on reading."""
    rng = np.random.default_rng(4)
    x, y = _knots(rng, 8), rng.normal(size=8)
    for tag, version in (("NaturalCubicSpline", "30000"), ("natCubicSpline", "20302"),
                         ("NaturalCubicSpline", "40000")):
        body = f'<{tag} name="f1"><x>{_numbers(x)}</x><y>{_numbers(y)}</y></{tag}>'
        theirs = _opensim_from_xml(tmp_path, body, version, f"{tag}.xml")
        assert theirs.getConcreteClassName() == "SimmSpline"
        ours, element = _ours_from_file(tmp_path / f"{tag}.xml")
        assert function_spec(element, "f.xml")["type"] == "natural_cubic_spline"
        _assert_matches(ours, theirs, _sample(x[0], x[-1], rng, knots=x), x[0], x[-1], tag)
    a = build({"type": "natural_cubic_spline", "x": list(x), "y": list(y)})
    b = build({"type": "simm_spline", "x": list(x), "y": list(y)})
    assert np.array_equal(a.to_params(), b.to_params())


@pytest.mark.parametrize("half_order,n", [(1, 2), (1, 7), (2, 4), (2, 9), (3, 6), (3, 11)])
def test_gcv_spline_matches_opensim(tmp_path, half_order, n):
    """GCVSpline (error variance 0) is the interpolating natural spline of degree 2m − 1,
    continued outside the knots by a polynomial of degree m − 1."""
    rng = np.random.default_rng(100 * half_order + n)
    x, y = _knots(rng, n), _r6(rng.normal(size=n))
    body = (f'<GCVSpline name="g"><half_order>{half_order}</half_order>'
            f'<x>{_numbers(x)}</x><y>{_numbers(y)}</y></GCVSpline>')
    theirs = _opensim_from_xml(tmp_path, body, name="gcv.xml")
    ours, element, reread = _roundtrip(theirs, tmp_path)    # as OpenSim writes it
    assert function_spec(element, "f.xml")["degree"] == 2 * half_order - 1
    xs = _sample(x[0], x[-1], rng, knots=x)
    _assert_matches(ours, theirs, xs, x[0], x[-1], f"GCVSpline half_order={half_order} n={n}")
    _assert_matches(ours, reread, xs, x[0], x[-1], f"GCVSpline half_order={half_order} n={n} re-read")
    # beyond the ends: a polynomial of degree m − 1 (its derivative m vanishes)
    outside = np.array([x[0] - 0.7, x[-1] + 0.9])
    f, df, d2f = ours.evaluate(outside)
    if half_order == 1:
        assert np.all(df == 0.0) and np.array_equal(f, [y[0], y[-1]])
    elif half_order == 2:
        assert np.all(d2f == 0.0) and np.all(df != 0.0)
    else:
        assert np.all(d2f != 0.0)


def test_gcv_spline_with_weights_and_coefficients_as_opensim(tmp_path):
    """OpenSim 4 refits a GCVSpline with unit weights: the file's weights and coefficients
    do not change it."""
    rng = np.random.default_rng(7)
    x, y = _knots(rng, 8), rng.normal(size=8)
    body = (f'<GCVSpline name="g"><half_order>2</half_order><error_variance>0</error_variance>'
            f'<x>{_numbers(x)}</x><y>{_numbers(y)}</y><weights>{_numbers(rng.uniform(0.5, 2, 8))}</weights>'
            f'<coefficients>{_numbers(rng.normal(size=8))}</coefficients></GCVSpline>')
    theirs = _opensim_from_xml(tmp_path, body, name="gcvw.xml")
    ours, _ = _ours_from_file(tmp_path / "gcvw.xml")
    _assert_matches(ours, theirs, _sample(x[0], x[-1], rng, knots=x), x[0], x[-1], "GCVSpline weights")


@pytest.mark.parametrize("n", [2, 3, 8])
def test_piecewise_linear_matches_opensim(tmp_path, n):
    osim = _osim()
    rng = np.random.default_rng(20 + n)
    x, y = _knots(rng, n), _r6(rng.normal(size=n))
    f = osim.PiecewiseLinearFunction()
    for a, b in zip(x, y):
        f.addPoint(float(a), float(b))
    ours, _, reread = _roundtrip(f, tmp_path)
    # the knots are sampled too: f' jumps there and the piece follows OpenSim's search
    xs = _sample(x[0], x[-1], rng, knots=x)
    _assert_matches(ours, f, xs, x[0], x[-1], f"PiecewiseLinearFunction n={n}")
    _assert_matches(ours, reread, xs, x[0], x[-1], f"PiecewiseLinearFunction n={n} re-read")


def test_multiplier_function_matches_opensim(tmp_path):
    rng = np.random.default_rng(8)
    x, y = _knots(rng, 6), _r6(rng.normal(size=6))
    inner = {
        "simm": f"<SimmSpline name='s'><x>{_numbers(x)}</x><y>{_numbers(y)}</y></SimmSpline>",
        "linear": "<LinearFunction><coefficients>0.5 -0.25</coefficients></LinearFunction>",
        "gcv": f"<GCVSpline><half_order>3</half_order><x>{_numbers(x)}</x><y>{_numbers(y)}</y></GCVSpline>",
        "nested": ("<MultiplierFunction><function><SimmSpline><x>" + _numbers(x) + "</x><y>"
                   + _numbers(y) + "</y></SimmSpline></function><scale>-2.5</scale></MultiplierFunction>"),
    }
    for name, body in inner.items():
        theirs = _opensim_from_xml(tmp_path, f"<MultiplierFunction name='m'><function>{body}</function>"
                                             f"<scale>0.3</scale></MultiplierFunction>", name=f"m_{name}.xml")
        ours, element, reread = _roundtrip(theirs, tmp_path, f"m_{name}_printed.xml")
        assert function_spec(element, "f.xml")["scale"] == 0.3
        xs = _sample(x[0], x[-1], rng, knots=x)
        _assert_matches(ours, theirs, xs, x[0], x[-1], f"MultiplierFunction {name}")
        _assert_matches(ours, reread, xs, x[0], x[-1], f"MultiplierFunction {name} re-read")
    # scale left out: OpenSim's default 1
    theirs = _opensim_from_xml(tmp_path, f"<MultiplierFunction><function>{inner['simm']}</function>"
                                         "</MultiplierFunction>", name="m_default.xml")
    ours, _ = _ours_from_file(tmp_path / "m_default.xml")
    _assert_matches(ours, theirs, _sample(x[0], x[-1], rng), x[0], x[-1], "MultiplierFunction default scale")


_MODEL = """<?xml version="1.0" encoding="UTF-8" ?>
<OpenSimDocument Version="40000">
  <Model name="fm">
    <BodySet name="bodyset"><objects>
      <Body name="b"><mass>1</mass><mass_center>0 0 0</mass_center><inertia>1 1 1 0 0 0</inertia></Body>
      <Body name="b2"><mass>1</mass><mass_center>0 0 0</mass_center><inertia>1 1 1 0 0 0</inertia></Body>
    </objects></BodySet>
    <JointSet name="jointset"><objects>
      <CustomJoint name="j">
        <socket_parent_frame>ground_offset</socket_parent_frame>
        <socket_child_frame>b_offset</socket_child_frame>
        <coordinates><Coordinate name="q"><default_value>0</default_value></Coordinate></coordinates>
        <frames>
          <PhysicalOffsetFrame name="ground_offset"><socket_parent>/ground</socket_parent></PhysicalOffsetFrame>
          <PhysicalOffsetFrame name="b_offset"><socket_parent>/bodyset/b</socket_parent></PhysicalOffsetFrame>
        </frames>
        <SpatialTransform>
          <TransformAxis name="rotation1"><coordinates>q</coordinates><axis>0 0 1</axis>
            <function><LinearFunction><coefficients>1 0</coefficients></LinearFunction></function></TransformAxis>
          <TransformAxis name="rotation2"><coordinates>q</coordinates><axis>1 0 0</axis>
            <SimmSpline><x>-2 -1 0 1 2</x><y>0.1 0.3 0 -0.2 0.05</y></SimmSpline></TransformAxis>
          <TransformAxis name="rotation3"><coordinates></coordinates><axis>0 1 0</axis></TransformAxis>
          <TransformAxis name="translation1"><coordinates>q</coordinates><axis>1 0 0</axis>
            <function><MultiplierFunction name="m"><function><SimmSpline name="s">
              <x>-2 -0.5 0.4 2</x><y>0.01 0.02 -0.01 0.03</y></SimmSpline></function>
              <scale>0.5</scale></MultiplierFunction></function></TransformAxis>
          <TransformAxis name="translation2"><coordinates>q</coordinates><axis>0 1 0</axis>
            <GCVSpline name="function"><half_order>3</half_order><x>-2 -1 -0.2 0.5 1 2</x>
              <y>0 0.01 0.03 0.02 -0.01 0</y></GCVSpline></TransformAxis>
          <TransformAxis name="translation3"><coordinates></coordinates><axis>0 0 1</axis>
            <function><Constant><value>0.25</value></Constant></function></TransformAxis>
        </SpatialTransform>
      </CustomJoint>
      <PinJoint name="j2">
        <socket_parent_frame>b_offset</socket_parent_frame>
        <socket_child_frame>b2_offset</socket_child_frame>
        <coordinates><Coordinate name="p"><default_value>0</default_value></Coordinate></coordinates>
        <frames>
          <PhysicalOffsetFrame name="b_offset"><socket_parent>/bodyset/b</socket_parent></PhysicalOffsetFrame>
          <PhysicalOffsetFrame name="b2_offset"><socket_parent>/bodyset/b2</socket_parent></PhysicalOffsetFrame>
        </frames>
      </PinJoint>
    </objects></JointSet>
    <ConstraintSet name="constraintset"><objects>
      <CoordinateCouplerConstraint name="cc">
        <coupled_coordinates_function>
          <PiecewiseLinearFunction><x>-1 0 1</x><y>0 0.5 2</y></PiecewiseLinearFunction>
        </coupled_coordinates_function>
        <independent_coordinate_names>q</independent_coordinate_names>
        <dependent_coordinate_name>p</dependent_coordinate_name>
      </CoordinateCouplerConstraint>
    </objects></ConstraintSet>
  </Model>
</OpenSimDocument>
"""


def test_model_functions_as_opensim_writes_them(tmp_path):
    """A CustomJoint and a CoordinateCouplerConstraint: OpenSim reads the model, writes it
    (TransformAxis functions as ``<Type name="function">``, the coupler's wrapped), and
    every function openfdk finds in either file evaluates as OpenSim's."""
    osim = _osim()
    source = tmp_path / "fm.osim"
    source.write_text(_MODEL)
    model = osim.Model(str(source))
    model.initSystem()
    printed = tmp_path / "fm_printed.osim"
    model.printToXML(str(printed))
    joint = osim.CustomJoint.safeDownCast(model.getJointSet().get("j"))
    axes = {joint.getSpatialTransform().getTransformAxis(k).getName():
            joint.getSpatialTransform().getTransformAxis(k).getFunction() for k in range(6)}
    coupler = osim.CoordinateCouplerConstraint.safeDownCast(model.getConstraintSet().get("cc"))
    rng = np.random.default_rng(9)
    xs = _sample(-2.0, 2.0, rng)
    for path in (source, printed):
        tree = etree.parse(str(path))
        for axis in tree.iter("TransformAxis"):
            element = function_element(axis, path.name)
            name = axis.get("name")
            if element is None:                    # OpenSim's default: Constant(0)
                assert name == "rotation3" and axes[name].calcValue(osim.Vector(1, 0.3)) == 0.0
                continue
            if path is printed and name in ("rotation1", "translation1"):
                assert element.get("name") == "function" and element.getparent() is axis
            ours = function_from_spec(function_spec(element, path.name), name, spec_error)
            _assert_matches(ours, axes[name], xs, -2.0, 2.0, f"{path.name} {name}")
        (cc,) = tree.iter("CoordinateCouplerConstraint")
        element = function_element(cc, path.name)
        assert element.tag == "PiecewiseLinearFunction"
        ours = function_from_spec(function_spec(element, path.name), "cc", spec_error)
        _assert_matches(ours, coupler.getFunction(), np.concatenate([xs, [-1.0, 0.0, 1.0]]), -1.0, 1.0,
                        f"{path.name} coupler")


# --------------------------------------------------------------------------------------
# without OpenSim
# --------------------------------------------------------------------------------------

def _fd_check(pp, xs, what):
    """Central differences of f and f′ against f′ and f″ at points away from the knots."""
    h = 1e-6
    f, df, d2f = pp.evaluate(xs)
    fp, dfp, _ = pp.evaluate(xs + h)
    fm, dfm, _ = pp.evaluate(xs - h)
    scale1 = max(np.max(np.abs(df)), 1e-12)
    scale2 = max(np.max(np.abs(d2f)), 1e-12)
    assert np.max(np.abs((fp - fm) / (2 * h) - df)) <= 1e-6 * scale1 + 1e-9, what
    assert np.max(np.abs((dfp - dfm) / (2 * h) - d2f)) <= 1e-5 * scale2 + 1e-7, what
    return df, d2f


def test_derivatives_by_finite_differences():
    rng = np.random.default_rng(11)
    x, y = _knots(rng, 9), rng.normal(size=9)
    cases = {
        "constant": ({"type": "constant", "value": 2.0}, 0, 0),
        "linear": ({"type": "linear", "slope": 0.4, "intercept": 1.0}, 1, 0),
        "polynomial": ({"type": "polynomial", "coefficients": [0.1, -0.3, 0.2, 1.0, -1.0, 0.5]}, 1, 1),
        "simm_spline": ({"type": "simm_spline", "x": list(x), "y": list(y)}, 1, 1),
        "natural_cubic_spline": ({"type": "natural_cubic_spline", "x": list(x), "y": list(y)}, 1, 1),
        "gcv_spline 1": ({"type": "gcv_spline", "x": list(x), "y": list(y), "degree": 1}, 1, 0),
        "gcv_spline 3": ({"type": "gcv_spline", "x": list(x), "y": list(y), "degree": 3}, 1, 1),
        "gcv_spline 5": ({"type": "gcv_spline", "x": list(x), "y": list(y), "degree": 5}, 1, 1),
        "piecewise_linear": ({"type": "piecewise_linear", "x": list(x), "y": list(y)}, 1, 0),
        "multiplier": ({"type": "multiplier", "scale": -0.7,
                        "function": {"type": "simm_spline", "x": list(x), "y": list(y)}}, 1, 1),
    }
    assert {spec["type"] for spec, _, _ in cases.values()} == set(FUNCTION_TYPES)
    # inside the pieces, away from the knots, and beyond both ends
    mids = 0.5 * (x[:-1] + x[1:])
    xs = np.concatenate([mids, mids + 0.1 * np.diff(x), [x[0] - 0.8, x[-1] + 0.8]])
    for name, (spec, curved1, curved2) in cases.items():
        df, d2f = _fd_check(build(spec), xs, name)
        assert bool(np.any(df != 0.0)) == bool(curved1), name
        assert bool(np.any(d2f != 0.0)) == bool(curved2), name


def _natural_spline_exact(x, y, m):
    """Power coefficients (in x − x_i) of the interpolating natural spline of degree 2m − 1,
    solved in exact rationals from the defining conditions (values at both ends of each
    piece, C^(2m−2) at interior knots, derivatives m … 2m−2 zero at the end knots)."""
    x = [Fraction(v) for v in x]
    y = [Fraction(v) for v in y]
    n, size = len(x), 2 * m
    unknowns = size * (n - 1)

    def row(piece, j, t):
        r = [Fraction(0)] * unknowns
        for k in range(j, size):
            r[piece * size + k] = Fraction(factorial(k), factorial(k - j)) * t ** (k - j)
        return r

    rows, rhs = [], []
    for i in range(n - 1):
        rows += [row(i, 0, Fraction(0)), row(i, 0, x[i + 1] - x[i])]
        rhs += [y[i], y[i + 1]]
    for i in range(1, n - 1):
        for j in range(1, size - 1):
            a, b = row(i - 1, j, x[i] - x[i - 1]), row(i, j, Fraction(0))
            rows.append([p - q for p, q in zip(a, b)])
            rhs.append(Fraction(0))
    for j in range(m, size - 1):
        rows += [row(0, j, Fraction(0)), row(n - 2, j, x[n - 1] - x[n - 2])]
        rhs += [Fraction(0), Fraction(0)]
    aug = [r + [v] for r, v in zip(rows, rhs)]
    for c in range(unknowns):                      # Gauss–Jordan, exact
        piv = next(r for r in range(c, unknowns) if aug[r][c] != 0)
        aug[c], aug[piv] = aug[piv], aug[c]
        aug[c] = [v / aug[c][c] for v in aug[c]]
        for r in range(unknowns):
            if r != c and aug[r][c] != 0:
                f = aug[r][c]
                aug[r] = [a - f * b for a, b in zip(aug[r], aug[c])]
    return np.array([[float(aug[i * size + k][-1]) for k in range(size)] for i in range(n - 1)])


@pytest.mark.parametrize("degree", [3, 5])
def test_natural_spline_against_exact_arithmetic(degree):
    """The GCVSpline model is the natural spline to round-off, also with a step 130 times
    shorter than its neighbour."""
    x = [0.0, 0.9, 1.0, 2.3, 2.31, 3.5, 5.0]
    y = [0.3, -1.0, 0.2, 0.8, 0.75, -0.4, 0.1]
    m = (degree + 1) // 2
    exact = _natural_spline_exact(x, y, m)
    pp = build({"type": "gcv_spline", "x": x, "y": y, "degree": degree})
    for i in range(len(x) - 1):
        scale = np.max(np.abs(exact[i]) * (x[i + 1] - x[i]) ** np.arange(2 * m))
        assert np.allclose(pp.coeffs[i, :2 * m], exact[i], rtol=0,
                           atol=1e-14 * scale / (x[i + 1] - x[i]) ** np.arange(2 * m)), i
    assert np.all(pp.coeffs[:, 2 * m:] == 0.0)
    assert np.allclose(pp.left[:m], exact[0, :m], rtol=1e-14) and np.all(pp.left[m:] == 0.0)


def test_scaled_by_hand():
    """A spline in degrees → millimetres becomes one in radians → metres."""
    x = [-30.0, 0.0, 20.0, 45.0, 90.0]              # degrees
    y = [1.5, 0.0, -2.0, 3.0, 10.0]                 # mm
    f = build({"type": "simm_spline", "x": x, "y": y})
    sx, sy = pi / 180.0, 1e-3
    g = f.scaled(sx, sy)
    assert np.allclose(g.breaks, np.radians(x), rtol=0, atol=1e-15)
    for q_deg in (-50.0, -30.0, -12.5, 0.0, 7.0, 33.3, 90.0, 120.0):
        q = q_deg * pi / 180.0
        f0, f1, f2 = f.evaluate(q_deg)
        g0, g1, g2 = g.evaluate(q)
        assert g0 == pytest.approx(1e-3 * f0, rel=1e-13, abs=1e-18)
        assert g1 == pytest.approx(1e-3 * f1 * 180.0 / pi, rel=1e-12, abs=1e-18)
        assert g2 == pytest.approx(1e-3 * f2 * (180.0 / pi) ** 2, rel=1e-12, abs=1e-18)
    # a polynomial by hand: f(u) = 2u² − u + 3, g(x) = 5 f(x/2) = 2.5 x² − 2.5 x + 15
    p = polynomial([2.0, -1.0, 3.0]).scaled(2.0, 5.0)
    assert p.evaluate(1.2) == pytest.approx((2.5 * 1.44 - 3.0 + 15.0, 5.0 * 1.2 - 2.5, 5.0), rel=1e-14)
    # the knot rule and the extrapolation travel with it
    gcv = build({"type": "gcv_spline", "x": x, "y": y, "degree": 1}).scaled(sx, sy)
    assert gcv.right_continuous
    assert gcv.evaluate(np.radians(150.0))[:2] == (1e-3 * 10.0, 0.0)
    with pytest.raises(ValueError, match="sx > 0"):
        f.scaled(-1.0, 1.0)


def test_params_layout_and_compiled_use():
    f = build({"type": "simm_spline", "x": [0.0, 1.0, 2.5, 3.0], "y": [0.0, 2.0, 1.0, 1.5]})
    g = build({"type": "gcv_spline", "x": [0.0, 1.0, 2.0], "y": [1.0, 0.0, 3.0], "degree": 1})
    c = build({"type": "polynomial", "coefficients": [1.0, 0.0, -1.0]})
    for pp in (f, g, c):
        params = pp.to_params()
        n = pp.n_pieces
        assert params.dtype == np.float64 and params.shape == (pp_params_size(n), ) == (7 * n + 15,)
        assert params[0] == n and params[1] == float(pp.right_continuous)
        assert np.array_equal(params[2:3 + n], pp.breaks)
        rows = params[3 + n:].reshape(n + 2, 6)
        assert np.array_equal(rows[0], pp.left) and np.array_equal(rows[-1], pp.right)
        assert np.array_equal(rows[1:-1], pp.coeffs)
    assert c.n_pieces == 0 and np.array_equal(c.breaks, [0.0])
    # several functions in one flat table, evaluated from another compiled kernel
    table = np.concatenate([np.zeros(3), f.to_params(), g.to_params(), c.to_params()])
    starts = np.array([3, 3 + f.to_params().size, 3 + f.to_params().size + g.to_params().size])

    @njit
    def total(table, starts, x):
        s, ds, dds = 0.0, 0.0, 0.0
        for k in range(starts.shape[0]):
            v, dv, ddv = pp_evaluate(table, starts[k], x)
            s += v
            ds += dv
            dds += ddv
        return s, ds, dds

    for x in (-1.0, 0.0, 0.3, 1.0, 2.7, 3.0, 4.2):
        want = np.sum([np.array(pp.evaluate(x)) for pp in (f, g, c)], axis=0)
        assert np.allclose(total(table, starts, x), want, rtol=1e-15, atol=1e-15)
    # array evaluation agrees with the scalar one
    xs = np.linspace(-1.0, 4.0, 11)
    arr = np.array(f.evaluate(xs))
    assert np.array_equal(arr, np.array([f.evaluate(float(v)) for v in xs]).T)


def test_piecewise_polynomial_checks():
    with pytest.raises(ValueError, match="increase strictly"):
        PiecewisePolynomial([0.0, 0.0], np.zeros((1, 6)), np.zeros(6), np.zeros(6))
    with pytest.raises(ValueError, match="breaks"):
        PiecewisePolynomial([0.0, 1.0, 2.0], np.zeros((1, 6)), np.zeros(6), np.zeros(6))
    with pytest.raises(ValueError, match="finite"):
        PiecewisePolynomial([0.0, np.nan], np.zeros((1, 6)), np.zeros(6), np.zeros(6))
    pp = simm_spline([0.0, 1.0, 2.0], [0.0, 1.0, 0.0])
    with pytest.raises(Exception):
        pp.breaks = np.zeros(3)
    with pytest.raises(ValueError):
        pp.coeffs[0, 0] = 1.0                      # read-only


def test_no_scipy_submodules_at_import():
    code = ("import sys, openfdk.model.coordinate_functions, openfdk.io.opensim.functions; "
            "print(sorted(m for m in sys.modules if m.startswith('scipy.') and m.split('.')[1] "
            "in ('interpolate', 'linalg', 'special', 'optimize', 'sparse')))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


# --------------------------------------------------------------------------------------
# errors: one line naming the entry
# --------------------------------------------------------------------------------------

@pytest.mark.parametrize("spec,needle", [
    ({"type": "simm_spline", "x": [0, 2, 1], "y": [0, 1, 2]}, "x is not increasing: x[1] = 2.0 > x[2] = 1.0"),
    ({"type": "simm_spline", "x": [0, 1, 1], "y": [0, 1, 2]}, "repeated value 1.0"),
    ({"type": "piecewise_linear", "x": [0, 1, 2], "y": [0, 1]}, "x has 3 values but y has 2"),
    ({"type": "simm_spline", "x": [0], "y": [1]}, "needs at least 2 points, got 1"),
    ({"type": "gcv_spline", "x": [0, 1, 2, 3, 4], "y": [0, 1, 0, 1, 0], "degree": 5},
     "needs at least 6 points, got 5"),
    ({"type": "simm_spline", "x": [0, float("nan"), 2], "y": [0, 1, 2]}, "x[1]: expected a finite number, got nan"),
    ({"type": "natural_cubic_spline", "x": [0, 1, 2], "y": [0, float("inf"), 2]}, "y[1]: expected a finite number"),
    ({"type": "constant", "value": float("nan")}, "value: expected a finite number"),
    ({"type": "linear", "slope": "1", "intercept": 0}, "slope: expected a number, got '1'"),
    ({"type": "sine", "amplitude": 1}, "unknown function type 'sine'"),
    ({"value": 1}, "unknown function type None"),
    ({"type": "linear", "slope": 1}, "linear function: missing intercept"),
    ({"type": "constant", "value": 1, "units": "mm"}, "constant function: unexpected units"),
    ({"type": "polynomial", "coefficients": [1, 2, 3, 4, 5, 6, 7]}, "unsupported degree 6"),
    ({"type": "polynomial", "coefficients": []}, "coefficients is empty"),
    ({"type": "gcv_spline", "x": list(range(9)), "y": list(range(9)), "degree": 7}, "unsupported degree 7"),
    ({"type": "gcv_spline", "x": list(range(9)), "y": list(range(9)), "degree": 3.0}, "degree must be an integer"),
    ({"type": "simm_spline", "x": "0 1 2", "y": [0, 1, 2]}, "x: expected a list of numbers"),
    ([1, 2], "a function must be a mapping"),
])
def test_spec_errors(spec, needle):
    with pytest.raises(ModelError) as info:
        build(spec, "joints.knee_r.transform.tx.function")
    msg = str(info.value)
    assert "\n" not in msg
    assert msg.startswith("model.yaml: joints.knee_r.transform.tx.function: "), msg
    assert needle in msg, msg


def test_spec_error_in_nested_function():
    spec = {"type": "multiplier", "scale": 2.0, "function": {"type": "simm_spline", "x": [0, 0], "y": [1, 2]}}
    with pytest.raises(ModelError, match=r"^model.yaml: f\.function: x has the repeated value 0\.0"):
        build(spec, "f")


def _xml_error(xml, parent=False):
    """The OsimError of reading ``xml`` (an element) from 'knee.osim'."""
    tree = etree.fromstring(xml).getroottree()
    element = tree.getroot()
    with pytest.raises(OsimError) as info:
        if parent:
            function_element(element, "knee.osim")
        else:
            function_spec(element, "knee.osim")
    msg = str(info.value)
    assert "\n" not in msg
    return msg


@pytest.mark.parametrize("xml,needle", [
    ('<SimmSpline name="f1">\n<x>0 2 1</x><y>0 1 2</y></SimmSpline>',
     "knee.osim: line 1: SimmSpline 'f1': x is not increasing"),
    ('<SimmSpline name="f1"><x>0 1 1</x><y>0 1 2</y></SimmSpline>', "SimmSpline 'f1': x has the repeated value 1.0"),
    ('<PiecewiseLinearFunction><x>0 1 2</x><y>0 1</y></PiecewiseLinearFunction>',
     "PiecewiseLinearFunction: x has 3 values but y has 2"),
    ('<SimmSpline><x>0</x><y>1</y></SimmSpline>', "needs at least 2 points, got 1"),
    ('<SimmSpline><y>1 2</y></SimmSpline>', "x has 0 values but y has 2"),
    ('<SimmSpline><x>0 NaN 2</x><y>0 1 2</y></SimmSpline>', "<x>: 'NaN' is not a finite number"),
    ('<SimmSpline><x>0 1 2</x><y>0 inf 2</y></SimmSpline>', "<y>: 'inf' is not a finite number"),
    ('<NaturalCubicSpline><x>0 1 2</x><y>0 1,5 2</y></NaturalCubicSpline>', "'1,5' is not a finite number"),
    ('<Constant><value></value></Constant>', "<value> must be one number, got 0"),
    ('<LinearFunction><coefficients>1 2 3</coefficients></LinearFunction>', "must be 2 numbers (slope, intercept)"),
    ('<PolynomialFunction><coefficients>1 2 3 4 5 6 7</coefficients></PolynomialFunction>', "unsupported degree 6"),
    ('<GCVSpline><half_order>4</half_order><x>0 1 2 3 4 5 6 7 8</x><y>0 1 2 3 4 5 6 7 8</y></GCVSpline>',
     "<half_order> 4 (degree 7) is not supported"),
    ('<GCVSpline><x>0 1 2 3</x><y>0 1 2 3</y></GCVSpline>', "<half_order> must be at least 1"),
    ('<GCVSpline><half_order>3</half_order><x>0 1 2 3</x><y>0 1 2 3</y></GCVSpline>', "needs at least 6 points"),
    ('<GCVSpline><half_order>2</half_order><error_variance>0.01</error_variance><x>0 1 2 3</x>'
     '<y>0 1 2 3</y></GCVSpline>', "<error_variance> 0.01: OpenSim then fits a smoothing spline"),
    ('<StepFunction name="s"><start_time>0</start_time></StepFunction>',
     "StepFunction 's': the OpenSim function type StepFunction is not supported"),
    ('<Sine><amplitude>1</amplitude></Sine>', "the OpenSim function type Sine is not supported"),
    ('<MultivariatePolynomialFunction/>', "MultivariatePolynomialFunction is not supported"),
    ('<FooSpline/>', "unknown function type 'FooSpline'"),
    ('<SimmSpline><x>0 1</x><y>0 1</y><z>1</z></SimmSpline>', "unexpected element <z>"),
    ('<SimmSpline><x>0 1</x><x>0 1</x><y>0 1</y></SimmSpline>', "<x> is given twice"),
    ('<MultiplierFunction><scale>2</scale></MultiplierFunction>', "no function to multiply"),
    ('<MultiplierFunction><SimmSpline><x>0 1</x><y>0 1</y></SimmSpline><scale>2</scale></MultiplierFunction>',
     "OpenSim reads the function of a MultiplierFunction only inside <function>"),
    ('<MultiplierFunction><function><SimmSpline><x>0 0</x><y>0 1</y></SimmSpline></function></MultiplierFunction>',
     "SimmSpline (MultiplierFunction"),
])
def test_xml_errors(xml, needle):
    msg = _xml_error(xml)
    assert msg.startswith("knee.osim: line "), msg
    assert needle in msg, msg


def test_xml_error_names_line_and_owner():
    xml = ('<CustomJoint name="knee_r">\n<SpatialTransform>\n<TransformAxis name="translation1">\n'
           '<coordinates>knee_angle_r</coordinates>\n<function>\n<SimmSpline name="f">\n'
           '<x> 0 1 0.5</x>\n<y> 0 1 2</y>\n</SimmSpline>\n</function>\n</TransformAxis>\n'
           '</SpatialTransform>\n</CustomJoint>')
    root = etree.fromstring(xml)
    axis = root.find("SpatialTransform/TransformAxis")
    element = function_element(axis, "gait.osim")
    with pytest.raises(OsimError) as info:
        function_spec(element, "gait.osim")
    assert str(info.value).startswith(
        "gait.osim: line 6: SimmSpline 'f' (TransformAxis 'translation1' of CustomJoint 'knee_r'): "
        "x is not increasing"), str(info.value)


@pytest.mark.parametrize("xml,tag", [
    ('<TransformAxis name="r1"><coordinates>q</coordinates><function><LinearFunction>'
     '<coefficients>1 0</coefficients></LinearFunction></function></TransformAxis>', "LinearFunction"),
    ('<TransformAxis name="r1"><axis>0 0 1</axis><LinearFunction name="function">'
     '<coefficients>1 0</coefficients></LinearFunction></TransformAxis>', "LinearFunction"),
    ('<TransformAxis name="r1"><SimmSpline><x>0 1</x><y>0 1</y></SimmSpline></TransformAxis>', "SimmSpline"),
    ('<CoordinateCouplerConstraint name="c"><coupled_coordinates_function><!-- a comment -->'
     '<SimmSpline><x>0 1</x><y>0 1</y></SimmSpline></coupled_coordinates_function>'
     '</CoordinateCouplerConstraint>', "SimmSpline"),
    ('<TransformAxis name="r3"><coordinates></coordinates><axis>0 1 0</axis></TransformAxis>', None),
])
def test_function_element_forms(xml, tag):
    element = function_element(etree.fromstring(xml), "m.osim")
    assert (element.tag if element is not None else None) == tag


@pytest.mark.parametrize("xml,needle", [
    ('<TransformAxis name="r1"><function/></TransformAxis>', "<function> is empty"),
    ('<TransformAxis name="r1"><function><Constant/><Constant/></function></TransformAxis>',
     "<function> holds 2 elements"),
    ('<TransformAxis name="r1"><function><Constant/></function><LinearFunction/></TransformAxis>',
     "more than one function"),
    ('<TransformAxis name="r1"><SimmSpline name="knee_tx"><x>0 1</x><y>0 1</y></SimmSpline></TransformAxis>',
     "must be named 'function' or not at all"),
    ('<CoordinateCouplerConstraint name="c"><SimmSpline><x>0 1</x><y>0 1</y></SimmSpline>'
     '</CoordinateCouplerConstraint>', "only inside <coupled_coordinates_function>"),
])
def test_function_element_errors(xml, needle):
    msg = _xml_error(xml, parent=True)
    assert msg.startswith("knee.osim: line 1: "), msg
    assert needle in msg, msg


def test_xml_defaults_as_opensim():
    """Properties left out take OpenSim's defaults (OpenSim writes only non-defaults)."""
    def spec(xml):
        return function_spec(etree.fromstring(xml), "d.osim")
    assert spec("<Constant/>") == {"type": "constant", "value": 0.0}
    assert spec("<LinearFunction/>") == {"type": "linear", "slope": 1.0, "intercept": 0.0}
    assert spec("<PolynomialFunction/>") == {"type": "polynomial", "coefficients": [1.0]}
    assert spec("<MultiplierFunction><function><Constant><value>2</value></Constant></function>"
                "</MultiplierFunction>")["scale"] == 1.0
    assert spec("<GCVSpline><half_order>2</half_order><x>0 1 2 3</x><y>0 1 0 1</y>"
                "<weights>1 1 1 1</weights></GCVSpline>") == {
        "type": "gcv_spline", "x": [0.0, 1.0, 2.0, 3.0], "y": [0.0, 1.0, 0.0, 1.0], "degree": 3}
    assert spec("<LinearFunction><coefficients>\n  2.5e-1\n -1E+2 </coefficients></LinearFunction>") == {
        "type": "linear", "slope": 0.25, "intercept": -100.0}
