"""The Hessian of the marker tracking's Lagrangian by forward differences, in one compiled
call (the FDK Jacobian's kinematic sensitivity, :func:`openfdk.fdk.jacobian.kinematic_sensitivity`).

The Lagrangian of Eqs. 4–5 has the gradient

    g(q̂) = Ψ_q̂ᵀ W (Ψ(q̂) − x) + Φ_q̂ᵀ λ       (n,) [N-less: m·weight, rad·weight]

with the markers Ψ = p_WM = r_B + R_WB s'_M (∂p/∂δr = I, ∂p/∂δπ' = −R_WB s̃'_M, so the
marker's rows of Ψ_q̂ᵀ r are r and s'_M × (R_WBᵀ r)), and H = ∂g/∂q̂ is differenced
forward along groups of columns whose rows do not overlap (Curtis, Powell & Reid 1974;
:func:`~openfdk.numerics.numdiff.column_groups`), each displacement q̂ ⊕ ε e_group on the
manifold as :meth:`~openfdk.model.state.BodyStates.displace`. Differencing the gradient
through Python took about 30 calls of the marker and constraint programs per Hessian,
2.7 ms on the DM knee (30 groups, 255 × 255 KKT), 8 % of the FDK bench window's time;
here each group is one pass over the markers and one evaluation of the compiled
constraint program (:func:`~openfdk.model.compiled.evaluate_into`), with no Python in
between.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ..model.compiled import evaluate_into
from ..model.kernels import displace_poses

#: status of :func:`tracking_hessian`: done; a constraint measure failed at a displaced pose
OK, MEASURE_ERROR = 0, 1


@njit(cache=True)
def _gradient(p_WB, R_WB, column, marker_body, p_BM, w, x, A, lam, g):
    """g (n,) ← Ψ_q̂ᵀ W (Ψ − x) + Aᵀ λ at the poses (module docstring); A (m, n) Φ_q̂,
    lam (m,), w (3 nm,) row weights, x (3 nm,) m (0 where w = 0)."""
    n = g.shape[0]
    m = A.shape[0]
    for c in range(n):
        s = 0.0
        for r in range(m):
            s += A[r, c] * lam[r]
        g[c] = s
    for k in range(marker_body.shape[0]):
        b = marker_body[k]
        c = column[b]
        if c < 0:
            continue
        R = R_WB[b]
        s0, s1, s2 = p_BM[k, 0], p_BM[k, 1], p_BM[k, 2]
        p0 = p_WB[b, 0] + R[0, 0] * s0 + R[0, 1] * s1 + R[0, 2] * s2
        p1 = p_WB[b, 1] + R[1, 0] * s0 + R[1, 1] * s1 + R[1, 2] * s2
        p2 = p_WB[b, 2] + R[2, 0] * s0 + R[2, 1] * s1 + R[2, 2] * s2
        r0 = w[3 * k] * (p0 - x[3 * k])
        r1 = w[3 * k + 1] * (p1 - x[3 * k + 1])
        r2 = w[3 * k + 2] * (p2 - x[3 * k + 2])
        g[c] += r0
        g[c + 1] += r1
        g[c + 2] += r2
        # (−R s̃')ᵀ r = s' × (Rᵀ r)
        q0 = R[0, 0] * r0 + R[1, 0] * r1 + R[2, 0] * r2
        q1 = R[0, 1] * r0 + R[1, 1] * r1 + R[2, 1] * r2
        q2 = R[0, 2] * r0 + R[1, 2] * r1 + R[2, 2] * r2
        g[c + 3] += s1 * q2 - s2 * q1
        g[c + 4] += s2 * q0 - s0 * q2
        g[c + 5] += s0 * q1 - s1 * q0


@njit(cache=True)
def tracking_hessian(op, node_row, node_size, i_start, iparams, f_start, fparams, out_rows, n_node_rows,
                     p_WB, quat_WB, R_WB, w_BB, v_WB, column, moving, marker_body, p_BM, w, x, lam, g0,
                     group_ptr, group_cols, pattern, eps, H):
    """H (n, n) ← (g(q̂ ⊕ ε e_G) − g0)/ε on each column's pattern rows, for the column
    groups G = group_cols[group_ptr[i]:group_ptr[i + 1]] (module docstring).

    The poses (p_WB (nb, 3) m, quat_WB (nb, 4), R_WB (nb, 3, 3), with w_BB, v_WB,
    column, moving as :class:`~openfdk.model.state.BodyStates`) are left as they were;
    the constraint program's arrays as :func:`~openfdk.model.compiled.evaluate_into`;
    marker_body (nm,), p_BM (nm, 3) m, w (3 nm,), x (3 nm,) m, lam (m,), g0 (n,) the
    gradient at the poses; pattern (n, n) bool; eps (m or rad). Returns (status,
    failing node, error code)."""
    n = H.shape[0]
    m = out_rows.shape[0]
    p0 = p_WB.copy()
    quat0 = quat_WB.copy()
    R0 = R_WB.copy()
    p = p_WB.copy()
    quat = quat_WB.copy()
    R = R_WB.copy()
    val = np.empty(m)
    A = np.empty((m, n))
    bias = np.empty(m)
    g = np.empty(n)
    e = np.zeros(n)
    for i in range(group_ptr.shape[0] - 1):
        p[:] = p0
        quat[:] = quat0
        R[:] = R0
        for j in range(group_ptr[i], group_ptr[i + 1]):
            e[group_cols[j]] = eps
        displace_poses(p, quat, R, moving, column, e)
        for j in range(group_ptr[i], group_ptr[i + 1]):
            e[group_cols[j]] = 0.0
        e_node, e_kind = evaluate_into(op, node_row, node_size, i_start, iparams, f_start, fparams, out_rows,
                                       n_node_rows, p, R, w_BB, v_WB, column, n, np.int64(1), val, A, bias)
        if e_node >= 0:
            return MEASURE_ERROR, e_node, e_kind
        _gradient(p, R, column, marker_body, p_BM, w, x, A, lam, g)
        for j in range(group_ptr[i], group_ptr[i + 1]):
            k = group_cols[j]
            for r in range(n):
                if pattern[r, k]:
                    H[r, k] = (g[r] - g0[r]) / eps
                else:
                    H[r, k] = 0.0
    return OK, -1, 0


def group_arrays(groups):
    """(group_ptr (n_groups + 1,), group_cols (n,)) int arrays of a list of column-index
    arrays (:func:`~openfdk.numerics.numdiff.column_groups`)."""
    ptr = np.zeros(len(groups) + 1, dtype=np.int64)
    ptr[1:] = np.cumsum([len(g) for g in groups])
    cols = np.concatenate(groups).astype(np.int64) if groups else np.zeros(0, dtype=np.int64)
    return ptr, cols


__all__ = ["tracking_hessian", "group_arrays", "OK", "MEASURE_ERROR"]
