"""Result object, errors and input checks shared by the recruitment solvers.

The recruitment problem (paper Eq. 11, docs/design.md §1) is

    minimise G(f_B)   subject to   C f = d,   0 ≤ f_B ≤ s,

with the unknown forces ``f = [f_B; f_F]`` ordered by column: first the ``n_bounded``
*bounded* forces f_B (muscles and unilateral reactions, N) with strengths ``s`` (N), then
the *free* forces f_F (joint reactions, FDK residual forces; N or N·m), which are
unbounded and not in the objective.

Sign convention of the equality multipliers: ``multipliers`` is the vector λ (n_eq,) with
``∇_f G = Cᵀ λ + ν_upper − ν_lower`` (ν ≥ 0 the multipliers of the bounds). By the envelope
theorem λ_k = ∂G*/∂d_k, the change of the optimal objective per unit change of the
right-hand side of equilibrium row k.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np
from numba import njit

__all__ = [
    "RecruitmentResult",
    "RecruitmentInputError",
    "RankDeficientFreeColumnsError",
    "STATUS_OPTIMAL",
    "STATUS_INFEASIBLE",
    "STATUS_NOT_CONVERGED",
]

STATUS_OPTIMAL = "optimal"
STATUS_INFEASIBLE = "infeasible"
STATUS_NOT_CONVERGED = "not_converged"


class RecruitmentInputError(ValueError):
    """An argument of a recruitment solver has the wrong shape, sign or value."""


class RankDeficientFreeColumnsError(RecruitmentInputError):
    """The free (unbounded) columns of C are linearly dependent.

    Their forces are then not determined by equilibrium and the objective does not
    penalise them; the model must be fixed (remove a redundant reaction) rather than
    regularised silently. ``columns`` holds the indices of the columns involved.
    """

    def __init__(self, message: str, columns: tuple[int, ...]):
        super().__init__(message)
        self.columns = columns


@dataclass(frozen=True)
class RecruitmentResult:
    """Solution of one recruitment problem (one time frame).

    Attributes
    ----------
    f : (n_var,) N (N·m for moment-type free columns)
        Forces ordered like the columns of C. When ``converged`` is False and the frame is
        infeasible, ``f`` is the phase-1 force set that minimises the ℓ1 equilibrium
        residual within the bounds — it does *not* satisfy equilibrium and is not optimal.
    converged : bool
        True only when ``f`` satisfies equilibrium and the optimality conditions to ``tol``.
    status : str
        ``"optimal"``, ``"infeasible"`` or ``"not_converged"``.
    message : str
        Human-readable summary; names the equilibrium rows that cannot be balanced.
    iterations : int
        Iterations of the solver (interior-point + dual Newton, or simplex/IPM of HiGHS).
    objective : float
        G(f) = Σ (f_i/s_i)^p for the polynomial criterion, β = max f_i/s_i for min/max
        (dimensionless).
    multipliers : (n_eq,) objective units per row unit (e.g. 1/N)
        λ with ∇_f G = Cᵀλ + bound multipliers; λ_k = ∂G*/∂d_k. NaN when not converged.
    active_upper : (n_var,) bool
        Bounded forces at their strength, f_i = s_i (False for free columns).
    active_lower : (n_var,) bool
        Bounded forces at zero, f_i = 0 (False for free columns).
    infeasible_rows : tuple of int
        Equilibrium rows with a residual that no admissible f can remove (empty when
        feasible).
    residual : (n_eq,) row units (N or N·m)
        C f − d.
    n_bounded : int
        Number of bounded columns (the first ``n_bounded`` columns of C).
    criterion : str
        ``"polynomial"``, ``"quadratic_daqp"`` or ``"minmax"``.
    p : float
        Exponent of the polynomial criterion (``inf`` for min/max).
    """

    f: np.ndarray
    converged: bool
    status: str
    message: str
    iterations: int
    objective: float
    multipliers: np.ndarray
    active_upper: np.ndarray
    active_lower: np.ndarray
    infeasible_rows: tuple[int, ...] = ()
    residual: np.ndarray = field(default_factory=lambda: np.zeros(0))
    n_bounded: int = 0
    criterion: str = "polynomial"
    p: float = 3.0

    @property
    def success(self) -> bool:
        """Alias of ``converged`` (scipy's name)."""
        return self.converged


def row_label(k: int, row_names) -> str:
    """Name of equilibrium row k for messages (``'name'`` or ``row 3``)."""
    if row_names is not None and k < len(row_names):
        return f"row '{row_names[k]}'"
    return f"row {k}"


def column_label(j: int, column_names) -> str:
    """Name of column j for messages (``'name'`` or ``column 3``)."""
    if column_names is not None and j < len(column_names):
        return f"column '{column_names[j]}'"
    return f"column {j}"


def _non_finite_entry(C, d, row_names, column_names) -> str:
    """The message naming the first non-finite entry of d (n_eq,) or C (n_eq, n_var):
    its equation (row) and, for C, its column."""
    def row(i):
        return f"row '{row_names[i]}'" if row_names is not None and i < len(row_names) else f"row {i}"

    bad_d = np.flatnonzero(~np.isfinite(d))
    if bad_d.size:
        i = int(bad_d[0])
        return (f"C and d must be finite: d of {row(i)} (the load the equation balances, N or N·m) is {float(d[i])}, "
                f"from a non-finite or overflowing input")
    i, j = (int(k) for k in np.argwhere(~np.isfinite(C))[0])
    return (f"C and d must be finite: C of {row(i)}, {column_label(j, column_names)} is {float(C[i, j])}, "
            f"from a non-finite or overflowing input")


def check_problem(C, d, n_bounded, s, row_names=None, column_names=None):
    """Validate and convert the arrays of a recruitment problem.

    Parameters
    ----------
    C : (n_eq, n_var) equilibrium matrix (row units per column units, e.g. 1 or m).
    d : (n_eq,) right-hand side (N or N·m per row).
    n_bounded : int, number of leading bounded columns.
    s : (n_bounded,) N, strengths, all ≥ 0 and finite (0: the force is fixed at zero, see
        :func:`solve_without_zero_strength`).

    Returns ``(C, d, s)`` as C-contiguous float64 arrays.
    Raises RecruitmentInputError naming the offending argument or column.
    """
    C = np.ascontiguousarray(C, dtype=np.float64)
    d = np.ascontiguousarray(d, dtype=np.float64)
    s = np.ascontiguousarray(s, dtype=np.float64)
    if C.ndim != 2:
        raise RecruitmentInputError(f"C must be a 2-D array (n_eq, n_var); got shape {C.shape}")
    n_eq, n_var = C.shape
    if d.shape != (n_eq,):
        raise RecruitmentInputError(f"d must have shape ({n_eq},) to match C; got {d.shape}")
    n_bounded = int(n_bounded)
    if not 0 <= n_bounded <= n_var:
        raise RecruitmentInputError(f"n_bounded must lie in [0, {n_var}]; got {n_bounded}")
    if s.shape != (n_bounded,):
        raise RecruitmentInputError(
            f"s (strengths) must have shape ({n_bounded},) = (n_bounded,); got {s.shape}"
        )
    cd_finite, s_ok = _value_checks(C, d, s)
    if not cd_finite:
        raise RecruitmentInputError(_non_finite_entry(C, d, row_names, column_names))
    if not s_ok:
        j = int(np.flatnonzero(~(np.isfinite(s) & (s >= 0.0)))[0])
        raise RecruitmentInputError(
            f"strength of {column_label(j, column_names)} must be finite and ≥ 0 N; got {s[j]!r}"
        )
    if row_names is not None and len(row_names) != n_eq:
        raise RecruitmentInputError(f"row_names must have {n_eq} entries; got {len(row_names)}")
    if column_names is not None and len(column_names) != n_var:
        raise RecruitmentInputError(
            f"column_names must have {n_var} entries; got {len(column_names)}"
        )
    return C, d, s


@njit(cache=True)
def _value_checks(C, d, s):
    """(all of C (n_eq, n_var) and d (n_eq,) finite, all strengths s (n_bounded,) N
    finite and ≥ 0): one pass over the values, no temporaries."""
    cd_finite = True
    for i in range(C.shape[0]):
        if not np.isfinite(d[i]):
            cd_finite = False
        for j in range(C.shape[1]):
            if not np.isfinite(C[i, j]):
                cd_finite = False
    s_ok = True
    for j in range(s.shape[0]):
        if not (np.isfinite(s[j]) and s[j] >= 0.0):
            s_ok = False
    return cd_finite, s_ok


def rank_deficiency_error(null_vectors, n_bounded, column_names):
    """Build the RankDeficientFreeColumnsError for null vectors of the free columns.

    null_vectors : (n_free, k) right null vectors of C_F (columns), dimensionless.
    """
    weight = np.max(np.abs(null_vectors), axis=1)
    involved = tuple(int(n_bounded + j) for j in np.flatnonzero(weight > 1e-6 * weight.max()))
    names = ", ".join(column_label(j, column_names) for j in involved)
    return RankDeficientFreeColumnsError(
        f"the free (unbounded) columns of C are linearly dependent ({names}); their forces "
        "are not determined by equilibrium. Remove a redundant reaction or make it bounded; "
        "openfdk does not regularise free forces silently.",
        involved,
    )


def solve_without_zero_strength(solve, C, d, n_bounded, s, *, column_names=None, x0=None,
                                **options):
    """Solve with the zero-strength bounded columns removed (their forces are fixed at 0).

    A muscle whose strength is 0 at this state (e.g. far down its force–length curve) can
    only carry f = 0; it is dropped, the problem is solved by ``solve`` (a solver with the
    signature of the openfdk recruitment solvers), and the result is expanded back to all
    columns with those forces at zero and marked ``active_lower``.

    C : (n_eq, n_var); d : (n_eq,); s : (n_bounded,) N with some zeros; x0 : optional warm
    start (forces (n_var,) or a RecruitmentResult). Returns RecruitmentResult (n_var columns).
    """
    n_var = C.shape[1]
    keep = np.ones(n_var, dtype=bool)
    keep[:n_bounded] = s > 0.0
    kept_index = np.flatnonzero(keep)
    names = None if column_names is None else [column_names[j] for j in kept_index]
    for key in ("upper", "lower"):
        if options.get(key) is not None:
            options[key] = np.asarray(options[key], float)[keep[:n_bounded]]
    if x0 is not None:
        if isinstance(x0, RecruitmentResult) and x0.converged:
            options["x0"] = x0  # its multipliers (per row) are all that is used
        else:
            forces = x0.f if isinstance(x0, RecruitmentResult) else np.asarray(x0, float)
            options["x0"] = forces[keep]
    n_kept = int(keep[:n_bounded].sum())
    try:
        sub = solve(C[:, keep], d, n_kept, s[keep[:n_bounded]], column_names=names, **options)
    except RankDeficientFreeColumnsError as error:
        error.columns = tuple(int(kept_index[j]) for j in error.columns)
        raise
    f = np.zeros(n_var)
    f[keep] = sub.f
    active_upper = np.zeros(n_var, dtype=bool)
    active_lower = np.zeros(n_var, dtype=bool)
    active_upper[keep] = sub.active_upper
    active_lower[keep] = sub.active_lower
    if sub.converged:
        active_lower[:n_bounded] |= ~keep[:n_bounded]
    return replace(sub, f=f, active_upper=active_upper, active_lower=active_lower,
                   n_bounded=n_bounded)
