"""Triangle surface meshes for contact: loading, validation, vertex areas and normals.

A :class:`SurfaceMesh` is a triangle mesh fixed in a body frame B (origin at the body's
centre of mass, docs/design.md §1), in metres. Meshes may be *open* — only the joint region of
a bone is usually meshed — and that is normal. What matters is the orientation: the
triangle normals (right-hand rule on the vertex order of each face) must point **out of
the bone, toward the joint space**. For a closed mesh this is the outward orientation and
it is checked; for an open mesh it cannot be inferred and is the caller's responsibility
(use ``flip_normals=True`` if a file is wound the other way).

Derived per-vertex quantities (computed once, on construction):

* ``vertex_areas`` — the tributary area of each vertex, one third of the area of every
  incident triangle: ``a_i = Σ_{f ∋ i} A_f / 3``, so ``Σ a_i`` is the mesh area.
* ``vertex_normals_B`` — the angle-weighted mean of the incident triangle normals
  (Thürmer & Wüthrich 1998; the "pseudo-normal" of Bærentzen & Aanæs 2005), normalised.
"""

from __future__ import annotations

import os
import warnings
from dataclasses import dataclass

import numpy as np

from .stl import read_stl
from .unique_rows import first_appearance_rows

__all__ = [
    "MeshError",
    "MeshWarning",
    "SurfaceMesh",
    "surface_mesh",
    "load_mesh",
    "check_scale",
    "offset",
    "LENGTH_UNITS",
]

#: metres per unit of each accepted file length unit
LENGTH_UNITS = {"m": 1.0, "dm": 0.1, "cm": 1e-2, "mm": 1e-3, "um": 1e-6, "in": 0.0254}

# A triangle is degenerate when its area is below this fraction of (bbox diagonal)².
_DEGENERATE_RELATIVE_AREA = 1e-12


class MeshError(ValueError):
    """A mesh file or mesh array is unusable; the message names the mesh."""


class MeshWarning(UserWarning):
    """A mesh was repaired or looks suspicious (winding, degenerate triangles, scale)."""


@dataclass(frozen=True, eq=False)
class SurfaceMesh:
    """Triangle mesh fixed in a body frame B (read-only arrays).

    Attributes
    ----------
    vertices_B : (n, 3) m — vertex positions in the body frame B.
    faces : (m, 3) int — vertex indices of each triangle, counter-clockwise seen from
        the side the normal points to (the joint space).
    vertex_normals_B : (n, 3) — unit angle-weighted vertex normals in B.
    vertex_areas : (n,) m² — tributary areas, one third of each incident triangle.
    name : str — file name or a descriptive label, used in messages.
    """

    vertices_B: np.ndarray
    faces: np.ndarray
    vertex_normals_B: np.ndarray
    vertex_areas: np.ndarray
    name: str

    @property
    def n_vertices(self) -> int:
        return int(self.vertices_B.shape[0])

    @property
    def n_faces(self) -> int:
        return int(self.faces.shape[0])

    @property
    def area(self) -> float:
        """Total surface area, m²."""
        return float(self.vertex_areas.sum())

    @property
    def face_normals_B(self) -> np.ndarray:
        """(m, 3) unit triangle normals in B."""
        return _face_normals_and_areas(self.vertices_B, self.faces)[0]

    @property
    def extent(self) -> float:
        """Largest side of the axis-aligned bounding box, m."""
        return float(np.ptp(self.vertices_B, axis=0).max())

    def __repr__(self) -> str:
        return (
            f"SurfaceMesh(name={self.name!r}, n_vertices={self.n_vertices}, "
            f"n_faces={self.n_faces}, area={self.area:.4g} m², extent={self.extent:.4g} m)"
        )


def _face_normals_and_areas(vertices, faces):
    """Unit normals (m, 3) and areas (m,) of triangles; zero normal for zero area."""
    v0, v1, v2 = vertices[faces[:, 0]], vertices[faces[:, 1]], vertices[faces[:, 2]]
    cross = np.cross(v1 - v0, v2 - v0)
    twice_area = np.linalg.norm(cross, axis=1)
    normals = np.zeros_like(cross)
    nz = twice_area > 0.0
    normals[nz] = cross[nz] / twice_area[nz, None]
    return normals, 0.5 * twice_area


def _vertex_areas(n_vertices, faces, face_areas):
    """Tributary areas (n,) m²: a_i = Σ_{f ∋ i} A_f / 3."""
    areas = np.zeros(n_vertices)
    for k in range(3):
        np.add.at(areas, faces[:, k], face_areas / 3.0)
    return areas


def _angle_weighted_normals(vertices, faces, face_normals):
    """Unit vertex normals (n, 3): Σ_f θ_{f,i} n_f normalised (θ = corner angle)."""
    normals = np.zeros_like(vertices)
    for k in range(3):
        i, j, l = faces[:, k], faces[:, (k + 1) % 3], faces[:, (k + 2) % 3]
        e1 = vertices[j] - vertices[i]
        e2 = vertices[l] - vertices[i]
        cos_t = np.einsum("ij,ij->i", e1, e2) / (
            np.linalg.norm(e1, axis=1) * np.linalg.norm(e2, axis=1)
        )
        theta = np.arccos(np.clip(cos_t, -1.0, 1.0))
        np.add.at(normals, i, theta[:, None] * face_normals)
    length = np.linalg.norm(normals, axis=1)
    good = length > 0.0
    normals[good] /= length[good, None]
    return normals


def _readonly(a):
    a = np.ascontiguousarray(a)
    a.setflags(write=False)
    return a


def _orient_consistently(faces, face_areas):
    """Flip triangles so that adjacent triangles wind consistently.

    Breadth-first traversal of the face-adjacency graph of each connected component;
    afterwards, in each component, the orientation held by the larger area of the
    *original* triangles is kept. Returns (faces, number of triangles flipped).
    """
    m = faces.shape[0]
    # directed half-edges (a -> b) of each face
    a = faces[:, [0, 1, 2]].ravel()
    b = faces[:, [1, 2, 0]].ravel()
    face_of = np.repeat(np.arange(m), 3)
    key_lo, key_hi = np.minimum(a, b), np.maximum(a, b)
    order = np.lexsort((key_hi, key_lo))
    lo, hi = key_lo[order], key_hi[order]
    same_edge = (lo[1:] == lo[:-1]) & (hi[1:] == hi[:-1])
    i0 = order[:-1][same_edge]
    i1 = order[1:][same_edge]
    f0, f1 = face_of[i0], face_of[i1]
    # consistent neighbours traverse the shared edge in opposite directions
    consistent = a[i0] != a[i1]
    keep = f0 != f1
    f0, f1, consistent = f0[keep], f1[keep], consistent[keep]
    if consistent.all():
        return faces, 0
    import scipy.sparse as sp  # here: only meshes to repair need it (≈ 0.15 s of imports)
    from scipy.sparse.csgraph import breadth_first_order, connected_components

    # weight 1 = keep relative orientation, 2 = flip
    w = np.where(consistent, 1, 2)
    graph = sp.coo_matrix((np.r_[w, w], (np.r_[f0, f1], np.r_[f1, f0])), shape=(m, m)).tocsr()
    n_comp, labels = connected_components(graph, directed=False)
    flip = np.zeros(m, dtype=bool)
    for c in range(n_comp):
        seed = int(np.flatnonzero(labels == c)[0])
        bfs, pred = breadth_first_order(graph, seed, directed=False, return_predecessors=True)
        # relation of each face to its BFS parent (2 = opposite orientation)
        relation = np.asarray(graph[bfs[1:], pred[bfs[1:]]]).ravel() == 2
        for f, p, r in zip(bfs[1:].tolist(), pred[bfs[1:]].tolist(), relation.tolist()):
            flip[f] = flip[p] ^ r
        members = bfs
        # keep the orientation of the majority (by area) of the original triangles
        if face_areas[members][flip[members]].sum() > face_areas[members][~flip[members]].sum():
            flip[members] = ~flip[members]
    faces = faces.copy()
    faces[flip] = faces[flip][:, ::-1]
    return faces, int(flip.sum())


def surface_mesh(vertices_B, faces, name="mesh", *, repair=True) -> SurfaceMesh:
    """Build a validated :class:`SurfaceMesh` from arrays.

    Parameters
    ----------
    vertices_B : (n, 3) m — vertex positions in the body frame.
    faces : (m, 3) int — triangle vertex indices.
    name : str — label used in messages.
    repair : bool — remove degenerate (zero-area) triangles and unreferenced vertices
        and make the winding consistent, each with a :class:`MeshWarning`. If False,
        the arrays are used as given (only shapes are checked).

    Raises
    ------
    MeshError — wrong shapes, no triangles, non-finite vertices, indices out of range,
        or all triangles degenerate.
    """
    vertices = np.asarray(vertices_B, dtype=float)
    faces = np.asarray(faces)
    if vertices.ndim != 2 or vertices.shape[1] != 3:
        raise MeshError(f"mesh '{name}': vertices must be (n, 3), got {vertices.shape}")
    if faces.size == 0:
        raise MeshError(f"mesh '{name}' contains no triangles (empty or unreadable file)")
    if faces.ndim != 2 or faces.shape[1] != 3:
        raise MeshError(f"mesh '{name}': faces must be (m, 3) triangles, got {faces.shape}")
    faces = faces.astype(np.int64)
    if not np.all(np.isfinite(vertices)):
        raise MeshError(f"mesh '{name}' has non-finite vertex coordinates")
    if faces.min() < 0 or faces.max() >= vertices.shape[0]:
        raise MeshError(
            f"mesh '{name}': face indices must lie in [0, {vertices.shape[0] - 1}], "
            f"got [{faces.min()}, {faces.max()}]"
        )
    normals, areas = _face_normals_and_areas(vertices, faces)
    if repair:
        diag = float(np.linalg.norm(np.ptp(vertices[faces.ravel()], axis=0)))
        degenerate = areas <= _DEGENERATE_RELATIVE_AREA * diag * diag
        n_bad = int(degenerate.sum())
        if n_bad == faces.shape[0]:
            raise MeshError(f"mesh '{name}': all {n_bad} triangles are degenerate (zero area)")
        if n_bad:
            warnings.warn(
                f"mesh '{name}': removed {n_bad} degenerate (zero-area) triangle(s)",
                MeshWarning,
                stacklevel=2,
            )
            faces, normals, areas = faces[~degenerate], normals[~degenerate], areas[~degenerate]
        faces, normals, areas = _drop_duplicate_faces(faces, normals, areas, name)
        _warn_non_manifold(faces, name)
        used = np.zeros(vertices.shape[0], dtype=bool)
        used[faces.ravel()] = True
        if not used.all():
            new_index = np.cumsum(used) - 1
            vertices = vertices[used]
            faces = new_index[faces]
        faces, n_flipped = _orient_consistently(faces, areas)
        if n_flipped:
            warnings.warn(
                f"mesh '{name}': {n_flipped} triangle(s) had winding inconsistent with "
                "their neighbours and were flipped to agree with the majority orientation",
                MeshWarning,
                stacklevel=2,
            )
            normals, areas = _face_normals_and_areas(vertices, faces)
    vertex_areas = _vertex_areas(vertices.shape[0], faces, areas)
    vertex_normals = _angle_weighted_normals(vertices, faces, normals)
    return SurfaceMesh(
        vertices_B=_readonly(vertices),
        faces=_readonly(faces),
        vertex_normals_B=_readonly(vertex_normals),
        vertex_areas=_readonly(vertex_areas),
        name=str(name),
    )


def _drop_duplicate_faces(faces, normals, areas, name):
    """Remove triangles on the same three vertices as an earlier one (any order), with a
    MeshWarning giving the count; (faces, normals, areas) of the rest."""
    first, _ = first_appearance_rows(np.sort(faces, axis=1))
    n_dup = faces.shape[0] - first.size
    if n_dup == 0:
        return faces, normals, areas
    warnings.warn(f"mesh '{name}': {n_dup} duplicate triangle(s) (the same three vertices as another) removed",
                  MeshWarning, stacklevel=3)
    return faces[first], normals[first], areas[first]


def _warn_non_manifold(faces, name):
    """MeshWarning with the number of edges shared by more than two triangles."""
    keys = undirected_edge_keys(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]))
    _, counts = np.unique(keys, return_counts=True)
    n_bad = int(np.sum(counts > 2))
    if n_bad:
        warnings.warn(f"mesh '{name}': {n_bad} non-manifold edge(s) shared by more than two triangles "
                      "(a fin or a self-touching surface); contact near them is unreliable",
                      MeshWarning, stacklevel=3)


def _placement_transform(placement, name):
    """(R (3,3), t (3,) m) from None, a 4x4 matrix, or (translation (3,), rotation (3,3))."""
    if placement is None:
        return np.eye(3), np.zeros(3)
    if isinstance(placement, (tuple, list)) and len(placement) == 2:
        t = np.asarray(placement[0], dtype=float)
        R = np.asarray(placement[1], dtype=float)
    else:
        T = np.asarray(placement, dtype=float)
        if T.shape != (4, 4):
            raise MeshError(
                f"mesh '{name}': placement must be a 4x4 matrix or (translation (3,), "
                f"rotation (3, 3)), got an array of shape {T.shape}"
            )
        R, t = T[:3, :3], T[:3, 3]
    if t.shape != (3,) or R.shape != (3, 3):
        raise MeshError(
            f"mesh '{name}': placement translation must be (3,) and rotation (3, 3), "
            f"got {t.shape} and {R.shape}"
        )
    if not np.allclose(R.T @ R, np.eye(3), atol=1e-6) or np.linalg.det(R) < 0.0:
        raise MeshError(f"mesh '{name}': placement rotation is not a proper rotation matrix")
    return R, t


def load_mesh(path, units="m", placement=None, *, flip_normals=False, name=None) -> SurfaceMesh:
    """Load an STL (ASCII or binary), OBJ or PLY triangle mesh into a body frame.

    Parameters
    ----------
    path : str or Path — mesh file.
    units : str — length unit of the file coordinates, one of :data:`LENGTH_UNITS`
        ("m", "mm", "cm", ...); vertices are converted to m.
    placement : None, (4, 4) homogeneous matrix, or (translation (3,) m, rotation (3, 3))
        — maps file coordinates (after unit conversion) into the body frame B, whose
        origin is the body's centre of mass: ``v_B = R v_file + t``.
    flip_normals : bool — reverse every triangle (for files wound inward).
    name : str — label for messages; defaults to the file name.

    Returns the validated :class:`SurfaceMesh`; repairs (degenerate triangles removed,
    inconsistent winding fixed, closed mesh turned outward) emit :class:`MeshWarning`.

    Raises :class:`MeshError` naming the file when it does not exist, cannot be read, or
    has no usable triangles.
    """
    path = os.fspath(path)
    label = name or os.path.basename(path)
    if not isinstance(units, str) or units not in LENGTH_UNITS:
        raise MeshError(
            f"mesh '{label}': unknown length unit {units!r}; expected one of "
            f"{sorted(LENGTH_UNITS)}"
        )
    if not os.path.isfile(path):
        raise MeshError(f"mesh file '{path}' does not exist")
    vertices, faces = _read_triangles(path)
    if faces.size == 0:
        raise MeshError(f"mesh file '{path}' contains no triangles (empty or unreadable)")
    R, t = _placement_transform(placement, label)
    vertices = vertices * LENGTH_UNITS[units] @ R.T + t
    if flip_normals:
        faces = faces[:, ::-1]
    mesh = surface_mesh(vertices, faces, name=label)
    # A closed bone surface must have outward normals: positive enclosed volume.
    if _is_closed(mesh.faces):
        volume = _signed_volume(mesh.vertices_B, mesh.faces)
        if volume < 0.0:
            warnings.warn(
                f"mesh '{label}' is closed but its normals point inward; all triangles "
                "were flipped so that the normals point out of the bone",
                MeshWarning,
                stacklevel=2,
            )
            mesh = surface_mesh(mesh.vertices_B, mesh.faces[:, ::-1], name=label, repair=False)
    return mesh


def _read_triangles(path):
    """(vertices (n, 3) file units, faces (m, 3) int) of a mesh file: STL by
    :mod:`.stl`, other formats by trimesh (imported only for them: ≈ 0.25 s), with
    duplicate vertices merged. Raises MeshError naming the file, also for a mesh above
    the size limits (:mod:`openfdk.io.limits`: a binary STL's header count and the other
    files' size are checked before reading)."""
    from ..io import limits

    try:
        if path.lower().endswith(".stl"):
            return read_stl(path)
        limits.check_file_bytes(path, "MESH_FILE_BYTES", f"mesh file '{path}'", MeshError)
        import trimesh

        loaded = trimesh.load(path, force="mesh", process=True)
    except MeshError:
        raise
    except Exception as exc:  # trimesh raises many exception types; StlError, OSError
        raise MeshError(f"could not read mesh file '{path}': {exc}") from exc
    faces = np.asarray(getattr(loaded, "faces", np.zeros((0, 3))))
    limits.check_count(len(faces), "MESH_TRIANGLES", f"mesh file '{path}'", "", "triangles", MeshError)
    return np.asarray(getattr(loaded, "vertices", np.zeros((0, 3))), dtype=float), faces


def undirected_edge_keys(ends) -> np.ndarray:
    """One int64 per undirected edge: lo·(n+1) + hi for vertex pairs ``ends`` (k, 2) int,
    n the largest index. Sorting the keys orders the edges like sorting the (lo, hi)
    rows, and a 1-D np.unique of them is several times faster than np.unique(axis=0)."""
    ends = np.asarray(ends, dtype=np.int64)
    lo, hi = ends.min(axis=1), ends.max(axis=1)
    return lo * (int(ends.max(initial=0)) + 1) + hi


def _is_closed(faces) -> bool:
    """True when every edge is shared by exactly two triangles."""
    keys = undirected_edge_keys(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]))
    _, counts = np.unique(keys, return_counts=True)
    return bool(np.all(counts == 2))


def _signed_volume(vertices, faces) -> float:
    """Enclosed volume m³ by the divergence theorem, Σ v0·(v1 × v2)/6."""
    v0, v1, v2 = vertices[faces[:, 0]], vertices[faces[:, 1]], vertices[faces[:, 2]]
    return float(np.einsum("ij,ij->i", v0, np.cross(v1, v2)).sum() / 6.0)


def check_scale(mesh: SurfaceMesh, model_length_scale: float, *, factor: float = 30.0) -> bool:
    """Warn when a mesh is about 1000× too large or too small for the model.

    Parameters
    ----------
    mesh : SurfaceMesh
    model_length_scale : float, m — the expected size of the meshed region (e.g. 0.02 for a
        TMJ condyle, or a typical distance between the model's points).
    factor : float — warn when the mesh extent differs from the scale by more than this
        ratio (default 30, well below the factor 1000 of an mm/m mix-up).

    Returns True when the scale is plausible; otherwise emits a :class:`MeshWarning`
    ("mesh 'fossa_r.stl' spans 25.0 m; is it in mm?") and returns False.
    """
    if not model_length_scale > 0.0:
        raise ValueError(f"model_length_scale must be > 0 m, got {model_length_scale!r}")
    extent = mesh.extent
    ratio = extent / model_length_scale
    if ratio > factor:
        warnings.warn(
            f"mesh '{mesh.name}' spans {extent:.1f} m; is it in mm? (the model's length "
            f"scale is {model_length_scale:g} m; pass units='mm' when loading)",
            MeshWarning,
            stacklevel=2,
        )
        return False
    if ratio < 1.0 / factor:
        warnings.warn(
            f"mesh '{mesh.name}' spans {extent * 1e3:.3g} mm; are its coordinates in m but "
            f"declared as mm? (the model's length scale is {model_length_scale:g} m)",
            MeshWarning,
            stacklevel=2,
        )
        return False
    return True


def offset(mesh: SurfaceMesh, distance: float) -> SurfaceMesh:
    """Move every vertex along its vertex normal: ``v_i ← v_i + distance · n_i``.

    Parameters: distance, m (positive = toward the joint space, e.g. 1e-3 for the paper's
    1 mm cartilage offset of the condyles). Returns a new SurfaceMesh (areas and normals
    recomputed) named ``"<name>+offset"``.
    """
    vertices = mesh.vertices_B + float(distance) * mesh.vertex_normals_B
    return surface_mesh(vertices, mesh.faces, name=f"{mesh.name}+{distance * 1e3:g}mm", repair=False)
