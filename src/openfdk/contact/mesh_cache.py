"""Surface meshes memoised per process, keyed by the mesh file's fingerprint.

Loading a mesh (:func:`~.mesh.load_mesh`: reading the file (:mod:`.stl` or trimesh), merging
vertices, checking and repairing the triangles, normals and tributary areas) takes tens
of milliseconds per mesh. A study runs many models that share their meshes (the
mandible parameter study: 45 cases × 4 meshes in 2 worker processes), so each process
loads a mesh once and hands the same read-only :class:`~.mesh.SurfaceMesh` to every
model built after it.

The key is the file's resolved path, its size and modification time (ns), and the load
options (length unit, placement, flip_normals, name), so an edited mesh file is read
again. The repair warnings that the first load emitted (:class:`~.mesh.MeshWarning`)
are emitted again on every later hit, so each model still reports them. At most
:data:`MEMORY_SLOTS` meshes are kept (least recently used dropped).
"""

from __future__ import annotations

import warnings
from collections import OrderedDict

import numpy as np

from ..io.fingerprint import file_stamp
from .mesh import SurfaceMesh, load_mesh

__all__ = ["cached_load_mesh", "clear_mesh_cache", "mesh_cache_size"]

MEMORY_SLOTS = 32
_MEMORY: OrderedDict[tuple, tuple[SurfaceMesh, tuple]] = OrderedDict()


def _placement_key(placement):
    """Hashable form of a placement (None, (4, 4) matrix, or (t (3,), R (3, 3)))."""
    if placement is None:
        return None
    if isinstance(placement, (tuple, list)) and len(placement) == 2:
        return tuple(np.asarray(p, dtype=float).tobytes() for p in placement)
    return (np.asarray(placement, dtype=float).tobytes(),)


def cached_load_mesh(path, units="m", placement=None, *, flip_normals=False, name=None) -> SurfaceMesh:
    """:func:`~.mesh.load_mesh` with the same arguments and result, read from the file
    only the first time in this process (module docstring). Raises what load_mesh
    raises (errors are not memoised)."""
    file_key = file_stamp(path)
    if file_key is None:
        return load_mesh(path, units, placement, flip_normals=flip_normals, name=name)
    key = (file_key, units, _placement_key(placement), bool(flip_normals), name)
    hit = _MEMORY.get(key)
    if hit is not None:
        _MEMORY.move_to_end(key)
        mesh, caught = hit
        for w in caught:
            warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
        return mesh
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        mesh = load_mesh(path, units, placement, flip_normals=flip_normals, name=name)
    for w in caught:  # to the caller's filters, as load_mesh would have
        warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
    _MEMORY[key] = (mesh, tuple(caught))
    while len(_MEMORY) > MEMORY_SLOTS:
        _MEMORY.popitem(last=False)
    return mesh


def clear_mesh_cache() -> None:
    """Forget every memoised mesh."""
    _MEMORY.clear()


def mesh_cache_size() -> int:
    """Number of meshes held."""
    return len(_MEMORY)
