"""Export a run to OpenSim: an ``.osim`` model and a ``.mot`` motion that plays the run.

``openfdk export-opensim RESULT_DIR --out DIR`` writes into DIR:

* ``<model>.osim`` — an OpenSim 4 model (``OpenSimDocument Version="40000"``) in which
  every openfdk body is an OpenSim ``Body`` attached to ``ground`` by a ``FreeJoint``
  named ``<body>_free``; the body's frame is openfdk's body frame (origin at the centre
  of mass, so ``mass_center`` is 0 and the joint's child frame is the body frame itself,
  without offset); inertia about the centre of mass in that frame; the contact meshes
  and the bodies' visual meshes (model-file ``visual:`` entries) as ``Mesh`` geometry
  (``Geometry/<contact>_<side>.obj``, ``Geometry/<body>_visual_<k>.obj``, vertices in the
  body frame, metres); the model's markers as a ``MarkerSet``.  openfdk's ground (body 0, world
  frame W) is OpenSim's ``ground``: its meshes and markers attach there.  Any other fixed
  openfdk body is exported like the rest, with its coordinates locked at its pose.
* ``<model>.mot`` — the free-joint coordinates over time.  OpenSim's FreeJoint
  (``FreeJoint.h``/``.cpp``) has coordinates in the order rx, ry, rz, tx, ty, tz: the
  child frame's orientation in the parent is the body-fixed X-Y-Z sequence
  R = Rx(rx)·Ry(ry)·Rz(rz), and (tx, ty, tz) is the child frame's origin in the parent
  frame.  With ground as parent and the body frame as child, that is R_WB and the
  centre of mass r_WB of openfdk's kinematics.  Angles are radians (``inDegrees=no``),
  unwrapped over time so that OpenSim's interpolation does not jump by 2π.

Frames whose kinematics failed are left out of the ``.mot`` (their poses are not
solutions); the header says how many and which.  Nothing here needs OpenSim: the files
are written from the format's documentation (docs/opensim.md).
"""

from __future__ import annotations

import os
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from ..spatial import rotation_matrix, xyz_angles_from_matrix
from .storage import write_storage

__all__ = ["OSIM_VERSION", "FREE_COORDINATES", "export_opensim", "free_joint_coordinates",
           "opensim_frame_path"]

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


def _coordinate(parent, name, value, locked, rotational):
    c = _sub(parent, "Coordinate", name=name)
    _sub(c, "default_value", repr(float(value)))
    _sub(c, "default_speed_value", "0")
    _sub(c, "range", "-3.1415926535897931 3.1415926535897931" if rotational else "-10 10")
    _sub(c, "clamped", "false")
    _sub(c, "locked", "true" if locked else "false")
    return c


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


def build_osim(model, coordinates0: dict, geometry=None) -> ET.ElementTree:
    """The ``.osim`` document of ``model``; coordinates0: body name -> (6,) default
    FreeJoint coordinates (the first exported frame); geometry: body index ->
    [(geometry name, mesh file relative to the .osim, "#rrggbb" colour or "")]."""
    doc = ET.Element("OpenSimDocument", Version=OSIM_VERSION)
    m = _sub(doc, "Model", name=_file_stem(model.name))  # OpenSim names: no spaces, \ * + / or tabs
    _sub(m, "credits", "Exported by openfdk (export-opensim): one FreeJoint per body; see docs/opensim.md")
    _sub(m, "length_units", "meters")
    _sub(m, "force_units", "N")
    _sub(m, "gravity", _vec(model.gravity_W))
    attached = geometry or {}
    ground = _sub(m, "Ground", name="ground")
    _attach(ground, attached.get(0, []))
    bodyset = _sub(_sub(m, "BodySet", name="bodyset"), "objects")
    jointset = _sub(_sub(m, "JointSet", name="jointset"), "objects")
    for b in model.bodies[1:]:
        name = b.name
        body = _sub(bodyset, "Body", name=name)
        _attach(body, attached.get(b.index, []))
        J = np.asarray(b.inertia_B, dtype=float)
        _sub(body, "mass", repr(float(b.mass)))
        _sub(body, "mass_center", "0 0 0")
        # OpenSim's order: Ixx Iyy Izz Ixy Ixz Iyz (about the centre of mass, body frame)
        _sub(body, "inertia", _vec([J[0, 0], J[1, 1], J[2, 2], J[0, 1], J[0, 2], J[1, 2]]))
        joint = _sub(jointset, "FreeJoint", name=f"{name}_free")
        _sub(joint, "socket_parent_frame", "/ground")
        _sub(joint, "socket_child_frame", f"/bodyset/{name}")
        coords = _sub(joint, "coordinates")
        for j, suffix in enumerate(FREE_COORDINATES):
            _coordinate(coords, f"{name}_{suffix}", coordinates0[b.name][j], b.fixed, j < 3)
    markerset = _sub(_sub(m, "MarkerSet", name="markerset"), "objects")
    mk = model.markers
    for j in range(mk.size):
        marker = _sub(markerset, "Marker", name=mk.labels[j])
        _sub(marker, "socket_parent_frame", opensim_frame_path(model, int(mk.body[j])))
        _sub(marker, "location", _vec(mk.p_BM[j]))
        _sub(marker, "fixed", "false")
    ET.indent(doc, space="  ")
    return ET.ElementTree(doc)


def export_opensim(results, out_dir, model=None) -> dict:
    """Write ``<name>.osim``, ``<name>.mot`` and ``Geometry/*.obj`` for a run.

    Args:
        results: a :class:`~openfdk.runresults.RunResults` or a result folder.
        out_dir: output folder (created).
        model: the analysed Model (default: the one the run recorded, see
            :meth:`RunResults.model`).
    Returns: dict with keys ``osim``, ``mot`` (paths), ``geometry`` (list of paths),
    ``frames`` (rows written) and ``skipped_frames`` (indices of failed frames left out).
    """
    from ..runresults import RunResults

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
    coords = {}
    for b in model.bodies[1:]:
        if b.name in moving:
            p = np.column_stack([k[f"{b.name}.{c}_m"].to_numpy(float) for c in "xyz"])
            q = np.column_stack([k[f"{b.name}.e{j}"].to_numpy(float) for j in range(4)])
        elif b.fixed:
            p, q = np.tile(b.p_WB0, (len(t), 1)), np.tile(b.quat_WB0, (len(t), 1))
        else:
            raise ValueError(f"{results.directory}: kinematics.csv has no pose of moving body {b.name!r} "
                             f"of model {model.name!r}; is this the run's model?")
        coords[b.name] = free_joint_coordinates(np.where(ok[:, None], p, np.nan), np.where(ok[:, None], q, np.nan))
        ok &= np.all(np.isfinite(coords[b.name]), axis=1)
    if not ok.any():
        raise ValueError(f"{results.directory}: no frame has converged kinematics; nothing to export")
    first = int(np.flatnonzero(ok)[0])
    geometry = _geometry(model, out)
    tree = build_osim(model, {n: c[first] for n, c in coords.items()}, geometry)
    stem = _file_stem(model.name)
    osim_path = out / f"{stem}.osim"
    tmp = osim_path.with_name(f".{osim_path.name}.tmp-{os.getpid()}")
    tree.write(tmp, encoding="UTF-8", xml_declaration=True)
    os.replace(tmp, osim_path)

    columns = {}
    for b in model.bodies[1:]:
        for j, suffix in enumerate(FREE_COORDINATES):
            columns[f"{b.name}_{suffix}"] = coords[b.name][ok, j]
    skipped = [int(i) for i in np.flatnonzero(~ok)]
    comments = [f"openfdk run of model {model.name!r}: FreeJoint coordinates (rad, m) of every body",
                f"Frames left out (kinematics failed): {len(skipped)}"
                + (f" (indices {skipped[:50]}{' ...' if len(skipped) > 50 else ''})" if skipped else "")]
    mot_path = write_storage(out / f"{stem}.mot", t[ok], columns, name=f"{stem}_coordinates", in_degrees=False,
                             comments=comments)
    return {"osim": osim_path, "mot": mot_path, "frames": int(ok.sum()), "skipped_frames": skipped,
            "geometry": sorted((out / GEOMETRY_DIR).glob("*.obj")) if geometry else []}


def _file_stem(name: str) -> str:
    stem = "".join(ch if ch.isalnum() or ch in "-_" else "_" for ch in name).strip("_")
    return stem or "model"
