"""Display meshes of bodies: the optional model-file entry ``bodies.<name>.visual``.

A visual mesh only changes what a viewer draws (``openfdk view``); it never enters an
analysis. The entry is one mapping or a list of mappings::

    bodies:
      mandible:
        visual:
          mesh: meshes/mandible.stl     # path relative to the model file
          units: mm                     # the mesh file's unit (default: the model's)
          placement: {position: [0, 0, 0], orientation: [0, 0, 0]}   # file -> body frame
          color: "#e8dcc8"              # optional display colour

The file is checked to exist when the model is loaded; it is read (and decimated for
display) only by the viewer.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

VISUALS = "visuals"
_COLOR = re.compile(r"^#[0-9a-fA-F]{6}$")
_UNITS = {1.0: "m", 0.01: "cm", 0.001: "mm"}


@dataclass(frozen=True, eq=False)
class VisualMesh:
    """A display mesh fixed on a body.

    body : str body name; path : str absolute mesh file path; units : the file's length
    unit ("m", "cm", "mm"); p_BF : (3,) m and R_BF : (3, 3), the placement of the file
    coordinates in the body frame (v_B = R_BF v_file + p_BF); color : "#rrggbb" or "";
    entry : the model-file entry ("bodies.skull.visual[0]"), for messages.
    """

    body: str
    path: str
    units: str
    p_BF: np.ndarray
    R_BF: np.ndarray
    color: str = ""
    entry: str = ""


def load_visuals(b, body, value, path, ctx):
    """Parse ``bodies.<body>.visual`` (a mapping or a list of mappings) into VisualMesh
    entries appended to ``b.elements["visuals"]``; errors name the file and the entry."""
    from .modelfile import _orientation

    entries = value if isinstance(value, list) else [value]
    if not entries:
        raise ctx.error(path, "expected a mapping {mesh, units, placement, color} or a non-empty list of them")
    items = list(b.elements.get(VISUALS, ()))
    for k, spec in enumerate(entries):
        p = f"{path}[{k}]" if isinstance(value, list) else path
        ctx.keys(spec, p, ["mesh", "units", "placement", "color"], required=("mesh",))
        if not isinstance(spec["mesh"], str) or not spec["mesh"]:
            raise ctx.error(f"{p}.mesh", f"expected a mesh file path, got {spec['mesh']!r}")
        mesh = (ctx.base_dir / spec["mesh"]).resolve()
        if not mesh.is_file():
            raise ctx.error(f"{p}.mesh", f"mesh file {str(mesh)!r} does not exist")
        units = spec.get("units", _UNITS.get(ctx.length, "m"))
        if units not in ("m", "cm", "mm"):
            raise ctx.error(f"{p}.units", f"unknown length unit {units!r}; expected one of ['m', 'cm', 'mm']")
        pl = ctx.keys(spec.get("placement") or {}, f"{p}.placement", ["position", "orientation"])
        p_BF = ctx.position(pl.get("position", [0, 0, 0]), f"{p}.placement.position")
        R_BF = _orientation(pl.get("orientation"), f"{p}.placement.orientation", ctx)
        color = spec.get("color", "")
        if color and not (isinstance(color, str) and _COLOR.match(color)):
            raise ctx.error(f"{p}.color", f"expected a colour '#rrggbb', got {color!r}")
        items.append(VisualMesh(body, str(mesh), units, p_BF, R_BF, color, p))
    b.elements[VISUALS] = tuple(items)
