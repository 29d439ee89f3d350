"""Procedural contact surfaces: sphere cap, flat patch, ellipsoid cap, fossa-like surface.

Used by tests (closed-form contact cases) and by the contact benchmark (a condyle-like cap
against a fossa-like surface). All sizes in m; every surface is open and its triangle
normals point out of the "bone" toward the joint space, as contact requires
(see :mod:`openfdk.contact.mesh`).

Curved surfaces are triangulated by mapping a 2-D point set (a hexagonal lattice clipped
to an ellipse plus equally spaced boundary points, Delaunay-triangulated) onto the surface,
so triangles are close to equilateral with the requested edge length.
"""

from __future__ import annotations

import numpy as np

from .mesh import SurfaceMesh, surface_mesh

__all__ = ["flat_patch", "sphere_cap", "ellipsoid_cap", "fossa_surface"]


def _ellipse_points(ax, ay, spacing):
    """2-D points (k, 2) filling the ellipse (u/ax)² + (v/ay)² ≤ 1 about every ``spacing``."""
    # boundary: equal arc-length samples of the ellipse
    t = np.linspace(0.0, 2.0 * np.pi, 4001)
    ring = np.c_[ax * np.cos(t), ay * np.sin(t)]
    arc = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(ring, axis=0), axis=1))]
    n_boundary = max(8, int(round(arc[-1] / spacing)))
    s = np.linspace(0.0, arc[-1], n_boundary, endpoint=False)
    t_b = np.interp(s, arc, t)
    boundary = np.c_[ax * np.cos(t_b), ay * np.sin(t_b)]
    # interior: hexagonal lattice (rows spacing·√3/2 apart), keep points ≥ spacing/2 inside
    dy = spacing * np.sqrt(3.0) / 2.0
    rows = np.arange(-np.ceil(ay / dy), np.ceil(ay / dy) + 1)
    pts = []
    for r in rows:
        shift = 0.5 * spacing * (int(r) % 2)
        u = np.arange(-np.ceil(ax / spacing) - 1, np.ceil(ax / spacing) + 2) * spacing + shift
        pts.append(np.c_[u, np.full_like(u, r * dy)])
    lattice = np.concatenate(pts)
    # inside the ellipse shrunk by half a spacing
    inner = (lattice[:, 0] / max(ax - 0.5 * spacing, 1e-300)) ** 2 + (
        lattice[:, 1] / max(ay - 0.5 * spacing, 1e-300)
    ) ** 2 < 1.0
    return np.concatenate([lattice[inner], boundary])


def _triangulate(points_2d):
    """Delaunay triangles (m, 3) of a convex 2-D point set, counter-clockwise."""
    from scipy.spatial import Delaunay

    tri = Delaunay(points_2d).simplices.astype(np.int64)
    p = points_2d
    signed = (p[tri[:, 1], 0] - p[tri[:, 0], 0]) * (p[tri[:, 2], 1] - p[tri[:, 0], 1]) - (
        p[tri[:, 1], 1] - p[tri[:, 0], 1]
    ) * (p[tri[:, 2], 0] - p[tri[:, 0], 0])
    tri[signed < 0] = tri[signed < 0][:, ::-1]
    return tri


def flat_patch(size_x, size_y, edge_length, name="flat patch") -> SurfaceMesh:
    """Rectangle in the plane z = 0, centred at the origin, normals +z.

    Parameters: size_x, size_y, edge_length — m. A regular grid of
    ``round(size/edge_length) + 1`` points per side, each square split in two triangles.
    """
    nx = max(2, int(round(size_x / edge_length)) + 1)
    ny = max(2, int(round(size_y / edge_length)) + 1)
    x = np.linspace(-0.5 * size_x, 0.5 * size_x, nx)
    y = np.linspace(-0.5 * size_y, 0.5 * size_y, ny)
    X, Y = np.meshgrid(x, y, indexing="ij")
    vertices = np.c_[X.ravel(), Y.ravel(), np.zeros(X.size)]
    idx = np.arange(nx * ny).reshape(nx, ny)
    a, b = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel()
    c, d = idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
    faces = np.concatenate([np.c_[a, b, c], np.c_[a, c, d]])  # counter-clockwise from +z
    return surface_mesh(vertices, faces, name=name, repair=False)


def sphere_cap(radius, half_angle, edge_length, *, pole=(0.0, 0.0, -1.0), inward=False,
               center=(0.0, 0.0, 0.0), name="sphere cap") -> SurfaceMesh:
    """Cap of a sphere around the direction ``pole``.

    Parameters
    ----------
    radius : m. half_angle : rad, the cap spans polar angles [0, half_angle] from ``pole``.
    edge_length : m, approximate triangle edge length.
    pole : (3,) direction from the centre to the middle of the cap.
    inward : False → normals point away from the centre (a ball); True → toward the
        centre (a cup / socket surface).
    center : (3,) m, sphere centre.

    Vertices lie exactly on the sphere (azimuthal-equidistant map of a disc of radius
    ``radius·half_angle``).
    """
    pole = np.asarray(pole, dtype=float)
    pole = pole / np.linalg.norm(pole)
    rho_max = radius * half_angle
    uv = _ellipse_points(rho_max, rho_max, edge_length)
    tri = _triangulate(uv)
    rho = np.hypot(uv[:, 0], uv[:, 1])
    theta = rho / radius
    phi = np.arctan2(uv[:, 1], uv[:, 0])
    # local frame (e1, e2, pole); right-handed so counter-clockwise in (u, v) faces +pole
    helper = np.array([1.0, 0.0, 0.0]) if abs(pole[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    e1 = np.cross(helper, pole)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(pole, e1)
    local = np.c_[np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)]
    vertices = radius * (local @ np.vstack([e1, e2, pole])) + np.asarray(center, dtype=float)
    if inward:
        tri = tri[:, ::-1]
    return surface_mesh(vertices, tri, name=name, repair=False)


def ellipsoid_cap(semi_axes, edge_length, name="ellipsoid cap") -> SurfaceMesh:
    """Upper half (z ≥ 0) of the ellipsoid (x/a)² + (y/b)² + (z/c)² = 1, normals outward.

    Parameters: semi_axes (a, b, c) m; edge_length m (approximate, largest along the
    longest axis). The base ellipse lies in z = 0; the top is at (0, 0, c).
    A condyle-like cap is ``ellipsoid_cap((10e-3, 4.5e-3, 4e-3), ...)``: 20 mm
    medio-lateral (x), 9 mm antero-posterior (y).
    """
    a, b, c = (float(s) for s in semi_axes)
    half_pi = 0.5 * np.pi
    # parameter domain: ellipse with semi-axes (a·π/2, b·π/2) ~ arc length over the cap
    uv = _ellipse_points(a * half_pi, b * half_pi, edge_length)
    tri = _triangulate(uv)
    un, vn = uv[:, 0] / (a * half_pi), uv[:, 1] / (b * half_pi)
    rho = np.minimum(np.hypot(un, vn), 1.0)
    theta = rho * half_pi  # polar angle from +z
    phi = np.arctan2(vn, un)
    vertices = np.c_[
        a * np.sin(theta) * np.cos(phi), b * np.sin(theta) * np.sin(phi), c * np.cos(theta)
    ]
    return surface_mesh(vertices, tri, name=name, repair=False)


def fossa_surface(length_ap=28e-3, width_ml=26e-3, edge_length=0.38e-3, *,
                  eminence_height=6e-3, eminence_distance=14e-3, ml_radius=35e-3,
                  name="fossa") -> SurfaceMesh:
    """Fossa-like height field: a concave roof with an articular eminence in front.

        z(x, y) = −½ H (1 − cos(π x / L)) − y² / (2 R_ml)

    over x (anterior) in [−0.32, 0.68]·length_ap and y (medio-lateral) in ±width_ml/2,
    on a regular grid of about ``edge_length`` (two triangles per square). The roof
    (glenoid fossa) is at the origin, the highest point; the eminence crest is at x = L,
    z = −H. Curvature radius along x at roof and crest: 2 L² / (H π²) (6.6 mm for the
    defaults); along y: R_ml (35 mm, flatter than a 20 mm-wide condyle's 25 mm). The
    defaults give ≈ 10 000 triangles. Normals point down (−z at the roof): out of the
    skull, into the joint space.

    Parameters: length_ap, width_ml, edge_length, eminence_height (H),
    eminence_distance (L), ml_radius (R_ml) — all m.
    """
    x0 = -0.32 * length_ap
    nx = max(2, int(round(length_ap / edge_length)) + 1)
    ny = max(2, int(round(width_ml / edge_length)) + 1)
    x = np.linspace(x0, x0 + length_ap, nx)
    y = np.linspace(-0.5 * width_ml, 0.5 * width_ml, ny)
    X, Y = np.meshgrid(x, y, indexing="ij")
    H, L = eminence_height, eminence_distance
    Z = -0.5 * H * (1.0 - np.cos(np.pi * X / L)) - Y**2 / (2.0 * ml_radius)
    vertices = np.c_[X.ravel(), Y.ravel(), Z.ravel()]
    idx = np.arange(nx * ny).reshape(nx, ny)
    a, b = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel()
    c, d = idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
    # clockwise seen from +z, so the normals point down into the joint space
    faces = np.concatenate([np.c_[a, c, b], np.c_[a, d, c]])
    return surface_mesh(vertices, faces, name=name, repair=False)
