"""Geometric stiffness of straight-segment paths, in compiled code.

A path of length l = Σ_k |u_k| (segments u_k = p_b − p_a between body points) under a
tension T acts as Q = −Lᵀ T (:mod:`.pathset`). At fixed T its stiffness is the
geometric term −T ∂Lᵀ/∂q̂, here in closed form per segment. With the world offsets
s_W = R s of the two points, e = u/|u|, P = (I − e eᵀ)/|u| and, per side i (sign
σ_a = −1, σ_b = +1, body i), G_i = [I, −s̃_W,i R_i] (3 × 6) so that δu = Σ σ_i G_i δq̂_i
(δp = δr + R (δπ × s)):

    ∂L_iᵀ/∂q̂_j = σ_i σ_j G_iᵀ P G_j + δ_ij σ_i [0 0; 0 s̃_i (R_iᵀ e)~]

the last block from turning R_iᵀ e with the body (∂(Rᵀx)/∂δπ = (Rᵀx)~). Checked against
finite differences of L on the manifold in tests/test_force_sets.py.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def _skew(v, out):
    """out (3, 3) ← ṽ."""
    out[0, 0], out[0, 1], out[0, 2] = 0.0, -v[2], v[1]
    out[1, 0], out[1, 1], out[1, 2] = v[2], 0.0, -v[0]
    out[2, 0], out[2, 1], out[2, 2] = -v[1], v[0], 0.0


@njit(cache=True)
def add_path_geometric_stiffness(p_WB, R_WB, column, seg_a, s_a, seg_b, s_b, seg_path, T, K):
    """K (n, n) −= Σ_paths T_p ∂L_pᵀ/∂q̂ for segments as in
    :func:`openfdk.model.kernels.path_lengths` (body indices seg_a/seg_b, body-frame
    points s_a/s_b (n_seg, 3) m, path of each segment seg_path); T (n_paths,) N."""
    G = np.zeros((2, 3, 6))  # work arrays, allocated once
    P = np.zeros((3, 3))
    GtP = np.zeros((6, 3))
    S = np.zeros((3, 3))
    X = np.zeros((3, 3))
    sW = np.zeros(3)
    u = np.zeros(3)
    x = np.zeros(3)
    for k in range(seg_a.shape[0]):
        t = T[seg_path[k]]
        if t == 0.0:
            continue
        u[:] = 0.0
        for side in range(2):
            i = seg_a[k] if side == 0 else seg_b[k]
            s = s_a[k] if side == 0 else s_b[k]
            sign = -1.0 if side == 0 else 1.0
            for r in range(3):
                sW[r] = R_WB[i, r, 0] * s[0] + R_WB[i, r, 1] * s[1] + R_WB[i, r, 2] * s[2]
                u[r] += sign * (p_WB[i, r] + sW[r])
            # G = [I, −s̃_W R]
            _skew(sW, S)
            for r in range(3):
                for c in range(3):
                    G[side, r, c] = 1.0 if r == c else 0.0
                    G[side, r, 3 + c] = -(S[r, 0] * R_WB[i, 0, c] + S[r, 1] * R_WB[i, 1, c] + S[r, 2] * R_WB[i, 2, c])
        length = np.sqrt(u[0] * u[0] + u[1] * u[1] + u[2] * u[2])
        for r in range(3):
            for c in range(3):
                P[r, c] = ((1.0 if r == c else 0.0) - u[r] * u[c] / (length * length)) / length
        for si in range(2):
            bi = seg_a[k] if si == 0 else seg_b[k]
            ci = column[bi]
            if ci < 0:
                continue
            sign_i = -1.0 if si == 0 else 1.0
            for r in range(6):
                for c in range(3):
                    GtP[r, c] = G[si, 0, r] * P[0, c] + G[si, 1, r] * P[1, c] + G[si, 2, r] * P[2, c]
            for sj in range(2):
                cj = column[seg_a[k] if sj == 0 else seg_b[k]]
                if cj < 0:
                    continue
                w = t * sign_i * (-1.0 if sj == 0 else 1.0)
                for r in range(6):
                    for c in range(6):
                        K[ci + r, cj + c] -= w * (GtP[r, 0] * G[sj, 0, c] + GtP[r, 1] * G[sj, 1, c]
                                                  + GtP[r, 2] * G[sj, 2, c])
            # the body's own rotation turns R_iᵀ e: s̃_i (R_iᵀ e)~
            for r in range(3):
                x[r] = (R_WB[bi, 0, r] * u[0] + R_WB[bi, 1, r] * u[1] + R_WB[bi, 2, r] * u[2]) / length
            _skew(s_a[k] if si == 0 else s_b[k], S)
            _skew(x, X)
            for r in range(3):
                for c in range(3):
                    K[ci + 3 + r, ci + 3 + c] -= t * sign_i * (S[r, 0] * X[0, c] + S[r, 1] * X[1, c] + S[r, 2] * X[2, c])
