"""Polygons and triangle strips to triangles, for the display-mesh readers
(:mod:`.vtp`, :mod:`.obj`).

A list of polygons is stored flat, as in VTK: ``connectivity`` (k,) holds the corner
vertex indices of all polygons one after the other and ``ends`` (p,) the position in
``connectivity`` just past each polygon's last corner (VTK's XML ``offsets``), so polygon
i has the corners ``connectivity[ends[i-1]:ends[i]]`` (from 0 for the first one).

Errors are ``ValueError`` with a one-line message that does not name the file (the
readers add it).
"""

from __future__ import annotations

import numpy as np

__all__ = ["fan_triangles", "strip_triangles"]


def _bounds(connectivity, ends, what, minimum):
    """(begins (p,), counts (p,)) int64 of the cells, checked."""
    connectivity = np.asarray(connectivity, dtype=np.int64).ravel()
    ends = np.asarray(ends, dtype=np.int64).ravel()
    if not len(ends):
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    begins = np.concatenate([[0], ends[:-1]])
    counts = ends - begins
    if np.any(counts <= 0):
        i = int(np.argmax(counts <= 0))
        raise ValueError(f"{what} offsets are not increasing (offset {i} is {ends[i]}, "
                         f"after {begins[i]})")
    if ends[-1] != len(connectivity):
        raise ValueError(f"{what} offsets end at {ends[-1]} but the connectivity holds {len(connectivity)} indices")
    if np.any(counts < minimum):
        i = int(np.argmax(counts < minimum))
        raise ValueError(f"{what} cell {i} has {counts[i]} corner(s); at least {minimum} are needed")
    return begins, counts


def fan_triangles(connectivity, ends, what="polygon") -> np.ndarray:
    """Triangles (m, 3) int64 of polygons, each fan-triangulated from its first corner:
    corners (c0, c1, …, c_{k-1}) give (c0, c_j, c_{j+1}) for j = 1 … k-2, in order, so the
    winding is kept. ``connectivity`` (k,) int and ``ends`` (p,) int as in the module
    docstring; every polygon needs at least 3 corners. Vertex indices are not checked
    against a vertex count (the caller does). ``what`` names the cells in messages."""
    connectivity = np.asarray(connectivity, dtype=np.int64).ravel()
    begins, counts = _bounds(connectivity, ends, what, 3)
    n_tri = counts - 2
    cell = np.repeat(np.arange(len(counts)), n_tri)
    j = np.arange(int(n_tri.sum())) - np.repeat(np.cumsum(n_tri) - n_tri, n_tri) + 1
    first = begins[cell]
    return np.stack([connectivity[first], connectivity[first + j], connectivity[first + j + 1]], axis=1)


def strip_triangles(connectivity, ends, what="strip") -> np.ndarray:
    """Triangles (m, 3) int64 of triangle strips: strip (p0, p1, …, p_{k-1}) gives
    (p_i, p_{i+1}, p_{i+2}) for even i and (p_{i+1}, p_i, p_{i+2}) for odd i (VTK's rule,
    which keeps one winding along the strip)."""
    connectivity = np.asarray(connectivity, dtype=np.int64).ravel()
    begins, counts = _bounds(connectivity, ends, what, 3)
    n_tri = counts - 2
    cell = np.repeat(np.arange(len(counts)), n_tri)
    i = np.arange(int(n_tri.sum())) - np.repeat(np.cumsum(n_tri) - n_tri, n_tri)
    at = begins[cell] + i
    odd = (i % 2).astype(bool)
    a, b = connectivity[at], connectivity[at + 1]
    return np.stack([np.where(odd, b, a), np.where(odd, a, b), connectivity[at + 2]], axis=1)


def parse_mesh_file(path, parse, errors=()):
    """``parse(bytes)`` of the file ``path``, every failure as one line
    ``ValueError("<path>: <what is wrong>")``: the file cannot be read, or ``parse``
    raised ValueError, OverflowError, MemoryError or one of ``errors``; a file above
    :data:`openfdk.io.limits.MESH_FILE_BYTES` is refused before it is read."""
    from pathlib import Path

    from . import limits

    path = Path(path)
    limits.check_file_bytes(path, "MESH_FILE_BYTES", str(path))
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise ValueError(f"{path}: cannot read the file ({exc.strerror or exc})") from None
    from .placeholders import placeholder

    if (why := placeholder(data)) is not None:
        raise ValueError(f"{path}: {why}")
    try:
        return parse(data)
    except (ValueError, OverflowError, MemoryError, *errors) as exc:
        raise ValueError(f"{path}: {' '.join(str(exc).split())}") from None
