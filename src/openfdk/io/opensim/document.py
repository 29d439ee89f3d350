"""An OpenSim model file (``.osim``, OpenSim 3.x or 4.x) read into plain records.

The XML is parsed by lxml with entity resolution and network access off; the reader
walks the elements it knows and lists every other element it meets. Both layouts are
read into the same records:

* OpenSim 4.x (``Version`` ≥ 40000): ``Ground``, ``BodySet``, ``JointSet`` (joints with
  ``socket_parent_frame``/``socket_child_frame`` naming ``PhysicalOffsetFrame``\\ s in the
  joint's ``frames``, the bodies' ``components`` or the model's ``components`` or
  ``ComponentSet``),
  ``ConstraintSet``, ``MarkerSet`` (``socket_parent_frame``), ``attached_geometry``;
* OpenSim 3.x (``Version`` < 40000): joints nested in the child body
  (``Body/Joint/CustomJoint`` with ``parent_body``, ``location_in_parent``,
  ``orientation_in_parent``, ``location``, ``orientation``), the ground a body named
  ``ground``, markers with ``body``, geometry as ``VisibleObject``/``DisplayGeometry``
  or ``geometry_files``.

ForceSet: ``Thelen2003Muscle`` and ``Millard2012EquilibriumMuscle`` (with its four curve
objects) with a GeometryPath of ``PathPoint``\\ s (4.x:
``socket_parent_frame``; 3.x: ``body``) is read into OsimMuscle records and a
Coordinate-, Point- or TorqueActuator into an ``actuators`` entry (:mod:`.actuators`); every other
force, and a muscle whose path holds anything but PathPoints, is listed as unsupported.

Units: OpenSim files are in m, kg, rad (``length_units`` other than meters is refused).
Orientations (``orientation``, ``orientation_in_parent``) are body-fixed X-Y-Z Euler
angles, rad. Nothing here builds an openfdk model: :mod:`openfdk.io.opensim.joints`
and :mod:`openfdk.io.opensim.to_model` do.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .errors import OsimError, where
from .upgrade import OLDEST_READ, upgraded_copy
from .functions import _NUMBER, FUNCTION_TAGS, function_element, function_spec

#: OpenSim joint types and their SpatialTransform (rotation axes, translation axes,
#: with the coordinate index of each axis or None): OpenSim's own definitions (Joint
#: classes' documentation; checked against OpenSim 4.6 in tests/test_opensim_import.py)
_X, _Y, _Z = (1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0)
JOINT_TRANSFORMS = {
    "PinJoint": (((_Z, 0), (_X, None), (_Y, None)), ((_X, None), (_Y, None), (_Z, None))),
    "SliderJoint": (((_X, None), (_Y, None), (_Z, None)), ((_X, 0), (_Y, None), (_Z, None))),
    "UniversalJoint": (((_X, 0), (_Y, 1), (_Z, None)), ((_X, None), (_Y, None), (_Z, None))),
    "GimbalJoint": (((_X, 0), (_Y, 1), (_Z, 2)), ((_X, None), (_Y, None), (_Z, None))),
    "BallJoint": (((_X, 0), (_Y, 1), (_Z, 2)), ((_X, None), (_Y, None), (_Z, None))),
    "FreeJoint": (((_X, 0), (_Y, 1), (_Z, 2)), ((_X, 3), (_Y, 4), (_Z, 5))),
    "PlanarJoint": (((_Z, 0), (_X, None), (_Y, None)), ((_X, 1), (_Y, 2), (_Z, None))),
    "WeldJoint": (((_X, None), (_Y, None), (_Z, None)), ((_X, None), (_Y, None), (_Z, None))),
}
JOINT_TYPES = ("CustomJoint",) + tuple(JOINT_TRANSFORMS)
CONSTRAINT_TYPES = ("CoordinateCouplerConstraint", "WeldConstraint", "PointConstraint", "ConstantDistanceConstraint",
                    "PointOnLineConstraint")
#: elements that carry no physics or kinematics (display settings, metadata)
_METADATA = {
    "credits", "publications", "length_units", "force_units", "assembly_accuracy", "defaults",
    "validatedMarkers", "FrameGeometry", "frame_geometry", "Appearance", "appearance", "VisibleObject",
    "gravity", "BodySet", "JointSet", "ConstraintSet", "MarkerSet", "Ground", "ComponentSet", "ContactGeometrySet",
    "ProbeSet", "ControllerSet", "ForceSet", "components", "attached_geometry",
}


@dataclass
class OsimFrame:
    """A frame: ``body`` (the frame it is attached to: a body, the ground or another
    frame, by its key in ``OsimDocument.frames``), X_BF as ``p_BF (3,) m`` and
    ``R_BF (3, 3)`` in that frame. Keys are scoped by their owner: a joint's or a body's
    PhysicalOffsetFrame is ``"owner/name"`` (OpenSim names them uniquely per owner only),
    bodies and the ground are their names."""

    name: str
    body: str
    p_BF: np.ndarray
    R_BF: np.ndarray
    line: int = 0


@dataclass
class OsimGeometry:
    """A display mesh: ``file`` as named in the model, on ``frame`` (an OsimFrame name
    or a body name), ``scale (3,)``."""

    file: str
    frame: str
    scale: np.ndarray
    p_FG: np.ndarray = field(default_factory=lambda: np.zeros(3))
    R_FG: np.ndarray = field(default_factory=lambda: np.eye(3))
    line: int = 0


@dataclass
class OsimBody:
    """mass kg, mass_center (3,) m in the body frame, inertia (3, 3) kg m² about the
    centre of mass in the body frame."""

    name: str
    mass: float
    mass_center: np.ndarray
    inertia: np.ndarray
    line: int = 0


@dataclass
class OsimCoordinate:
    """default (rad or m), range (2,), clamped, locked, prescribed (+ function spec of
    time), motion_type ("rotational", "translational", "coupled"; from the axes when the
    file does not say), joint name; opensim_motion: the motion type OpenSim 4 reports
    (:func:`opensim_motion_type`), which decides the unit of its ``.mot`` columns."""

    name: str
    joint: str
    default: float
    range: tuple
    clamped: bool
    locked: bool
    prescribed: bool
    prescribed_function: dict | None
    motion_type: str
    line: int = 0
    opensim_motion: str = ""  # OpenSim 4's motion type (opensim_motion_type), when it differs


@dataclass
class OsimAxis:
    """One TransformAxis: unit ``axis (3,)`` (normalised), ``coordinates`` (names),
    ``function`` (spec dict of :func:`openfdk.model.coordinate_functions.function_from_spec`)."""

    name: str
    axis: np.ndarray
    coordinates: tuple
    function: dict
    line: int = 0


@dataclass
class OsimJoint:
    """A joint: ``type`` (OpenSim class), ``parent``/``child`` frame names (OsimFrame),
    ``coordinates`` (names, in the joint's order), ``rotations`` and ``translations``
    (3 OsimAxis each, OpenSim's SpatialTransform)."""

    name: str
    type: str
    parent: str
    child: str
    coordinates: tuple
    rotations: tuple
    translations: tuple
    line: int = 0


@dataclass
class OsimConstraint:
    """A constraint: CoordinateCouplerConstraint (``independent``, ``dependent``,
    ``function``), WeldConstraint (``frames``), PointConstraint (``frames``: two
    frames whose origins coincide), ConstantDistanceConstraint (``frames``: two frames
    whose origins stay ``value`` m apart) or PointOnLineConstraint (``frames``: a frame
    on the line body at ``point_on_line`` whose x axis is the line's direction, and one
    at the follower's point, which stays on that x axis)."""

    name: str
    type: str
    independent: tuple = ()
    dependent: str = ""
    function: dict | None = None
    frames: tuple = ()
    line: int = 0
    value: float = 0.0


@dataclass
class OsimMarker:
    name: str
    body: str
    location: np.ndarray
    frame: str = ""
    line: int = 0


#: the muscle classes read from the ForceSet (every other force is refused by name)
MUSCLE_TYPES = ("Thelen2003Muscle", "Millard2012EquilibriumMuscle", "Millard2012AccelerationMuscle",
                "RigidTendonMuscle", "Schutte1993Muscle_Deprecated")
#: Blankevoort1991Ligament properties and OpenSim 4.6's defaults (slack_length has none)
LIGAMENT_DEFAULTS = {"linear_stiffness": 1.0, "slack_length": 0.0, "transition_strain": 0.06,
                     "damping_coefficient": 0.003}
_LIGAMENT_PROPERTIES = set(LIGAMENT_DEFAULTS) | {"appliesForce", "isDisabled", "GeometryPath", "components",
                                                 "Appearance"}
#: Thelen2003Muscle properties and OpenSim 4.6's defaults (a property absent from the
#: file has its default, as OpenSim reads it)
THELEN_DEFAULTS = {
    "max_isometric_force": 1000.0, "optimal_fiber_length": 0.1, "tendon_slack_length": 0.2,
    "pennation_angle_at_optimal": 0.0, "max_contraction_velocity": 10.0, "FmaxTendonStrain": 0.04,
    "FmaxMuscleStrain": 0.6, "KshapeActive": 0.45, "KshapePassive": 5.0, "Af": 0.25, "Flen": 1.4,
    # read and reported, not used by openfdk's recruitment (docs/opensim-import.md)
    "min_control": 0.01, "max_control": 1.0, "optimal_force": 1.0, "default_activation": 0.05,
    "default_fiber_length": 0.1, "fv_linear_extrap_threshold": 0.95, "maximum_pennation_angle": 1.4706289056333368,
    "activation_time_constant": 0.015, "deactivation_time_constant": 0.05, "minimum_activation": 0.01,
}
#: Millard2012EquilibriumMuscle properties and OpenSim 4.6's defaults (Muscle's, and the
#: Millard muscle's own constructProperties; min_control defaults to minimum_activation)
MILLARD_DEFAULTS = {
    "max_isometric_force": 1000.0, "optimal_fiber_length": 0.1, "tendon_slack_length": 0.2,
    "pennation_angle_at_optimal": 0.0, "max_contraction_velocity": 10.0,
    "maximum_pennation_angle": 1.4706289056333368, "fiber_damping": 0.1, "minimum_activation": 0.01,
    # read and reported, not used by openfdk's recruitment (docs/opensim-import.md)
    "min_control": 0.01, "max_control": 1.0, "optimal_force": 1.0, "default_activation": 0.05,
    "default_fiber_length": 0.1, "activation_time_constant": 0.01, "deactivation_time_constant": 0.04,
}
#: Millard2012AccelerationMuscle properties and OpenSim 4.6's defaults (its own
#: constructProperties; min_control of Muscle is 0)
ACCELERATION_DEFAULTS = {
    "max_isometric_force": 1000.0, "optimal_fiber_length": 0.1, "tendon_slack_length": 0.2,
    "pennation_angle_at_optimal": 0.0, "max_contraction_velocity": 10.0, "fiber_damping": 0.01,
    # read and reported, not used by openfdk's recruitment (docs/opensim-import.md)
    "min_control": 0.0, "max_control": 1.0, "optimal_force": 1.0, "default_activation": 0.0,
    "default_fiber_length": 0.1, "default_fiber_velocity": 0.0, "mass": 0.1, "tendon_force_length_damping": 0.1,
    "fiber_compressive_force_length_damping": 1.0, "fiber_force_length_damping": 0.01,
    "fiber_compressive_force_cos_pennation_damping": 1.0,
}
#: the acceleration muscle's objects read and reported only (compressive curves act at
#: l̃ < 0.5 or pennation > 85°; the activation model is a simulation setting)
ACCELERATION_REPORTED = {
    "FiberCompressiveForceLengthCurve": ("norm_length_at_zero_force", "stiffness_at_zero_length", "curviness"),
    "FiberCompressiveForceCosPennationCurve": ("engagement_angle_in_degrees", "stiffness_at_perpendicular",
                                               "curviness"),
    "MuscleFirstOrderActivationDynamicModel": ("activation_time_constant", "deactivation_time_constant",
                                               "minimum_activation"),
}
#: RigidTendonMuscle and Schutte1993Muscle_Deprecated properties and OpenSim 4.6's defaults
CURVE_MUSCLE_DEFAULTS = {
    "RigidTendonMuscle": {
        "max_isometric_force": 1000.0, "optimal_fiber_length": 0.1, "tendon_slack_length": 0.2,
        "pennation_angle_at_optimal": 0.0, "max_contraction_velocity": 10.0,
        "min_control": 0.0, "max_control": 1.0, "optimal_force": 1.0},
    "Schutte1993Muscle_Deprecated": {
        "max_isometric_force": 1000.0, "optimal_fiber_length": 0.1, "tendon_slack_length": 0.2,
        "pennation_angle_at_optimal": 0.0, "max_contraction_velocity": 10.0, "time_scale": 0.1, "damping": 0.1,
        "activation1": 7.667, "activation2": 1.459854,
        "min_control": 0.0, "max_control": 1.0, "optimal_force": 1.0},
}
#: their curve properties (each holds one OpenSim Function; absent: OpenSim's default)
CURVE_MUSCLE_FUNCTIONS = {
    "RigidTendonMuscle": ("active_force_length_curve", "passive_force_length_curve", "force_velocity_curve"),
    "Schutte1993Muscle_Deprecated": ("active_force_length_curve", "passive_force_length_curve",
                                     "tendon_force_length_curve"),
}
#: the Millard muscle's curve objects and their properties (absent: OpenSim's default,
#: applied by :mod:`openfdk.forces.millard_curves`)
MILLARD_CURVES = {
    "ActiveForceLengthCurve": ("min_norm_active_fiber_length", "transition_norm_fiber_length",
                               "max_norm_active_fiber_length", "shallow_ascending_slope", "minimum_value"),
    "ForceVelocityCurve": ("concentric_slope_at_vmax", "concentric_slope_near_vmax", "isometric_slope",
                           "eccentric_slope_at_vmax", "eccentric_slope_near_vmax",
                           "max_eccentric_velocity_force_multiplier", "concentric_curviness", "eccentric_curviness"),
    "FiberForceLengthCurve": ("strain_at_zero_force", "strain_at_one_norm_force", "stiffness_at_low_force",
                              "stiffness_at_one_norm_force", "curviness"),
    "TendonForceLengthCurve": ("strain_at_one_norm_force", "stiffness_at_one_norm_force", "norm_force_at_toe_end",
                               "curviness"),
}
#: OpenSim 3.x Millard curves that OpenSim 4.x no longer has (it drops them on reading)
MILLARD_DROPPED = {"FiberCompressiveForceLengthCurve", "FiberCompressiveForceCosPennationCurve"}
#: Thelen2003Muscle's own properties, left in a Millard2012EquilibriumMuscle when a model's
#: muscles were retyped (OpenSim's walk_gait1018_subject01.osim): OpenSim 4.6 has no such
#: property on the Millard muscle and ignores them (its tendon strain stays 0.049 under
#: <FmaxTendonStrain>0.033</FmaxTendonStrain>); openfdk too, with a warning
THELEN_ONLY = {"FmaxTendonStrain", "FmaxMuscleStrain", "KshapeActive", "KshapePassive", "Af", "Flen",
               "fv_linear_extrap_threshold"}
#: children of a curve object that carry no physics
_CURVE_METADATA = {"components"}
#: boolean properties of a muscle, read and reported
_MUSCLE_FLAGS = {"ignore_tendon_compliance": False, "ignore_activation_dynamics": False}
#: muscle children that carry no physics (display, empty component lists)
_MUSCLE_METADATA = {"components", "appliesForce", "isDisabled", "GeometryPath", "Appearance", "time_scale"}
_PATH_METADATA = {"PathPointSet", "PathWrapSet", "Appearance", "default_color", "display", "components",
                  "VisibleObject"}
_POINT_METADATA = {"socket_parent_frame", "body", "Appearance", "display", "components"}
#: the path points read, with their properties (OpenSim 4.x and 3.x names)
_PATH_POINT_PROPERTIES = {
    "PathPoint": _POINT_METADATA | {"location"},
    "ConditionalPathPoint": _POINT_METADATA | {"location", "range", "socket_coordinate", "coordinate"},
    "MovingPathPoint": _POINT_METADATA | {"location", "socket_x_coordinate", "socket_y_coordinate",
                                          "socket_z_coordinate", "x_coordinate", "y_coordinate", "z_coordinate",
                                          "x_location", "y_location", "z_location", "XAttachment", "YAttachment",
                                          "ZAttachment"},
}


@dataclass
class OsimPathPoint:
    """A PathPoint: ``location (3,)`` m in ``frame`` (an OsimFrame key once resolved).
    A ConditionalPathPoint has ``condition`` (coordinate, lo, hi) (rad or m); a
    MovingPathPoint has ``moving`` (coordinate or None, (spec_x, spec_y, spec_z)): each a
    function dict of the coordinate (m), ``location`` unused."""

    name: str
    frame: str
    location: np.ndarray
    line: int = 0
    condition: tuple = None
    moving: tuple = None


#: OpenSim wrap objects read (others are refused by name)
WRAP_TYPES = {"WrapCylinder": "cylinder", "WrapSphere": "sphere", "WrapEllipsoid": "ellipsoid", "WrapTorus": "torus"}
#: OpenSim's spellings of a WrapObject's ``quadrant`` -> (axis, sign); (None, 0): all
QUADRANTS = {**{q: (None, 0) for q in ("all", "ALL", "All", "Unassigned")},
             **{f"{s}{a}": ("xyz".index(a.lower()), -1 if s == "-" else 1)
                for a in "xyzXYZ" for s in ("", "+", "-")}}
#: the ellipsoid methods of a PathWrap (OpenSim's spellings)
WRAP_METHODS = {m: m.lower() for base in ("hybrid", "midpoint", "axial")
                for m in (base, base.capitalize(), base.upper())}
_WRAP_PROPERTIES = {"active", "xyz_body_rotation", "translation", "quadrant", "Appearance", "display_preference",
                    "color", "VisibleObject", "components"}
_WRAP_DIMENSIONS = {"WrapCylinder": {"radius", "length"}, "WrapSphere": {"radius"}, "WrapEllipsoid": {"dimensions"},
                    "WrapTorus": {"inner_radius", "outer_radius"}}


@dataclass
class OsimWrapObject:
    """A WrapCylinder, WrapSphere or WrapEllipsoid: on ``frame`` (the body or frame whose
    WrapObjectSet holds it), at ``p_FS (3,)`` m, axes ``R_FS (3, 3)`` (``translation``,
    ``xyz_body_rotation``); ``quadrant`` (axis 0–2 or None, sign ±1 or 0); ``active``;
    ``radius`` m (cylinder, sphere; a torus's ``inner_radius``, its tube), ``length`` m
    (cylinder; a torus's ``outer_radius``, its centre circle), ``dimensions (3,)`` m
    (ellipsoid semi-axes)."""

    name: str
    type: str
    frame: str
    p_FS: np.ndarray
    R_FS: np.ndarray
    quadrant: tuple
    quadrant_text: str
    active: bool
    radius: float = 0.0
    length: float = 0.0
    dimensions: np.ndarray = None
    line: int = 0


@dataclass
class OsimPathWrap:
    """A PathWrap of a GeometryPath: ``wrap_object`` (name), ``method`` (hybrid, midpoint
    or axial: OpenSim's ellipsoid approximation; openfdk computes the geodesic),
    ``range`` (first, last) 1-based PathPointSet indices, −1 (< 1): the path's end."""

    name: str
    wrap_object: str
    method: str
    range: tuple
    line: int = 0


@dataclass
class OsimMuscle:
    """A muscle of the ForceSet: ``type`` (OpenSim class), ``points`` (OsimPathPoint,
    in the path's order), ``parameters`` {OpenSim property: value} (every property of
    THELEN_DEFAULTS or MILLARD_DEFAULTS and the flags, the file's value or OpenSim's
    default; a Millard muscle's curves as {curve tag: {property: value}}, only the
    properties the file gives)."""

    name: str
    type: str
    points: list
    parameters: dict
    line: int = 0
    wraps: list = field(default_factory=list)  # OsimPathWrap, in the PathWrapSet's order


@dataclass
class OsimDocument:
    """The records of one model file (see the module docstring)."""

    source: str
    path: Path
    name: str
    version: int
    gravity: np.ndarray
    bodies: dict
    frames: dict
    joints: list
    coordinates: dict
    constraints: list
    markers: list
    geometry: list
    unsupported: list  # (type, name, line) of elements openfdk does not read
    ignored: list = field(default_factory=list)  # the same, left out on request (--ignore)
    muscles: list = field(default_factory=list)  # OsimMuscle, in the ForceSet's order
    actuators: dict = field(default_factory=dict)  # CoordinateActuators {name: actuators-section entry}
    wrap_objects: dict = field(default_factory=dict)  # OsimWrapObject {name: record}
    springs: dict = field(default_factory=dict)  # SpringGeneralizedForces {name: springs-section entry}
    ligaments: list = field(default_factory=list)  # Blankevoort1991Ligaments (OsimMuscle records), in order
    contact_meshes: dict = field(default_factory=dict)  # Smith2018ContactMesh records {name: dict}
    contact_forces: dict = field(default_factory=dict)  # Smith2018ArticularContactForce records {name: dict}
    element_types: frozenset = frozenset()  # every element tag in the <Model> (--ignore's hints)


def _parser():
    from lxml import etree

    return etree.XMLParser(resolve_entities=False, no_network=True, huge_tree=False, remove_comments=True,
                           remove_pis=True)


def read_document(path, ignore=()) -> OsimDocument:
    """Read ``path`` (an ``.osim``) into an OsimDocument; ``ignore``: element types (tag
    names, or ``forces`` for the ForceSet and wrap objects) to leave out, listed in
    ``OsimDocument.ignored``. Raises OsimError (one line naming file, line, element)."""
    path = Path(path)
    source = path.name
    root = parse_xml(path, source).getroot()
    if root.tag != "OpenSimDocument":
        raise OsimError(f"{source}: line {root.sourceline}: the root element is <{root.tag}>, not <OpenSimDocument>: "
                        "not an OpenSim model")
    try:
        version = int(root.get("Version", "0"))
    except ValueError:
        raise OsimError(f"{source}: line {root.sourceline}: OpenSimDocument Version {_clip(root.get('Version'))!r} is not "
                        "a number") from None
    if version < OLDEST_READ:                      # OpenSim 1.x, 2.x: OpenSim upgrades it
        import tempfile
        import warnings

        from ...model.plausibility import PlausibilityWarning

        with tempfile.TemporaryDirectory(prefix="openfdk-osim-") as folder:
            new, opensim_version = upgraded_copy(path, version, Path(folder), source)
            source = f"{source} (as OpenSim {opensim_version} upgrades it)"
            root = parse_xml(new, source).getroot()
        warnings.warn(f"{path.name}: OpenSimDocument Version {version} (OpenSim {version // 10000}.x): read as "
                      f"OpenSim {opensim_version} upgrades it; line numbers in messages are the upgraded file's",
                      PlausibilityWarning, stacklevel=2)
        version = int(root.get("Version", "0"))
    model = root.find("Model")
    if model is None:
        raise OsimError(f"{source}: line {root.sourceline}: no <Model> in the OpenSimDocument")
    reader = _Reader(source, path, set(ignore))
    doc = reader.read(model, version)
    doc.element_types = frozenset(e.tag for e in model.iter() if isinstance(e.tag, str))
    return doc


def parse_xml(path, source):
    """The lxml tree of the XML file ``path`` (an .osim or an OpenSim setup file), or
    OsimError naming ``source``: the file must be a regular file (not a FIFO or a device,
    which would block or never end), be at most :data:`openfdk.io.limits.INPUT_FILE_BYTES`
    (checked before parsing) and have no DOCTYPE (OpenSim writes none; its entities,
    unexpanded here, would silently drop or change values)."""
    import os
    import stat

    from lxml import etree

    from .. import limits

    try:
        st = os.stat(path)
        if not stat.S_ISREG(st.st_mode):
            raise OsimError(f"{source}: cannot read the file (not a regular file)")
        limits.check_count(st.st_size, "INPUT_FILE_BYTES", source, "", "bytes", OsimError)
        tree = etree.parse(str(path), _parser())
    except OSError as exc:
        if "encoding" not in str(exc) or not Path(path).is_file():
            raise OsimError(f"{source}: cannot read the file ({exc.strerror or exc})") from None
        # libxml2 reports bytes that are not UTF-8 as an I/O error
        from types import SimpleNamespace

        bad = _as_utf8(Path(path).read_bytes())[1]
        tree = _parse_as_opensim(path, source, SimpleNamespace(msg="bytes that are not UTF-8",
                                                               lineno=bad[0] if bad else 1))
    except etree.XMLSyntaxError as exc:
        from ..placeholders import placeholder_of_file

        if (why := placeholder_of_file(path)) is not None:
            raise OsimError(f"{source}: {why}") from None
        tree = _parse_as_opensim(path, source, exc)
    if tree.docinfo.doctype:
        raise OsimError(f"{source}: has a DOCTYPE declaration ({_clip(tree.docinfo.doctype)}); OpenSim files have "
                        "none (refused: its entities could hide or change values)")
    return tree


#: an '&' that starts no entity or character reference ('&amp;', '&#38;', '&#x26;')
_BARE_AMPERSAND = re.compile(rb"&(?![A-Za-z_:][\w.:-]*;|#[0-9]+;|#x[0-9A-Fa-f]+;)")
#: comments and CDATA sections, where '&' is text
_VERBATIM = re.compile(rb"<!--.*?-->|<!\[CDATA\[.*?\]\]>", re.S)
#: a tag name with OpenSim's '::' (``<HuntCrossleyForce::ContactParametersSet``), which
#: XML reads as an undeclared namespace prefix; group 1 the '<' or '</'
_SCOPED_TAG = re.compile(rb"(</?)([A-Za-z_][\w.-]*)::(?=[A-Za-z_])")
#: what '::' becomes in such a tag name
SCOPE = "__"


def _parse_as_opensim(path, source, error):
    """The tree of ``path`` whose only XML errors are two that OpenSim's parser accepts:

    * an '&' written bare in text (e.g. "Smith, C. R., & Thelen, D. G." in jam-resources'
      full_body_healthy_knee.osim), read as the character '&' with a warning naming the
      lines;
    * a tag name with '::', as OpenSim writes a contact force's parameters
      (``<HuntCrossleyForce::ContactParametersSet>`` in opensim-models' BouncingBlock,
      ToyLanding, Jumper, SoccerKick and WalkerModel), read with '::' as :data:`SCOPE`
      (``HuntCrossleyForce__ContactParametersSet``).

    Any other syntax error, or one left after these, is OsimError with the file's line."""
    import warnings

    from lxml import etree

    from ...model.plausibility import PlausibilityWarning

    data = Path(path).read_bytes()
    data, recoded = _as_utf8(data)
    # a comment may hold a bare '&' or a '::' (and a CDATA section any text): those stay
    kept = [m.span() for m in _VERBATIM.finditer(data)]

    def outside(matches):
        return [m for m in matches if not any(a <= m.start() < b for a, b in kept)]

    bare = [m.start() for m in outside(_BARE_AMPERSAND.finditer(data))]
    scoped = outside(_SCOPED_TAG.finditer(data))
    if not bare and not scoped and not recoded:
        raise OsimError(f"{source}: not well-formed XML: {error.msg} (line {error.lineno})") from None
    if recoded:
        warnings.warn(f"{source}: {_lines(recoded)}: bytes that are not UTF-8, read as Windows-1252 text "
                      "(as OpenSim reads the file)", PlausibilityWarning, stacklevel=3)
    edits = sorted([(i, i + 1, b"&amp;") for i in bare] +
                   [(m.end() - 2, m.end(), SCOPE.encode()) for m in scoped])  # (start, end, replacement)
    pieces, at = [], 0
    for a, b, text in edits:
        pieces += [data[at:a], text]
        at = b
    try:
        tree = etree.ElementTree(etree.fromstring(b"".join(pieces) + data[at:], _parser()))
    except etree.XMLSyntaxError:  # the first error stands (the lines are the file's)
        raise OsimError(f"{source}: not well-formed XML: {error.msg} (line {error.lineno})") from None
    if not bare:
        return tree
    lines = sorted({data.count(b"\n", 0, i) + 1 for i in bare})
    warnings.warn(f"{source}: {_lines(lines)}: '&' not written '&amp;' (XML's escape); "
                  "read as the character '&', as OpenSim reads the file", PlausibilityWarning, stacklevel=3)
    return tree


def _lines(numbers):
    """'line 5' or 'lines 3, 8, … and 4 more' for a message."""
    shown = ", ".join(map(str, numbers[:5])) + (f" and {len(numbers) - 5} more" if len(numbers) > 5 else "")
    return f"line{'s' if len(numbers) > 1 else ''} {shown}"


#: an XML declaration's encoding
_ENCODING = re.compile(rb"""^\s*<\?xml[^>]*encoding\s*=\s*["']([A-Za-z0-9._-]+)["']""")


def _as_utf8(data):
    """(``data`` as UTF-8, the line numbers that were not UTF-8): a file declared UTF-8
    (or undeclared) whose text holds Windows-1252 bytes (an en dash 0x96 in the
    publications of opensim-core's subject1_abdbonepin.osim) is read as that encoding,
    as OpenSim's parser reads it; other files are returned as they are."""
    declared = _ENCODING.match(data)
    if declared and declared.group(1).lower().replace(b"_", b"-") not in (b"utf-8", b"utf8"):
        return data, []
    try:
        data.decode("utf-8")
        return data, []
    except UnicodeDecodeError:
        pass
    lines, out = [], []
    for k, line in enumerate(data.split(b"\n"), start=1):
        try:
            out.append(line.decode("utf-8"))
        except UnicodeDecodeError:
            lines.append(k)
            try:
                out.append(line.decode("cp1252"))
            except UnicodeDecodeError:               # 0x81, 0x8D, 0x8F, 0x90, 0x9D
                out.append(line.decode("latin-1"))
    return "\n".join(out).encode("utf-8"), lines


def _clip(text, n=80):
    """``text`` cut to ``n`` characters for a message."""
    text = str(text)
    return text if len(text) <= n else f"{text[:n]}… ({len(text)} characters)"


def numbers(element, source, n=None, what=None):
    """The whitespace-separated numbers of an element's text -> float array; ``n``: the
    count required. Errors name the element and its line. Numbers are decimal as OpenSim
    writes them (no '1_000', hexadecimal or non-ASCII digits, which Python's float reads)."""
    text = (element.text or "").split()
    if not all(_NUMBER.match(x) or x.lower().lstrip("+-") in ("nan", "inf", "infinity") for x in text):
        raise OsimError(f"{where(source, element, what)}: expected numbers, got {_clip(element.text)!r}")
    arr = np.array([float(x) for x in text])
    if n is not None and arr.shape != (n,):
        raise OsimError(f"{where(source, element, what)}: expected {n} numbers, got {len(arr)}")
    if not np.all(np.isfinite(arr)):
        raise OsimError(f"{where(source, element, what)}: non-finite number in {_clip(element.text)!r}")
    return arr


def _constant_value(spec):
    """The value of a function spec that is constant everywhere (a MultiplierFunction of a
    Constant, a degree-0 polynomial, …), else None."""
    from ...model.coordinate_functions import function_from_spec

    def error(path, msg):
        return OsimError(f"{path}: {msg}")

    f = function_from_spec(spec, "function", error)
    if f.n_pieces == 0 and np.array_equal(f.left, f.right) and not np.any(f.left[1:]):
        return float(f.left[0])
    return None


def opensim_motion_type(rotations, translations, coordinate):
    """The motion type OpenSim 4 gives a CustomJoint's coordinate (CustomJoint's
    constructCoordinates): over rotation1–3 then translation1–3, an axis that is a
    LinearFunction of it with slope ±1 makes it rotational or translational (a later such
    axis wins); any other function of it makes it coupled unless an axis already made it
    pure. OpenSim converts only rotational coordinates between degrees and radians (the
    ``.mot`` files' ``inDegrees``, CoordinateLimitForce's limits); a coupled one's values
    are in rad or m as they are."""
    motion = ""
    for kind, axes in (("rotational", rotations), ("translational", translations)):
        for ax in axes:
            if coordinate not in ax.coordinates:
                continue
            f = ax.function
            if f.get("type") == "linear" and abs(float(f.get("slope", 0.0))) == 1.0:
                motion = kind
            elif not motion:
                motion = "coupled"
    return motion or "coupled"


def in_degrees(entry):
    """Whether OpenSim gives a coordinate in degrees where its files say so (a ``.mot``'s
    ``inDegrees=yes``, CoordinateLimitForce's limits): only a rotational one, not a coupled
    one. ``entry``: the coordinate's mapping of the model file (``motion`` and, where
    OpenSim's differs, ``opensim_motion``)."""
    return entry.get("opensim_motion", entry.get("motion", "rotational")) == "rotational"


def _affine_in(axis, coordinate):
    """Whether the OsimAxis ``axis`` is an affine function of ``coordinate`` with a
    non-zero slope (a LinearFunction, a MultiplierFunction of one, …)."""
    from ...model.coordinate_functions import function_from_spec
    from ...model.coordinate_joint import affine

    if coordinate not in axis.coordinates:
        return False
    line = affine(function_from_spec(axis.function, axis.name, lambda path, msg: OsimError(f"{path}: {msg}")))
    return line is not None and line[0] != 0.0


def _basis_with_x(direction):
    """(3, 3) rotation whose first column is ``direction`` normalised (the other two
    complete a right-handed basis; which ones does not matter to a line)."""
    x = np.asarray(direction, float) / np.linalg.norm(direction)
    helper = np.eye(3)[int(np.argmin(np.abs(x)))]
    y = np.cross(x, helper)
    y /= np.linalg.norm(y)
    return np.column_stack((x, y, np.cross(x, y)))


def rotation_xyz(angles):
    """R = Rx(a0) Ry(a1) Rz(a2): body-fixed X-Y-Z Euler angles (rad) -> (3, 3)."""
    out = np.eye(3)
    for k, a in enumerate(angles):
        c, s = np.cos(a), np.sin(a)
        i, j = (k + 1) % 3, (k + 2) % 3
        R = np.eye(3)
        R[i, i], R[i, j], R[j, i], R[j, j] = c, -s, s, c
        out = out @ R
    return out


class _Reader:
    def __init__(self, source, path, ignore):
        self.source = source
        self.path = path
        self.ignore = ignore
        self.bodies, self.frames, self.coordinates = {}, {}, {}
        self.joints, self.constraints, self.markers, self.geometry = [], [], [], []
        self.muscles = []
        self.actuators = {}
        self.springs = {}
        self.ligaments = []
        self.contact_meshes = {}
        self.contact_forces = {}
        self.wrap_objects = {}
        self.unsupported, self.ignored = [], []
        self.inert = {}  # {property: [muscle]}: properties OpenSim has not on that muscle and ignores
        self.pending = []  # (frame key, socket path, scope): frames whose parent is resolved after reading
        self.joint_sockets = []  # (joint, parent path, child path, scope)
        self.seen = set()  # (kind, name) of the joints, constraints and markers: each name once

    # -- small helpers ----------------------------------------------------------------
    def err(self, element, msg, what=None):
        return OsimError(f"{where(self.source, element, what)}: {msg}")

    def once(self, element, kind, name):
        """Refuse a second joint, constraint or marker of the same name (OpenSim's
        names are unique within a set; openfdk would keep one of them)."""
        if (kind, name) in self.seen:
            raise self.err(element, f"a second {kind} named {name!r}")
        self.seen.add((kind, name))

    def child_numbers(self, element, tag, n, default=None):
        e = element.find(tag)
        if e is None or not (e.text or "").strip():
            if default is None:
                raise self.err(element, f"missing <{tag}>")
            return np.array(default, dtype=float)
        return numbers(e, self.source, n, f"{element.tag} {element.get('name')!r} <{tag}>"
                       if element.get("name") else f"{element.tag} <{tag}>")

    def child_text(self, element, tag, default=None):
        e = element.find(tag)
        if e is None or e.text is None or not e.text.strip():
            if default is None:
                raise self.err(element, f"missing <{tag}>")
            return default
        return e.text.strip()

    def child_bool(self, element, tag, default):
        text = self.child_text(element, tag, "")
        if text == "":
            return default
        if text.lower() not in ("true", "false"):
            raise self.err(element, f"<{tag}> must be true or false, got {text!r}")
        return text.lower() == "true"

    def skip(self, element, kind=None, name=None):
        """An element openfdk does not read: ignored on request, else listed."""
        kind = kind or element.tag
        entry = (kind, name or element.get("name") or "", element.sourceline)
        if kind in self.ignore or ("forces" in self.ignore and (kind == "ForceSet" or kind.startswith("Wrap"))):
            self.ignored.append(entry)
        else:
            self.unsupported.append(entry)

    @staticmethod
    def objects(element):
        """The children of a Set's <objects> (or of the element itself)."""
        if element is None:
            return []
        objs = element.find("objects")
        return list(objs) if objs is not None else list(element)

    @staticmethod
    def last(path):
        """The component name at the end of an OpenSim path ('/bodyset/femur_r' -> 'femur_r')."""
        return path.rstrip("/").split("/")[-1] if path else path

    # -- the model --------------------------------------------------------------------
    def read(self, model, version):
        name = model.get("name") or self.path.stem
        units = self.child_text(model, "length_units", "meters")
        # 'Unassigned': OpenSim's Units default, no unit declared (its test models): meters,
        # as OpenSim computes in them whatever the property says
        if units.lower() not in ("meters", "m", "unassigned"):
            raise self.err(model.find("length_units"), f"length unit {units!r}: openfdk reads OpenSim models in meters")
        gravity = self.child_numbers(model, "gravity", 3, [0.0, -9.80665, 0.0])
        legacy = version < 40000
        ground = model.find("Ground")
        if ground is not None:  # a frame of its own: joints and markers may name "/ground" directly
            self.add_frame(OsimFrame("ground", "ground", np.zeros(3), np.eye(3), ground.sourceline), ground)
            self.body_geometry(ground, "ground")
            self.read_wrap_objects(ground, "ground")
        self.bodies_ground = "ground" if ground is None else (ground.get("name") or "ground")
        for body in self.objects(model.find("BodySet")):
            if body.tag != "Body":
                self.skip(body)
                continue
            self.read_body(body, legacy)
        if not legacy:
            for joint in self.objects(model.find("JointSet")):
                self.read_joint(joint, legacy=False)
        # model-level components: <components> (what Model::addComponent writes) and the
        # older <ComponentSet>
        for comp in self.objects(model.find("ComponentSet")) + self.objects(model.find("components")):
            if comp.tag == "PhysicalOffsetFrame":
                self.read_offset_frame(comp)
            else:
                self.skip(comp)
        for c in self.objects(model.find("ConstraintSet")):
            self.read_constraint(c, legacy)
        for m in self.objects(model.find("MarkerSet")):
            self.read_marker(m, legacy)
        from .actuators import ACTUATOR_TYPES, read_actuator  # (imports this module)
        from .passive_forces import PASSIVE_TYPES, read_spring
        from .contact import FORCE_TYPE as CONTACT_FORCE, MESH_TYPE as CONTACT_MESH, read_contact_force, \
            read_contact_mesh

        # ForceSet elements read into one record each: tag -> (kind, reader, store)
        readers = {CONTACT_FORCE: ("contact force", read_contact_force, self.contact_forces)}
        readers.update({t: ("spring", read_spring, self.springs) for t in PASSIVE_TYPES})
        readers.update({t: ("actuator", read_actuator, self.actuators) for t in ACTUATOR_TYPES})
        for tag in ("ForceSet", "ContactGeometrySet", "ProbeSet", "ControllerSet"):
            for e in self.objects(model.find(tag)):
                if tag == "ForceSet" and "forces" in self.ignore:
                    self.ignored.append((e.tag, e.get("name") or "", e.sourceline))
                elif tag == "ForceSet" and e.tag in MUSCLE_TYPES and e.tag not in self.ignore:
                    self.read_muscle(e, legacy)
                elif tag == "ForceSet" and e.tag == "Blankevoort1991Ligament" and e.tag not in self.ignore:
                    self.read_ligament(e, legacy)
                elif tag == "ContactGeometrySet" and e.tag == CONTACT_MESH and e.tag not in self.ignore:
                    mesh_name, record = read_contact_mesh(e, self.source)  # (``name`` is the model's)
                    self.once(e, "contact mesh", mesh_name)
                    self.contact_meshes[mesh_name] = record
                elif tag == "ForceSet" and e.tag in readers and e.tag not in self.ignore:
                    kind, read, store = readers[e.tag]
                    force_name, entry = read(e, self.source)
                    if entry is None:
                        self.ignored.append((e.tag, force_name, e.sourceline))  # disabled: OpenSim skips it too
                    else:
                        self.once(e, kind, force_name)
                        store[force_name] = entry
                else:
                    self.skip(e)
        for e in model:
            if not isinstance(e.tag, str):
                continue
            if e.tag not in _METADATA:
                self.skip(e)
        for key, path, scope in self.pending:
            self.frames[key].body = self.resolve(path, scope)
        for j, scope in self.joint_sockets:
            j.parent, j.child = self.resolve(j.parent, scope), self.resolve(j.child, scope)
        for m in self.markers:
            m.frame = m.body = self.resolve(m.frame)
        for mesh_name, mesh in self.contact_meshes.items():
            mesh["frame"] = self.resolve(mesh["path"])
            if mesh["frame"] not in self.frames and mesh["frame"] != "ground":
                raise OsimError(f"{self.source}: line {mesh['line']}: Smith2018ContactMesh {mesh_name!r}: frame "
                                f"{mesh['path']!r} is neither a body nor a frame of the model")
        for force_name, force in self.contact_forces.items():
            for key in ("target", "casting"):
                if force[key] not in self.contact_meshes:
                    raise OsimError(f"{self.source}: line {force['line']}: Smith2018ArticularContactForce {force_name!r}: "
                                    f"no Smith2018ContactMesh {force[key]!r} (its {key} mesh)")
        for mu in self.muscles + self.ligaments:
            for pt in mu.points:
                pt.frame = self.resolve(pt.frame)
                if pt.frame not in self.frames and pt.frame != "ground":
                    raise OsimError(f"{self.source}: line {pt.line}: {mu.type} {mu.name!r}: PathPoint {pt.name!r}: "
                                    f"frame {pt.frame!r} is neither a body nor a frame of the model")
        for w in self.wrap_objects.values():
            w.frame = self.resolve(w.frame)
        ignored_wraps = {n for k, n, _ in self.ignored if k.startswith("Wrap")}
        unsupported_wraps = {n for k, n, _ in self.unsupported if k.startswith("Wrap")}
        for mu in list(self.muscles):
            for pw in mu.wraps:
                if pw.wrap_object in self.wrap_objects:
                    continue
                if pw.wrap_object in ignored_wraps | unsupported_wraps:  # refused by name, or left out on request
                    self.muscles.remove(mu)
                    self.ignored.append(("PathWrap", f"{mu.name}/{pw.name}", pw.line))
                    self.ignored.append((mu.type, mu.name, mu.line))
                    break
                raise OsimError(f"{self.source}: line {pw.line}: PathWrap '{mu.name}/{pw.name}': unknown wrap object "
                                f"{pw.wrap_object!r} (wrap objects of the model: {sorted(self.wrap_objects)})")
        for g in self.geometry:
            g.frame = self.resolve(g.frame)
        for j in self.joints:
            for f in (j.parent, j.child):
                if f not in self.frames:
                    raise OsimError(f"{self.source}: line {j.line}: {j.type} {j.name!r}: frame {f!r} is neither a "
                                    "body nor a PhysicalOffsetFrame of the model")
        for key, f in self.frames.items():  # every frame ends on a body or the ground
            if f.body == key and key not in self.bodies and key != "ground":
                raise OsimError(f"{self.source}: line {f.line}: frame {key!r} is attached to itself")
            if f.body not in self.frames and f.body != "ground":
                raise OsimError(f"{self.source}: line {f.line}: frame {key!r} is attached to {f.body!r}, which is "
                                "neither a body nor a frame of the model")
        for what, items in (("Marker", self.markers), ("Mesh", self.geometry)):
            for m in items:
                if m.frame not in self.frames and m.frame != "ground":
                    raise OsimError(f"{self.source}: line {m.line}: {what} {getattr(m, 'name', None) or m.file!r}: "
                                    f"frame {m.frame!r} is neither a body nor a frame of the model")
        for c in self.constraints:
            for f in c.frames:
                if f not in self.frames and f != "ground":
                    raise OsimError(f"{self.source}: line {c.line}: {c.type} {c.name!r}: frame {f!r} is neither a "
                                    "body nor a frame of the model")
        if self.inert:
            import warnings

            from ...model.plausibility import PlausibilityWarning

            listed = "; ".join(f"<{tag}> in {len(muscles)} muscle{'s' * (len(muscles) > 1)} ({muscles[0]}"
                               f"{', …' if len(muscles) > 1 else ''})" for tag, muscles in self.inert.items())
            warnings.warn(f"{self.source}: Thelen2003Muscle properties in Millard2012EquilibriumMuscles, which "
                          f"have no such property: OpenSim ignores them, and so does openfdk: {listed}",
                          PlausibilityWarning, stacklevel=3)
        return OsimDocument(self.source, self.path, name, version, gravity, self.bodies, self.frames, self.joints,
                            self.coordinates, self.constraints, self.markers, self.geometry, self.unsupported,
                            self.ignored, self.muscles, self.actuators, self.wrap_objects, self.springs,
                            self.ligaments, self.contact_meshes, self.contact_forces)

    def resolve(self, path, scope=""):
        """The key in ``self.frames`` of a socket path, read in ``scope`` (the owner of
        the element holding the socket): ``scope/name`` first, then a body or model-level
        frame of that name, then the single frame of that name anywhere."""
        parts = [x for x in path.strip().split("/") if x and x != ".."]
        if not parts:  # ".." (what OpenSim writes for a body's own frames): the owner itself
            return scope or path
        last = parts[-1]
        if len(parts) >= 2 and f"{parts[-2]}/{last}" in self.frames:
            return f"{parts[-2]}/{last}"
        if scope and f"{scope}/{last}" in self.frames:
            return f"{scope}/{last}"
        if last in self.frames:
            return last
        found = [k for k in self.frames if k.endswith(f"/{last}")]
        return found[0] if len(found) == 1 else last

    def add_frame(self, frame, element):
        if frame.name in self.frames and self.frames[frame.name] is not frame:
            old = self.frames[frame.name]
            if not (old.body == frame.body and np.allclose(old.p_BF, frame.p_BF) and np.allclose(old.R_BF, frame.R_BF)):
                raise self.err(element, f"a second frame named {frame.name!r} (first at line {old.line}); "
                                        "openfdk needs frame names unique within the model")
        self.frames[frame.name] = frame

    def read_body(self, body, legacy):
        name = body.get("name")
        if not name:
            raise self.err(body, "a body without a name")
        if not legacy and name == "ground":
            raise self.err(body, "a body named 'ground', the name of the model's ground")
        if legacy and name == "ground":
            self.add_frame(OsimFrame("ground", "ground", np.zeros(3), np.eye(3), body.sourceline), body)
            self.body_geometry(body, "ground")
            return
        mass = float(self.child_numbers(body, "mass", 1)[0])
        com = self.child_numbers(body, "mass_center", 3, [0, 0, 0])
        if body.find("inertia") is not None:
            i = self.child_numbers(body, "inertia", 6)
        else:
            i = np.array([float(self.child_numbers(body, f"inertia_{k}", 1, [0.0])[0])
                          for k in ("xx", "yy", "zz", "xy", "xz", "yz")])
        inertia = np.array([[i[0], i[3], i[4]], [i[3], i[1], i[5]], [i[4], i[5], i[2]]])
        if name in self.bodies:
            raise self.err(body, f"a second body named {name!r}")
        self.bodies[name] = OsimBody(name, mass, com, inertia, body.sourceline)
        self.add_frame(OsimFrame(name, name, np.zeros(3), np.eye(3), body.sourceline), body)
        self.body_geometry(body, name)
        for comp in self.objects(body.find("components")):
            if comp.tag == "PhysicalOffsetFrame":
                self.read_offset_frame(comp, scope=name, default_parent=name)
            else:
                self.skip(comp)
        self.read_wrap_objects(body, name)
        for e in body:
            if isinstance(e.tag, str) and e.tag not in (
                    "mass", "mass_center", "inertia", "inertia_xx", "inertia_yy", "inertia_zz", "inertia_xy",
                    "inertia_xz", "inertia_yz", "attached_geometry", "components", "WrapObjectSet", "Joint",
                    "VisibleObject", "FrameGeometry", "frame_geometry", "GeometrySet"):
                self.skip(e)
        if legacy:
            holder = body.find("Joint")
            for joint in list(holder) if holder is not None else []:
                if isinstance(joint.tag, str):
                    self.read_joint(joint, legacy=True, child_body=name)

    def body_geometry(self, element, frame):
        """attached_geometry (4.x) or VisibleObject (3.x) of a body or frame."""
        for g in self.objects(element.find("attached_geometry")):
            if g.tag == "Mesh":
                f = self.child_text(g, "mesh_file", "")
                if f:
                    self.geometry.append(OsimGeometry(f, frame, self.child_numbers(g, "scale_factors", 3, [1, 1, 1]),
                                                      line=g.sourceline))
            # analytic display shapes (Sphere, Cylinder, Brick, …) are display only: not drawn yet
        vis = element.find("VisibleObject")
        if vis is None:
            return
        scale = self.child_numbers(vis, "scale_factors", 3, [1, 1, 1])
        for f in (self.child_text(vis, "geometry_files", "") or "").split():
            self.geometry.append(OsimGeometry(f, frame, scale, line=vis.sourceline))
        for g in self.objects(vis.find("GeometrySet")):
            if g.tag != "DisplayGeometry":
                continue
            f = self.child_text(g, "geometry_file", "")
            t = self.child_numbers(g, "transform", 6, [0, 0, 0, 0, 0, 0])
            s = self.child_numbers(g, "scale_factors", 3, [1, 1, 1])
            if f:
                self.geometry.append(OsimGeometry(f, frame, s * scale, t[3:], rotation_xyz(t[:3]), g.sourceline))

    def read_offset_frame(self, element, scope="", default_parent=None):
        name = element.get("name")
        parent = self.child_text(element, "socket_parent", default_parent or "")
        if not name or not parent:
            raise self.err(element, "a PhysicalOffsetFrame needs a name and a <socket_parent>")
        self.pending.append((name if not scope else f"{scope}/{name}", parent, scope))
        frame = OsimFrame(name if not scope else f"{scope}/{name}", parent, self.child_numbers(element, "translation", 3, [0, 0, 0]),
                          rotation_xyz(self.child_numbers(element, "orientation", 3, [0, 0, 0])), element.sourceline)
        self.add_frame(frame, element)
        self.body_geometry(element, frame.name)
        self.read_wrap_objects(element, frame.name)
        return frame

    def read_wrap_objects(self, element, frame):
        """The WrapObjectSet of a body, the ground or a PhysicalOffsetFrame: WrapCylinder,
        WrapSphere and WrapEllipsoid are read (OsimWrapObject on ``frame``); any other
        wrap object (WrapTorus, …) is unsupported, refused by name unless ignored."""
        for w in self.objects(element.find("WrapObjectSet")):
            if not isinstance(w.tag, str):
                continue
            if w.tag not in WRAP_TYPES or w.tag in self.ignore:
                self.skip(w)
                continue
            name = w.get("name")
            if not name:
                raise self.err(w, "a wrap object without a name")
            if name in self.wrap_objects:
                raise self.err(w, f"a second wrap object named {name!r} (first at line "
                                  f"{self.wrap_objects[name].line})")
            for e in w:
                if isinstance(e.tag, str) and e.tag not in _WRAP_PROPERTIES | _WRAP_DIMENSIONS[w.tag]:
                    raise self.err(e, f"{w.tag} {name!r}: property <{e.tag}> is not read by openfdk; leave it out "
                                      f"with --ignore {w.tag}")
            text = self.child_text(w, "quadrant", "Unassigned")
            if text not in QUADRANTS:
                raise self.err(w, f"quadrant {text!r}: expected all, +x, -x, +y, -y, +z or -z (OpenSim's values)")
            rec = OsimWrapObject(name, w.tag, frame, self.child_numbers(w, "translation", 3, [0, 0, 0]),
                                 rotation_xyz(self.child_numbers(w, "xyz_body_rotation", 3, [0, 0, 0])),
                                 QUADRANTS[text], text, self.child_bool(w, "active", True), line=w.sourceline)
            if w.tag == "WrapEllipsoid":
                rec.dimensions = self.child_numbers(w, "dimensions", 3, [0.05, 0.05, 0.05])  # OpenSim's default
                bad = not np.all(rec.dimensions > 0)
            elif w.tag == "WrapTorus":  # OpenSim's defaults 0.01, 0.05 m
                rec.radius = float(self.child_numbers(w, "inner_radius", 1, [0.01])[0])
                rec.length = float(self.child_numbers(w, "outer_radius", 1, [0.05])[0])
                bad = not 0 < rec.radius < rec.length
                if rec.quadrant[0] is not None:
                    raise self.err(w, f"WrapTorus {name!r}: quadrant {text!r} is not supported (openfdk reads a "
                                      "torus without a quadrant); leave it out with --ignore WrapTorus")
            else:
                rec.radius = float(self.child_numbers(w, "radius", 1, [1.0 if w.tag == "WrapCylinder" else 0.05])[0])
                rec.length = float(self.child_numbers(w, "length", 1, [1.0])[0]) if w.tag == "WrapCylinder" else 0.0
                bad = not rec.radius > 0 or (w.tag == "WrapCylinder" and not rec.length > 0)
            if bad:
                raise self.err(w, "its radius, length or dimensions must be > 0 m (a torus: 0 < inner_radius < "
                                  "outer_radius)")
            self.wrap_objects[name] = rec

    def path_wrap(self, pw, label):
        """An OsimPathWrap of a PathWrap element (``wrap_object``, ``method``, ``range``)."""
        for e in pw:
            if isinstance(e.tag, str) and e.tag not in ("wrap_object", "method", "range", "components"):
                raise self.err(e, f"{label}: property <{e.tag}> is not read by openfdk; leave the muscle out with "
                                  "--ignore PathWrap")
        obj = self.child_text(pw, "wrap_object", "")
        if not obj:
            raise self.err(pw, f"{label}: no <wrap_object>")
        method = self.child_text(pw, "method", "hybrid")
        if method == "Unassigned":
            method = "hybrid"
        if method not in WRAP_METHODS:
            raise self.err(pw, f"{label}: method {method!r}: expected hybrid, midpoint or axial (OpenSim's values)")
        rng = self.child_text(pw, "range", "-1 -1").split()
        if len(rng) != 2 or not all(x.lstrip("+-").isdigit() for x in rng):
            raise self.err(pw, f"{label}: range {' '.join(rng)!r}: expected two point numbers (-1: the path's end)")
        return OsimPathWrap(pw.get("name") or "", obj, WRAP_METHODS[method], (int(rng[0]), int(rng[1])),
                            pw.sourceline)

    # -- joints -----------------------------------------------------------------------
    def read_joint(self, joint, legacy, child_body=None):
        kind = joint.tag
        if kind not in JOINT_TYPES:
            raise self.err(joint, f"joint type {kind} is not supported by openfdk (supported: {', '.join(JOINT_TYPES)})")
        # a 3.x joint nested in its body may have no name: OpenSim names it by its type
        # in lower case ('sliderjoint'), and so does openfdk
        name = joint.get("name") or kind.lower()
        self.once(joint, "joint", name)
        if self.child_bool(joint, "reverse", False):
            raise self.err(joint, "<reverse>true</reverse> joints are not supported")
        if legacy:
            parent_body = self.child_text(joint, "parent_body")
            parent = OsimFrame(f"{name}_parent", parent_body, self.child_numbers(joint, "location_in_parent", 3, [0, 0, 0]),
                               rotation_xyz(self.child_numbers(joint, "orientation_in_parent", 3, [0, 0, 0])),
                               joint.sourceline)
            child = OsimFrame(f"{name}_child", child_body, self.child_numbers(joint, "location", 3, [0, 0, 0]),
                              rotation_xyz(self.child_numbers(joint, "orientation", 3, [0, 0, 0])), joint.sourceline)
            self.add_frame(parent, joint)
            self.add_frame(child, joint)
            coord_elements = self.objects(joint.find("CoordinateSet"))
            parent_name, child_name = parent.name, child.name
        else:
            for f in self.objects(joint.find("frames")):
                if f.tag == "PhysicalOffsetFrame":
                    self.read_offset_frame(f, scope=name)
                else:
                    self.skip(f)
            parent_name = self.child_text(joint, "socket_parent_frame")
            child_name = self.child_text(joint, "socket_child_frame")
            coord_elements = self.objects(joint.find("coordinates"))
        coords = []
        for c in coord_elements:
            if c.tag != "Coordinate":
                self.skip(c)
                continue
            coords.append(self.read_coordinate(c, name))
        names = tuple(c.name for c in coords)
        if kind == "CustomJoint":
            rotations, translations = self.spatial_transform(joint, names)
        else:
            rotations, translations = self.fixed_transform(joint, kind, names)
        used = {c for ax in rotations + translations for c in ax.coordinates}
        for c in coords:
            if c.name not in used:
                raise self.err(joint, f"coordinate {c.name!r} moves no axis of the joint")
            if not c.motion_type:
                # the kind of the axis that is the coordinate itself (an affine function
                # of it; rotations first): what OpenSim 4 reports when that function is a
                # LinearFunction of slope 1 (it says "coupled" otherwise), and the axis
                # that measures the coordinate in openfdk (coordinate_joint), so its unit
                c.motion_type = ("rotational" if any(_affine_in(ax, c.name) for ax in rotations) else
                                 "translational" if any(_affine_in(ax, c.name) for ax in translations) else
                                 "rotational" if any(c.name in ax.coordinates for ax in rotations) else
                                 "translational")
            c.opensim_motion = (opensim_motion_type(rotations, translations, c.name) if kind == "CustomJoint"
                                else c.motion_type)
        self.joints.append(OsimJoint(name, kind, parent_name, child_name, names, rotations, translations,
                                     joint.sourceline))
        if not legacy:
            self.joint_sockets.append((self.joints[-1], name))

    def read_coordinate(self, c, joint):
        name = c.get("name")
        if not name:
            raise self.err(c, "a coordinate without a name")
        if name in self.coordinates:
            raise self.err(c, f"a second coordinate named {name!r}")
        rng = self.child_numbers(c, "range", 2, [-np.inf, np.inf]) if c.find("range") is not None else (-np.inf, np.inf)
        if rng[0] > rng[1]:
            raise self.err(c, f"range {list(rng)} has its lower bound above the upper")
        prescribed = self.child_bool(c, "prescribed", False)
        fn = None
        holder = c.find("prescribed_function")
        if holder is not None and len(holder):  # (3.x files write an empty <prescribed_function/>)
            fe = function_element(c, self.source)
            fn = None if fe is None else function_spec(fe, self.source)
        if prescribed and fn is None:
            raise self.err(c, "prescribed but no <prescribed_function>")
        motion = self.child_text(c, "motion_type", "").lower()    # 'Coupled' in Moco's example models
        if motion and motion not in ("rotational", "translational", "coupled"):
            raise self.err(c, f"motion_type {motion!r}: expected rotational, translational or coupled")
        coord = OsimCoordinate(name, joint, float(self.child_numbers(c, "default_value", 1, [0.0])[0]),
                               (float(rng[0]), float(rng[1])), self.child_bool(c, "clamped", False),
                               self.child_bool(c, "locked", False), prescribed, fn, motion, c.sourceline)
        self.coordinates[name] = coord
        return coord

    def spatial_transform(self, joint, names):
        st = joint.find("SpatialTransform")
        if st is None:
            raise self.err(joint, "a CustomJoint without a <SpatialTransform>")
        axes = {}
        for ta in st:
            if not isinstance(ta.tag, str):
                continue
            if ta.tag != "TransformAxis":
                raise self.err(ta, f"unexpected <{ta.tag}> in a SpatialTransform")
            label = ta.get("name")
            if label not in ("rotation1", "rotation2", "rotation3", "translation1", "translation2", "translation3"):
                raise self.err(ta, f"TransformAxis name {label!r}: expected rotation1-3 or translation1-3")
            axes[label] = ta
        out = []
        for kind in ("rotation", "translation"):
            row = []
            for k in (1, 2, 3):
                ta = axes.get(f"{kind}{k}")
                if ta is None:  # an absent axis does not move the joint
                    default = (_X, _Y, _Z)[k - 1]
                    row.append(OsimAxis(f"{kind}{k}", np.array(default), (), {"type": "constant", "value": 0.0},
                                        joint.sourceline))
                    continue
                coords = tuple(self.child_text(ta, "coordinates", "").split())
                for cname in coords:
                    if cname not in names:
                        raise self.err(ta, f"coordinate {cname!r} is not one of the joint's coordinates {list(names)}",
                                       f"TransformAxis '{ta.get('name')}' of {joint.tag} '{joint.get('name')}'")
                axis = self.child_numbers(ta, "axis", 3)
                fe = function_element(ta, self.source)
                if fe is None:  # OpenSim 4.6 reads an axis without a function as Constant(0)
                    spec = {"type": "constant", "value": 0.0}
                else:
                    spec = function_spec(fe, self.source)
                if len(coords) > 1:
                    raise self.err(ta, f"a function of {len(coords)} coordinates {list(coords)}: openfdk reads "
                                       "transform axes driven by one coordinate",
                                   f"TransformAxis '{ta.get('name')}' of {joint.tag} '{joint.get('name')}'")
                if not coords and spec["type"] != "constant":
                    value = _constant_value(spec)
                    if value is None:
                        raise self.err(ta, "a non-constant function without a coordinate",
                                       f"TransformAxis '{ta.get('name')}' of {joint.tag} '{joint.get('name')}'")
                    spec = {"type": "constant", "value": value}
                norm = float(np.linalg.norm(axis))
                if not np.isfinite(norm):  # components near the float limit: scale down first
                    axis = axis / np.max(np.abs(axis))
                    norm = float(np.linalg.norm(axis))
                if norm == 0.0:
                    if coords or spec.get("value", 0.0) != 0.0:
                        raise self.err(ta, "a zero axis", f"TransformAxis '{ta.get('name')}' of {joint.tag} "
                                                          f"'{joint.get('name')}'")
                    axis, norm = np.array((_X, _Y, _Z)[k - 1]), 1.0
                row.append(OsimAxis(f"{kind}{k}", axis / norm, coords, spec, ta.sourceline))
            out.append(tuple(row))
        return out[0], out[1]

    def fixed_transform(self, joint, kind, names):
        rot, tra = JOINT_TRANSFORMS[kind]
        needed = 1 + max([k for _, k in rot + tra if k is not None], default=-1)
        if len(names) != needed:
            raise self.err(joint, f"a {kind} has {needed} coordinates, the file gives {len(names)}")
        out = []
        for kind_name, axes in (("rotation", rot), ("translation", tra)):
            row = []
            for k, (axis, ci) in enumerate(axes):
                if ci is None:
                    row.append(OsimAxis(f"{kind_name}{k + 1}", np.array(axis), (), {"type": "constant", "value": 0.0},
                                        joint.sourceline))
                else:
                    row.append(OsimAxis(f"{kind_name}{k + 1}", np.array(axis), (names[ci],),
                                        {"type": "linear", "slope": 1.0, "intercept": 0.0}, joint.sourceline))
            out.append(tuple(row))
        return out[0], out[1]

    # -- constraints and markers ------------------------------------------------------
    def read_constraint(self, c, legacy):
        kind, name = c.tag, c.get("name") or c.tag.lower()     # unnamed: by type, as OpenSim names it
        if kind not in CONSTRAINT_TYPES:
            self.skip(c)
            return
        enforced = self.child_bool(c, "isEnforced", True) and not self.child_bool(c, "isDisabled", False)
        if not enforced:
            self.ignored.append((kind, name, c.sourceline))  # disabled in the file: OpenSim does not apply it
            return
        self.once(c, "constraint", name)
        if kind == "CoordinateCouplerConstraint":
            indep = tuple(self.child_text(c, "independent_coordinate_names").split())
            dep = self.child_text(c, "dependent_coordinate_name")
            fe = function_element(c, self.source)
            if fe is None:
                raise self.err(c, "no <coupled_coordinates_function>")
            spec = function_spec(fe, self.source)
            scale = float(self.child_numbers(c, "scale_factor", 1, [1.0])[0])
            if scale != 1.0:
                spec = {"type": "multiplier", "scale": scale, "function": spec}
            if len(indep) != 1:
                raise self.err(c, f"{len(indep)} independent coordinates {list(indep)}: openfdk reads couplers with "
                                  "one independent coordinate")
            self.constraints.append(OsimConstraint(name, kind, indep, dep, spec, line=c.sourceline))
            return
        if kind == "WeldConstraint":
            if legacy:
                frames = []
                for k in (1, 2):
                    body = self.child_text(c, f"body_{k}")
                    f = OsimFrame(f"{name}_frame{k}", body, self.child_numbers(c, f"location_body_{k}", 3, [0, 0, 0]),
                                  rotation_xyz(self.child_numbers(c, f"orientation_body_{k}", 3, [0, 0, 0])),
                                  c.sourceline)
                    self.add_frame(f, c)
                    frames.append(f.name)
            else:
                for f in self.objects(c.find("frames")):
                    if f.tag == "PhysicalOffsetFrame":
                        self.read_offset_frame(f, scope=name)
                frames = [self.resolve(self.child_text(c, "socket_frame1"), name),
                          self.resolve(self.child_text(c, "socket_frame2"), name)]
            self.constraints.append(OsimConstraint(name, kind, frames=tuple(frames), line=c.sourceline))
            return
        if kind == "PointOnLineConstraint":
            direction = self.child_numbers(c, "line_direction_vec", 3, [1, 0, 0])
            if not np.linalg.norm(direction) > 0:
                raise self.err(c, f"line_direction_vec {[float(v) for v in direction]} has no direction")
            frames = []
            for role, point, R in (("line", "point_on_line", _basis_with_x(direction)),
                                   ("follower", "point_on_follower", np.eye(3))):
                body = self.last(self.child_text(c, f"socket_{role}_body", "") or self.child_text(c, f"{role}_body"))
                f = OsimFrame(f"{name}_{role}", body, self.child_numbers(c, point, 3, [0, 0, 0]), R, c.sourceline)
                self.add_frame(f, c)
                frames.append(f.name)
            self.constraints.append(OsimConstraint(name, kind, frames=tuple(frames), line=c.sourceline))
            return
        # PointConstraint, ConstantDistanceConstraint: body_1 + location_body_1, body_2 + location_body_2
        frames = []
        for k in (1, 2):
            body = self.last(self.child_text(c, f"socket_body_{k}", "") or self.child_text(c, f"body_{k}"))
            f = OsimFrame(f"{name}_point{k}", body, self.child_numbers(c, f"location_body_{k}", 3, [0, 0, 0]),
                          np.eye(3), c.sourceline)
            self.add_frame(f, c)
            frames.append(f.name)
        distance = 0.0
        if kind == "ConstantDistanceConstraint":
            distance = float(self.child_numbers(c, "constant_distance", 1)[0])
            if not distance > 0:
                raise self.err(c, f"constant_distance {distance:g}: expected a positive distance (m)")
        self.constraints.append(OsimConstraint(name, kind, frames=tuple(frames), line=c.sourceline, value=distance))

    def read_marker(self, m, legacy):
        if m.tag != "Marker":
            self.skip(m)
            return
        name = m.get("name")
        if not name:
            raise self.err(m, "a marker without a name")
        self.once(m, "marker", name)
        frame = (self.child_text(m, "body") if legacy and m.find("body") is not None
                 else self.child_text(m, "socket_parent_frame"))
        self.markers.append(OsimMarker(name, frame, self.child_numbers(m, "location", 3), frame, m.sourceline))

    # -- muscles ----------------------------------------------------------------------
    @staticmethod
    def _point_error(label, msg):
        return OsimError(f"{label}: {msg}; leave the muscle out with --ignore {label.split(': ')[-1].split()[0]}")

    def _coordinate_of(self, p, tags, label):
        """The coordinate named by the first of ``tags`` present (4.x socket path or 3.x
        name), or None."""
        for tag in tags:
            text = self.child_text(p, tag, "")
            if text:
                return self.last(text)
        return None

    def conditional_point(self, p, label):
        """(coordinate, lo, hi) of a ConditionalPathPoint (OpenSim's ``range``)."""
        coordinate = self._coordinate_of(p, ("socket_coordinate", "coordinate"), label)
        if coordinate is None:
            raise self._point_error(label, "no coordinate (OpenSim would never activate it)")
        lo, hi = self.child_numbers(p, "range", 2)
        if not lo <= hi:
            raise self._point_error(label, f"range [{lo:g}, {hi:g}] is empty")
        return coordinate, float(lo), float(hi)

    def moving_point(self, p, label):
        """(coordinate or None, (spec_x, spec_y, spec_z)) of a MovingPathPoint: each axis
        the function of its ``x_location`` … (default Constant 0). OpenSim requires the
        three coordinates to be one; an axis without one is its function at 0."""
        coords = [self._coordinate_of(p, (f"socket_{a}_coordinate", f"{a}_coordinate"), label) for a in "xyz"]
        if len(set(coords)) != 1:
            raise self._point_error(label, f"x, y and z must depend on the same coordinate (OpenSim's rule), got "
                                           f"{coords}")
        specs = []
        for a, legacy_tag in zip("xyz", ("XAttachment", "YAttachment", "ZAttachment")):
            holder = p.find(f"{a}_location")
            holder = holder if holder is not None else p.find(legacy_tag)
            if holder is None:
                specs.append({"type": "constant", "value": 0.0})
                continue
            inner = [e for e in holder if isinstance(e.tag, str)]
            if len(inner) != 1:
                raise self._point_error(label, f"<{holder.tag}> must hold one function, it has {len(inner)}")
            specs.append(function_spec(inner[0], self.source))
        return coords[0], tuple(specs)

    def read_muscle(self, m, legacy):
        """A muscle of MUSCLE_TYPES with a path of PathPoints. A muscle whose path holds
        anything else (ConditionalPathPoint, MovingPathPoint, a PathWrap) is left out as
        a whole: that element is refused by name (or, ignored with --ignore, listed as
        dropped together with its muscle) — never imported without it."""
        kind, name = m.tag, m.get("name")
        if not name:
            raise self.err(m, "a muscle without a name")
        self.once(m, "muscle", name)
        enabled = self.child_bool(m, "appliesForce", True) and not self.child_bool(m, "isDisabled", False)
        if not enabled:
            self.ignored.append((kind, name, m.sourceline))  # OpenSim does not apply it either
            return
        label = f"{kind} {name!r}"
        params = {}
        defaults = {"Millard2012EquilibriumMuscle": MILLARD_DEFAULTS, "Millard2012AccelerationMuscle":
                    ACCELERATION_DEFAULTS, "Thelen2003Muscle": THELEN_DEFAULTS}.get(kind) or CURVE_MUSCLE_DEFAULTS[kind]
        curves = MILLARD_CURVES if kind.startswith("Millard") else {}
        if kind == "Millard2012AccelerationMuscle":
            curves = {**MILLARD_CURVES, **ACCELERATION_REPORTED}
        functions = CURVE_MUSCLE_FUNCTIONS.get(kind, ())
        for tag, default in defaults.items():
            params[tag] = float(self.child_numbers(m, tag, 1, [default])[0])
        if kind == "Millard2012EquilibriumMuscle" and m.find("min_control") is None:
            params["min_control"] = params["minimum_activation"]  # OpenSim: setMinControl(minimum_activation)
        for tag, default in _MUSCLE_FLAGS.items():
            params[tag] = self.child_bool(m, tag, default)
        seen = set()
        for e in m:
            if not isinstance(e.tag, str):
                continue
            # a function property as OpenSim 4 writes it: <SimmSpline name="active_force_length_curve">
            tag = e.get("name") if functions and e.get("name") in functions and e.tag in FUNCTION_TAGS else e.tag
            if tag in seen:  # which one OpenSim would use is not the file's to leave open
                raise self.err(e, f"{label}: property <{tag}> given twice")
            seen.add(tag)
            if e.tag in defaults or e.tag in _MUSCLE_FLAGS:
                continue
            if e.tag in curves:
                params[e.tag] = self.read_curve(e, curves[e.tag], label)
            elif tag in functions:
                params[tag] = function_spec(e, self.source) if tag != e.tag else self.read_function(e, label)
            elif kind == "Millard2012EquilibriumMuscle" and e.tag in MILLARD_DROPPED:
                continue  # not a property of OpenSim 4.x's muscle: it has no effect there either
            elif kind == "Millard2012EquilibriumMuscle" and e.tag in THELEN_ONLY:
                self.inert.setdefault(e.tag, []).append(name)     # OpenSim ignores it: warned once
            elif e.tag == "components" and len(e):
                for comp in e:
                    if isinstance(comp.tag, str):
                        self.skip(comp)
            elif e.tag not in _MUSCLE_METADATA:
                raise self.err(e, f"{label}: property <{e.tag}> is not read by openfdk; leave the muscle out with "
                                  f"--ignore {kind}")
        read = self.read_path(m, kind, name, label, legacy)
        if read is None:
            return
        points, wraps = read
        self.muscles.append(OsimMuscle(name, kind, points, params, m.sourceline, wraps))

    def read_function(self, e, label):
        """The function dict of a muscle's curve property ``e`` (it holds one OpenSim
        Function: SimmSpline, PiecewiseLinearFunction, …)."""
        inner = [c for c in e if isinstance(c.tag, str)]
        if len(inner) != 1:
            raise self.err(e, f"{label}: <{e.tag}> must hold one function, it has {len(inner)}")
        return function_spec(inner[0], self.source)

    def read_curve(self, e, properties, label):
        """{property: value} of a Millard curve object ``e`` (only the properties the file
        gives; the rest take OpenSim's defaults); an unknown child is refused by name."""
        out = {}
        for c in e:
            if not isinstance(c.tag, str) or c.tag in _CURVE_METADATA:
                continue
            if c.tag not in properties:
                raise self.err(c, f"{label}: {e.tag} property <{c.tag}> is not read by openfdk (it reads "
                                  f"{', '.join(properties)})")
            if c.tag in out:
                raise self.err(c, f"{label}: {e.tag} property <{c.tag}> given twice")
            if (c.text or "").strip():
                out[c.tag] = float(self.child_numbers(e, c.tag, 1)[0])
        return out

    def read_path(self, m, kind, name, label, legacy):
        """(points, wraps) of the GeometryPath of a muscle or ligament ``m``: PathPoint,
        ConditionalPathPoint and MovingPathPoint records and PathWrap records, or None
        when an element of it is refused (named, or with --ignore listed as dropped with
        its owner, which is then left out as a whole)."""
        path = m.find("GeometryPath")
        if path is None:
            raise self.err(m, "no <GeometryPath>")
        refused = []
        for e in path:
            if isinstance(e.tag, str) and e.tag not in _PATH_METADATA:
                refused.append(e)
        points = []
        for p in self.objects(path.find("PathPointSet")):
            if p.tag not in _PATH_POINT_PROPERTIES or p.tag in self.ignore:
                refused.append(p)
                continue
            pname = p.get("name") or f"point{len(points) + 1}"
            if legacy and p.find("body") is not None:
                frame = self.child_text(p, "body")
            else:
                frame = self.child_text(p, "socket_parent_frame")
            for e in p:
                if isinstance(e.tag, str) and e.tag not in _PATH_POINT_PROPERTIES[p.tag]:
                    raise self.err(e, f"{label}: {p.tag} {pname!r}: property <{e.tag}> is not read by openfdk; "
                                      f"leave the muscle out with --ignore {kind}")
            point = OsimPathPoint(pname, frame, np.zeros(3), p.sourceline)
            where_ = f"{self.source}: line {p.sourceline}: {p.tag} '{name}/{pname}'"  # OpenSim's component path
            if p.tag == "MovingPathPoint":
                point.moving = self.moving_point(p, where_)
            else:
                point.location = self.child_numbers(p, "location", 3)
            if p.tag == "ConditionalPathPoint":
                point.condition = self.conditional_point(p, where_)
            points.append(point)
        wraps = []
        for pw in self.objects(path.find("PathWrapSet")):
            if not isinstance(pw.tag, str):
                continue
            if pw.tag != "PathWrap" or pw.tag in self.ignore:
                refused.append(pw)
                continue
            wraps.append(self.path_wrap(pw, f"{label}: PathWrap '{name}/{pw.get('name') or ''}'"))
        if refused:
            before = len(self.unsupported)
            for e in refused:  # named by their place, "muscle/point", as OpenSim's component paths
                self.skip(e, name=f"{name}/{e.get('name') or ''}")
            if len(self.unsupported) == before:  # all of them ignored on request: the owner goes with them
                self.ignored.append((kind, name, m.sourceline))
            return None
        if len(points) < 2:
            raise self.err(m, f"its path needs at least 2 PathPoints, the file gives {len(points)}")
        return points, wraps

    def read_ligament(self, m, legacy):
        """A Blankevoort1991Ligament (OpenSim ≥ 4.1 core, and OpenSim-JAM's models): its
        path as a muscle's, ``linear_stiffness`` (N per unit strain), ``slack_length`` (m),
        ``transition_strain`` and ``damping_coefficient`` (OpenSim's defaults 1, —, 0.06,
        0.003)."""
        kind, name = m.tag, m.get("name")
        if not name:
            raise self.err(m, "a ligament without a name")
        self.once(m, "ligament", name)
        if not self.child_bool(m, "appliesForce", True) or self.child_bool(m, "isDisabled", False):
            self.ignored.append((kind, name, m.sourceline))
            return
        label = f"{kind} {name!r}"
        for e in m:
            if isinstance(e.tag, str) and e.tag not in _LIGAMENT_PROPERTIES:
                raise self.err(e, f"{label}: property <{e.tag}> is not read by openfdk; leave the ligament out "
                                  f"with --ignore {kind}")
        params = {tag: float(self.child_numbers(m, tag, 1, [default])[0]) for tag, default in
                  LIGAMENT_DEFAULTS.items()}
        if m.find("slack_length") is None:
            raise self.err(m, f"{label}: no <slack_length>")
        read = self.read_path(m, kind, name, label, legacy)
        if read is None:
            return
        points, wraps = read
        self.ligaments.append(OsimMuscle(name, kind, points, params, m.sourceline, wraps))
