"""Elastic-foundation contact between triangle meshes (docs/design.md §1).

* :mod:`.mesh` — :class:`SurfaceMesh`, :func:`load_mesh` (STL/OBJ/PLY), :func:`check_scale`,
  :func:`offset`.
* :mod:`.elastic_foundation` — :class:`ElasticFoundation` contact pairs and
  :class:`ContactResult` (generalized forces, centre of pressure, area, peak pressure,
  stiffness).
* :mod:`.element` — :class:`ContactElement`, a pair as a model force element (scatters Q
  and K into a model's q̂ columns).
* :mod:`.signed_distance`, :mod:`.distance_grid` — exact (libigl) and gridded (numba)
  signed distance to an open surface.
* :mod:`.shapes` — procedural test surfaces (sphere cap, flat patch, ellipsoid cap, fossa).

See docs/contact.md for the model, its rules for open meshes and the accuracy/speed
measurements.
"""

from .elastic_foundation import (
    DEFAULT_GRID_SPACING,
    DEFAULT_MAX_DEPTH,
    ContactResult,
    ElasticFoundation,
)
from .element import ContactElement
from .mesh import (
    MeshError,
    MeshWarning,
    SurfaceMesh,
    check_scale,
    load_mesh,
    offset,
    surface_mesh,
)

__all__ = [
    "ElasticFoundation",
    "ContactElement",
    "ContactResult",
    "DEFAULT_GRID_SPACING",
    "DEFAULT_MAX_DEPTH",
    "SurfaceMesh",
    "surface_mesh",
    "load_mesh",
    "check_scale",
    "offset",
    "MeshError",
    "MeshWarning",
]
