"""OpenSim muscles in: Thelen2003Muscle with PathPoint paths (docs/opensim-import.md),
against OpenSim 4.6 as the oracle.

Models are built with OpenSim's API (4.x) or written by hand in the 3.x layout, printed,
then read by OpenSim (``opensim.Model(path)``) and by openfdk. At random coordinate
values each muscle's path length and its moment arm about each coordinate
(``computeMomentArm``: −∂l/∂q) are compared with openfdk's path length and its path
Jacobian projected on the coordinate (the pose velocity of q̇ = e_q from
``pose_from_coordinates``), and with a central difference of openfdk's length over q.
"""

from __future__ import annotations

import numpy as np
import pytest
from lxml import etree

opensim = pytest.importorskip("opensim")

import opensim_models as om  # noqa: E402  (tests/opensim_models.py)

from openfdk.forces.hill import hill_curvature  # noqa: E402
from openfdk.io.modelfile import model_from_dict  # noqa: E402
from openfdk.io.opensim import OsimError, read_osim  # noqa: E402
from openfdk.kinematics.coordinate_pose import pose_from_coordinates  # noqa: E402

N_SAMPLES = 60

#: non-default Thelen2003Muscle parameters of each muscle of the 4.x model
PARAMS = {
    "biceps.long": dict(max_isometric_force=812.5, optimal_fiber_length=0.121, tendon_slack_length=0.251,
                        pennation_angle_at_optimal=0.11, max_contraction_velocity=8.5, FmaxTendonStrain=0.05,
                        FmaxMuscleStrain=0.55, KshapeActive=0.5, KshapePassive=4.5, Af=0.3, Flen=1.6),
    "triceps": dict(max_isometric_force=1200.0, optimal_fiber_length=0.09, tendon_slack_length=0.22,
                    pennation_angle_at_optimal=0.2, max_contraction_velocity=12.0, FmaxTendonStrain=0.033,
                    FmaxMuscleStrain=0.7, KshapeActive=0.4, KshapePassive=3.5, Af=0.15, Flen=1.8),
    "delt": dict(max_isometric_force=500.0, optimal_fiber_length=0.1, tendon_slack_length=0.23,
                 pennation_angle_at_optimal=0.0, max_contraction_velocity=10.0, FmaxTendonStrain=0.04,
                 FmaxMuscleStrain=0.6, KshapeActive=0.45, KshapePassive=5.0, Af=0.5, Flen=1.4),
}
#: each muscle's path points: (name, body, location)
POINTS = {
    "biceps.long": [("origin", "ground", (0.02, 0.9, 0.01)), ("mid", "upper", (0.03, -0.2, 0.01)),
                    ("ins", "fore", (0.02, -0.05, 0.0))],
    "triceps": [("o", "upper", (-0.03, -0.05, 0.0)), ("via1", "upper", (-0.04, -0.25, 0.01)),
                ("via2", "fore", (-0.03, 0.04, -0.01)), ("i", "fore", (-0.01, -0.03, 0.0))],
    "delt": [("o", "ground", (0.12, 1.02, 0.3)), ("i", "upper", (0.04, -0.08, 0.02))],
}
HILL_KEYS = {
    "max_isometric_force": "max_isometric_force", "optimal_fiber_length": "optimal_fibre_length",
    "tendon_slack_length": "tendon_slack_length", "pennation_angle_at_optimal": "pennation_angle_at_optimal",
    "max_contraction_velocity": "max_contraction_velocity", "FmaxTendonStrain": "tendon_strain_at_max_force",
    "FmaxMuscleStrain": "passive_strain_at_max_force", "KshapeActive": "force_length_width",
    "KshapePassive": "passive_shape_factor", "Flen": "max_eccentric_force",
}


def arm_skeleton(name):
    """(model, {body name: body}) of two bodies on pin joints q_shoulder and q_elbow
    (offset, rotated frames), no forces yet."""
    m = opensim.Model()
    m.setName(name)
    bodies = {"ground": m.getGround()}
    upper = opensim.Body("upper", 2.0, om.vec3((0.01, -0.15, 0.02)), opensim.Inertia(0.02, 0.01, 0.02, 0.001, 0, 0))
    fore = opensim.Body("fore", 1.0, om.vec3((0.0, -0.12, -0.01)), opensim.Inertia(0.01, 0.005, 0.01))
    for b in (upper, fore):
        m.addBody(b)
        bodies[b.getName()] = b
    shoulder = opensim.PinJoint("shoulder", m.getGround(), om.vec3((0, 1, 0)), om.vec3((0.1, 0.2, 0.3)),
                                upper, om.vec3((0, 0.05, 0)), om.vec3((0, 0, 0)))
    elbow = opensim.PinJoint("elbow", upper, om.vec3((0, -0.3, 0)), om.vec3((0.0, 0.3, 0.2)),
                             fore, om.vec3((0, 0.02, 0)), om.vec3((0.1, 0, 0)))
    shoulder.updCoordinate().setName("q_shoulder")
    elbow.updCoordinate().setName("q_elbow")
    m.addJoint(shoulder)
    m.addJoint(elbow)
    return m, bodies


def arm_model(path):
    """Two bodies on pin joints (offset, rotated frames), three Thelen2003Muscles with
    2–4 PathPoints on the ground and both bodies; written by OpenSim."""
    m, bodies = arm_skeleton("arm")
    for name, params in PARAMS.items():
        mu = opensim.Thelen2003Muscle(name, params["max_isometric_force"], params["optimal_fiber_length"],
                                      params["tendon_slack_length"], params["pennation_angle_at_optimal"])
        for key, value in params.items():
            getattr(mu, f"set_{key}")(value)
        for pname, body, loc in POINTS[name]:
            mu.addNewPathPoint(pname, bodies[body], om.vec3(loc))
        m.addForce(mu)
    m.finalizeConnections()
    assert m.printToXML(str(path))
    return path


def model_3x_text():
    """The 3.x layout: CustomJoints nested in the bodies (one about an oblique axis),
    a Thelen2003Muscle whose PathPoints name their ``<body>``."""
    rot = lambda q, axis: [om._axis_3x("rotation1", axis, q, om.LINEAR_3X), om._axis_3x("rotation2", "1 0 0"),
                           om._axis_3x("rotation3", "0 1 0"), om._axis_3x("translation1", "1 0 0"),
                           om._axis_3x("translation2", "0 1 0"), om._axis_3x("translation3", "0 0 1")]
    j1 = om._joint_3x("CustomJoint", "shoulder", "ground", ("0 1 0", "0.1 0.2 0.3", "0 0.05 0", "0 0 0"),
                      [om._coordinate_3x("q_shoulder", 0, -2, 2)], rot("q_shoulder", "0 0 1"))
    j2 = om._joint_3x("CustomJoint", "elbow", "upper", ("0 -0.3 0", "0 0.3 0.2", "0 0.02 0", "0.1 0 0"),
                      [om._coordinate_3x("q_elbow", 0, -2, 2)], rot("q_elbow", "0.2 0.1 0.97"))
    bodies = (om._body_3x("ground", 0, "0 0 0", (0,) * 6)
              + om._body_3x("upper", 2.0, "0.01 -0.15 0.02", (0.02, 0.01, 0.02, 0.001, 0, 0), j1)
              + om._body_3x("fore", 1.0, "0 -0.12 -0.01", (0.01, 0.005, 0.01, 0, 0, 0), j2))
    points = "".join(f"""
              <PathPoint name="{n}"><location>{" ".join(map(str, loc))}</location><body>{b}</body></PathPoint>"""
                     for n, b, loc in POINTS["triceps"])
    params = "".join(f"<{k}>{v}</{k}>" for k, v in PARAMS["triceps"].items())
    return f"""<?xml version="1.0" encoding="UTF-8" ?>
<OpenSimDocument Version="30000">
  <Model name="arm3x">
    <length_units>meters</length_units>
    <force_units>N</force_units>
    <gravity> 0 -9.80665 0</gravity>
    <BodySet><objects>{bodies}
    </objects><groups /></BodySet>
    <ForceSet><objects>
      <Thelen2003Muscle name="triceps">
        <isDisabled>false</isDisabled>
        <min_control>0.02</min_control>
        <max_control>1</max_control>
        <GeometryPath>
          <PathPointSet><objects>{points}
          </objects><groups /></PathPointSet>
          <PathWrapSet><objects /><groups /></PathWrapSet>
        </GeometryPath>
        {params}
        <activation_time_constant>0.01</activation_time_constant>
        <deactivation_time_constant>0.04</deactivation_time_constant>
      </Thelen2003Muscle>
    </objects><groups /></ForceSet>
  </Model>
</OpenSimDocument>
"""


@pytest.fixture(scope="module")
def workdir(tmp_path_factory):
    return tmp_path_factory.mktemp("osim_muscles")


@pytest.fixture(autouse=True)
def _in_workdir(workdir, monkeypatch):
    monkeypatch.chdir(workdir)  # OpenSim writes opensim.log into the cwd


@pytest.fixture(scope="module")
def arm(workdir):
    return arm_model(workdir / "arm.osim")


def _compare_paths(path, n=N_SAMPLES, seed=0, their_length_derivative=()):
    """Largest |Δl| (m), |Δr| analytic and |Δr| by central difference (m) over ``n``
    random coordinate samples, every muscle, every coordinate. OpenSim's moment arm is
    its ``computeMomentArm``, or for the muscles in ``their_length_derivative`` −∂l/∂q
    by a central difference of OpenSim's own length."""
    data, _ = read_osim(path)
    ours = model_from_dict(data, source=str(path))
    theirs = opensim.Model(str(path))
    state = theirs.initSystem()
    coords = [theirs.getCoordinateSet().get(k) for k in range(theirs.getCoordinateSet().getSize())]
    muscles = [theirs.getMuscles().get(k) for k in range(theirs.getMuscles().getSize())]
    ours_by_name = {m.name: m for m in ours.muscles}
    assert sorted(ours_by_name) == sorted(om_name.replace(".", "_") for om_name in (m.getName() for m in muscles))
    rng = np.random.default_rng(seed)
    worst = np.zeros(3)
    h = 1e-6
    for _ in range(n):
        q = {c.getName(): float(rng.uniform(-1.5, 1.5)) for c in coords}
        for c in coords:
            c.setValue(state, q[c.getName()], False)
        theirs.realizePosition(state)
        for c in coords:
            st, _ = pose_from_coordinates(ours, q, qdot={c.getName(): 1.0})
            st_p, _ = pose_from_coordinates(ours, {**q, c.getName(): q[c.getName()] + h}, state=st.copy())
            st_m, _ = pose_from_coordinates(ours, {**q, c.getName(): q[c.getName()] - h}, state=st.copy())
            for mu in muscles:
                m = ours_by_name[mu.getName().replace(".", "_")]
                value, L, _ = m.path.evaluate(st, 1)
                l_ours = float(np.ravel(value)[0])
                r_ours = -float(np.ravel(np.asarray(L) @ st.get_v())[0])
                r_fd = -(float(np.ravel(m.path.evaluate(st_p, 0)[0])[0])
                         - float(np.ravel(m.path.evaluate(st_m, 0)[0])[0])) / (2 * h)
                if mu.getName() in their_length_derivative:
                    q0 = q[c.getName()]
                    c.setValue(state, q0 + h, False)
                    theirs.realizePosition(state)
                    l_plus = mu.getLength(state)
                    c.setValue(state, q0 - h, False)
                    theirs.realizePosition(state)
                    r_theirs = -(l_plus - mu.getLength(state)) / (2 * h)
                    c.setValue(state, q0, False)
                else:
                    r_theirs = mu.computeMomentArm(state, c)
                theirs.realizePosition(state)
                worst = np.maximum(worst, [abs(l_ours - mu.getLength(state)), abs(r_ours - r_theirs),
                                           abs(r_fd - r_theirs)])
    return worst


def test_path_lengths_and_moment_arms_equal_opensim(arm):
    """3 muscles (2–4 PathPoints on the ground and two bodies), 60 random poses: path
    length ≤ 1e-9 m, moment arm from the analytic path Jacobian ≤ 1e-9 m and from a
    central difference of openfdk's length ≤ 1e-6 m."""
    dl, dr, dr_fd = _compare_paths(arm)
    print(f"4.x: |Δl| ≤ {dl:.2e} m, |Δr| ≤ {dr:.2e} m (analytic), {dr_fd:.2e} m (central difference)")
    assert dl <= 1e-9 and dr <= 1e-9 and dr_fd <= 1e-6


def test_opensim_3x_muscle_path_equals_opensim(workdir):
    """A 3.x file (PathPoints with ``<body>``, CustomJoints, one about an oblique axis)
    read by openfdk equals OpenSim 4.6 reading (converting) it."""
    path = workdir / "arm3x.osim"
    path.write_text(model_3x_text())
    dl, dr, dr_fd = _compare_paths(path, seed=1)
    print(f"3.x: |Δl| ≤ {dl:.2e} m, |Δr| ≤ {dr:.2e} m (analytic), {dr_fd:.2e} m (central difference)")
    assert dl <= 1e-9 and dr <= 1e-9 and dr_fd <= 1e-6
    _, info = read_osim(path)
    s = info["muscle_settings"]["triceps"]
    assert (s["min_control"], s["activation_time_constant"], s["deactivation_time_constant"]) == (0.02, 0.01, 0.04)


def test_hill_parameters_equal_opensim(arm):
    """Each mapped parameter equals OpenSim's value of the file (OpenSim reading it):
    Af is Hill's curvature A = 0.1 + 0.4·fast_fibre_fraction (Thelen's concentric
    force–velocity at full activation, (1 + ṽ)/(1 − ṽ/Af), is openfdk's); the settings
    openfdk's recruitment does not use are reported, unchanged."""
    data, info = read_osim(arm)
    ours = {m.name: m.law for m in model_from_dict(data, source=str(arm)).muscles}
    theirs = opensim.Model(str(arm))
    for k in range(theirs.getMuscles().getSize()):
        mu = opensim.Thelen2003Muscle.safeDownCast(theirs.getMuscles().get(k))
        name = mu.getName().replace(".", "_")
        law = ours[name]
        for osim_key, hill_key in HILL_KEYS.items():
            assert getattr(law, hill_key) == getattr(mu, f"get_{osim_key}")(), (name, osim_key)
        assert float(hill_curvature(law.fast_fibre_fraction)) == pytest.approx(mu.get_Af(), abs=1e-15)
        assert law.max_isometric_force == PARAMS[mu.getName()]["max_isometric_force"]
        s = info["muscle_settings"][name]
        assert s["min_control"] == mu.get_min_control() and s["minimum_activation"] == mu.get_minimum_activation()
        assert s["activation_time_constant"] == mu.get_activation_time_constant()
        assert s["deactivation_time_constant"] == mu.get_deactivation_time_constant()
    assert data["muscles"]["biceps_long"]["path"] == ["ground.biceps_long_origin", "upper.biceps_long_mid",
                                                     "fore.biceps_long_ins"]


def test_defaults_are_opensims(workdir):
    """A Thelen2003Muscle that gives only its path reads OpenSim's defaults."""
    from openfdk.io.opensim.document import THELEN_DEFAULTS

    mu = opensim.Thelen2003Muscle()
    for key, value in THELEN_DEFAULTS.items():
        assert getattr(mu, f"get_{key}")() == pytest.approx(value, rel=1e-15), key


def _edit(src, dst, edit):
    tree = etree.parse(str(src))
    element = edit(tree)
    tree.write(str(dst))
    return etree.parse(str(dst)).xpath(f"//{element.tag}[@name='{element.get('name')}']")[0].sourceline


def _conditional(tree):
    p = tree.xpath("//Thelen2003Muscle[@name='biceps.long']//PathPoint[@name='mid']")[0]
    p.tag = "ConditionalPathPoint"
    p.append(etree.fromstring("<socket_coordinate>/jointset/elbow/q_elbow</socket_coordinate>"))
    p.append(etree.fromstring("<range>-1 0.5</range>"))
    return p


def _moving(tree):
    p = tree.xpath("//Thelen2003Muscle[@name='triceps']//PathPoint[@name='via2']")[0]
    p.tag = "MovingPathPoint"
    return p


def _wrap(tree):
    """delt wraps over a WrapDoubleCylinderObst (openfdk reads cylinders, spheres,
    ellipsoids and tori: tests/test_opensim_wrapping.py)."""
    body = tree.xpath("//Body[@name='upper']")[0]
    torus = etree.SubElement(etree.SubElement(etree.SubElement(body, "WrapObjectSet"), "objects"), "WrapDoubleCylinderObst",
                             name="humerus_head")
    path = tree.xpath("//Thelen2003Muscle[@name='delt']/GeometryPath")[0]
    wraps = etree.SubElement(path, "PathWrapSet")
    w = etree.SubElement(etree.SubElement(wraps, "objects"), "PathWrap", name="delt_wrap")
    etree.SubElement(w, "wrap_object").text = "humerus_head"
    return torus


def _other_muscle(tree):
    m = tree.xpath("//Thelen2003Muscle[@name='delt']")[0]
    m.tag = "DeGrooteFregly2016Muscle"  # (Millard, rigid-tendon, Schutte: test_opensim_millard, _curve_muscles)
    return m


def _moving_functions(tree):
    """triceps' via2 a MovingPathPoint on q_elbow: x a SimmSpline, y a LinearFunction,
    z a MultiplierFunction of a Constant (metres in the forearm's frame)."""
    p = _moving(tree)
    for a in "xyz":
        p.append(etree.fromstring(f"<socket_{a}_coordinate>/jointset/elbow/q_elbow</socket_{a}_coordinate>"))
    p.append(etree.fromstring("<x_location><SimmSpline><x>-2 -1 0 0.7 2</x><y>-0.05 -0.041 -0.03 -0.026 -0.02</y>"
                              "</SimmSpline></x_location>"))
    p.append(etree.fromstring("<y_location><LinearFunction><coefficients>0.01 0.04</coefficients></LinearFunction>"
                              "</y_location>"))
    p.append(etree.fromstring("<z_location><MultiplierFunction><function><Constant><value>-0.01</value></Constant>"
                              "</function><scale>1.5</scale></MultiplierFunction></z_location>"))
    return p


def test_conditional_and_moving_points_equal_opensim(arm, workdir):
    """biceps' mid point active only for q_elbow in [−1, 0.5] (a ConditionalPathPoint),
    triceps' via2 moving with q_elbow: at 60 random poses (both sides of the range) the
    lengths equal OpenSim's to 1e-9 m, the moment arms from the analytic Jacobian
    (including f′(q) ∂q/∂q̂ of the moving point) to 1e-9 m; at the range's ends and
    2e-5 rad beyond them (OpenSim's tolerance is 1e-5) the switch is OpenSim's.

    The triceps' moment arm is compared with −∂l/∂q of OpenSim's own length (central
    difference, ≤ 1e-7 m): OpenSim 4.6's ``computeMomentArm`` (the generalised force of a
    unit tension) leaves out the moving point's f′(q) term and differs from the
    derivative of its own length by up to 9 mm here (at q_elbow = 0.3: −0.0215 against
    −0.0297 m)."""
    path = workdir / "arm_moving.osim"
    tree = etree.parse(str(arm))
    _conditional(tree)
    _moving_functions(tree)
    tree.write(str(path))
    dl, dr, dr_fd = _compare_paths(path, their_length_derivative=("triceps",))
    print(f"conditional + moving: |Δl| ≤ {dl:.2e} m, |Δr| ≤ {dr:.2e} m, {dr_fd:.2e} m (central difference)")
    assert dl <= 1e-9 and dr <= 1e-7 and dr_fd <= 1e-6
    data, _ = read_osim(path)
    ours = model_from_dict(data, source=str(path))
    biceps = next(m for m in ours.muscles if m.name == "biceps_long")
    theirs = opensim.Model(str(path))
    state = theirs.initSystem()
    mu = theirs.getMuscles().get("biceps.long")
    elbow = theirs.getCoordinateSet().get("q_elbow")
    lengths = []
    for q in (-1.0, -1.0 - 2e-5, 0.5, 0.5 + 2e-5, -1.0 + 2e-5, 0.5 - 2e-5):
        elbow.setValue(state, q, False)
        theirs.realizePosition(state)
        st, _ = pose_from_coordinates(ours, {"q_shoulder": 0.0, "q_elbow": q})
        mine = float(np.ravel(biceps.path.evaluate(st, 0)[0])[0])
        assert abs(mine - mu.getLength(state)) < 1e-9, q
        lengths.append(mine)
    # the point drops out just beyond the ends: a jump of the length there
    assert abs(lengths[0] - lengths[1]) > 1e-3 and abs(lengths[2] - lengths[3]) > 1e-4


def _conditional_without_coordinate(tree):
    p = _conditional(tree)
    p.remove(p.find("socket_coordinate"))
    return p


def _moving_on_two_coordinates(tree):
    p = _moving(tree)
    p.append(etree.fromstring("<socket_x_coordinate>/jointset/elbow/q_elbow</socket_x_coordinate>"))
    p.append(etree.fromstring("<socket_y_coordinate>/jointset/shoulder/q_shoulder</socket_y_coordinate>"))
    return p


@pytest.mark.parametrize("edit,kind,name,muscle", [
    (_conditional_without_coordinate, "ConditionalPathPoint", "biceps.long/mid", "biceps_long"),
    (_moving_on_two_coordinates, "MovingPathPoint", "triceps/via2", "triceps"),
    (_wrap, "WrapDoubleCylinderObst", "humerus_head", "delt"),
    (_other_muscle, "DeGrooteFregly2016Muscle", "delt", "delt"),
])
def test_unsupported_path_elements_refuse_the_muscle(arm, workdir, edit, kind, name, muscle):
    """A PathWrap over a WrapTorus, or another muscle class, is refused in one line
    naming the element and its line; ``--ignore TYPE`` leaves the whole muscle out
    (never imported without the point or the wrap), listed as dropped — also for the
    conditional and moving points openfdk reads (a broken one here: no coordinate);
    ``--ignore forces`` drops the ForceSet (and the wrap objects)."""
    path = workdir / f"bad_{kind}.osim"
    line = _edit(arm, path, edit)
    with pytest.raises(OsimError) as exc:
        read_osim(path)
    msg = str(exc.value)
    assert "\n" not in msg and f"line {line}:" in msg and f"{kind} {name!r}" in msg, msg
    assert f"--ignore {kind}" in msg and path.name in msg, msg
    data, info = read_osim(path, ignore=(kind,))
    assert muscle not in data["muscles"] and len(data["muscles"]) == 2
    dropped = {(d["type"], d["name"]) for d in info["dropped"]}
    assert (kind, name) in dropped
    if kind != "DeGrooteFregly2016Muscle":
        assert ("Thelen2003Muscle", muscle.replace("_", ".") if muscle == "biceps_long" else muscle) in dropped
    data, info = read_osim(path, ignore=("forces",))
    assert "muscles" not in data and len([d for d in info["dropped"] if d["type"] != "WrapDoubleCylinderObst"]) == 3


def test_ignore_thelen_drops_every_muscle(arm):
    data, info = read_osim(arm, ignore=("Thelen2003Muscle",))
    assert "muscles" not in data and [d["type"] for d in info["dropped"]] == ["Thelen2003Muscle"] * 3


def test_af_outside_hill_curvature_range_is_refused(arm, workdir):
    """Af outside [0.1, 0.5] (fast_fibre_fraction outside [0, 1]) is refused by name."""
    def edit(tree):
        m = tree.xpath("//Thelen2003Muscle[@name='delt']")[0]
        m.find("Af").text = "0.6"
        return m

    path = workdir / "af.osim"
    line = _edit(arm, path, edit)
    with pytest.raises(OsimError) as exc:
        read_osim(path)
    msg = str(exc.value)
    assert f"line {line}:" in msg and "Thelen2003Muscle 'delt'" in msg and "Af 0.6" in msg, msg


def test_import_opensim_file_keeps_the_muscles(arm, workdir):
    """``openfdk import-opensim`` writes the muscles (Hill parameters, paths, path-point
    frames); the written file loads to the same path lengths as the .osim."""
    from openfdk.cli import main
    from openfdk.io.modelfile import load_model_and_settings

    out = workdir / "imported"
    assert main(["import-opensim", str(arm), "--out", str(out)]) == 0
    written, _ = load_model_and_settings(out / "arm.yaml")
    data, _ = read_osim(arm)
    direct = model_from_dict(data, source=str(arm))
    q = {"q_shoulder": 0.4, "q_elbow": -0.7}
    st_w, _ = pose_from_coordinates(written, q)
    st_d, _ = pose_from_coordinates(direct, q)
    for a, b in zip(written.muscles, direct.muscles):
        assert a.name == b.name and a.law == b.law and a.points == b.points
        assert float(np.ravel(a.path.evaluate(st_w, 0)[0])[0]) == float(np.ravel(b.path.evaluate(st_d, 0)[0])[0])


def test_maximal_tendon_force_equals_opensims_equilibrium(arm):
    """At full activation and zero speed, openfdk's maximal tendon force s + f_P (the
    tendon–fibre equilibrium of docs/muscles.md) equals the tendon force of OpenSim's
    Thelen2003Muscle after ``equilibrateMuscles``, ≤ 1e-6 relative, at 12 random poses
    (every mapped parameter enters: F0, Lf0, Lt0, α0, ε0_T, ε0_M, γ, k_PE). The passive
    state differs by design: OpenSim's activation never goes below
    ``minimum_activation`` (0.01), openfdk's passive force is at a = 0."""
    data, _ = read_osim(arm)
    ours = model_from_dict(data, source=str(arm))
    theirs = opensim.Model(str(arm))
    state = theirs.initSystem()
    coords = [theirs.getCoordinateSet().get(k) for k in range(theirs.getCoordinateSet().getSize())]
    muscles = [opensim.Thelen2003Muscle.safeDownCast(theirs.getMuscles().get(k))
               for k in range(theirs.getMuscles().getSize())]
    by_name = {m.name: m for m in ours.muscles}
    rng = np.random.default_rng(2)
    worst = 0.0
    for _ in range(12):
        q = {c.getName(): float(rng.uniform(-1.2, 1.2)) for c in coords}
        for c in coords:
            c.setValue(state, q[c.getName()], False)
        for mu in muscles:
            mu.setActivation(state, 1.0)
        theirs.equilibrateMuscles(state)
        theirs.realizeDynamics(state)
        st, _ = pose_from_coordinates(ours, q)
        for mu in muscles:
            m = by_name[mu.getName().replace(".", "_")]
            length = float(np.ravel(m.path.evaluate(st, 0)[0])[0])
            s, f_p = m.law.evaluate(length, 0.0)
            worst = max(worst, abs(s + f_p - mu.getTendonForce(state)) / mu.getTendonForce(state))
    print(f"maximal tendon force: relative difference ≤ {worst:.1e}")
    assert worst <= 1e-6


@pytest.mark.parametrize("edit,words", [
    (lambda m: m.find("tendon_slack_length").__setattr__("text", "-1"), "tendon_slack_length"),
    (lambda m: m.find("Flen").__setattr__("text", "0.9"), "the file's Flen"),
    (lambda m: etree.SubElement(m, "Flen").__setattr__("text", "1.5"), "<Flen> given twice"),
    (lambda m: etree.SubElement(m, "damping").__setattr__("text", "0.1"), "<damping> is not read"),
    (lambda m: m.remove(m.find("GeometryPath")), "no <GeometryPath>"),
    (lambda m: m.find(".//PathPoint/location").__setattr__("text", "nan 0 0"), "non-finite"),
    (lambda m: m.find(".//PathPoint/socket_parent_frame").__setattr__("text", "/bodyset/nope"), "'nope'"),
])
def test_bad_muscle_values_are_one_line_errors(arm, workdir, edit, words):
    """An invalid parameter, a property given twice or unknown, a missing path, a bad
    point: one line naming the file, the line and what is wrong."""
    def apply(tree):
        m = tree.xpath("//Thelen2003Muscle[@name='delt']")[0]
        edit(m)
        return m

    path = workdir / "bad_value.osim"
    _edit(arm, path, apply)
    with pytest.raises(OsimError) as exc:
        read_osim(path)
    msg = str(exc.value)
    assert "\n" not in msg and path.name in msg and "line " in msg and words in msg, msg
