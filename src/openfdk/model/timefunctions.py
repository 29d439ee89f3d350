"""Functions of time for drivers: value, first and second derivative.

Each function maps t (s) to an array of ``size`` values (in the driven measure's SI
units) and provides ``derivatives(t) -> (f, ḟ, f̈)``. Declared in model files by type
and parameters (never as expressions to evaluate, docs/design.md §4).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from openfdk.numerics.cubic_spline import NotAKnotSpline
from openfdk.numerics.natural_spline import natural_spline_coefficients
from openfdk.numerics.spline_columns import SplineColumns

__all__ = ["Constant", "Polynomial", "Fourier", "SplineThroughData", "TimeFunction"]


class TimeFunction:
    size: int = 1

    def derivatives(self, t):  # pragma: no cover - interface
        """Returns (f (size,), ḟ (size,), f̈ (size,)) at time t (s)."""
        raise NotImplementedError


def _as_rows(a, what):
    arr = np.asarray(a, dtype=float)
    if arr.ndim == 1:
        arr = arr[:, None]
    if arr.ndim != 2 or not np.all(np.isfinite(arr)):
        raise ValueError(f"{what}: expected finite numbers, got {a!r}")
    return arr


class Constant(TimeFunction):
    """f(t) = c. value : (size,)."""

    def __init__(self, value):
        self.value = np.atleast_1d(np.asarray(value, dtype=float))
        self.size = self.value.size

    def derivatives(self, t):
        z = np.zeros(self.size)
        return self.value.copy(), z, z.copy()


class Polynomial(TimeFunction):
    """f(t) = Σ_k c_k t^k. coefficients : (n_terms,) or (n_terms, size), c_0 first."""

    def __init__(self, coefficients):
        self.c = _as_rows(coefficients, "polynomial coefficients")
        self.size = self.c.shape[1]
        k = np.arange(self.c.shape[0], dtype=float)
        self.dc = (self.c * k[:, None])[1:]
        self.ddc = (self.dc * k[1:, None] - self.dc)[1:] if len(self.dc) else self.dc

    @staticmethod
    def _eval(c, t):
        out = np.zeros(c.shape[1])
        for row in c[::-1]:
            out = out * t + row
        return out

    def derivatives(self, t):
        return self._eval(self.c, t), self._eval(self.dc, t), self._eval(self.ddc, t)


class Fourier(TimeFunction):
    """f(t) = a_0 + Σ_{k≥1} a_k cos(k ω t) + b_k sin(k ω t), ω = 2π·frequency.

    a : (n+1,) or (n+1, size) with a_0 first; b : (n,) or (n, size); frequency in Hz.
    """

    def __init__(self, frequency, a, b):
        self.omega = 2.0 * np.pi * float(frequency)
        self.a = _as_rows(a, "fourier a")
        self.b = _as_rows(b, "fourier b")
        if self.b.shape[0] != self.a.shape[0] - 1 or self.b.shape[1] != self.a.shape[1]:
            raise ValueError(
                f"fourier: need len(b) = len(a) - 1 with equal widths, got a{self.a.shape} b{self.b.shape}"
            )
        self.size = self.a.shape[1]

        self._kw = np.arange(1, self.a.shape[0], dtype=float) * self.omega  # (n,) rad/s

    def derivatives(self, t):
        f, df, ddf = np.empty(self.size), np.empty(self.size), np.empty(self.size)
        _fourier(self._kw, self.a, self.b, float(t), f, df, ddf)
        return f, df, ddf


@njit(cache=True)
def _fourier(kw, a, b, t, f, df, ddf):
    """f, ḟ, f̈ (size,) of the Fourier series at t (s): kw (n,) rad/s the harmonics'
    k ω, a (n+1, size), b (n, size) (one compiled loop)."""
    for j in range(f.shape[0]):
        v, dv, ddv = a[0, j], 0.0, 0.0
        for k in range(kw.shape[0]):
            w = kw[k]
            c, s = np.cos(w * t), np.sin(w * t)
            v += c * a[k + 1, j] + s * b[k, j]
            dv += -w * s * a[k + 1, j] + w * c * b[k, j]
            ddv -= w * w * c * a[k + 1, j] + w * w * s * b[k, j]
        f[j], df[j], ddf[j] = v, dv, ddv


class SplineThroughData(TimeFunction):
    """A spline through samples: the C² cubic with not-a-knot ends (``natural`` None), or
    the natural spline of degree ``natural`` ∈ {1, 3, 5}, which OpenSim's ``GCVSpline``
    with error variance 0 is (:mod:`openfdk.numerics.natural_spline`; OpenSim's
    InverseDynamicsTool fits degree 5 to a coordinate file).

    times : (n,) s strictly increasing; values : (n,) or (n, size). Outside the sample
    range the end polynomials are extrapolated — a driver evaluated there is the user's
    choice, so :meth:`derivatives` raises instead when ``extrapolate`` is False.
    """

    def __init__(self, times, values, extrapolate=False, natural=None):
        times = np.asarray(times, dtype=float)
        values = _as_rows(values, "spline values")
        if times.ndim != 1 or len(times) < 2 or np.any(np.diff(times) <= 0):
            raise ValueError("spline: times must be a strictly increasing list of at least 2 values")
        if len(times) != values.shape[0]:
            raise ValueError(f"spline: {len(times)} times but {values.shape[0]} values")
        self.size = values.shape[1]
        self.t_range = (times[0], times[-1])
        self.extrapolate = extrapolate
        if natural is None:
            self._s = NotAKnotSpline(times, values)
        else:
            self._s = SplineColumns(times, natural_spline_coefficients(times, values, natural))

    def derivatives_range_check(self, t):
        """Raise ValueError when t (s) is outside the data and extrapolation is off."""
        lo, hi = self.t_range
        if not self.extrapolate and not (lo - 1e-12 <= t <= hi + 1e-12):
            raise ValueError(f"spline driver evaluated at t = {t} s outside its data [{lo}, {hi}] s")

    def derivatives(self, t):
        self.derivatives_range_check(t)
        return self._s.derivatives(t)


def sampled_time_range(functions):
    """(first, last) s over which every sampled, not extrapolated time function among
    ``functions`` (:class:`SplineThroughData`; others and None are skipped) has data, or
    (−inf, inf) when none is sampled."""
    lo, hi = -np.inf, np.inf
    for function in functions:
        if isinstance(function, SplineThroughData) and not function.extrapolate:
            lo, hi = max(lo, float(function.t_range[0])), min(hi, float(function.t_range[1]))
    return lo, hi
