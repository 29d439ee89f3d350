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
      non-unit axis, a constant translation and a PolynomialFunction of the ankle angle.
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
    set_ranges(m, {"hip_flexion": (-1.0, 1.5), "hip_adduction": (-0.4, 0.4), "hip_rotation": (-0.8, 0.8),
                   "knee_angle": KNEE_RANGE, "ankle_angle": (-0.7, 0.5), "subtalar": (-0.5, 0.5),
                   "ankle_slide": (-0.05, 0.05)}, rng)
    for b in (femur, tibia, foot):
        add_markers(m, b, rng)
    write(m, path)
    # the knee's rotation3 as a NaturalCubicSpline (OpenSim reads it as a SimmSpline)
    tree = etree.parse(str(path))
    (el,) = tree.xpath("//CustomJoint[@name='knee']/SpatialTransform/TransformAxis[@name='rotation3']/SimmSpline")
    el.tag = "NaturalCubicSpline"
    tree.write(str(path), xml_declaration=True, encoding="UTF-8")
    return path


def constraints_model(path, seed=3):
    """Couplers, a WeldConstraint and a PointConstraint:

    ground -Pin(q1)- a -Pin(q2)- b, coupler q2 = SimmSpline(q1);
    ground -Slider(qs)- s, coupler qs = 0.7·(0.2 q1 + 0.05) (LinearFunction, scale factor 0.7
    added to the XML: the Python API has no setter);
    ground -Free- w, WeldConstraint between offset frames of b and w;
    ground -Free- p, PointConstraint between a point of b and a point of p.
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
    m.addJoint(fixed_joint(osim.FreeJoint, "jw", g, B["w"], rng, [(-3.0, 3.0)] * 3 + [(-2.0, 2.0)] * 3))
    m.addJoint(fixed_joint(osim.FreeJoint, "jp", g, B["p"], rng, BALL_RANGES + [(-2.0, 2.0)] * 3))
    x = np.linspace(-1.6, 1.6, 7)
    spline = spline_points(osim.SimmSpline(), r6(x), r6(0.8 * np.sin(1.2 * x) + 0.3))
    c1 = osim.CoordinateCouplerConstraint()
    c1.setName("couple_b")
    c1.setIndependentCoordinateNames(osim.ArrayStr("j1_coord_0", 1))
    c1.setDependentCoordinateName("j2_coord_0")
    c1.setFunction(spline)
    m.addConstraint(c1)
    c2 = osim.CoordinateCouplerConstraint()
    c2.setName("couple_s")
    c2.setIndependentCoordinateNames(osim.ArrayStr("j1_coord_0", 1))
    c2.setDependentCoordinateName("js_coord_0")
    c2.setFunction(osim.LinearFunction(0.2, 0.05))
    m.addConstraint(c2)
    R1, R2 = osim.Rotation(), osim.Rotation()
    R1.setRotationToBodyFixedXYZ(vec3([0.3, -0.2, 0.5]))
    R2.setRotationToBodyFixedXYZ(vec3([-0.4, 0.1, 0.2]))
    X1 = osim.Transform(R1, vec3([0.05, -0.1, 0.02]))
    X2 = osim.Transform(R2, vec3([-0.03, 0.04, 0.08]))
    m.addConstraint(osim.WeldConstraint("weld_bw", B["b"], X1, B["w"], X2))
    m.addConstraint(osim.PointConstraint(B["b"], vec3([0.1, 0.05, -0.04]), B["p"], vec3([-0.02, 0.07, 0.03])))
    for b in B.values():
        add_markers(m, b, rng)
    write(m, path)
    # the scale factor (a property the Python API does not set)
    tree = etree.parse(str(path))
    (el,) = tree.xpath("//CoordinateCouplerConstraint[@name='couple_s']")
    etree.SubElement(el, "scale_factor").text = "0.7"
    tree.write(str(path), xml_declaration=True, encoding="UTF-8")
    return path


def weld_chain_model(path, seed=4):
    """A WeldJoint chain: ground -Pin- a -Weld- b -Weld- c, a -Pin- d, c -Ball- e (with
    offsets and rotations on every joint): b and c are merged into a."""
    rng = np.random.default_rng(seed)
    m = osim.Model()
    m.setName("weld_chain")
    g = m.getGround()
    B = {n: random_body(n, rng) for n in ("a", "b", "c", "d", "e")}
    for b in B.values():
        m.addBody(b)
    m.addJoint(fixed_joint(osim.PinJoint, "ja", g, B["a"], rng, [(-2.0, 2.0)]))
    m.addJoint(fixed_joint(osim.WeldJoint, "jb", B["a"], B["b"], rng))
    m.addJoint(fixed_joint(osim.WeldJoint, "jc", B["b"], B["c"], rng))
    m.addJoint(fixed_joint(osim.PinJoint, "jd", B["a"], B["d"], rng, [(-2.0, 2.0)]))
    m.addJoint(fixed_joint(osim.BallJoint, "je", B["c"], B["e"], rng, BALL_RANGES))
    for b in B.values():
        add_markers(m, b, rng)
    return write(m, path)


# -------------------------------------------------------------------------- the oracle


class Oracle:
    """OpenSim's model of a file (``opensim.Model(path)``) and its state."""

    def __init__(self, path):
        self.model = osim.Model(str(path))
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
        out = {}
        for name, c in self.coords.items():
            for other in self.coords.values():
                other.setValue(s, 0.0, False)
            c.setValue(s, 0.123456, False)
            q = np.array(s.getQ().to_numpy())
            (idx,) = np.flatnonzero(np.abs(q - 0.123456) < 1e-12)
            out[name] = int(idx)
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

    def set(self, q, u=None):
        """Coordinate values (and speeds, u: OpenSim's generalized speeds) -> the state
        realized to velocity; returns q̇ of every coordinate {name: dq/dt}."""
        s = self.state
        for n, v in q.items():
            self.coords[n].setValue(s, v, False)
        for n, c in self.coords.items():
            c.setSpeedValue(s, 0.0 if u is None else u.get(n, 0.0))
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
