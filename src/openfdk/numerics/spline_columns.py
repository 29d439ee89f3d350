"""Columns of one piecewise polynomial on shared knots, evaluated with their first two
derivatives: the form of every spline a driver or a load follows through data whose
coefficients come from elsewhere (:mod:`openfdk.numerics.natural_spline`'s natural
splines of degree 1, 3 or 5).

On knots x_0 < … < x_{n−1}, column c is Σ_j coef[i, j, c] (t − x_i)^j on
[x_i, x_{i+1}]; outside [x_0, x_{n−1}] the end pieces are extrapolated, and at an
interior knot the piece to its right is used. Value and derivatives come from one Horner
pass over the coefficients (p, p′ and p″/2 updated together), in one compiled kernel when
written into a caller's arrays.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .cubic_spline import pieces_at

__all__ = ["SplineColumns"]


class SplineColumns:
    """Piecewise polynomial columns: ``x (n,)`` knots (strictly increasing) and
    ``coef (n − 1, w, k)`` (module docstring). Units: those of the data — y per unit
    of x^j for coefficient j."""

    def __init__(self, x, coef):
        self.x = np.ascontiguousarray(x, dtype=np.float64)
        self.coef = np.ascontiguousarray(coef, dtype=np.float64)
        if self.x.ndim != 1 or self.coef.ndim != 3 or self.coef.shape[0] != self.x.shape[0] - 1:
            raise ValueError(f"spline columns: {self.x.shape} knots and coefficients {self.coef.shape} "
                             "do not match (n knots, n − 1 pieces)")
        self._knots = self.x.tolist()

    def derivatives(self, t: float):
        """(s, ṡ, s̈) at the scalar ``t``: three arrays ``(k,)`` in units of y, y per unit
        of x, y per unit of x²."""
        k = self.coef.shape[2]
        f, df, ddf = np.empty(k), np.empty(k), np.empty(k)
        _derivatives_into(self.x, self.coef, float(t), np.arange(k), f, df, ddf)
        return f, df, ddf

    def derivatives_into(self, t, rows, f, df, ddf):
        """:meth:`derivatives` at the scalar ``t`` written into entries ``rows (k,)`` int of
        f, df, ddf (one compiled call)."""
        _derivatives_into(self.x, self.coef, float(t), rows, f, df, ddf)

    def derivatives_over(self, times):
        """(s, ṡ, s̈) at every entry of ``times (nf,)``: three arrays ``(nf, k)``, what
        :meth:`derivatives_into` gives one time at a time (the same pieces, the same
        arithmetic)."""
        i, tau = pieces_at(self.x, times)
        c = self.coef[i]  # (nf, w, k)
        p = c[:, -1].copy()
        dp = np.zeros_like(p)
        half_ddp = np.zeros_like(p)
        for j in range(c.shape[1] - 2, -1, -1):
            half_ddp = half_ddp * tau + dp
            dp = dp * tau + p
            p = p * tau + c[:, j]
        return p, dp, 2.0 * half_ddp

    def values(self, times):
        """s at every entry of ``times (nf,)``: ``(nf, k)`` in units of y (the value's
        Horner pass of :meth:`derivatives_over` alone)."""
        i, tau = pieces_at(self.x, times)
        c = self.coef[i]  # (nf, w, k)
        p = c[:, -1].copy()
        for j in range(c.shape[1] - 2, -1, -1):
            p = p * tau + c[:, j]
        return p


@njit(cache=True)
def _derivatives_into(x, coef, t, rows, f, df, ddf):  # pragma: no cover - compiled (numba)
    """f[rows], df[rows], ddf[rows] ← (s, ṡ, s̈) at t of the columns with knots x (n,)
    and coefficients coef (n − 1, w, k) (:class:`SplineColumns`)."""
    i = min(max(np.searchsorted(x, t, side="right") - 1, 0), x.shape[0] - 2)
    tau = t - x[i]
    w = coef.shape[1]
    for c in range(rows.shape[0]):
        p = coef[i, w - 1, c]
        dp = 0.0
        half_ddp = 0.0
        for j in range(w - 2, -1, -1):
            half_ddp = half_ddp * tau + dp
            dp = dp * tau + p
            p = p * tau + coef[i, j, c]
        r = rows[c]
        f[r] = p
        df[r] = dp
        ddf[r] = 2.0 * half_ddp
