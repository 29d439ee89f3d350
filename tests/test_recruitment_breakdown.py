"""Polynomial recruitment where the interior point breaks down (recruitment/polynomial.py).

jam-resources' full_body_healthy_knee.osim has no arm muscles: reserves of optimal force
1 N m carry the arms, with activities of hundreds, beside muscles whose activities sit
1e-15 from 0. The interior point continued to the 1e-10 tolerance then met barrier terms
z/x of 1e20 and gave NaN; the first polish (8 dual Newton steps) had not converged, and
32 of its 515 gait frames failed although feasible. Here: random problems of that shape
(90 muscles, 10 reserve pairs, rows only the reserves can carry 3 kN m), the breakdown
checked on the solver's own stages, and the answer checked against the optimality
conditions with multipliers computed here, independently of the solver's."""

import numpy as np
import pytest

from openfdk.recruitment.dual_newton import DUAL_CONVERGED, power_box_dual_newton
from openfdk.recruitment.interior_point import IPM_CONVERGED, ipm_starting_point, power_box_ipm
from openfdk.recruitment.polynomial import _IPM_LOOSE_TOL, _POLISH_MAX_ITER, _RANK_RTOL, _CONSISTENCY_RTOL
from openfdk.recruitment.polynomial import solve_polynomial
from openfdk.recruitment.reduction import reduce_problem

P = 3.0


def _problem(seed, n_m=90, n_r=10, rows=30, load=3000.0):
    """(C, d, n_bounded, s, upper): muscles of 100–2500 N with sparse moment arms (m),
    then a reserve pair (±, optimal force 1, no upper bound) on each of the first n_r
    rows; three of those rows carry ±load beyond what the muscles give."""
    rng = np.random.default_rng(seed)
    C_m = rng.normal(0.0, 0.03, (rows, n_m)) * (rng.random((rows, n_m)) < 0.3)
    C_r = np.zeros((rows, n_r))
    C_r[np.arange(n_r), np.arange(n_r)] = 1.0
    C = np.c_[C_m, C_r, -C_r]
    s = np.r_[rng.uniform(100.0, 2500.0, n_m), np.ones(2 * n_r)]
    upper = np.r_[np.ones(n_m), np.full(2 * n_r, np.inf)]
    d = C_m @ (rng.uniform(0.0, 0.2, n_m) * s[:n_m])
    d[:3] += load * rng.choice([-1.0, 1.0], 3)
    return C, d, n_m + 2 * n_r, s, upper


def _stages_break_down(C, d, nb, s, upper, tol=1e-10):
    """Whether the solver's former path fails on this problem: the interior point
    converges to the loose tolerance, its polish of _POLISH_MAX_ITER steps does not, and
    the interior point continued to ``tol`` does not converge."""
    lower = np.zeros(nb)
    _, _, A_r, b_r, *_ = reduce_problem(C, d, nb, s, _RANK_RTOL, _CONSISTENCY_RTOL)
    x, z, w, mu = ipm_starting_point(A_r, b_r, P, lower, upper)
    if power_box_ipm(A_r, b_r, P, lower, upper, x, z, w, mu, _IPM_LOOSE_TOL, 100)[0] != IPM_CONVERGED:
        return False
    polished = power_box_dual_newton(A_r, b_r, P, lower, upper, mu.copy(), tol, np.int64(_POLISH_MAX_ITER))[2]
    if polished == DUAL_CONVERGED:
        return False
    return power_box_ipm(A_r, b_r, P, lower, upper, x, z, w, mu, tol, 100)[0] != IPM_CONVERGED


def _optimality(C, d, nb, s, upper, f):
    """(max |C f − d| N, stationarity error, smallest reduced gradient of the columns at
    0 (activities below 1e-9 of the largest)), all relative to the gradient's scale, with λ the least-squares multipliers of the
    columns strictly inside their bounds and the free ones: for the optimum of
    Σ (f/s)^p the first two vanish and the last is ≥ 0."""
    x = f[:nb] / s
    near = 1e-9 * max(1.0, x.max())  # (an interior-point answer leaves tol · x_max at a bound)
    inner = (x > near) & (x < upper * (1.0 - 1e-9))
    cols = np.r_[np.flatnonzero(inner), np.arange(nb, C.shape[1])]
    grad = np.r_[P * x[inner] ** (P - 1) / s[inner], np.zeros(C.shape[1] - nb)]
    lam = np.linalg.lstsq(C[:, cols].T, grad, rcond=None)[0]
    g = C.T @ lam
    scale = np.abs(grad).max()
    at_zero = x <= near
    reduced = (P * np.maximum(x[at_zero], 0.0) ** (P - 1) / s[at_zero] - g[:nb][at_zero]) / scale
    return np.abs(C @ f - d).max(), np.abs(g[cols] - grad).max() / scale, reduced.min()


@pytest.mark.parametrize("seed", [14, 42, 54, 65])
def test_a_problem_the_interior_point_breaks_down_on_is_solved_to_its_optimum(seed):
    C, d, nb, s, upper = _problem(seed)
    assert _stages_break_down(C, d, nb, s, upper)  # what failed before
    r = solve_polynomial(C, d, nb, s, P, upper=upper)
    assert r.converged, r.message
    residual, stationarity, reduced = _optimality(C, d, nb, s, upper, r.f)
    assert residual < 1e-7 * np.abs(d).max()
    assert stationarity < 1e-10 and reduced > -1e-10
    assert np.max(r.f[nb - 20:nb]) > 2000.0  # the reserves carry kN m, activities of thousands
    assert r.f[:nb].min() >= 0.0 and np.all(r.f[:90] <= s[:90] * (1 + 1e-12))


def test_more_problems_of_that_shape_are_solved_to_their_optimum():
    """Twelve more seeds (most of which the loose stage's polish solves): each answer is
    the optimum, whichever stage gave it."""
    checked = 0
    for seed in range(12):
        C, d, nb, s, upper = _problem(seed)
        r = solve_polynomial(C, d, nb, s, P, upper=upper)
        assert r.converged, (seed, r.message)
        residual, stationarity, reduced = _optimality(C, d, nb, s, upper, r.f)
        assert residual < 1e-7 * np.abs(d).max() and stationarity < 1e-10 and reduced > -1e-10, seed
        checked += 1
    assert checked == 12
