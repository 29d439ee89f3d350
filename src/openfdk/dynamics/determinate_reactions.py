"""Reactions of a statically determinate frame: the equilibrium C f = d (Eq. 12) with
as many free reaction columns as equilibrium rows and no recruited column (every
coordinate driven, OpenSim's inverse dynamics) has one solution, so the recruitment
(Eq. 11) is that solve, G = 0 and λ = 0 — the result
:func:`openfdk.recruitment.polynomial.solve_polynomial` gives such a frame.

C's columns are the reaction rows of Φ_q̂ (C[r, k] = ±Φ_q̂[sel_k, eq_r]), so C is
Φ_q̂ᵀ restricted, with Φ_q̂'s sparsity transposed: a tree of joints makes it block
triangular with one 6×6 block per body (:mod:`openfdk.kinematics.block_triangular`).
The form is found once per model from the constraint rows' checked pattern
(``ConstraintSystem.checked_pattern``), not from each frame's C, whose exact zeros
vary with the pose.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ..kinematics.block_triangular import block_lu, block_solve, block_triangular_form
from ..recruitment.result import STATUS_OPTIMAL, RecruitmentResult
from .equilibrium import _reaction_rows


def reactions_form(system, layout):
    """The BlockForm of C for ``layout`` (EquilibriumLayout of ``system``, a
    ConstraintSystem) when its frames are determinate — square, with no muscle,
    actuator or one-sided reaction — and the system's pattern is checked; else None."""
    n_eq = len(layout.eq_coords)
    if layout.n_bounded or layout.n_actuators or n_eq != layout.n_columns or n_eq == 0:
        return None
    pattern = system.checked_pattern()
    if pattern is None:
        return None
    sel, _ = _reaction_rows(layout)
    return block_triangular_form(pattern[sel][:, layout.eq_coords].T)


@njit(cache=True)
def block_reactions(C, d, rows, cols, starts, ptr, earlier, f, residual):
    """f (n,) ← C⁻¹ d by blocks, residual (n,) ← C f − d; False when C is singular, f
    not finite or the residual above 1e-8 max(|d|, 1) (one compiled call per frame)."""
    n = C.shape[0]
    LU, piv = np.empty((n, n)), np.empty(n, np.int64)
    if not block_lu(C, rows, cols, starts, LU, piv):
        return False
    block_solve(LU, piv, rows, cols, starts, ptr, earlier, d, f)
    scale = 1.0
    for r in range(n):
        scale = max(scale, abs(d[r]))
    worst = 0.0
    for r in range(n):
        if not np.isfinite(f[r]):
            return False
        acc = -d[r]
        for c in range(n):
            acc += C[r, c] * f[c]
        residual[r] = acc
        worst = max(worst, abs(acc))
    return worst <= 1e-8 * scale


def determinate_reactions(C, d, form, p):
    """The RecruitmentResult of C f = d (C (n, n), d (n,) N, N m) solved by blocks
    (``form`` of :func:`reactions_form`; p the criterion's exponent, recorded), or None
    when C is singular or the solve is not accurate (residual > 1e-8 max(|d|, 1)): the
    recruitment solver then handles (and names) it."""
    n = C.shape[0]
    f, residual = np.empty(n), np.empty(n)
    if not block_reactions(np.ascontiguousarray(C, dtype=float), np.ascontiguousarray(d, dtype=float), form.rows,
                  form.cols, form.starts, form.ptr, form.earlier, f, residual):
        return None
    zero = np.zeros(n, bool)
    return RecruitmentResult(
        f=f, converged=True, status=STATUS_OPTIMAL, message="optimal", iterations=0, objective=0.0,
        multipliers=np.zeros(n), active_upper=zero, active_lower=zero.copy(), infeasible_rows=(),
        residual=residual, n_bounded=0, criterion="polynomial", p=float(p))
