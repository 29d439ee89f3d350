"""Sensitivity of the polynomial recruitment solution to the equilibrium data C and d.

Needed by the analytic FDK Jacobian (docs/design.md §1): how the optimal forces f move when the
kinematics change C and d. With the active set held fixed — interior bounded forces I,
bounded forces at a bound (f = 0 or f = s, unchanged), free forces F — the optimality
conditions of paper Eq. 11 are

    ∇G_I(f_I) = C_Iᵀ λ,     C_Fᵀ λ = 0,     C f = d,
    ∇G_i = p f_i^(p−1) / s_i^p,   H_i = ∂²G/∂f_i² = p (p−1) f_i^(p−2) / s_i^p.

Differentiating along a direction (dC, dd) (implicit-function theorem on the KKT system,
Fiacco, "Introduction to Sensitivity and Stability Analysis in Nonlinear Programming",
1983, Thm 3.2.2; Nocedal & Wright 2006, §16.1):

    H_I df_I − C_Iᵀ dλ = dC_Iᵀ λ
           − C_Fᵀ dλ = dC_Fᵀ λ
    C_I df_I + C_F df_F = dd − dC f.

Eliminating df_I = H_I⁻¹ (dC_Iᵀ λ + C_Iᵀ dλ) leaves the symmetric (n_eq + n_free) system

    [C_I H_I⁻¹ C_Iᵀ   C_F] [dλ  ]   [dd − dC f − C_I H_I⁻¹ dC_Iᵀ λ]
    [C_Fᵀ             0  ] [df_F] = [−dC_Fᵀ λ                     ],

factored once for all directions. The derivative exists when strict complementarity holds
(no bounded force exactly at a bound with a zero bound multiplier); at such points this is
the one-sided derivative for the current active set.
"""

from __future__ import annotations

import numpy as np

from openfdk.kinematics.envelope_lu import lu_factor_envelope, solve_permuted_columns
from openfdk.recruitment.result import RecruitmentInputError, RecruitmentResult

__all__ = ["RecruitmentSensitivity", "recruitment_sensitivity"]


def _as_directions(dC, dd, n_eq, n_var):
    """Stack directions as dC (k, n_eq, n_var), dd (k, n_eq); returns (dC, dd, batched)."""
    if isinstance(dC, (list, tuple)):
        dC = np.stack([np.asarray(a, dtype=np.float64) for a in dC])
    else:
        dC = np.asarray(dC, dtype=np.float64)
    if isinstance(dd, (list, tuple)):
        dd = np.stack([np.asarray(a, dtype=np.float64) for a in dd])
    else:
        dd = np.asarray(dd, dtype=np.float64)
    batched = dC.ndim == 3
    if not batched:
        dC = dC[None]
        dd = dd[None]
    k = dC.shape[0]
    if dC.shape != (k, n_eq, n_var):
        raise RecruitmentInputError(
            f"dC must have shape ({n_eq}, {n_var}) or (k, {n_eq}, {n_var}); got {dC.shape}"
        )
    if dd.shape != (k, n_eq):
        raise RecruitmentInputError(f"dd must have shape ({k}, {n_eq}) to match dC; got "
                                    f"{dd.shape}")
    return dC, dd, batched


class RecruitmentSensitivity:
    """The KKT system of the module docstring at one converged polynomial solution,
    factored once (:meth:`along` solves it for any number of direction sets: the FDK
    Jacobian's n_fdk directions and the contact split's applied loads share one
    factorisation, fdk/jacobian.py).

    result : converged polynomial RecruitmentResult of (C, d, s, p); C (n_eq, n_var);
    d (n_eq,) N or N·m; s (n_bounded,) N; p ≥ 2. Raises RecruitmentInputError if the
    result is not a converged polynomial solution of (C, d)."""

    def __init__(self, result: RecruitmentResult, C, d, s, p):
        if not result.converged:
            raise RecruitmentInputError(
                f"sensitivity needs a converged recruitment result; got status "
                f"'{result.status}': {result.message}"
            )
        if result.criterion == "minmax":
            raise RecruitmentInputError(
                "sensitivity is defined for the polynomial criterion only; the min/max "
                "solution is not unique"
            )
        C = np.asarray(C, dtype=np.float64)
        d = np.asarray(d, dtype=np.float64)
        s = np.asarray(s, dtype=np.float64)
        p = float(p)
        n_eq, n_var = C.shape
        n_bounded = result.n_bounded
        f = result.f
        if f.shape != (n_var,) or s.shape != (n_bounded,):
            raise RecruitmentInputError(
                f"result (n_var={f.shape[0]}, n_bounded={n_bounded}) does not match C "
                f"{C.shape} and s {s.shape}"
            )
        scale = np.max(np.abs(d), initial=0.0) + np.max(np.abs(C) @ np.abs(f), initial=0.0)
        if np.max(np.abs(C @ f - d), initial=0.0) > 1e-6 * max(scale, 1e-300):
            raise RecruitmentInputError("result does not satisfy C f = d for the C and d given")
        self.C, self.s, self.p, self.f, self.lam = C, s, p, f, result.multipliers
        self.n_eq, self.n_var, self.n_bounded = n_eq, n_var, n_bounded
        self.upper = np.flatnonzero(result.active_upper[:n_bounded])
        active = np.zeros(n_var, dtype=bool)
        active[:n_bounded] = result.active_lower[:n_bounded] | result.active_upper[:n_bounded]
        self.interior = interior = np.flatnonzero(~active[:n_bounded])
        self.free = free = np.arange(n_bounded, n_var)
        n_free = free.size

        # H_i = p (p−1) f_i^(p−2) / s_i^p on the interior bounded forces
        self.f_I = f_I = f[interior]
        # (|f| and sign(f) |f|^(p−1): an actuator's folded column may be negative, its
        # criterion is |f/s|^p — :mod:`openfdk.forces.actuators`)
        self.hessian_I = p * (p - 1.0) * np.abs(f_I) ** (p - 2.0) / s[interior] ** p
        self.C_I = C[:, interior]
        C_F = C[:, free]
        self.CI_Hinv = self.C_I / self.hessian_I  # C_I H_I⁻¹

        # KKT matrix [[C_I H⁻¹ C_Iᵀ, C_F], [C_Fᵀ, 0]]
        kkt = np.zeros((n_eq + n_free, n_eq + n_free))
        kkt[:n_eq, :n_eq] = self.CI_Hinv @ self.C_I.T
        kkt[:n_eq, n_eq:] = C_F
        kkt[n_eq:, :n_eq] = C_F.T
        # symmetric equilibration D K D (nearly free bounded forces — 20 kN unilateral
        # reactions with tiny f — give entries of H_I⁻¹ up to ~1e12), then one LU
        # factorisation (the compiled one of small_solve, no BLAS call)
        row_max = np.max(np.abs(kkt), axis=1)
        self.equilibrate = 1.0 / np.sqrt(np.where(row_max > 0.0, row_max, 1.0))
        self.kkt_scaled = kkt * self.equilibrate[:, None] * self.equilibrate[None, :]
        self.LU = np.array(self.kkt_scaled, order="C")
        n = self.LU.shape[0]
        self.piv, self.first, self.last = np.empty(n, np.int64), np.empty(n, np.int64), np.empty(n, np.int64)
        self.factored = bool(lu_factor_envelope(self.LU, self.piv, 0, n, self.first, self.last))
        self.unpermuted = np.arange(n)

    def along(self, dC, dd, ds=None):
        """Directional derivative(s) df of the optimal forces for perturbations (dC, dd, ds).

        A change of strength ds (Hill muscles: s depends on length and speed) enters twice:
        a force at its upper bound moves with it (df_i = ds_i, and C_U ds_U leaves the
        right-hand side), and an interior force feels ∂∇G_i/∂s_i ds_i = −p² f_i^(p−1)/s_i^(p+1)
        ds_i in its stationarity row (added to dC_Iᵀ λ with the opposite sign).

        dC : (n_eq, n_var) or (k, n_eq, n_var) or a list of k such arrays — dC/dε; None:
        zero (a change of the applied loads alone, through d). dd : (n_eq,) or (k, n_eq)
        or a list — dd/dε (N or N·m per unit ε). ds : optional (n_bounded,) or
        (k, n_bounded) — ds/dε (N per unit ε).

        Returns df (n_var,) or (k, n_var) — df/dε (N per unit ε), with the active set held
        fixed (bounded forces at 0 or s do not move)."""
        n_eq, n_var, n_bounded, p = self.n_eq, self.n_var, self.n_bounded, self.p
        interior, free, upper, f_I, lam = self.interior, self.free, self.upper, self.f_I, self.lam
        if dC is None:  # a change of d alone (applied loads): no dC terms
            dd = np.asarray(dd, dtype=np.float64)
            batched = dd.ndim == 2
            dd = dd if batched else dd[None]
            if dd.ndim != 2 or dd.shape[1] != n_eq:
                raise RecruitmentInputError(f"dd must have shape ({n_eq},) or (k, {n_eq}); got {dd.shape}")
        else:
            dC, dd, batched = _as_directions(dC, dd, n_eq, n_var)
        k = dd.shape[0]
        ds = np.zeros((k, n_bounded)) if ds is None else np.asarray(ds, dtype=np.float64).reshape(k, n_bounded)

        # right-hand sides, one column per direction
        # dC_Iᵀ λ (k, n_I)
        dCI_T_lam = np.zeros((k, interior.size)) if dC is None else np.einsum("kei,e->ki", dC[:, :, interior], lam)
        # strength change of interior forces: −∂∇G_I/∂s ds = p² f^(p−1)/s^(p+1) ds
        dCI_T_lam = dCI_T_lam + p * p * np.sign(f_I) * np.abs(f_I) ** (p - 1.0) / self.s[interior] ** (p + 1.0) \
            * ds[:, interior]
        dd = dd - ds[:, upper] @ self.C[:, upper].T  # forces at their strength move with it
        rhs = np.zeros((n_eq + free.size, k))
        rhs[:n_eq] = (dd - dCI_T_lam @ self.CI_Hinv.T).T
        if dC is not None:
            rhs[:n_eq] -= (dC @ self.f).T
            rhs[n_eq:] = -np.einsum("kef,e->fk", dC[:, :, free], lam)
        rhs_scaled = rhs * self.equilibrate[:, None]
        solution = None
        if self.factored:
            # all directions in one compiled call (a call per column cost about 3× more on the
            # DM knee, 16 columns of 140 rows), without BLAS (kinematics/envelope_lu.py)
            solution = solve_permuted_columns(self.LU, self.piv, self.first, self.last, self.unpermuted,
                                              np.ascontiguousarray(rhs_scaled))
            if not np.all(np.isfinite(solution)):
                solution = None
        if solution is None:
            # degenerate active set (too few interior forces to span the rows): minimum norm
            solution = np.linalg.lstsq(self.kkt_scaled, rhs_scaled, rcond=None)[0]
        solution = solution * self.equilibrate[:, None]
        dlam = solution[:n_eq].T  # (k, n_eq)
        df = np.zeros((k, n_var))
        # df_I = H_I⁻¹ (dC_Iᵀ λ + C_Iᵀ dλ)
        df[:, interior] = (dCI_T_lam + dlam @ self.C_I) / self.hessian_I
        df[:, free] = solution[n_eq:].T
        df[:, upper] = ds[:, upper]
        return df if batched else df[0]


def recruitment_sensitivity(result: RecruitmentResult, C, d, s, p, dC, dd, ds=None):
    """Directional derivative(s) of the optimal forces f for perturbations (dC, dd, ds):
    ``RecruitmentSensitivity(result, C, d, s, p).along(dC, dd, ds)`` (see there).

    Parameters
    ----------
    result : converged polynomial RecruitmentResult of (C, d, s, p).
    C : (n_eq, n_var); d : (n_eq,) N or N·m; s : (n_bounded,) N; p : float ≥ 2.
    dC : (n_eq, n_var) or (k, n_eq, n_var) or a list of k such arrays — dC/dε; None:
        zero (a change of the applied loads alone, through d).
    dd : (n_eq,) or (k, n_eq) or a list — dd/dε (N or N·m per unit ε).
    ds : optional (n_bounded,) or (k, n_bounded) — ds/dε (N per unit ε).

    Returns
    -------
    df : (n_var,) or (k, n_var) — df/dε (N per unit ε), with the active set of ``result``
    held fixed (bounded forces at 0 or s do not move).

    Raises
    ------
    RecruitmentInputError if the result is not a converged polynomial solution of (C, d).
    """
    return RecruitmentSensitivity(result, C, d, s, p).along(dC, dd, ds)
