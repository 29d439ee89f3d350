"""OpenSim's CoordinateActuator, PointActuator and TorqueActuator: in a model's ForceSet,
or in an actuator file (``--actuators RESERVES.xml``, what a static-optimisation setup
lists under ``force_set_files``, e.g. Gait2392's residual actuators FX…MZ), each becomes
an entry of the model-file section ``actuators`` (:mod:`openfdk.forces.actuator_section`):
a recruitment column weighted by its optimal force, as in OpenSim's static optimisation.

Read: ``optimal_force`` (> 0), ``min_control`` and ``max_control`` (``-Inf``/``Inf``: no
bound); a CoordinateActuator's ``coordinate``; a PointActuator's ``body``, ``point``,
``point_is_global``, ``direction``, ``force_is_global``; a TorqueActuator's ``bodyA``
(gets the torque), ``bodyB`` (the opposite torque), ``axis``, ``torque_is_global``.
Vectors in an OpenSim body's frame are turned into the openfdk body's frame (a welded
body is part of another; openfdk's body origin is the centre of mass). Disabled
actuators (``appliesForce`` false, or 3.x ``isDisabled`` true) are left out and listed,
as OpenSim skips them.
"""

from __future__ import annotations

import math
from pathlib import Path

from .document import parse_xml
from .errors import OsimError, where

ACTUATOR_TYPES = ("CoordinateActuator", "PointActuator", "TorqueActuator")
_COMMON = {"optimal_force", "min_control", "max_control", "appliesForce", "isDisabled", "components", "Appearance"}
_PROPERTIES = {"CoordinateActuator": _COMMON | {"coordinate"},
               "PointActuator": _COMMON | {"body", "point", "point_is_global", "direction", "force_is_global"},
               "TorqueActuator": _COMMON | {"bodyA", "bodyB", "axis", "torque_is_global"}}


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


def _vector(element, tag, source, label, default=None):
    text = _text(element, tag)
    if not text:
        if default is None:
            raise OsimError(f"{where(source, element)}: no <{tag}>")
        return list(default)
    try:
        v = [float(x) for x in text.split()]
    except ValueError:
        v = []
    if len(v) != 3 or not all(math.isfinite(x) for x in v):
        raise OsimError(f"{where(source, element.find(tag))}: {label}: <{tag}> expected 3 finite numbers, "
                        f"got {text!r}")
    return v


def _flag(element, tag, source, label, default):
    text = (_text(element, tag) or "").lower()
    if text == "":
        return default
    if text not in ("true", "false"):
        raise OsimError(f"{where(source, element.find(tag))}: {label}: <{tag}> must be true or false, got {text!r}")
    return text == "true"


def _body_name(element, tag, source, label, default=None):
    text = _text(element, tag) or default
    if not text:
        raise OsimError(f"{where(source, element)}: no <{tag}>")
    return text.rstrip("/").split("/")[-1]  # a 4.x path '/bodyset/pelvis' or a name


def read_actuator(element, source):
    """(name, entry) of an OpenSim actuator (ACTUATOR_TYPES) in OpenSim's terms (bodies by
    OpenSim name, vectors in OpenSim body frames), or (name, None) when it is disabled.
    Errors name the file, the line and the actuator."""
    kind = element.tag
    name = element.get("name") or ""
    label = f"{kind} {name!r}"
    if not name:
        raise OsimError(f"{where(source, element)}: a {kind} without a name")
    for child in element:
        if isinstance(child.tag, str) and child.tag not in _PROPERTIES[kind]:
            raise OsimError(f"{where(source, child)}: {label}: property <{child.tag}> is not read by openfdk")
    if not _flag(element, "appliesForce", source, label, True) or _flag(element, "isDisabled", source, label, False):
        return name, None
    force = _number(element, "optimal_force", source, label, 1.0)
    if not (0.0 < force < math.inf):
        raise OsimError(f"{where(source, element)}: optimal_force must be a positive number, got {force:g}")
    low = _number(element, "min_control", source, label, -math.inf)
    high = _number(element, "max_control", source, label, math.inf)
    if low > 0.0 or high < 0.0 or low >= high:
        raise OsimError(f"{where(source, element)}: controls [{low:g}, {high:g}] must contain 0 and be an "
                        "interval (openfdk recruits an actuator from rest)")
    entry = {"optimal_force": force}
    if math.isfinite(low):
        entry["min_control"] = low
    if math.isfinite(high):
        entry["max_control"] = high
    if kind == "CoordinateActuator":
        coordinate = _text(element, "coordinate")
        if not coordinate:
            raise OsimError(f"{where(source, element)}: no <coordinate>")
        entry["coordinate"] = coordinate
    elif kind == "PointActuator":
        entry.update(type="point", body=_body_name(element, "body", source, label),
                     point=_vector(element, "point", source, label, (0.0, 0.0, 0.0)),
                     point_frame="world" if _flag(element, "point_is_global", source, label, False) else "body",
                     direction=_vector(element, "direction", source, label),
                     direction_frame="world" if _flag(element, "force_is_global", source, label, False) else "body")
    else:
        entry.update(type="torque", body=_body_name(element, "bodyA", source, label),
                     reaction_body=_body_name(element, "bodyB", source, label, "ground"),
                     axis=_vector(element, "axis", source, label),
                     axis_frame="world" if _flag(element, "torque_is_global", source, label, True) else "body")
    if "direction" in entry and not any(entry["direction"]) or "axis" in entry and not any(entry["axis"]):
        raise OsimError(f"{where(source, element)}: a zero direction")
    entry["line"] = element.sourceline
    return name, entry


def add_actuators(data, actuators, body_frames, source):
    """``data`` (a model mapping) with ``actuators`` {OpenSim name: entry of
    :func:`read_actuator`} added to its ``actuators`` section, in openfdk's terms: bodies
    by their openfdk body (a welded body: the body it is merged into) and vectors given
    in an OpenSim body's frame turned into that body's frame (``body_frames``: OpenSim
    body -> (openfdk body, p (3,) m, R (3, 3)), the import's info). Each must act on a
    coordinate or bodies of the model and have a new name."""
    import numpy as np

    from .to_model import safe_name

    out = dict(data)
    section = dict(out.get("actuators") or {})
    coordinates = data.get("coordinates", {})
    for name, entry in actuators.items():
        entry = dict(entry)
        line = entry.pop("line", None)
        kind = {"point": "PointActuator", "torque": "TorqueActuator"}.get(entry.get("type"), "CoordinateActuator")
        label = f"{source}: line {line}: {kind} {name!r}"

        def frame_of(osim_body):
            if osim_body not in body_frames:
                raise OsimError(f"{label}: unknown body {osim_body!r}")
            body, p, R = body_frames[osim_body]
            return body, np.asarray(p, float), np.asarray(R, float)

        if "coordinate" in entry:
            if entry["coordinate"] not in coordinates:
                raise OsimError(f"{label}: unknown coordinate {entry['coordinate']!r}")
        elif entry["type"] == "point":
            body, p, R = frame_of(entry["body"])
            if body == "ground":
                raise OsimError(f"{label}: a force on the ground does nothing")
            entry["body"] = body
            if entry["point_frame"] == "body":
                entry["point"] = (p + R @ np.asarray(entry["point"], float)).tolist()
            if entry["direction_frame"] == "body":
                entry["direction"] = (R @ np.asarray(entry["direction"], float)).tolist()
        else:
            body, _, R = frame_of(entry["body"])
            other = frame_of(entry["reaction_body"])[0]
            if body == other:
                raise OsimError(f"{label}: bodyA and bodyB are the same body")
            if body == "ground":  # the torque on the ground is the reaction: swap, opposite axis
                body, other, entry["axis"] = other, body, [-x for x in entry["axis"]]
                if entry["axis_frame"] == "body":
                    raise OsimError(f"{label}: an axis in the ground's frame with bodyA the ground: give "
                                    "torque_is_global true")
            elif entry["axis_frame"] == "body":
                entry["axis"] = (R @ np.asarray(entry["axis"], float)).tolist()
            entry["body"], entry["reaction_body"] = body, other
        safe = safe_name(name)
        if safe in section:
            raise OsimError(f"{label}: an actuator named {safe!r} exists already")
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
            name, entry = read_actuator(e, source)
            if entry is None:
                info.setdefault("dropped", []).append({"type": e.tag, "name": name, "line": e.sourceline,
                                                       "file": source})
            elif name in found:
                raise OsimError(f"{where(source, e)}: {e.tag} {name!r} is defined twice")
            else:
                found[name] = entry
    return add_actuators(data, found, info.get("body_frames", {}), source)
