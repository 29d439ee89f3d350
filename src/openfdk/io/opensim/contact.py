"""OpenSim-JAM's articular contact: ``Smith2018ContactMesh`` (in the ContactGeometrySet)
and ``Smith2018ArticularContactForce`` (in the ForceSet) become an entry of the
model-file section ``contacts`` (openfdk's elastic foundation, docs/contact.md).

The elastic-foundation pressure of a layer of thickness h, Young's modulus E and
Poisson's ratio ν pressed by a depth d (Bei & Fregly 2004; Smith et al. 2018):

    linear:      p = K d / h,                K = E (1 − ν) / ((1 + ν)(1 − 2ν))
    non-linear:  p = −K ln(1 − d/h)

``use_lumped_contact_model`` (OpenSim-JAM's default true) lumps the two meshes' layers
into one: E and ν their means, h = h₁ + h₂. Otherwise the two layers are springs in
series, d = d₁ + d₂ at equal pressure: linear p = d / (h₁/K₁ + h₂/K₂), non-linear
d = Σ h_j (1 − exp(−p/K_j)). The linear law becomes openfdk's pressure modulus (N/m³),
the non-linear one ``law: nonlinear`` with its ``layers`` [K, h]
(:mod:`openfdk.contact.pressure_law`). The casting mesh (whose triangles OpenSim-JAM casts
rays from) carries the vertices; the target is the opposite surface; ``max_proximity``
(m), capped at the two layers' total thickness (:func:`contact_depth`), is the largest
depth counted (openfdk's ``max_depth``); ``min_proximity`` must be 0.
A mesh is read from its ``mesh_file`` as a display mesh is (next to the model, its
Geometry folder, ``--geometry``), placed by its ``socket_frame`` in its body, and within
that frame by ContactGeometry's ``location`` and ``orientation`` (body-fixed X-Y-Z Euler
angles) where the file gives them (models written by OpenSim 4.0–4.4).

Variable thickness (``use_variable_thickness`` with its ``mesh_back_file``,
``min_thickness``, ``max_thickness``): the mesh's surface gets ``thickness: {back_mesh,
min, max}`` and its layer ``thickness: vertices`` or ``surface`` (both added for the
lumped layer), computed as OpenSim-JAM computes it (:mod:`openfdk.contact.thickness`);
a ``mesh_back_file`` without it is not read, as JAM does not read it.

Read and refused by name: ``scale_factors`` other than 1, use_variable_thickness without
its back mesh, a missing ``thickness`` (uniform), ``elastic_modulus`` or
``poissons_ratio``, ``modulus_heterogeneity``, a body-less (ground) pair.
"""

from __future__ import annotations

import math

import numpy as np

from .actuators import _flag, _number, _text
from .document import numbers, rotation_xyz
from .errors import OsimError, where

MESH_TYPE = "Smith2018ContactMesh"
FORCE_TYPE = "Smith2018ArticularContactForce"
_MESH_PROPERTIES = {"socket_frame", "socket_scale_frame", "mesh_file", "elastic_modulus", "poissons_ratio",
                    "thickness", "scale_factors", "Appearance", "components", "use_variable_thickness",
                    "mesh_back_file", "min_thickness", "max_thickness", "display_preference", "color",
                    "elastic_foundation_formulation", "location", "orientation"}
_FORCE_PROPERTIES = {"socket_target_mesh", "socket_casting_mesh", "min_proximity", "max_proximity",
                     "elastic_foundation_formulation", "use_lumped_contact_model", "appliesForce", "isDisabled",
                     "components", "Appearance", "modulus_heterogeneity", "verbose"}


def _check_properties(element, source, label, allowed):
    for child in element:
        if isinstance(child.tag, str) and child.tag not in allowed:
            raise OsimError(f"{where(source, child)}: {label}: property <{child.tag}> is not read by openfdk")


def read_contact_mesh(element, source):
    """(name, record) of a Smith2018ContactMesh: frame (OpenSim path), mesh_file, E (Pa),
    nu, h (m), line. Errors name the file, the line and the mesh."""
    name = element.get("name") or ""
    label = f"{MESH_TYPE} {name!r}"
    if not name:
        raise OsimError(f"{where(source, element)}: a {MESH_TYPE} without a name")
    _check_properties(element, source, label, _MESH_PROPERTIES)
    variable = None
    if _flag(element, "use_variable_thickness", source, label, False):
        if not _text(element, "mesh_back_file"):
            raise OsimError(f"{where(source, element)}: use_variable_thickness without a mesh_back_file "
                            "(the back mesh that gives the thickness is missing)")
        # OpenSim-JAM's defaults: min_thickness 1 mm, max_thickness 10 mm (contact/thickness.py)
        h_min = _number(element, "min_thickness", source, label, 0.001)
        h_max = _number(element, "max_thickness", source, label, 0.01)
        if not (math.isfinite(h_min) and math.isfinite(h_max) and 0.0 < h_min < h_max):
            raise OsimError(f"{where(source, element)}: min_thickness {h_min:g} and max_thickness {h_max:g} m: "
                            "openfdk needs 0 < min < max")
        variable = {"back_file": _text(element, "mesh_back_file"), "min": h_min, "max": h_max}
    # (a mesh_back_file without use_variable_thickness is not read, as OpenSim-JAM does not)
    scale = (_text(element, "scale_factors") or "1 1 1").split()
    if [float(x) for x in scale] != [1.0, 1.0, 1.0]:
        raise OsimError(f"{where(source, element)}: scale_factors {' '.join(scale)} (openfdk reads "
                        "unscaled contact meshes)")
    frame, mesh = _text(element, "socket_frame"), _text(element, "mesh_file")
    if not frame or not mesh:
        raise OsimError(f"{where(source, element)}: needs a socket_frame and a mesh_file")
    record = {"frame": frame.rstrip("/").split("/")[-1] if frame.startswith("/bodyset/") and frame.count("/") == 2
              else frame, "path": frame, "mesh_file": mesh, "line": element.sourceline}
    # ContactGeometry's pose of the mesh in its frame (OpenSim 4.0–4.4 and the JAM models
    # written with them, e.g. Lenhart 2015): p_FG = location (m), R_FG from the body-fixed
    # X-Y-Z Euler angles of orientation (rad)
    for tag, key, convert in (("location", "p_FG", np.asarray), ("orientation", "R_FG", rotation_xyz)):
        node = element.find(tag)
        record[key] = convert(numbers(node, source, 3, f"{label}: {tag}") if node is not None else np.zeros(3))
    for tag, key, ok in (("elastic_modulus", "E", lambda x: x > 0), ("poissons_ratio", "nu", lambda x: -1 < x < 0.5),
                         ("thickness", "h", lambda x: x > 0)):
        if key == "h" and variable is not None:
            continue  # (from the back mesh: OpenSim-JAM does not read <thickness> then)
        if not _text(element, tag):
            raise OsimError(f"{where(source, element)}: <{tag}> is missing (the elastic layer's "
                            f"{'thickness (m)' if key == 'h' else tag} is needed for the pressure law)")
        value = _number(element, tag, source, label, math.nan)
        if not (math.isfinite(value) and ok(value)):
            raise OsimError(f"{where(source, element)}: {tag} {value:g} is out of range")
        record[key] = value
    record["variable"] = variable
    if variable is not None:
        record["h"] = variable["max"]  # the thickest it can be (the depth the law allows)
    return name, record


def read_contact_force(element, source):
    """(name, record or None if disabled) of a Smith2018ArticularContactForce: target,
    casting (mesh names), max_proximity (m), line."""
    name = element.get("name") or ""
    label = f"{FORCE_TYPE} {name!r}"
    if not name:
        raise OsimError(f"{where(source, element)}: a {FORCE_TYPE} without a name")
    _check_properties(element, source, label, _FORCE_PROPERTIES)
    if not _flag(element, "appliesForce", source, label, True) or _flag(element, "isDisabled", source, label, False):
        return name, None
    formulation = (_text(element, "elastic_foundation_formulation") or "linear").strip()
    if formulation not in ("linear", "nonlinear"):
        raise OsimError(f"{where(source, element)}: elastic_foundation_formulation {formulation!r} is neither "
                        "'linear' nor 'nonlinear'")
    lumped = _flag(element, "use_lumped_contact_model", source, label, True)
    if _flag(element, "modulus_heterogeneity", source, label, False):
        raise OsimError(f"{where(source, element)}: modulus_heterogeneity is not supported by openfdk")
    meshes = {}
    for key in ("target", "casting"):
        text = _text(element, f"socket_{key}_mesh")
        if not text:
            raise OsimError(f"{where(source, element)}: no socket_{key}_mesh")
        meshes[key] = text.rstrip("/").split("/")[-1]
    low = _number(element, "min_proximity", source, label, 0.0)
    high = _number(element, "max_proximity", source, label, 0.01)
    if low != 0.0 or not (0.0 < high < math.inf):
        raise OsimError(f"{where(source, element)}: proximity range [{low:g}, {high:g}] m: openfdk needs "
                        "min_proximity 0 and a positive max_proximity")
    return name, {**meshes, "max_proximity": high, "line": element.sourceline, "formulation": formulation,
                  "lumped": lumped}


def layer_modulus(record):
    """K/h (N/m³) of a mesh's layer: E (1 − ν) / ((1 + ν)(1 − 2ν) h)."""
    E, nu, h = record["E"], record["nu"], record["h"]
    return E * (1.0 - nu) / ((1.0 + nu) * (1.0 - 2.0 * nu) * h)


def pressure_modulus(target, casting):
    """openfdk's pressure modulus (N/m³) of two layers in series: 1 / (h₁/K₁ + h₂/K₂)."""
    return 1.0 / (1.0 / layer_modulus(target) + 1.0 / layer_modulus(casting))


def contact_depth(force, target, casting):
    """openfdk's ``max_depth`` (m) of a Smith2018ArticularContactForce: its
    ``max_proximity``, but no deeper than the two layers together (h₁ + h₂). JAM's
    max_proximity is how far its rays search; a depth beyond the layers' total
    thickness would put the backing surfaces through each other (the non-linear law's
    pressure is infinite at the thickness), and the distance grid's band, built to that
    depth, costs in proportion (DM's femoral component: 20 mm → 10 mm)."""
    return min(force["max_proximity"], target["h"] + casting["h"])


def pressure_law(force, target, casting):
    """The ``contacts`` entry keys of the pressure law of a Smith2018ArticularContactForce
    record ``force`` between the mesh records ``target`` and ``casting`` (module
    docstring): ``{pressure_modulus}`` (linear) or ``{law: nonlinear, layers}``."""
    from ...contact.pressure_law import layer_modulus as confined

    def h(record, side):  # a layer's thickness: its number, or the side's field (variable)
        return side if record.get("variable") else record["h"]

    if force["lumped"]:  # OpenSim-JAM: mean E and ν, the thicknesses added
        E, nu = (target["E"] + casting["E"]) / 2, (target["nu"] + casting["nu"]) / 2
        parts = [h(casting, "vertices"), h(target, "surface")]
        layers = [(confined(E, nu), parts if any(isinstance(x, str) for x in parts) else sum(parts))]
    else:
        layers = [(confined(casting["E"], casting["nu"]), h(casting, "vertices")),
                  (confined(target["E"], target["nu"]), h(target, "surface"))]
    variable = any(isinstance(t, (str, list)) for _, t in layers)
    if force["formulation"] == "linear" and not variable:
        return {"pressure_modulus": 1.0 / sum(t / K for K, t in layers)}
    law = {"law": force["formulation"]} if force["formulation"] == "nonlinear" or variable else {}
    return {**law, "layers": [{"modulus": K, "thickness": t} for K, t in layers]}
