"""OpenSim's ExternalLoads (``--external-loads LOADS.xml``): each ExternalForce as an
entry of the model-file section ``external_loads`` (:mod:`openfdk.forces.data_load_section`),
applied exactly as OpenSim applies it:

* ``applied_to_body`` — the body the load acts on (a welded body: its merged body, with
  the welded body's frame);
* ``force_expressed_in_body`` / ``point_expressed_in_body`` — ``ground`` (world) or the
  applied body (its OpenSim frame, whose origin is the body origin, not the centre of
  mass); another body is refused by name;
* ``force_identifier``, ``point_identifier``, ``torque_identifier`` — column prefixes
  of the data file (``ground_force_v`` -> ``ground_force_vx``, ``…vy``, ``…vz``); an
  empty point applies the force at the body's origin, an empty torque is zero;
* ``datafile`` of the ExternalLoads (or each force's ``data_source_name`` when it names
  a file), a ``.mot``/``.sto`` relative to the XML file,
  read while importing: a file that cannot be read, or an identifier without its three
  columns, is an error naming the XML file, the line and the force.

Disabled forces (``isDisabled`` true, ``appliesForce`` false) are left out and listed;
these booleans read as the .osim reader reads them: ``true`` or ``false`` (any case), an
empty element the default, anything else an error naming the file, the line and the force.

Also refused, in one line naming the file, the line and the object: an ExternalForce
without a name (OpenSim refers to forces by name), and OpenSim's ``file="…"`` attribute
on any object of the file (OpenSim would read the object from that other file; openfdk
does not follow it: copy the object in). An element that is no property of the
ExternalLoads or of an ExternalForce in OpenSim 4.x (e.g. ``<units>``), which OpenSim
ignores without a word, is ignored with one warning naming the file and the elements.
"""

from __future__ import annotations

from pathlib import Path

from ...model.names import name_problem
from .document import parse_xml
from .errors import OsimError, where


#: the properties of an ExternalLoads (OpenSim 4.6: Component, ModelComponentSet) and
#: those OpenSim 3.x wrote (a Set's defaults, the load kinematics), which OpenSim 4.x
#: reads and ignores
EXTERNAL_LOADS_TAGS = frozenset({"components", "objects", "groups", "datafile", "defaults",
                                 "external_loads_model_kinematics_file", "lowpass_cutoff_frequency_for_load_kinematics"})
#: the properties of an ExternalForce (OpenSim 4.6), with the older isDisabled and the
#: socket spelling of applied_to_body, both read
EXTERNAL_FORCE_TAGS = frozenset({"components", "appliesForce", "isDisabled", "applied_to_body", "socket_applied_to_body",
                                 "force_expressed_in_body", "point_expressed_in_body", "force_identifier",
                                 "point_identifier", "torque_identifier", "data_source_name"})


def _text(element, tag):
    e = element.find(tag)
    return "" if e is None or e.text is None else e.text.strip()


def _bool(source, force, tag, default):
    """The boolean property ``tag`` of ``force``: ``true``/``false`` in any case (as the
    .osim reader reads them), ``default`` when absent or empty; OsimError otherwise."""
    text = _text(force, tag)
    if not text:
        return default
    if text.lower() not in ("true", "false"):
        raise OsimError(f"{where(source, force)}: <{tag}> must be true or false, got {text!r}")
    return text.lower() == "true"


def _check_structure(source, loads):
    """OsimError for a ``file`` attribute on any object of ``loads`` (the <ExternalLoads>
    element); one warning listing the elements that are no property of the ExternalLoads
    or of its ExternalForces (module docstring)."""
    for element in loads.iter():
        if isinstance(element.tag, str) and element.get("file") is not None:
            raise OsimError(f"{where(source, element)}: file={element.get('file')!r}: openfdk does not read objects "
                            f"from other files (OpenSim's file attribute); copy the object into {source}")
    unknown = [f"<{e.tag}> (line {e.sourceline})" for e in loads if isinstance(e.tag, str)
               and e.tag not in EXTERNAL_LOADS_TAGS]
    objects = loads.find("objects")
    for force in (objects if objects is not None else []):
        if isinstance(force.tag, str) and force.tag == "ExternalForce":
            unknown += [f"<{e.tag}> of ExternalForce {force.get('name')!r} (line {e.sourceline})" for e in force
                        if isinstance(e.tag, str) and e.tag not in EXTERNAL_FORCE_TAGS]
    if unknown:
        import warnings

        warnings.warn(f"{source}: {', '.join(unknown)}: not an OpenSim ExternalLoads or ExternalForce property, "
                      f"ignored (as OpenSim ignores it)")


def _data_columns(path, file, source, force, cache):
    """The column labels of the data file ``file`` (relative to the ExternalLoads file
    ``path``), read once; OsimError naming the XML file, the force and the data file."""
    from ..storage import read_storage

    p = path.parent / file
    if p not in cache:
        try:
            cache[p] = read_storage(p)[1]
        except ValueError as exc:
            raise OsimError(f"{where(source, force)}: data file {file!r}: {exc}") from None
    return cache[p]


def read_external_loads(path, data, info, cutoff_hz=None):
    """The model mapping ``data`` (an imported .osim) with the ExternalForces of
    ``path`` as its ``external_loads`` section; ``info`` is the import's info (body
    frames); ``cutoff_hz`` (Hz, > 0): each entry's low-pass (``cutoff_hz``,
    :mod:`openfdk.forces.load_filter`), None or 0: the data as given, as OpenSim applies
    them. Errors name the file, the line and the force."""
    path = Path(path)
    source = path.name
    root = parse_xml(path, source).getroot()
    loads = root if root.tag == "ExternalLoads" else root.find(".//ExternalLoads")
    if loads is None:
        raise OsimError(f"{source}: line {root.sourceline}: no <ExternalLoads>: not an OpenSim external loads file")
    _check_structure(source, loads)
    datafile = _text(loads, "datafile")
    objects = loads.find("objects")
    body_frames = info.get("body_frames", {})
    section = dict(data.get("external_loads") or {})
    bodies = data["bodies"]
    dropped = info.setdefault("dropped", [])
    files = {}
    for force in (objects if objects is not None else []):
        if not isinstance(force.tag, str):
            continue
        name = force.get("name") or ""
        if force.tag != "ExternalForce":
            raise OsimError(f"{where(source, force)}: not supported in an ExternalLoads file (ExternalForce only)")
        if not name.strip():
            raise OsimError(f"{where(source, force)}: no name (name=\"…\"): OpenSim refers to each ExternalForce "
                            f"by its name")
        disabled = _bool(source, force, "isDisabled", False) or not _bool(source, force, "appliesForce", True)
        if disabled:
            dropped.append({"type": "ExternalForce", "name": name, "line": force.sourceline})
            continue
        body = _text(force, "applied_to_body") or _text(force, "socket_applied_to_body")
        body = body.rstrip("/").split("/")[-1]
        if body not in body_frames or body == "ground":
            raise OsimError(f"{where(source, force)}: applied_to_body {body!r} is not a body of the model")
        frames = {}
        for key, tag in (("force_frame", "force_expressed_in_body"), ("point_frame", "point_expressed_in_body")):
            value = (_text(force, tag) or "ground").rstrip("/").split("/")[-1]
            if value == "ground":
                frames[key] = "world"
            elif value == body:
                frames[key] = "body"
            else:
                raise OsimError(f"{where(source, force)}: {tag} {value!r}: openfdk reads loads expressed in the ground "
                                f"or in the applied body {body!r}")
        file = datafile
        own = _text(force, "data_source_name")
        if own and own.lower() != "unassigned" and (path.parent / own).is_file():
            file = own
        if not file:
            raise OsimError(f"{where(source, force)}: no data file (<datafile> of the ExternalLoads)")
        columns = _data_columns(path, file, source, force, files)
        root_body, p, R = body_frames[body]
        frame_name = f"{body}_osim"
        bodies[root_body].setdefault("frames", {})[frame_name] = {"position": p, "orientation": {"matrix": R}}
        entry = {"body": root_body, "frame": f"{root_body}.{frame_name}", **frames,
                 "file": str((path.parent / file).resolve())}
        for key, tag in (("force", "force_identifier"), ("point", "point_identifier"),
                         ("torque", "torque_identifier")):
            prefix = _text(force, tag)
            if prefix:
                entry[key] = [f"{prefix}{c}" for c in "xyz"]
                missing = [c for c in entry[key] if c not in columns]
                if missing:
                    raise OsimError(f"{where(source, force)}: {tag} {prefix!r}: {columns.absent(missing[0])} in {file}")
        if "force" not in entry:
            raise OsimError(f"{where(source, force)}: no <force_identifier>")
        if "point" not in entry:
            entry["point_frame"] = "body"
        if cutoff_hz:
            entry["cutoff_hz"] = float(cutoff_hz)
        if name_problem(name):
            raise OsimError(f"{where(source, force)}: {name_problem(name)}")
        if name in section:
            raise OsimError(f"{where(source, force)}: a second external force named {name!r}")
        section[name] = entry
    if not section:
        raise OsimError(f"{source}: no ExternalForce applied")
    out = dict(data)
    out["external_loads"] = section
    return out
