"""Polynomial muscle recruitment (paper Eq. 11): min Σ (f_i/s_i)^p s.t. C f = d, 0 ≤ f_B ≤ u s.

u is 1 for muscles and one-sided reactions (the paper's 0 ≤ f ≤ s); an actuator (OpenSim's
reserve and residual actuators, :mod:`openfdk.forces.actuators`) has s = its optimal force
(its weight) and u = its control limit, possibly +∞.

Pipeline (all numerical work in one numba call):

1. :func:`~openfdk.recruitment.reduction.reduce_problem` eliminates the free forces
   (joint reactions, FDK residual forces) and redundant rows, leaving
   min Σ x^p s.t. A_r x = b_r, 0 ≤ x ≤ u in the activities x = f_B/s (a column the free
   forces absorb is exactly zero there, so its force is exactly zero). On a whole-leg
   model it is about half of the solve (DM knee, 138 rows and 117 free columns: 0.6 of
   1.3 ms with the QR factors of the free columns; 2.1 of 2.6 ms with their singular value
   decomposition before); the warm-started dual Newton method below is about 0.1 ms.
2. Cold start: Mehrotra predictor–corrector primal–dual interior-point method
   (:mod:`~openfdk.recruitment.interior_point`; Wright 1997, ch. 10; Nocedal & Wright
   2006, Alg. 16.4 / §19.3) to a moderate tolerance, then
3. a dual Newton polish (:mod:`~openfdk.recruitment.dual_newton`) to ``tol``, which makes
   the active set exact (bounded forces exactly 0 or s). If it does not converge, the
   interior point goes on to 1e-8 and then to ``tol``, polished after each; if the
   interior point breaks down on the way (activities of thousands, a reserve's, beside
   ones 1e-15 from their bound), a longer polish from its last converged stage.
   Warm start (``x0`` = previous result or forces): the dual Newton method starts from the
   previous multipliers; it falls back to step 2 if it does not converge in 20 iterations.
4. Back-substitution of the free forces and of the multipliers λ of C f = d.

Infeasible frames (not enough strength, or a row nothing can balance) are diagnosed with a
phase-1 LP (:mod:`~openfdk.recruitment.diagnosis`) and returned with ``converged=False``;
rank-deficient free columns raise :class:`RankDeficientFreeColumnsError`.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from openfdk.recruitment.diagnosis import diagnose_infeasibility
from openfdk.recruitment.dense import power
from openfdk.recruitment.dual_newton import (
    DUAL_CONVERGED,
    multipliers_from_primal,
    power_box_dual_newton,
)
from openfdk.recruitment.interior_point import (
    IPM_CONVERGED,
    IPM_FAILED,
    ipm_starting_point,
    power_box_ipm,
)
from openfdk.recruitment.reduction import (
    REDUCE_INCONSISTENT_ROWS,
    REDUCE_RANK_DEFICIENT_FREE,
    free_forces,
    multiplier_to_reduced,
    reduce_problem,
)
from openfdk.recruitment.result import (
    STATUS_INFEASIBLE,
    STATUS_NOT_CONVERGED,
    STATUS_OPTIMAL,
    RecruitmentInputError,
    RecruitmentResult,
    check_problem,
    rank_deficiency_error,
    solve_without_zero_strength,
)

__all__ = ["solve_polynomial"]

# kernel status codes
_OPTIMAL = 0
_MAX_ITER = 1
_RANK_DEFICIENT_FREE = 2
_INCONSISTENT_ROWS = 3
_NUMERICAL_FAILURE = 4

_RANK_RTOL = 1e-11  # singular values below this × max|C s| count as zero
_CONSISTENCY_RTOL = 1e-9  # unbalanceable part of d above this × (‖d‖ + max|C s|) is infeasible
_IPM_LOOSE_TOL = 1e-6  # interior point stops here first; the dual Newton polish goes on
_IPM_MIDDLE_TOL = 1e-8  # … and here second, when that polish did not converge
_POLISH_MAX_ITER = 8
_WARM_MAX_ITER = 20
_LONG_POLISH_MAX_ITER = 50  # the polish after the interior point broke down


@njit(cache=True, error_model="numpy")
def _solve_polynomial_kernel(C, d, n_bounded, s, lower, upper, p, warm_mode, lam_start, x_start, tol,
                             max_iter):
    """Numba driver; lower, upper (n_B,) activity bounds l, u (+∞ allowed); warm_mode 0
    cold, 1 from multipliers λ (m,), 2 from activities x (n_B,).

    Returns f (n,) N, λ (m,), active_upper (n,) bool, active_lower (n,) bool,
    residual C f − d (m,), objective G, status code, iterations.
    """
    m, n = C.shape
    status_r, A_full, A_r, b_r, L, Q1, R_F, Sigma_r, Q2U_r = reduce_problem(
        C, d, n_bounded, s, _RANK_RTOL, _CONSISTENCY_RTOL
    )
    f = np.full(n, np.nan)
    lam = np.full(m, np.nan)
    bound_state = np.zeros(n_bounded, dtype=np.int8)
    r = A_r.shape[0]
    iterations = 0
    status = _OPTIMAL
    if status_r == REDUCE_RANK_DEFICIENT_FREE:
        status = _RANK_DEFICIENT_FREE
    elif status_r == REDUCE_INCONSISTENT_ROWS:
        status = _INCONSISTENT_ROWS
    x = np.zeros(n_bounded)
    mu = np.zeros(r)
    from_dual = True  # x from the dual Newton method: bounds exactly 0 or 1
    # (r = 0: the free forces balance everything, all bounded forces are zero)
    if r > 0 and status == _OPTIMAL:
        solved = False
        if warm_mode > 0:
            if warm_mode == 1:
                mu_start = multiplier_to_reduced(lam_start, Sigma_r, Q2U_r)
            else:
                mu_start = multipliers_from_primal(A_r, x_start, p, lower, upper)
            x, mu, dual_status, it = power_box_dual_newton(A_r, b_r, p, lower, upper, mu_start, tol,
                                                           np.int64(_WARM_MAX_ITER))
            iterations += it
            solved = dual_status == DUAL_CONVERGED
        if not solved:
            # interior point by stages (a loose tolerance, a middle one, ``tol``), each
            # continued from the last and followed by the dual Newton polish from its
            # multipliers; the first polish that converges gives the solution
            x_ipm, z_ipm, w_ipm, mu_ipm = ipm_starting_point(A_r, b_r, p, lower, upper)
            mu_good = mu_ipm.copy()
            have_good = False
            ipm_status = IPM_CONVERGED
            stage_tol = np.inf
            for stage in range(3):
                last = stage_tol
                stage_tol = max(tol, (_IPM_LOOSE_TOL, _IPM_MIDDLE_TOL, tol)[stage])
                if stage_tol >= last:
                    continue  # (tol looser than this stage's)
                ipm_status, it = power_box_ipm(A_r, b_r, p, lower, upper, x_ipm, z_ipm, w_ipm, mu_ipm, stage_tol,
                                               max_iter if stage == 0 else max(max_iter - iterations, 1))
                iterations += it
                if ipm_status != IPM_CONVERGED:
                    break
                mu_good[:] = mu_ipm
                have_good = True
                x, mu, dual_status, it = power_box_dual_newton(A_r, b_r, p, lower, upper, mu_ipm.copy(), tol,
                                                               np.int64(_POLISH_MAX_ITER if stage == 0
                                                                        else _WARM_MAX_ITER))
                iterations += it
                solved = dual_status == DUAL_CONVERGED
                if solved:
                    break
                if stage_tol == tol:
                    # the interior-point solution itself meets ``tol``: accept it, with
                    # the active set read from the bound multipliers
                    x = x_ipm
                    mu = mu_ipm
                    from_dual = False
                    solved = True
                    for j in range(n_bounded):
                        if z_ipm[j] > x_ipm[j] - lower[j]:
                            bound_state[j] = -1
                        elif w_ipm[j] > upper[j] - x_ipm[j]:
                            bound_state[j] = 1
                    break
            if not solved and have_good:
                # the continued interior point broke down: its barrier terms z/x reach 1e20
                # when activities of thousands (a reserve's) sit beside ones 1e-15 from
                # their bound (jam-resources' full_body_healthy_knee.osim, whose arms only
                # reserves move: 32 of 515 frames failed). A longer polish from the last
                # stage that converged: 9–30 steps on those problems
                x, mu, dual_status, it = power_box_dual_newton(A_r, b_r, p, lower, upper, mu_good, tol,
                                                               np.int64(_LONG_POLISH_MAX_ITER))
                iterations += it
                solved = dual_status == DUAL_CONVERGED
                from_dual = True
            if not solved:
                status = _NUMERICAL_FAILURE if ipm_status == IPM_FAILED else _MAX_ITER
    active_upper = np.zeros(n, dtype=np.bool_)
    active_lower = np.zeros(n, dtype=np.bool_)
    residual = np.full(m, np.nan)
    if status != _OPTIMAL:
        return f, lam, active_upper, active_lower, residual, np.nan, status, iterations
    objective = 0.0
    for j in range(n_bounded):
        objective += power(x[j], p)
        if from_dual:
            active_lower[j] = x[j] <= lower[j]
            active_upper[j] = x[j] >= upper[j]
        else:
            active_lower[j] = bound_state[j] < 0
            active_upper[j] = bound_state[j] > 0

    # f_B = s x; f_F = R_F⁻¹ Q1ᵀ (d − A x); λ = L μ
    for j in range(n_bounded):
        f[j] = s[j] * x[j]
    f[n_bounded:] = free_forces(Q1, R_F, d - A_full @ x)
    for i in range(m):
        acc = 0.0
        for a in range(r):
            acc += L[i, a] * mu[a]
        lam[i] = acc
    # residual C f − d (N, N·m)
    for i in range(m):
        acc = -d[i]
        for j in range(n):
            acc += C[i, j] * f[j]
        residual[i] = acc
    return f, lam, active_upper, active_lower, residual, objective, status, iterations


def _warm_start(x0, n_eq, n_var, n_bounded, s):
    """Translate ``x0`` into (warm_mode, λ_start (m,), x_start (n_B,))."""
    if x0 is None:
        return 0, np.zeros(n_eq), np.zeros(n_bounded)
    if isinstance(x0, RecruitmentResult):
        lam = np.asarray(x0.multipliers, dtype=np.float64)
        if x0.converged and lam.shape == (n_eq,) and np.isfinite(lam).all():
            return 1, np.ascontiguousarray(lam), np.zeros(n_bounded)
        x0 = x0.f
    x0 = np.asarray(x0, dtype=np.float64)
    if x0.shape != (n_var,):
        raise RecruitmentInputError(f"x0 must have shape ({n_var},) = (n_var,); got {x0.shape}")
    if not np.all(np.isfinite(x0[:n_bounded])):
        return 0, np.zeros(n_eq), np.zeros(n_bounded)
    return 2, np.zeros(n_eq), np.ascontiguousarray(x0[:n_bounded] / s)


def solve_polynomial(C, d, n_bounded, s, p=3.0, *, x0=None, tol=1e-10, max_iter=100,
                     row_names=None, column_names=None, upper=None, lower=None) -> RecruitmentResult:
    """Polynomial recruitment: minimise G = Σ_{i<n_bounded} (f_i/s_i)^p s.t. C f = d, l s ≤ f_B ≤ u s.

    Parameters
    ----------
    C : (n_eq, n_var) equilibrium matrix, columns ordered [bounded..., free...]
        (row units per column unit: 1 for force rows, m for moment rows of force columns).
    d : (n_eq,) N (force rows) or N·m (moment rows).
    n_bounded : int, number of bounded columns (muscles, unilateral reactions).
    s : (n_bounded,) N, strengths ≥ 0 (0 fixes that force at zero).
    p : float ≥ 2, exponent (3 = the paper's cubic criterion, 2 = quadratic).
    x0 : optional warm start — a previous :class:`RecruitmentResult` (its multipliers are
        used; best) or forces (n_var,) N.
    tol : tolerance on the equilibrium residual in scaled units (activity, dimensionless)
        after the free forces are eliminated, times the largest activity where that
        exceeds 1 (an actuator of optimal force 1 N carrying 2 000 N: an absolute 1e-10
        on activities of 2 000 is below the residual's round-off, and the solve failed
        although feasible); optimality and bounds hold exactly.
    max_iter : maximal interior-point iterations.
    row_names : optional (n_eq,) names used in messages; column_names : optional (n_var,).
    upper : optional (n_bounded,) activity bounds u > 0 (default 1: f_B ≤ s), +∞ for none:
        an actuator weighted by its optimal force s with control limit u.
    lower : optional (n_bounded,) activity bounds 0 ≤ l < u (default 0): a muscle's
        minimum activation (OpenSim's static optimisation).

    Returns
    -------
    RecruitmentResult (``criterion="polynomial"``). Infeasible frames return
    ``converged=False``, ``status="infeasible"`` and a message naming the rows.

    Raises
    ------
    RecruitmentInputError for malformed input, RankDeficientFreeColumnsError when the free
    columns are linearly dependent.
    """
    C, d, s = check_problem(C, d, n_bounded, s, row_names, column_names)
    upper = activity_bounds(upper, n_bounded)
    lower = lower_activity_bounds(lower, upper)
    if n_bounded and s.min() == 0.0:
        return solve_without_zero_strength(solve_polynomial, C, d, int(n_bounded), s,
                                           column_names=column_names, p=p, x0=x0, tol=tol,
                                           max_iter=max_iter, row_names=row_names, upper=upper, lower=lower)
    p = float(p)
    if not (np.isfinite(p) and p >= 2.0):
        raise RecruitmentInputError(f"exponent p must be a finite number ≥ 2; got {p!r}")
    n_eq, n_var = C.shape
    n_bounded = int(n_bounded)
    if n_bounded == 0 and n_eq == n_var:
        # no recruited column and as many free columns as rows (e.g. every coordinate
        # driven, OpenSim's inverse dynamics): C f = d has one solution, G = 0, λ = 0
        fast = _square_free_solution(C, d)
        if fast is not None:
            f, residual = fast
            zero = np.zeros(n_var, bool)
            return RecruitmentResult(
                f=f, converged=True, status=STATUS_OPTIMAL, message="optimal", iterations=0, objective=0.0,
                multipliers=np.zeros(n_eq), active_upper=zero, active_lower=zero.copy(), infeasible_rows=(),
                residual=residual, n_bounded=0, criterion="polynomial", p=p)
    warm_mode, lam_start, x_start = _warm_start(x0, n_eq, n_var, n_bounded, s)
    f, lam, active_upper, active_lower, residual, objective, code, iterations = \
        _solve_polynomial_kernel(
            C, d, n_bounded, s, lower, upper, p, warm_mode, lam_start, x_start, float(tol), int(max_iter)
        )
    if code == _RANK_DEFICIENT_FREE:
        _, sigma, VT = np.linalg.svd(C[:, n_bounded:])
        scale = max(np.max(np.abs(C[:, :n_bounded] * s), initial=0.0), np.max(np.abs(C)))
        rank = int(np.sum(sigma > _RANK_RTOL * scale))
        raise rank_deficiency_error(VT[rank:].T, n_bounded, column_names)
    if code == _OPTIMAL:
        return RecruitmentResult(
            f=f, converged=True, status=STATUS_OPTIMAL, message="optimal",
            iterations=int(iterations), objective=float(objective), multipliers=lam,
            active_upper=active_upper, active_lower=active_lower, infeasible_rows=(),
            residual=residual, n_bounded=n_bounded, criterion="polynomial", p=p,
        )
    return failed_result(C, d, n_bounded, s, p, iterations, row_names, "polynomial",
                         f"polynomial recruitment (p = {p:g})", upper=upper, lower=lower)


def _square_free_solution(C, d):
    """(f, residual C f − d) of a square system of free columns by one LU, or None when
    it is singular or ill-conditioned (the kernel then names the dependent columns)."""
    from ..kinematics.frame_kernels import small_solve

    try:
        f = small_solve(C, d)
    except np.linalg.LinAlgError:
        return None
    residual = C @ f - d
    scale = max(float(np.max(np.abs(d), initial=0.0)), 1.0)
    if not np.all(np.isfinite(f)) or np.max(np.abs(residual)) > 1e-8 * scale:
        return None
    return f, residual


def activity_bounds(upper, n_bounded):
    """The activity bounds u (n_bounded,) of :func:`solve_polynomial`: ones by default;
    each > 0 (+∞ allowed), else RecruitmentInputError."""
    if upper is None:
        return np.ones(int(n_bounded))
    upper = np.ascontiguousarray(upper, dtype=np.float64)
    if upper.shape != (int(n_bounded),):
        raise RecruitmentInputError(f"upper must have shape ({n_bounded},) = (n_bounded,); got {upper.shape}")
    if np.isnan(upper).any() or (upper <= 0.0).any():
        raise RecruitmentInputError("upper (activity bounds) must be > 0 (+inf for none)")
    return upper


def lower_activity_bounds(lower, upper):
    """The lower activity bounds l (n_bounded,) of :func:`solve_polynomial`: zeros by
    default; each 0 ≤ l < u, else RecruitmentInputError."""
    if lower is None:
        return np.zeros(upper.shape[0])
    lower = np.ascontiguousarray(lower, dtype=np.float64)
    if lower.shape != upper.shape:
        raise RecruitmentInputError(f"lower must have shape {upper.shape} = (n_bounded,); got {lower.shape}")
    if not (np.all(np.isfinite(lower)) and np.all(lower >= 0.0) and np.all(lower < upper)):
        raise RecruitmentInputError("lower (activity bounds) must be finite, ≥ 0 and below upper")
    return lower


def failed_result(C, d, n_bounded, s, p, iterations, row_names, criterion, what, upper=None, lower=None):
    """Result for a frame the solver could not solve: diagnose with the phase-1 LP.

    Returns RecruitmentResult with converged=False; status ``infeasible`` (rows named) or
    ``not_converged`` (the problem is feasible but the solver failed).
    """
    n_eq, n_var = C.shape
    diagnosis = diagnose_infeasibility(C, d, n_bounded, s, row_names, upper=upper, lower=lower)
    nan_lam = np.full(n_eq, np.nan)
    no_mask = np.zeros(n_var, dtype=bool)
    if diagnosis.feasible:
        status = STATUS_NOT_CONVERGED
        message = (f"{what} did not converge after {iterations} iterations although a "
                   "force set within the bounds meets equilibrium (phase-1 LP); "
                   "the forces returned are that feasible point, not the optimum")
    elif not diagnosis.rows:  # the phase-1 LP itself failed: neither verdict
        status = STATUS_NOT_CONVERGED
        message = f"{what} did not converge after {iterations} iterations; {diagnosis.message}"
    else:
        status = STATUS_INFEASIBLE
        message = diagnosis.message
    return RecruitmentResult(
        f=diagnosis.f, converged=False, status=status, message=message,
        iterations=int(iterations + diagnosis.iterations), objective=float("nan"),
        multipliers=nan_lam, active_upper=no_mask, active_lower=no_mask.copy(),
        infeasible_rows=diagnosis.rows, residual=diagnosis.residual, n_bounded=n_bounded,
        criterion=criterion, p=p,
    )
