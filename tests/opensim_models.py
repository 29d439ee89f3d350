"""Small OpenSim models for tests/test_opensim_import.py, built with OpenSim's own Python
API (the ``opensim`` package, 4.6) and written by OpenSim (``printToXML``), and the
oracle: OpenSim loading the file it wrote (``opensim.Model(path)``) and reporting poses,
velocities and mass properties. Import this module only after
``pytest.importorskip("opensim")``.

Every model has random masses, centres of mass and (valid) inertias, PhysicalOffsetFrames
with non-zero translation and orientation on both sides of every joint, explicit
coordinate ranges, non-zero default values and two markers per moving body.
"""

from __future__ import annotations

import numpy as np
import opensim as osim
from lxml import etree

# -------------------------------------------------------------------------- small helpers


def vec3(x):
    return osim.Vec3(*(float(v) for v in x))


def six_dof_transform(names):
    """A CustomJoint's SpatialTransform with one coordinate per axis, ``names`` (6,):
    rotations about z, x, y, then translations along x, y, z, each the identity function."""
    transform = osim.SpatialTransform()
    for k, (axis, name) in enumerate(zip(np.r_[np.eye(3)[[2, 0, 1]], np.eye(3)], names)):
        ta = transform.updTransformAxis(k)
        ta.setAxis(vec3(axis))
        ta.setCoordinateNames(osim.ArrayStr(name, 1))
        ta.set_function(osim.LinearFunction(1.0, 0.0))
    return transform


def np3(v):
    return np.array([v.get(i) for i in range(3)])


def np33(R):
    return np.array([[R.get(i, j) for j in range(3)] for i in range(3)])


def rotvec_matrix(r):
    r = np.asarray(r, float)
    a = np.linalg.norm(r)
    if a == 0.0:
        return np.eye(3)
    k = r / a
    K = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + np.sin(a) * K + (1.0 - np.cos(a)) * (K @ K)


def random_body(name, rng, mass=None):
    """A Body with a random mass, centre of mass and inertia (about the centre of mass,
    principal moments 0.05-0.1 kg m² about rotated axes: positive definite and meeting
    the triangle inequality, as Simbody requires)."""
    mass = rng.uniform(0.5, 5.0) if mass is None else mass
    Q = rotvec_matrix(rng.normal(size=3))
    inertia = Q @ np.diag(rng.uniform(0.05, 0.1, 3)) @ Q.T
    I = osim.Inertia(inertia[0, 0], inertia[1, 1], inertia[2, 2], inertia[0, 1], inertia[0, 2], inertia[1, 2])
    return osim.Body(name, float(mass), vec3(rng.uniform(-0.1, 0.1, 3)), I)


def offsets(rng):
    """(location, orientation) of a joint frame: non-zero translation and X-Y-Z angles."""
    return vec3(rng.uniform(-0.15, 0.15, 3)), vec3(rng.uniform(-0.6, 0.6, 3))


def add_markers(model, body, rng, n=2):
    for k in range(n):
        model.addMarker(osim.Marker(f"{body.getName()}.M{k}", body, vec3(rng.uniform(-0.15, 0.15, 3))))


def set_coordinates(joint, ranges, rng):
    """Ranges [(lo, hi)] of the joint's coordinates (in order) and a random default in
    the middle half of each."""
    for i, (lo, hi) in enumerate(ranges):
        c = joint.upd_coordinates(i)
        c.setRangeMin(lo)
        c.setRangeMax(hi)
        c.setDefaultValue(float(rng.uniform(0.75 * lo + 0.25 * hi, 0.25 * lo + 0.75 * hi)))


def fixed_joint(cls, name, parent, child, rng, ranges=()):
    """A joint of OpenSim class ``cls`` (PinJoint, …) between ``parent`` and ``child``
    with random offset frames on both sides."""
    p1, o1 = offsets(rng)
    p2, o2 = offsets(rng)
    j = cls(name, parent, p1, o1, child, p2, o2)
    set_coordinates(j, ranges, rng)
    return j


def spline_points(fn, x, y):
    for a, b in zip(x, y):
        fn.addPoint(float(a), float(b))
    return fn


def coupler(name, independent, dependent, function):
    """A CoordinateCouplerConstraint ``dependent`` = function(``independent``)."""
    c = osim.CoordinateCouplerConstraint()
    c.setName(name)
    c.setIndependentCoordinateNames(osim.ArrayStr(independent, 1))
    c.setDependentCoordinateName(dependent)
    c.setFunction(function)
    return c


def r6(values):
    """Values rounded to 6 significant digits (what OpenSim writes number lists with)."""
    return [float(f"{v:.6g}") for v in np.ravel(values)]


def custom_joint(name, parent, child, rng, axes):
    """A CustomJoint; ``axes``: six (axis (3,), coordinate name or None, OpenSim Function)
    for rotation1-3, translation1-3 (the coordinates' ranges: :func:`set_ranges`)."""
    st = osim.SpatialTransform()
    for k, (axis, coord, fn) in enumerate(axes):
        ta = st.updTransformAxis(k)
        ta.setAxis(vec3(axis))
        if coord is not None:
            ta.setCoordinateNames(osim.ArrayStr(coord, 1))
        if fn is not None:
            ta.set_function(fn)
    p1, o1 = offsets(rng)
    p2, o2 = offsets(rng)
    j = osim.CustomJoint(name, parent, p1, o1, child, p2, o2, st)
    return j


def set_ranges(model, ranges, rng):
    """Ranges {coordinate: (lo, hi)} and random defaults of a model's coordinates, set
    once the joints are in the model (a CustomJoint makes its coordinates from its
    SpatialTransform when it is connected, with OpenSim's defaults)."""
    model.finalizeFromProperties()
    cs = model.updCoordinateSet()
    for name, (lo, hi) in ranges.items():
        c = cs.get(name)
        c.setRangeMin(lo)
        c.setRangeMax(hi)
        c.setDefaultValue(float(rng.uniform(0.75 * lo + 0.25 * hi, 0.25 * lo + 0.75 * hi)))


def write(model, path):
    model.finalizeConnections()
    model.initSystem()  # OpenSim checks the model (e.g. collinear rotation axes) before it is written
    assert model.printToXML(str(path))
    return path


# -------------------------------------------------------------------------- the models

BALL_RANGES = [(-2.5, 2.5), (-1.2, 1.2), (-2.5, 2.5)]
FREE_RANGES = BALL_RANGES + [(-0.5, 0.5)] * 3


def joints_model(path, seed=1):
    """Every OpenSim joint type but CustomJoint, in two chains, with markers:

    ground -Pin- pin -Slider- slider -Universal- universal -Ball- ball -Gimbal- gimbal;
    ground -Free- free -Planar- planar -Weld- welded -Pin- after_weld;
    ground -Weld- on_ground -Pin- swing.

    ``welded`` is merged into ``planar`` and ``on_ground`` into the ground."""
    rng = np.random.default_rng(seed)
    m = osim.Model()
    m.setName("joints")
    g = m.getGround()
    bodies = {}
    for name in ("pin", "slider", "universal", "ball", "gimbal", "free", "planar", "welded", "after_weld",
                 "on_ground", "swing"):
        bodies[name] = random_body(name, rng)
        m.addBody(bodies[name])
    B = bodies
    specs = [
        (osim.PinJoint, "pin_j", g, B["pin"], [(-2.0, 2.0)]),
        (osim.SliderJoint, "slider_j", B["pin"], B["slider"], [(-0.2, 0.3)]),
        (osim.UniversalJoint, "universal_j", B["slider"], B["universal"], [(-1.2, 1.2)] * 2),
        (osim.BallJoint, "ball_j", B["universal"], B["ball"], BALL_RANGES),
        (osim.GimbalJoint, "gimbal_j", B["ball"], B["gimbal"], BALL_RANGES),
        (osim.FreeJoint, "free_j", g, B["free"], FREE_RANGES),
        (osim.PlanarJoint, "planar_j", B["free"], B["planar"], [(-2.0, 2.0), (-0.3, 0.3), (-0.3, 0.3)]),
        (osim.WeldJoint, "weld_j", B["planar"], B["welded"], []),
        (osim.PinJoint, "after_weld_j", B["welded"], B["after_weld"], [(-2.0, 2.0)]),
        (osim.WeldJoint, "ground_weld_j", g, B["on_ground"], []),
        (osim.PinJoint, "swing_j", B["on_ground"], B["swing"], [(-2.0, 2.0)]),
    ]
    for cls, name, parent, child, ranges in specs:
        m.addJoint(fixed_joint(cls, name, parent, child, rng, ranges))
    for name, b in bodies.items():
        if name != "on_ground":
            add_markers(m, b, rng)
    return write(m, path)


def oblique_model(path, seed=6, constant_first=True):
    """CustomJoints whose moving rotation axes are not orthogonal, as the wrist model's
    and the thumb's (openfdk.model.axis_angles):

    * ``cmc`` (ground → metacarpal): a constant rotation about z (last with
      ``constant_first`` False), then two rotations about (1, 0, 0) and the oblique
      (0.3, 0.9, −0.2) (cos 0.31), constant translations;
    * ``mcp`` (metacarpal → phalanx): three rotations about (1, 0, 0), (0.2, 1, 0) and
      (0.1, 0.3, 1), the third of slope −1, and one translation linear in a coordinate
      of its own;
    * markers on each moving body."""
    rng = np.random.default_rng(seed)
    m = osim.Model()
    m.setName("oblique")
    g = m.getGround()
    meta, phal = random_body("metacarpal", rng), random_body("phalanx", rng)
    for b in (meta, phal):
        m.addBody(b)
    lin = osim.LinearFunction
    rotations = [((1, 0, 0), "cmc_flex", lin(1.0, 0.0)), ((0.3, 0.9, -0.2), "cmc_abd", lin(1.0, 0.0))]
    constant = ((0, 0, 1), None, osim.Constant(0.2))
    rotations = [constant] + rotations if constant_first else rotations + [constant]
    m.addJoint(custom_joint("cmc", g, meta, rng, [
        *rotations,
        ((1, 0, 0), None, osim.Constant(0.01)),
        ((0, 1, 0), None, osim.Constant(-0.02)),
        ((0, 0, 1), None, osim.Constant(0.03)),
    ]))
    m.addJoint(custom_joint("mcp", meta, phal, rng, [
        ((1, 0, 0), "mcp_flex", lin(1.0, 0.0)),
        ((0.2, 1, 0), "mcp_abd", lin(1.0, 0.0)),
        ((0.1, 0.3, 1), "mcp_rot", lin(-1.0, 0.05)),
        ((0, 1, 0), "mcp_slide", lin(1.0, 0.0)),
        ((1, 0, 0), None, osim.Constant(0.0)),
        ((0, 0, 1), None, osim.Constant(0.01)),
    ]))
    set_ranges(m, {"cmc_flex": (-1.0, 1.0), "cmc_abd": (-0.9, 0.9), "mcp_flex": (-1.2, 0.8), "mcp_abd": (-0.7, 0.7),
                   "mcp_rot": (-0.8, 0.8), "mcp_slide": (-0.01, 0.01)}, rng)
    for b in (meta, phal):
        add_markers(m, b, rng)
    return write(m, path)


#: knots of the knee's functions (flexion, rad) and the flexion range
KNEE_X = np.linspace(-2.2, 0.4, 9)
KNEE_RANGE = (-2.0, 0.2)


def custom_model(path, seed=2):
    """CustomJoints with every OpenSim coordinate function:

    * ``hip`` (ground → femur): three linear rotations (z, x, y), a LinearFunction with
      slope −2 and intercept 0.1 among them, and constant translations along
      non-orthogonal axes;
    * ``knee`` (femur → tibia): rotation1 about the non-unit axis ``0 0 2`` (linear in
      knee_angle), rotation2 a SimmSpline, rotation3 a NaturalCubicSpline (written as
      such into the file after OpenSim wrote it), translation1 a GCVSpline (degree 5),
      translation2 a PiecewiseLinearFunction along the non-unit axis ``0 2 0``,
      translation3 a MultiplierFunction of a PolynomialFunction — all of knee_angle;
    * ``ankle`` (tibia → foot): a Constant rotation about a non-orthogonal axis first,
      then two linear rotations; a translational coordinate (slope 0.5) along a
      non-unit axis, a constant translation and a PolynomialFunction of the ankle angle;
    * ``mtp`` (foot → toe): a translational coordinate (a LinearFunction of slope 1 on
      translation1) that also turns rotation1 through a SimmSpline;
    * markers on two joint frames of the same name (``femur_offset`` of hip and knee).
    """
    rng = np.random.default_rng(seed)
    m = osim.Model()
    m.setName("custom")
    g = m.getGround()
    femur, tibia, foot = (random_body(n, rng) for n in ("femur", "tibia", "foot"))
    for b in (femur, tibia, foot):
        m.addBody(b)

    def const(v):
        return osim.Constant(float(v))

    hip = custom_joint("hip", g, femur, rng, [
        ((0, 0, 1), "hip_flexion", osim.LinearFunction(1.0, 0.0)),
        ((1, 0, 0), "hip_adduction", osim.LinearFunction(-2.0, 0.1)),
        ((0, 1, 0), "hip_rotation", osim.LinearFunction(1.0, 0.0)),
        ((1, 0, 0), None, const(0.01)),
        ((1, 1, 0), None, const(0.02)),
        ((0, 0.3, 1), None, const(-0.03)),
    ])
    m.addJoint(hip)

    x = KNEE_X
    simm = spline_points(osim.SimmSpline(), r6(x), r6(0.12 * np.sin(1.3 * x) + 0.01 * x ** 2))
    natural = spline_points(osim.SimmSpline(), r6(x), r6(-0.08 * np.cos(x) + 0.05 * x))
    gcv = osim.GCVSpline()
    gcv.setDegree(5)
    spline_points(gcv, r6(x), r6(-0.004 * x ** 2 + 0.003 * np.sin(2 * x)))
    plf = spline_points(osim.PiecewiseLinearFunction(), r6(x), r6(0.01 * np.cos(x) - 0.2))
    poly = osim.PolynomialFunction(osim.Vector([0.002, -0.003, 0.01, 0.004]))
    poly.thisown = False  # the MultiplierFunction owns (and deletes) its function
    mult = osim.MultiplierFunction(poly, 1.5)
    knee = custom_joint("knee", femur, tibia, rng, [
        ((0, 0, 2), "knee_angle", osim.LinearFunction(1.0, 0.0)),
        ((1, 0, 0), "knee_angle", simm),
        ((0, 1, 0), "knee_angle", natural),
        ((1, 0, 0), "knee_angle", gcv),
        ((0, 2, 0), "knee_angle", plf),
        ((0, 0, 1), "knee_angle", mult),
    ])
    m.addJoint(knee)

    ankle = custom_joint("ankle", tibia, foot, rng, [
        ((1, 1, 0.2), None, const(0.3)),
        ((1, 0, 0), "ankle_angle", osim.LinearFunction(1.0, 0.0)),
        ((0, 1, 0), "subtalar", osim.LinearFunction(1.0, 0.0)),
        ((0, 1.5, 0.5), "ankle_slide", osim.LinearFunction(0.5, 0.01)),
        ((1, 0.4, 0), None, const(0.015)),
        ((0, 0, 1), "ankle_angle", osim.PolynomialFunction(osim.Vector([0.01, -0.02, 0.003]))),
    ])
    m.addJoint(ankle)
    toe = random_body("toe", rng)
    m.addBody(toe)
    xs = np.linspace(-0.06, 0.06, 7)
    mtp = custom_joint("mtp", foot, toe, rng, [
        ((0, 0, 1), "mtp_slide", spline_points(osim.SimmSpline(), r6(xs), r6(8.0 * xs + 40.0 * xs ** 2))),
        ((1, 0, 0), None, const(0.0)),
        ((0, 1, 0), None, const(0.0)),
        ((1, 0, 0), "mtp_slide", osim.LinearFunction(1.0, 0.0)),
        ((0, 1, 0), None, const(0.004)),
        ((0, 0, 1), None, const(0.0)),
    ])
    m.addJoint(mtp)
    set_ranges(m, {"hip_flexion": (-1.0, 1.5), "hip_adduction": (-0.4, 0.4), "hip_rotation": (-0.8, 0.8),
                   "knee_angle": KNEE_RANGE, "ankle_angle": (-0.7, 0.5), "subtalar": (-0.5, 0.5),
                   "ankle_slide": (-0.05, 0.05), "mtp_slide": (-0.05, 0.05)}, rng)
    for b in (femur, tibia, foot, toe):
        add_markers(m, b, rng)
    # markers on joint frames: both are named femur_offset (the hip's child frame and the
    # knee's parent frame), told apart by their paths /jointset/<joint>/femur_offset
    m.addMarker(osim.Marker("hip.F", hip.getChildFrame(), vec3([0.02, -0.01, 0.03])))
    m.addMarker(osim.Marker("knee.F", knee.getParentFrame(), vec3([-0.01, 0.02, 0.015])))
    write(m, path)
    # the knee's rotation3 as a NaturalCubicSpline (OpenSim reads it as a SimmSpline)
    tree = etree.parse(str(path))
    # OpenSim's GCVSpline.addPoint leaves the new weights uninitialised: once in many CI
    # runs the file held '1 8.062e+72 2.15228e-312 1 … -nan' and OpenSim could not read it
    # back. The weights are ones (OpenSim 4 refits with unit weights anyway)
    for gcv in tree.iter("GCVSpline"):
        weights = gcv.find("weights")
        if weights is not None:
            weights.text = " ".join(["1"] * len(gcv.find("x").text.split()))
    (el,) = tree.xpath("//CustomJoint[@name='knee']/SpatialTransform/TransformAxis[@name='rotation3']/SimmSpline")
    el.tag = "NaturalCubicSpline"
    tree.write(str(path), xml_declaration=True, encoding="UTF-8")
    return path


def xyz_angles(R):
    """Body-fixed X-Y-Z angles (a, b, c) of R = Rx(a) Ry(b) Rz(c), |b| < π/2."""
    return np.array([np.arctan2(-R[1, 2], R[2, 2]), np.arcsin(np.clip(R[0, 2], -1.0, 1.0)),
                     np.arctan2(-R[0, 1], R[0, 0])])


def constraints_model(path, seed=3):
    """Couplers, a WeldConstraint and a PointConstraint:

    ground -Pin(q1)- a -Pin(q2)- b, coupler q2 = SimmSpline(q1);
    ground -Slider(qs)- s, coupler qs = 0.7·(0.2 q1 + 0.05) (LinearFunction; the scale
    factor 0.7 is added to the XML: the Python API has no setter);
    ground -Free- w, WeldConstraint between offset frames of b and w;
    ground -Free- p, PointConstraint between a point of b and a point of p.

    The coordinates of w and p's translations are free to satisfy the constraints
    (``is_free_to_satisfy_constraints``: no assembly goal), so that OpenSim's assembly
    keeps q1 and p's rotations and places the rest. The defaults satisfy every
    constraint: Simbody's weld condition (three perpendicular axis pairs) has spurious
    solutions, and OpenSim's assembly started far away can end on one of them; the tests
    move there from the defaults in small steps (continuation).
    """
    rng = np.random.default_rng(seed)
    m = osim.Model()
    m.setName("constraints")
    g = m.getGround()
    B = {n: random_body(n, rng) for n in ("a", "b", "s", "w", "p")}
    for b in B.values():
        m.addBody(b)
    m.addJoint(fixed_joint(osim.PinJoint, "j1", g, B["a"], rng, [(-1.5, 1.5)]))
    m.addJoint(fixed_joint(osim.PinJoint, "j2", B["a"], B["b"], rng, [(-3.0, 3.0)]))
    m.addJoint(fixed_joint(osim.SliderJoint, "js", g, B["s"], rng, [(-1.0, 1.0)]))
    m.addJoint(osim.FreeJoint("jw", g, vec3([0, 0, 0]), vec3([0, 0, 0]), B["w"], vec3([0, 0, 0]), vec3([0, 0, 0])))
    m.addJoint(fixed_joint(osim.FreeJoint, "jp", g, B["p"], rng, BALL_RANGES + [(-2.0, 2.0)] * 3))
    x = np.linspace(-1.6, 1.6, 7)
    spline = spline_points(osim.SimmSpline(), r6(x), r6(0.8 * np.sin(1.2 * x) + 0.3))
    m.addConstraint(coupler("couple_b", "j1_coord_0", "j2_coord_0", spline))
    m.addConstraint(coupler("couple_s", "j1_coord_0", "js_coord_0", osim.LinearFunction(0.2, 0.05)))
    # defaults on the couplers, then w's defaults on the weld
    m.finalizeFromProperties()
    cs = m.updCoordinateSet()
    q1 = cs.get("j1_coord_0").getDefaultValue()
    cs.get("j2_coord_0").setDefaultValue(spline.calcValue(osim.Vector(1, q1)))
    cs.get("js_coord_0").setDefaultValue(0.7 * (0.2 * q1 + 0.05))
    state = m.initSystem()
    Xb = B["b"].getTransformInGround(state)
    p_Gb, R_Gb = np3(Xb.p()), np33(Xb.R())
    R1, R2 = rotvec_matrix([0.3, -0.2, 0.5]), rotvec_matrix([-0.4, 0.1, 0.2])
    p1, p2 = np.array([0.05, -0.1, 0.02]), np.array([-0.03, 0.04, 0.08])
    R_Gw = R_Gb @ R1 @ R2.T
    p_Gw = p_Gb + R_Gb @ p1 - R_Gw @ p2
    for k, v in enumerate(np.concatenate([xyz_angles(R_Gw), p_Gw])):
        cs.get(f"jw_coord_{k}").setDefaultValue(float(v))
    X1 = osim.Transform(osim.Rotation(osim.Mat33(*R1.ravel())), vec3(p1))
    X2 = osim.Transform(osim.Rotation(osim.Mat33(*R2.ravel())), vec3(p2))
    m.addConstraint(osim.WeldConstraint("weld_bw", B["b"], X1, B["w"], X2))
    m.addConstraint(osim.PointConstraint(B["b"], vec3([0.1, 0.05, -0.04]), B["p"], vec3([-0.02, 0.07, 0.03])))
    for b in B.values():
        add_markers(m, b, rng)
    m.finalizeFromProperties()
    for name in [f"jw_coord_{k}" for k in range(6)] + [f"jp_coord_{k}" for k in (3, 4, 5)]:
        m.updCoordinateSet().get(name).set_is_free_to_satisfy_constraints(True)
    write(m, path)
    # the scale factor (a property the Python API does not set)
    tree = etree.parse(str(path))
    (el,) = tree.xpath("//CoordinateCouplerConstraint[@name='couple_s']")
    etree.SubElement(el, "scale_factor").text = "0.7"
    tree.write(str(path), xml_declaration=True, encoding="UTF-8")
    return path


def patella_model(path, seed=5, coupler="linear"):
    """Rajagopal 2016's patella, made up: ground -Pin(hip)- femur -Pin(knee)- tibia, and
    femur -CustomJoint- patella moved by its own coordinate ``beta`` through splines only
    (rotation1 and two translations SimmSplines of beta, no axis linear in it), with a
    CoordinateCouplerConstraint beta = f(knee): ``coupler`` "linear" is Rajagopal's
    LinearFunction(1, 0), "spline" a SimmSpline of the knee angle. Markers on every body."""
    rng = np.random.default_rng(seed)
    m = osim.Model()
    m.setName("patella")
    g = m.getGround()
    B = {n: random_body(n, rng) for n in ("femur", "tibia", "patella")}
    for b in B.values():
        m.addBody(b)
    m.addJoint(fixed_joint(osim.PinJoint, "hip", g, B["femur"], rng, [(-1.0, 1.0)]))
    m.addJoint(fixed_joint(osim.PinJoint, "knee", B["femur"], B["tibia"], rng, [(0.0, 2.0)]))
    x = np.linspace(0.0, 2.0944, 13)
    axes = [((0, 0, 1), "beta", spline_points(osim.SimmSpline(), r6(x), r6(-0.86 * x + 0.05 * np.sin(3 * x)))),
            ((0, 1, 0), None, None), ((1, 0, 0), None, None),
            ((1, 0, 0), "beta", spline_points(osim.SimmSpline(), r6(x), r6(0.0524 - 0.036 * x))),
            ((0, 1, 0), "beta", spline_points(osim.SimmSpline(), r6(x), r6(-0.0108 - 0.03 * np.sin(1.5 * x)))),
            ((0, 0, 1), None, None)]
    m.addJoint(custom_joint("patellofemoral", B["femur"], B["patella"], rng, axes))
    con = osim.CoordinateCouplerConstraint()
    con.setName("patella_follows_knee")
    con.setIndependentCoordinateNames(osim.ArrayStr("knee_coord_0", 1))
    con.setDependentCoordinateName("beta")
    con.setFunction(osim.LinearFunction(1.0, 0.0) if coupler == "linear" else
                    spline_points(osim.SimmSpline(), r6(x), r6(0.9 * x + 0.1 * np.sin(2 * x))))
    m.addConstraint(con)
    m.finalizeFromProperties()
    cs = m.updCoordinateSet()
    cs.get("beta").setRangeMin(0.0)
    cs.get("beta").setRangeMax(2.0944)
    knee = cs.get("knee_coord_0").getDefaultValue()
    cs.get("beta").setDefaultValue(con.getFunction().calcValue(osim.Vector(1, knee)))
    for b in B.values():
        add_markers(m, b, rng)
    write(m, path)
    return path


def weld_chain_model(path, seed=4):
    """A WeldJoint chain: ground -Pin- a -Weld- b -Weld- c, a -Pin- d, c -Ball- e (with
    offsets and rotations on every joint): b and c are merged into a. Also frames on
    frames: d owns an offset frame f1 (a body component, ``socket_parent`` ``..``), the
    model owns f2 on f1 (a model component), f2 carries a marker and is the parent frame
    of the PinJoint of body g; d's coordinate is prescribed (a SimmSpline of time)."""
    rng = np.random.default_rng(seed)
    m = osim.Model()
    m.setName("weld_chain")
    g = m.getGround()
    B = {n: random_body(n, rng) for n in ("a", "b", "c", "d", "e", "g")}
    for b in B.values():
        m.addBody(b)
    m.addJoint(fixed_joint(osim.PinJoint, "ja", g, B["a"], rng, [(-2.0, 2.0)]))
    m.addJoint(fixed_joint(osim.WeldJoint, "jb", B["a"], B["b"], rng))
    m.addJoint(fixed_joint(osim.WeldJoint, "jc", B["b"], B["c"], rng))
    m.addJoint(fixed_joint(osim.PinJoint, "jd", B["a"], B["d"], rng, [(-2.0, 2.0)]))
    m.addJoint(fixed_joint(osim.BallJoint, "je", B["c"], B["e"], rng, BALL_RANGES))
    R1, R2 = osim.Rotation(), osim.Rotation()
    R1.setRotationToBodyFixedXYZ(vec3([0.2, -0.3, 0.4]))
    R2.setRotationToBodyFixedXYZ(vec3([-0.5, 0.1, 0.3]))
    f1 = osim.PhysicalOffsetFrame("f1", B["d"], osim.Transform(R1, vec3([0.1, 0.02, -0.05])))
    B["d"].addComponent(f1)
    f2 = osim.PhysicalOffsetFrame("f2", f1, osim.Transform(R2, vec3([-0.03, 0.06, 0.01])))
    m.addComponent(f2)
    m.addJoint(fixed_joint(osim.PinJoint, "jg", f2, B["g"], rng, [(-2.0, 2.0)]))
    m.addMarker(osim.Marker("f2.M", f2, vec3([0.01, 0.02, 0.03])))
    for b in B.values():
        add_markers(m, b, rng)
    m.finalizeFromProperties()
    c = m.updCoordinateSet().get("jd_coord_0")
    c.setPrescribedFunction(spline_points(osim.SimmSpline(), [0.0, 0.5, 1.0, 1.5], [0.1, 0.9, 0.2, -0.6]))
    c.setDefaultIsPrescribed(True)
    return write(m, path)


# -------------------------------------------------------------------------- the oracle


class Oracle:
    """OpenSim's model of a file (``opensim.Model(path)``) and its state."""

    def __init__(self, path, assembly_accuracy=None):
        self.model = osim.Model(str(path))
        if assembly_accuracy is not None:
            self.model.set_assembly_accuracy(assembly_accuracy)
        self.state = self.model.initSystem()
        cs = self.model.getCoordinateSet()
        self.coords = {cs.get(i).getName(): cs.get(i) for i in range(cs.getSize())}
        self.bodies = {self.model.getBodySet().get(i).getName(): self.model.getBodySet().get(i)
                       for i in range(self.model.getBodySet().getSize())}
        ms = self.model.getMarkerSet()
        self.markers = {ms.get(i).getName(): ms.get(i) for i in range(ms.getSize())}
        self.q_index = self._q_indices()

    def _q_indices(self):
        """The index in the State's q of each coordinate (found by setting it alone)."""
        s = self.state
        q0 = osim.Vector(s.getQ())
        locked = [c for c in self.coords.values() if c.getLocked(s)]
        for c in locked:
            c.setLocked(s, False)
        out = {}
        for name, c in self.coords.items():
            for other in self.coords.values():
                other.setValue(s, 0.0, False)
            c.setValue(s, 0.123456, False)
            q = np.array(s.getQ().to_numpy())
            (idx,) = np.flatnonzero(np.abs(q - 0.123456) < 1e-12)
            out[name] = int(idx)
        s.setQ(q0)  # back to the assembled defaults
        for c in locked:
            c.setLocked(s, True)
        self.model.realizeVelocity(s)
        return out

    def ranges(self):
        return {n: (c.getRangeMin(), c.getRangeMax()) for n, c in self.coords.items()}

    def sample(self, rng, names=None):
        """Coordinate values uniform in their ranges ({name: value})."""
        names = list(self.coords) if names is None else names
        out = {}
        for n in names:
            lo, hi = self.coords[n].getRangeMin(), self.coords[n].getRangeMax()
            out[n] = float(rng.uniform(lo, hi))
        return out

    def set(self, q, u=None, t=None):
        """Coordinate values (and speeds, u: OpenSim's generalized speeds) at time t (the
        state's time if None; prescribed coordinates take their function's value and
        derivative) -> the state realized to velocity; returns q̇ of every coordinate
        {name: dq/dt}."""
        s = self.state
        if t is not None:
            s.setTime(float(t))
        x = osim.Vector(1, s.getTime())
        for n, v in q.items():
            self.coords[n].setValue(s, v, False)
        for n, c in self.coords.items():
            c.setSpeedValue(s, 0.0 if u is None else u.get(n, 0.0))
            if c.isPrescribed(s):
                f = c.getPrescribedFunction()
                c.setValue(s, f.calcValue(x), False)
                c.setSpeedValue(s, f.calcDerivative([0], x))
        self.model.realizeVelocity(s)
        qdot = np.array(s.getQDot().to_numpy())
        return {n: float(qdot[i]) for n, i in self.q_index.items()}

    def body_pose(self, name):
        X = self.bodies[name].getTransformInGround(self.state)
        return np3(X.p()), np33(X.R())

    def body_velocity(self, name):
        """(ω in ground, velocity of the body origin in ground)."""
        V = self.bodies[name].getVelocityInGround(self.state)
        return np3(V.get(0)), np3(V.get(1))

    def marker_position(self, name):
        return np3(self.markers[name].getLocationInGround(self.state))

    def marker_velocity(self, name):
        return np3(self.markers[name].getVelocityInGround(self.state))


# -------------------------------------------------------------------------- OpenSim 3.x

def _coordinate_3x(name, default, lo, hi, locked=False, motion="rotational"):
    return f"""
                <Coordinate name="{name}">
                  <motion_type>{motion}</motion_type>
                  <default_value>{default}</default_value>
                  <default_speed_value>0</default_speed_value>
                  <range>{lo} {hi}</range>
                  <clamped>false</clamped>
                  <locked>{'true' if locked else 'false'}</locked>
                  <prescribed_function />
                  <prescribed>false</prescribed>
                </Coordinate>"""


def _axis_3x(label, axis, coordinate="", function="<Constant><value>0</value></Constant>"):
    return f"""
              <TransformAxis name="{label}">
                <function>{function}</function>
                <coordinates>{coordinate}</coordinates>
                <axis>{axis}</axis>
              </TransformAxis>"""


LINEAR_3X = "<LinearFunction><coefficients>1 0</coefficients></LinearFunction>"


def _constant(value):
    return f"<Constant><value>{value}</value></Constant>"


def _joint_3x(tag, name, parent, frames, coordinates, axes=()):
    """A 3.x joint element: ``frames`` (location_in_parent, orientation_in_parent,
    location, orientation) as text, ``coordinates`` the Coordinate elements, ``axes``
    the six TransformAxis elements of a CustomJoint."""
    loc_in_parent, ori_in_parent, loc, ori = frames
    transform = f"""
            <SpatialTransform>{"".join(axes)}
            </SpatialTransform>""" if axes else ""
    return f"""
          <{tag} name="{name}">
            <parent_body>{parent}</parent_body>
            <location_in_parent>{loc_in_parent}</location_in_parent>
            <orientation_in_parent>{ori_in_parent}</orientation_in_parent>
            <location>{loc}</location>
            <orientation>{ori}</orientation>
            <CoordinateSet>
              <objects>{"".join(coordinates)}
              </objects>
            </CoordinateSet>
            <reverse>false</reverse>{transform}
          </{tag}>"""


def _body_3x(name, mass, com, inertia, joint=""):
    xx, yy, zz, xy, xz, yz = inertia
    return f"""
      <Body name="{name}">
        <mass>{mass}</mass>
        <mass_center>{com}</mass_center>
        <inertia_xx>{xx}</inertia_xx>
        <inertia_yy>{yy}</inertia_yy>
        <inertia_zz>{zz}</inertia_zz>
        <inertia_xy>{xy}</inertia_xy>
        <inertia_xz>{xz}</inertia_xz>
        <inertia_yz>{yz}</inertia_yz>
        <Joint>{joint}
        </Joint>
        <VisibleObject>
          <geometry_files />
          <scale_factors>1 1 1</scale_factors>
        </VisibleObject>
        <WrapObjectSet><objects /></WrapObjectSet>
      </Body>"""


def _spline(tag, x, y):
    return f"<{tag}><x> {x}</x><y> {y}</y></{tag}>"


KNEE_X_3X = "-2.0944 -1.74533 -1.39626 -1.0472 -0.698132 -0.349066 -0.174533 0.197344 0.337395 0.490178 1.52146 2.0944"
KNEE_TX_3X = "-0.0032 0.00179 0.00411 0.0041 0.00212 -0.001 -0.0031 -0.005227 -0.005435 -0.005574 -0.005435 -0.00525"
KNEE_TY_3X = "-0.4226 -0.4082 -0.399 -0.3976 -0.3966 -0.3971 -0.3972 -0.397401 -0.401963 -0.4 -0.3932 -0.39"
#: the brace's FreeJoint frames are the WeldConstraint's frames (welded at q = 0)
WELD_FRAMES_3X = ("0.03 -0.2 0.04", "0.2 -0.1 0.3", "-0.02 0.05 0.01", "0.1 0.4 -0.2")
#: the plate's FreeJoint locations are the PointConstraint's points
POINT_3X = ("0.05 0.02 -0.03", "-0.01 0.04 0.02")
#: coordinates of the 3.x model that OpenSim's assembly places (no goal)
FREE_3X = tuple(f"brace_{k}" for k in ("rx", "ry", "rz", "tx", "ty", "tz")) + ("plate_tx", "plate_ty", "plate_tz")


def _free_coordinates_3x(prefix, rotation_ranges):
    out = [_coordinate_3x(f"{prefix}_r{a}", 0, lo, hi) for a, (lo, hi) in zip("xyz", rotation_ranges)]
    return out + [_coordinate_3x(f"{prefix}_t{a}", 0, -1, 1, motion="translational") for a in "xyz"]


def model_3x_text():
    """An OpenSim 3.x model (``Version="30000"``), written by hand in the 3.x layout:
    joints nested in their child body (``Body/Joint/…`` with ``parent_body``,
    ``location_in_parent``, ``orientation_in_parent``, ``location``, ``orientation`` and a
    ``CoordinateSet``), the ground a Body named ``ground``, inertia as ``inertia_xx`` …,
    functions wrapped in ``<function>``, markers with ``<body>``, and a ConstraintSet with
    a CoordinateCouplerConstraint (``scale_factor``, ``isDisabled``), a WeldConstraint
    (``body_1``, ``location_body_1``, ``orientation_body_1`` …) and a PointConstraint.

    pelvis (6-dof CustomJoint from ground) → femur (CustomJoint hip, hip_rotation locked)
    → tibia (CustomJoint knee: translations SimmSpline and NaturalCubicSpline of
    knee_angle) → foot (PinJoint ankle) → toes (WeldJoint, merged into foot);
    tibia → patella (CustomJoint, patella_angle = 1.2·spline(knee_angle), a coupler);
    tibia → brace (FreeJoint whose frames are the WeldConstraint's: welded at q = 0);
    foot → plate (FreeJoint; PointConstraint between foot and plate: its translations
    follow its rotations)."""
    lin, c0 = LINEAR_3X, _constant(0)
    pelvis = _joint_3x("CustomJoint", "ground_pelvis", "ground", ("0 0.9 0", "0 0 0", "0 0 0", "0 0 0"), [
        _coordinate_3x("pelvis_tilt", 0.05, -1.0, 1.0), _coordinate_3x("pelvis_list", -0.03, -0.5, 0.5),
        _coordinate_3x("pelvis_rotation", 0.1, -1.0, 1.0),
        _coordinate_3x("pelvis_tx", 0.2, -1.0, 1.0, motion="translational"),
        _coordinate_3x("pelvis_ty", 0.93, 0.5, 1.2, motion="translational"),
        _coordinate_3x("pelvis_tz", -0.1, -0.5, 0.5, motion="translational"),
    ], [
        _axis_3x("rotation1", "0 0 1", "pelvis_tilt", lin), _axis_3x("rotation2", "1 0 0", "pelvis_list", lin),
        _axis_3x("rotation3", "0 1 0", "pelvis_rotation", lin), _axis_3x("translation1", "1 0 0", "pelvis_tx", lin),
        _axis_3x("translation2", "0 1 0", "pelvis_ty", lin), _axis_3x("translation3", "0 0 1", "pelvis_tz", lin),
    ])
    hip = _joint_3x("CustomJoint", "hip_r", "pelvis",
                    ("-0.0707 -0.0661 0.0835", "0.05 -0.1 0.2", "0.01 0.02 -0.03", "-0.1 0.05 0.15"), [
        _coordinate_3x("hip_flexion_r", 0.2, -1.2, 2.0), _coordinate_3x("hip_adduction_r", -0.05, -0.8, 0.4),
        _coordinate_3x("hip_rotation_r", 0.1, -0.7, 0.7, locked=True),
    ], [
        _axis_3x("rotation1", "0 0 1", "hip_flexion_r", lin), _axis_3x("rotation2", "1 0 0", "hip_adduction_r", lin),
        _axis_3x("rotation3", "0 1 0", "hip_rotation_r", lin), _axis_3x("translation1", "1 0 0"),
        _axis_3x("translation2", "0 1 0"), _axis_3x("translation3", "0 0 1"),
    ])
    knee = _joint_3x("CustomJoint", "knee_r", "femur_r",
                     ("0 0 0", "0.02 -0.03 0.04", "0.005 0.01 -0.02", "0.03 0.02 -0.05"), [
        _coordinate_3x("knee_angle_r", -0.4, -2.0, 0.15),
    ], [
        _axis_3x("rotation1", "0 0 1", "knee_angle_r", lin), _axis_3x("rotation2", "1 0 0", "", c0),
        _axis_3x("rotation3", "0 1 0", "", c0),
        _axis_3x("translation1", "1 0 0", "knee_angle_r", _spline('SimmSpline name="f1"', KNEE_X_3X, KNEE_TX_3X)
                 .replace('</SimmSpline name="f1">', "</SimmSpline>")),
        _axis_3x("translation2", "0 1 0", "knee_angle_r", _spline("NaturalCubicSpline", KNEE_X_3X, KNEE_TY_3X)),
        _axis_3x("translation3", "0 0 1", "", _constant(0.002)),
    ])
    patella = _joint_3x("CustomJoint", "patellofemoral_r", "tibia_r",
                        ("0.05 -0.02 0.003", "0 0 0.1", "0 0.03 0", "0 0 0"), [
        _coordinate_3x("patella_angle_r", -0.2, -3.0, 3.0),
    ], [
        _axis_3x("rotation1", "0 0 1", "patella_angle_r", lin), _axis_3x("rotation2", "1 0 0", "", c0),
        _axis_3x("rotation3", "0 1 0", "", c0), _axis_3x("translation1", "1 0 0", "", _constant(0.01)),
        _axis_3x("translation2", "0 1 0", "", _constant(-0.02)), _axis_3x("translation3", "0 0 1"),
    ])
    ankle = _joint_3x("PinJoint", "ankle_r", "tibia_r",
                      ("0 -0.43 0", "0.175895 -0.105208 0.0186622", "0.01 0.02 0.005", "-0.05 0.1 0.02"),
                      [_coordinate_3x("ankle_angle_r", 0.1, -0.7, 0.5)])
    toes = _joint_3x("WeldJoint", "mtp_r", "foot_r", ("0.1788 -0.002 0.00108", "-0.1 0.2 0.05", "0.005 0 -0.01",
                                                       "0.1 0 0.3"), [])
    brace = _joint_3x("FreeJoint", "brace_free", "tibia_r", WELD_FRAMES_3X,
                      _free_coordinates_3x("brace", [(-3.14159, 3.14159)] * 3))
    plate = _joint_3x("FreeJoint", "plate_free", "foot_r", (POINT_3X[0], "0 0 0", POINT_3X[1], "0 0 0"),
                      _free_coordinates_3x("plate", [(-1.5, 1.5), (-1.2, 1.2), (-1.5, 1.5)]))
    bodies = "".join([
        _body_3x("ground", 0, "0 0 0", (0, 0, 0, 0, 0, 0)),
        _body_3x("pelvis", 11.777, "-0.0707 0 0", (0.1028, 0.0871, 0.0579, 0.001, -0.002, 0.003), pelvis),
        _body_3x("femur_r", 9.3014, "0 -0.17 0", (0.1339, 0.0351, 0.1412, 0, 0, 0), hip),
        _body_3x("tibia_r", 3.7075, "0 -0.1867 0", (0.0504, 0.0051, 0.0511, 0, 0, 0), knee),
        _body_3x("patella_r", 0.0862, "0.0018 0.0264 0", (2.87e-06, 1.311e-05, 1.311e-05, 0, 0, 0), patella),
        _body_3x("foot_r", 1.25, "0.1 0.03 0", (0.0014, 0.0039, 0.0041, 0, 0, 0), ankle),
        _body_3x("toes_r", 0.2166, "0.0346 0.006 -0.0175", (0.0001, 0.0002, 0.0001, 0, 0, 0), toes),
        _body_3x("brace", 0.5, "0.01 -0.02 0.03", (0.002, 0.001, 0.002, 0.0001, 0, 0), brace),
        _body_3x("plate", 0.3, "0.02 0.01 -0.01", (0.001, 0.0015, 0.002, 0, 0.0001, 0), plate),
    ])
    markers = [("R.ASIS", "pelvis", "0.0148 0.0 0.128"), ("V.Sacral", "pelvis", "-0.175 0.01 0"),
               ("R.Thigh", "femur_r", "0.01 -0.2 0.07"), ("R.Knee.Lat", "femur_r", "0 -0.404 0.05"),
               ("R.Shank", "tibia_r", "0.02 -0.2 0.05"), ("R.Ankle.Lat", "tibia_r", "-0.005 -0.41 0.053"),
               ("R.Heel", "foot_r", "-0.02 0.01 -0.005"), ("R.Toe.Tip", "toes_r", "0.06 -0.005 0.01"),
               ("R.Patella", "patella_r", "0.01 0.02 0.0"), ("Brace.M", "brace", "0.02 0.03 -0.01"),
               ("Plate.M", "plate", "0.05 -0.01 0.02")]
    marker_xml = "".join(f"""
        <Marker name="{n}">
          <body>{b}</body>
          <location>{loc}</location>
          <fixed>false</fixed>
        </Marker>""" for n, b, loc in markers)
    patella_spline = _spline("SimmSpline", "-2.0944 -1.5 -1.0 -0.5 0 0.2", "-1.8 -1.3 -0.88 -0.42 0 0.15")
    constraints = f"""
        <CoordinateCouplerConstraint name="patella_coupler">
          <isDisabled>false</isDisabled>
          <coupled_coordinates_function>{patella_spline}</coupled_coordinates_function>
          <independent_coordinate_names>knee_angle_r</independent_coordinate_names>
          <dependent_coordinate_name>patella_angle_r</dependent_coordinate_name>
          <scale_factor>1.2</scale_factor>
        </CoordinateCouplerConstraint>
        <WeldConstraint name="brace_weld">
          <isDisabled>false</isDisabled>
          <body_1>tibia_r</body_1>
          <body_2>brace</body_2>
          <location_body_1>{WELD_FRAMES_3X[0]}</location_body_1>
          <orientation_body_1>{WELD_FRAMES_3X[1]}</orientation_body_1>
          <location_body_2>{WELD_FRAMES_3X[2]}</location_body_2>
          <orientation_body_2>{WELD_FRAMES_3X[3]}</orientation_body_2>
        </WeldConstraint>
        <PointConstraint name="plate_point">
          <isDisabled>false</isDisabled>
          <body_1>foot_r</body_1>
          <body_2>plate</body_2>
          <location_body_1>{POINT_3X[0]}</location_body_1>
          <location_body_2>{POINT_3X[1]}</location_body_2>
        </PointConstraint>"""
    return f"""<?xml version="1.0" encoding="UTF-8" ?>
<OpenSimDocument Version="30000">
  <Model name="leg3x">
    <defaults />
    <credits>openfdk tests</credits>
    <publications />
    <length_units>meters</length_units>
    <force_units>N</force_units>
    <gravity> 0 -9.80665 0</gravity>
    <BodySet>
      <objects>{bodies}
      </objects>
      <groups />
    </BodySet>
    <ConstraintSet>
      <objects>{constraints}
      </objects>
      <groups />
    </ConstraintSet>
    <ForceSet>
      <objects />
      <groups />
    </ForceSet>
    <MarkerSet>
      <objects>{marker_xml}
      </objects>
      <groups />
    </MarkerSet>
  </Model>
</OpenSimDocument>
"""


# ------------------------------------------------------------ arms for the force tests

def two_link_arm(name="arm"):
    """A model with two pin joints (coordinates q1, q2): ``upper`` hangs from the ground
    at (0, 1, 0), ``lower`` from ``upper`` at (0, −0.3, 0), offset and rotated frames and
    off-axis mass properties. Returns (model, upper, lower), not finalised."""
    m = osim.Model()
    m.setName(name)
    b1 = osim.Body("upper", 2.0, osim.Vec3(0, -0.15, 0.01), osim.Inertia(0.02, 0.005, 0.021, 0.001, 0, 0))
    b2 = osim.Body("lower", 1.2, osim.Vec3(0.01, -0.12, 0), osim.Inertia(0.01, 0.003, 0.011, 0, 0.0005, 0))
    m.addBody(b1)
    m.addBody(b2)
    j1 = osim.PinJoint("shoulder", m.getGround(), osim.Vec3(0, 1.0, 0), osim.Vec3(0.1, 0, 0), b1,
                          osim.Vec3(0, 0, 0), osim.Vec3(0, 0, 0))
    j2 = osim.PinJoint("elbow", b1, osim.Vec3(0, -0.3, 0), osim.Vec3(0, 0, 0), b2, osim.Vec3(0, 0, 0),
                          osim.Vec3(0, 0.2, 0))
    m.addJoint(j1)
    m.addJoint(j2)
    j1.updCoordinate().setName("q1")
    j2.updCoordinate().setName("q2")
    return m, b1, b2


def write_motion(path, t, columns):
    """A coordinate file (.mot, radians) of {name: (n,)} at times t (n,) s."""
    names = list(columns)
    with open(path, "w") as f:
        f.write(f"motion\nversion=1\nnRows={len(t)}\nnColumns={len(names) + 1}\ninDegrees=no\nendheader\n"
                + "\t".join(["time"] + names) + "\n")
        for k in range(len(t)):
            f.write("\t".join(f"{x:.12g}" for x in [t[k]] + [columns[n][k] for n in names]) + "\n")
    return path


def static_optimization(model_path, motion_path, folder, start=0.1, end=0.9, exponent=2):
    """Run OpenSim's StaticOptimization (AnalyzeTool, unfiltered coordinates, the model's
    force set) and return (times (n,), {actuator: forces (n,)}) of its force file."""
    from openfdk.io.storage import read_storage

    tool = osim.AnalyzeTool()
    tool.setModelFilename(str(model_path))
    tool.setName("so")
    tool.setCoordinatesFileName(str(motion_path))
    tool.setLowpassCutoffFrequency(-1)
    tool.setInitialTime(start)
    tool.setFinalTime(end)
    tool.setResultsDir(str(folder / "so"))
    so = osim.StaticOptimization()
    so.setStartTime(start)
    so.setEndTime(end)
    so.setActivationExponent(exponent)
    tool.getAnalysisSet().cloneAndAppend(so)
    tool.printToXML(str(folder / "so_setup.xml"))
    osim.AnalyzeTool(str(folder / "so_setup.xml")).run()
    t, columns, _ = read_storage(folder / "so" / "so_StaticOptimization_force.sto")
    return t, columns


def arm_static_optimization(model_path, folder):
    """The arm at ``model_path`` (coordinates q_shoulder, q_elbow) with a reserve
    CoordinateActuator (optimal force 1 N m) on each coordinate, written to
    ``folder/arm_so.osim``, a smooth motion (201 samples over 1 s) and OpenSim's
    StaticOptimization over 0.1–0.9 s with exponent 2. Returns (model path, motion path,
    (times (n,), {actuator: forces (n,)}))."""
    model = osim.Model(str(model_path))
    for coordinate in ("q_shoulder", "q_elbow"):
        reserve = osim.CoordinateActuator(coordinate)
        reserve.setName(f"reserve_{coordinate}")
        reserve.setOptimalForce(1.0)
        model.addForce(reserve)
    path = write(model, folder / "arm_so.osim")
    t = np.linspace(0, 1, 201)
    motion = write_motion(folder / "motion.mot", t, {"q_shoulder": 0.3 + 0.3 * np.sin(2 * np.pi * 0.8 * t),
                                                     "q_elbow": 0.6 + 0.5 * np.sin(2 * np.pi * 1.1 * t + 0.5)})
    return path, motion, static_optimization(path, motion, folder)
