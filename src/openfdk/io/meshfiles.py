"""Display-mesh files: one reader for every format a ``visual:`` entry may name.

:func:`read_display_mesh` dispatches on the file suffix (case-insensitive):

* ``.stl`` — binary or ASCII STL (:func:`openfdk.contact.stl.read_stl`; equal corners
  merged into one vertex);
* ``.vtp`` — VTK XML PolyData, OpenSim's bone geometry (:func:`openfdk.io.vtp.read_vtp`);
* ``.obj`` — Wavefront OBJ (:func:`openfdk.io.obj.read_obj`), also what
  ``openfdk export-opensim`` writes;
* ``.ply`` — read by trimesh (kept for model files written before the other readers).

The readers are imported only when a file of their kind is read. Whatever the format,
the result is checked: finite coordinates, vertex indices in range, at least one
triangle and at most :data:`openfdk.io.limits.MESH_TRIANGLES` (a binary STL's count is
checked from its header, the other formats' file size against
:data:`openfdk.io.limits.MESH_FILE_BYTES`, before reading). Display only: contact meshes are loaded by :mod:`openfdk.contact.mesh`.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from . import limits

__all__ = ["DISPLAY_MESH_SUFFIXES", "read_display_mesh"]

#: file suffixes read by :func:`read_display_mesh`
DISPLAY_MESH_SUFFIXES = (".stl", ".vtp", ".obj", ".ply")


def read_display_mesh(path) -> tuple[np.ndarray, np.ndarray]:
    """Vertices ``(n, 3)`` float64 in the file's length unit and triangles ``(m, 3)``
    int64 (0-based vertex indices, m ≥ 1) of the mesh file ``path``, by its suffix.
    Raises ``ValueError("<path>: <what is wrong>")`` (one line) for an unknown suffix, a
    file that cannot be read, or a malformed or empty mesh."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix == ".vtp":
        from .vtp import read_vtp

        vertices, triangles = read_vtp(path)
    elif suffix == ".obj":
        from .obj import read_obj

        vertices, triangles = read_obj(path)
    elif suffix == ".stl":
        vertices, triangles = _read_stl(path)
    elif suffix == ".ply":
        vertices, triangles = _read_ply(path)
    else:
        raise ValueError(f"{path}: unknown display-mesh format {path.suffix!r}; expected one of "
                         f"{', '.join(DISPLAY_MESH_SUFFIXES)}")
    vertices = np.asarray(vertices, dtype=np.float64).reshape(-1, 3)
    triangles = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
    limits.check_count(len(triangles), "MESH_TRIANGLES", str(path), "", "triangles")
    if not len(triangles):
        raise ValueError(f"{path}: contains no triangles")
    if not np.all(np.isfinite(vertices)):
        i = int(np.argmax(~np.isfinite(vertices).all(axis=1)))
        raise ValueError(f"{path}: vertex {i} has a non-finite coordinate {vertices[i].tolist()}")
    if triangles.min() < 0 or triangles.max() >= len(vertices):
        raise ValueError(f"{path}: a triangle refers to a vertex beyond the {len(vertices)} of the file")
    return vertices, triangles


def _read_stl(path):
    from ..contact.stl import read_stl

    try:
        return read_stl(path)
    except OSError as exc:
        raise ValueError(f"{path}: cannot read the file ({exc.strerror or exc})") from None
    except ValueError as exc:   # StlError
        raise ValueError(f"{path}: {' '.join(str(exc).split())}") from None


def _read_ply(path):
    limits.check_file_bytes(path, "MESH_FILE_BYTES", str(path))
    try:
        import trimesh

        mesh = trimesh.load(path, force="mesh", process=False)
        return np.asarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.faces, dtype=np.int64)
    except Exception as exc:  # trimesh raises many exception types
        raise ValueError(f"{path}: could not read the PLY file ({' '.join(str(exc).split())})") from None
