"""An OpenSim document as an openfdk model mapping (the model-file format of
docs/model-file.md, in SI units), so that an ``.osim`` and the file
``openfdk import-opensim`` writes are read by the same loader.

* Bodies: one openfdk body per OpenSim body that is not welded to another (welded ones
  are merged, :class:`~openfdk.io.opensim.tree.Tree`); openfdk's body frame has the
  OpenSim body's axes and its origin at the centre of mass, so every point of the body
  moves by −mass_center. The reference pose is the forward kinematics at the
  coordinates' default values.
* Joints: ``type: custom`` with OpenSim's SpatialTransform (every joint type is one);
  coordinates under ``coordinates``; CoordinateCouplerConstraints under ``couplers``;
  WeldConstraint and PointConstraint as weld and spherical joints; ConstantDistanceConstraint
  and PointOnLineConstraint as constraints on a distance and on a vector's two components.
* Markers: OpenSim names may hold characters openfdk names may not ('.', spaces): the
  name is made safe and the trial label stays the OpenSim name.
* Muscles: a Thelen2003Muscle becomes a Hill muscle of the ``muscles`` section
  (:func:`hill_parameters`, every parameter mapped), a Millard2012EquilibriumMuscle a
  ``model: millard`` muscle with its curves (:func:`millard_parameters`), a
  Millard2012AccelerationMuscle one with its curves as given
  (:func:`acceleration_parameters`), a RigidTendonMuscle or Schutte1993Muscle_Deprecated
  a ``model: opensim_rigid_tendon`` or ``schutte1993`` muscle with the file's functions
  (:func:`curve_muscle_parameters`); its PathPoints become frames on
  their (merged) bodies, named ``<muscle>_<point>``, and its path lists them in order.
  The settings openfdk's recruitment does not use (activation floor, time constants, …)
  are returned in ``info["muscle_settings"]``.
* Geometry: ``visual`` entries with the mesh file found next to the model, in its
  ``Geometry`` folder, or in ``../Geometry`` (the layout of opensim-models); a missing
  mesh is an error unless ``Mesh`` is ignored.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from ...model.coordinate_functions import function_from_spec
from .document import WRAP_TYPES, OsimDocument, OsimGeometry
from .errors import OsimError
from .tree import Tree

_SAFE = re.compile(r"[^A-Za-z0-9_\-]")
#: a principal moment of inertia below −this × the largest entry is negative (rounding of
#: a zero moment, a point mass's, stays above it)
INERTIA_TOLERANCE = 1e-12


def _violates_triangle(inertia):
    """Whether the principal moments of ``inertia`` (3, 3) kg m² break I1 + I2 >= I3
    (False when they cannot be found: the model's checks name such an inertia)."""
    from ...model.plausibility import breaks_triangle_inequality, principal_moments

    try:
        return breaks_triangle_inequality(principal_moments(inertia))
    except np.linalg.LinAlgError:
        return False


def _no_error(path, msg):  # the function dicts of the reader are checked already
    return OsimError(f"{path}: {msg}")


def safe_name(name):
    """An openfdk name for an OpenSim one ('R.ASIS' -> 'R_ASIS')."""
    return _SAFE.sub("_", name)


def _pose(p, R):
    return {"position": [float(x) for x in p], "orientation": {"matrix": np.asarray(R, float).tolist()}}


def model_dict(doc: OsimDocument, mesh_dirs=(), ignore=(), keep_welds=()):
    """The openfdk model mapping of ``doc`` (SI units; module docstring). Returns
    (mapping, info) where info lists the merged bodies and the dropped elements.
    ``keep_welds``: WeldJoints (names, or True for all) whose bodies are not merged
    (:class:`~.tree.Tree`)."""
    tree = Tree(doc, keep_welds)
    X = tree.poses()
    names = {}

    def unique(kind, name):
        safe = safe_name(name)
        key = (kind, safe)
        if key in names and names[key] != name:
            raise OsimError(f"{doc.source}: {kind} names {names[key]!r} and {name!r} both become {safe!r} in openfdk")
        if key in names:  # e.g. a WeldConstraint named as a joint: one would replace the other
            raise OsimError(f"{doc.source}: two {kind}s named {name!r}")
        names[key] = name
        return safe

    bodies = {"ground": {}}
    com = {"ground": np.zeros(3)}
    reset = tree.inertia_resets()
    if reset:  # as OpenSim: "Body … is massless but nonzero inertia provided", "… has invalid inertia"
        import warnings

        warnings.warn(f"{doc.source}: the inertia of {len(reset)} body(ies) replaced as OpenSim replaces it: "
                      + "; ".join(f"{b!r} (line {doc.bodies[b].line}): {note}" for b, note in reset[:3])
                      + (f"; and {len(reset) - 3} more" if len(reset) > 3 else ""), stacklevel=2)
    moving = {tree.root[tree.frame_body(j.child)[0]] for j in tree.order}
    for b in (b for b in doc.bodies if b in moving):  # in the file's order (OpenSim's BodySet)
        mass, c, inertia = tree.mass_properties(b)
        if mass < 0.0:
            raise OsimError(f"{doc.source}: line {doc.bodies[b].line}: Body {b!r}: mass {mass:g} kg is negative")
        if not (np.isfinite(mass) and np.all(np.isfinite(c)) and np.all(np.isfinite(inertia))):
            raise OsimError(f"{doc.source}: line {doc.bodies[b].line}: Body {b!r}: its mass, centre of mass or "
                            "inertia (with the bodies welded to it) overflows: the numbers are too large")
        # a massless body or a point mass (zero inertia) moves as OpenSim moves it: its
        # inertial forces are zero (Newton–Euler); a negative principal moment is no body
        if np.any(np.linalg.eigvalsh(inertia / (np.max(np.abs(inertia)) or 1.0)) < -INERTIA_TOLERANCE):
            raise OsimError(f"{doc.source}: line {doc.bodies[b].line}: Body {b!r}: its inertia about the centre of "
                            f"mass {inertia.round(9).tolist()} has a negative principal moment")
        p_WB, R_WB = X[b]
        com[b] = c
        key = unique("body", b)
        bodies[key] = {"mass": mass, "inertia": inertia.tolist(), **_pose(p_WB + R_WB @ c, R_WB)}
        if _violates_triangle(inertia):  # OpenSim's release builds take it (Simbody's check is compiled out)
            bodies[key]["inertia_as_given"] = True

    def frame_of(frame_name, label, kind="frame"):
        """Add an openfdk frame for an OpenSim frame; returns "body.frame"."""
        root, p, R = tree.frame_in_root(frame_name)
        body = bodies["ground" if root == tree.ground else safe_name(root)]
        frames = body.setdefault("frames", {})
        fname = unique(f"frame of {root}", label)
        frames[fname] = _pose(p - com[root], R)
        return f"{'ground' if root == tree.ground else safe_name(root)}.{fname}"

    coordinates, joints, couplers, constraints = {}, {}, {}, {}
    for j in tree.order:
        parent = frame_of(j.parent, f"{j.name}_parent")
        child = frame_of(j.child, f"{j.name}_child")
        spec = {"type": "custom", "parent": parent, "child": child}
        for kind, axes in (("rotations", j.rotations), ("translations", j.translations)):
            items = []
            for ax in axes:
                if ax.coordinates:
                    items.append({"axis": ax.axis.tolist(), "coordinate": safe_name(ax.coordinates[0]),
                                  "function": ax.function})
                else:
                    items.append({"axis": ax.axis.tolist(), "value": float(ax.function["value"])})
            spec[kind] = items
        joints[unique("joint", j.name)] = spec
        for cname in j.coordinates:
            c = doc.coordinates[cname]
            entry = {"motion": c.motion_type, "default": c.default, "clamped": c.clamped, "locked": c.locked}
            if c.opensim_motion and c.opensim_motion != c.motion_type:
                entry["opensim_motion"] = c.opensim_motion  # (the unit of its .mot columns)
            if np.all(np.isfinite(c.range)):
                entry["range"] = list(c.range)
            if c.prescribed:
                entry["prescribed"] = c.prescribed_function
            coordinates[unique("coordinate", cname)] = entry
    # in the file's order (OpenSim's CoordinateSet), not the tree's
    coordinates = {safe_name(c): coordinates[safe_name(c)] for c in doc.coordinates if safe_name(c) in coordinates}
    for c in doc.constraints:
        if c.type == "CoordinateCouplerConstraint":
            for q in c.independent + (c.dependent,):
                if q not in doc.coordinates:
                    raise OsimError(f"{doc.source}: line {c.line}: {c.type} {c.name!r}: unknown coordinate {q!r}")
            if c.dependent in c.independent:
                raise OsimError(f"{doc.source}: line {c.line}: {c.type} {c.name!r}: the dependent coordinate "
                                f"{c.dependent!r} is also its independent coordinate")
            couplers[unique("constraint", c.name)] = {"independent": safe_name(c.independent[0]),
                                                       "dependent": safe_name(c.dependent), "function": c.function}
        else:
            f1 = frame_of(c.frames[0], f"{c.name}_1")
            f2 = frame_of(c.frames[1], f"{c.name}_2")
            if f1.split(".")[0] == f2.split(".")[0]:
                _check_within_one_body(doc, tree, c)
                continue  # both frames on one (merged) body: the constraint holds by construction
            if c.type == "ConstantDistanceConstraint":       # |p2 − p1| = d: one row
                constraints[unique("constraint", c.name)] = {
                    "measure": {"type": "distance", "from": f1, "to": f2}, "value": c.value}
            elif c.type == "PointOnLineConstraint":          # p2 − p1 ⊥ the line's normals: two rows
                constraints[unique("constraint", c.name)] = {
                    "measure": {"type": "vector", "from": f1, "to": f2, "expressed_in": f1}, "components": [1, 2]}
            else:
                joints[unique("joint", c.name)] = {
                    "type": "weld" if c.type == "WeldConstraint" else "spherical", "parent": f1, "child": f2}
    for m in doc.markers:
        root, p, _ = tree.frame_in_root(m.frame)
        body = "ground" if root == tree.ground else safe_name(root)
        if body == "ground":
            # its distance to the trial's marker is the same at every pose, so OpenSim's IK
            # optimum is the one without it: left out, listed as dropped
            doc.ignored.append(("Marker", m.name, m.line))
            continue
        entry = {"position": (p + tree.frame_in_root(m.frame)[2] @ m.location - com[root]).tolist()}
        safe = unique("marker", m.name)
        if safe != m.name:
            entry["label"] = m.name
        bodies[body].setdefault("markers", {})[safe] = entry
    muscles, settings, wrapping = {}, {}, {}

    def wrap_surface(wo):
        """The ``wrapping`` entry of an OsimWrapObject (added once); returns its name."""
        safe = safe_name(wo.name)
        if safe in wrapping:
            return safe
        unique("wrapping surface", wo.name)
        root, p, R = tree.frame_in_root(wo.frame)
        body = "ground" if root == tree.ground else safe_name(root)
        fname = unique(f"frame of {root}", f"wrap_{wo.name}")
        bodies[body].setdefault("frames", {})[fname] = _pose(p + R @ wo.p_FS - com[root], R @ wo.R_FS)
        entry = {"type": WRAP_TYPES[wo.type], "frame": f"{body}.{fname}", "inside": "straight", "one_segment": True}
        if wo.type == "WrapEllipsoid":
            entry["semi_axes"] = [float(x) for x in wo.dimensions]
        elif wo.type == "WrapTorus":
            entry.update(radius=wo.length, tube_radius=wo.radius)
        else:
            entry["radius"] = wo.radius
        if wo.type == "WrapCylinder":
            entry["length"] = wo.length
        axis, sign = wo.quadrant
        if axis is not None:
            entry["side"] = f"{'+' if sign > 0 else '-'}{'xyz'[axis]}"
            if wo.type != "WrapCylinder":
                entry["crossing_only"] = True  # OpenSim wraps a sphere or ellipsoid only where the line crosses it
            if wo.type == "WrapEllipsoid":
                entry["rule"] = "opensim"  # the quadrant as OpenSim imposes it: its planar path
        wrapping[safe] = entry
        return safe

    def path_of(mu):
        """The ``path`` entries of a muscle's or ligament's points and wraps."""
        path = [frame_of(pt.frame, f"{mu.name}_{pt.name}", kind="path point") for pt in mu.points]
        # a PathPoint is a frame at its location, axes of its parent frame; a moving one
        # is the parent frame itself, its functions give the location in its axes
        for k, (pt, ref) in enumerate(zip(mu.points, path)):
            body, fname = ref.split(".", 1)
            _, _, R = tree.frame_in_root(pt.frame)
            frame = bodies[body]["frames"][fname]
            location = pt.location
            if pt.moving is not None and pt.moving[0] is None:  # no coordinate: the functions at 0
                location = np.array([function_from_spec(f, "", _no_error).evaluate(0.0)[0] for f in pt.moving[1]])
            if pt.moving is None or pt.moving[0] is None:
                frame["position"] = (np.asarray(frame["position"]) + R @ location).tolist()
            label = f"{doc.source}: line {pt.line}: {mu.type} {mu.name!r}: point {pt.name!r}"
            for spec in (pt.condition, pt.moving):
                if spec is not None and spec[0] is not None and spec[0] not in coordinates:
                    raise OsimError(f"{label}: unknown coordinate {spec[0]!r}")
            if pt.condition is not None:
                c, lo, hi = pt.condition
                path[k] = {"point": ref, "active": {"coordinate": c, "range": [lo, hi]}}
            elif pt.moving is not None and pt.moving[0] is not None:
                c, (fx, fy, fz) = pt.moving
                path[k] = {"frame": ref, "moving": {"coordinate": c, "x": fx, "y": fy, "z": fz}}
        if mu.wraps:
            path = _wrapped_path(doc, tree, mu, path, wrap_surface)
        return path

    for mu in doc.muscles:
        safe = unique("muscle", mu.name)
        path = path_of(mu)
        if mu.type == "Millard2012EquilibriumMuscle":
            law = {"model": "millard", **millard_parameters(mu, doc.source)}
            reported = MILLARD_SETTINGS
        elif mu.type == "Millard2012AccelerationMuscle":
            law = {"model": "millard", **acceleration_parameters(mu, doc.source)}
            reported = ACCELERATION_SETTINGS
        elif mu.type in CURVE_MUSCLE_MODELS:
            law = curve_muscle_parameters(mu, doc.source)
            reported = CURVE_MUSCLE_SETTINGS
        else:
            law = {"model": "hill", **hill_parameters(mu, doc.source)}
            reported = RECRUITMENT_SETTINGS
        muscles[safe] = {"path": path, **law,
                         # activation bounds of OpenSim's static optimisation (static_optimization: opensim)
                         "min_control": mu.parameters["min_control"], "max_control": mu.parameters["max_control"]}
        settings[safe] = {k: v for k, v in mu.parameters.items() if k in reported}
    ligaments = {}
    for lig in doc.ligaments:
        safe = unique("ligament", lig.name)
        ligaments[safe] = {"path": path_of(lig), **ligament_parameters(lig, doc.source)}
    contacts = {}
    for name, force in doc.contact_forces.items():
        from .contact import contact_depth, pressure_law

        sides = {}
        for role, key in (("vertices", "casting"), ("surface", "target")):
            mesh = doc.contact_meshes[force[key]]
            file = find_mesh(doc, OsimGeometry(mesh["mesh_file"], mesh["frame"], np.ones(3), line=mesh["line"]),
                             mesh_dirs, kind="Smith2018ContactMesh")
            root, p, R = tree.frame_in_root(mesh["frame"])
            body = "ground" if root == tree.ground else safe_name(root)
            p_BG, R_BG = p + R @ mesh["p_FG"] - com[root], R @ mesh["R_FG"]
            sides[role] = {"body": body, "mesh": str(file), "units": "m",
                           "placement": {"position": p_BG.tolist(), "orientation": {"matrix": R_BG.tolist()}}}
            if mesh.get("variable"):  # the bone behind the cartilage, in the same file frame
                back = find_mesh(doc, OsimGeometry(mesh["variable"]["back_file"], mesh["frame"], np.ones(3),
                                                   line=mesh["line"]), mesh_dirs, kind="Smith2018ContactMesh")
                sides[role]["thickness"] = {"back_mesh": str(back), "min": mesh["variable"]["min"],
                                            "max": mesh["variable"]["max"]}
        if sides["vertices"]["body"] == sides["surface"]["body"]:
            raise OsimError(f"{doc.source}: line {force['line']}: Smith2018ArticularContactForce {name!r}: both meshes "
                            "are on one body")
        target, casting = doc.contact_meshes[force["target"]], doc.contact_meshes[force["casting"]]
        contacts[unique("contact", name)] = {
            **sides, **pressure_law(force, target, casting),
            "max_depth": contact_depth(force, target, casting), "grid_spacing": IMPORT_GRID_SPACING_M}
    missing = []
    for g in doc.geometry:
        path = find_mesh(doc, g, mesh_dirs, "Mesh" in ignore, missing=missing)
        if path is None:
            doc.ignored.append(("Mesh", g.file, g.line))
            continue
        root, p, R = tree.frame_in_root(g.frame)
        body = "ground" if root == tree.ground else safe_name(root)
        p_BG = p + R @ g.p_FG - com[root]
        bodies[body].setdefault("visual", []).append(
            {"mesh": str(path), "units": "m", "scale": [float(s) for s in g.scale],
             "placement": {"position": p_BG.tolist(), "orientation": {"matrix": (R @ g.R_FG).tolist()}}})
    if missing:  # display meshes only: as OpenSim, the model is read without them, and says so
        import warnings

        names = ", ".join(repr(f[:60]) for f, _ in missing[:3]) + (f" and {len(missing) - 3} more" if len(missing) > 3
                                                                  else "")
        warnings.warn(f"{doc.source}: {len(missing)} display mesh file(s) not found ({names}; looked in "
                      f"{missing[0][1]}): the model is read without them (the viewer draws those bodies plain); give "
                      "their folder with --geometry DIR, or leave the meshes out with --ignore Mesh", stacklevel=2)
    out = {"openfdk": 1, "name": safe_name(doc.name), "units": {"length": "m", "angle": "rad"},
           "gravity": [float(x) for x in doc.gravity], "bodies": bodies}
    if coordinates:
        out["coordinates"] = coordinates
    out["joints"] = joints
    if couplers:
        out["couplers"] = couplers
    if constraints:
        out["constraints"] = constraints
    if wrapping:
        out["wrapping"] = wrapping
    if muscles:
        out["muscles"] = muscles
    if ligaments:
        out["ligaments"] = ligaments
    if contacts:
        out["contacts"] = contacts
    merged = {b: tree.root[b] for b in doc.bodies if tree.root[b] != b}
    # each OpenSim body frame in its openfdk body (for data given in a body's frame)
    body_frames = {}
    for b in list(doc.bodies) + [tree.ground]:
        root = tree.root[b]
        p, R = tree.X_root[b]
        body_frames[b] = ("ground" if root == tree.ground else safe_name(root), (p - com[root]).tolist(), R.tolist())
    if doc.springs:
        from .passive_forces import add_springs

        out = add_springs(out, doc.springs, doc.source)
    if doc.actuators:
        from .actuators import add_actuators

        out = add_actuators(out, doc.actuators, body_frames, doc.source)
    # every other OpenSim frame (PhysicalOffsetFrames: a joint's "knee_r/tibia_r_offset") in its openfdk body
    offset_frames = {}
    for name, f in doc.frames.items():
        if name in body_frames:
            continue
        try:
            body, p_BF, R_BF = tree.frame_body(name)
        except OsimError:  # a frame nothing uses whose chain does not resolve: OpenSim's reader names it if used
            continue
        root = tree.root[body]
        p, R = tree.X_root[body]
        offset_frames[name] = ("ground" if root == tree.ground else safe_name(root),
                               (p + R @ p_BF - com[root]).tolist(), (R @ R_BF).tolist())
    welds = {tree.joint_of[b].name: [b, tree.root[b]] for b in merged}  # WeldJoint: [its child, the body it is in]
    # each kept joint's OpenSim parent and child bodies (its frames' base bodies: a merged body keeps its name),
    # in the JointSet's order (OpenSim's JointReaction reports "all" joints in it)
    kept = {id(j) for j in tree.order}
    joint_bodies = {safe_name(j.name): [tree.frame_body(j.parent)[0], tree.frame_body(j.child)[0]]
                    for j in doc.joints if id(j) in kept}
    return out, {"merged_bodies": merged, "welds": welds, "joint_bodies": joint_bodies, "body_frames": body_frames,
                 "offset_frames": offset_frames, "muscle_settings": settings}


def _wrapped_path(doc, tree, mu, path, wrap_surface):
    """``path`` (the muscle's point entries) with its PathWraps' surfaces inserted.

    OpenSim tries a PathWrap on every segment between the points of its ``range``
    (1-based, −1: the path's end) and wraps one: the first whose straight line crosses
    the object, else the one whose length grows least. The surface is listed in every
    segment of the range and is ``one_segment``: the kernel applies the same rule (with
    conditional points, between the range's first and last active points).
    Surfaces in one segment follow the PathWrapSet's order. An inactive wrap object is
    left out, as OpenSim leaves it out."""
    n = len(mu.points)
    segments = [[] for _ in range(n - 1)]
    tori = set()
    for pw in mu.wraps:
        label = f"{doc.source}: line {pw.line}: PathWrap '{mu.name}/{pw.name}'"
        if mu.points[0].condition is not None or mu.points[-1].condition is not None:
            raise OsimError(f"{label}: a wrapped path that starts or ends at a ConditionalPathPoint is not "
                            "supported; leave the muscle out with --ignore PathWrap")
        wo = doc.wrap_objects[pw.wrap_object]
        if wo.type == "WrapCylinder" and wo.quadrant[0] == 2:
            raise OsimError(f"{doc.source}: line {wo.line}: WrapCylinder {wo.name!r}: quadrant {wo.quadrant_text!r} "
                            "along the cylinder's axis is not supported (openfdk's side is across the axis: x or y); "
                            "leave it out with --ignore WrapCylinder")
        first = 0 if pw.range[0] < 1 else pw.range[0] - 1
        last = n - 1 if pw.range[1] < 1 else pw.range[1] - 1
        if first > n - 1 or last > n - 1:
            raise OsimError(f"{label}: range {list(pw.range)} beyond the path's {n} points")
        if not wo.active or last <= first:  # OpenSim never wraps it
            doc.ignored.append(("PathWrap", f"{mu.name}/{pw.name}", pw.line))
            continue
        surface = wrap_surface(wo)
        if wo.type == "WrapTorus" or (wo.type == "WrapEllipsoid" and wo.quadrant[0] is not None):
            tori.add(surface)  # a surface whose length is not stationary in its tangent points
        for k in range(first, last):
            segments[k].append(surface)
    out = [path[0]]
    for k in range(n - 1):
        if len(segments[k]) > 1 and tori.intersection(segments[k]):
            raise OsimError(f"{doc.source}: line {mu.line}: {mu.type} {mu.name!r}: a WrapTorus or a WrapEllipsoid with "
                            "a quadrant and another PathWrap over one segment are not supported; leave the muscle out "
                            "with --ignore PathWrap")
        if len(segments[k]) > MAX_WRAPS_PER_SEGMENT:
            raise OsimError(f"{doc.source}: line {mu.line}: {mu.type} {mu.name!r}: {len(segments[k])} PathWraps "
                            f"over one segment; openfdk imports at most {MAX_WRAPS_PER_SEGMENT}; leave the muscle "
                            "out with --ignore PathWrap")
        out += _any_order(segments[k]) + [path[k + 1]]
    return out


#: the most PathWraps a segment may have (its surfaces are listed 2ⁿ − 1 times)
MAX_WRAPS_PER_SEGMENT = 4


def _any_order(surfaces):
    """A sequence in which one entry of each surface can be chosen in any order: each
    PathWrap wraps the path as OpenSim left it, before or after the points of the ones
    applied before it, so the surface applied last stands between every two others
    ([A, B] -> [B, A, B]; [A, B, C] -> [C, B, C, A, C, B, C]); the kernel keeps one
    entry of each (``one_segment``)."""
    seq = []
    for s in surfaces:
        new = [s]
        for x in seq:
            new += [x, s]
        seq = new
    return seq


#: the distance-grid spacing of imported contacts (m): implant surfaces span ~70 mm, and
#: openfdk's default 0.3 mm would need gigabytes for them (docs/contact.md, memory)
IMPORT_GRID_SPACING_M = 0.5e-3


def ligament_parameters(lig, source):
    """The ``ligaments`` entry keys of a Blankevoort1991Ligament (SI): OpenSim's
    ``linear_stiffness`` is per unit strain, openfdk's ``stiffness`` per metre (k = K/l0);
    OpenSim's ``transition_strain`` ends the toe, openfdk's is half of it; OpenSim's
    ``damping_coefficient`` is per unit strain rate, openfdk's ``damping`` per m/s
    (c = C/l0), with OpenSim's rule (``damping_rule: opensim``). Invalid values raise
    OsimError naming the ligament and its line."""
    p = lig.parameters
    label = f"{source}: line {lig.line}: {lig.type} {lig.name!r}"
    l0 = p["slack_length"]
    for key, ok in (("slack_length", l0 > 0), ("linear_stiffness", p["linear_stiffness"] >= 0),
                    ("transition_strain", p["transition_strain"] > 0),
                    ("damping_coefficient", p["damping_coefficient"] >= 0)):
        if not ok:
            raise OsimError(f"{label}: {key} {p[key]:g} is out of range")
    return {"stiffness": p["linear_stiffness"] / l0, "slack_length": l0, "transition_strain": p["transition_strain"] / 2,
            "damping": p["damping_coefficient"] / l0, "damping_rule": "opensim"}


#: Thelen2003Muscle properties -> openfdk Hill keys (docs/opensim-import.md); Af is
#: mapped separately (fast_fibre_fraction)
THELEN_TO_HILL = {
    "max_isometric_force": "max_isometric_force", "optimal_fiber_length": "optimal_fibre_length",
    "tendon_slack_length": "tendon_slack_length", "pennation_angle_at_optimal": "pennation_angle_at_optimal",
    "max_contraction_velocity": "max_contraction_velocity", "FmaxTendonStrain": "tendon_strain_at_max_force",
    "FmaxMuscleStrain": "passive_strain_at_max_force", "KshapeActive": "force_length_width",
    "KshapePassive": "passive_shape_factor", "Flen": "max_eccentric_force",
}
#: Thelen2003Muscle properties read but not used by openfdk's recruitment (reported)
RECRUITMENT_SETTINGS = ("min_control", "max_control", "optimal_force", "default_activation", "default_fiber_length",
                        "fv_linear_extrap_threshold", "maximum_pennation_angle", "activation_time_constant",
                        "deactivation_time_constant", "minimum_activation", "ignore_tendon_compliance",
                        "ignore_activation_dynamics")


#: Millard2012EquilibriumMuscle properties -> openfdk ``model: millard`` keys
MILLARD_TO_OPENFDK = {
    "max_isometric_force": "max_isometric_force", "optimal_fiber_length": "optimal_fibre_length",
    "tendon_slack_length": "tendon_slack_length", "pennation_angle_at_optimal": "pennation_angle_at_optimal",
    "max_contraction_velocity": "max_contraction_velocity", "maximum_pennation_angle": "maximum_pennation_angle",
    "fiber_damping": "fiber_damping", "ignore_tendon_compliance": "ignore_tendon_compliance",
    "minimum_activation": "minimum_activation",
    "ActiveForceLengthCurve": "active_force_length", "ForceVelocityCurve": "force_velocity",
    "FiberForceLengthCurve": "fibre_force_length", "TendonForceLengthCurve": "tendon_force_length",
}
#: Millard2012EquilibriumMuscle properties read but not used by openfdk's recruitment (reported)
MILLARD_SETTINGS = ("min_control", "max_control", "optimal_force", "default_activation", "default_fiber_length",
                    "activation_time_constant", "deactivation_time_constant", "ignore_activation_dynamics")


#: Millard2012AccelerationMuscle properties read but not used by openfdk's recruitment (reported)
ACCELERATION_SETTINGS = ("min_control", "max_control", "optimal_force", "default_activation", "default_fiber_length",
                         "default_fiber_velocity", "mass", "tendon_force_length_damping",
                         "fiber_compressive_force_length_damping", "fiber_force_length_damping",
                         "fiber_compressive_force_cos_pennation_damping", "FiberCompressiveForceLengthCurve",
                         "FiberCompressiveForceCosPennationCurve", "MuscleFirstOrderActivationDynamicModel",
                         "ignore_activation_dynamics")


def acceleration_parameters(muscle, source):
    """The ``muscles`` entry keys (``model: millard``, ``curve_rule: as_given``) of a
    Millard2012AccelerationMuscle: its four Millard curves exactly as the file gives them
    (OpenSim's acceleration muscle adjusts none; an absent ActiveForceLengthCurve is its
    default with ``minimum_value`` 0, the muscle's own default), pennation up to π/2
    (its MuscleFixedWidthPennationModel), ``minimum_activation`` of its
    MuscleFirstOrderActivationDynamicModel (default 0). Its masses, dampings and
    compressive curves are reported (docs/opensim-import.md)."""
    import math
    from copy import copy

    p = dict(muscle.parameters)
    p["maximum_pennation_angle"] = math.pi / 2
    p["minimum_activation"] = p.get("MuscleFirstOrderActivationDynamicModel", {}).get("minimum_activation", 0.0)
    p.setdefault("ActiveForceLengthCurve", {"minimum_value": 0.0})
    as_millard = copy(muscle)
    as_millard.parameters = p
    out = millard_parameters(as_millard, source, curve_rule="as_given")
    return {**out, "curve_rule": "as_given"}


#: RigidTendonMuscle and Schutte1993Muscle_Deprecated -> openfdk ``model`` (:mod:`openfdk.forces.curve_muscle`)
CURVE_MUSCLE_MODELS = {"RigidTendonMuscle": "opensim_rigid_tendon", "Schutte1993Muscle_Deprecated": "schutte1993"}
#: their properties read but not used by openfdk's recruitment (reported)
CURVE_MUSCLE_SETTINGS = ("min_control", "max_control", "optimal_force", "activation1", "activation2",
                         "ignore_tendon_compliance", "ignore_activation_dynamics")
_CURVE_KEYS = {"max_isometric_force": "max_isometric_force", "optimal_fiber_length": "optimal_fibre_length",
               "tendon_slack_length": "tendon_slack_length", "pennation_angle_at_optimal": "pennation_angle_at_optimal",
               "max_contraction_velocity": "max_contraction_velocity", "time_scale": "time_scale",
               "damping": "damping", "active_force_length_curve": "active_force_length",
               "passive_force_length_curve": "passive_force_length", "force_velocity_curve": "force_velocity",
               "tendon_force_length_curve": "tendon_force_length"}


def curve_muscle_parameters(muscle, source):
    """The ``muscles`` entry (``model: opensim_rigid_tendon`` or ``schutte1993``, SI) of
    a RigidTendonMuscle or Schutte1993Muscle_Deprecated: every property mapped, the
    curves as the file's functions (absent: OpenSim's defaults; a Schutte muscle's absent
    passive curve is OpenSim's exponential). Checked by
    :class:`~openfdk.forces.curve_muscle.CurveMuscle`; an invalid value raises OsimError
    naming the muscle and its line."""
    from ...forces.curve_muscle import CurveMuscle

    p = muscle.parameters
    model = CURVE_MUSCLE_MODELS[muscle.type]
    out = {ours: p[osim] for osim, ours in _CURVE_KEYS.items() if osim in p}
    try:
        CurveMuscle(kind={"opensim_rigid_tendon": "rigid_tendon"}.get(model, model), name=muscle.name, **out)
    except (ValueError, TypeError) as exc:
        raise OsimError(f"{source}: line {muscle.line}: {muscle.type} {muscle.name!r}: {exc}") from None
    return {"model": model, **out}


def millard_parameters(muscle, source, curve_rule="equilibrium"):
    """The ``muscles`` entry keys (``model: millard``) of an OsimMuscle
    (Millard2012EquilibriumMuscle), SI units; the curves as {property: value} with the
    file's properties only (the rest OpenSim's defaults). Checked by
    :class:`~openfdk.forces.millard.MillardMuscle`; an invalid value raises OsimError
    naming the muscle and its line."""
    from ...forces import millard_curves as mc
    from ...forces.millard import MillardMuscle

    p = muscle.parameters
    label = f"{source}: line {muscle.line}: {muscle.type} {muscle.name!r}"
    out = {ours: (dict(p[osim]) if isinstance(p[osim], dict) else p[osim])
           for osim, ours in MILLARD_TO_OPENFDK.items() if osim in p}
    classes = {"active_force_length": mc.ActiveForceLengthCurve, "force_velocity": mc.ForceVelocityCurve,
               "fibre_force_length": mc.FiberForceLengthCurve, "tendon_force_length": mc.TendonForceLengthCurve}
    try:
        MillardMuscle(name=muscle.name, curve_rule=curve_rule,
                      **{k: (classes[k](**v) if k in classes else v) for k, v in out.items()})
    except (ValueError, TypeError) as exc:
        raise OsimError(f"{label}: {exc}") from None
    return out


def hill_parameters(muscle, source):
    """The ``muscles`` entry keys of an OsimMuscle (Thelen2003Muscle), in SI units.

    Thelen's force–velocity curve at full activation is Hill's hyperbola
    (1 + ṽ)/(1 − ṽ/Af), openfdk's with curvature A = 0.1 + 0.4·ff: so
    ff = (Af − 0.1)/0.4, and an Af outside [0.1, 0.5] (ff outside [0, 1]) is refused.
    Every value is checked by :class:`~openfdk.forces.hill.Hill3ElementMuscle`; an
    invalid one raises OsimError naming the muscle and its line."""
    from ...forces.hill import Hill3ElementMuscle

    p = muscle.parameters
    label = f"{source}: line {muscle.line}: {muscle.type} {muscle.name!r}"
    out = {hill: p[osim] for osim, hill in THELEN_TO_HILL.items()}
    af = p["Af"]
    if not 0.1 <= af <= 0.5:
        raise OsimError(f"{label}: Af {af:g}: openfdk's Hill curvature A = 0.1 + 0.4·fast_fibre_fraction covers "
                        "Af in [0.1, 0.5]")
    out["fast_fibre_fraction"] = min(1.0, max(0.0, (af - 0.1) / 0.4))
    try:
        Hill3ElementMuscle(name=muscle.name, **out)
    except ValueError as exc:
        named = [osim for osim, hill in THELEN_TO_HILL.items() if hill in str(exc)]
        raise OsimError(f"{label}: {exc}" + (f" (the file's {named[0]})" if named else "")) from None
    return out


def find_mesh(doc, geometry, mesh_dirs=(), ignore_missing=False, kind="Mesh", missing=None):
    """The mesh file of an OsimGeometry: next to the model, in its Geometry folder, in
    ../Geometry or in ``mesh_dirs``; None when it is missing and ``ignore_missing``.
    ``kind``: the element type the file belongs to, for the message (a display ``Mesh``,
    or a contact's ``Smith2018ContactMesh``, which ``--ignore Mesh`` does not leave out).
    ``missing``: a list to which a file not found is appended as (its name, the folders
    looked in) and None returned, instead of an error (display meshes, which OpenSim
    too leaves out with a warning); a file of an unknown format is still an error."""
    import os

    from ..meshfiles import DISPLAY_MESH_SUFFIXES

    base = doc.path.resolve().parent  # absolute: "../Geometry" of a model named relative to the cwd
    file = geometry.file
    name = Path(file)
    shown = file if len(file) <= 200 else f"{file[:200]}… ({len(file)} characters)"
    if name.suffix.lower() not in DISPLAY_MESH_SUFFIXES:  # refused before any file is read or copied
        if ignore_missing:
            return None
        raise OsimError(f"{doc.source}: line {geometry.line}: Mesh {shown!r}: unknown mesh format {name.suffix!r} "
                        f"(openfdk reads {', '.join(DISPLAY_MESH_SUFFIXES)}); leave the meshes out with --ignore Mesh")
    candidates = [name] if name.is_absolute() else [base / name, base / "Geometry" / name,
                                                     base.parent / "Geometry" / name] + \
        [Path(d) / name for d in mesh_dirs]
    for c in candidates:
        try:
            if c.is_file():  # a regular file (not a FIFO or a device), through symlinks
                return Path(os.path.realpath(c))
        except OSError:  # e.g. a name too long for the file system: not there
            pass
    if ignore_missing:
        return None
    folders = dict.fromkeys(os.path.realpath(c.parent) for c in candidates)  # each once (a model in the cwd)
    if missing is not None:
        missing.append((shown, ", ".join(f[:200] for f in folders)))
        return None
    leave = ("the meshes out with --ignore Mesh" if kind == "Mesh" else
             f"the contacts out with --ignore {kind} --ignore Smith2018ArticularContactForce")
    raise OsimError(f"{doc.source}: line {geometry.line}: {kind} {shown!r} not found (looked in "
                    f"{', '.join(f[:200] for f in folders)}); give its folder with --geometry DIR, or leave {leave}")


def _check_within_one_body(doc, tree, c):
    """A constraint between two frames of one (merged) body holds by construction, or
    never: a weld or point constraint is taken as holding (OpenSim's welds), a distance
    or a point on a line that the body's geometry violates is OsimError."""
    if c.type not in ("ConstantDistanceConstraint", "PointOnLineConstraint"):
        return
    (_, p1, R1), (_, p2, _) = (tree.frame_in_root(f) for f in c.frames)
    d = p2 - p1
    error = (abs(np.linalg.norm(d) - c.value) if c.type == "ConstantDistanceConstraint"
             else float(np.linalg.norm(d - (d @ R1[:, 0]) * R1[:, 0])))
    if error > 1e-9:
        raise OsimError(f"{doc.source}: line {c.line}: {c.type} {c.name!r}: both points are on one body (welded), "
                        f"and its geometry misses the constraint by {error:.3g} m")
