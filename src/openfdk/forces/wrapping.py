"""Muscle and ligament paths through via points and wrapping surfaces, in any order.

A path is a list of *nodes*: body points and wrapping surfaces (cylinder, sphere,
ellipsoid fixed to a body, see :mod:`.wrap_kernels`). The first and last nodes are
points. Each surface wraps the path between its neighbouring anchors: the previous point
(or the exit tangent point T2 of the previous surface in contact) and the next point (or
the entry tangent point T1 of the next surface in contact). Surfaces next to each other
are solved by block Gauss–Seidel sweeps until the tangent points stop moving.

Length:  l = Σ straight segments + Σ geodesic arcs.
Jacobian (moment arms): the path is locally shortest, so by the envelope theorem
∂l/∂q̂ equals the derivative with the tangent points held fixed *in their surface's
body*; the arcs are then rigid and only the straight segments count:
L = Σ_segments eᵀ (M_B − M_A), e the unit segment direction, M the point Jacobians
(docs/design.md §1). This is exact for the closed-form cylinder and sphere arcs and as
accurate as the shooting tolerance for the ellipsoid. Lengthening speed l̇ = L v; a
tension T acts as Q = −Lᵀ T. The acceleration bias b = L̇ v (needed only when a path
length is driven or used as a constraint) is a central difference of L along v.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..model.measures import Measure
from .wrap_kernels import (CROSSING_ONLY, INSIDE_STRAIGHT, OPENSIM_PLANE, POINT, STATUS_TEXT, SURFACE_KINDS, WARM_SIZE,
                           wrapped_path_lengths)


@dataclass(frozen=True, eq=False)
class WrapSurface:
    """A wrapping surface fixed to a body.

    kind : "cylinder" (axis z_S, infinite), "sphere" or "ellipsoid" (semi-axes along
    x_S, y_S, z_S); body : body index; p_BS (3,) m and R_BS (3, 3): the surface frame S
    in the body frame; dims (3,) m: (r, r, r) or the semi-axes (a, b, c); side (3,): a
    direction in S on which the path must pass (zeros: the shorter way). half_length m:
    a cylinder's half length (inf: infinite; finite: no wrap while both tangent points
    lie beyond it, OpenSim's WrapCylinder ``length``); crossing_only: a sphere or
    ellipsoid wraps only while the straight line between its anchors crosses it
    (OpenSim's rule for WrapSphere and WrapEllipsoid), ``side`` then only picks the way
    round; inside_straight: an anchor inside the surface leaves the path straight
    (OpenSim's rule) instead of being an error; one_segment: listed in several segments
    of a path, the surface wraps one of them, the first whose straight line crosses it,
    else the one that lengthens least (OpenSim's PathWrap over a range of points);
    opensim_plane: an ellipsoid's path is OpenSim's planar curve, ``side`` its quadrant
    (:mod:`.wrap_ellipsoid_plane`).
    """

    name: str
    kind: str
    body: int
    p_BS: np.ndarray
    R_BS: np.ndarray
    dims: np.ndarray
    side: np.ndarray
    half_length: float = np.inf
    crossing_only: bool = False
    inside_straight: bool = False
    one_segment: bool = False
    opensim_plane: bool = False


def _groups(nodes, path_name):
    """{surface name: group id} of the ``one_segment`` surfaces a path lists more than
    once (each a group; the kernel wraps one of its segments)."""
    count = {}
    for node in nodes:
        if isinstance(node, WrapSurface) and node.one_segment:
            count[node.name] = count.get(node.name, 0) + 1
    return {name: k for k, name in enumerate(n for n, c in count.items() if c > 1)}


class PathSubsets:
    """Mixin of the node sets built from ``(paths, names)``: :meth:`subset` gives the
    node set of some of the paths (cached by rows), so that a finite difference over
    the tensed paths alone does not evaluate the slack ones (a knee's 149 ligament
    strands, most slack at any instant, share one kernel call)."""

    def _keep(self, paths, names):
        self._paths, self._names, self._subsets = list(paths), list(names), {}

    def subset(self, rows):
        """The node set (same class) of the paths ``rows`` (indices, increasing)."""
        key = tuple(int(r) for r in rows)
        if len(key) == len(self._paths):
            return self
        out = self._subsets.get(key)
        if out is None:
            if len(self._subsets) >= 8:
                self._subsets.clear()
            out = self._subsets[key] = type(self)([self._paths[r] for r in key], [self._names[r] for r in key])
        return out


class WrapNodes(PathSubsets):
    """The node arrays of one or more wrapped paths, ready for the kernel.

    paths : list of node lists; a node is ``(body, p_BP)`` for a point or a
    :class:`WrapSurface`. names : the paths' names (error messages).
    """

    def __init__(self, paths, names):
        self._keep(paths, names)
        kinds, bodies, p_B, R_BS, dims, sides, limits, start = [], [], [], [], [], [], [], [0]
        for nodes, path_name in zip(paths, names):
            groups = _groups(nodes, path_name)
            for node in nodes:
                if isinstance(node, WrapSurface):
                    kinds.append(SURFACE_KINDS[node.kind])
                    bodies.append(node.body)
                    p_B.append(node.p_BS)
                    R_BS.append(node.R_BS)
                    dims.append(node.dims)
                    sides.append(node.side)
                    limits.append((node.half_length, float(CROSSING_ONLY * node.crossing_only
                                                               + INSIDE_STRAIGHT * node.inside_straight
                                                               + OPENSIM_PLANE * node.opensim_plane),
                                   groups.get(node.name, -1)))
                else:
                    body, p_BP = node
                    kinds.append(POINT)
                    bodies.append(body)
                    p_B.append(p_BP)
                    R_BS.append(np.eye(3))
                    dims.append(np.zeros(3))
                    sides.append(np.zeros(3))
                    limits.append((np.inf, 0.0, -1))
            start.append(len(kinds))
        self.names = list(names)
        self.kinds = np.array(kinds, dtype=np.int64)
        self.bodies = np.array(bodies, dtype=np.int64)
        self.p_B = np.array(p_B, dtype=float).reshape(-1, 3)
        self.R_BS = np.array(R_BS, dtype=float).reshape(-1, 3, 3)
        self.dims = np.array(dims, dtype=float).reshape(-1, 3)
        self.sides = np.array(sides, dtype=float).reshape(-1, 3)
        self.limits = np.array(limits, dtype=float).reshape(-1, 3)
        self.start = np.array(start, dtype=np.int64)
        self.n_paths = len(self.names)
        # each ellipsoid node's last geodesic, the next solve's warm start (wrap_kernels.ellipsoid_wrap_from)
        self.warm = np.zeros((len(kinds), WARM_SIZE))

    def evaluate(self, state, with_tangents=False):
        """l (n_paths,) m and L (n_paths, n_coords); raises FloatingPointError naming the
        path when a path cannot be formed (a point inside a surface, no convergence)."""
        l, L, status, T_W = wrapped_path_lengths(
            state.p_WB, state.R_WB, state.column, self.kinds, self.bodies, self.p_B, self.R_BS,
            self.dims, self.sides, self.limits, self.start, state.n_coords, self.warm)
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
        return path_evaluate(self.kernel, state, order)


def path_evaluate(kernel, state, order=1):
    """(l (1,), L (1, n) or None, b (1,) or None) of a path measure whose ``kernel``
    gives (l, L) at a state: b = L̇ v by a central difference of L along v on the
    manifold (step 1e-6 s, relative error ~1e-8); the state's pose is restored."""
    l, L = kernel.evaluate(state)
    if order == 0:
        return l, None, None
    if order == 1:
        return l, L, None
    v = state.get_v()
    h = 1e-6
    base = state.copy()
    state.displace(h * v)
    Lp = kernel.evaluate(state)[1]
    _restore_pose(state, base)
    state.displace(-h * v)
    Lm = kernel.evaluate(state)[1]
    _restore_pose(state, base)
    return l, L, ((Lp - Lm) / (2.0 * h)) @ v


def _restore_pose(state, base):
    state.p_WB[:] = base.p_WB
    state.quat_WB[:] = base.quat_WB
    state.R_WB[:] = base.R_WB


__all__ = ["WrapSurface", "WrappedPath", "WrapNodes", "SURFACE_KINDS", "path_evaluate"]
