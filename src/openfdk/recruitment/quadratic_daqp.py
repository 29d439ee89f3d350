"""Quadratic recruitment (p = 2) with the DAQP active-set QP solver.

An alternative to :func:`openfdk.recruitment.polynomial.solve_polynomial` with ``p=2``:
after the free forces and redundant rows are eliminated
(:mod:`~openfdk.recruitment.reduction`) the problem is the strictly convex QP

    minimise ½ xᵀ(2I)x   s.t.   A_r x = b_r,   0 ≤ x ≤ 1,     x = f_B / s,

solved by DAQP, a dual active-set method (Arnström, Bemporad & Axehill, "A Dual Active-Set
Solver for Embedded Quadratic Programming Using Recursive LDLᵀ Updates", IEEE TAC 67(8),
2022). DAQP's Lagrangian is ½xᵀHx + λᵀ(A x − b) (sign opposite to openfdk's), hence
λ = −L λ_DAQP with L from the reduction.
(The reduction zeroes the columns the free forces absorb: :mod:`.reduction`.)
"""

from __future__ import annotations

import daqp
import numpy as np

from openfdk.recruitment.polynomial import failed_result
from openfdk.recruitment.reduction import (
    REDUCE_INCONSISTENT_ROWS,
    REDUCE_RANK_DEFICIENT_FREE,
    free_forces,
    reduce_problem,
)
from openfdk.recruitment.result import (
    STATUS_OPTIMAL,
    RecruitmentResult,
    check_problem,
    rank_deficiency_error,
    solve_without_zero_strength,
)

__all__ = ["solve_quadratic_daqp"]

_RANK_RTOL = 1e-11
_CONSISTENCY_RTOL = 1e-9
_DAQP_OPTIMAL = 1
_SENSE_EQUALITY = 5


def solve_quadratic_daqp(C, d, n_bounded, s, *, row_names=None, column_names=None,
                         primal_tol=1e-10) -> RecruitmentResult:
    """Quadratic recruitment min Σ (f_i/s_i)² s.t. C f = d, 0 ≤ f_B ≤ s, solved by DAQP.

    Parameters
    ----------
    C : (n_eq, n_var), columns ordered [bounded..., free...]; d : (n_eq,) N or N·m;
    n_bounded : int; s : (n_bounded,) N strengths ≥ 0 (0 fixes that force at zero);
    row_names, column_names : optional names for messages;
    primal_tol : DAQP's primal feasibility tolerance (scaled, dimensionless).

    Returns
    -------
    RecruitmentResult (``criterion="quadratic_daqp"``, ``p=2``); infeasible frames are
    diagnosed with the phase-1 LP like the other solvers.
    """
    C, d, s = check_problem(C, d, n_bounded, s, row_names, column_names)
    if n_bounded and s.min() == 0.0:
        return solve_without_zero_strength(solve_quadratic_daqp, C, d, int(n_bounded), s,
                                           column_names=column_names, row_names=row_names, primal_tol=primal_tol)
    n_eq, n_var = C.shape
    n_bounded = int(n_bounded)
    status, A_full, A_r, b_r, L, Q1, R_F, _, _ = reduce_problem(
        C, d, n_bounded, s, _RANK_RTOL, _CONSISTENCY_RTOL
    )
    if status == REDUCE_RANK_DEFICIENT_FREE:
        _, sigma, VT = np.linalg.svd(C[:, n_bounded:])
        scale = max(np.max(np.abs(A_full), initial=0.0), np.max(np.abs(C)))
        rank = int(np.sum(sigma > _RANK_RTOL * scale))
        raise rank_deficiency_error(VT[rank:].T, n_bounded, column_names)
    if status == REDUCE_INCONSISTENT_ROWS:
        return failed_result(C, d, n_bounded, s, 2.0, 0, row_names, "quadratic_daqp",
                             "quadratic recruitment (DAQP)")

    r = A_r.shape[0]
    iterations = 0
    if r == 0:
        x = np.zeros(n_bounded)
        lam_daqp = np.zeros(n_bounded)
        mu = np.zeros(0)
    else:
        # bounds 0 ≤ x ≤ 1 are DAQP's simple bounds (first n_bounded entries), then A_r x = b_r
        hessian = 2.0 * np.eye(n_bounded)
        upper = np.concatenate([np.ones(n_bounded), b_r])
        lower = np.concatenate([np.zeros(n_bounded), b_r])
        sense = np.zeros(n_bounded + r, dtype=np.int32)
        sense[n_bounded:] = _SENSE_EQUALITY
        x, _, exitflag, info = daqp.solve(hessian, np.zeros(n_bounded), A_r, upper, lower,
                                          sense, primal_tol=primal_tol)
        iterations = int(info["iterations"])
        if exitflag != _DAQP_OPTIMAL:
            return failed_result(C, d, n_bounded, s, 2.0, iterations, row_names,
                                 "quadratic_daqp", f"quadratic recruitment (DAQP exit flag "
                                 f"{exitflag})")
        lam_all = np.asarray(info["lam"])
        lam_daqp = lam_all[:n_bounded]
        mu = -lam_all[n_bounded:]
        x = np.clip(x, 0.0, 1.0)

    # f_B = s x; f_F = R_F⁻¹ Q1ᵀ (d − A x); λ = L μ
    f = np.concatenate([s * x, free_forces(Q1, R_F, d - A_full @ x)])
    active_upper = np.zeros(n_var, dtype=bool)
    active_lower = np.zeros(n_var, dtype=bool)
    active_upper[:n_bounded] = lam_daqp > 0.0
    active_lower[:n_bounded] = (lam_daqp < 0.0) | ((r == 0) & (x == 0.0))
    return RecruitmentResult(
        f=f, converged=True, status=STATUS_OPTIMAL, message="optimal", iterations=iterations,
        objective=float(x @ x), multipliers=L @ mu, active_upper=active_upper,
        active_lower=active_lower, infeasible_rows=(), residual=C @ f - d,
        n_bounded=n_bounded, criterion="quadratic_daqp", p=2.0,
    )
