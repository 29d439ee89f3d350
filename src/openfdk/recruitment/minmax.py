"""Min/max muscle recruitment (paper Eq. 11 with the min/max criterion) as a linear programme.

    minimise β   s.t.   C f = d,   0 ≤ f_i ≤ s_i,   f_i / s_i ≤ β   (i < n_bounded),

i.e. minimise the largest activity f_i/s_i (Rasmussen, Damsgaard & Voigt, "Muscle
recruitment by the min/max criterion — a comparative numerical study", J Biomech 34,
2001). In the activities x = f_B/s the LP has variables [x, f_F, β] and is solved with
HiGHS (``scipy.optimize.linprog(method="highs")``; Huangfu & Hall, "Parallelizing the dual
revised simplex method", Math Prog Comp 10, 2018).

The optimal β is unique, the forces in general are not (only the most loaded synergy is
determined); the forces returned are HiGHS's vertex solution. The equality multipliers
are HiGHS's marginals, λ_k = ∂β*/∂d_k.
"""

from __future__ import annotations

import numpy as np

from openfdk.recruitment.polynomial import failed_result
from openfdk.recruitment.result import (
    STATUS_OPTIMAL,
    RecruitmentResult,
    check_problem,
    rank_deficiency_error,
    solve_without_zero_strength,
)

__all__ = ["solve_minmax"]

_RANK_RTOL = 1e-11
_HIGHS_OPTIMAL = 0
_BOUND_TOL = 1e-9  # activity within this of 0 or 1 counts as at the bound


def solve_minmax(C, d, n_bounded, s, *, row_names=None, column_names=None
                 ) -> RecruitmentResult:
    """Min/max recruitment: minimise β = max_i f_i/s_i s.t. C f = d, 0 ≤ f_B ≤ s.

    Parameters
    ----------
    C : (n_eq, n_var), columns ordered [bounded..., free...]; d : (n_eq,) N or N·m;
    n_bounded : int; s : (n_bounded,) N strengths ≥ 0 (0 fixes that force at zero);
    row_names, column_names : optional names for messages.

    Returns
    -------
    RecruitmentResult with ``criterion="minmax"``, ``objective`` = β (dimensionless),
    ``p = inf``. Infeasible frames: ``converged=False`` with the rows named.

    Raises
    ------
    RankDeficientFreeColumnsError when the free columns are linearly dependent.
    """
    C, d, s = check_problem(C, d, n_bounded, s, row_names, column_names)
    if n_bounded and s.min() == 0.0:
        return solve_without_zero_strength(solve_minmax, C, d, int(n_bounded), s,
                                           column_names=column_names, row_names=row_names)
    n_eq, n_var = C.shape
    n_bounded = int(n_bounded)
    n_free = n_var - n_bounded
    scaled = np.hstack([C[:, :n_bounded] * s, C[:, n_bounded:]])
    if n_free:
        _, sigma, VT = np.linalg.svd(C[:, n_bounded:])
        scale = max(np.max(np.abs(scaled)), 1e-300)
        rank = int(np.sum(sigma > _RANK_RTOL * scale))
        if rank < n_free:
            raise rank_deficiency_error(VT[rank:].T, n_bounded, column_names)

    # variables v = [x (n_bounded), f_F (n_free), β]; minimise β
    cost = np.zeros(n_var + 1)
    cost[-1] = 1.0
    A_eq = np.hstack([scaled, np.zeros((n_eq, 1))])
    # x_i − β ≤ 0
    A_ub = np.hstack([np.eye(n_bounded), np.zeros((n_bounded, n_free)),
                      -np.ones((n_bounded, 1))])
    bounds = [(0.0, 1.0)] * n_bounded + [(None, None)] * n_free + [(0.0, None)]
    from scipy.optimize import linprog  # here: scipy.optimize costs ≈ 0.2 s of imports at start-up

    lp = linprog(cost, A_ub=A_ub if n_bounded else None, b_ub=np.zeros(n_bounded)
                 if n_bounded else None, A_eq=A_eq, b_eq=d, bounds=bounds, method="highs")
    iterations = int(getattr(lp, "nit", 0))
    if lp.status != _HIGHS_OPTIMAL:
        return failed_result(C, d, n_bounded, s, np.inf, iterations, row_names, "minmax",
                             f"min/max recruitment (HiGHS: {lp.message})")
    x = lp.x[:n_bounded]
    f = np.concatenate([x * s, lp.x[n_bounded:n_var]])
    active_upper = np.zeros(n_var, dtype=bool)
    active_lower = np.zeros(n_var, dtype=bool)
    active_upper[:n_bounded] = x >= 1.0 - _BOUND_TOL
    active_lower[:n_bounded] = x <= _BOUND_TOL
    return RecruitmentResult(
        f=f, converged=True, status=STATUS_OPTIMAL, message="optimal", iterations=iterations,
        objective=float(lp.x[-1]), multipliers=np.asarray(lp.eqlin.marginals, dtype=float),
        active_upper=active_upper, active_lower=active_lower, infeasible_rows=(),
        residual=C @ f - d, n_bounded=n_bounded, criterion="minmax", p=float("inf"),
    )
