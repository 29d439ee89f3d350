"""OpenSim's IK tasks (``--ik-tasks FILE``): the IKTaskSet of a ``Setup_IK.xml``
(``<InverseKinematicsTool>``) or of a tasks ``.xml`` (``<IKTaskSet>``), as openfdk's
marker weights and coordinate tasks (:mod:`openfdk.model.tasks`).

* ``IKMarkerTask``: the marker's weight; ``apply`` false, or a model marker with no
  task, gives weight 0 (OpenSim's IK tracks only the markers of its task set).
* ``IKCoordinateTask`` with ``apply`` true: a task row q − f(t) with its ``weight``;
  ``value_type`` ``default_value`` (the coordinate's default), ``manual_value``
  (``value``, rad or m as OpenSim stores it) or ``from_file`` (the coordinate's column of
  the setup's ``coordinate_file``, a ``.mot``/``.sto``; degrees converted when the file
  says ``inDegrees=yes``), as a spline through the file's samples.

OpenSim's IK cost is Σ w_m |p_m − x_m|² + Σ w_q (q − f)²; openfdk's tracking minimises
½ Ψᵀ W Ψ over the same rows with the same weights, so both solve the same problem.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .document import in_degrees as opensim_in_degrees
from .document import parse_xml
from .errors import OsimError, where
from .functions import _NUMBER


def _number(task, tag, default, source):
    """The finite number of a task's <tag> (``default`` when absent), decimal as OpenSim
    writes it; errors name the file, the line and the task."""
    text = (task.findtext(tag) or default).strip()
    if not _NUMBER.match(text):
        raise OsimError(f"{where(source, task)}: <{tag}> is not a finite number: {text[:40]!r}")
    value = float(text)
    if not np.isfinite(value):
        raise OsimError(f"{where(source, task)}: <{tag}> is not a finite number: {text[:40]!r}")
    return value


def read_ik_tasks(path):
    """(marker weights {OpenSim marker name: weight}, coordinate tasks {coordinate:
    {weight, value_type, value, column (times, values) or None}}) of a setup or tasks
    file. Errors name the file, the line and the task."""
    path = Path(path)
    source = path.name
    root = parse_xml(path, source).getroot()
    tool = root.find(".//InverseKinematicsTool")
    taskset = root.find(".//IKTaskSet")
    if taskset is None:
        raise OsimError(f"{source}: line {root.sourceline}: no <IKTaskSet>: not an OpenSim IK setup or tasks file")
    coordinate_file = None
    if tool is not None:
        text = (tool.findtext("coordinate_file") or "").strip()
        if text and text.lower() != "unassigned":
            coordinate_file = path.parent / text
    objects = taskset.find("objects")
    markers, coords, seen = {}, {}, set()
    for task in (objects if objects is not None else taskset):
        if not isinstance(task.tag, str):
            continue
        name = task.get("name")
        if task.tag not in ("IKMarkerTask", "IKCoordinateTask"):
            raise OsimError(f"{where(source, task)}: not an IK task (IKMarkerTask or IKCoordinateTask)")
        if not name:
            raise OsimError(f"{where(source, task)}: a task without a name")
        if (task.tag, name) in seen:
            raise OsimError(f"{where(source, task)}: a second {task.tag} named {name!r}")
        seen.add((task.tag, name))
        apply = (task.findtext("apply") or "true").strip().lower()
        if apply not in ("true", "false"):
            raise OsimError(f"{where(source, task)}: <apply> must be true or false, got {apply!r}")
        weight = _number(task, "weight", "1", source)
        if weight < 0:
            raise OsimError(f"{where(source, task)}: <weight> must be >= 0, got {weight}")
        if task.tag == "IKMarkerTask":
            markers[name] = weight if apply == "true" else 0.0
            continue
        if apply != "true":
            continue
        kind = (task.findtext("value_type") or "default_value").strip()
        entry = {"weight": weight, "value_type": kind, "value": None, "line": task.sourceline}
        if kind == "manual_value":
            entry["value"] = _number(task, "value", "0", source)
        elif kind == "from_file":
            if coordinate_file is None:
                raise OsimError(f"{where(source, task)}: value_type from_file needs the setup's <coordinate_file>")
            entry["file"] = coordinate_file
        elif kind != "default_value":
            raise OsimError(f"{where(source, task)}: value_type {kind!r}: expected default_value, manual_value or "
                            "from_file")
        coords[name] = entry
    return markers, coords


def apply_ik_tasks(data, path, doc_coordinates, dropped=()):
    """The model mapping ``data`` (imported from an .osim) with the marker weights and
    coordinate tasks of the IK setup or tasks file ``path``. ``doc_coordinates``:
    {name: default (SI) and motion} of the model's coordinates. ``dropped``: the import's
    dropped elements ({type, name, line}); a marker task of a dropped marker (one fixed to
    the ground: a constant term of OpenSim's IK) is accepted and has nothing to weight."""
    from ..storage import read_storage
    from .motion import by_coordinate

    source = Path(path).name
    weights, tasks = read_ik_tasks(path)
    by_label = {}
    for body in data["bodies"].values():
        for mname, m in (body.get("markers") or {}).items():
            by_label[m.get("label", mname)] = m
    dropped_markers = {d["name"] for d in dropped if d["type"] == "Marker"}
    for name, weight in weights.items():  # a task that is off (apply false or weight 0) does nothing: not checked
        if weight > 0 and name not in by_label and name not in dropped_markers:
            raise OsimError(f"{source}: IKMarkerTask {name!r}: the model has no marker of that name")
    for label, m in by_label.items():
        m["weight"] = float(weights.get(label, 0.0))
    if by_label and not tasks and not any(m["weight"] > 0 for m in by_label.values()):
        raise OsimError(f"{source}: no marker is tracked: none of the model's {len(by_label)} markers has an "
                        "IKMarkerTask with <apply>true</apply> and a weight > 0 (OpenSim's IK tracks only the "
                        "markers its task set applies)")
    out = dict(data.get("tasks") or {})
    files = {}
    for name, t in tasks.items():
        if name not in doc_coordinates:
            raise OsimError(f"{source}: line {t['line']}: IKCoordinateTask {name!r}: the model has no coordinate of "
                            "that name")
        coord = doc_coordinates[name]
        if t["value_type"] == "default_value":
            value = coord["default"]
        elif t["value_type"] == "manual_value":
            value = t["value"]
        else:
            f = t["file"]
            if f not in files:
                try:
                    times, columns, in_degrees = read_storage(f)
                except ValueError as exc:
                    raise OsimError(f"{source}: coordinate_file: {exc}") from None
                # by name or by state path (/jointset/<joint>/<name>/value), as --motion reads them
                files[f] = (times, by_coordinate(columns, Path(f).name), in_degrees)
            times, columns, in_degrees = files[f]
            if name not in columns:
                raise OsimError(f"{source}: line {t['line']}: IKCoordinateTask {name!r}: {columns.absent(name)} in "
                                f"{Path(f).name}")
            values = columns[name]
            bad = np.flatnonzero(~np.isfinite(values))
            if len(bad) or len(times) < 6:
                problem = (f"the value at t = {times[bad[0]]:g} s is {values[bad[0]]}" if len(bad) else
                           f"{len(times)} rows; a coordinate task from a file needs at least 6 (OpenSim's "
                           "quintic spline)")
                raise OsimError(f"{source}: line {t['line']}: IKCoordinateTask {name!r}: column {name!r} of "
                                f"{Path(f).name}: {problem}")
            if in_degrees and opensim_in_degrees(coord):
                values = np.radians(values)
            # OpenSim's IK splines its coordinate file as its ID tool does: the natural quintic
            value = {"type": "gcv_spline", "degree": 5, "times": times.tolist(), "values": values.tolist()}
        out[name] = {"measure": name, "weight": t["weight"], "value": value}
    if out:
        data = dict(data)
        data["tasks"] = out
    return data
