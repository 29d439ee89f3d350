"""Muscle recruitment (paper Eq. 11): distribute the unknown forces of C f = d.

Columns of C are ordered [bounded..., free...]: bounded forces (muscles, unilateral
reactions) satisfy 0 ≤ f ≤ s; free forces (joint reactions, FDK residual forces) are
unbounded and not in the objective. See docs/recruitment.md.

* :func:`solve_polynomial` — min Σ (f/s)^p, p ≥ 2 (numba interior point + dual Newton).
* :func:`solve_quadratic_daqp` — p = 2 with the DAQP active-set QP solver.
* :func:`solve_minmax` — min max f/s, an LP solved with HiGHS.
* :func:`recruitment_sensitivity` — df for perturbations (dC, dd), for the FDK Jacobian
  (:class:`RecruitmentSensitivity`: its KKT system factored once for several direction sets).
"""

from openfdk.recruitment.minmax import solve_minmax
from openfdk.recruitment.polynomial import solve_polynomial
from openfdk.recruitment.quadratic_daqp import solve_quadratic_daqp
from openfdk.recruitment.result import (
    RankDeficientFreeColumnsError,
    RecruitmentInputError,
    RecruitmentResult,
)
from openfdk.recruitment.sensitivity import RecruitmentSensitivity, recruitment_sensitivity

__all__ = [
    "RecruitmentResult",
    "RecruitmentInputError",
    "RankDeficientFreeColumnsError",
    "solve_polynomial",
    "solve_quadratic_daqp",
    "solve_minmax",
    "RecruitmentSensitivity",
    "recruitment_sensitivity",
]
