"""Many muscle/ligament paths evaluated at once (numba kernels), for the hot loop.

A path is a chain of body points with straight segments (see :mod:`.elements`); the
kernel :func:`openfdk.model.kernels.path_lengths` returns every path's length (m) and
Jacobian L = ∂l/∂q̂ in one call. Paths over wrapping surfaces
(:class:`~openfdk.forces.wrapping.WrappedPath`) go through one call of
:func:`openfdk.forces.wrapping.wrapped_path_lengths`, and paths with conditional or
moving points (:class:`~openfdk.forces.coordinate_path.CoordinatePath`) through one call
of :func:`openfdk.forces.coordinate_path.coordinate_path_lengths`; wrapped paths with
such points (:class:`~openfdk.forces.coordinate_wrapping.CoordinateWrappedPath`) through
one call of each.
"""

from __future__ import annotations

import numpy as np

from ..model.kernels import path_lengths
from ..numerics.numdiff import manifold_jacobian
from .path_stiffness import add_path_geometric_stiffness
from .wrap_stiffness import DONE, single_surface_paths, single_wrap_stiffness_along
from .coordinate_path import CoordinatePath, CoordinatePathNodes
from .coordinate_wrapping import CoordinateWrapNodes, CoordinateWrappedPath
from .wrapping import WrapNodes, WrappedPath


class PathSet:
    """Lengths and Jacobians of the paths of ``elements`` (each with ``.path``, a Linear
    of Distance measures as built by :func:`openfdk.forces.elements.path_measure`)."""

    def __init__(self, elements):
        seg_a, s_a, seg_b, s_b, seg_path = [], [], [], [], []
        wrapped = [k for k, el in enumerate(elements) if isinstance(el.path, WrappedPath)]
        self.wrapped_rows = np.array(wrapped, dtype=np.int64)
        self.wrapped = WrapNodes([elements[k].path.nodes for k in wrapped], [elements[k].name for k in wrapped]) if wrapped else None
        #: the wrapped paths over one surface (bool over the wrapped rows): their geometric
        #: stiffness along directions has a kernel (:mod:`.wrap_stiffness`)
        self.single_surface = np.zeros(len(wrapped), dtype=bool)
        if wrapped:
            self.single_surface[single_surface_paths(self.wrapped.kinds, self.wrapped.limits, self.wrapped.start)] = True
        moving = [k for k, el in enumerate(elements) if isinstance(el.path, CoordinatePath)]
        self.moving_rows = np.array(moving, dtype=np.int64)
        self.moving = CoordinatePathNodes([elements[k].path.nodes for k in moving],
                                          [elements[k].name for k in moving]) if moving else None
        mixed = [k for k, el in enumerate(elements) if isinstance(el.path, CoordinateWrappedPath)]
        self.mixed_rows = np.array(mixed, dtype=np.int64)
        self.mixed = CoordinateWrapNodes([elements[k].path.nodes for k in mixed],
                                         [elements[k].name for k in mixed]) if mixed else None
        for k, el in enumerate(elements):
            if isinstance(el.path, (WrappedPath, CoordinatePath, CoordinateWrappedPath)):
                continue
            for C, dist in el.path.terms:
                if C.shape != (1, 1) or C[0, 0] != 1.0 or not hasattr(dist, "vector"):
                    raise ValueError(f"path of {el.name!r} is not a chain of segments")
                v = dist.vector
                seg_a.append(v.point_a.body)
                s_a.append(v.point_a.p_BP)
                seg_b.append(v.point_b.body)
                s_b.append(v.point_b.p_BP)
                seg_path.append(k)
        self.n_paths = len(elements)
        self.seg_a = np.array(seg_a, dtype=np.int64)
        self.seg_b = np.array(seg_b, dtype=np.int64)
        self.s_a = np.array(s_a, dtype=float).reshape(-1, 3)
        self.s_b = np.array(s_b, dtype=float).reshape(-1, 3)
        self.seg_path = np.array(seg_path, dtype=np.int64)

    def evaluate(self, state):
        """l (n_paths,) m and L (n_paths, n_coords)."""
        l, L = path_lengths(state.p_WB, state.R_WB, state.column, self.seg_a, self.s_a, self.seg_b,
                            self.s_b, self.seg_path, self.n_paths, state.n_coords)
        if self.wrapped is not None:
            l[self.wrapped_rows], L[self.wrapped_rows] = self.wrapped.evaluate(state)
        if self.moving is not None:
            l[self.moving_rows], L[self.moving_rows] = self.moving.evaluate(state)
        if self.mixed is not None:
            l[self.mixed_rows], L[self.mixed_rows] = self.mixed.evaluate(state)
        return l, L

    def _tensed_wrapped(self, T, L):
        """(node set, tensions (k,) N, T·L (n,) at the state, touched columns) of the tensed
        paths of each kind of wrapped nodes, and T (n_paths,) with those rows zeroed
        (the straight paths' tensions)."""
        T = np.ascontiguousarray(T, dtype=float)
        straight = T.copy()
        groups = []
        for nodes, rows in ((self.wrapped, self.wrapped_rows), (self.moving, self.moving_rows),
                            (self.mixed, self.mixed_rows)):
            if nodes is None:
                continue
            straight[rows] = 0.0
            T_w = T[rows]
            tensed = np.flatnonzero(T_w != 0.0)
            if len(tensed):
                # only the tensed paths are differenced (a slack path adds nothing), and
                # only over the bodies they touch: a body whose 6 columns of L are all zero
                # for them (not a point's, not a wrapping surface's in contact) is not
                # perturbed
                touched = np.any(L[rows][tensed] != 0.0, axis=0).reshape(-1, 6).any(axis=1)
                columns = (6 * np.flatnonzero(touched)[:, None] + np.arange(6)).ravel()
                part = nodes.subset(tensed) if hasattr(nodes, "subset") else nodes
                T_p = T_w[tensed] if part is not nodes else T_w
                groups.append((part, T_p, T_p @ L[rows][tensed if part is not nodes else slice(None)], columns))
        return groups, straight

    def add_geometric_stiffness(self, state, T, L, K):
        """K (n, n) −= Σ_p T_p ∂L_pᵀ/∂q̂ at ``state`` for tensions T (n_paths,) N, the
        geometric stiffness of Q = −Lᵀ T; L (n_paths, n): the Jacobians at ``state``.
        Straight paths in closed form (:mod:`.path_stiffness`); wrapped paths by one
        batched forward difference of their analytic Jacobians on the manifold."""
        groups, straight = self._tensed_wrapped(T, L)
        for part, T_p, f0, columns in groups:
            K -= manifold_jacobian(lambda s: T_p @ part.evaluate(s)[1], state, 1e-7, central=False, f0=f0,
                                   columns=columns)
        add_path_geometric_stiffness(state.p_WB, state.R_WB, state.column, self.seg_a, self.s_a, self.seg_b,
                                     self.s_b, self.seg_path, straight, K)

    def geometric_stiffness_along(self, state, T, L, U):
        """−Σ_p T_p (∂L_pᵀ/∂q̂) U (n, m) at ``state`` for tensions T (n_paths,) N and
        directions U (n, m) [m, rad]: :meth:`add_geometric_stiffness` times U, the
        wrapped paths by one forward difference along each column of U (step 1e-7 of
        its largest entry) instead of one per touched coordinate (a knee's 10 FDK
        directions against the 18 coordinates of femur, tibia and patella). The tensed
        paths over one surface take the closed form with their tangent points'
        derivatives (:mod:`.wrap_stiffness`: five wrap solves of each such path, a
        geodesic's one solve and six shots, instead of one of every tensed path per
        direction) unless a difference there changes the contact."""
        KU_single, T = self._single_surface_along(state, T, U)
        groups, straight = self._tensed_wrapped(T, L)
        K = np.zeros((state.n_coords, state.n_coords))
        add_path_geometric_stiffness(state.p_WB, state.R_WB, state.column, self.seg_a, self.s_a, self.seg_b,
                                     self.s_b, self.seg_path, straight, K)
        KU = K @ U
        for part, T_p, f0, _ in groups:
            for j in range(U.shape[1]):
                h = 1e-7 / max(float(np.max(np.abs(U[:, j]))), 1e-12)
                moved = state.copy()
                moved.displace(h * U[:, j])
                KU[:, j] -= (T_p @ part.evaluate(moved)[1] - f0) / h
        return KU + KU_single

    def _single_surface_along(self, state, T, U):
        """(−Σ T_p (∂L_pᵀ/∂q̂) U (n, m) of the tensed single-surface wrapped paths, T
        (n_paths,) with their tensions zeroed), or (0, T) when a difference changed a
        contact (those paths are then differenced along U)."""
        if self.wrapped is None:
            return 0.0, T
        T_w = np.asarray(T, dtype=float)[self.wrapped_rows]
        paths = np.flatnonzero((T_w != 0.0) & self.single_surface)
        if not len(paths):
            return 0.0, T
        w = self.wrapped
        status, KU = single_wrap_stiffness_along(
            state.p_WB, state.R_WB, state.column, w.kinds, w.bodies, w.p_B, w.R_BS, w.dims, w.sides, w.limits,
            w.start, w.warm, paths, np.ascontiguousarray(T_w[paths]), np.ascontiguousarray(U, dtype=float))
        if status != DONE:
            return 0.0, T
        rest = np.array(T, dtype=float)
        rest[self.wrapped_rows[paths]] = 0.0
        return KU, rest
