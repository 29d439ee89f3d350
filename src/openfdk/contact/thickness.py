"""Variable cartilage thickness from the bone behind it (OpenSim-JAM's
``Smith2018ContactMesh`` with ``use_variable_thickness``; Smith et al. 2018).

A cartilage mesh's triangle t has the thickness

    h_t = distance from its centre c_t along −n_t to the first hit on the back mesh

(n_t its outward unit normal, (v₂ − v₁) × (v₃ − v₁) normalised), taken as OpenSim-JAM
takes it: below ``min`` it is ``min``; a ray that misses the back mesh, or a distance
above ``max``, gives ``min`` too (JAM's rule: a ray past ``max`` has left the cartilage
through a gap of the bone mesh, not crossed a thick layer).

openfdk's elastic foundation tests the *vertices* of one surface (each with its
tributary area, a third of each incident triangle's) against the other surface. A vertex
of the vertices' surface gets the area-weighted mean of its triangles' thicknesses
(:func:`vertex_thickness`); a point of the opposite surface gets the thickness of the
triangle whose centre is nearest (:class:`TriangleThickness`), as JAM takes the
thickness of the triangle its ray hits. Both are in metres, in the mesh's body frame.
"""

from __future__ import annotations

import numpy as np

__all__ = ["triangle_thickness", "vertex_thickness", "TriangleThickness"]


def triangle_thickness(V, F, back_V, back_F, h_min, h_max):
    """h (n_tri,) m of the triangles (V (n, 3) m, F (n_tri, 3) int) of a cartilage mesh
    over its back mesh (back_V, back_F, same frame and unit), clamped as OpenSim-JAM
    clamps it (module docstring). Returns (h, hit (n_tri,) bool: the ray met the back
    mesh within ``h_max``)."""
    import igl

    V = np.ascontiguousarray(V, dtype=np.float64)
    F = np.ascontiguousarray(F, dtype=np.int64)
    back_V = np.ascontiguousarray(back_V, dtype=np.float64)
    back_F = np.ascontiguousarray(back_F, dtype=np.int64)
    from .mesh import _face_normals_and_areas

    n = _face_normals_and_areas(V, F)[0]  # (a degenerate triangle's zero normal casts no ray)
    centre = V[F].mean(axis=1)
    # libigl's ray–triangle test has an absolute tolerance: on triangles of 0.4 mm written
    # in metres every ray missed. The rays are cast in units of the back mesh's median
    # edge (the distances scale back exactly)
    edges = np.linalg.norm(back_V[back_F[:, [1, 2, 0]]] - back_V[back_F], axis=2)
    unit = float(np.median(edges)) if edges.size else 1.0
    unit = unit if unit > 0.0 else 1.0
    scaled_V = np.ascontiguousarray(back_V / unit)
    tree = igl.AABB()
    tree.init(scaled_V, back_F)
    face, t, _ = tree.intersect_ray_first(scaled_V, back_F, np.ascontiguousarray(centre / unit),
                                          np.ascontiguousarray(-n))
    t = np.asarray(t, dtype=np.float64) * unit
    hit = (np.asarray(face) >= 0) & np.isfinite(t) & (t >= 0.0) & (t <= h_max)
    h = np.where(hit, np.maximum(t, h_min), h_min)
    return h, hit


def vertex_thickness(mesh, h_tri):
    """h (n_vertices,) m of a SurfaceMesh's vertices: the mean of their triangles'
    thicknesses h_tri (n_tri,) weighted by the triangles' areas (the vertex's tributary
    area, a third of each); a vertex of no triangle gets the mean thickness."""
    from .mesh import _face_normals_and_areas

    F = mesh.faces
    area = _face_normals_and_areas(mesh.vertices_B, F)[1]
    num = np.zeros(mesh.vertices_B.shape[0])
    den = np.zeros(mesh.vertices_B.shape[0])
    for k in range(3):
        np.add.at(num, F[:, k], area * h_tri)
        np.add.at(den, F[:, k], area)
    mean = float(np.sum(area * h_tri) / max(np.sum(area), 1e-300))
    return np.where(den > 0.0, num / np.where(den > 0.0, den, 1.0), mean)


class TriangleThickness:
    """The thickness of a surface at points near it: that of the triangle whose centre is
    nearest (a k-d tree of the centres, in the surface body's frame)."""

    def __init__(self, mesh, h_tri):
        from scipy.spatial import cKDTree

        V, F = mesh.vertices_B, mesh.faces
        self.h = np.asarray(h_tri, dtype=np.float64)
        self._tree = cKDTree((V[F[:, 0]] + V[F[:, 1]] + V[F[:, 2]]) / 3.0)

    def at(self, points):
        """h (k,) m at points (k, 3) m of the surface's body frame."""
        if len(points) == 0:
            return np.zeros(0)
        return self.h[self._tree.query(np.asarray(points, dtype=np.float64))[1]]
