"""OpenSim's CoordinateActuator: in a model's ForceSet, or in an actuator file
(``--actuators RESERVES.xml``, what a static-optimisation setup lists under
``force_set_files``), each becomes an entry of the model-file section ``actuators``
(:mod:`openfdk.forces.actuator_section`): a recruitment column weighted by its optimal
force, as in OpenSim's static optimisation.

Read: ``coordinate`` (by name), ``optimal_force`` (> 0), ``min_control`` and
``max_control`` (``-Inf``/``Inf``: no bound). Disabled actuators (``appliesForce``
false, or 3.x ``isDisabled`` true) are left out and listed, as OpenSim skips them.
"""

from __future__ import annotations

import math
from pathlib import Path

from .document import parse_xml
from .errors import OsimError, where

ACTUATOR_TYPES = ("CoordinateActuator",)
_KNOWN = {"coordinate", "optimal_force", "min_control", "max_control", "appliesForce", "isDisabled",
          "components", "Appearance"}


def _text(element, tag):
    e = element.find(tag)
    return None if e is None or e.text is None else e.text.strip()


def _number(element, tag, source, label, default):
    text = _text(element, tag)
    if text is None or text == "":
        return default
    try:
        value = float(text)
    except ValueError:
        raise OsimError(f"{where(source, element.find(tag))}: {label}: <{tag}> expected a number, got {text!r}") \
            from None
    if math.isnan(value):
        raise OsimError(f"{where(source, element.find(tag))}: {label}: <{tag}> is NaN")
    return value


def read_coordinate_actuator(element, source):
    """(name, entry of the ``actuators`` section) of a <CoordinateActuator>, or (name,
    None) when it is disabled. Errors name the file, the line and the actuator."""
    name = element.get("name") or ""
    label = f"CoordinateActuator {name!r}"
    if not name:
        raise OsimError(f"{where(source, element)}: a CoordinateActuator without a name")
    for child in element:
        if isinstance(child.tag, str) and child.tag not in _KNOWN:
            raise OsimError(f"{where(source, child)}: {label}: property <{child.tag}> is not read by openfdk")
    if (_text(element, "appliesForce") or "true").lower() == "false" or \
            (_text(element, "isDisabled") or "false").lower() == "true":
        return name, None
    coordinate = _text(element, "coordinate")
    if not coordinate:
        raise OsimError(f"{where(source, element)}: {label}: no <coordinate>")
    force = _number(element, "optimal_force", source, label, 1.0)
    if not (0.0 < force < math.inf):
        raise OsimError(f"{where(source, element)}: {label}: optimal_force must be a positive number, got {force:g}")
    entry = {"coordinate": coordinate, "optimal_force": force}
    low = _number(element, "min_control", source, label, -math.inf)
    high = _number(element, "max_control", source, label, math.inf)
    if low > 0.0 or high < 0.0 or low >= high:
        raise OsimError(f"{where(source, element)}: {label}: controls [{low:g}, {high:g}] must contain 0 and be an "
                        "interval (openfdk recruits an actuator from rest)")
    if math.isfinite(low):
        entry["min_control"] = low
    if math.isfinite(high):
        entry["max_control"] = high
    return name, entry


def add_actuators(data, actuators, coordinates, source):
    """``data`` (a model mapping) with ``actuators`` {OpenSim name: entry} added to its
    ``actuators`` section; each must act on a coordinate of ``coordinates`` (the
    mapping's ``coordinates`` section) and have a new name."""
    from .to_model import safe_name

    out = dict(data)
    section = dict(out.get("actuators") or {})
    for name, entry in actuators.items():
        if entry["coordinate"] not in coordinates:
            raise OsimError(f"{source}: CoordinateActuator {name!r}: unknown coordinate {entry['coordinate']!r}")
        safe = safe_name(name)
        if safe in section:
            raise OsimError(f"{source}: CoordinateActuator {name!r}: an actuator named {safe!r} exists already")
        section[safe] = entry
    if section:
        out["actuators"] = section
    return out


def read_actuator_file(path, data, info):
    """``data`` (an imported .osim's mapping) with the CoordinateActuators of the actuator
    file ``path`` (an OpenSim ForceSet document); other forces are refused by name, and
    disabled actuators listed in ``info["dropped"]``."""
    path = Path(path)
    source = path.name
    root = parse_xml(path, source).getroot()
    sets = [root] if root.tag == "ForceSet" else root.findall(".//ForceSet")
    if not sets:
        raise OsimError(f"{source}: no <ForceSet> (an OpenSim actuator file holds a ForceSet of actuators)")
    found = {}
    for force_set in sets:
        objects = force_set.find("objects")
        for e in (objects if objects is not None else force_set):
            if not isinstance(e.tag, str) or e.tag in ("groups", "objects"):
                continue
            if e.tag not in ACTUATOR_TYPES:
                raise OsimError(f"{where(source, e)}: {e.tag} {e.get('name') or ''!r}: openfdk reads "
                                f"{', '.join(ACTUATOR_TYPES)} from an actuator file")
            name, entry = read_coordinate_actuator(e, source)
            if entry is None:
                info.setdefault("dropped", []).append({"type": e.tag, "name": name, "line": e.sourceline,
                                                       "file": source})
            elif name in found:
                raise OsimError(f"{where(source, e)}: CoordinateActuator {name!r} is defined twice")
            else:
                found[name] = entry
    return add_actuators(data, found, data.get("coordinates", {}), source)
