"""Vertex-clustering decimation of triangle meshes for display.

Vertices are grouped in the cells of a regular grid; each cell becomes one vertex at the
mean of its members, triangles are re-indexed and those that collapse (two corners in
one cell) or repeat are dropped. The cell size grows until the mesh has at most
``max_vertices`` vertices. The cluster label of every original vertex is returned, so
per-vertex data (contact pressure) can be carried to the display mesh. Display only:
the analysis always uses the full mesh.
"""

from __future__ import annotations

import numpy as np


def cluster_vertices(vertices, cell):
    """Cluster label (n,) int of each vertex of ``vertices`` (n, 3) m in a grid of cell
    size ``cell`` m, and the number of clusters."""
    keys = np.floor((vertices - vertices.min(0)) / cell).astype(np.int64)
    _, labels = np.unique(keys, axis=0, return_inverse=True)
    labels = labels.ravel()
    return labels, int(labels.max()) + 1 if len(labels) else 0


def decimate(vertices, faces, max_vertices):
    """(vertices (k, 3), faces (m', 3) int, labels (n,) int) with k ≤ max_vertices.

    vertices : (n, 3) m; faces : (m, 3) int. A mesh already small enough is returned
    unchanged (labels = arange(n))."""
    vertices = np.asarray(vertices, dtype=float)
    faces = np.asarray(faces, dtype=np.int64)
    n = len(vertices)
    if n <= max_vertices:
        return vertices, faces, np.arange(n)
    extent = float(np.linalg.norm(vertices.max(0) - vertices.min(0)))
    # start from the cell that would give max_vertices cells on a surface of this area
    edges = vertices[faces[:, [1, 2, 0]]] - vertices[faces]
    area = 0.5 * np.linalg.norm(np.cross(edges[:, 0], -edges[:, 2]), axis=1).sum()
    cell = max(np.sqrt(area / max_vertices), extent * 1e-6)
    while True:
        labels, k = cluster_vertices(vertices, cell)
        if k <= max_vertices:
            break
        cell *= 1.25
    counts = np.bincount(labels, minlength=k).astype(float)
    out_v = np.stack([np.bincount(labels, weights=vertices[:, j], minlength=k) for j in range(3)], axis=1) / counts[:, None]
    f = labels[faces]
    keep = (f[:, 0] != f[:, 1]) & (f[:, 1] != f[:, 2]) & (f[:, 2] != f[:, 0])
    f = f[keep]
    # drop repeated triangles (same corners, same winding up to rotation)
    rot = np.argmin(f, axis=1)
    canon = np.stack([f[np.arange(len(f)), (rot + j) % 3] for j in range(3)], axis=1)
    _, first = np.unique(canon, axis=0, return_index=True)
    return out_v, f[np.sort(first)], labels
