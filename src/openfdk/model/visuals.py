"""Display meshes of bodies: the optional model-file entry ``bodies.<name>.visual``.

A visual mesh only changes what a viewer draws (``openfdk view``); it never enters an
analysis. The entry is one mapping or a list of mappings::

    bodies:
      femur:
        visual:
          mesh: meshes/femur_r.vtp      # path relative to the model file: .stl, .vtp, .obj (.ply)
          units: m                      # the mesh file's unit (default: the model's)
          scale: [1, 1, 1]              # optional: per-axis factors on the file coordinates
          placement: {position: [0, 0, 0], orientation: [0, 0, 0]}   # file -> body frame
          color: "#e8dcc8"              # optional display colour

Formats are read by :func:`openfdk.io.meshfiles.read_display_mesh`: STL (binary or
ASCII), VTK XML PolyData ``.vtp`` (OpenSim's bone geometry), Wavefront OBJ and PLY.

``scale`` (dimensionless, three finite non-zero numbers, default ``[1, 1, 1]``) is
OpenSim's ``scale_factors``: a diagonal S applied to the file coordinates before the
placement, so a vertex v_file (in ``units``, converted to m by u) lands in the body frame
at ``v_B = R_BF (S u v_file) + p_BF``. A scale with an odd number of negative factors
mirrors the mesh; the triangles are then reversed so that their winding (right-hand
normals) still points out of the surface.

The file is checked to exist and to have a known suffix when the model is loaded; it is
read (by :func:`visual_mesh_B`, then decimated for display) only by the viewer and the
OpenSim exporter.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field

import numpy as np

VISUALS = "visuals"
_COLOR = re.compile(r"^#[0-9a-fA-F]{6}$")
_UNITS = {1.0: "m", 0.01: "cm", 0.001: "mm"}
_METRES = {"m": 1.0, "cm": 0.01, "mm": 0.001}


@dataclass(frozen=True, eq=False)
class VisualMesh:
    """A display mesh fixed on a body.

    body : str body name; path : str absolute mesh file path; units : the file's length
    unit ("m", "cm", "mm"); p_BF : (3,) m and R_BF : (3, 3), the placement of the file
    coordinates in the body frame; color : "#rrggbb" or ""; entry : the model-file entry
    ("bodies.skull.visual[0]"), for messages; scale : (3,) dimensionless per-axis factors
    S on the file coordinates (default ones): v_B = R_BF (S u v_file) + p_BF, u the
    file unit in m.
    """

    body: str
    path: str
    units: str
    p_BF: np.ndarray
    R_BF: np.ndarray
    color: str = ""
    entry: str = ""
    scale: np.ndarray = field(default_factory=lambda: np.ones(3))


def visual_mesh_B(vis: VisualMesh) -> tuple[np.ndarray, np.ndarray]:
    """Vertices ``(n, 3)`` m in the body frame, ``v_B = R_BF (S u v_file) + p_BF``, and
    triangles ``(m, 3)`` int64 of the visual mesh ``vis`` (reversed when S mirrors).
    Raises ``ValueError("<file>: <what is wrong>")`` when the file cannot be read."""
    from ..io.meshfiles import read_display_mesh

    vertices, triangles = read_display_mesh(vis.path)
    scale = np.asarray(vis.scale, dtype=float)
    vertices_B = (vertices * (_METRES[vis.units] * scale)) @ np.asarray(vis.R_BF, dtype=float).T + vis.p_BF
    if np.prod(np.sign(scale)) < 0:
        triangles = triangles[:, ::-1].copy()
    return vertices_B, triangles


def load_visuals(b, body, value, path, ctx):
    """Parse ``bodies.<body>.visual`` (a mapping or a list of mappings) into VisualMesh
    entries appended to the builder's visuals (``model.visuals`` once built); errors name the file and the entry."""
    from ..io.meshfiles import DISPLAY_MESH_SUFFIXES
    from .orientation_entry import _orientation

    entries = value if isinstance(value, list) else [value]
    if not entries:
        raise ctx.error(path, "expected a mapping {mesh, units, scale, placement, color} or a non-empty list of them")
    items = list(b.elements.get(VISUALS, ()))
    for k, spec in enumerate(entries):
        p = f"{path}[{k}]" if isinstance(value, list) else path
        ctx.keys(spec, p, ["mesh", "units", "scale", "placement", "color"], required=("mesh",))
        if not isinstance(spec["mesh"], str) or not spec["mesh"]:
            raise ctx.error(f"{p}.mesh", f"expected a mesh file path, got {spec['mesh']!r}")
        mesh = (ctx.base_dir / spec["mesh"]).resolve()
        if not mesh.is_file():
            raise ctx.error(f"{p}.mesh", f"mesh file {str(mesh)!r} does not exist")
        if mesh.suffix.lower() not in DISPLAY_MESH_SUFFIXES:
            raise ctx.error(f"{p}.mesh", f"unknown mesh format {mesh.suffix!r} ({mesh.name}); "
                                         f"expected one of {list(DISPLAY_MESH_SUFFIXES)}")
        units = spec.get("units", _UNITS.get(ctx.length, "m"))
        if units not in ("m", "cm", "mm"):
            raise ctx.error(f"{p}.units", f"unknown length unit {units!r}; expected one of ['m', 'cm', 'mm']")
        scale = ctx.vector(spec.get("scale", [1, 1, 1]), f"{p}.scale", n=3)
        if np.any(scale == 0):
            raise ctx.error(f"{p}.scale", f"scale factors must be non-zero, got {spec['scale']!r}")
        pl = ctx.keys(spec.get("placement") or {}, f"{p}.placement", ["position", "orientation"])
        p_BF = ctx.position(pl.get("position", [0, 0, 0]), f"{p}.placement.position")
        R_BF = _orientation(pl.get("orientation"), f"{p}.placement.orientation", ctx)
        color = spec.get("color", "")
        if color and not (isinstance(color, str) and _COLOR.match(color)):
            raise ctx.error(f"{p}.color", f"expected a colour '#rrggbb', got {color!r}")
        items.append(VisualMesh(body, str(mesh), units, p_BF, R_BF, color, p, scale))
    b.elements[VISUALS] = tuple(items)
