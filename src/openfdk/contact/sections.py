"""Model-file section ``contacts`` and the builder function :func:`add_contact`.

```yaml
contacts:
  tmj_r:
    vertices:                         # surface whose vertices are tested (body a)
      body: mandible
      mesh: meshes/condyle_r.stl      # path relative to the model file
      units: mm                       # the mesh file's unit (default: the model's)
      placement: {position: [0, 0, 0], orientation: [0, 0, 0]}   # file -> body frame
      offset: 1.0                     # along vertex normals, model length unit
    surface:                          # the opposite surface (body b)
      body: skull
      mesh: meshes/fossa_r.stl
    pressure_modulus: 1.0e10          # N/m³ (always SI): the linear law P = p d
    # or the non-linear law P = −K ln(1 − d/h) (Bei & Fregly 2004; contact/pressure_law.py):
    # law: nonlinear
    # layers: [{modulus: 2.3e7, thickness: 4}]   # K Pa (SI), h model length unit; 2 layers in series
    # a layer's thickness may vary over its cartilage (OpenSim-JAM's variable thickness,
    # contact/thickness.py): a surface gets  thickness: {back_mesh: bone.stl, min: 1, max: 10}
    # and the layer  thickness: vertices | surface | [vertices, surface] (added: JAM's
    # lumped layer; a number may be one of the two); the linear law then takes layers
    # too: P = d / Σ h_j/K_j
    mode: grid                        # grid (default) or exact
    grid_spacing: 0.3                 # model length unit (default 0.3 mm)
    max_depth: 3                      # model length unit (default 3 mm)
    regions:                          # optional: the force of parts of the contact (outputs)
      medial: {axis: [0, 0, -1]}      # the surface body's frame; origin: [x, y, z] (default 0)
      lateral: {axis: [0, 0, 1]}      # forces.csv: <contact>.medial_N, <contact>.lateral_N
```
"""

from __future__ import annotations

import warnings

import numpy as np

from ..model.modelfile import _orientation, _wrap
from ..model.model import ModelError
from .elastic_foundation import DEFAULT_GRID_SPACING, DEFAULT_MAX_DEPTH, ElasticFoundation
from .element import ContactElement
from .mesh import MeshError, MeshWarning, check_scale, offset
from .mesh_cache import cached_load_mesh

CONTACTS = "contacts"
#: typical size (m) of a meshed joint region, for the mm-vs-m order-of-magnitude warning
JOINT_REGION_SIZE = 0.05


def add_contact(b, name, body_a, surface_a, body_b, surface_b, pressure_modulus, mode="grid",
                grid_spacing=None, max_depth=DEFAULT_MAX_DEPTH, layers=None, variable=None):
    """Add an elastic-foundation contact: vertices of ``surface_a`` (SurfaceMesh in body_a's
    frame) against ``surface_b`` (in body_b's frame); pressure modulus in N/m³, or the
    non-linear law's ``layers`` [(K Pa, h m), …] (:mod:`.pressure_law`), or layers
    whose thickness varies over the surfaces (``variable``: a
    :class:`~.variable_layers.VariableLayers`).
    Warns (MeshWarning) when the two surfaces are far apart in the reference pose.
    The name must pass :func:`~openfdk.model.names.name_problem` (it names exported files)."""
    from ..model.names import check_name

    check_name(name, "contact")
    ia, ib = b._body_index(body_a, f"contact {name!r}"), b._body_index(body_b, f"contact {name!r}")
    if ia == ib:
        raise ModelError(f"contact {name!r}: both surfaces are on body {body_a!r}")
    pair = ElasticFoundation(surface_a, surface_b, pressure_modulus, mode, grid_spacing, max_depth, name, layers,
                             variable)
    _warn_if_apart(b, name, ia, surface_a, ib, surface_b, max_depth)
    items = list(b.elements.get(CONTACTS, ()))
    if any(c.name == name for c in items):
        raise ModelError(f"contact {name!r} is defined twice")
    items.append(ContactElement(name, ia, ib, pair))
    b.elements[CONTACTS] = tuple(items)
    return items[-1]


def _warn_if_apart(b, name, ia, surf_a, ib, surf_b, max_depth):
    from ..numerics.spatial import rotation_matrix

    def world(i, surf):
        rec = b._bodies[i]
        return rec["position"] + surf.vertices_B @ rotation_matrix(rec["quat"]).T

    A, B = world(ia, surf_a), world(ib, surf_b)
    gap = np.maximum(0.0, np.maximum(A.min(0) - B.max(0), B.min(0) - A.max(0)))
    distance = float(np.linalg.norm(gap))
    if distance > max(5e-3, 10 * max_depth):
        warnings.warn(
            f"contact {name!r}: the surfaces are {distance * 1e3:.1f} mm apart in the reference pose "
            f"(bounding boxes); check the mesh units and placement",
            MeshWarning, stacklevel=3,
        )


def _surface(spec, path, ctx):
    ctx.keys(spec, path, ["body", "mesh", "units", "placement", "offset", "flip_normals", "thickness"],
             required=("body", "mesh"))
    units = spec.get("units", {1.0: "m", 0.01: "cm", 0.001: "mm"}.get(ctx.length, "m"))
    placement = None
    if "placement" in spec:
        pl = ctx.keys(spec["placement"], f"{path}.placement", ["position", "orientation"])
        t = ctx.position(pl.get("position", [0, 0, 0]), f"{path}.placement.position")
        placement = (t, _orientation(pl.get("orientation"), f"{path}.placement.orientation", ctx))
    mesh_path = ctx.base_dir / str(spec["mesh"])
    try:
        mesh = cached_load_mesh(mesh_path, units=units, placement=placement,
                                flip_normals=ctx.boolean(spec.get("flip_normals", False), f"{path}.flip_normals"),
                                name=str(spec["mesh"]))
    except MeshError as exc:
        raise ctx.error(f"{path}.mesh", str(exc)) from None
    check_scale(mesh, JOINT_REGION_SIZE)
    if "offset" in spec:
        mesh = offset(mesh, ctx.number(spec["offset"], f"{path}.offset") * ctx.length)
    h_tri = None
    if "thickness" in spec:
        h_tri = _thickness(spec["thickness"], f"{path}.thickness", mesh, units, placement, ctx)
    return spec["body"], mesh, h_tri


def _thickness(spec, path, mesh, units, placement, ctx):
    """h (n_tri,) m of the mesh's triangles from ``thickness: {back_mesh, min, max}``
    (the bone behind the cartilage, in the mesh's file frame and unit; min and max in
    the model's length unit; :mod:`.thickness`)."""
    from .thickness import triangle_thickness

    spec = ctx.keys(spec, path, ["back_mesh", "min", "max"], required=("back_mesh", "min", "max"))
    h_min = ctx.number(spec["min"], f"{path}.min", positive=True) * ctx.length
    h_max = ctx.number(spec["max"], f"{path}.max", positive=True) * ctx.length
    if not h_min < h_max:
        raise ctx.error(path, f"min {spec['min']!r} must be below max {spec['max']!r}")
    try:
        back = cached_load_mesh(ctx.base_dir / str(spec["back_mesh"]), units=units, placement=placement,
                                name=str(spec["back_mesh"]))
    except MeshError as exc:
        raise ctx.error(f"{path}.back_mesh", str(exc)) from None
    h, hit = triangle_thickness(mesh.vertices_B, mesh.faces, back.vertices_B, back.faces, h_min, h_max)
    if not hit.any():
        raise ctx.error(f"{path}.back_mesh", f"no triangle's inward normal meets {spec['back_mesh']!r} within max "
                        f"{spec['max']!r}: is it the bone behind this cartilage, in the same frame?")
    return h


def _layers(items, path, ctx, fields):
    """[(K Pa, h m (constant part), from A, from B)] of ``layers``: a layer's thickness
    is a number, a surface's thickness field (``vertices`` or ``surface``), or a list of
    those added (OpenSim-JAM's lumped layer: [vertices, surface])."""
    if not isinstance(items, list) or not 1 <= len(items) <= 2:
        raise ctx.error(path, "expected a list of 1 or 2 layers {modulus: K Pa, thickness: h}")
    out = []
    for j, item in enumerate(items):
        q = f"{path}[{j}]"
        ctx.keys(item, q, ["modulus", "thickness"], required=("modulus", "thickness"))
        K = ctx.number(item["modulus"], f"{q}.modulus", positive=True)
        parts = item["thickness"] if isinstance(item["thickness"], list) else [item["thickness"]]
        if not 1 <= len(parts) <= 2:
            raise ctx.error(f"{q}.thickness", f"expected a thickness or a list of 2 added, got {item['thickness']!r}")
        h, used = 0.0, []
        for part in parts:
            if isinstance(part, str):
                if part not in fields or part in used:
                    raise ctx.error(f"{q}.thickness", f"expected a number, 'vertices' or 'surface' (each once), got "
                                    f"{part!r}")
                if fields[part] is None:
                    raise ctx.error(f"{q}.thickness", f"the {part} surface has no 'thickness' field")
                used.append(part)
            else:
                h += ctx.number(part, f"{q}.thickness", positive=True) * ctx.length
        out.append((K, h, "vertices" in used, "surface" in used))
    return out


def load_contacts(b, data, ctx):
    for name, spec in ctx.mapping(data, CONTACTS).items():
        p = f"{CONTACTS}.{name}"
        ctx.keys(spec, p, ["vertices", "surface", "pressure_modulus", "law", "layers", "mode", "grid_spacing",
                           "max_depth", "regions"], required=("vertices", "surface"))
        body_a, surf_a, h_A = _surface(spec["vertices"], f"{p}.vertices", ctx)
        body_b, surf_b, h_B = _surface(spec["surface"], f"{p}.surface", ctx)
        law = spec.get("law", "linear")
        if law not in ("linear", "nonlinear"):
            raise ctx.error(f"{p}.law", f"expected 'linear' or 'nonlinear', got {law!r}")
        layers = variable = None
        if law == "linear" and "layers" not in spec:
            if "pressure_modulus" not in spec:
                raise ctx.error(p, "the linear law needs 'pressure_modulus' (N/m³) or 'layers'")
            k = ctx.number(spec["pressure_modulus"], f"{p}.pressure_modulus", positive=True)
        else:
            if "pressure_modulus" in spec:
                raise ctx.error(f"{p}.pressure_modulus", "give 'layers' or 'pressure_modulus', not both")
            if "layers" not in spec:
                raise ctx.error(p, "the non-linear law needs 'layers'")
            items = _layers(spec["layers"], f"{p}.layers", ctx, {"vertices": h_A, "surface": h_B})
            if any(a or b_ for _, _, a, b_ in items):
                from .thickness import TriangleThickness, vertex_thickness
                from .variable_layers import VariableLayers

                variable = VariableLayers(items, law == "nonlinear",
                                          None if h_A is None else vertex_thickness(surf_a, h_A),
                                          None if h_B is None else TriangleThickness(surf_b, h_B))
                k = variable.mean_modulus()
            elif law == "nonlinear":
                layers = [(K, h) for K, h, _, _ in items]
                k = 1.0 / sum(h / K for K, h in layers)
            else:  # linear with uniform layers: their series modulus
                k = 1.0 / sum(h / K for K, h, _, _ in items)
        for side, h in (("vertices", h_A), ("surface", h_B)):
            if h is not None and variable is None:
                raise ctx.error(f"{p}.{side}.thickness", "no layer uses this thickness field (a layer's "
                                f"thickness: {side})")
        mode = spec.get("mode", "grid")
        h = ctx.number(spec["grid_spacing"], f"{p}.grid_spacing", positive=True) * ctx.length if "grid_spacing" in spec else DEFAULT_GRID_SPACING
        depth = ctx.number(spec["max_depth"], f"{p}.max_depth", positive=True) * ctx.length if "max_depth" in spec else DEFAULT_MAX_DEPTH
        regions = _regions(spec.get("regions"), f"{p}.regions", ctx)
        try:
            element = _wrap(ctx, p, lambda: add_contact(b, name, body_a, surf_a, body_b, surf_b, k, mode, h, depth,
                                                        layers, variable))
        except (ValueError, TypeError) as exc:
            if isinstance(exc, ModelError):
                raise
            raise ctx.error(p, str(exc)) from None
        element.pair.set_regions(regions)


def _regions(data, path, ctx):
    """[(name, axis (3,), origin (3,) m)] of a contact's ``regions`` (module docstring)."""
    from ..model.names import name_problem

    if data is None:
        return []
    out = []
    for name, spec in ctx.mapping(data, path).items():
        q = f"{path}.{name}"
        problem = name_problem(name) if isinstance(name, str) and name else "a region needs a name (text)"
        if problem:
            raise ctx.error(q, problem)
        ctx.keys(spec, q, ["axis", "origin"], required=("axis",))
        axis = _vector(spec["axis"], f"{q}.axis", ctx)
        if not np.linalg.norm(axis) > 0.0:
            raise ctx.error(f"{q}.axis", "expected a non-zero direction")
        origin = (_vector(spec["origin"], f"{q}.origin", ctx) * ctx.length) if "origin" in spec else np.zeros(3)
        out.append((name, axis, origin))
    return out


def _vector(value, path, ctx):
    """A finite (3,) vector of the model file, or a one-line error naming the entry."""
    if (not isinstance(value, (list, tuple)) or len(value) != 3
            or not all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in value)
            or not np.all(np.isfinite(np.asarray(value, dtype=float)))):
        raise ctx.error(path, f"expected 3 finite numbers, got {value!r}")
    return np.asarray(value, dtype=float)

