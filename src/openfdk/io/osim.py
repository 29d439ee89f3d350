"""Export a run to OpenSim: an ``.osim`` model and a ``.mot`` motion that plays the run.

``openfdk export-opensim RESULT_DIR --out DIR`` writes into DIR (docs/opensim.md):

* ``<model>.osim`` — an OpenSim 4 model (``OpenSimDocument Version="40000"``): every
  openfdk body is an OpenSim ``Body`` whose frame is openfdk's body frame (origin at the
  centre of mass, so ``mass_center`` is 0), inertia about the centre of mass in that
  frame; the joints as an OpenSim tree with their coordinates, loop-closing welds and
  spherical joints and couplers as constraints (:mod:`.osim_joints`); the markers as a
  ``MarkerSet``; muscles and ligaments with their paths (:mod:`.osim_forces`); the
  contact meshes and the bodies' visual meshes as ``Mesh`` geometry
  (``Geometry/<contact>_<side>.obj``, ``Geometry/<body>_visual_<k>.obj``, vertices in the
  body frame, metres). openfdk's ground (body 0, world frame W) is OpenSim's ``ground``.
* ``<model>.mot`` — the joint coordinates over time, from the run's body poses (rad, m;
  angles unwrapped over time so that OpenSim's interpolation does not jump by 2π).

What OpenSim cannot hold is returned as ``notes`` {element kind: [names]} and printed one
line per kind (:func:`note_lines`). Frames whose kinematics failed are left out of the
``.mot`` (their poses are not solutions); the header says how many and which. Nothing
here needs OpenSim: the files are written from the format's documentation.
"""

from __future__ import annotations

import os
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from ..numerics.spatial import rotation_matrix, xyz_angles_from_matrix
from .osim_forces import function_element
from .storage import write_storage

__all__ = ["OSIM_VERSION", "FREE_COORDINATES", "build_osim", "export_model", "export_opensim",
           "free_joint_coordinates", "note_lines", "opensim_frame_path"]

OSIM_VERSION = "40000"
#: FreeJoint coordinate suffixes, in OpenSim's order
FREE_COORDINATES = ("rx", "ry", "rz", "tx", "ty", "tz")
GEOMETRY_DIR = "Geometry"


def opensim_frame_path(model, index: int) -> str:
    """OpenSim path of openfdk body ``index``: ``/ground`` for the ground (body 0),
    ``/bodyset/<name>`` otherwise."""
    return "/ground" if index == 0 else f"/bodyset/{model.bodies[index].name}"


def free_joint_coordinates(p_WB, quat_WB):
    """FreeJoint coordinates of body poses.

    Args: p_WB ``(n, 3) m`` centre-of-mass positions in world; quat_WB ``(n, 4)`` unit
    quaternions (scalar first).
    Returns: ``(n, 6)`` [rx, ry, rz (rad, body-fixed X-Y-Z, unwrapped along n), tx, ty, tz (m)];
    rows with a non-finite pose are NaN.
    """
    p_WB, quat_WB = np.atleast_2d(p_WB), np.atleast_2d(quat_WB)
    out = np.full((len(p_WB), 6), np.nan)
    for i, (p, q) in enumerate(zip(p_WB, quat_WB)):
        if np.all(np.isfinite(p)) and np.all(np.isfinite(q)):
            out[i, :3] = xyz_angles_from_matrix(rotation_matrix(q / np.linalg.norm(q)))
            out[i, 3:] = p
    ok = np.all(np.isfinite(out), axis=1)
    if ok.any():
        out[ok, :3] = np.unwrap(out[ok, :3], axis=0)
    return out


def _sub(parent, tag, text=None, **attrib):
    el = ET.SubElement(parent, tag, attrib)
    if text is not None:
        el.text = text
    return el


def _vec(values) -> str:
    return " ".join(repr(float(x)) for x in values)


def _write_obj(path, vertices, faces, comment):
    """Wavefront OBJ: ``v x y z`` lines (m) then ``f i j k`` (1-based)."""
    lines = [f"# {comment}"]
    lines += [f"v {_vec(v)}" for v in vertices]
    lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in np.asarray(faces, dtype=int)]
    from .outdir import refuse_link, write_new_file

    refuse_link(path.parent)
    refuse_link(path)
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    write_new_file(tmp, ("\n".join(lines) + "\n").encode())
    os.replace(tmp, path)


def _geometry_path(out_dir, fname):
    """``out_dir/Geometry/fname``; ValueError when ``fname`` (made of model names) is not a
    plain file name (a '/', '..' or control character would leave the output folder)."""
    from ..model.names import name_problem

    problem = name_problem(fname)
    if problem or Path(fname).name != fname:
        raise ValueError(f"cannot export mesh file {fname!r}: {problem or 'not a plain file name'}")
    return out_dir / GEOMETRY_DIR / fname


def _check_exported_names(model):
    """ValueError naming the model and the item when a name written to the ``.osim`` (a
    body, a contact, a marker's label) is not safe in XML and file names — a Model made
    without the builder (whose ``build`` checks them) could carry one."""
    from ..model.names import label_problem, name_problem

    named = [("body", b.name) for b in model.bodies] + [("contact", c.name) for c in getattr(model, "contacts", ())]
    for what, name in named:
        if name_problem(name):
            raise ValueError(f"model {model.name!r}: {what} {name_problem(name)}")
    for label in model.markers.labels:
        if label_problem(label):
            raise ValueError(f"model {model.name!r}: marker {label_problem(label)}")


def _geometry(model, out_dir):
    """Write the contact meshes and the bodies' visual meshes (model-file ``visual:``
    entries) in their body frames; returns body index -> [(geometry name, file, colour)]."""
    attached = {}
    contacts = model.contacts
    visuals = model.visuals
    if contacts or visuals:
        (out_dir / GEOMETRY_DIR).mkdir(parents=True, exist_ok=True)
    for c in contacts:
        for side, body, surface in (("vertices", c.body_a, c.pair.surface_A), ("surface", c.body_b, c.pair.surface_B)):
            fname = f"{c.name}_{side}.obj"
            _write_obj(_geometry_path(out_dir, fname), surface.vertices_B, surface.faces,
                       f"openfdk contact {c.name!r} {side} mesh ({surface.name}), body "
                       f"{model.bodies[body].name!r} frame, metres")
            attached.setdefault(body, []).append((f"{c.name}_{side}", f"{GEOMETRY_DIR}/{fname}", ""))
    if visuals:
        from ..model.visuals import visual_mesh_B

    for k, v in enumerate(visuals):
        vertices_B, faces = visual_mesh_B(v)   # .stl/.vtp/.obj/.ply file -> body frame, m (units, scale, placement)
        body = model.body(v.body).index
        fname = f"{v.body}_visual_{k}.obj"
        _write_obj(_geometry_path(out_dir, fname), vertices_B, faces,
                   f"openfdk visual mesh {v.entry} ({Path(v.path).name}), body {v.body!r} frame, metres")
        attached.setdefault(body, []).append((f"{v.body}_visual_{k}", f"{GEOMETRY_DIR}/{fname}", v.color))
    return attached


def _coordinate(parent, c, value):
    """A ``Coordinate`` (OsimCoordinate ``c``) with default ``value`` (rad or m)."""
    el = _sub(parent, "Coordinate", name=c.name)
    _sub(el, "default_value", repr(float(value)))
    _sub(el, "default_speed_value", "0")
    lo, hi = c.range if c.range is not None else ((-np.pi, np.pi) if c.motion != "translational" else (-10.0, 10.0))
    lo, hi = min(lo, float(value)), max(hi, float(value))
    _sub(el, "range", _vec([lo, hi]))
    _sub(el, "clamped", "true" if c.clamped else "false")
    _sub(el, "locked", "true" if c.locked else "false")
    if c.prescribed is not None:
        from .osim_functions import function_xml

        xml = function_xml(c.prescribed)
        if xml is not None:
            _sub(el, "prescribed", "true")
            function_element(_sub(el, "prescribed_function"), xml)
    return el


def _attach(frame_element, geoms):
    """``attached_geometry`` Mesh entries (name, file, colour) on a Ground or Body element."""
    if not geoms:
        return
    ag = _sub(frame_element, "attached_geometry")
    for gname, fname, color in geoms:
        mesh = _sub(ag, "Mesh", name=gname)
        _sub(mesh, "socket_frame", "..")
        _sub(mesh, "scale_factors", "1 1 1")
        if color:  # "#rrggbb" -> OpenSim's r g b in [0, 1]
            _sub(_sub(mesh, "Appearance"), "color", " ".join(f"{int(color[i:i + 2], 16) / 255:.6g}" for i in (1, 3, 5)))
        _sub(mesh, "mesh_file", fname)


def _offset_frame(frames, name, parent_path, p, R):
    f = _sub(frames, "PhysicalOffsetFrame", name=name)
    _sub(f, "socket_parent", parent_path)
    _sub(f, "translation", _vec(p))
    _sub(f, "orientation", _vec(xyz_angles_from_matrix(R)))  # body-fixed X-Y-Z (OpenSim's OffsetFrame)


def _joint(jointset, model, j, defaults):
    el = _sub(jointset, j.kind, name=j.name)
    names = ("parent_offset", "child_offset")
    _sub(el, "socket_parent_frame", names[0])
    _sub(el, "socket_child_frame", names[1])
    if j.coordinates:
        coords = _sub(el, "coordinates")
        for c in j.coordinates:
            _coordinate(coords, c, defaults[c.name])
    frames = _sub(el, "frames")
    _offset_frame(frames, names[0], opensim_frame_path(model, j.parent), j.p_PF, j.R_PF)
    _offset_frame(frames, names[1], opensim_frame_path(model, j.child), j.p_CM, j.R_CM)
    if j.kind == "CustomJoint":
        st = _sub(el, "SpatialTransform")
        labels = ("rotation1", "rotation2", "rotation3", "translation1", "translation2", "translation3")
        for label, (axis, q, xml) in zip(labels, j.axes):
            ta = _sub(st, "TransformAxis", name=label)
            _sub(ta, "coordinates", q or "")
            _sub(ta, "axis", _vec(axis))
            function_element(ta, xml, name="function")


def _constraint(constraintset, model, c):
    el = _sub(constraintset, c.kind, name=c.name)
    if c.kind == "WeldConstraint":
        _sub(el, "socket_frame1", "frame1")
        _sub(el, "socket_frame2", "frame2")
        frames = _sub(el, "frames")
        for k in range(2):
            _offset_frame(frames, f"frame{k + 1}", opensim_frame_path(model, c.bodies[k]), c.p[k], c.R[k])
    elif c.kind == "PointConstraint":
        for k in range(2):
            _sub(el, f"socket_body_{k + 1}", opensim_frame_path(model, c.bodies[k]))
        for k in range(2):
            _sub(el, f"location_body_{k + 1}", _vec(c.p[k]))
    else:  # CoordinateCouplerConstraint
        function_element(_sub(el, "coupled_coordinates_function"), c.function)
        _sub(el, "independent_coordinate_names", c.independent)
        _sub(el, "dependent_coordinate_name", c.dependent)


def model_notes(model, exported=()):
    """{element kind: [names]} of the model's elements that have no OpenSim twin in the
    export (besides those :func:`~openfdk.io.osim_joints.plan_joints` and
    :func:`~openfdk.io.osim_forces.write_forces` report)."""
    notes = {}
    generated = {f"{c.name}_locked" for c in model.coordinates} | {f"{c.name}_prescribed" for c in model.coordinates}
    for c in model.constraints:
        if c.name in generated:
            continue
        if c.joint_type == "generic":
            notes.setdefault("not exported: constraint on an openfdk measure", []).append(c.name)
        elif c.joint_type == "driver":
            notes.setdefault("not exported: driver (its motion is in the .mot)", []).append(c.name)
    from_rows = {f"{r.name}_{label}" for r in model.joints for label in r.fdk_rows}
    for d in model.fdk_dofs:
        if d.name not in from_rows:
            notes.setdefault("not exported: FDK DOF on an openfdk measure (no coordinate)", []).append(d.name)
    for kind in ("springs", "unilateral_reactions", "loads", "external_loads", "actuators", "tasks"):
        for e in (e for e in getattr(model, kind, ()) if getattr(e, "name", None) not in exported):
            notes.setdefault(f"not exported: {kind.replace('_', ' ').rstrip('s')}", []).append(getattr(e, "name", "?"))
    for c in model.contacts:
        notes.setdefault("not exported: contact force (its meshes are exported as geometry)", []).append(c.name)
    return notes


def build_osim(model, state0=None, geometry=None):
    """(``.osim`` document, exported joints, notes {kind: [names]}) of ``model``.

    state0: BodyStates whose coordinates are the defaults (default: the reference pose);
    geometry: body index -> [(geometry name, mesh file relative to the .osim, "#rrggbb" or "")]."""
    from .osim_forces import write_forces
    from .osim_joints import joint_coordinates, plan_joints

    joints, constraints, notes = plan_joints(model)
    state0 = state0 if state0 is not None else model.initial_state()
    defaults = joint_coordinates(joints, state0)
    doc = ET.Element("OpenSimDocument", Version=OSIM_VERSION)
    m = _sub(doc, "Model", name=_file_stem(model.name))  # OpenSim names: no spaces, \ * + / or tabs
    _sub(m, "credits", "Exported by openfdk (export-opensim); see docs/opensim.md")
    _sub(m, "length_units", "meters")
    _sub(m, "force_units", "N")
    _sub(m, "gravity", _vec(model.gravity_W))
    attached = geometry or {}
    ground = _sub(m, "Ground", name="ground")
    _attach(ground, attached.get(0, []))
    bodyset = _sub(_sub(m, "BodySet", name="bodyset"), "objects")
    for b in model.bodies[1:]:
        body = _sub(bodyset, "Body", name=b.name)
        _attach(body, attached.get(b.index, []))
        J = np.asarray(b.inertia_B, dtype=float)
        _sub(body, "mass", repr(float(b.mass)))
        _sub(body, "mass_center", "0 0 0")
        # OpenSim's order: Ixx Iyy Izz Ixy Ixz Iyz (about the centre of mass, body frame)
        _sub(body, "inertia", _vec([J[0, 0], J[1, 1], J[2, 2], J[0, 1], J[0, 2], J[1, 2]]))
    jointset = _sub(_sub(m, "JointSet", name="jointset"), "objects")
    for j in joints:
        _joint(jointset, model, j, defaults)
    if constraints:
        cset = _sub(_sub(m, "ConstraintSet", name="constraintset"), "objects")
        for c in constraints:
            _constraint(cset, model, c)
    coordinate_path = {c.name: f"/jointset/{j.name}/{c.name}" for j in joints for c in j.coordinates}
    forces = ET.Element("objects")
    exported = set()
    for kind, names in write_forces(forces, model, lambda i: opensim_frame_path(model, i), coordinate_path,
                                    exported).items():
        notes.setdefault(kind, []).extend(names)
    if len(forces):
        _sub(m, "ForceSet", name="forceset").append(forces)
    markerset = _sub(_sub(m, "MarkerSet", name="markerset"), "objects")
    mk = model.markers
    for j in range(mk.size):
        marker = _sub(markerset, "Marker", name=mk.labels[j])
        _sub(marker, "socket_parent_frame", opensim_frame_path(model, int(mk.body[j])))
        _sub(marker, "location", _vec(mk.p_BM[j]))
        _sub(marker, "fixed", "false")
    for kind, names in model_notes(model, exported).items():
        notes.setdefault(kind, []).extend(names)
    ET.indent(doc, space="  ")
    return ET.ElementTree(doc), joints, notes


def note_lines(notes):
    """One line per element kind: ``not exported: <kind> (n): name, name, …`` (or
    ``approximated: …`` for an element written in a nearby form)."""
    lines = []
    for kind, names in notes.items():
        shown = ", ".join(names[:8]) + (f", … ({len(names) - 8} more)" if len(names) > 8 else "")
        lines.append(f"{kind} ({len(names)}): {shown}")
    return lines


def _write_tree(tree, path):
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    tree.write(tmp, encoding="UTF-8", xml_declaration=True)
    os.replace(tmp, path)


def export_model(model, out_dir) -> dict:
    """Write ``<name>.osim`` (and ``Geometry/*.obj``) of ``model`` at its reference pose.
    Returns dict ``osim`` (path), ``geometry`` (paths), ``notes`` ({kind: [names]})."""
    _check_exported_names(model)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    geometry = _geometry(model, out)
    tree, _, notes = build_osim(model, None, geometry)
    path = out / f"{_file_stem(model.name)}.osim"
    _write_tree(tree, path)
    return {"osim": path, "notes": notes,
            "geometry": sorted((out / GEOMETRY_DIR).glob("*.obj")) if geometry else []}


def export_opensim(results, out_dir, model=None) -> dict:
    """Write ``<name>.osim``, ``<name>.mot`` and ``Geometry/*.obj`` for a run.

    Args:
        results: a :class:`~openfdk.results.run.RunResults` or a result folder.
        out_dir: output folder (created).
        model: the analysed Model (default: the one the run recorded, see
            :meth:`RunResults.model`).
    Returns: dict with keys ``osim``, ``mot`` (paths), ``geometry`` (list of paths),
    ``frames`` (rows written), ``skipped_frames`` (indices of failed frames left out) and
    ``notes`` ({element kind: [names]} of what OpenSim cannot hold, :func:`note_lines`).
    """
    from ..model.state import BodyStates
    from ..results.run import RunResults
    from .osim_joints import joint_coordinates

    if not isinstance(results, RunResults):
        results = RunResults.read(results)
    model = model or results.model()
    if model is None:
        where = results.directory / "summary.json" if results.directory else "the run"
        raise ValueError(f"{where}: the model file of this run cannot be found "
                         f"(input.model = {results.summary.get('input', {}).get('model')!r}); pass --model")
    _check_exported_names(model)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    k = results.kinematics
    t = results.time
    ok = k["converged"].to_numpy() == 1
    moving = set(results.bodies())
    n = len(t)
    p_WB = np.tile(np.array([b.p_WB0 for b in model.bodies], float), (n, 1, 1))
    quat_WB = np.tile(np.array([b.quat_WB0 for b in model.bodies], float), (n, 1, 1))
    for b in model.bodies[1:]:
        if b.name in moving:
            p_WB[:, b.index] = np.column_stack([k[f"{b.name}.{c}_m"].to_numpy(float) for c in "xyz"])
            quat_WB[:, b.index] = np.column_stack([k[f"{b.name}.e{j}"].to_numpy(float) for j in range(4)])
        elif not b.fixed:
            raise ValueError(f"{results.directory}: kinematics.csv has no pose of moving body {b.name!r} "
                             f"of model {model.name!r}; is this the run's model?")
    ok &= np.all(np.isfinite(p_WB), axis=(1, 2)) & np.all(np.isfinite(quat_WB), axis=(1, 2))
    if not ok.any():
        raise ValueError(f"{results.directory}: no frame has converged kinematics; nothing to export")
    column = [b.column for b in model.bodies]
    states = {i: BodyStates(p_WB[i], quat_WB[i] / np.linalg.norm(quat_WB[i], axis=1)[:, None], column)
              for i in np.flatnonzero(ok)}
    first = int(np.flatnonzero(ok)[0])
    geometry = _geometry(model, out)
    tree, joints, notes = build_osim(model, states[first], geometry)
    stem = _file_stem(model.name)
    osim_path = out / f"{stem}.osim"
    _write_tree(tree, osim_path)

    rows = [joint_coordinates(joints, states[i]) for i in sorted(states)]
    names = [c.name for j in joints for c in j.coordinates]
    rotational = {c.name for j in joints for c in j.coordinates if c.motion != "translational"}
    columns = {}
    for name in names:
        v = np.array([r[name] for r in rows])
        columns[name] = np.unwrap(v) if name in rotational else v
    skipped = [int(i) for i in np.flatnonzero(~ok)]
    comments = [f"openfdk run of model {model.name!r}: joint coordinates (rad, m) of the exported model",
                f"Frames left out (kinematics failed): {len(skipped)}"
                + (f" (indices {skipped[:50]}{' ...' if len(skipped) > 50 else ''})" if skipped else "")]
    mot_path = write_storage(out / f"{stem}.mot", t[ok], columns, name=f"{stem}_coordinates", in_degrees=False,
                             comments=comments)
    return {"osim": osim_path, "mot": mot_path, "frames": int(ok.sum()), "skipped_frames": skipped,
            "geometry": sorted((out / GEOMETRY_DIR).glob("*.obj")) if geometry else [], "notes": notes}


def _file_stem(name: str) -> str:
    stem = "".join(ch if ch.isalnum() or ch in "-_" else "_" for ch in name).strip("_")
    return stem or "model"
