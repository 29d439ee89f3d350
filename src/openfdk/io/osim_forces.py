"""openfdk's muscles and ligaments as OpenSim forces, for ``export-opensim``
(docs/opensim.md, "Muscles and ligaments").

* A Hill muscle (:class:`~openfdk.forces.hill.Hill3ElementMuscle`) becomes a
  ``Thelen2003Muscle`` — the inverse of the import's mapping
  (:data:`~openfdk.io.opensim.to_model.THELEN_TO_HILL`), with Af = 0.1 + 0.4·ff
  (Hill's curvature); a Millard muscle a ``Millard2012EquilibriumMuscle`` with every
  curve property written out.
* A ligament (:class:`~openfdk.forces.blankevoort.Blankevoort1991Ligament`) becomes a
  ``Blankevoort1991Ligament``: OpenSim's ``linear_stiffness`` is per unit strain
  (K = k·l0), its ``transition_strain`` ends the toe (twice openfdk's), its
  ``damping_coefficient`` is per unit strain rate (C = c·l0).
* Paths: each fixed point a ``PathPoint`` at its body-frame location; a conditional point
  a ``ConditionalPathPoint`` (range in the coordinate's SI unit); a moving point a
  ``MovingPathPoint`` with its three functions of the coordinate.

Not written, and reported in ``notes``: a muscle of another strength model (constant
strength), a path over wrapping surfaces (openfdk's surfaces have no exact OpenSim
twin here), a moving point whose function has no OpenSim class, a point on a coordinate
the export has no joint for.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import fields

import numpy as np

from .osim_functions import function_xml

#: Hill3ElementMuscle field -> Thelen2003Muscle property (Af separately)
HILL_TO_THELEN = {
    "max_isometric_force": "max_isometric_force", "optimal_fibre_length": "optimal_fiber_length",
    "tendon_slack_length": "tendon_slack_length", "pennation_angle_at_optimal": "pennation_angle_at_optimal",
    "max_contraction_velocity": "max_contraction_velocity", "tendon_strain_at_max_force": "FmaxTendonStrain",
    "passive_strain_at_max_force": "FmaxMuscleStrain", "force_length_width": "KshapeActive",
    "passive_shape_factor": "KshapePassive", "max_eccentric_force": "Flen",
}
#: the least min_control (and minimum_activation) OpenSim's Thelen2003Muscle accepts
THELEN_MIN_ACTIVATION = 0.01
#: MillardMuscle scalar field -> Millard2012EquilibriumMuscle property
MILLARD_SCALARS = {
    "max_isometric_force": "max_isometric_force", "optimal_fibre_length": "optimal_fiber_length",
    "tendon_slack_length": "tendon_slack_length", "pennation_angle_at_optimal": "pennation_angle_at_optimal",
    "max_contraction_velocity": "max_contraction_velocity", "maximum_pennation_angle": "maximum_pennation_angle",
    "fiber_damping": "fiber_damping", "ignore_tendon_compliance": "ignore_tendon_compliance",
    "minimum_activation": "minimum_activation",
}
#: MillardMuscle curve field -> Millard2012EquilibriumMuscle curve element
MILLARD_CURVES = {"active_force_length": "ActiveForceLengthCurve", "force_velocity": "ForceVelocityCurve",
                  "fibre_force_length": "FiberForceLengthCurve", "tendon_force_length": "TendonForceLengthCurve"}


def _sub(parent, tag, text=None, **attrib):
    el = ET.SubElement(parent, tag, attrib)
    if text is not None:
        el.text = text
    return el


def _text(value) -> str:
    if isinstance(value, (bool, np.bool_)):
        return "true" if value else "false"
    if np.ndim(value):
        return " ".join(repr(float(x)) for x in np.ravel(value))
    return repr(float(value))


def function_element(parent, tag_and_props, name=None):
    """``<Tag [name=…]><prop>text</prop>…</Tag>`` under ``parent``."""
    tag, props = tag_and_props
    el = _sub(parent, tag, **({"name": name} if name else {}))
    for key, text in props.items():
        _sub(el, key, text)
    return el


def _path(parent, element, model, frame_path, coordinate_path, problems):
    """The GeometryPath of ``element.points``; False (and a reason in ``problems``) when a
    point cannot be written."""
    gp = _sub(parent, "GeometryPath", name="path")
    objects = _sub(_sub(gp, "PathPointSet"), "objects")
    for k, entry in enumerate(element.points):
        if isinstance(entry, str) and "." not in entry:
            problems.append("path over wrapping surfaces")
            return False
        if isinstance(entry, str):
            f = model.frame(entry)
            pt = _sub(objects, "PathPoint", name=f"p{k + 1}")
            _sub(pt, "socket_parent_frame", frame_path(model.body(f.body).index))
            _sub(pt, "location", _text(f.p_BF))
            continue
        if "active" in entry:
            cname, lo, hi = entry["active"]
            f = model.frame(entry["point"])
            if cname not in coordinate_path:
                problems.append("conditional point on a coordinate without an exported joint")
                return False
            pt = _sub(objects, "ConditionalPathPoint", name=f"p{k + 1}")
            _sub(pt, "socket_parent_frame", frame_path(model.body(f.body).index))
            _sub(pt, "location", _text(f.p_BF))
            _sub(pt, "socket_coordinate", coordinate_path[cname])
            _sub(pt, "range", _text([lo, hi]))
            continue
        cname, fns = entry["moving"]
        f = model.frame(entry["frame"])
        if cname not in coordinate_path:
            problems.append("moving point on a coordinate without an exported joint")
            return False
        # the point is at R_BF·(f_x, f_y, f_z) + p_BF: OpenSim's location is in the
        # parent frame's axes, so the frame must be the body's axes
        if not np.allclose(f.R_BF, np.eye(3), atol=1e-15, rtol=0):
            problems.append("moving point in a rotated frame")
            return False
        pt = _sub(objects, "MovingPathPoint", name=f"p{k + 1}")
        _sub(pt, "socket_parent_frame", frame_path(model.body(f.body).index))
        for axis, fn, offset in zip("xyz", fns, f.p_BF):
            if isinstance(fn, (int, float)):
                xml = ("Constant", {"value": repr(float(fn) + float(offset))})
            else:
                xml = function_xml(_shifted(fn, offset) if offset else fn)
                if xml is None:
                    problems.append("moving point whose function has no OpenSim class")
                    return False
            _sub(pt, f"socket_{axis}_coordinate", coordinate_path[cname])
            function_element(_sub(pt, f"{axis}_location"), xml)
    return True


def _shifted(fn, offset):
    """f + offset (a PiecewisePolynomial)."""
    from ..model.coordinate_functions import PiecewisePolynomial

    c = np.array(fn.coeffs)
    left, right = np.array(fn.left), np.array(fn.right)
    if c.size:
        c[:, 0] += offset
    left[0] += offset
    right[0] += offset
    return PiecewisePolynomial(fn.breaks, c, left, right, fn.right_continuous)


def write_forces(forceset, model, frame_path, coordinate_path, exported=None):
    """Append the muscles and ligaments of ``model`` to ``forceset`` (the ``objects`` of
    the ForceSet), and the linear springs and coordinate actuators on exported
    coordinates (``SpringGeneralizedForce``, ``CoordinateActuator``; their names are
    added to the set ``exported``). frame_path(body index) -> OpenSim frame path;
    coordinate_path: {coordinate: "/jointset/<joint>/<coordinate>"}. Returns notes
    {kind: [names]}."""
    exported = set() if exported is None else exported
    from ..forces.hill import Hill3ElementMuscle
    from ..forces.millard import MillardMuscle

    notes = {}
    for mu in model.muscles:
        law = mu.law
        if not isinstance(law, (Hill3ElementMuscle, MillardMuscle)):
            notes.setdefault(f"not exported: muscle with a {type(law).__name__} (OpenSim has no such muscle)", []).append(mu.name)
            continue
        tag = "Thelen2003Muscle" if isinstance(law, Hill3ElementMuscle) else "Millard2012EquilibriumMuscle"
        el = ET.Element(tag, name=mu.name)
        _sub(el, "min_control", _text(mu.min_control))
        _sub(el, "max_control", _text(mu.max_control))
        problems = []
        if not _path(el, mu, model, frame_path, coordinate_path, problems):
            notes.setdefault(f"not exported: muscle with a {problems[0]}", []).append(mu.name)
            continue
        if tag == "Thelen2003Muscle":
            for ours, theirs in HILL_TO_THELEN.items():
                _sub(el, theirs, _text(getattr(law, ours)))
            _sub(el, "Af", _text(0.1 + 0.4 * law.fast_fibre_fraction))
            if mu.min_control < THELEN_MIN_ACTIVATION:
                el.find("min_control").text = _text(THELEN_MIN_ACTIVATION)
                notes.setdefault(f"approximated: muscle min_control below {THELEN_MIN_ACTIVATION} (written as "
                                 f"{THELEN_MIN_ACTIVATION}, Thelen2003Muscle's least)", []).append(mu.name)
        else:
            for ours, theirs in MILLARD_SCALARS.items():
                _sub(el, theirs, _text(getattr(law, ours)))
            if mu.min_control < law.minimum_activation:  # OpenSim: min_control >= minimum_activation
                el.find("min_control").text = _text(law.minimum_activation)
                notes.setdefault("approximated: muscle min_control below its minimum_activation (written as "
                                 "minimum_activation)", []).append(mu.name)
            for ours, theirs in MILLARD_CURVES.items():
                curve = getattr(law, ours)
                c = _sub(el, theirs, name=f"{mu.name}_{theirs}")
                for fld in fields(curve):
                    value = getattr(curve, fld.name)
                    if value is not None:
                        _sub(c, fld.name, _text(value))
        forceset.append(el)
    coordinate_of = {id(c.measure): c.name for c in model.coordinates if c.name in coordinate_path}
    for sp in model.springs:
        from ..forces.spring import LinearSpring

        q = coordinate_of.get(id(sp.measure))
        if q is None or type(sp.law) is not LinearSpring:
            continue  # named by model_notes
        el = ET.Element("SpringGeneralizedForce", name=sp.name)
        _sub(el, "coordinate", q)
        _sub(el, "stiffness", _text(sp.law.stiffness))       # f = −k (q − q_rest) − c q̇, as openfdk's
        _sub(el, "rest_length", _text(sp.law.rest_value))
        _sub(el, "viscosity", _text(sp.viscosity))
        forceset.append(el)
        exported.add(sp.name)
    for act in model.actuators:
        q = coordinate_of.get(id(getattr(act, "measure", None)))
        if q is None or not hasattr(act, "optimal_force"):
            continue
        el = ET.Element("CoordinateActuator", name=act.name)
        for key in ("min_control", "max_control"):
            v = float(getattr(act, key))
            _sub(el, key, ("-Inf" if v < 0 else "Inf") if np.isinf(v) else _text(v))
        _sub(el, "coordinate", q)
        _sub(el, "optimal_force", _text(act.optimal_force))
        forceset.append(el)
        exported.add(act.name)
    for lig in model.ligaments:
        law = lig.law
        el = ET.Element("Blankevoort1991Ligament", name=lig.name)
        problems = []
        if not _path(el, lig, model, frame_path, coordinate_path, problems):
            notes.setdefault(f"not exported: ligament with a {problems[0]}", []).append(lig.name)
            continue
        l0 = law.slack_length
        _sub(el, "linear_stiffness", _text(law.stiffness * l0))
        _sub(el, "transition_strain", _text(2.0 * law.transition_strain))
        _sub(el, "damping_coefficient", _text(law.damping * l0))
        _sub(el, "slack_length", _text(l0))
        if law.damping > 0.0 and law.damping_rule != "opensim":
            notes.setdefault("approximated: ligament damping with openfdk's rule (written with OpenSim's)", []).append(lig.name)
        forceset.append(el)
    return notes
