"""Simple, recognisable display meshes of the virtual subject's skull and mandible
(``skull.stl``, ``mandible.stl`` of :func:`~openfdk.mandible.generator.create_subject`),
drawn by ``openfdk view`` as the bodies' ``visual`` meshes (docs/subject-folder.md).

They are procedural, not anatomy: the analysis never reads them.

* Mandible: a bar of elliptic cross-section swept along a U: from below each condyle down
  the ramus to the gonial angle, forward along the body, round the symphysis below the
  incisal point; and each condyle head, the full ellipsoid of the contact condyle
  (:class:`~openfdk.mandible.geometry.CondyleShape`: its top is the condyle-top landmark).
* Skull: a cranial vault above the joints, the face (maxilla) in front of them, the upper
  dental arch as a U-shaped bar above the lower incisal point, and the zygomatic arches.

Every part is a closed triangle mesh with outward (right-hand) winding; a body's mesh is
the parts side by side (overlapping, not merged). All positions m, subject frame (x
anterior, y left, z up) at the reference pose.
"""

from __future__ import annotations

import numpy as np

_MM = 1e-3


def ellipsoid_mesh(center, semi_axes, R=np.eye(3), n_lat=10, n_lon=16):
    """Closed ellipsoid: vertices (n, 3) m, faces (m, 3) outward. center (3,) m,
    semi_axes (3,) m along the columns of R (3, 3)."""
    theta = np.linspace(0.0, np.pi, n_lat + 1)[1:-1]            # polar angle, poles apart
    phi = np.linspace(0.0, 2.0 * np.pi, n_lon, endpoint=False)
    T, P = np.meshgrid(theta, phi, indexing="ij")
    unit = np.stack([np.sin(T) * np.cos(P), np.sin(T) * np.sin(P), np.cos(T)], axis=-1).reshape(-1, 3)
    unit = np.vstack([[0.0, 0.0, 1.0], unit, [0.0, 0.0, -1.0]])
    vertices = np.asarray(center, float) + (unit * np.asarray(semi_axes, float)) @ np.asarray(R, float).T
    faces = []
    ring = lambda i, j: 1 + i * n_lon + (j % n_lon)              # noqa: E731
    bottom = len(unit) - 1
    for j in range(n_lon):
        faces.append((0, ring(0, j), ring(0, j + 1)))
        faces.append((bottom, ring(n_lat - 2, j + 1), ring(n_lat - 2, j)))
        for i in range(n_lat - 2):
            a, b, c, d = ring(i, j), ring(i, j + 1), ring(i + 1, j), ring(i + 1, j + 1)
            faces += [(a, c, d), (a, d, b)]
    return vertices, _outward(vertices, np.array(faces, dtype=np.int64))


def swept_tube(path, semi, normal0, n_sides=14):
    """A closed tube of elliptic cross-section along a polyline.

    path (n, 3) m; semi (n, 2) m: semi-axes along the transported normal and the
    binormal at each point; normal0 (3,): the first cross-section's normal direction.
    The normal is carried along by projection (a rotation-minimising frame for a finely
    sampled path). Ends closed by fans. Returns vertices, faces (outward)."""
    path = np.asarray(path, float)
    n = len(path)
    tangents = np.gradient(path, axis=0)
    tangents /= np.linalg.norm(tangents, axis=1, keepdims=True)
    normal = np.asarray(normal0, float)
    rings = []
    angles = np.linspace(0.0, 2.0 * np.pi, n_sides, endpoint=False)
    for k in range(n):
        t = tangents[k]
        normal = normal - (normal @ t) * t
        normal /= np.linalg.norm(normal)
        binormal = np.cross(t, normal)
        rings.append(path[k] + np.outer(np.cos(angles) * semi[k][0], normal)
                     + np.outer(np.sin(angles) * semi[k][1], binormal))
    vertices = np.vstack(rings + [path[:1], path[-1:]])
    first, last = n * n_sides, n * n_sides + 1
    faces = []
    for k in range(n - 1):
        for j in range(n_sides):
            a, b = k * n_sides + j, k * n_sides + (j + 1) % n_sides
            c, d = a + n_sides, b + n_sides
            faces += [(a, b, d), (a, d, c)]
    for j in range(n_sides):
        faces.append((first, (j + 1) % n_sides, j))
        faces.append((last, (n - 1) * n_sides + j, (n - 1) * n_sides + (j + 1) % n_sides))
    return vertices, _outward(vertices, np.array(faces, dtype=np.int64))


def signed_volume(vertices, faces) -> float:
    """Σ over triangles of det[a, b, c]/6 (m³): the enclosed volume, > 0 for an outward
    winding of a closed mesh."""
    a, b, c = (vertices[faces[:, k]] for k in range(3))
    return float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0)


def _outward(vertices, faces):
    """``faces`` with their winding reversed if the closed part encloses a negative volume."""
    return faces if signed_volume(vertices, faces) > 0.0 else faces[:, ::-1].copy()


def _join(parts):
    vertices, faces, offset = [], [], 0
    for v, f in parts:
        vertices.append(v)
        faces.append(f + offset)
        offset += len(v)
    return np.vstack(vertices), np.vstack(faces)


def _smooth(points, n=48):
    """A Catmull–Rom curve (n·(k−1) + 1 points) through the control points (k, 3)."""
    p = np.asarray(points, float)
    p = np.vstack([2 * p[0] - p[1], p, 2 * p[-1] - p[-2]])
    out = []
    for i in range(1, len(p) - 2):
        for s in np.linspace(0.0, 1.0, n, endpoint=False):
            p0, p1, p2, p3 = p[i - 1], p[i], p[i + 1], p[i + 2]
            out.append(0.5 * ((2 * p1) + (-p0 + p2) * s + (2 * p0 - 5 * p1 + 4 * p2 - p3) * s ** 2
                              + (-p0 + 3 * p1 - 3 * p2 + p3) * s ** 3))
    out.append(p[-2])
    return np.array(out)


def mandible_mesh(condyles, incisal_point):
    """The mandible: condyles {side: CondyleShape} (sides "r", "l"), incisal_point (3,)
    m. Returns vertices (n, 3) m, faces (m, 3)."""
    r, l = condyles["r"], condyles["l"]
    inc = np.asarray(incisal_point, float)
    half = 0.5 * abs(l.top[1] - r.top[1])
    below = 14 * _MM                                # the neck starts below the condyle top

    def side(top, sign):
        return [top + [0.0, 0.0, -below],
                top + [-2 * _MM, -sign * 1 * _MM, -30 * _MM],
                top + [-6 * _MM, -sign * 2 * _MM, -56 * _MM],                # gonial angle
                [top[0] + 10 * _MM, sign * (half - 6 * _MM), top[2] - 66 * _MM],
                [0.55 * inc[0], sign * 0.62 * half, inc[2] - 16 * _MM]]    # below the molars

    right, left = side(r.top, -1.0), side(l.top, 1.0)
    chin = [inc[0] - 4 * _MM, 0.0, inc[2] - 18 * _MM]
    control = right + [chin] + left[::-1]
    path = _smooth(control, n=12)
    s = np.linspace(0.0, 1.0, len(path))
    # semi-axes: thickness (transported normal: lateral) and height; the ramus is wider
    # antero-posteriorly near the condyle neck than the body is high
    neck = np.clip(1.0 - s / 0.08, 0.0, 1.0) + np.clip(1.0 - (1.0 - s) / 0.08, 0.0, 1.0)
    semi = np.column_stack([np.full_like(s, 4.5 * _MM), 11 * _MM - 5 * _MM * neck])
    parts = [swept_tube(path, semi, normal0=[0.0, 1.0, 0.0])]
    for c in (r, l):
        parts.append(ellipsoid_mesh(c.center, c.semi_axes, c.axes))
    return _join(parts)


def skull_mesh(condyles, incisal_point):
    """The skull: cranial vault, face, upper dental arch and zygomatic arches above and
    in front of the joints. Returns vertices (n, 3) m, faces (m, 3)."""
    r, l = condyles["r"], condyles["l"]
    inc = np.asarray(incisal_point, float)
    half = 0.5 * abs(l.top[1] - r.top[1])
    top_z = max(r.top[2], l.top[2])
    parts = [
        ellipsoid_mesh([0.3 * inc[0], 0.0, top_z + 60 * _MM], [95 * _MM, 0.75 * half + 10 * _MM, 62 * _MM]),
        ellipsoid_mesh([0.72 * inc[0], 0.0, top_z - 10 * _MM], [30 * _MM, 0.85 * half, 40 * _MM]),
    ]
    arch = [[0.15 * inc[0], -0.75 * half, inc[2] + 8 * _MM], [0.6 * inc[0], -0.5 * half, inc[2] + 6 * _MM],
            [inc[0] - 2 * _MM, 0.0, inc[2] + 8 * _MM],
            [0.6 * inc[0], 0.5 * half, inc[2] + 6 * _MM], [0.15 * inc[0], 0.75 * half, inc[2] + 8 * _MM]]
    path = _smooth(arch, n=10)
    parts.append(swept_tube(path, np.tile([5 * _MM, 7 * _MM], (len(path), 1)), normal0=[0.0, 1.0, 0.0]))
    for c, sign in ((r, -1.0), (l, 1.0)):
        zyg = _smooth([c.top + [8 * _MM, sign * 6 * _MM, 4 * _MM], c.top + [35 * _MM, sign * 8 * _MM, 2 * _MM],
                       [0.72 * inc[0], sign * 0.8 * half, top_z - 8 * _MM]], n=10)
        parts.append(swept_tube(zyg, np.tile([3 * _MM, 5 * _MM], (len(zyg), 1)), normal0=[0.0, 0.0, 1.0]))
    return _join(parts)
