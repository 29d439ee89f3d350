"""Numba kernels for the hot measure evaluations (compiled once, cached on disk)."""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def marker_positions_jacobian(p_WB, R_WB, w_BB, column, body, p_BM, n_coords, order):
    """Stacked marker measure (DESIGN.md §1, a point fixed in a body):
    p = r + R s', ∂p/∂δr = I, ∂p/∂δπ' = −R s̃', b = R ω̃' ω̃' s'.

    p_WB (nb, 3) m; R_WB (nb, 3, 3); w_BB (nb, 3) rad/s; column (nb,) int;
    body (n,) int; p_BM (n, 3) m. Returns value (3n,), M (3n, n_coords), b (3n,)
    (M and b are zero-filled when ``order`` is below 1 or 2).
    """
    n = body.shape[0]
    value = np.empty(3 * n)
    M = np.zeros((3 * n, n_coords)) if order >= 1 else np.zeros((0, n_coords))
    b = np.zeros(3 * n)
    for k in range(n):
        i = body[k]
        s0, s1, s2 = p_BM[k, 0], p_BM[k, 1], p_BM[k, 2]
        R = R_WB[i]
        for r in range(3):
            value[3 * k + r] = p_WB[i, r] + R[r, 0] * s0 + R[r, 1] * s1 + R[r, 2] * s2
        c = column[i]
        if order >= 1 and c >= 0:
            for r in range(3):
                M[3 * k + r, c + r] = 1.0
                # row r of −R s̃' : −(R[r,1] s2 − R[r,2] s1, R[r,2] s0 − R[r,0] s2, R[r,0] s1 − R[r,1] s0)
                M[3 * k + r, c + 3] = R[r, 2] * s1 - R[r, 1] * s2
                M[3 * k + r, c + 4] = R[r, 0] * s2 - R[r, 2] * s0
                M[3 * k + r, c + 5] = R[r, 1] * s0 - R[r, 0] * s1
        if order >= 2:
            w0, w1, w2 = w_BB[i, 0], w_BB[i, 1], w_BB[i, 2]
            # ω × s, then ω × (ω × s)
            a0, a1, a2 = w1 * s2 - w2 * s1, w2 * s0 - w0 * s2, w0 * s1 - w1 * s0
            c0, c1, c2 = w1 * a2 - w2 * a1, w2 * a0 - w0 * a2, w0 * a1 - w1 * a0
            for r in range(3):
                b[3 * k + r] = R[r, 0] * c0 + R[r, 1] * c1 + R[r, 2] * c2
    return value, M, b


@njit(cache=True)
def displace_poses(p_WB, quat_WB, R_WB, moving, column, dq_hat):
    """In place: r ← r + δr, p ← p ⊗ exp(½ δπ') (normalised, scalar part ≥ 0), R ← R(p)
    for every moving body (DESIGN.md §1). dq_hat (6 n_moving,) [m, rad]."""
    for i in moving:
        c = column[i]
        for r in range(3):
            p_WB[i, r] += dq_hat[c + r]
        x, y, z = dq_hat[c + 3], dq_hat[c + 4], dq_hat[c + 5]
        angle = np.sqrt(x * x + y * y + z * z)
        if angle < 1e-8:
            s = 0.5 - angle * angle / 48.0
        else:
            s = np.sin(0.5 * angle) / angle
        d0, d1, d2, d3 = np.cos(0.5 * angle), s * x, s * y, s * z
        p0, p1, p2, p3 = quat_WB[i, 0], quat_WB[i, 1], quat_WB[i, 2], quat_WB[i, 3]
        e0 = p0 * d0 - p1 * d1 - p2 * d2 - p3 * d3
        e1 = p0 * d1 + p1 * d0 + p2 * d3 - p3 * d2
        e2 = p0 * d2 - p1 * d3 + p2 * d0 + p3 * d1
        e3 = p0 * d3 + p1 * d2 - p2 * d1 + p3 * d0
        norm = np.sqrt(e0 * e0 + e1 * e1 + e2 * e2 + e3 * e3)
        if e0 < 0:
            norm = -norm
        e0, e1, e2, e3 = e0 / norm, e1 / norm, e2 / norm, e3 / norm
        quat_WB[i, 0], quat_WB[i, 1], quat_WB[i, 2], quat_WB[i, 3] = e0, e1, e2, e3
        R_WB[i, 0, 0] = 1 - 2 * (e2 * e2 + e3 * e3)
        R_WB[i, 0, 1] = 2 * (e1 * e2 - e0 * e3)
        R_WB[i, 0, 2] = 2 * (e1 * e3 + e0 * e2)
        R_WB[i, 1, 0] = 2 * (e1 * e2 + e0 * e3)
        R_WB[i, 1, 1] = 1 - 2 * (e1 * e1 + e3 * e3)
        R_WB[i, 1, 2] = 2 * (e2 * e3 - e0 * e1)
        R_WB[i, 2, 0] = 2 * (e1 * e3 - e0 * e2)
        R_WB[i, 2, 1] = 2 * (e2 * e3 + e0 * e1)
        R_WB[i, 2, 2] = 1 - 2 * (e1 * e1 + e2 * e2)
