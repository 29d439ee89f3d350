"""Functions y = f(x) of one coordinate, as OpenSim 4.6 evaluates them: the ``function`` of
a ``TransformAxis`` and the ``coupled_coordinates_function`` of a
``CoordinateCouplerConstraint``.

Every supported OpenSim function is, exactly, a piecewise polynomial of degree ≤ 5 in x
with an explicit rule outside its knots, so openfdk stores all of them in one form,
:class:`PiecewisePolynomial`, flattens it into a float array (:meth:`~PiecewisePolynomial.to_params`)
and evaluates value, first and second derivative in one compiled kernel
(:func:`pp_evaluate`, callable from other numba kernels). The OpenSim classes and what
they are (OpenSim 4.6 sources, ``OpenSim/Common``; checked numerically against the
``opensim`` Python package in tests/test_coordinate_functions.py):

* ``Constant`` — f = value.
* ``LinearFunction`` — coefficients (slope, intercept): f = slope·x + intercept
  (``SimTK::Function::Linear``).
* ``PolynomialFunction`` — coefficients from the highest power to the lowest,
  f = c_0 x^{n−1} + … + c_{n−1} (``SimTK::Function::Polynomial``).
* ``SimmSpline`` — the cubic interpolating spline of Forsythe, Malcolm & Moler
  (*Computer Methods for Mathematical Computations*, 1977, §4.4, routine SPLINE): C², and
  at each end the third derivative equals that of the cubic through the four end points
  (three points: the parabola; two points: the line). Knot steps below 1e-7 are replaced
  by 1e-7 when the coefficients are computed (``TINY_NUMBER`` in ``SimmMacros.h``), which
  is reproduced. Outside [x_0, x_{n−1}] it is the tangent line at the end knot (f″ = 0).
* ``NaturalCubicSpline`` (and the older ``natCubicSpline``) — OpenSim renames the type to
  ``SimmSpline`` on reading (``RegisterTypes_osimCommon.cpp``: the old class "wasn't a
  natural cubic spline"), so it is a SimmSpline here too, not a natural spline.
* ``PiecewiseLinearFunction`` — straight lines between the points (steps below 1e-7
  replaced by 1e-7 in the slopes, as in OpenSim); outside, the end segment's line
  continued; f″ = 0.
* ``GCVSpline`` — Woltring's GCVSPL (Simbody ``SplineFitter::fitFromErrorVariance`` with
  unit weights; the file's ``weights`` and ``coefficients`` are not used by OpenSim 4).
  With the file's ``error_variance`` 0 the smoothing parameter p runs down to GCVSPL's
  floor (p·tr(B)/tr(WE) = 1e-15), which leaves the interpolating *natural spline* of
  degree 2m − 1 (m = ``half_order``): C^{2m−2}, f^{(j)} = 0 at both end knots for
  j = m … 2m − 2, and outside the knots the polynomial of degree m − 1 that continues it
  (Woltring 1986, *Adv. Eng. Software* 8(2):104–113; de Boor, *A Practical Guide to
  Splines*, Ch. XIV). That spline is built here to ≈ 1e-15 (the tests compare it
  with exact rational arithmetic); OpenSim's own values differ from it by its
  1e-15 smoothing and B-spline round-off, ≲ 1e-12 relative (≈ 1e-14 … 6e-13 on uneven
  test knots). Degrees 1, 3 and 5 are supported (7, half_order 4, would need a degree-7
  piece). At a knot GCVSPL takes the piece to the right (it matters for degree 1 only).
* ``MultiplierFunction`` — scale × inner function.

Functions are declared as plain dicts (:func:`function_from_spec`, the form of openfdk's
model files); OpenSim's XML is turned into those dicts by :mod:`openfdk.io.opensim.functions`.
"""

from __future__ import annotations

from dataclasses import dataclass
from math import factorial, isfinite

import numpy as np
from numba import njit

__all__ = ["FUNCTION_TYPES", "PP_WIDTH", "PiecewisePolynomial", "pp_evaluate", "pp_params_size",
           "constant", "polynomial", "simm_spline", "piecewise_linear", "natural_spline",
           "function_from_spec"]

#: the ``type`` names of :func:`function_from_spec`
FUNCTION_TYPES = ("constant", "linear", "polynomial", "simm_spline", "natural_cubic_spline",
                  "gcv_spline", "piecewise_linear", "multiplier")

#: coefficients per piece: c0 … c5 of the powers 0 … 5 (degree ≤ 5)
PP_WIDTH = 6

#: OpenSim's ``TINY_NUMBER`` (SimmMacros.h): the smallest knot step its SimmSpline and
#: PiecewiseLinearFunction use when computing coefficients
OPENSIM_TINY_NUMBER = 0.0000001

#: GCVSpline degrees (2·half_order − 1) that fit in a degree-5 piece
GCV_DEGREES = (1, 3, 5)


# --------------------------------------------------------------------------------------
# the piecewise polynomial
# --------------------------------------------------------------------------------------

@dataclass(frozen=True, eq=False)
class PiecewisePolynomial:
    """f(x) on n ≥ 0 pieces with its extrapolation.

    * ``breaks (n+1,)`` strictly increasing, unit of x.
    * ``coeffs (n, 6)``: on [breaks[i], breaks[i+1]], f(x) = Σ_k coeffs[i, k]·(x − breaks[i])^k
      (unit of y per unit of x^k).
    * ``left (6,)``: below breaks[0], f(x) = Σ_k left[k]·(x − breaks[0])^k.
    * ``right (6,)``: above breaks[-1], f(x) = Σ_k right[k]·(x − breaks[-1])^k.
    * ``right_continuous``: which polynomial holds at x = a break, as OpenSim decides for
      the function type (it matters only where a derivative jumps: piecewise linear
      functions). False: the piece OpenSim's SimmSpline/PiecewiseLinearFunction binary
      search reaches (SimmSpline.cpp: it stops at the first k with
      breaks[k] ≤ x ≤ breaks[k+1]), and the last piece at breaks[-1]. True (GCVSpline,
      GCVSPL's SEARCH): the piece starting at x, and ``right`` at breaks[-1].

    ``left`` and ``right`` carry OpenSim's extrapolation rule of the function type (the
    end tangent for SimmSpline and PiecewiseLinearFunction, the degree-(m−1) natural
    continuation for GCVSpline). A function given by one polynomial everywhere
    (constant, linear, polynomial) has no pieces: ``breaks = [0.0]``, ``coeffs (0, 6)``
    and ``left = right`` = its coefficients in powers of x.
    """

    breaks: np.ndarray
    coeffs: np.ndarray
    left: np.ndarray
    right: np.ndarray
    right_continuous: bool = False

    def __post_init__(self):
        breaks = np.array(self.breaks, dtype=np.float64, ndmin=1)
        coeffs = np.array(self.coeffs, dtype=np.float64)
        if coeffs.size == 0:
            coeffs = coeffs.reshape(0, PP_WIDTH)
        if coeffs.ndim != 2 or coeffs.shape[1] != PP_WIDTH:
            raise ValueError(f"piecewise polynomial: coeffs must have shape (n, {PP_WIDTH}), got {coeffs.shape}")
        left = np.array(self.left, dtype=np.float64)
        right = np.array(self.right, dtype=np.float64)
        n = coeffs.shape[0]
        if breaks.ndim != 1 or breaks.shape[0] != n + 1:
            raise ValueError(f"piecewise polynomial: {n} pieces need {n + 1} breaks, got shape {breaks.shape}")
        if left.shape != (PP_WIDTH,) or right.shape != (PP_WIDTH,):
            raise ValueError(f"piecewise polynomial: left and right need {PP_WIDTH} coefficients, "
                             f"got shapes {left.shape} and {right.shape}")
        if not (np.all(np.isfinite(breaks)) and np.all(np.isfinite(coeffs))
                and np.all(np.isfinite(left)) and np.all(np.isfinite(right))):
            raise ValueError("piecewise polynomial: breaks and coefficients must be finite")
        if np.any(np.diff(breaks) <= 0.0):
            raise ValueError("piecewise polynomial: breaks must increase strictly")
        for name, value in (("breaks", breaks), ("coeffs", coeffs), ("left", left), ("right", right)):
            value.setflags(write=False)
            object.__setattr__(self, name, value)
        object.__setattr__(self, "right_continuous", bool(self.right_continuous))
        object.__setattr__(self, "_params", self._flatten())

    @property
    def n_pieces(self) -> int:
        return self.coeffs.shape[0]

    def _flatten(self) -> np.ndarray:
        n = self.n_pieces
        rows = np.vstack([self.left[None, :], self.coeffs, self.right[None, :]])
        return np.concatenate([[float(n), float(self.right_continuous)], self.breaks, rows.ravel()])

    def to_params(self) -> np.ndarray:
        """The function as one float64 array of length 7n + 15 (n pieces), read by
        :func:`pp_evaluate`::

            [n, right_continuous (0 or 1), breaks[0] … breaks[n],
             left (6), coeffs[0] (6) … coeffs[n−1] (6), right (6)]

        i.e. after the n + 1 breaks come n + 2 rows of 6 coefficients: row 0 is ``left``,
        row i + 1 is piece i, row n + 1 is ``right``."""
        return self._params.copy()

    def evaluate(self, x):
        """(f, f′, f″) at ``x`` (unit of x): three floats for a scalar x, three arrays of
        x's shape otherwise (units of y, y per x, y per x²)."""
        if np.ndim(x) == 0:
            return pp_evaluate(self._params, 0, float(x))
        xs = np.asarray(x, dtype=np.float64)
        f, df, d2f = _pp_evaluate_many(self._params, np.ascontiguousarray(xs.ravel()))
        return f.reshape(xs.shape), df.reshape(xs.shape), d2f.reshape(xs.shape)

    def scaled(self, sx: float, sy: float) -> "PiecewisePolynomial":
        """g(u) = sy · f(u / sx): the same function with x in units of ``1/sx`` of f's
        (sx = new x-unit per old x-unit, > 0) and y multiplied by ``sy``. For a file giving
        x in degrees and y in mm, ``scaled(pi/180, 1e-3)`` is the function of radians in
        metres. Breaks become sx·breaks and coefficient k becomes sy·c_k / sx^k."""
        sx, sy = float(sx), float(sy)
        if not (isfinite(sx) and sx > 0.0):
            raise ValueError(f"piecewise polynomial: scaled needs a finite sx > 0, got {sx}")
        if not isfinite(sy):
            raise ValueError(f"piecewise polynomial: scaled needs a finite sy, got {sy}")
        factor = sy / sx ** np.arange(PP_WIDTH, dtype=np.float64)
        return PiecewisePolynomial(self.breaks * sx, self.coeffs * factor, self.left * factor,
                                   self.right * factor, self.right_continuous)


def pp_params_size(n_pieces: int) -> int:
    """Length of :meth:`PiecewisePolynomial.to_params` for ``n_pieces`` pieces."""
    return 2 + (n_pieces + 1) + PP_WIDTH * (n_pieces + 2)


@njit(cache=True)
def pp_evaluate(fparams, start, x):  # pragma: no cover - compiled (numba); tested through evaluate
    """(f, f′, f″) at the scalar ``x`` of the function stored at ``fparams[start:]`` in the
    layout of :meth:`PiecewisePolynomial.to_params`."""
    n = int(fparams[start])
    b = start + 2                       # breaks fparams[b] … fparams[b + n]
    rows = b + n + 1                    # coefficient row r at fparams[rows + 6 r]
    if x < fparams[b]:
        r = 0
        x0 = fparams[b]
    elif fparams[start + 1] != 0.0:     # right-continuous (GCVSPL's SEARCH)
        if n == 0 or x >= fparams[b + n]:
            r = n + 1
            x0 = fparams[b + n]
        else:                           # breaks[i] <= x < breaks[j]
            i = 0
            j = n
            while j - i > 1:
                k = (i + j) // 2
                if x < fparams[b + k]:
                    j = k
                else:
                    i = k
            r = i + 1
            x0 = fparams[b + i]
    elif n == 0 or x > fparams[b + n]:
        r = n + 1
        x0 = fparams[b + n]
    elif x == fparams[b + n]:           # the last knot: the last piece
        r = n
        x0 = fparams[b + n - 1]
    else:
        # the binary search of OpenSim's SimmSpline/PiecewiseLinearFunction::calcValue over
        # the n + 1 knots: stops at the first k it tries with breaks[k] <= x <= breaks[k + 1]
        # (x < breaks[n] here, so k + 1 <= n)
        i = 0
        j = n + 1
        k = 0
        while True:
            k = (i + j) // 2
            if x < fparams[b + k]:
                j = k
            elif x > fparams[b + k + 1]:
                i = k
            else:
                break
        r = k + 1
        x0 = fparams[b + k]
    c = rows + PP_WIDTH * r
    d = x - x0
    c0, c1, c2 = fparams[c], fparams[c + 1], fparams[c + 2]
    c3, c4, c5 = fparams[c + 3], fparams[c + 4], fparams[c + 5]
    f = c0 + d * (c1 + d * (c2 + d * (c3 + d * (c4 + d * c5))))
    df = c1 + d * (2.0 * c2 + d * (3.0 * c3 + d * (4.0 * c4 + d * (5.0 * c5))))
    d2f = 2.0 * c2 + d * (6.0 * c3 + d * (12.0 * c4 + d * (20.0 * c5)))
    return f, df, d2f


@njit(cache=True)
def _pp_evaluate_many(fparams, xs):  # pragma: no cover - compiled (numba)
    m = xs.shape[0]
    f = np.empty(m)
    df = np.empty(m)
    d2f = np.empty(m)
    for q in range(m):
        f[q], df[q], d2f[q] = pp_evaluate(fparams, np.int64(0), xs[q])
    return f, df, d2f


# --------------------------------------------------------------------------------------
# the OpenSim function types
# --------------------------------------------------------------------------------------

def _row(values) -> np.ndarray:
    out = np.zeros(PP_WIDTH)
    out[:len(values)] = values
    return out


def _global(coefficients_low_first) -> PiecewisePolynomial:
    row = _row(coefficients_low_first)
    return PiecewisePolynomial(np.zeros(1), np.zeros((0, PP_WIDTH)), row, row)


def constant(value: float) -> PiecewisePolynomial:
    """f = value (OpenSim ``Constant``)."""
    return _global([float(value)])


def polynomial(coefficients) -> PiecewisePolynomial:
    """f = c_0 x^{n−1} + … + c_{n−1}: ``coefficients (n,)``, 1 ≤ n ≤ 6, highest power
    first as in OpenSim's ``PolynomialFunction`` (``LinearFunction``: (slope, intercept))."""
    c = [float(v) for v in coefficients]
    if not 1 <= len(c) <= PP_WIDTH:
        raise ValueError(f"polynomial: 1 to {PP_WIDTH} coefficients supported, got {len(c)}")
    return _global(c[::-1])


def _points(x, y, min_points, what):
    x = [float(v) for v in x]
    y = [float(v) for v in y]
    if len(x) != len(y) or len(x) < min_points:
        raise ValueError(f"{what}: needs at least {min_points} points with as many x as y, "
                         f"got {len(x)} x and {len(y)} y")
    if not all(isfinite(v) for v in x + y):
        raise ValueError(f"{what}: x and y must be finite")
    if any(b <= a for a, b in zip(x, x[1:])):
        raise ValueError(f"{what}: x must increase strictly")
    return x, y


def simm_spline(x, y) -> PiecewisePolynomial:
    """OpenSim's ``SimmSpline`` (also ``NaturalCubicSpline``) through ≥ 2 points,
    x strictly increasing.

    Forsythe, Malcolm & Moler's cubic spline (see the module docstring): with steps
    h_i = max(1e-7, x_{i+1} − x_i), slopes δ_i = (y_{i+1} − y_i)/h_i and unknowns σ_i
    (one sixth of f″ at x_i) the C² conditions

        h_{i−1} σ_{i−1} + 2 (h_{i−1} + h_i) σ_i + h_i σ_{i+1} = δ_i − δ_{i−1},  i = 1 … n−2,

    and the end rows −h_0 σ_0 + h_0 σ_1 = h_0² Δ³_0 and h_{n−2} σ_{n−2} − h_{n−2} σ_{n−1}
    = −h_{n−2}² Δ³_{n−1} (Δ³: the third divided difference of the four end points; zero
    for three points) are solved by elimination without pivoting in OpenSim's order, so the
    coefficients agree with OpenSim's to round-off. Piece i is
    y_i + b_i d + 3σ_i d² + (σ_{i+1} − σ_i)/h_i d³ with b_i = δ_i − h_i (σ_{i+1} + 2σ_i)."""
    x, y = _points(x, y, 2, "SimmSpline")
    n = len(x)
    tiny = OPENSIM_TINY_NUMBER
    if n == 2:
        slope = (y[1] - y[0]) / max(tiny, x[1] - x[0])
        return PiecewisePolynomial(x, [_row([y[0], slope])], _row([y[0], slope]), _row([y[1], slope]))
    h = [max(tiny, x[i + 1] - x[i]) for i in range(n - 1)]
    # tridiagonal system: diagonal `diag`, off-diagonals h, right-hand side `rhs`
    diag = [0.0] * n
    rhs = [0.0] * n
    secant = (y[1] - y[0]) / h[0]
    for i in range(1, n - 1):
        diag[i] = 2.0 * (h[i - 1] + h[i])
        next_secant = (y[i + 1] - y[i]) / h[i]
        rhs[i] = next_secant - secant
        secant = next_secant
    diag[0] = -h[0]
    diag[n - 1] = -h[n - 2]
    if n > 3:
        # third derivative at each end from the cubic through the four end points
        d31 = max(tiny, x[3] - x[1])
        d20 = max(tiny, x[2] - x[0])
        d30 = max(tiny, x[3] - x[0])
        e1 = max(tiny, x[n - 1] - x[n - 3])
        e2 = max(tiny, x[n - 2] - x[n - 4])
        e3 = max(tiny, x[n - 1] - x[n - 4])
        rhs0 = rhs[2] / d31 - rhs[1] / d20
        rhs_last = rhs[n - 2] / e1 - rhs[n - 3] / e2
        rhs[0] = rhs0 * h[0] * h[0] / d30
        rhs[n - 1] = -rhs_last * h[n - 2] * h[n - 2] / e3
    for i in range(1, n):                       # forward elimination
        t = h[i - 1] / diag[i - 1]
        diag[i] -= t * h[i - 1]
        rhs[i] -= t * rhs[i - 1]
    sigma = [0.0] * n                           # back substitution
    sigma[n - 1] = rhs[n - 1] / diag[n - 1]
    for i in range(n - 2, -1, -1):
        sigma[i] = (rhs[i] - h[i] * sigma[i + 1]) / diag[i]
    coeffs = np.zeros((n - 1, PP_WIDTH))
    for i in range(n - 1):
        coeffs[i, 0] = y[i]
        coeffs[i, 1] = (y[i + 1] - y[i]) / h[i] - h[i] * (sigma[i + 1] + 2.0 * sigma[i])
        coeffs[i, 2] = 3.0 * sigma[i]
        coeffs[i, 3] = (sigma[i + 1] - sigma[i]) / h[i]
    end_slope = (y[n - 1] - y[n - 2]) / h[n - 2] + h[n - 2] * (sigma[n - 2] + 2.0 * sigma[n - 1])
    return PiecewisePolynomial(x, coeffs, _row([y[0], coeffs[0, 1]]), _row([y[n - 1], end_slope]))


def piecewise_linear(x, y) -> PiecewisePolynomial:
    """OpenSim's ``PiecewiseLinearFunction`` through ≥ 2 points, x strictly increasing:
    slopes (y_{i+1} − y_i)/max(1e-7, x_{i+1} − x_i); outside, the end segments' lines."""
    x, y = _points(x, y, 2, "PiecewiseLinearFunction")
    n = len(x)
    slopes = [(y[i + 1] - y[i]) / max(OPENSIM_TINY_NUMBER, x[i + 1] - x[i]) for i in range(n - 1)]
    coeffs = np.array([_row([y[i], slopes[i]]) for i in range(n - 1)])
    return PiecewisePolynomial(x, coeffs, _row([y[0], slopes[0]]), _row([y[n - 1], slopes[-1]]))


def natural_spline(x, y, degree: int) -> PiecewisePolynomial:
    """The interpolating natural spline of odd ``degree`` = 2m − 1 ∈ {1, 3, 5} through
    n ≥ 2m points (x strictly increasing): what OpenSim's ``GCVSpline`` with
    ``half_order`` m and ``error_variance`` 0 evaluates (module docstring). The pieces
    are :func:`openfdk.numerics.natural_spline.natural_spline_coefficients`'s. Outside
    the knots: the Taylor polynomial of degree m − 1 at the end knot. At a knot the piece
    to its right is used, as GCVSPL's SEARCH does (matters for degree 1 only)."""
    from ..numerics.natural_spline import natural_spline_coefficients

    degree = int(degree)
    if degree not in GCV_DEGREES:
        raise ValueError(f"natural spline: degree must be one of {GCV_DEGREES}, got {degree}")
    m = (degree + 1) // 2
    x, y = _points(x, y, 2 * m, f"GCVSpline of degree {degree}")
    n = len(x)
    size = 2 * m
    coeffs = np.zeros((n - 1, PP_WIDTH))
    coeffs[:, :size] = natural_spline_coefficients(x, y, degree)[:, :, 0]
    left = _row(coeffs[0, :m])
    last, step = coeffs[n - 2, :size], x[n - 1] - x[n - 2]
    right = _row([sum(factorial(k) // factorial(k - j) * last[k] * step ** (k - j)
                      for k in range(j, size)) / factorial(j) for j in range(m)])
    right[0] = y[n - 1]
    return PiecewisePolynomial(x, coeffs, left, right, right_continuous=True)


# --------------------------------------------------------------------------------------
# the model-file form
# --------------------------------------------------------------------------------------

_KEYS = {
    "constant": ("value",),
    "linear": ("slope", "intercept"),
    "polynomial": ("coefficients",),
    "simm_spline": ("x", "y"),
    "natural_cubic_spline": ("x", "y"),
    "gcv_spline": ("x", "y", "degree"),
    "piecewise_linear": ("x", "y"),
    "multiplier": ("scale", "function"),
}

_MIN_POINTS = {"simm_spline": 2, "natural_cubic_spline": 2, "piecewise_linear": 2}


def _number(value, path, key, error):
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise error(path, f"{key}: expected a number, got {value!r}")
    v = float(value)
    if not isfinite(v):
        raise error(path, f"{key}: expected a finite number, got {v}")
    return v


def _numbers(value, path, key, error):
    if isinstance(value, (str, bytes, dict)) or not hasattr(value, "__len__"):
        raise error(path, f"{key}: expected a list of numbers, got {value!r}")
    out = []
    for k, v in enumerate(value):
        if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)):
            raise error(path, f"{key}[{k}]: expected a number, got {v!r}")
        f = float(v)
        if not isfinite(f):
            raise error(path, f"{key}[{k}]: expected a finite number, got {f}")
        out.append(f)
    return out


def _knots(spec, path, error, min_points):
    x = _numbers(spec["x"], path, "x", error)
    y = _numbers(spec["y"], path, "y", error)
    if len(x) != len(y):
        raise error(path, f"x has {len(x)} values but y has {len(y)}")
    if len(x) < min_points:
        raise error(path, f"needs at least {min_points} points, got {len(x)}")
    for k in range(1, len(x)):
        if x[k] == x[k - 1]:
            raise error(path, f"x has the repeated value {x[k]!r} (x[{k - 1}] = x[{k}]); "
                              "x must increase strictly")
        if x[k] < x[k - 1]:
            raise error(path, f"x is not increasing: x[{k - 1}] = {x[k - 1]!r} > x[{k}] = {x[k]!r}")
    return x, y


#: the deepest nesting of multiplier functions read (deeper specs are refused rather than
#: exhausting Python's recursion limit; an .osim cannot nest deeper: lxml's depth limit)
MAX_NESTING = 200


def function_from_spec(spec, path: str, error, _depth=0) -> PiecewisePolynomial:
    """The :class:`PiecewisePolynomial` of a function declared as a plain dict, in the
    units of the declaration (convert with :meth:`PiecewisePolynomial.scaled`):

    * ``{type: constant, value}``
    * ``{type: linear, slope, intercept}`` — slope·x + intercept
    * ``{type: polynomial, coefficients: [c_0, …, c_{n−1}]}`` — OpenSim's order, highest
      power first: c_0 x^{n−1} + … + c_{n−1}; 1 ≤ n ≤ 6 (degree ≤ 5)
    * ``{type: simm_spline, x, y}`` and ``{type: natural_cubic_spline, x, y}`` — both
      OpenSim's SimmSpline (OpenSim reads ``NaturalCubicSpline`` as SimmSpline); ≥ 2 points
    * ``{type: gcv_spline, x, y, degree}`` — OpenSim's GCVSpline with error variance 0,
      degree = 2·half_order − 1 ∈ {1, 3, 5}, ≥ degree + 1 points
    * ``{type: piecewise_linear, x, y}`` — ≥ 2 points
    * ``{type: multiplier, scale, function: {…}}`` — scale × the nested function

    x must increase strictly and every number be finite. ``error(path, message)`` returns
    the exception to raise (one line); nested functions are reported at ``path.function``."""
    if not isinstance(spec, dict):
        raise error(path, f"a function must be a mapping with a 'type', got {spec!r}")
    kind = spec.get("type")
    if not isinstance(kind, str) or kind not in _KEYS:
        raise error(path, f"unknown function type {kind!r} (expected one of {', '.join(FUNCTION_TYPES)})")
    expected = set(_KEYS[kind])
    given = set(spec) - {"type"}
    missing = sorted(expected - given, key=str)
    extra = sorted(given - expected, key=str)
    if missing or extra:
        parts = []
        if missing:
            parts.append(f"missing {', '.join(map(str, missing))}")
        if extra:
            parts.append(f"unexpected {', '.join(map(str, extra))}")
        raise error(path, f"{kind} function: {'; '.join(parts)} "
                          f"(a {kind} function has {', '.join(_KEYS[kind])})")
    return _build(kind, spec, path, error, _depth)


def _made(make, path, error, *args):
    """``make(*args)`` with its ValueError (input the checks above cannot see, such as too
    large a spline) raised as ``error(path, …)``."""
    try:
        return make(*args)
    except ValueError as exc:
        raise error(path, str(exc)) from None


def _build(kind, spec, path, error, depth=0):
    if kind == "constant":
        return _made(constant, path, error, _number(spec["value"], path, "value", error))
    if kind == "linear":
        return _made(polynomial, path, error, [_number(spec["slope"], path, "slope", error),
                                               _number(spec["intercept"], path, "intercept", error)])
    if kind == "polynomial":
        c = _numbers(spec["coefficients"], path, "coefficients", error)
        if not c:
            raise error(path, "polynomial function: coefficients is empty")
        if len(c) > PP_WIDTH:
            raise error(path, f"polynomial function: unsupported degree {len(c) - 1} "
                              f"(openfdk supports degree <= {PP_WIDTH - 1})")
        return _made(polynomial, path, error, c)
    if kind in ("simm_spline", "natural_cubic_spline"):
        return _made(simm_spline, path, error, *_knots(spec, path, error, 2))
    if kind == "piecewise_linear":
        return _made(piecewise_linear, path, error, *_knots(spec, path, error, 2))
    if kind == "gcv_spline":
        degree = spec["degree"]
        if isinstance(degree, bool) or not isinstance(degree, (int, np.integer)):
            raise error(path, f"gcv_spline function: degree must be an integer, got {degree!r}")
        if degree not in GCV_DEGREES:
            raise error(path, f"gcv_spline function: unsupported degree {degree} "
                              f"(openfdk supports {', '.join(map(str, GCV_DEGREES))})")
        return _made(natural_spline, path, error, *_knots(spec, path, error, degree + 1), degree)
    # multiplier
    scale = _number(spec["scale"], path, "scale", error)
    if depth >= MAX_NESTING:  # (named at the outermost function, not at .function.function…)
        top = path[:-len(".function") * depth] if path.endswith(".function") else path
        raise error(top, f"multiplier functions nested more than {MAX_NESTING} deep")
    inner = function_from_spec(spec["function"], f"{path}.function" if path else "function", error, depth + 1)
    try:
        return inner.scaled(1.0, scale)
    except ValueError:
        raise error(path, f"scale {scale:g} times the function overflows (the numbers are too large)") from None
