"""STL triangle meshes (binary and ASCII) read without trimesh.

STL is the format bone and implant surfaces come in, and importing trimesh costs
≈ 0.25 s (it brings scipy.spatial, scipy.sparse and scipy.optimize) in every process
that loads a mesh — each ``openfdk`` command and each study worker. :func:`read_stl`
gives what ``trimesh.load(path, process=True)`` gives for an STL file (the same vertices
in the same order, the same faces: tests/test_contact_mesh.py compares them); other
formats still go through trimesh (:func:`openfdk.contact.mesh.load_mesh`).

Format (the 3D Systems specification, "StereoLithography Interface Specification", 1989):

* binary: an 80-byte header, a little-endian uint32 triangle count n, then n records of
  50 bytes: normal (3 float32), three vertices (3 × 3 float32), a uint16 attribute. A
  file is binary when its size is exactly 84 + 50 n (an ASCII file's size is not, in
  practice; binary headers may begin with "solid" too);
* ASCII: ``solid name``, then per triangle ``facet normal nx ny nz / outer loop /
  vertex x y z`` (three times) ``/ endloop / endfacet``, then ``endsolid``.

The stored normals are ignored (the winding defines the orientation). An STL stores each
triangle's corners separately; corners with exactly the same coordinates are merged into
one vertex, numbered in the order of their first appearance.
"""

from __future__ import annotations

import os

import struct

import numpy as np

from .unique_rows import first_appearance_rows

__all__ = ["StlError", "check_stl_size", "read_stl", "write_stl"]

_RECORD = np.dtype([("normal", "<f4", (3,)), ("corners", "<f4", (3, 3)), ("attribute", "<u2")])


class StlError(ValueError):
    """An STL file that cannot be read; the message says why (the caller names the file)."""


def read_stl(path) -> tuple[np.ndarray, np.ndarray]:
    """Vertices ``(n_vertices, 3)`` float64 (the file's length unit) and faces
    ``(n_faces, 3)`` int64 (vertex indices, the file's winding) of the STL file ``path``.
    Raises OSError when the file cannot be opened and :class:`StlError` when it is not an
    STL file or is above a size limit (checked before the triangles are read: a binary
    file's triangle count from its header against :data:`openfdk.io.limits.MESH_TRIANGLES`,
    an ASCII file's size against :data:`openfdk.io.limits.MESH_FILE_BYTES`); an STL file
    without triangles gives empty arrays."""
    with open(path, "rb") as f:
        n = _checked_size(f)
        if n >= 0:
            corners = np.frombuffer(f.read(), dtype=_RECORD, count=n)["corners"]
            return _merge_corners(corners.reshape(-1, 3).astype(np.float64))
        data = f.read()
    return _merge_corners(_ascii_corners(data))


def write_stl(path, vertices, faces, header=b"openfdk"):
    """Write the mesh as a binary STL file: 80-byte ``header``, uint32 count, one 50-byte
    record per face (unit normal of the winding, three corners, zero attribute).
    vertices (n, 3) in the file's length unit, faces (m, 3) vertex indices; returns the
    Path. :func:`read_stl` reads it back (corners as float32)."""
    from pathlib import Path

    corners = np.asarray(vertices, dtype=float)[np.asarray(faces, dtype=np.int64)]
    normals = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    normals /= np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-300)
    records = np.zeros(len(corners), dtype=_RECORD)
    records["normal"], records["corners"] = normals, corners
    with open(path, "wb") as f:
        f.write(bytes(header).ljust(80, b" ")[:80] + struct.pack("<I", len(corners)))
        f.write(records.tobytes())
    return Path(path)


def check_stl_size(path):
    """Raise :class:`StlError` when the STL file ``path`` is above the size limits (as
    :func:`read_stl` checks them), reading only its header; OSError when it cannot be
    opened. For readers of STL files other than :func:`read_stl` (trimesh)."""
    with open(path, "rb") as f:
        _checked_size(f)


def _checked_size(f) -> int:
    """The triangle count of a binary STL (from its header), or -1 for an ASCII one, of
    the open file ``f`` (left positioned after the header, or at the start for ASCII),
    after checking it against :data:`openfdk.io.limits.MESH_TRIANGLES` (binary) or the
    file size against :data:`openfdk.io.limits.MESH_FILE_BYTES` (ASCII)."""
    from ..io import limits

    size = os.fstat(f.fileno()).st_size
    head = f.read(84)
    n = int(np.frombuffer(head, dtype="<u4", count=1, offset=80)[0]) if len(head) == 84 else -1
    if n >= 0 and size == 84 + 50 * n:
        limits.check_count(n, "MESH_TRIANGLES", "", "", "triangles (binary STL header)", StlError)
        return n
    limits.check_count(size, "MESH_FILE_BYTES", "", "", "bytes of ASCII STL text", StlError)
    f.seek(0)
    return -1


def _ascii_corners(data: bytes) -> np.ndarray:
    """Corner coordinates ``(3 n_faces, 3)`` of an ASCII STL file's bytes."""
    from ..io.placeholders import placeholder

    if (why := placeholder(data)) is not None:
        raise StlError(why)
    try:
        tokens = data.decode("ascii").split()
    except UnicodeDecodeError:
        raise StlError("neither a binary STL (size is not 84 + 50 × triangle count) nor ASCII text") from None
    if not tokens or tokens[0].lower() != "solid":
        raise StlError("neither a binary STL (size is not 84 + 50 × triangle count) nor an ASCII STL "
                       "(does not begin with 'solid')")
    lowered = [t.lower() for t in tokens]
    at = [i for i, t in enumerate(lowered) if t == "vertex"]
    n_facets = lowered.count("facet")
    if len(at) != 3 * n_facets:
        raise StlError(f"ASCII STL with {n_facets} facets but {len(at)} vertices (STL facets are triangles)")
    try:
        corners = np.array([[float(tokens[i + 1]), float(tokens[i + 2]), float(tokens[i + 3])] for i in at],
                           dtype=np.float64).reshape(-1, 3)
    except (ValueError, IndexError):
        raise StlError("ASCII STL with a 'vertex' line that does not hold three numbers") from None
    return corners


def _merge_corners(corners: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(vertices, faces) from corners ``(3 n_faces, 3)``: equal corners become one
    vertex, vertices in order of first appearance."""
    first, inverse = first_appearance_rows(corners)
    return corners[first], inverse.reshape(-1, 3)
