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

form a banded system (3m − 2 diagonals below and above the main one: 7 for the quintic,
4 for the cubic) that LAPACK's banded LU with partial pivoting (``dgbtrf``) factors
in O(n); every column is then one ``dgbtrs`` solve. The matrix depends on the knots and
the degree only, so the last few factorizations are kept: a file's force, point and torque
columns (ExternalLoads' data, 2 000 Hz, 8 000 samples) are splined on one factorization. In this local
form the system stays well conditioned for uneven steps (eliminating first to the knot
derivatives, the textbook route, lost five digits when one step was 100 times shorter
than its neighbour). tests/test_natural_spline.py checks the result against exact
rational arithmetic and against OpenSim's GCVSpline.
"""

from __future__ import annotations

from math import factorial

import numpy as np

__all__ = ["natural_spline_coefficients"]

#: the factorizations kept, (knots' bytes, degree) -> (LU, pivots, lower, upper)
_FACTORS: dict = {}
_KEEP = 4


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
    from scipy.linalg import lapack

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
    key = (x.tobytes(), degree)
    factors = _FACTORS.get(key)
    if factors is None:
        factors = _FACTORS[key] = _factor(h, m)
        while len(_FACTORS) > _KEEP:
            _FACTORS.pop(next(iter(_FACTORS)))
    lu, piv, lower, upper = factors
    base = (m - 1) + size * np.arange(n - 1)                  # the first row of piece i
    rhs = np.zeros((size * (n - 1), Y2.shape[1]))
    rhs[base] = Y2[:-1]
    rhs[base + 1] = Y2[1:]
    local, info = lapack.dgbtrs(lu, lower, upper, rhs, piv)
    if info != 0:  # pragma: no cover - LAPACK's argument checks
        raise ValueError(f"natural spline of degree {degree}: LAPACK dgbtrs info {info}")
    local = local.reshape(n - 1, size, -1)
    return local / (h[:, None] ** np.arange(size))[:, :, None]


def _factor(h, m):
    """LAPACK's banded LU (``dgbtrf``) of the natural spline's system (module docstring)
    on knot steps ``h (n − 1,)`` for half-order m: (LU, pivots, lower and upper band)."""
    from scipy.linalg import lapack

    n = h.shape[0] + 1
    size = 2 * m
    lower, upper = size + m - 2, size + m - 2
    unknowns = size * (n - 1)
    ab = np.zeros((2 * lower + upper + 1, unknowns))  # dgbtrf's storage: lower extra rows for the fill-in
    ends = [_ends(j, size) for j in range(size)]
    k = np.arange(size)

    def put(rows, first_col, values):       # a[rows[r], first_col[r] + k] = values[r, k]
        cols = first_col[:, None] + k
        ab[lower + upper + rows[:, None] - cols, cols] = values

    one = np.ones(1, dtype=int)
    # rows: m − 1 natural conditions at x_0, then per piece i its two values and (i < n − 2)
    # the 2m − 2 continuity rows with piece i + 1, then m − 1 natural conditions at x_{n−1}
    base = (m - 1) + size * np.arange(n - 1)                  # the first row of piece i
    for q, j in enumerate(range(m, size - 1)):
        put(q * one, 0 * one, ends[j][0][None, :])
        put((base[-1] + 2 + q) * one, size * (n - 2) * one, ends[j][1][None, :])
    first = size * np.arange(n - 1)
    put(base, first, np.broadcast_to(ends[0][0], (n - 1, size)))
    put(base + 1, first, np.broadcast_to(ends[0][1], (n - 1, size)))
    if n > 2:
        inner = np.arange(n - 2)
        short = np.minimum(h[:-1], h[1:])
        for j in range(1, size - 1):
            rows = base[inner] + 1 + j
            put(rows, first[inner], ends[j][1][None, :] * ((short / h[:-1]) ** j)[:, None])
            put(rows, first[inner] + size, -ends[j][0][None, :] * ((short / h[1:]) ** j)[:, None])
    lu, piv, info = lapack.dgbtrf(ab, lower, upper)
    if info != 0:
        raise ValueError(f"natural spline: the system is singular (LAPACK dgbtrf info {info})")
    return lu, piv, lower, upper
