"""Millard et al. (2013) muscle curves: the four smooth curves of OpenSim's
``Millard2012EquilibriumMuscle``, built from their properties exactly as OpenSim builds
them (``SmoothSegmentedFunctionFactory``), evaluated in numba (value and slope).

Each curve is a chain of quintic Bézier segments in the plane; outside its domain
[x0, x1] it continues linearly with its end slope. A segment is a *corner*: between two
points (x_a, y_a) and (x_b, y_b) with slopes k_a and k_b, the two tangent lines meet at
C = (x_c, y_c) (or, when k_a ≈ k_b within √ε, at the mean x on the line through b); the six
control points are

    P0 = A,  P1 = P2 = A + c (C − A),  P3 = P4 = B + c (C − B),  P5 = B,

with the curviness c = 0.1 + 0.8·curviness (curviness in [0, 1]). The corner must be
"C-shaped" (|AB| longer than |AC| and |BC|), else the curve is refused. Evaluation at x
finds the segment holding x, solves x(u) = x for u ∈ [0, 1] by safeguarded Newton, and
returns y(u) and dy/dx = y'(u)/x'(u).

For speed each segment also stores x(u) at nine values of u; the Newton iteration starts
from the linear interpolation between them.

The curves (normalised fibre length l̃ = l_f/Lf0, normalised fibre velocity ṽ =
v_f/(V_max Lf0), tendon length l̃_T = l_T/Lt0; OpenSim's property names and defaults):

* **Active force–length** f_L(l̃), 5 corners through (l_min, y_min), the shallow
  ascending limb (slope ``shallow_ascending_slope`` from ``transition_norm_fiber_length``),
  the plateau at (1, 1) and back to y_min at ``max_norm_active_fiber_length``
  (defaults 0.4441, 0.73, 1.8123, slope 0.8616, ``minimum_value`` 0.1, curviness 1).
* **Force–velocity** f_V(ṽ), 4 corners through (−1, 0), (−0.9, ·), (0, 1), (0.9, ·),
  (1, F_ecc) with the slopes at and near ±V_max and at ṽ = 0 (defaults: concentric 0
  and 0.25, isometric 5, eccentric 0 and 0.15, F_ecc 1.4, curviness 0.6 and 0.9).
* **Fibre force–length** (passive) f_PE(l̃), 2 corners from 1 + ``strain_at_zero_force``
  (0) to 1 + ``strain_at_one_norm_force`` (0.7) where f_PE = 1; the optional
  ``stiffness_at_low_force``, ``stiffness_at_one_norm_force``, ``curviness`` are all given
  or all absent (then 0.2, 2/(ε1 − ε0), 0.75).
* **Tendon force–length** f_T(l̃_T), 2 corners from (1, 0) to the end of the toe
  (f_toe reached on the line of slope k through (1 + ε0, 1)); the optional
  ``stiffness_at_one_norm_force``, ``norm_force_at_toe_end``, ``curviness`` are all given or
  all absent (then 1.375/ε0, 2/3, 0.5); ``strain_at_one_norm_force`` default 0.049.

Source: Millard M, Uchida T, Seth A, Delp SL (2013) Flexing computational muscle:
modeling and simulation of musculotendon dynamics. J Biomech Eng 135:021005; the curve
construction of OpenSim 4.x (SmoothSegmentedFunctionFactory, SegmentedQuinticBezierToolkit),
re-derived here and verified against OpenSim 4.6 (tests/test_opensim_millard.py).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np
from numba import njit

__all__ = [
    "CurveError", "ActiveForceLengthCurve", "ForceVelocityCurve", "FiberForceLengthCurve",
    "TendonForceLengthCurve", "curve_table", "evaluate_curve", "CURVE_WIDTH",
]

#: most Bézier segments of a curve (the active force–length has 5)
MAX_SEGMENTS = 5
# NOTE: the kernels of .millard are compiled (numba, cache=True) with this layout and
# curve_value inside them; numba's on-disk cache does not see a change made here, so a
# change of the layout or of curve_value must come with an edit of millard.py (or a
# cleared __pycache__), else stale kernels read the old layout.
#: x(u) samples per segment at u = j/N_SAMPLES (the Newton start for u(x))
N_SAMPLES = 8
#: numbers per segment: 6 x, 6 y control points, N_SAMPLES + 1 samples of x(u)
SEGMENT_WIDTH = 12 + N_SAMPLES + 1
#: length of a flattened curve: n, x0, x1, y0, y1, dydx0, dydx1, then the segments
CURVE_WIDTH = 7 + SEGMENT_WIDTH * MAX_SEGMENTS
_ROOT_EPS = math.sqrt(np.finfo(float).eps)


class CurveError(ValueError):
    """A curve parameter is out of its range; the message names the curve and the property."""


def _curviness(c):
    return 0.1 + 0.8 * c


def _corner(x0, y0, k0, x1, y1, k1, c, who):
    """Six x and six y control points of the quintic Bézier corner (module docstring)."""
    if abs(k0 - k1) > _ROOT_EPS:
        xc = (y1 - y0 - x1 * k1 + x0 * k0) / (k0 - k1)
    else:
        xc = 0.5 * (x1 + x0)
    yc = (xc - x1) * k1 + y1
    a = (xc - x0) ** 2 + (yc - y0) ** 2
    b = (xc - x1) ** 2 + (yc - y1) ** 2
    d = (x1 - x0) ** 2 + (y1 - y0) ** 2
    if not (d > a and d > b):
        raise CurveError(f"{who}: the parameters give an S-shaped, not a C-shaped, corner between "
                         f"({x0:g}, {y0:g}) and ({x1:g}, {y1:g})")
    xa, ya = x0 + c * (xc - x0), y0 + c * (yc - y0)
    xb, yb = x1 + c * (xc - x1), y1 + c * (yc - y1)
    return (x0, xa, xa, xb, xb, x1), (y0, ya, ya, yb, yb, y1)


def _flatten(corners, x0, x1, y0, y1, dydx0, dydx1):
    out = np.zeros(CURVE_WIDTH)
    out[:7] = len(corners), x0, x1, y0, y1, dydx0, dydx1
    for i, (xs, ys) in enumerate(corners):
        k = 7 + SEGMENT_WIDTH * i
        out[k: k + 6] = xs
        out[k + 6: k + 12] = ys
        for j in range(N_SAMPLES + 1):
            out[k + 12 + j] = _bezier(j / N_SAMPLES, out, k)[0]
    return out


def _require(who, name, value, ok, expected):
    if not (math.isfinite(value) and ok(value)):
        raise CurveError(f"{who}: {name} must be finite and {expected}, got {value!r}")


@dataclass(frozen=True)
class ActiveForceLengthCurve:
    """OpenSim's ActiveForceLengthCurve (module docstring); lengths normalised by Lf0."""

    min_norm_active_fiber_length: float = 0.47 - 0.0259
    transition_norm_fiber_length: float = 0.73
    max_norm_active_fiber_length: float = 1.8123
    shallow_ascending_slope: float = 0.8616
    minimum_value: float = 0.1

    def table(self, who="ActiveForceLengthCurve"):
        x0, x1, x2, x3 = (self.min_norm_active_fiber_length, self.transition_norm_fiber_length, 1.0,
                          self.max_norm_active_fiber_length)
        ylow, dydx = self.minimum_value, self.shallow_ascending_slope
        for f in fields(self):
            _require(who, f.name, getattr(self, f.name), lambda v: True, "a number")
        if not (x0 >= 0 and x1 > x0 + _ROOT_EPS and x2 > x1 + _ROOT_EPS and x3 > x2 + _ROOT_EPS):
            raise CurveError(f"{who}: need 0 <= min_norm_active_fiber_length < "
                             "transition_norm_fiber_length < 1 < max_norm_active_fiber_length")
        _require(who, "minimum_value", ylow, lambda v: v >= 0, ">= 0")
        _require(who, "shallow_ascending_slope", dydx, lambda v: 0 <= v < (1 - ylow) / (x2 - x1),
                 f"in [0, {(1 - ylow) / (x2 - x1):g}) ((1 − minimum_value)/(1 − transition))")
        c = _curviness(1.0)
        dx = 0.05 * x2
        xs = x2 - dx
        y0, y1 = 0.0, 1.0 - dydx * (xs - x1)
        dydx01 = 1.25 * (y1 - y0) / (x1 - x0)
        x01, y01 = x0 + 0.5 * (x1 - x0), y0 + 0.5 * (y1 - y0)
        x1s, y1s = x1 + 0.5 * (xs - x1), y1 + 0.5 * (1 - y1)
        y2, y3 = 1.0, 0.0
        x23, y23 = (x2 + dx) + 0.5 * (x3 - (x2 + dx)), y2 + 0.5 * (y3 - y2)
        dydx23 = (y3 - y2) / ((x3 - dx) - (x2 + dx))
        corners = [_corner(x0, ylow, 0.0, x01, y01, dydx01, c, who),
                   _corner(x01, y01, dydx01, x1s, y1s, dydx, c, who),
                   _corner(x1s, y1s, dydx, x2, y2, 0.0, c, who),
                   _corner(x2, y2, 0.0, x23, y23, dydx23, c, who),
                   _corner(x23, y23, dydx23, x3, ylow, 0.0, c, who)]
        return _flatten(corners, x0, x3, ylow, ylow, 0.0, 0.0)


@dataclass(frozen=True)
class ForceVelocityCurve:
    """OpenSim's ForceVelocityCurve (module docstring); velocity normalised by V_max Lf0."""

    concentric_slope_at_vmax: float = 0.0
    concentric_slope_near_vmax: float = 0.25
    isometric_slope: float = 5.0
    eccentric_slope_at_vmax: float = 0.0
    eccentric_slope_near_vmax: float = 0.15
    max_eccentric_velocity_force_multiplier: float = 1.4
    concentric_curviness: float = 0.6
    eccentric_curviness: float = 0.9

    def table(self, who="ForceVelocityCurve"):
        fmax = self.max_eccentric_velocity_force_multiplier
        for f in fields(self):
            _require(who, f.name, getattr(self, f.name), lambda v: True, "a number")
        _require(who, "max_eccentric_velocity_force_multiplier", fmax, lambda v: v > 1, "> 1")
        kc = self.concentric_slope_at_vmax
        _require(who, "concentric_slope_at_vmax", kc, lambda v: 0 <= v < 1, "in [0, 1)")
        _require(who, "concentric_slope_near_vmax", self.concentric_slope_near_vmax,
                 lambda v: kc < v <= 1, "in (concentric_slope_at_vmax, 1]")
        _require(who, "isometric_slope", self.isometric_slope, lambda v: v > 1, "> 1")
        ke = self.eccentric_slope_at_vmax
        _require(who, "eccentric_slope_at_vmax", ke, lambda v: 0 <= v < fmax - 1,
                 f"in [0, {fmax - 1:g}) (max_eccentric_velocity_force_multiplier − 1)")
        _require(who, "eccentric_slope_near_vmax", self.eccentric_slope_near_vmax,
                 lambda v: ke <= v < fmax - 1, f"in [eccentric_slope_at_vmax, {fmax - 1:g})")
        for name in ("concentric_curviness", "eccentric_curviness"):
            _require(who, name, getattr(self, name), lambda v: 0 <= v <= 1, "in [0, 1]")
        cc, ce = _curviness(self.concentric_curviness), _curviness(self.eccentric_curviness)
        kc, knc, kiso = self.concentric_slope_at_vmax, self.concentric_slope_near_vmax, self.isometric_slope
        ke, kne = self.eccentric_slope_at_vmax, self.eccentric_slope_near_vmax
        x_nc = -0.9
        y_nc = 0.5 * knc * (x_nc + 1.0) + 0.5 * kc * (x_nc + 1.0)
        x_ne = 0.9
        y_ne = fmax + 0.5 * kne * (x_ne - 1.0) + 0.5 * ke * (x_ne - 1.0)
        corners = [_corner(-1.0, 0.0, kc, x_nc, y_nc, knc, cc, who),
                   _corner(x_nc, y_nc, knc, 0.0, 1.0, kiso, cc, who),
                   _corner(0.0, 1.0, kiso, x_ne, y_ne, kne, ce, who),
                   _corner(x_ne, y_ne, kne, 1.0, fmax, ke, ce, who)]
        return _flatten(corners, -1.0, 1.0, 0.0, fmax, kc, ke)


@dataclass(frozen=True)
class FiberForceLengthCurve:
    """OpenSim's FiberForceLengthCurve (passive fibre force; module docstring). The three
    optional properties are all None (OpenSim's fitted defaults) or all given."""

    strain_at_zero_force: float = 0.0
    strain_at_one_norm_force: float = 0.7
    stiffness_at_low_force: float | None = None
    stiffness_at_one_norm_force: float | None = None
    curviness: float | None = None

    def in_use(self, who="FiberForceLengthCurve"):
        """(k_low, k_iso, curviness) as OpenSim uses them."""
        opt = (self.stiffness_at_low_force, self.stiffness_at_one_norm_force, self.curviness)
        if all(v is None for v in opt):
            return 0.2, 2.0 / (self.strain_at_one_norm_force - self.strain_at_zero_force), 0.75
        if any(v is None for v in opt):
            raise CurveError(f"{who}: stiffness_at_low_force, stiffness_at_one_norm_force and curviness "
                             "must all be given or all be absent")
        return tuple(float(v) for v in opt)

    def table(self, who="FiberForceLengthCurve"):
        e0, e1 = self.strain_at_zero_force, self.strain_at_one_norm_force
        _require(who, "strain_at_zero_force", e0, lambda v: True, "a number")
        _require(who, "strain_at_one_norm_force", e1, lambda v: v > e0, "> strain_at_zero_force")
        k_low, k_iso, curv = self.in_use(who)
        _require(who, "stiffness_at_one_norm_force", k_iso, lambda v: v > 1 / (e1 - e0),
                 f"> 1/(strain_at_one_norm_force − strain_at_zero_force) = {1 / (e1 - e0):g}")
        _require(who, "stiffness_at_low_force", k_low, lambda v: 0 < v < 1 / (e1 - e0),
                 f"in (0, {1 / (e1 - e0):g})")
        _require(who, "curviness", curv, lambda v: 0 <= v <= 1, "in [0, 1]")
        c = _curviness(curv)
        x_zero, x_iso = 1.0 + e0, 1.0 + e1
        dx = min(0.1 / k_iso, 0.1 * (x_iso - x_zero))
        x_low = x_zero + dx
        x_foot = x_zero + 0.5 * (x_low - x_zero)
        y_low = k_low * (x_low - x_foot)
        corners = [_corner(x_zero, 0.0, 0.0, x_low, y_low, k_low, c, who),
                   _corner(x_low, y_low, k_low, x_iso, 1.0, k_iso, c, who)]
        return _flatten(corners, x_zero, x_iso, 0.0, 1.0, 0.0, k_iso)


@dataclass(frozen=True)
class TendonForceLengthCurve:
    """OpenSim's TendonForceLengthCurve (module docstring). The three optional properties
    are all None (OpenSim's fitted defaults, stiffness 1.375/ε0) or all given."""

    strain_at_one_norm_force: float = 0.049
    stiffness_at_one_norm_force: float | None = None
    norm_force_at_toe_end: float | None = None
    curviness: float | None = None

    def in_use(self, who="TendonForceLengthCurve"):
        """(k_iso, f_toe, curviness) as OpenSim uses them."""
        opt = (self.stiffness_at_one_norm_force, self.norm_force_at_toe_end, self.curviness)
        if all(v is None for v in opt):
            return 1.375 / self.strain_at_one_norm_force, 2.0 / 3.0, 0.5
        if any(v is None for v in opt):
            raise CurveError(f"{who}: stiffness_at_one_norm_force, norm_force_at_toe_end and curviness "
                             "must all be given or all be absent")
        return tuple(float(v) for v in opt)

    def table(self, who="TendonForceLengthCurve"):
        e_iso = self.strain_at_one_norm_force
        _require(who, "strain_at_one_norm_force", e_iso, lambda v: v > 0, "> 0")
        k_iso, f_toe, curv = self.in_use(who)
        _require(who, "norm_force_at_toe_end", f_toe, lambda v: 0 < v < 1, "in (0, 1)")
        _require(who, "stiffness_at_one_norm_force", k_iso, lambda v: v > 1 / e_iso,
                 f"> 1/strain_at_one_norm_force = {1 / e_iso:g}")
        _require(who, "curviness", curv, lambda v: 0 <= v <= 1, "in [0, 1]")
        c = _curviness(curv)
        x_iso = 1.0 + e_iso
        x_toe = (f_toe - 1.0) / k_iso + x_iso
        x_foot = 1.0 + (x_toe - 1.0) / 10.0
        y_toe_mid = 0.5 * f_toe
        x_toe_mid = (y_toe_mid - 1.0) / k_iso + x_iso
        k_mid = y_toe_mid / (x_toe_mid - x_foot)
        x_ctrl = x_foot + 0.5 * (x_toe_mid - x_foot)
        y_ctrl = k_mid * (x_ctrl - x_foot)
        corners = [_corner(1.0, 0.0, 0.0, x_ctrl, y_ctrl, k_mid, c, who),
                   _corner(x_ctrl, y_ctrl, k_mid, x_toe, f_toe, k_iso, c, who)]
        return _flatten(corners, 1.0, x_toe, 0.0, f_toe, 0.0, k_iso)


def curve_table(curve, who=None):
    """The flattened curve (CURVE_WIDTH,) of a curve object (for :func:`evaluate_curve`)."""
    return curve.table(who or type(curve).__name__)


# ------------------------------------------------------------------------- numba kernels
@njit(cache=True)
def _bezier(u, p, k):
    """Quintic Bézier value and du-derivative of control points p[k:k+6]."""
    v = 1.0 - u
    u2, v2 = u * u, v * v
    u3, v3 = u2 * u, v2 * v
    u4, v4 = u3 * u, v3 * v
    b0, b1, b2, b3, b4, b5 = p[k], p[k + 1], p[k + 2], p[k + 3], p[k + 4], p[k + 5]
    val = (v4 * v * b0 + 5.0 * v4 * u * b1 + 10.0 * v3 * u2 * b2
           + 10.0 * v2 * u3 * b3 + 5.0 * v * u4 * b4 + u4 * u * b5)
    der = 5.0 * (v4 * (b1 - b0) + 4.0 * v3 * u * (b2 - b1) + 6.0 * v2 * u2 * (b3 - b2)
                 + 4.0 * v * u3 * (b4 - b3) + u4 * (b5 - b4))
    return val, der


@njit(cache=True)
def curve_value(c, o, x):
    """Value and dy/dx of the flattened curve c[o:o+CURVE_WIDTH] at x."""
    n = int(c[o])
    x0, x1 = c[o + 1], c[o + 2]
    if x < x0:
        return c[o + 3] + c[o + 5] * (x - x0), c[o + 5]
    if x > x1:
        return c[o + 4] + c[o + 6] * (x - x1), c[o + 6]
    if x != x:
        return np.nan, np.nan
    seg = n - 1
    for i in range(n):
        k = o + 7 + SEGMENT_WIDTH * i
        if c[k] <= x < c[k + 5]:
            seg = i
            break
    kx = o + 7 + SEGMENT_WIDTH * seg
    ky = kx + 6
    # start: linear between the samples x(j/N) around x
    ks = kx + 12
    j = 0
    while j < N_SAMPLES - 1 and x >= c[ks + j + 1]:
        j += 1
    xa, xb = c[ks + j], c[ks + j + 1]
    t = (x - xa) / (xb - xa) if xb > xa else 0.0
    u = min(max((j + t) / N_SAMPLES, 0.0), 1.0)
    lo, hi = 0.0, 1.0
    for _ in range(100):
        f, df = _bezier(u, c, kx)
        f -= x
        if abs(f) <= 1e-15 * max(1.0, abs(x)):
            break
        if f < 0.0:
            lo = u
        else:
            hi = u
        u_new = u - f / df if df > 0.0 else -1.0
        if not (lo <= u_new <= hi):
            u_new = 0.5 * (lo + hi)
        if abs(u_new - u) <= 4e-16 or hi - lo < 1e-17:  # at round-off (no further progress)
            u = u_new
            break
        u = u_new
    dx, dxdu = _bezier(u, c, kx)
    y, dydu = _bezier(u, c, ky)
    return y, dydu / dxdu


@njit(cache=True)
def _evaluate_many(c, xs, out_y, out_dy):
    for i in range(xs.shape[0]):
        out_y[i], out_dy[i] = curve_value(c, np.int64(0), xs[i])


def evaluate_curve(curve, x):
    """(value, dy/dx) of a curve (object or flattened table) at x (any shape)."""
    table = curve if isinstance(curve, np.ndarray) else curve_table(curve)
    xs = np.atleast_1d(np.asarray(x, dtype=float))
    y, dy = np.empty(xs.size), np.empty(xs.size)
    _evaluate_many(table, np.ascontiguousarray(xs.ravel()), y, dy)
    if np.ndim(x) == 0:
        return float(y[0]), float(dy[0])
    return y.reshape(xs.shape), dy.reshape(xs.shape)
