"""Geometric stiffness of paths over one wrapping surface along given directions (numba).

A path P → surface → Q (P fixed in body a, Q in body b, the surface in body s) under a
tension T acts as Q = −Lᵀ T, with L = Σ_segments eᵀ (M_B − M_A) and its tangent points
T1, T2 held in body s: the length is stationary in them (the envelope theorem,
:mod:`.wrap_kernels`). Its geometric stiffness along a direction u, −T (∂Lᵀ/∂q̂) u, is

* that of the straight segments P → T1 and T2 → Q with T1, T2 fixed in body s (closed
  form, :func:`~.path_stiffness.add_path_geometric_stiffness`), plus
* what the tangent points' sliding on the surface adds. With τ1, τ2 (3,) m the tangent
  points in the surface frame S, functions of the anchors P_S, Q_S (3,) m in S, and
  w_i = R_WS δτ_i their sliding in the world,

      δe1 = P1 w1,  P1 = (I − e1 e1ᵀ)/|T1 − P|,   e1 = (T1 − P)/|T1 − P|,
      δe2 = −P2 w2, P2 = (I − e2 e2ᵀ)/|Q − T2|,   e2 = (Q − T2)/|Q − T2|,

  and T1's and T2's moment arms about body s move by w1 and w2:

      δLᵀ = (G_s(T1) − G_a(P))ᵀ P1 w1 + [0; R_sᵀ (w1 × e1)]_s
            − (G_b(Q) − G_s(T2))ᵀ P2 w2 − [0; R_sᵀ (w2 × e2)]_s,

  where G_i(x) = [I, −(x − p_i)~ R_i] maps body i's q̂ (3 + 3) to the velocity of its
  point at x. The anchors move relative to the surface by δP_S = R_WSᵀ (G_a(P) δq̂_a −
  G_s(P) δq̂_s) (P's velocity relative to the point of body s at P), δQ_S likewise, and
  δτ_i = ∂τ_i/∂P_S δP_S + ∂τ_i/∂Q_S δQ_S.

The 3 × 6 derivatives ∂τ_i/∂(P_S, Q_S) are forward differences of the surface's wrap
(:func:`~.wrap_kernels._wrap_one`, step 1e-6 of |P_S| + |Q_S|) from the path's warm start.
An anchor moved along its tangent line (P along e1, Q along e2) leaves the path as it
is, so two differences across the line per anchor suffice: four solves of each tensed
path instead of one solve of every tensed path per direction
(:meth:`.pathset.PathSet.geometric_stiffness_along`; the DM knee's 65 tensed ligament
strands over ellipsoids and cylinders, ten directions). A geodesic over an ellipsoid
takes its four moves from its own solve by the implicit function theorem on the
shooting residual (:func:`~.wrap_kernels.ellipsoid_tangent_moves`: 6 shots instead
of four Newton solves of 3–4 each); the cylinder, the sphere and OpenSim's planar rule
are solved again for each move.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .path_stiffness import add_path_geometric_stiffness
from .wrap_kernels import (BLEND_W, CROSSING_ONLY, CYLINDER, ELLIPSOID, OPENSIM_PLANE, POINT, SPHERE, _wrap_one,
                           crosses, ellipsoid_tangent_moves)

#: forward-difference step of the tangent points' derivatives, times |P_S| + |Q_S|
TANGENT_STEP = 1e-6
#: status of :func:`single_wrap_stiffness_along`: done; a difference left the surface
#: (contact changed within the step: the caller differences the paths along U instead)
DONE, CONTACT_CHANGED = 0, 1


def single_surface_paths(kinds, limits, start):
    """Indices (k,) of the paths (node ranges start[p]:start[p+1]) that are a point, one
    cylinder, sphere or ellipsoid (not OpenSim's planar rule) and a point."""
    out = []
    for p in range(len(start) - 1):
        j0, j1 = start[p], start[p + 1]
        if j1 - j0 != 3 or kinds[j0] != POINT or kinds[j0 + 2] != POINT:
            continue
        kind, flags = kinds[j0 + 1], int(limits[j0 + 1, 1])
        if kind in (CYLINDER, SPHERE) or (kind == ELLIPSOID and not flags & OPENSIM_PLANE):
            out.append(p)
    return np.array(out, dtype=np.int64)


@njit(cache=True)
def _velocity(p_WB, R_WB, column, i, x, u):
    """G_i(x) u (3,) m: the velocity of body i's point at x (3,) m along u (n,)."""
    out = np.zeros(3)
    c = column[i]
    if c < 0:
        return out
    w = R_WB[i] @ u[c + 3:c + 6]
    s = x - p_WB[i]
    out[0] = u[c] + w[1] * s[2] - w[2] * s[1]
    out[1] = u[c + 1] + w[2] * s[0] - w[0] * s[2]
    out[2] = u[c + 2] + w[0] * s[1] - w[1] * s[0]
    return out


@njit(cache=True)
def _add_transposed(out, p_WB, R_WB, column, i, x, f, scale):
    """out (n,) += scale G_i(x)ᵀ f: f (3,) N at body i's point x (3,) m as generalised
    forces [f; R_iᵀ ((x − p_i) × f)]."""
    c = column[i]
    if c < 0:
        return
    s = x - p_WB[i]
    m = np.array([s[1] * f[2] - s[2] * f[1], s[2] * f[0] - s[0] * f[2], s[0] * f[1] - s[1] * f[0]])
    mb = R_WB[i].T @ m
    for r in range(3):
        out[c + r] += scale * f[r]
        out[c + 3 + r] += scale * mb[r]


@njit(cache=True)
def _add_angular(out, R_WB, column, i, v, scale):
    """out (n,) += scale [0; R_iᵀ v] in body i's columns."""
    c = column[i]
    if c < 0:
        return
    vb = R_WB[i].T @ v
    for r in range(3):
        out[c + 3 + r] += scale * vb[r]


@njit(cache=True)
def _normals(e):
    """Two unit vectors (2, 3) orthogonal to the unit vector e (3,) and to each other."""
    a = np.zeros(3)
    a[np.argmin(np.abs(e))] = 1.0
    n1 = np.cross(e, a)
    n1 = n1 / np.sqrt(n1 @ n1)
    out = np.empty((2, 3))
    out[0] = n1
    out[1] = np.cross(e, n1)
    return out


@njit(cache=True)
def single_wrap_stiffness_along(p_WB, R_WB, column, kinds, bodies, p_B, R_BS, dims, sides, limits, start, warm,
                                paths, T, U):
    """(status, KU (n, m)) with KU = −Σ_p T_p (∂L_pᵀ/∂q̂) U for the single-surface paths
    ``paths`` (k,) (:func:`single_surface_paths`) under tensions T (k,) N, directions U
    (n, m) [m, rad]; the node arrays as :func:`~.wrap_kernels.wrapped_path_lengths`
    (``warm`` read only: each solve starts from a copy of its node's row). status
    CONTACT_CHANGED when a difference's wrap left the surface or failed, or a path is a
    blend of its two ways round (:func:`~.wrap_kernels._blended`; KU is then not
    complete)."""
    n, m = U.shape
    k = paths.shape[0]
    seg_a = np.empty(2 * k, dtype=np.int64)
    seg_b = np.empty(2 * k, dtype=np.int64)
    s_a = np.zeros((2 * k, 3))
    s_b = np.zeros((2 * k, 3))
    seg_path = np.empty(2 * k, dtype=np.int64)
    n_seg = 0
    KU = np.zeros((n, m))
    for q in range(k):
        p = paths[q]
        j0 = start[p]
        j = j0 + 1
        a, s, b = bodies[j0], bodies[j], bodies[j0 + 2]
        P_W = p_WB[a] + R_WB[a] @ p_B[j0]
        Q_W = p_WB[b] + R_WB[b] @ p_B[j0 + 2]
        X_S = p_WB[s] + R_WB[s] @ p_B[j]
        R_S = R_WB[s] @ R_BS[j]
        P_S = R_S.T @ (P_W - X_S)
        Q_S = R_S.T @ (Q_W - X_S)
        flags = int(limits[j, 1])
        row = warm[j].copy()
        st, _, T1, T2, _ = _wrap_one(kinds[j], P_S, Q_S, dims[j], sides[j], limits[j, 0], flags, row)
        if st < 0 or (kinds[j] == ELLIPSOID and not flags & OPENSIM_PLANE and row[BLEND_W] > 0.0):
            return CONTACT_CHANGED, KU  # (a blend of two ways round: differenced instead)
        if st != 1:  # straight: one segment P → Q, closed form only
            seg_a[n_seg], s_a[n_seg], seg_b[n_seg], s_b[n_seg], seg_path[n_seg] = a, p_B[j0], b, p_B[j0 + 2], q
            n_seg += 1
            continue
        T1_W = X_S + R_S @ T1
        T2_W = X_S + R_S @ T2
        # the segments with T1, T2 fixed in body s (closed form below)
        seg_a[n_seg], s_a[n_seg], seg_b[n_seg], s_b[n_seg], seg_path[n_seg] = \
            a, p_B[j0], s, R_WB[s].T @ (T1_W - p_WB[s]), q
        seg_a[n_seg + 1], s_a[n_seg + 1], seg_b[n_seg + 1], s_b[n_seg + 1], seg_path[n_seg + 1] = \
            s, R_WB[s].T @ (T2_W - p_WB[s]), b, p_B[j0 + 2], q
        n_seg += 2
        # ∂τ_i/∂(P_S, Q_S) (3, 6) by forward differences of the wrap across each anchor's
        # tangent line: an anchor moved along its line keeps the path (the tangent points
        # do not move), so two differences per anchor, along normals n of e1 (e2), give
        # ∂τ/∂P_S = Σ_n (Δτ_n / h) nᵀ
        h = TANGENT_STEP * (np.sqrt(P_S @ P_S) + np.sqrt(Q_S @ Q_S))
        moves = np.zeros((2, 4, 3))  # the four anchor moves: (P, Q) by h along each normal
        normals = np.empty((4, 3))
        for end in range(2):
            line = T1 - P_S if end == 0 else Q_S - T2
            two = _normals(line / np.sqrt(line @ line))
            for k in range(2):
                normals[2 * end + k] = two[k]
                moves[end, 2 * end + k] = h * two[k]
        # a geodesic: the four moves by the implicit function theorem from this solve
        # (2 + 4 shots), where the moved anchors stay in contact as a solve would find them
        # (OpenSim's crossing rule); else each move solved (3–4 shots each)
        linear = kinds[j] == ELLIPSOID and not flags & OPENSIM_PLANE
        if linear and flags & CROSSING_ONLY:
            for v in range(4):
                linear = linear and crosses(P_S + moves[0, v], Q_S + moves[1, v], dims[j])
        ok = False
        if linear:
            ok, dT1, dT2 = ellipsoid_tangent_moves(P_S, Q_S, dims[j], sides[j], row, moves[0], moves[1])
        if not ok:
            dT1 = np.empty((4, 3))
            dT2 = np.empty((4, 3))
            for v in range(4):
                st_c, _, T1c, T2c, _ = _wrap_one(kinds[j], P_S + moves[0, v], Q_S + moves[1, v], dims[j], sides[j],
                                                 limits[j, 0], flags, warm[j].copy())
                if st_c != 1:
                    return CONTACT_CHANGED, KU
                dT1[v] = T1c - T1
                dT2[v] = T2c - T2
        D1 = np.zeros((3, 6))
        D2 = np.zeros((3, 6))
        for v in range(4):
            end = v // 2
            nrm = normals[v]
            for r in range(3):
                for c in range(3):
                    D1[r, 3 * end + c] += dT1[v, r] / h * nrm[c]
                    D2[r, 3 * end + c] += dT2[v, r] / h * nrm[c]
        u1 = T1_W - P_W
        l1 = np.sqrt(u1 @ u1)
        e1 = u1 / l1
        u2 = Q_W - T2_W
        l2 = np.sqrt(u2 @ u2)
        e2 = u2 / l2
        t = T[q]
        col = np.zeros(n)
        for c in range(m):
            u = np.ascontiguousarray(U[:, c])
            dPQ = np.empty(6)
            dPQ[:3] = R_S.T @ (_velocity(p_WB, R_WB, column, a, P_W, u) - _velocity(p_WB, R_WB, column, s, P_W, u))
            dPQ[3:] = R_S.T @ (_velocity(p_WB, R_WB, column, b, Q_W, u) - _velocity(p_WB, R_WB, column, s, Q_W, u))
            w1 = R_S @ (D1 @ dPQ)
            w2 = R_S @ (D2 @ dPQ)
            f1 = (w1 - (e1 @ w1) * e1) / l1  # P1 w1
            f2 = (w2 - (e2 @ w2) * e2) / l2  # P2 w2
            col[:] = 0.0
            _add_transposed(col, p_WB, R_WB, column, s, T1_W, f1, 1.0)
            _add_transposed(col, p_WB, R_WB, column, a, P_W, f1, -1.0)
            _add_angular(col, R_WB, column, s, np.cross(w1, e1), 1.0)
            _add_transposed(col, p_WB, R_WB, column, b, Q_W, f2, -1.0)
            _add_transposed(col, p_WB, R_WB, column, s, T2_W, f2, 1.0)
            _add_angular(col, R_WB, column, s, np.cross(w2, e2), -1.0)
            for r in range(n):
                KU[r, c] -= t * col[r]
    K = np.zeros((n, n))
    add_path_geometric_stiffness(p_WB, R_WB, column, seg_a[:n_seg], s_a[:n_seg], seg_b[:n_seg], s_b[:n_seg],
                                 seg_path[:n_seg], T, K)
    KU += K @ U
    return DONE, KU


__all__ = ["single_surface_paths", "single_wrap_stiffness_along", "TANGENT_STEP", "DONE", "CONTACT_CHANGED"]
