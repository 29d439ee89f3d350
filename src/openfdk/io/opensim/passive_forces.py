"""OpenSim's SpringGeneralizedForce (a generalised force −k (q − q_rest) − c q̇ on one
coordinate) CoordinateLimitForce (a coordinate's limit force, :mod:`openfdk.forces.limit_force`)
and ExpressionBasedCoordinateForce (f(q, qdot) parsed safely,
:mod:`openfdk.forces.expression_force`), read from a model's ForceSet into entries of the
model-file section ``springs`` (:mod:`openfdk.forces.spring_forces`).

Read: ``coordinate``, ``stiffness`` (default 0), ``rest_length`` (default 0; rad or m,
the coordinate's unit), ``viscosity`` (default 0). Disabled ones (``appliesForce``
false, 3.x ``isDisabled`` true) are left out and listed.
"""

from __future__ import annotations

import math

from .actuators import _flag, _number, _text
from .errors import OsimError, where

PASSIVE_TYPES = ("SpringGeneralizedForce", "CoordinateLimitForce", "ExpressionBasedCoordinateForce")
_LIMIT_PROPERTIES = {"coordinate", "upper_stiffness", "upper_limit", "lower_stiffness", "lower_limit", "damping",
                     "transition", "compute_dissipation_energy", "appliesForce", "isDisabled", "components"}
#: OpenSim 4.6's defaults of a CoordinateLimitForce
LIMIT_DEFAULTS = {"upper_stiffness": 1.0, "upper_limit": 0.0, "lower_stiffness": 1.0, "lower_limit": 0.0,
                  "damping": 0.001, "transition": 0.1}
_PROPERTIES = {"coordinate", "stiffness", "rest_length", "viscosity", "appliesForce", "isDisabled", "components"}


def read_spring(element, source):
    """(name, ``springs`` entry in OpenSim's terms) of a SpringGeneralizedForce or a
    CoordinateLimitForce, or (name, None) when it is disabled; errors name the file, the
    line and the force."""
    name = element.get("name") or ""
    label = f"{element.tag} {name!r}"
    if not name:
        raise OsimError(f"{where(source, element)}: a {element.tag} without a name")
    if element.tag == "CoordinateLimitForce":
        return name, _read_limit(element, source, label)
    if element.tag == "ExpressionBasedCoordinateForce":
        return name, _read_expression(element, source, label)
    for child in element:
        if isinstance(child.tag, str) and child.tag not in _PROPERTIES:
            raise OsimError(f"{where(source, child)}: {label}: property <{child.tag}> is not read by openfdk")
    if not _flag(element, "appliesForce", source, label, True) or _flag(element, "isDisabled", source, label, False):
        return name, None
    coordinate = _text(element, "coordinate")
    if not coordinate:
        raise OsimError(f"{where(source, element)}: {label}: no <coordinate>")
    entry = {"measure": coordinate}
    for tag, key in (("stiffness", "stiffness"), ("rest_length", "rest_value"), ("viscosity", "viscosity")):
        value = _number(element, tag, source, label, 0.0)
        if not math.isfinite(value) or (key != "rest_value" and value < 0.0):
            raise OsimError(f"{where(source, element)}: {label}: {tag} must be a finite number"
                            f"{' >= 0' if key != 'rest_value' else ''}, got {value:g}")
        entry[key] = value
    entry["line"] = element.sourceline
    return name, entry


def _read_limit(element, source, label):
    """The ``springs`` entry of a CoordinateLimitForce (or None when disabled), in
    OpenSim's units (degrees for a rotational coordinate; converted by add_springs)."""
    for child in element:
        if isinstance(child.tag, str) and child.tag not in _LIMIT_PROPERTIES:
            raise OsimError(f"{where(source, child)}: {label}: property <{child.tag}> is not read by openfdk")
    if not _flag(element, "appliesForce", source, label, True) or _flag(element, "isDisabled", source, label, False):
        return None
    coordinate = _text(element, "coordinate")
    if not coordinate:
        raise OsimError(f"{where(source, element)}: {label}: no <coordinate>")
    law = {key: _number(element, key, source, label, default) for key, default in LIMIT_DEFAULTS.items()}
    if law["upper_stiffness"] <= 0 or law["lower_stiffness"] <= 0 or law["transition"] <= 0 or law["damping"] < 0 \
            or law["lower_limit"] > law["upper_limit"]:
        raise OsimError(f"{where(source, element)}: {label}: stiffnesses and transition must be > 0, damping >= 0 "
                        f"and lower_limit <= upper_limit, got {law}")
    return {"measure": coordinate, "law": {"type": "coordinate_limit", **law}, "line": element.sourceline,
            "opensim_units": True}


def _read_expression(element, source, label):
    """The ``springs`` entry of an ExpressionBasedCoordinateForce (or None when
    disabled); the expression is checked here (parsed safely, never run as code)."""
    from ...forces.expression_force import parse_expression
    from ...forces.force_laws import ForceLawError

    for child in element:
        if isinstance(child.tag, str) and child.tag not in {"coordinate", "expression", "appliesForce", "isDisabled",
                                                            "components"}:
            raise OsimError(f"{where(source, child)}: {label}: property <{child.tag}> is not read by openfdk")
    if not _flag(element, "appliesForce", source, label, True) or _flag(element, "isDisabled", source, label, False):
        return None
    coordinate, expression = _text(element, "coordinate"), _text(element, "expression") or "0.0"
    if not coordinate:
        raise OsimError(f"{where(source, element)}: {label}: no <coordinate>")
    try:
        parse_expression(expression, "expression")
    except ForceLawError as exc:
        raise OsimError(f"{where(source, element)}: {label}: {exc}") from None
    return {"measure": coordinate, "law": {"type": "expression", "expression": expression}, "line": element.sourceline}


def add_springs(data, springs, source):
    """``data`` (a model mapping) with ``springs`` {OpenSim name: entry} added to its
    ``springs`` section; each must name a coordinate of the mapping."""
    from .to_model import safe_name

    out = dict(data)
    section = dict(out.get("springs") or {})
    coordinates = data.get("coordinates", {})
    for name, entry in springs.items():
        entry = dict(entry)
        line = entry.pop("line", None)
        if entry.pop("opensim_units", False) and entry["measure"] in coordinates:
            # OpenSim: a rotational coordinate's limits and transition in degrees, its
            # stiffnesses and damping per degree; openfdk's law is in rad
            from .document import in_degrees

            # (OpenSim's CoordinateLimitForce: its rotational coordinates only, not coupled ones)
            w = math.pi / 180.0 if in_degrees(coordinates[entry["measure"]]) else 1.0
            law = dict(entry["law"])
            for key in ("upper_limit", "lower_limit", "transition"):
                law[key] *= w
            for key in ("upper_stiffness", "lower_stiffness", "damping"):
                law[key] /= w
            entry["law"] = law
        if entry["measure"] not in coordinates:
            raise OsimError(f"{source}: line {line}: SpringGeneralizedForce {name!r}: unknown coordinate "
                            f"{entry['measure']!r}")
        safe = safe_name(name)
        if safe in section:
            raise OsimError(f"{source}: line {line}: SpringGeneralizedForce {name!r}: a spring named {safe!r} "
                            "exists already")
        section[safe] = entry
    if section:
        out["springs"] = section
    return out
