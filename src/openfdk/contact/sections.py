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
                grid_spacing=None, max_depth=DEFAULT_MAX_DEPTH, layers=None):
    """Add an elastic-foundation contact: vertices of ``surface_a`` (SurfaceMesh in body_a's
    frame) against ``surface_b`` (in body_b's frame); pressure modulus in N/m³, or the
    non-linear law's ``layers`` [(K Pa, h m), …] (:mod:`.pressure_law`).
    Warns (MeshWarning) when the two surfaces are far apart in the reference pose.
    The name must pass :func:`~openfdk.model.names.name_problem` (it names exported files)."""
    from ..model.names import check_name

    check_name(name, "contact")
    ia, ib = b._body_index(body_a, f"contact {name!r}"), b._body_index(body_b, f"contact {name!r}")
    if ia == ib:
        raise ModelError(f"contact {name!r}: both surfaces are on body {body_a!r}")
    pair = ElasticFoundation(surface_a, surface_b, pressure_modulus, mode, grid_spacing, max_depth, name, layers)
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
    ctx.keys(spec, path, ["body", "mesh", "units", "placement", "offset", "flip_normals"], required=("body", "mesh"))
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
    return spec["body"], mesh


def load_contacts(b, data, ctx):
    for name, spec in ctx.mapping(data, CONTACTS).items():
        p = f"{CONTACTS}.{name}"
        ctx.keys(spec, p, ["vertices", "surface", "pressure_modulus", "law", "layers", "mode", "grid_spacing",
                           "max_depth", "regions"], required=("vertices", "surface"))
        body_a, surf_a = _surface(spec["vertices"], f"{p}.vertices", ctx)
        body_b, surf_b = _surface(spec["surface"], f"{p}.surface", ctx)
        law = spec.get("law", "linear")
        layers = None
        if law == "linear":
            if "pressure_modulus" not in spec:
                raise ctx.error(p, "the linear law needs 'pressure_modulus' (N/m³)")
            if "layers" in spec:
                raise ctx.error(f"{p}.layers", "'layers' belong to 'law: nonlinear'")
            k = ctx.number(spec["pressure_modulus"], f"{p}.pressure_modulus", positive=True)
        elif law == "nonlinear":
            if "pressure_modulus" in spec:
                raise ctx.error(f"{p}.pressure_modulus", "the non-linear law takes 'layers', not 'pressure_modulus'")
            items = spec.get("layers")
            if not isinstance(items, list) or not 1 <= len(items) <= 2:
                raise ctx.error(f"{p}.layers", "expected a list of 1 or 2 layers {modulus: K Pa, thickness: h}")
            layers = []
            for j, item in enumerate(items):
                q = f"{p}.layers[{j}]"
                ctx.keys(item, q, ["modulus", "thickness"], required=("modulus", "thickness"))
                layers.append((ctx.number(item["modulus"], f"{q}.modulus", positive=True),
                               ctx.number(item["thickness"], f"{q}.thickness", positive=True) * ctx.length))
            k = 1.0 / sum(h / K for K, h in layers)
        else:
            raise ctx.error(f"{p}.law", f"expected 'linear' or 'nonlinear', got {law!r}")
        mode = spec.get("mode", "grid")
        h = ctx.number(spec["grid_spacing"], f"{p}.grid_spacing", positive=True) * ctx.length if "grid_spacing" in spec else DEFAULT_GRID_SPACING
        depth = ctx.number(spec["max_depth"], f"{p}.max_depth", positive=True) * ctx.length if "max_depth" in spec else DEFAULT_MAX_DEPTH
        regions = _regions(spec.get("regions"), f"{p}.regions", ctx)
        try:
            element = _wrap(ctx, p, lambda: add_contact(b, name, body_a, surf_a, body_b, surf_b, k, mode, h, depth,
                                                        layers))
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

