"""World polylines of wrapped paths (muscles, ligaments, springs over cylinders, spheres
and ellipsoids), one per frame, for the viewer.

A wrapped path is not a chain of body points: its tangent points slide over the
surfaces. At each frame's recorded body poses the wrapping kernel
(:meth:`openfdk.forces.wrapping.WrapNodes.evaluate`) gives the world tangent points
T1, T2 of every surface in contact; the polyline is then

    point, …, T1, arc samples, T2, …, point

with straight segments between points/tangent points and each arc sampled at
``ARC_POINTS`` points (T1 and T2 included):

* cylinder: the helix about z_S from T1 to T2, angle and height linear in the parameter;
* sphere:   the great circle about n = (T1 − o) × d, d the incoming segment direction;
* ellipsoid: the geodesic ODE shot from T1 along d projected on the tangent plane, over
  the arc length of the kernel's single-surface solution (Dormand–Prince, see
  :func:`openfdk.forces.wrap_kernels.shoot_geodesic`).

The direction of turn comes from the incoming segment (the path is tangent at T1), so
long-way-round wraps (θ > π) are drawn correctly. A surface not in contact contributes
ARC_POINTS copies of the previous vertex (zero-length segments), so every path has a
fixed number of points and all frames pack as one (nf, n_points, 3) float32 array.
Frames without poses, or where the path cannot be formed, are NaN (not drawn).
"""

from __future__ import annotations

import numpy as np

from ..forces.wrap_kernels import ELLIPSOID_TOL, ellipsoid_wrap, shoot_geodesic
from ..forces.wrapping import WrappedPath, WrapSurface
from ..model.state import BodyStates

#: points per arc (T1 and T2 included)
ARC_POINTS = 16
#: integrator steps per arc sample of an ellipsoid geodesic
GEODESIC_SUBSTEPS = 8


def wrapped_measure(measure):
    """The WrappedPath of a muscle/ligament path or spring measure, or None."""
    return measure if isinstance(measure, WrappedPath) else None


def n_points(path):
    """Fixed polyline point count of a WrappedPath: 1 per point node, ARC_POINTS per surface."""
    return sum(ARC_POINTS if isinstance(n, WrapSurface) else 1 for n in path.nodes)


def _arc_S(kind, T1, T2, d, dims, k):
    """k points (k, 3) m in the surface frame S from T1 to T2 (S) on a cylinder (helix)
    or sphere (great circle), leaving T1 along the incoming direction d (S); dims (3,) m."""
    u = np.linspace(0.0, 1.0, k)
    if kind == "cylinder":
        a1, a2 = np.arctan2(T1[1], T1[0]), np.arctan2(T2[1], T2[0])
        turn = 1.0 if T1[0] * d[1] - T1[1] * d[0] >= 0 else -1.0  # sign of (T1 × d)·z_S
        theta = (turn * (a2 - a1)) % (2 * np.pi)
        a = a1 + turn * theta * u
        r = dims[0]
        return np.stack([r * np.cos(a), r * np.sin(a), T1[2] + (T2[2] - T1[2]) * u], axis=1)
    n = np.cross(T1, d)
    n /= np.linalg.norm(n)
    b = np.cross(n, T1)  # sphere: T1 rotated by +90° about n (|b| = r)
    theta = np.arctan2(T2 @ b, T2 @ T1) % (2 * np.pi)
    a = theta * u
    return np.cos(a)[:, None] * T1 + np.sin(a)[:, None] * b


def _ellipsoid_arc_S(P, Q, T1, d, dims, side, k):
    """Geodesic samples (k, 3) m of the wrap P→Q (S) over the ellipsoid with semi-axes dims."""
    status, _l, _t1, _t2, s = ellipsoid_wrap(P, Q, dims, side, ELLIPSOID_TOL)
    if status != 1:
        raise FloatingPointError("the ellipsoid arc could not be re-formed")
    A = 1.0 / dims ** 2
    v = d - (d @ (A * T1)) * (A * T1) / ((A * T1) @ (A * T1))  # tangent-plane part
    v /= np.linalg.norm(v)
    out = np.empty((k, 3))
    out[0] = x = T1.copy()
    for i in range(1, k):
        x, v = shoot_geodesic(x, v, A, s / (k - 1), GEODESIC_SUBSTEPS)
        out[i] = x
    return out


def polyline(path, state, T_W=None):
    """World polyline (n_points(path), 3) m of ``path`` at ``state``'s poses (see the
    module docstring); raises FloatingPointError when the path cannot be formed.
    T_W : (n_nodes, 2, 3) m, the path's world tangent points at these poses when known
    (a wrapping-kernel call for many paths, :func:`wrapped_polylines`); None: found here."""
    T_W = path.tangent_points(state) if T_W is None else T_W
    pts = []
    nodes = path.nodes
    for j, node in enumerate(nodes):
        if not isinstance(node, WrapSurface):
            b, p_B = node
            pts.append(state.p_WB[b] + state.R_WB[b] @ p_B)
            continue
        T1, T2 = T_W[j]
        if not np.all(np.isfinite(T1)):  # lift-off: repeat the previous vertex
            pts.extend([pts[-1]] * ARC_POINTS)
            continue
        R_WS = state.R_WB[node.body] @ node.R_BS
        o_W = state.p_WB[node.body] + state.R_WB[node.body] @ node.p_BS
        to_S = lambda x: R_WS.T @ (x - o_W)  # noqa: E731
        T1_S, T2_S = to_S(T1), to_S(T2)
        d_S = R_WS.T @ (T1 - pts[-1])
        if node.kind == "ellipsoid":
            nxt = _next_anchor(nodes, T_W, j, state)
            arc = _ellipsoid_arc_S(to_S(pts[-1]), to_S(nxt), T1_S, d_S, node.dims, node.side, ARC_POINTS)
        else:
            arc = _arc_S(node.kind, T1_S, T2_S, d_S, node.dims, ARC_POINTS)
        pts.extend(o_W + arc @ R_WS.T)
    return np.array(pts)


def _next_anchor(nodes, T_W, j, state):
    """World position of the anchor after surface j: the next point, or the entry
    tangent point of the next surface in contact."""
    for k in range(j + 1, len(nodes)):
        node = nodes[k]
        if not isinstance(node, WrapSurface):
            b, p_B = node
            return state.p_WB[b] + state.R_WB[b] @ p_B
        if np.all(np.isfinite(T_W[k, 0])):
            return T_W[k, 0]
    raise AssertionError("a path ends with a point")


def wrapped_polylines(model, paths, poses):
    """(nf, Σ n_points, 3) m world polylines of ``paths`` (WrappedPath list) at every
    frame's poses (nf, nb, 7) [m, -]; NaN rows where the poses are missing or the path
    cannot be formed.

    One wrapping-kernel call per frame gives the tangent points of every path; the
    points and the cylinder and sphere arcs are then formed for all frames at once
    (:func:`_arcs_W`). A path over an ellipsoid is drawn frame by frame (:func:`polyline`:
    its geodesic is shot per frame), from that call's tangent points and one BodyStates
    per frame for all such paths (DM's 139-frame gait cycle, 84 of them: a state and a
    kernel call per path and frame were 2–3 s of the viewer's 7.5 s)."""
    from ..forces.wrap_kernels import wrapped_path_lengths
    from ..forces.wrapping import WrapNodes
    from ..numerics.spatial import rotation_matrix

    column = np.array([b.column for b in model.bodies])
    counts = [n_points(p) for p in paths]
    nf = len(poses)
    out = np.full((nf, sum(counts), 3), np.nan)
    if not paths:
        return out
    offsets = np.cumsum([0] + counts)
    poses = np.asarray(poses, dtype=float)
    ok = np.all(np.isfinite(poses.reshape(nf, -1)), axis=1)
    p_WB = poses[:, :, :3]
    R_WB = np.moveaxis(rotation_matrix(np.moveaxis(poses[:, :, 3:], -1, 0)), (0, 1), (-2, -1))  # (nf, nb, 3, 3)
    kernel = WrapNodes([p.nodes for p in paths], [p.name for p in paths])
    T_W = np.full((nf, len(kernel.kinds), 2, 3), np.nan)
    formed = np.zeros((nf, len(paths)), dtype=bool)
    n_coords = 6 * int(np.count_nonzero(column >= 0))
    for f in np.flatnonzero(ok):
        _, _, status, T_W[f] = wrapped_path_lengths(
            np.ascontiguousarray(p_WB[f]), np.ascontiguousarray(R_WB[f]), column, kernel.kinds, kernel.bodies,
            kernel.p_B, kernel.R_BS, kernel.dims, kernel.sides, kernel.limits, kernel.start, n_coords, kernel.warm)
        formed[f] = status == 0
    curved = [k for k, path in enumerate(paths)  # in increasing order
              if any(isinstance(n, WrapSurface) and n.kind == "ellipsoid" for n in path.nodes)]
    frames = np.flatnonzero(ok & formed[:, curved].any(axis=1)) if curved else []
    for f in frames:
        state = BodyStates(poses[f, :, :3], poses[f, :, 3:], column)
        for k in curved:
            if formed[f, k]:
                try:
                    out[f, offsets[k]:offsets[k + 1]] = polyline(paths[k], state,
                                                                 T_W[f, kernel.start[k]:kernel.start[k + 1]])
                except FloatingPointError:
                    pass  # path not formed at this frame: not drawn (NaN)
    for k, path in enumerate(paths):
        if k in curved:
            continue
        rows = slice(offsets[k], offsets[k + 1])
        pts = _path_points_W(path, p_WB, R_WB, T_W[:, kernel.start[k]:kernel.start[k + 1]])
        pts[~(ok & formed[:, k])] = np.nan
        out[:, rows] = pts
    return out


def _path_points_W(path, p_WB, R_WB, T_W):
    """(nf, n_points(path), 3) m: the polyline of a path without ellipsoids at every
    frame, as :func:`polyline` forms it; T_W (nf, n_nodes, 2, 3) its tangent points."""
    nf = len(p_WB)
    pts = []
    for j, node in enumerate(path.nodes):
        if not isinstance(node, WrapSurface):
            b, p_B = node
            pts.append((p_WB[:, b] + R_WB[:, b] @ np.asarray(p_B, dtype=float))[:, None])
            continue
        prev = pts[-1][:, -1]
        T1, T2 = T_W[:, j, 0], T_W[:, j, 1]
        contact = np.all(np.isfinite(T1), axis=1)
        block = np.repeat(prev[:, None], ARC_POINTS, axis=1)  # lift-off: the previous vertex repeated
        if contact.any():
            R_WS = R_WB[contact, node.body] @ node.R_BS  # (nc, 3, 3)
            o_W = p_WB[contact, node.body] + R_WB[contact, node.body] @ node.p_BS
            to_S = lambda x: np.einsum("fji,fj->fi", R_WS, x - o_W)  # noqa: E731
            arc_S = _arcs_S(node.kind, to_S(T1[contact]), to_S(T2[contact]),
                            np.einsum("fji,fj->fi", R_WS, T1[contact] - prev[contact]), node.dims, ARC_POINTS)
            block[contact] = o_W[:, None] + np.einsum("fij,fkj->fki", R_WS, arc_S)
        pts.append(block)
    out = np.concatenate(pts, axis=1)
    assert out.shape == (nf, n_points(path), 3)
    return out


def _arcs_S(kind, T1, T2, d, dims, k):
    """:func:`_arc_S` for many frames: T1, T2, d (nf, 3) in the surface frame; returns
    (nf, k, 3) m."""
    u = np.linspace(0.0, 1.0, k)
    if kind == "cylinder":
        a1, a2 = np.arctan2(T1[:, 1], T1[:, 0]), np.arctan2(T2[:, 1], T2[:, 0])
        turn = np.where(T1[:, 0] * d[:, 1] - T1[:, 1] * d[:, 0] >= 0, 1.0, -1.0)  # sign of (T1 × d)·z_S
        theta = (turn * (a2 - a1)) % (2 * np.pi)
        a = a1[:, None] + (turn * theta)[:, None] * u
        r = dims[0]
        z = T1[:, 2, None] + (T2[:, 2] - T1[:, 2])[:, None] * u
        return np.stack([r * np.cos(a), r * np.sin(a), z], axis=2)
    n = np.cross(T1, d)
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    b = np.cross(n, T1)  # sphere: T1 rotated by +90° about n (|b| = r)
    theta = np.arctan2(np.einsum("fi,fi->f", T2, b), np.einsum("fi,fi->f", T2, T1)) % (2 * np.pi)
    a = theta[:, None] * u
    return np.cos(a)[:, :, None] * T1[:, None] + np.sin(a)[:, :, None] * b[:, None]


__all__ = ["ARC_POINTS", "n_points", "polyline", "wrapped_measure", "wrapped_polylines"]
