"""Wrapped paths whose points depend on joint coordinates: OpenSim's PathWrap on a
GeometryPath with ConditionalPathPoints or MovingPathPoints.

A path is a list of :class:`~openfdk.forces.coordinate_path.PathNode` points (fixed,
conditional, moving) and :class:`~openfdk.forces.wrapping.WrapSurface` surfaces. Per
evaluation one kernel gives each point's presence, location in its body and velocity per
unit of its coordinate (:func:`~openfdk.forces.coordinate_path.coordinate_points`), and
the wrapping kernel forms the path through the present points
(:func:`~openfdk.forces.wrap_kernels.wrapped_moving_path_lengths`).

Length: as :mod:`.wrapping`, over the present points. Jacobian: the tangent points held
fixed in their surface's body (the path is locally shortest), plus, for a moving point
at the end of a straight segment of direction e, ± eᵀ (R R_BF f′(u)) ∂u/∂q̂
(:mod:`.coordinate_path`). A conditional point switches the path where its coordinate
crosses a bound, as in OpenSim (the length jumps there). A surface listed for a PathWrap
``range`` (``one_segment``) wraps only segments between present points of that range
(OpenSim scans the range for its first and last active points).
"""

from __future__ import annotations

import numpy as np

from ..model.measures import Measure
from .coordinate_path import CoordinatePathNodes, PathNode, coordinate_points
from .wrap_kernels import POINT, STATUS_TEXT, wrapped_moving_path_lengths
from .wrapping import PathSubsets, WrapNodes, WrapSurface, path_evaluate

__all__ = ["CoordinateWrapNodes", "CoordinateWrappedPath"]


def _spans(nodes):
    """(len(nodes), 2) node indices (within the path) of the points just before the first
    and just after the last listing of each ``one_segment`` surface (its PathWrap range),
    −1 for points and other surfaces."""
    span = np.full((len(nodes), 2), -1, dtype=np.int64)
    first, last = {}, {}
    for k, n in enumerate(nodes):
        if isinstance(n, WrapSurface) and n.one_segment:
            first.setdefault(n.name, k)
            last[n.name] = k
    for k, n in enumerate(nodes):
        if isinstance(n, WrapSurface) and n.one_segment:
            a = max(i for i in range(first[n.name]) if isinstance(nodes[i], PathNode))
            b = min(i for i in range(last[n.name] + 1, len(nodes)) if isinstance(nodes[i], PathNode))
            span[k] = a, b
    return span


class CoordinateWrapNodes(PathSubsets):
    """The arrays of one or more wrapped paths with coordinate-dependent points:
    ``evaluate(state)`` -> l (n_paths,) m, L (n_paths, n). paths : lists of PathNode and
    WrapSurface (first and last a fixed or moving point); names : the paths' names."""

    def __init__(self, paths, names):
        self._keep(paths, names)
        for nodes, name in zip(paths, names):
            for end in (nodes[0], nodes[-1]):
                if not isinstance(end, PathNode) or end.condition is not None:
                    raise ValueError(f"path {name!r}: a wrapped path starts and ends at a fixed or moving point")
        self.points = CoordinatePathNodes([[n for n in nodes if isinstance(n, PathNode)] for nodes in paths], names)
        self.wrap = WrapNodes([[(n.body, np.asarray(n.p_BF, float)) if isinstance(n, PathNode) else n for n in nodes]
                               for nodes in paths], names)
        self.rows = np.flatnonzero(self.wrap.kinds == POINT)
        offsets = self.wrap.start[:-1]
        self.span = np.concatenate([np.where(_spans(nodes) >= 0, _spans(nodes) + o, -1)
                                    for nodes, o in zip(paths, offsets)]).astype(np.int64).reshape(-1, 2)
        N = len(self.wrap.kinds)
        self.move = np.full(N, -1, dtype=np.int64)
        self.move[self.rows] = self.points.move
        self.names = list(names)
        self.n_paths = len(self.names)

    def evaluate(self, state, with_tangents=False):
        """l (n_paths,) m and L (n_paths, n_coords) (and T_W (N, 2, 3) m, the world
        tangent points); FloatingPointError naming a path that cannot be formed."""
        c, w = self.points, self.wrap
        u, U, _ = c.program.evaluate(state, 1)
        present_p, p_B_p, dX_p = coordinate_points(state.p_WB, state.R_WB, u, c.body, c.p, c.R_BF, c.cond,
                                                   c.cond_range, c.move, c.move_range, c.fn_start, c.fparams)
        N = len(w.kinds)
        present = np.ones(N, dtype=np.bool_)
        present[self.rows] = present_p
        p_B = w.p_B.copy()
        p_B[self.rows] = p_B_p
        dX_W = np.zeros((N, 3))
        dX_W[self.rows] = dX_p
        U = np.ascontiguousarray(U, dtype=float).reshape(-1, state.n_coords)
        if U.shape[0] == 0:
            U = np.zeros((1, state.n_coords))
        l, L, status, T_W = wrapped_moving_path_lengths(
            state.p_WB, state.R_WB, state.column, w.kinds, w.bodies, p_B, w.R_BS, w.dims, w.sides, w.limits, w.start,
            state.n_coords, present, dX_W, self.move, U, self.span, w.warm)
        bad = np.flatnonzero(status)
        if len(bad):
            k = bad[0]
            raise FloatingPointError(f"path {self.names[k]!r}: {STATUS_TEXT[int(status[k])]}")
        return (l, L, T_W) if with_tangents else (l, L)


class CoordinateWrappedPath(Measure):
    """Length (m) of a path through fixed, conditional and moving points and wrapping
    surfaces (a scalar measure; module docstring). nodes : list of PathNode and
    WrapSurface. ``evaluate`` gives (l (1,), L (1, n), b (1,)); b = L̇ v by a central
    difference of L along v."""

    size = 1
    units = ("length",)

    def __init__(self, nodes, name=""):
        self.nodes = list(nodes)
        self.name = name
        self.kernel = CoordinateWrapNodes([self.nodes], [name])

    def bodies(self):
        out = {int(n.body) for n in self.nodes}
        for n in self.nodes:
            for spec in (getattr(n, "condition", None), getattr(n, "moving", None)):
                if spec is not None:
                    out.update(spec[0].bodies())
        return tuple(sorted(out))

    def tangent_points(self, state):
        """World tangent points (n_nodes, 2, 3) m of each surface (NaN if not in contact)."""
        return self.kernel.evaluate(state, with_tangents=True)[2]

    def evaluate(self, state, order=1):
        return path_evaluate(self.kernel, state, order)
