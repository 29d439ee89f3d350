"""openfdk's coordinate functions (:class:`~openfdk.model.coordinate_functions.PiecewisePolynomial`,
SI units) written back as OpenSim 4.6 functions, for ``export-opensim``.

A PiecewisePolynomial does not remember which OpenSim class it came from, so the class
is recognised from the function itself and checked by rebuilding it: a function with no
pieces is a ``Constant``, ``LinearFunction`` or ``PolynomialFunction`` (exact); one with
pieces is tried as a ``PiecewiseLinearFunction``, a ``SimmSpline`` and a ``GCVSpline``
(degree 1, 3, 5, error variance 0) through its knots and kept when the rebuilt function
has the same coefficients and extrapolation (to 1e-12 relative). Anything else (a
spline whose knot values were edited, say) returns None, and the export reports it.
"""

from __future__ import annotations

import numpy as np

from ..model.coordinate_functions import natural_spline, piecewise_linear, simm_spline

#: relative tolerance of the rebuilt function's coefficients
MATCH_RTOL = 1e-12


def _same(a, b) -> bool:
    if a.n_pieces != b.n_pieces or not np.array_equal(a.breaks, b.breaks):
        return False
    A = np.vstack([a.left, a.coeffs, a.right])
    B = np.vstack([b.left, b.coeffs, b.right])
    scale = max(1.0, float(np.max(np.abs(A))))
    return bool(np.max(np.abs(A - B)) <= MATCH_RTOL * scale) and a.right_continuous == b.right_continuous


def _num(x) -> str:
    return repr(float(x))


def function_xml(fn):
    """(tag, {child tag: text}) of the OpenSim function equal to ``fn``, or None.

    The children are the XML properties of that class: ``value`` (Constant),
    ``coefficients`` (LinearFunction: slope intercept; PolynomialFunction: highest power
    first), ``x`` and ``y`` (splines, piecewise linear), ``half_order`` and
    ``error_variance`` (GCVSpline)."""
    if fn.n_pieces == 0:
        c = np.trim_zeros(np.asarray(fn.left, float), "b")   # low power first
        if c.size <= 1:
            return "Constant", {"value": _num(c[0] if c.size else 0.0)}
        if c.size == 2:
            return "LinearFunction", {"coefficients": f"{_num(c[1])} {_num(c[0])}"}
        return "PolynomialFunction", {"coefficients": " ".join(_num(v) for v in c[::-1])}
    x = fn.breaks
    y = np.asarray(fn.evaluate(x)[0], float)
    if fn.right_continuous:  # GCVSPL: y at the last break from the right extrapolation
        y[-1] = fn.right[0]
    points = {"x": " ".join(_num(v) for v in x), "y": " ".join(_num(v) for v in y)}
    candidates = [("PiecewiseLinearFunction", lambda: piecewise_linear(x, y), {}),
                  ("SimmSpline", lambda: simm_spline(x, y), {})]
    candidates += [("GCVSpline", (lambda d=d: natural_spline(x, y, d)),
                    {"half_order": str((d + 1) // 2), "error_variance": "0"}) for d in (1, 3, 5)]
    for tag, make, extra in candidates:
        try:
            rebuilt = make()
        except ValueError:
            continue
        if _same(rebuilt, fn):
            return tag, {**extra, **points}
    return None
