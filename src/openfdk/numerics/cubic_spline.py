"""C² cubic interpolating spline with not-a-knot ends, written for openfdk so that reading
a trial or building a spline driver does not import ``scipy.interpolate`` (≈ 0.2 s of
imports — it brings scipy.special and scipy.optimize — on every ``openfdk`` command and
every study worker). It computes the spline ``scipy.interpolate.CubicSpline(x, y, axis=0,
bc_type="not-a-knot")`` computes, to round-off (tests/test_cubic_spline.py compares the two).

On knots x_0 < … < x_{n−1} with values y_i, steps h_i = x_{i+1} − x_i and secant slopes
δ_i = (y_{i+1} − y_i)/h_i, piece i is the cubic Hermite polynomial in τ = t − x_i

    p_i(τ) = y_i + m_i τ + c2_i τ² + c3_i τ³,
    c2_i = (3 δ_i − 2 m_i − m_{i+1}) / h_i,   c3_i = (m_i + m_{i+1} − 2 δ_i) / h_i²,

which is C¹ for any knot slopes m_i. The slopes follow from (de Boor, *A Practical Guide
to Splines*, rev. ed., Ch. IV):

* C² at each interior knot, i = 1 … n−2:
  h_i m_{i−1} + 2 (h_{i−1} + h_i) m_i + h_{i−1} m_{i+1} = 3 (h_i δ_{i−1} + h_{i−1} δ_i);
* not-a-knot at x_1 (p‴ continuous there, so pieces 0 and 1 are one cubic):
  h_1 m_0 + (h_0 + h_1) m_1 = ((3 h_0 + 2 h_1) h_1 δ_0 + h_0² δ_1) / (h_0 + h_1),
  and its mirror image at x_{n−2}:
  (h_{n−3} + h_{n−2}) m_{n−2} + h_{n−3} m_{n−1}
      = (h_{n−2}² δ_{n−3} + (2 h_{n−3} + 3 h_{n−2}) h_{n−3} δ_{n−2}) / (h_{n−3} + h_{n−2}).

The end rows are not diagonally dominant (|h_1| < |h_0 + h_1|), so they are first
subtracted from the C² rows at x_1 and x_{n−2}, which removes m_0 and m_{n−1}:

  (h_0 + h_1) m_1 + h_0 m_2 = r_1 − r_0,
  h_{n−2} m_{n−3} + (h_{n−3} + h_{n−2}) m_{n−2} = r_{n−2} − r_{n−1},

r_i being the right-hand side of the C² row i (r_0, r_{n−1}: of the end rows).

The remaining tridiagonal system in m_1 … m_{n−2} is strictly diagonally dominant for
any knot spacing and is solved by forward elimination and back substitution without
pivoting; m_0 and m_{n−1} then follow from the end rows. Three knots with not-a-knot at
both ends leave one parabola through the three points, and two knots the straight line
(as in scipy).

The solve runs in one numba kernel (``cache=True``), vectorised over the columns of y.
"""

from __future__ import annotations

from bisect import bisect_right

import numpy as np
from numba import njit

__all__ = ["NotAKnotSpline", "not_a_knot_coefficients", "pieces_at"]


def not_a_knot_coefficients(x, y) -> np.ndarray:
    """Coefficients ``(n − 1, 4, k)`` of the not-a-knot cubic spline through
    ``y (n,) or (n, k)`` at knots ``x (n,)`` (strictly increasing, n ≥ 2; any unit): entry
    ``[i, j, c]`` multiplies (t − x_i)^j on [x_i, x_{i+1}] for column c (units of y per
    unit of x^j). A 1-D ``y`` is one column (k = 1)."""
    x = np.ascontiguousarray(x, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    if x.ndim != 1 or x.shape[0] < 2:
        raise ValueError(f"spline: needs at least 2 knots in a 1-D array, got shape {x.shape}")
    if y.ndim not in (1, 2) or y.shape[0] != x.shape[0]:
        raise ValueError(f"spline: {x.shape[0]} knots but values of shape {y.shape}")
    Y = np.ascontiguousarray(y if y.ndim == 2 else y[:, None])
    h = np.diff(x)
    if not np.all(h > 0.0):
        raise ValueError("spline: knots must increase strictly")
    return _coefficients(x, Y)


@njit(cache=True)
def _coefficients(x, Y):  # pragma: no cover - compiled (numba); tested through not_a_knot_coefficients
    n, k = Y.shape
    coef = np.empty((n - 1, 4, k))
    m = np.empty(n)                        # knot slopes of one column
    diag = np.empty(n)
    rhs = np.empty(n)
    for c in range(k):
        if n == 2:
            m[0] = (Y[1, c] - Y[0, c]) / (x[1] - x[0])
            m[1] = m[0]
        elif n == 3:                        # the parabola through the three points
            h0, h1 = x[1] - x[0], x[2] - x[1]
            d0, d1 = (Y[1, c] - Y[0, c]) / h0, (Y[2, c] - Y[1, c]) / h1
            half_curvature = (d1 - d0) / (h0 + h1)
            m[0] = d0 - half_curvature * h0
            m[1] = d0 + half_curvature * h0
            m[2] = d1 + half_curvature * h1
        else:
            # rows 1 … n−2 in diag (diagonal) and rhs; sub-diagonal h_i, super-diagonal h_{i−1}
            h0, h1 = x[1] - x[0], x[2] - x[1]
            d0, d1 = (Y[1, c] - Y[0, c]) / h0, (Y[2, c] - Y[1, c]) / h1
            r_first = ((3.0 * h0 + 2.0 * h1) * h1 * d0 + h0 * h0 * d1) / (h0 + h1)
            for i in range(1, n - 1):
                hp, hi = x[i] - x[i - 1], x[i + 1] - x[i]
                dp, di = (Y[i, c] - Y[i - 1, c]) / hp, (Y[i + 1, c] - Y[i, c]) / hi
                diag[i] = 2.0 * (hp + hi)
                rhs[i] = 3.0 * (hi * dp + hp * di)
            hq, hl = x[n - 2] - x[n - 3], x[n - 1] - x[n - 2]
            dq, dl = (Y[n - 2, c] - Y[n - 3, c]) / hq, (Y[n - 1, c] - Y[n - 2, c]) / hl
            r_last = (hl * hl * dq + (2.0 * hq + 3.0 * hl) * hq * dl) / (hq + hl)
            diag[1] -= h0 + h1              # row 1 − end row at x_0 (removes m_0)
            rhs[1] -= r_first
            diag[n - 2] -= hq + hl          # row n−2 − end row at x_{n−1} (removes m_{n−1})
            rhs[n - 2] -= r_last
            # forward elimination (row 1 has no sub-diagonal after the subtraction)
            for i in range(2, n - 1):
                w = (x[i + 1] - x[i]) / diag[i - 1]       # sub-diagonal of row i: h_i
                diag[i] -= w * (x[i - 1] - x[i - 2])   # super-diagonal of row i−1: h_{i−2}
                rhs[i] -= w * rhs[i - 1]
            m[n - 2] = rhs[n - 2] / diag[n - 2]
            for i in range(n - 3, 0, -1):
                m[i] = (rhs[i] - (x[i] - x[i - 1]) * m[i + 1]) / diag[i]
            m[0] = (r_first - (h0 + h1) * m[1]) / h1
            m[n - 1] = (r_last - (hq + hl) * m[n - 2]) / hq
        for i in range(n - 1):
            h = x[i + 1] - x[i]
            d = (Y[i + 1, c] - Y[i, c]) / h
            coef[i, 0, c] = Y[i, c]
            coef[i, 1, c] = m[i]
            coef[i, 2, c] = (3.0 * d - 2.0 * m[i] - m[i + 1]) / h
            coef[i, 3, c] = (m[i] + m[i + 1] - 2.0 * d) / (h * h)
    return coef


def pieces_at(x, times):
    """(i (nf,) int, τ (nf, 1)) of every entry of ``times`` on knots ``x (n,)``: the piece
    [x_i, x_{i+1}] it is evaluated on (the end pieces outside the knots, the piece to the
    right at an interior knot) and its offset τ = t − x_i, in the unit of x."""
    times = np.asarray(times, dtype=np.float64).reshape(-1)
    i = np.clip(np.searchsorted(x, times, side="right") - 1, 0, len(x) - 2)
    return i, (times - x[i])[:, None]


class NotAKnotSpline:
    """The not-a-knot cubic spline through ``y (n,) or (n, k)`` at knots ``x (n,)``
    (:func:`not_a_knot_coefficients`), evaluated with its first two derivatives. Outside
    [x_0, x_{n−1}] the end pieces are extrapolated; at an interior knot the piece to its
    right is used (the spline is C² there, so either gives the same values)."""

    def __init__(self, x, y):
        self.x = np.asarray(x, dtype=np.float64)
        self.coef = not_a_knot_coefficients(self.x, y)   # (n − 1, 4, k)
        self._knots = self.x.tolist()

    def derivatives(self, t: float):
        """(s, ṡ, s̈) at the scalar ``t`` (unit of x): three arrays ``(k,)`` in units of y,
        y per unit of x, y per unit of x²."""
        i = min(max(bisect_right(self._knots, t) - 1, 0), len(self._knots) - 2)
        tau = t - self._knots[i]
        c0, c1, c2, c3 = self.coef[i]
        return (c0 + tau * (c1 + tau * (c2 + tau * c3)),
                c1 + tau * (2.0 * c2 + 3.0 * tau * c3),
                2.0 * c2 + 6.0 * tau * c3)

    def derivatives_into(self, t, rows, f, df, ddf):
        """:meth:`derivatives` at the scalar ``t`` written into entries ``rows`` (k,) int
        of f, df, ddf (one compiled call; the same piece, the same arithmetic)."""
        _derivatives_into(self.x, self.coef, float(t), rows, f, df, ddf)

    def derivatives_over(self, times):
        """(s, ṡ, s̈) at every entry of ``times`` (nf,): three arrays (nf, k), what
        :meth:`derivatives_into` gives one time at a time (the same pieces, the same
        arithmetic)."""
        i, tau = pieces_at(self.x, times)
        c0, c1, c2, c3 = (self.coef[i, j] for j in range(4))  # (nf, k) each
        return (c0 + tau * (c1 + tau * (c2 + tau * c3)),
                c1 + tau * (2.0 * c2 + 3.0 * tau * c3),
                2.0 * c2 + 6.0 * tau * c3)

    def values(self, times):
        """s at every entry of ``times`` (nf,) (unit of x): (nf, k) in units of y, the
        values :meth:`derivatives` gives one time at a time (the same pieces, the same
        arithmetic), for a whole trial's frames at once."""
        i, tau = pieces_at(self.x, times)
        c = self.coef[i]  # (nf, 4, k)
        return c[:, 0] + tau * (c[:, 1] + tau * (c[:, 2] + tau * c[:, 3]))


@njit(cache=True)
def _derivatives_into(x, coef, t, rows, f, df, ddf):  # pragma: no cover - compiled (numba)
    """f[rows], df[rows], ddf[rows] ← (s, ṡ, s̈) at t of the spline with knots x (n,) and
    coefficients coef (n − 1, 4, k) (:meth:`NotAKnotSpline.derivatives`)."""
    i = min(max(np.searchsorted(x, t, side="right") - 1, 0), x.shape[0] - 2)
    tau = t - x[i]
    for c in range(rows.shape[0]):
        c0, c1, c2, c3 = coef[i, 0, c], coef[i, 1, c], coef[i, 2, c], coef[i, 3, c]
        r = rows[c]
        f[r] = c0 + tau * (c1 + tau * (c2 + tau * c3))
        df[r] = c1 + tau * (2.0 * c2 + 3.0 * tau * c3)
        ddf[r] = 2.0 * c2 + 6.0 * tau * c3
