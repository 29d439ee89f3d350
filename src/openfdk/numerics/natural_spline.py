"""The interpolating natural spline of odd degree 2m − 1 (m = 1, 2, 3) through n ≥ 2m
points, for any number of points and of columns: what Woltring's GCVSPL computes with
error variance 0 (OpenSim's ``GCVSpline``; de Boor, *A Practical Guide to Splines*,
Ch. XIV). It is C^{2m−2} at the interior knots and its derivatives m … 2m−2 vanish at both
end knots (for m = 3, the quintic OpenSim's InverseDynamicsTool and StaticOptimization
fit to a coordinate file: f‴ = f⁗ = 0 at the ends).

Piece i is written in t = (x − x_i)/h_i ∈ [0, 1] with 2m coefficients a_ik h_i^k. The
2m·(n − 1) equations, in this order,

* the m − 1 natural conditions at x_0 (piece 0),
* for each piece i: its values at both ends, then (i < n − 2) the continuity of
  derivatives 1 … 2m−2 with piece i + 1, each row multiplied by min(h_i, h_{i+1})^j so
  that it is O(1) whatever the steps,
* the m − 1 natural conditions at x_{n−1} (piece n − 2),

form a banded system (at most 2m + 1 diagonals below and above the main one) that LAPACK's
banded LU with partial pivoting solves in O(n) for every column at once. In this local
form the system stays well conditioned for uneven steps (eliminating first to the knot
derivatives, the textbook route, lost five digits when one step was 100 times shorter
than its neighbour). tests/test_natural_spline.py checks the result against exact
rational arithmetic and against OpenSim's GCVSpline.
"""

from __future__ import annotations

from math import factorial

import numpy as np

__all__ = ["natural_spline_coefficients"]


def _ends(j, size):
    """(row at t = 0, row at t = 1) of g^(j) for g = Σ_k a_k t^k, k < size."""
    at0 = np.zeros(size)
    at0[j] = factorial(j)
    at1 = np.array([factorial(k) // factorial(k - j) if k >= j else 0 for k in range(size)], float)
    return at0, at1


def natural_spline_coefficients(x, Y, degree: int) -> np.ndarray:
    """Coefficients ``(n − 1, 2m, k)`` of the natural spline of odd ``degree`` = 2m − 1 ∈
    {1, 3, 5} through the columns of ``Y (n,) or (n, k)`` at knots ``x (n,)`` (strictly
    increasing, n ≥ 2m; any unit): entry ``[i, j, c]`` multiplies (x − x_i)^j on
    [x_i, x_{i+1}] for column c (unit of Y per unit of x^j). Raises ValueError for a
    degree, knot count or knot order it cannot build."""
    from scipy.linalg import solve_banded

    degree = int(degree)
    if degree not in (1, 3, 5):
        raise ValueError(f"natural spline: degree must be 1, 3 or 5, got {degree}")
    m = (degree + 1) // 2
    size = 2 * m
    x = np.asarray(x, dtype=np.float64)
    Y = np.asarray(Y, dtype=np.float64)
    Y2 = Y[:, None] if Y.ndim == 1 else Y
    n = x.shape[0]
    if x.ndim != 1 or Y2.ndim != 2 or Y2.shape[0] != n or n < size:
        raise ValueError(f"natural spline of degree {degree}: needs at least {size} knots with one row of "
                         f"values each, got knots {x.shape} and values {Y.shape}")
    h = np.diff(x)
    if not np.all(h > 0.0):
        raise ValueError(f"natural spline of degree {degree}: knots must increase strictly")
    unknowns = size * (n - 1)
    band = size + 1                         # diagonals below and above the main one (at most)
    ab = np.zeros((2 * band + 1, unknowns))
    rhs = np.zeros((unknowns, Y2.shape[1]))

    def put(row, col, values):              # a[row, col + k] = values[k] in LAPACK's band storage
        cols = col + np.arange(len(values))
        ab[band + row - cols, cols] = values

    ends = [_ends(j, size) for j in range(size)]
    r = 0
    for j in range(m, size - 1):            # natural conditions at x_0
        put(r, 0, ends[j][0])
        r += 1
    for i in range(n - 1):
        put(r, size * i, ends[0][0])
        rhs[r] = Y2[i]
        put(r + 1, size * i, ends[0][1])
        rhs[r + 1] = Y2[i + 1]
        r += 2
        if i < n - 2:                       # C^(2m−2) at x_{i+1}
            short = min(h[i], h[i + 1])
            for j in range(1, size - 1):
                put(r, size * i, ends[j][1] * (short / h[i]) ** j)
                put(r, size * (i + 1), -ends[j][0] * (short / h[i + 1]) ** j)
                r += 1
    for j in range(m, size - 1):            # natural conditions at x_{n−1}
        put(r, size * (n - 2), ends[j][1])
        r += 1
    local = solve_banded((band, band), ab, rhs, check_finite=False).reshape(n - 1, size, -1)
    return local / (h[:, None] ** np.arange(size))[:, :, None]
