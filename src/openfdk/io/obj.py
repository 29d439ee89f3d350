"""Wavefront OBJ triangle meshes (text): the ``v`` and ``f`` statements.

* ``v x y z [w]`` (optionally followed by colour components): a vertex, numbered from 1
  in the order of the file; only x, y, z are used;
* ``f c1 c2 c3 …``: a polygon of 3 or more corners, each ``i``, ``i/t``, ``i//n`` or
  ``i/t/n`` (vertex, texture and normal indices; only the vertex index i is used). A
  negative i counts back from the latest vertex (-1 is the vertex defined last before
  this line). Polygons are fan-triangulated from their first corner (:mod:`.polygons`).

Comments (``#`` to the end of the line), lines continued by a trailing backslash, and all
other statements (``vt``, ``vn``, ``g``, ``o``, ``s``, ``l``, ``usemtl``, ``mtllib`` …)
are accepted and ignored. Every problem raises one ``ValueError`` line
``<file>: line <k>: <what is wrong>``.
"""

from __future__ import annotations


import numpy as np

from .polygons import fan_triangles, parse_mesh_file

__all__ = ["read_obj"]

_MAX_INDEX = 2**53


def read_obj(path) -> tuple[np.ndarray, np.ndarray]:
    """Vertices ``(n, 3)`` float64 (the file's length unit, in file order) and triangles
    ``(m, 3)`` int64 (0-based vertex indices, the file's winding) of the Wavefront OBJ
    file ``path``. Raises ``ValueError("<path>: <what is wrong>")`` (one line)."""
    return parse_mesh_file(path, _parse)


def _lines(data: bytes):
    """(line number, statement tokens) of the non-empty lines, comments removed and
    backslash continuations joined."""
    if b"\0" in data:
        raise ValueError("is a binary file, not a Wavefront OBJ text file")
    text = data.decode("utf-8", errors="replace")
    pending, first = "", 0
    for k, line in enumerate(text.splitlines(), start=1):
        line = line.split("#", 1)[0]
        if line.rstrip().endswith("\\"):
            first = first or k
            pending += line.rstrip()[:-1] + " "
            continue
        line, at = pending + line, first or k
        pending, first = "", 0
        tokens = line.split()
        if tokens:
            yield at, tokens
    if pending.split():
        yield first, pending.split()


def _parse(data: bytes):
    vertices, vertex_lines, corners, ends, face_lines = [], [], [], [], []
    for k, tokens in _lines(data):
        key = tokens[0]
        if key == "v":
            if len(tokens) < 4:
                raise ValueError(f"line {k}: a vertex needs x y z, got {' '.join(tokens)!r}")
            try:
                vertices.append((float(tokens[1]), float(tokens[2]), float(tokens[3])))
            except ValueError:
                raise ValueError(f"line {k}: vertex coordinates {' '.join(tokens[1:4])!r} are not numbers") from None
            vertex_lines.append(k)
        elif key == "f":
            if len(tokens) < 4:
                raise ValueError(f"line {k}: a face needs at least 3 corners, got {len(tokens) - 1}")
            corners.extend(_face(tokens[1:], len(vertices), k))
            ends.append(len(corners))
            face_lines.append(k)
    v = np.array(vertices, dtype=np.float64).reshape(-1, 3)
    bad = ~np.isfinite(v).all(axis=1)
    if bad.any():
        i = int(np.argmax(bad))
        raise ValueError(f"line {vertex_lines[i]}: vertex {i + 1} has a non-finite coordinate {v[i].tolist()}")
    conn = np.array(corners, dtype=np.int64)
    bad = conn >= len(v)
    if bad.any():
        face = int(np.searchsorted(np.array(ends), int(np.argmax(bad)), side="right"))
        raise ValueError(f"line {face_lines[face]}: face vertex index {conn[bad][0] + 1} is beyond the "
                         f"{len(v)} vertices of the file")
    return v, fan_triangles(conn, np.array(ends, dtype=np.int64), "face")


def _face(tokens, n_before, k):
    """0-based vertex indices of the corners ``tokens`` of a face on line k, after
    n_before vertices (negative indices count back from there)."""
    try:
        idx = [int(t) for t in tokens]   # the common plain form "f i j k"
    except ValueError:
        idx = []
        for t in tokens:
            try:
                idx.append(int(t.split("/", 1)[0]))
            except ValueError:
                raise ValueError(f"line {k}: face corner {t!r} does not begin with a vertex index") from None
    out = []
    for t, i in zip(tokens, idx):
        if abs(i) > _MAX_INDEX:
            raise ValueError(f"line {k}: face corner {t!r} is beyond any vertex of the file")
        if i > 0:
            out.append(i - 1)
        elif i < 0 and i + n_before >= 0:
            out.append(i + n_before)
        elif i < 0:
            raise ValueError(f"line {k}: face corner {t!r} counts back beyond the first vertex "
                             f"({n_before} defined so far)")
        else:
            raise ValueError(f"line {k}: face corner {t!r}: vertex indices start at 1 (or -1)")
    return out
