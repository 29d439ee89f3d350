"""Numba kernels for the hot measure evaluations (compiled once, cached on disk)."""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def marker_positions_jacobian(p_WB, R_WB, w_BB, column, body, p_BM, n_coords, order):
    """Stacked marker measure (docs/design.md §1, a point fixed in a body):
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
def _set_rotation(R_WB, i, e0, e1, e2, e3):
    """R_WB[i] ← R(p) of the unit Euler parameters p = (e0, e1, e2, e3)."""
    R_WB[i, 0, 0] = 1 - 2 * (e2 * e2 + e3 * e3)
    R_WB[i, 0, 1] = 2 * (e1 * e2 - e0 * e3)
    R_WB[i, 0, 2] = 2 * (e1 * e3 + e0 * e2)
    R_WB[i, 1, 0] = 2 * (e1 * e2 + e0 * e3)
    R_WB[i, 1, 1] = 1 - 2 * (e1 * e1 + e3 * e3)
    R_WB[i, 1, 2] = 2 * (e2 * e3 - e0 * e1)
    R_WB[i, 2, 0] = 2 * (e1 * e3 - e0 * e2)
    R_WB[i, 2, 1] = 2 * (e2 * e3 + e0 * e1)
    R_WB[i, 2, 2] = 1 - 2 * (e1 * e1 + e2 * e2)


@njit(cache=True)
def displace_poses(p_WB, quat_WB, R_WB, moving, column, dq_hat):
    """In place: r ← r + δr, p ← p ⊗ exp(½ δπ') (normalised, scalar part ≥ 0), R ← R(p)
    for every moving body (docs/design.md §1). dq_hat (6 n_moving,) [m, rad]."""
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
        _set_times(quat_WB, R_WB, i, d0, d1, d2, d3)


@njit(cache=True)
def displace_by_rates(p_WB, quat_WB, R_WB, moving, column, v, vdot, dt):
    """In place: the poses carried forward by a second-order Taylor step,
    q ⊕ (v Δt + ½ v̇ Δt²) (the determinate warm start). v, vdot (6 n_moving,) [m/s,
    rad/s; m/s², rad/s²]; dt s. Returns False (poses untouched) if v or v̇ is not finite."""
    dq = np.empty(v.shape[0])
    for k in range(v.shape[0]):
        dq[k] = v[k] * dt + 0.5 * dt * dt * vdot[k]
        if not np.isfinite(dq[k]):
            return False
    displace_poses(p_WB, quat_WB, R_WB, moving, column, dq)
    return True


@njit(cache=True)
def _quat_product(p0, p1, p2, p3, d0, d1, d2, d3):
    """p ⊗ d of two quaternions (scalar first), as four numbers."""
    return (p0 * d0 - p1 * d1 - p2 * d2 - p3 * d3,
            p0 * d1 + p1 * d0 + p2 * d3 - p3 * d2,
            p0 * d2 - p1 * d3 + p2 * d0 + p3 * d1,
            p0 * d3 + p1 * d2 - p2 * d1 + p3 * d0)


@njit(cache=True)
def _set_times(quat_WB, R_WB, i, d0, d1, d2, d3):
    """quat_WB[i] ← p ⊗ d normalised with scalar part ≥ 0 (p = quat_WB[i], d a
    quaternion as four numbers), R_WB[i] ← R of it; quat_WB (nb, 4), R_WB (nb, 3, 3)."""
    e0, e1, e2, e3 = _quat_product(quat_WB[i, 0], quat_WB[i, 1], quat_WB[i, 2], quat_WB[i, 3], d0, d1, d2, d3)
    norm = np.sqrt(e0 * e0 + e1 * e1 + e2 * e2 + e3 * e3)
    if e0 < 0:
        norm = -norm
    e0, e1, e2, e3 = e0 / norm, e1 / norm, e2 / norm, e3 / norm
    quat_WB[i, 0], quat_WB[i, 1], quat_WB[i, 2], quat_WB[i, 3] = e0, e1, e2, e3
    _set_rotation(R_WB, i, e0, e1, e2, e3)


@njit(cache=True)
def relative_vector(p_WB, R_WB, w_BB, v_WB, column, ia, s_a, ib, s_b, k, n_coords, order):
    """Vector u = p_b − p_a between points s_a (on body ia) and s_b (on body ib),
    expressed in body k's frame (world if k < 0): w = R_kᵀ u.

    M = R_kᵀ (M_b − M_a) (+ w̃ in k's rotation columns); b = R_kᵀ b_u − 2 ω'_k × (R_kᵀ u̇)
    + ω'_k × (ω'_k × w) with b_u = R_b ω̃'_b ω̃'_b s_b − R_a ω̃'_a ω̃'_a s_a (docs/design.md §1).
    Returns value (3,), M (3, n_coords), b (3,), u̇ expressed like w (3,).
    """
    value = np.zeros(3)
    M = np.zeros((3, n_coords))
    b = np.zeros(3)
    du = np.zeros(3)
    sW = np.zeros((2, 3))
    u = np.zeros(3)
    for side in range(2):
        i = ia if side == 0 else ib
        s = s_a if side == 0 else s_b
        R = R_WB[i]
        for r in range(3):
            sW[side, r] = R[r, 0] * s[0] + R[r, 1] * s[1] + R[r, 2] * s[2]
        sign = -1.0 if side == 0 else 1.0
        for r in range(3):
            u[r] += sign * (p_WB[i, r] + sW[side, r])
    if k >= 0:
        Rk = R_WB[k]
    else:
        Rk = np.eye(3)
    for r in range(3):
        value[r] = Rk[0, r] * u[0] + Rk[1, r] * u[1] + Rk[2, r] * u[2]
    if order == 0:
        return value, M, b, du
    for side in range(2):
        i = ia if side == 0 else ib
        c = column[i]
        if c < 0:
            continue
        sign = -1.0 if side == 0 else 1.0
        R = R_WB[i]
        s = s_a if side == 0 else s_b
        # block_W = [I, −R s̃] ; M += sign · R_kᵀ block_W
        blk = np.zeros((3, 6))
        for r in range(3):
            blk[r, r] = 1.0
            blk[r, 3] = R[r, 2] * s[1] - R[r, 1] * s[2]
            blk[r, 4] = R[r, 0] * s[2] - R[r, 2] * s[0]
            blk[r, 5] = R[r, 1] * s[0] - R[r, 0] * s[1]
        for r in range(3):
            for j in range(6):
                acc = Rk[0, r] * blk[0, j] + Rk[1, r] * blk[1, j] + Rk[2, r] * blk[2, j]
                M[r, c + j] += sign * acc
    if k >= 0 and column[k] >= 0:
        ck = column[k]
        # + w̃ in k's rotation columns
        M[0, ck + 4] += -value[2]
        M[0, ck + 5] += value[1]
        M[1, ck + 3] += value[2]
        M[1, ck + 5] += -value[0]
        M[2, ck + 3] += -value[1]
        M[2, ck + 4] += value[0]
    if order == 1:
        return value, M, b, du
    duW = np.zeros(3)
    bW = np.zeros(3)
    for side in range(2):
        i = ia if side == 0 else ib
        s = s_a if side == 0 else s_b
        sign = -1.0 if side == 0 else 1.0
        R = R_WB[i]
        w0, w1, w2 = w_BB[i, 0], w_BB[i, 1], w_BB[i, 2]
        a0, a1, a2 = w1 * s[2] - w2 * s[1], w2 * s[0] - w0 * s[2], w0 * s[1] - w1 * s[0]
        c0, c1, c2 = w1 * a2 - w2 * a1, w2 * a0 - w0 * a2, w0 * a1 - w1 * a0
        for r in range(3):
            duW[r] += sign * (v_WB[i, r] + R[r, 0] * a0 + R[r, 1] * a1 + R[r, 2] * a2)
            bW[r] += sign * (R[r, 0] * c0 + R[r, 1] * c1 + R[r, 2] * c2)
    for r in range(3):
        du[r] = Rk[0, r] * duW[0] + Rk[1, r] * duW[1] + Rk[2, r] * duW[2]
        b[r] = Rk[0, r] * bW[0] + Rk[1, r] * bW[1] + Rk[2, r] * bW[2]
    if k >= 0:
        wk0, wk1, wk2 = w_BB[k, 0], w_BB[k, 1], w_BB[k, 2]
        x0, x1, x2 = wk1 * du[2] - wk2 * du[1], wk2 * du[0] - wk0 * du[2], wk0 * du[1] - wk1 * du[0]
        y0, y1, y2 = wk1 * value[2] - wk2 * value[1], wk2 * value[0] - wk0 * value[2], wk0 * value[1] - wk1 * value[0]
        z0, z1, z2 = wk1 * y2 - wk2 * y1, wk2 * y0 - wk0 * y2, wk0 * y1 - wk1 * y0
        b[0] += -2.0 * x0 + z0
        b[1] += -2.0 * x1 + z1
        b[2] += -2.0 * x2 + z2
        # the rate of w itself: ẇ = R_kᵀ u̇ − ω'_k × w
        du[0] -= y0
        du[1] -= y1
        du[2] -= y2
    return value, M, b, du


@njit(cache=True)
def path_lengths(p_WB, R_WB, column, seg_a, s_a, seg_b, s_b, seg_path, n_paths, n_coords):
    """Lengths l (n_paths,) m and Jacobians L = ∂l/∂q̂ (n_paths, n_coords) of paths made
    of straight segments between body points (segment k from s_a[k] on body seg_a[k]
    to s_b[k] on body seg_b[k], belonging to path seg_path[k]): l = Σ |p_b − p_a|,
    L = Σ eᵀ (M_b − M_a), e the unit segment direction."""
    l = np.zeros(n_paths)
    L = np.zeros((n_paths, n_coords))
    for k in range(seg_a.shape[0]):
        ia, ib = seg_a[k], seg_b[k]
        Ra, Rb = R_WB[ia], R_WB[ib]
        sa = np.zeros(3)
        sb = np.zeros(3)
        u = np.zeros(3)
        for r in range(3):
            sa[r] = Ra[r, 0] * s_a[k, 0] + Ra[r, 1] * s_a[k, 1] + Ra[r, 2] * s_a[k, 2]
            sb[r] = Rb[r, 0] * s_b[k, 0] + Rb[r, 1] * s_b[k, 1] + Rb[r, 2] * s_b[k, 2]
            u[r] = p_WB[ib, r] + sb[r] - p_WB[ia, r] - sa[r]
        length = np.sqrt(u[0] * u[0] + u[1] * u[1] + u[2] * u[2])
        p = seg_path[k]
        l[p] += length
        e0, e1, e2 = u[0] / length, u[1] / length, u[2] / length
        for side in range(2):
            i = ia if side == 0 else ib
            c = column[i]
            if c < 0:
                continue
            sign = -1.0 if side == 0 else 1.0
            sW = sa if side == 0 else sb
            L[p, c] += sign * e0
            L[p, c + 1] += sign * e1
            L[p, c + 2] += sign * e2
            # eᵀ(−R s̃) = eᵀ(−s̃_W R) = (s_W × e)ᵀ R ... computed as (R ᵀ (s_W × e))ᵀ
            x0 = sW[1] * e2 - sW[2] * e1
            x1 = sW[2] * e0 - sW[0] * e2
            x2 = sW[0] * e1 - sW[1] * e0
            R = R_WB[i]
            for j in range(3):
                L[p, c + 3 + j] += sign * (R[0, j] * x0 + R[1, j] * x1 + R[2, j] * x2)
    return l, L


@njit(cache=True)
def set_poses(q, moving, p_WB, quat_WB, R_WB):
    """In place, for the k-th moving body i: r_i ← q[7k:7k+3], p_i ← q[7k+3:7k+7]
    normalised with scalar part ≥ 0, R_i ← R(p_i). q (7 n_moving,) [m, -].
    Returns −1, or k when the k-th quaternion cannot be normalised (zero or non-finite)."""
    for k in range(moving.shape[0]):
        i = moving[k]
        for r in range(3):
            p_WB[i, r] = q[7 * k + r]
        e0, e1, e2, e3 = q[7 * k + 3], q[7 * k + 4], q[7 * k + 5], q[7 * k + 6]
        norm = np.sqrt(e0 * e0 + e1 * e1 + e2 * e2 + e3 * e3)
        if not np.isfinite(norm) or norm == 0.0:
            return k
        if e0 < 0:
            norm = -norm
        e0, e1, e2, e3 = e0 / norm, e1 / norm, e2 / norm, e3 / norm
        quat_WB[i, 0], quat_WB[i, 1], quat_WB[i, 2], quat_WB[i, 3] = e0, e1, e2, e3
        _set_rotation(R_WB, i, e0, e1, e2, e3)
    return -1


@njit(cache=True)
def set_velocities(v, column, moving, v_WB, w_BB):
    """In place: ṙ_i ← v[c:c+3], ω'_i ← v[c+3:c+6] for every moving body i with
    c = column[i]. v (6 n_moving,) [m/s, rad/s]."""
    for i in moving:
        c = column[i]
        for r in range(3):
            v_WB[i, r] = v[c + r]
            w_BB[i, r] = v[c + 3 + r]


@njit(cache=True)
def get_poses(p_WB, quat_WB, moving, q):
    """q ← [r_1, p_1, r_2, p_2, …] (7 n_moving,) [m, -] of the moving bodies."""
    for k in range(moving.shape[0]):
        i = moving[k]
        for r in range(3):
            q[7 * k + r] = p_WB[i, r]
        for r in range(4):
            q[7 * k + 3 + r] = quat_WB[i, r]


@njit(cache=True)
def get_velocities(v_WB, w_BB, column, moving, v):
    """v[c:c+3] ← ṙ_i, v[c+3:c+6] ← ω'_i for every moving body i (c = column[i]);
    v (6 n_moving,) [m/s, rad/s]. Inverse of :func:`set_velocities`."""
    for i in moving:
        c = column[i]
        for r in range(3):
            v[c + r] = v_WB[i, r]
            v[c + 3 + r] = w_BB[i, r]


@njit(cache=True)
def extrapolate_poses(p_WB, quat_WB, R_WB, moving, q_prev):
    """In place, for every moving body: r ← 2 r − r_prev and p ← p ⊗ (p_prev* ⊗ p)
    (normalised, scalar part ≥ 0), R ← R(p): the next frame's pose predicted linearly
    on the manifold (the same body-frame rotation increment again). q_prev
    (7 n_moving,) [m, -] the previous frame's pose in :func:`get_poses` layout."""
    for k in range(moving.shape[0]):
        i = moving[k]
        for r in range(3):
            p_WB[i, r] = 2 * p_WB[i, r] - q_prev[7 * k + r]
        # d = p_prev* ⊗ p, then p ← p ⊗ d
        d0, d1, d2, d3 = _quat_product(q_prev[7 * k + 3], -q_prev[7 * k + 4], -q_prev[7 * k + 5],
                                       -q_prev[7 * k + 6], quat_WB[i, 0], quat_WB[i, 1], quat_WB[i, 2],
                                       quat_WB[i, 3])
        _set_times(quat_WB, R_WB, i, d0, d1, d2, d3)
