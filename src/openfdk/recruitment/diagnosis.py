"""Phase-1 diagnosis of infeasible recruitment frames (HiGHS linear programme).

Called only when a fast solver fails. It finds the forces within the bounds that come
closest to equilibrium in the ℓ1 sense,

    minimise Σ_k (ρ⁺_k + ρ⁻_k)   s.t.   C f + ρ⁺ − ρ⁻ = d,   l s ≤ f_B ≤ u s,   ρ± ≥ 0,

(the standard phase-1 problem of the simplex method, Nocedal & Wright, "Numerical
Optimization", 2nd ed., §13.5), solved with HiGHS through ``scipy.optimize.linprog``.
Rows with a non-zero residual ρ⁺ − ρ⁻ at the optimum are the rows the admissible forces
cannot balance; their names go into the message.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from openfdk.recruitment.result import row_label

__all__ = ["InfeasibilityDiagnosis", "diagnose_infeasibility"]

#: |d| (N, N·m) from which a row counts as unbalanceable without an LP: HiGHS's infinity
HUGE = 1e20


@dataclass(frozen=True)
class InfeasibilityDiagnosis:
    """Outcome of the phase-1 LP.

    feasible : bool — a force set within the bounds meets equilibrium (to tolerance).
    f : (n_var,) N — the least-ℓ1-residual forces.
    residual : (n_eq,) row units — C f − d at those forces.
    rows : tuple of int — rows with a residual above tolerance.
    message : str — names the rows (empty when feasible).
    iterations : int — HiGHS iterations.
    """

    feasible: bool
    f: np.ndarray
    residual: np.ndarray
    rows: tuple[int, ...]
    message: str
    iterations: int


def diagnose_infeasibility(C, d, n_bounded, s, row_names=None, rtol=1e-7, upper=None, lower=None):
    """Solve the phase-1 LP and name the rows that cannot be balanced.

    Parameters
    ----------
    C : (n_eq, n_var); d : (n_eq,) N or N·m; n_bounded : int; s : (n_bounded,) N;
    row_names : optional sequence of n_eq names; rtol : a row counts as unbalanced when
    |residual| > rtol · (‖d‖∞ + max_kj |C_kj s_j|); upper : optional (n_bounded,) activity
    bounds u (default 1; +∞ for none); lower : optional (n_bounded,) activity bounds l (default 0).

    Returns InfeasibilityDiagnosis.
    """
    n_eq, n_var = C.shape
    n_free = n_var - n_bounded
    scaled = np.hstack([C[:, :n_bounded] * s, C[:, n_bounded:]])
    # rows no force can meet: non-finite, or |d| at or beyond the LP's infinity (HiGHS
    # refuses such a model; a contact's logarithmic law near full depth gives 1e30 N)
    bad = np.flatnonzero(~(np.abs(d) < HUGE) | ~np.all(np.isfinite(scaled), axis=1))
    if len(bad):
        names = "; ".join(f"{row_label(int(k), row_names)} (d = {d[k]:.3g})" for k in bad[:4]) + (
            f" and {len(bad) - 4} more" if len(bad) > 4 else "")
        return InfeasibilityDiagnosis(
            feasible=False, f=np.full(n_var, np.nan), residual=np.full(n_eq, np.nan), rows=tuple(int(k) for k in bad),
            message=f"equilibrium cannot be met: no finite force balances {names}", iterations=0)
    threshold = rtol * (np.max(np.abs(d), initial=0.0) + np.max(np.abs(scaled), initial=0.0))

    # variables [x = f_B/s (n_bounded), f_F (n_free), ρ⁺ (n_eq), ρ⁻ (n_eq)]
    cost = np.concatenate([np.zeros(n_var), np.ones(2 * n_eq)])
    A_eq = np.hstack([scaled, np.eye(n_eq), -np.eye(n_eq)])
    u = np.ones(n_bounded) if upper is None else np.asarray(upper, float)
    lo = np.zeros(n_bounded) if lower is None else np.asarray(lower, float)
    bounds = ([(float(l_j), None if np.isinf(u_j) else float(u_j)) for l_j, u_j in zip(lo, u)]
              + [(None, None)] * n_free
              + [(0.0, None)] * (2 * n_eq))
    from scipy.optimize import linprog  # here: only infeasible frames need it (≈ 0.2 s of imports)

    lp = linprog(cost, A_eq=A_eq, b_eq=d, bounds=bounds, method="highs")
    if lp.status != 0 or lp.x is None:  # feasible and bounded with finite data: HiGHS's own failure
        return InfeasibilityDiagnosis(
            feasible=False, f=np.full(n_var, np.nan), residual=np.full(n_eq, np.nan), rows=(),
            message=f"equilibrium not diagnosed: the phase-1 LP failed ({lp.message})",
            iterations=int(getattr(lp, "nit", 0) or 0))
    f = np.concatenate([lp.x[:n_bounded] * s, lp.x[n_bounded:n_var]])
    residual = C @ f - d
    rows = tuple(int(k) for k in np.flatnonzero(np.abs(residual) > threshold))

    # rows on which no column acts at all (zero row of C, d ≠ 0)
    empty_rows = {k for k in rows if np.max(np.abs(scaled[k]), initial=0.0) == 0.0}
    parts = []
    for k in rows:
        if k in empty_rows:
            parts.append(
                f"{row_label(k, row_names)} cannot be balanced: no force in C acts on it "
                f"(d = {d[k]:.6g})"
            )
        else:
            parts.append(
                f"not enough strength for {row_label(k, row_names)} "
                f"(residual {residual[k]:.6g})"
            )
    message = ""
    if rows:
        message = "equilibrium cannot be met: " + "; ".join(parts)
    iterations = int(getattr(lp, "nit", 0))
    return InfeasibilityDiagnosis(
        feasible=not rows, f=f, residual=residual, rows=rows, message=message,
        iterations=iterations,
    )
