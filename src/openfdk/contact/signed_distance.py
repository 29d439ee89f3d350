"""Exact signed distance to an open, oriented triangle surface (libigl AABB tree).

For a query point x (in the surface's body frame B) let c be the closest point on the
surface and ``dist = |x − c|``. The sign comes from the *pseudo-normal* of the feature
that contains c (Bærentzen & Aanæs, IEEE TVCG 2005): the face normal if c is inside a
triangle, the sum of the two face normals if c is on an edge, the angle-weighted vertex
normal if c is a vertex. Then

    φ(x) = sign((x − c) · n_feature) · dist          (φ > 0 in front, φ < 0 behind)

and, where φ ≠ 0, the unit normal of the distance field is ∇φ = (x − c) / φ (equal to the
face normal when c is inside a triangle).

Open surfaces: a point whose closest point lies on the boundary rim (a boundary edge or a
boundary vertex) is *beyond the rim* — neither in front of nor behind the surface — and
is flagged ``valid = False``. Contact ignores such points.
"""

from __future__ import annotations

import numpy as np

from .mesh import SurfaceMesh, undirected_edge_keys

__all__ = ["OpenSurfaceDistance"]

# barycentric coordinate below which the closest point is taken to lie on an edge/vertex
_BARY_TOL = 1e-9


class OpenSurfaceDistance:
    """Signed distance, outward normal and rim test for one :class:`SurfaceMesh`.

    The AABB tree and the feature pseudo-normals are built once on construction.
    """

    def __init__(self, mesh: SurfaceMesh):
        import igl

        self.mesh = mesh
        self._V = np.ascontiguousarray(mesh.vertices_B, dtype=np.float64)
        self._F = np.ascontiguousarray(mesh.faces, dtype=np.int64)
        self._tree = igl.AABB()
        self._tree.init(self._V, self._F)
        F = self._F
        face_normals = mesh.face_normals_B
        # local edge k of a face is the edge opposite its vertex k: (v[k+1], v[k+2])
        ends = np.stack([F[:, [1, 2]], F[:, [2, 0]], F[:, [0, 1]]], axis=1)  # (m, 3, 2)
        keys = np.sort(ends.reshape(-1, 2), axis=1)
        _, edge_id, counts = np.unique(undirected_edge_keys(keys), return_inverse=True, return_counts=True)
        edge_id = edge_id.ravel()
        edge_normal = np.zeros((counts.size, 3))
        np.add.at(edge_normal, edge_id, np.repeat(face_normals, 3, axis=0))
        # (m, 3) boundary flag and (m, 3, 3) pseudo-normal of each local edge
        self._edge_is_rim = (counts[edge_id] == 1).reshape(-1, 3)
        self._edge_normal = edge_normal[edge_id].reshape(-1, 3, 3)
        vertex_is_rim = np.zeros(mesh.n_vertices, dtype=bool)
        vertex_is_rim[keys[counts[edge_id] == 1].ravel()] = True
        self._vertex_is_rim = vertex_is_rim
        self._face_normals = face_normals
        self._vertex_normals = np.asarray(mesh.vertex_normals_B)

    def query(self, p_BQ):
        """Signed distance of points to the surface.

        Parameters
        ----------
        p_BQ : (k, 3) m — query points in the surface's body frame B.

        Returns
        -------
        phi : (k,) m — signed distance, negative behind the surface (penetration depth
            is −phi).
        normal_B : (k, 3) — unit outward normal of the distance field at the points
            (∇φ; direction from the closest point toward the query point when φ > 0).
        valid : (k,) bool — False when the closest point is on the boundary rim.
        p_BC : (k, 3) m — closest points on the surface.
        """
        P = np.ascontiguousarray(p_BQ, dtype=np.float64).reshape(-1, 3)
        if P.shape[0] == 0:
            return np.zeros(0), np.zeros((0, 3)), np.zeros(0, dtype=bool), np.zeros((0, 3))
        sqr_dist, face, p_BC = self._tree.squared_distance(self._V, self._F, P)
        dist = np.sqrt(sqr_dist)
        F = self._F[face]
        v0, v1, v2 = self._V[F[:, 0]], self._V[F[:, 1]], self._V[F[:, 2]]
        bary = _barycentric(p_BC, v0, v1, v2)
        on_edge = bary < _BARY_TOL  # (k, 3): zero coordinate k → on edge opposite vertex k
        n_zero = on_edge.sum(axis=1)
        # pseudo-normal of the feature holding the closest point
        n_feature = self._face_normals[face].copy()
        valid = np.ones(P.shape[0], dtype=bool)
        edge_rows = np.flatnonzero(n_zero == 1)
        if edge_rows.size:
            k = np.argmax(on_edge[edge_rows], axis=1)
            n_feature[edge_rows] = self._edge_normal[face[edge_rows], k]
            valid[edge_rows] = ~self._edge_is_rim[face[edge_rows], k]
        vertex_rows = np.flatnonzero(n_zero >= 2)
        if vertex_rows.size:
            k = np.argmax(bary[vertex_rows], axis=1)  # the vertex with coordinate ≈ 1
            vid = F[vertex_rows, k]
            n_feature[vertex_rows] = self._vertex_normals[vid]
            valid[vertex_rows] = ~self._vertex_is_rim[vid]
        offset = P - p_BC
        side = np.einsum("ij,ij->i", offset, n_feature)
        sign = np.where(side < 0.0, -1.0, 1.0)
        phi = sign * dist
        # ∇φ = (x − c)/φ where the distance is resolvable, else the feature normal
        normal_B = np.empty_like(P)
        scale = max(float(np.ptp(self._V, axis=0).max()), 1e-300)
        far = dist > 1e-12 * scale
        normal_B[far] = offset[far] / phi[far, None]
        nf = n_feature[~far]
        normal_B[~far] = nf / np.linalg.norm(nf, axis=1)[:, None]
        return phi, normal_B, valid, p_BC


def _barycentric(p, a, b, c):
    """Barycentric coordinates (k, 3) of points p (k, 3) in triangles (a, b, c) (k, 3)."""
    v0, v1, v2 = b - a, c - a, p - a
    d00 = np.einsum("ij,ij->i", v0, v0)
    d01 = np.einsum("ij,ij->i", v0, v1)
    d11 = np.einsum("ij,ij->i", v1, v1)
    d20 = np.einsum("ij,ij->i", v2, v0)
    d21 = np.einsum("ij,ij->i", v2, v1)
    denom = d00 * d11 - d01 * d01
    w1 = (d11 * d20 - d01 * d21) / denom
    w2 = (d00 * d21 - d01 * d20) / denom
    return np.c_[1.0 - w1 - w2, w1, w2]
