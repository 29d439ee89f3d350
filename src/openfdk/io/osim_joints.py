"""openfdk's joints as an OpenSim tree of joints, for ``export-opensim`` (docs/opensim.md,
"Joints").

openfdk keeps every body's pose as an unknown and its joints as constraint rows, in any
graph; OpenSim needs a tree rooted at ``ground`` with one parent joint per body, whose
coordinates place the child. :func:`plan_joints` builds that tree from the model's
joint records (``model.joints``):

* Joints are taken in their declared direction from the bodies already placed (ground and
  the fixed bodies, welded to ground) outward; a weld, spherical, revolute or prismatic
  joint without FDK rows is taken reversed when only its child is placed.
* Each tree joint becomes, with F its parent frame and M its child frame:

  ====================  ======================  =========================================
  openfdk              OpenSim                 coordinates (values from the poses)
  ====================  ======================  =========================================
  weld                  WeldJoint               —
  revolute              PinJoint                ``<joint>_rz`` = angle of R_FM about z
  spherical             BallJoint               ``<joint>_rx, _ry, _rz``: R_FM = Rx Ry Rz
  custom (OpenSim's)    CustomJoint             its own coordinates, axes and functions
  rows made FDK DOFs,   CustomJoint (or         the free rotations (z, or x-y-z) and the
  prismatic,            FreeJoint)              free translations ``<joint>_tx …`` along
  point_on_plane                                the parent frame's axes (the plane's)
  ====================  ======================  =========================================

* A weld or spherical joint that closes a loop becomes a WeldConstraint or a
  PointConstraint; a coupler a CoordinateCouplerConstraint.
* A body no joint reaches gets a FreeJoint ``<body>_free`` to ground (coordinates
  ``<body>_rx … _tz``, body-fixed X-Y-Z angles and the position in ground).

What cannot be written (another joint closing a loop, a function OpenSim has no class
for, …) is collected in ``notes`` {element kind: [names]}, and the export still writes
the rest. All lengths m, angles rad; body frames are openfdk's (origin at the centre of
mass).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..model.state import BodyStates
from ..numerics.spatial import xyz_angles_from_matrix
from .osim_functions import function_xml

_E = np.eye(3)
_LINEAR = ("LinearFunction", {"coefficients": "1.0 0.0"})


@dataclass
class OsimCoordinate:
    """An exported coordinate: name, motion ("rotational", "translational", "coupled"),
    flags, range (2,) in SI or None, prescribed function of time (PiecewisePolynomial) or
    None."""

    name: str
    motion: str
    locked: bool = False
    clamped: bool = False
    range: tuple | None = None
    prescribed: object = None


@dataclass
class OsimJoint:
    """An exported tree joint: OpenSim class ``kind``; ``parent``/``child`` body indices
    with the joint frames F and M in them (p (3,) m, R (3, 3)); ``coordinates`` in
    OpenSim's order; ``axes`` (CustomJoint): six (axis (3,), coordinate name or None,
    (function tag, properties)); ``values(R_FM, p_FM, state)`` -> (k,) coordinates."""

    name: str
    kind: str
    parent: int
    p_PF: np.ndarray
    R_PF: np.ndarray
    child: int
    p_CM: np.ndarray
    R_CM: np.ndarray
    coordinates: list = field(default_factory=list)
    axes: list = field(default_factory=list)
    values: object = None


@dataclass
class OsimConstraint:
    """A WeldConstraint (two frames), PointConstraint (two points) or
    CoordinateCouplerConstraint (independent, dependent, function) to write."""

    name: str
    kind: str
    bodies: tuple = ()
    p: tuple = ()
    R: tuple = ()
    independent: str = ""
    dependent: str = ""
    function: tuple = ()


def _frame(model, qualified):
    f = model.frame(qualified)
    return model.body(f.body).index, np.asarray(f.p_BF, float), np.asarray(f.R_BF, float)


def _free_sets(rec):
    """(rotations "none" | "z" | "xyz", translation basis U (3, 3) in F, free columns,
    widened: True when the FDK rows free only some rotations and all three are given)."""
    fdk = set(rec.fdk_rows)
    rot = {"weld": set(), "prismatic": set(), "revolute": {"z"}}.get(rec.type, {"x", "y", "z"})
    rot |= {label[-1] for label in fdk if label in ("rx", "ry", "rz")}
    rot |= {"x" if label == "zy" else "y" for label in fdk if label in ("zx", "zy")}
    trans = {"prismatic": {2}, "point_on_plane": {0, 1}}.get(rec.type, set())
    trans |= {"xyz".index(label) for label in fdk if label in ("x", "y", "z")}
    U = _E
    if rec.type == "point_on_plane":
        n = np.asarray(rec.normal, float)
        helper = _E[int(np.argmin(np.abs(n)))]
        u = np.cross(helper, n)
        u /= np.linalg.norm(u)
        U = np.column_stack([u, np.cross(n, u), n])
        if "n" in fdk:
            trans.add(2)
    rotations = "none" if not rot else ("z" if rot == {"z"} else "xyz")
    return rotations, U, sorted(trans), rotations == "xyz" and rot != {"x", "y", "z"}


def _builtin(model, rec, parent, child):
    """The OsimJoint of a weld/revolute/spherical/prismatic/point_on_plane joint (with its
    FDK rows as free coordinates)."""
    rotations, U, trans, widened = _free_sets(rec)
    (ia, p_a, R_a), (ib, p_b, R_b) = _frame(model, parent), _frame(model, child)
    n = rec.name
    coords = []
    if rotations == "z":
        coords.append(OsimCoordinate(f"{n}_rz", "rotational"))
    elif rotations == "xyz":
        coords += [OsimCoordinate(f"{n}_r{a}", "rotational") for a in "xyz"]
    coords += [OsimCoordinate(f"{n}_t{'xyz'[k]}", "translational") for k in trans]

    def values(R_FM, p_FM, state):
        out = []
        if rotations == "z":
            out.append(np.arctan2(R_FM[1, 0], R_FM[0, 0]))
        elif rotations == "xyz":
            out += list(xyz_angles_from_matrix(R_FM))
        out += [float(U[:, k] @ p_FM) for k in trans]
        return np.array(out)

    identity = np.array_equal(U, _E)
    if not trans and rotations == "none":
        kind = "WeldJoint"
    elif not trans and rotations == "z":
        kind = "PinJoint"
    elif not trans and rotations == "xyz":
        kind = "BallJoint"
    elif trans == [0, 1, 2] and rotations == "xyz" and identity:
        kind = "FreeJoint"
    else:
        kind = "CustomJoint"
    axes = []
    if kind == "CustomJoint":
        rot_axes = {"none": [(_E[0], None), (_E[1], None), (_E[2], None)],
                    "z": [(_E[2], f"{n}_rz"), (_E[0], None), (_E[1], None)],
                    "xyz": [(_E[k], f"{n}_r{'xyz'[k]}") for k in range(3)]}[rotations]
        axes = [(a, q, _LINEAR if q else ("Constant", {"value": "0.0"})) for a, q in rot_axes]
        axes += [(U[:, k], f"{n}_t{'xyz'[k]}" if k in trans else None,
                  _LINEAR if k in trans else ("Constant", {"value": "0.0"})) for k in range(3)]
    joint = OsimJoint(n, kind, ia, p_a, R_a, ib, p_b, R_b, coords, axes, values)
    return joint, widened


def _custom(model, rec):
    """The CustomJoint of an OpenSim-style joint, or None when a function has no OpenSim
    class (:func:`~openfdk.io.osim_functions.function_xml`)."""
    (ia, p_a, R_a), (ib, p_b, R_b) = _frame(model, rec.parent), _frame(model, rec.child)
    axes, order = [], []
    for ax in tuple(rec.rotations) + tuple(rec.translations):
        if ax.coordinate is None:
            axes.append((np.asarray(ax.axis, float), None, ("Constant", {"value": repr(float(ax.function))})))
            continue
        xml = function_xml(ax.function)
        if xml is None:
            return None
        axes.append((np.asarray(ax.axis, float), ax.coordinate, xml))
        if ax.coordinate not in order:
            order.append(ax.coordinate)
    by_name = {c.name: c for c in model.coordinates}
    coords = []
    for q in order:
        c = by_name[q]
        prescribed = None
        if c.prescribed:
            driver = next((k for k in model.constraints if k.name == f"{q}_prescribed"), None)
            prescribed = getattr(getattr(driver, "function", None), "function", None)
        coords.append(OsimCoordinate(q, c.motion, c.locked, c.clamped,
                                     tuple(c.range) if np.all(np.isfinite(c.range)) else None, prescribed))
    measures = [by_name[q].measure for q in order]

    def values(R_FM, p_FM, state):
        return np.array([float(np.ravel(m.evaluate(state, 0)[0])[0]) for m in measures])

    return OsimJoint(rec.name, "CustomJoint", ia, p_a, R_a, ib, p_b, R_b, coords, axes, values)


def free_joint(model, body):
    """The FreeJoint ``<body>_free`` from ground of body index ``body``."""
    name = model.bodies[body].name
    coords = [OsimCoordinate(f"{name}_r{a}", "rotational") for a in "xyz"]
    coords += [OsimCoordinate(f"{name}_t{a}", "translational") for a in "xyz"]

    def values(R_FM, p_FM, state):
        return np.concatenate([xyz_angles_from_matrix(R_FM), p_FM])

    return OsimJoint(f"{name}_free", "FreeJoint", 0, np.zeros(3), _E, body, np.zeros(3), _E, coords, [], values)


def _reversed(rec):
    from dataclasses import replace

    return replace(rec, parent=rec.child, child=rec.parent)


def plan_joints(model):
    """(tree joints [OsimJoint] in parent-before-child order, constraints
    [OsimConstraint], notes {kind: [names]}) of ``model`` (module docstring)."""
    notes = {}
    placed = {0}
    joints = []
    for b in model.bodies[1:]:
        if b.fixed:  # welded to ground at its pose
            joints.append(OsimJoint(f"{b.name}_to_ground", "WeldJoint", 0, np.array(b.p_WB0, float),
                                    np.array(BodyStates([b.p_WB0], [b.quat_WB0], [-1]).R_WB[0]), b.index,
                                    np.zeros(3), _E))
            placed.add(b.index)
    records = [r for r in model.joints if r.type != "coupler"]
    pending = list(records)
    reversible = ("weld", "spherical", "revolute", "prismatic")

    def body_of(frame):
        return model.body(model.frame(frame).body).index

    while pending:
        step = next((r for r in pending if body_of(r.parent) in placed and body_of(r.child) not in placed), None)
        rec = step
        if step is None:
            step = next((r for r in pending if body_of(r.child) in placed and body_of(r.parent) not in placed), None)
            if step is None:
                break
            rec = _reversed(step) if step.type in reversible and not step.fdk_rows else None
        pending.remove(step)
        child = body_of(step.child if rec is not None else step.parent)
        joint = None
        if rec is not None and rec.type == "custom":
            joint = _custom(model, rec)
            if joint is None:
                notes.setdefault("approximated: joint with a function OpenSim has no class for (exported as a FreeJoint)",
                                 []).append(rec.name)
        elif rec is not None:
            joint, widened = _builtin(model, rec, rec.parent, rec.child)
            if widened:
                notes.setdefault("approximated: joint whose FDK rows free one or two rotations (exported with all three)",
                                 []).append(rec.name)
        else:
            notes.setdefault("approximated: joint reached from its child (exported as a FreeJoint)", []).append(step.name)
        if joint is None:
            joint = free_joint(model, child)
        joints.append(joint)
        placed.add(child)
    constraints = []
    for rec in pending:  # both bodies placed (a loop), or neither reachable from ground
        a, b = body_of(rec.parent), body_of(rec.child)
        if a in placed and b in placed and rec.type in ("weld", "spherical") and not rec.fdk_rows:
            (ia, p_a, R_a), (ib, p_b, R_b) = _frame(model, rec.parent), _frame(model, rec.child)
            constraints.append(OsimConstraint(rec.name, "WeldConstraint" if rec.type == "weld" else "PointConstraint",
                                              (ia, ib), (p_a, p_b), (R_a, R_b)))
        elif a in placed and b in placed:
            notes.setdefault(f"not exported: {rec.type} joint closing a loop", []).append(rec.name)
        else:
            pending_free = [x for x in (a, b) if x not in placed]
            for x in pending_free:
                joints.append(free_joint(model, x))
                placed.add(x)
            notes.setdefault("approximated: joint between bodies no joint path reaches from ground (bodies exported on "
                             "FreeJoints)", []).append(rec.name)
    for b in model.bodies[1:]:
        if b.index not in placed:
            joints.append(free_joint(model, b.index))
    for rec in model.joints:
        if rec.type == "coupler":
            xml = function_xml(rec.function)
            if xml is None:
                notes.setdefault("not exported: coupler with a function OpenSim has no class for", []).append(rec.name)
            else:
                constraints.append(OsimConstraint(rec.name, "CoordinateCouplerConstraint", independent=rec.independent,
                                                  dependent=rec.dependent, function=xml))
    return joints, constraints, notes


def joint_coordinates(joints, state):
    """{coordinate name: value} of every exported joint at ``state`` (BodyStates); rad, m."""
    out = {}
    for j in joints:
        if not j.coordinates:
            continue
        R_WF = state.R_WB[j.parent] @ j.R_PF
        p_WF = state.p_WB[j.parent] + state.R_WB[j.parent] @ j.p_PF
        R_WM = state.R_WB[j.child] @ j.R_CM
        p_WM = state.p_WB[j.child] + state.R_WB[j.child] @ j.p_CM
        v = j.values(R_WF.T @ R_WM, R_WF.T @ (p_WM - p_WF), state)
        out.update({c.name: float(x) for c, x in zip(j.coordinates, v)})
    return out
