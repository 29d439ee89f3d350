"""Muscle and ligament paths through via points and wrapping surfaces, in any order.

A path is a list of *nodes*: body points and wrapping surfaces (cylinder, sphere,
ellipsoid fixed to a body, see :mod:`.wrap_geodesics`). The first and last nodes are
points. Each surface wraps the path between its neighbouring anchors: the previous point
(or the exit tangent point T2 of the previous surface in contact) and the next point (or
the entry tangent point T1 of the next surface in contact). Surfaces next to each other
are solved by block Gauss–Seidel sweeps until the tangent points stop moving.

Length:  l = Σ straight segments + Σ geodesic arcs.
Jacobian (moment arms): the path is locally shortest, so by the envelope theorem
∂l/∂q̂ equals the derivative with the tangent points held fixed *in their surface's
body*; the arcs are then rigid and only the straight segments count:
L = Σ_segments eᵀ (M_B − M_A), e the unit segment direction, M the point Jacobians
(DESIGN.md §1). This is exact for the closed-form cylinder and sphere arcs and as
accurate as the shooting tolerance for the ellipsoid. Lengthening speed l̇ = L v; a
tension T acts as Q = −Lᵀ T. The acceleration bias b = L̇ v (needed only when a path
length is driven or used as a constraint) is a central difference of L along v.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from ..model.measures import Measure
from .wrap_geodesics import cylinder_wrap, ellipsoid_wrap, sphere_wrap

POINT, CYLINDER, SPHERE, ELLIPSOID = 0, 1, 2, 3
SURFACE_KINDS = {"cylinder": CYLINDER, "sphere": SPHERE, "ellipsoid": ELLIPSOID}
#: Newton tolerance of the ellipsoid geodesic end condition (m)
ELLIPSOID_TOL = 1e-13
#: status codes of :func:`wrapped_path_lengths`
STATUS_TEXT = {-1: "a path point lies inside the wrapping surface", -2: "the ellipsoid geodesic did not converge",
               -3: "adjacent wrapping surfaces did not settle"}


@dataclass(frozen=True, eq=False)
class WrapSurface:
    """A wrapping surface fixed to a body.

    kind : "cylinder" (axis z_S, infinite), "sphere" or "ellipsoid" (semi-axes along
    x_S, y_S, z_S); body : body index; p_BS (3,) m and R_BS (3, 3): the surface frame S
    in the body frame; dims (3,) m: (r, r, r) or the semi-axes (a, b, c); side (3,): a
    direction in S on which the path must pass (zeros: the shorter way).
    """

    name: str
    kind: str
    body: int
    p_BS: np.ndarray
    R_BS: np.ndarray
    dims: np.ndarray
    side: np.ndarray


@njit(cache=True)
def _wrap_one(kind, P_S, Q_S, dims, side):
    if kind == CYLINDER:
        return cylinder_wrap(P_S, Q_S, dims[0], side)
    if kind == SPHERE:
        return sphere_wrap(P_S, Q_S, dims[0], side)
    return ellipsoid_wrap(P_S, Q_S, dims, side, ELLIPSOID_TOL)


@njit(cache=True)
def _anchor(j, step, kinds, active, X_W, T1_W, T2_W):
    """Nearest node before (step −1) or after (+1) node j that the path touches: a point's
    position, or T2 (before) / T1 (after) of a surface in contact."""
    k = j + step
    while kinds[k] != POINT and not active[k]:
        k += step
    if kinds[k] == POINT:
        return X_W[k]
    return T2_W[k] if step < 0 else T1_W[k]


@njit(cache=True)
def _add_segment(L, p, column, p_WB, R_WB, ia, xa, ib, xb):
    """L[p] += eᵀ (M_B − M_A) for the segment from xa (fixed in body ia) to xb (in ib);
    returns its length (m)."""
    u = xb - xa
    length = np.sqrt(u @ u)
    if length == 0.0:
        return 0.0
    e = u / length
    for side in range(2):
        i = ia if side == 0 else ib
        c = column[i]
        if c < 0:
            continue
        sign = -1.0 if side == 0 else 1.0
        sW = (xa if side == 0 else xb) - p_WB[i]
        x0 = sW[1] * e[2] - sW[2] * e[1]
        x1 = sW[2] * e[0] - sW[0] * e[2]
        x2 = sW[0] * e[1] - sW[1] * e[0]
        R = R_WB[i]
        for r in range(3):
            L[p, c + r] += sign * e[r]
            L[p, c + 3 + r] += sign * (R[0, r] * x0 + R[1, r] * x1 + R[2, r] * x2)
    return length


@njit(cache=True)
def wrapped_path_lengths(p_WB, R_WB, column, kinds, bodies, p_B, R_BS, dims, sides, start, n_coords):
    """Lengths, Jacobians and tangent points of paths through points and surfaces.

    p_WB (nb, 3) m, R_WB (nb, 3, 3); column (nb,) first q̂ column of each body (−1 fixed);
    nodes of all paths concatenated: kinds (N,) (POINT, CYLINDER, SPHERE, ELLIPSOID),
    bodies (N,), p_B (N, 3) m (point, or surface origin, in the body frame), R_BS (N, 3, 3),
    dims (N, 3) m, sides (N, 3); path k owns nodes start[k]:start[k+1].
    Returns l (n_paths,) m, L (n_paths, n_coords), status (n_paths,) (0 ok, < 0 see
    ``STATUS_TEXT``), T_W (N, 2, 3) m the world tangent points of each surface in
    contact (NaN when not in contact or for points).
    """
    n_paths = start.shape[0] - 1
    N = kinds.shape[0]
    l = np.zeros(n_paths)
    L = np.zeros((n_paths, n_coords))
    status = np.zeros(n_paths, dtype=np.int64)
    T_W = np.full((N, 2, 3), np.nan)
    X_W = np.zeros((N, 3))
    R_WS = np.zeros((N, 3, 3))
    for j in range(N):
        i = bodies[j]
        X_W[j] = p_WB[i] + R_WB[i] @ p_B[j]
        R_WS[j] = R_WB[i] @ R_BS[j]
    active = np.zeros(N, dtype=np.bool_)
    T1_W = np.zeros((N, 3))
    T2_W = np.zeros((N, 3))
    arc = np.zeros(N)
    for p in range(n_paths):
        j0, j1 = start[p], start[p + 1]
        adjacent = False
        for j in range(j0 + 1, j1 - 1):
            if kinds[j] != POINT and kinds[j + 1] != POINT:
                adjacent = True
        scale = 0.0
        for j in range(j0, j1):
            scale = max(scale, np.sqrt((X_W[j] - X_W[j0]) @ (X_W[j] - X_W[j0])))
        settled = False
        for sweep in range(200 if adjacent else 1):
            change = 0.0
            for j in range(j0 + 1, j1 - 1):
                if kinds[j] == POINT:
                    continue
                P_W = _anchor(j, -1, kinds, active, X_W, T1_W, T2_W)
                Q_W = _anchor(j, 1, kinds, active, X_W, T1_W, T2_W)
                R = R_WS[j]
                st, _, T1, T2, a = _wrap_one(kinds[j], R.T @ (P_W - X_W[j]), R.T @ (Q_W - X_W[j]), dims[j], sides[j])
                if st < 0:
                    status[p] = st
                    break
                new_active = st == 1
                t1 = X_W[j] + R @ T1
                t2 = X_W[j] + R @ T2
                if new_active != active[j]:
                    change = np.inf
                elif new_active:
                    change = max(change, np.sqrt((t1 - T1_W[j]) @ (t1 - T1_W[j])), np.sqrt((t2 - T2_W[j]) @ (t2 - T2_W[j])))
                active[j] = new_active
                T1_W[j] = t1
                T2_W[j] = t2
                arc[j] = a
            if status[p] < 0:
                break
            if change <= 1e-14 * scale:
                settled = True
                break
        if status[p] < 0:
            l[p] = np.nan
            continue
        if adjacent and not settled:
            status[p] = -3
            l[p] = np.nan
            continue
        # l = Σ segments + Σ arcs;  L = Σ eᵀ (M_B − M_A), tangent points fixed in their bodies
        last_body, last_x = bodies[j0], X_W[j0]
        total = 0.0
        for j in range(j0 + 1, j1):
            if kinds[j] == POINT:
                total += _add_segment(L, p, column, p_WB, R_WB, last_body, last_x, bodies[j], X_W[j])
                last_body, last_x = bodies[j], X_W[j]
            elif active[j]:
                total += _add_segment(L, p, column, p_WB, R_WB, last_body, last_x, bodies[j], T1_W[j])
                total += arc[j]
                T_W[j, 0] = T1_W[j]
                T_W[j, 1] = T2_W[j]
                last_body, last_x = bodies[j], T2_W[j]
        l[p] = total
    return l, L, status, T_W


class WrapNodes:
    """The node arrays of one or more wrapped paths, ready for the kernel.

    paths : list of node lists; a node is ``(body, p_BP)`` for a point or a
    :class:`WrapSurface`. names : the paths' names (error messages).
    """

    def __init__(self, paths, names):
        kinds, bodies, p_B, R_BS, dims, sides, start = [], [], [], [], [], [], [0]
        for nodes in paths:
            for node in nodes:
                if isinstance(node, WrapSurface):
                    kinds.append(SURFACE_KINDS[node.kind])
                    bodies.append(node.body)
                    p_B.append(node.p_BS)
                    R_BS.append(node.R_BS)
                    dims.append(node.dims)
                    sides.append(node.side)
                else:
                    body, p_BP = node
                    kinds.append(POINT)
                    bodies.append(body)
                    p_B.append(p_BP)
                    R_BS.append(np.eye(3))
                    dims.append(np.zeros(3))
                    sides.append(np.zeros(3))
            start.append(len(kinds))
        self.names = list(names)
        self.kinds = np.array(kinds, dtype=np.int64)
        self.bodies = np.array(bodies, dtype=np.int64)
        self.p_B = np.array(p_B, dtype=float).reshape(-1, 3)
        self.R_BS = np.array(R_BS, dtype=float).reshape(-1, 3, 3)
        self.dims = np.array(dims, dtype=float).reshape(-1, 3)
        self.sides = np.array(sides, dtype=float).reshape(-1, 3)
        self.start = np.array(start, dtype=np.int64)
        self.n_paths = len(self.names)

    def evaluate(self, state, with_tangents=False):
        """l (n_paths,) m and L (n_paths, n_coords); raises FloatingPointError naming the
        path when a path cannot be formed (a point inside a surface, no convergence)."""
        l, L, status, T_W = wrapped_path_lengths(
            state.p_WB, state.R_WB, state.column, self.kinds, self.bodies, self.p_B, self.R_BS,
            self.dims, self.sides, self.start, state.n_coords)
        bad = np.flatnonzero(status)
        if len(bad):
            k = bad[0]
            raise FloatingPointError(f"path {self.names[k]!r}: {STATUS_TEXT[int(status[k])]}")
        return (l, L, T_W) if with_tangents else (l, L)


class WrappedPath(Measure):
    """Length (m) of a path through body points and wrapping surfaces (a scalar measure).

    nodes : list of ``(body, p_BP (3,) m)`` points and :class:`WrapSurface` objects, first
    and last a point. ``evaluate`` gives (l (1,), L (1, n), b (1,)); b = L̇ v is a central
    difference of L along v on the manifold (step 1e-6 s, relative error ~1e-8).
    """

    size = 1
    units = ("length",)

    def __init__(self, nodes, name=""):
        self.nodes = list(nodes)
        self.name = name
        self.kernel = WrapNodes([self.nodes], [name])

    def bodies(self):
        return tuple(sorted({n.body if isinstance(n, WrapSurface) else int(n[0]) for n in self.nodes}))

    def tangent_points(self, state):
        """World tangent points (n_nodes, 2, 3) m of each surface (NaN if not in contact)."""
        return self.kernel.evaluate(state, with_tangents=True)[2]

    def evaluate(self, state, order=1):
        l, L = self.kernel.evaluate(state)
        if order == 0:
            return l, None, None
        if order == 1:
            return l, L, None
        v = state.get_v()
        h = 1e-6
        base = state.copy()
        state.displace(h * v)
        Lp = self.kernel.evaluate(state)[1]
        _restore_pose(state, base)
        state.displace(-h * v)
        Lm = self.kernel.evaluate(state)[1]
        _restore_pose(state, base)
        b = ((Lp - Lm) / (2.0 * h)) @ v
        return l, L, b


def _restore_pose(state, base):
    state.p_WB[:] = base.p_WB
    state.quat_WB[:] = base.quat_WB
    state.R_WB[:] = base.R_WB


__all__ = ["WrapSurface", "WrappedPath", "WrapNodes", "wrapped_path_lengths", "SURFACE_KINDS"]
