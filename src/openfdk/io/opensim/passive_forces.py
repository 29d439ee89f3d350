"""OpenSim's SpringGeneralizedForce: a generalised force −k (q − q_rest) − c q̇ on one
coordinate, read from a model's ForceSet into an entry of the model-file section
``springs`` (a linear spring with a parallel damper on the coordinate's measure,
:mod:`openfdk.forces.spring_forces`).

Read: ``coordinate``, ``stiffness`` (default 0), ``rest_length`` (default 0; rad or m,
the coordinate's unit), ``viscosity`` (default 0). Disabled ones (``appliesForce``
false, 3.x ``isDisabled`` true) are left out and listed.
"""

from __future__ import annotations

import math

from .actuators import _flag, _number, _text
from .errors import OsimError, where

PASSIVE_TYPES = ("SpringGeneralizedForce",)
_PROPERTIES = {"coordinate", "stiffness", "rest_length", "viscosity", "appliesForce", "isDisabled", "components"}


def read_spring(element, source):
    """(name, ``springs`` entry in OpenSim's terms) of a SpringGeneralizedForce, or
    (name, None) when it is disabled; errors name the file, the line and the force."""
    name = element.get("name") or ""
    label = f"SpringGeneralizedForce {name!r}"
    if not name:
        raise OsimError(f"{where(source, element)}: a SpringGeneralizedForce without a name")
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
