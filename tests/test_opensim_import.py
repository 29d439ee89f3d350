"""The OpenSim model reader (:mod:`openfdk.io.opensim`) against OpenSim 4.6 itself.

Every model is built with OpenSim's Python API (tests/opensim_models.py), written by
OpenSim (``printToXML``) and then read twice from the same file: by openfdk
(``load_model_and_settings``) and by OpenSim (``opensim.Model(path)``, the oracle — the
file holds the numbers both read, so rounding in the file is no difference). At random
coordinate values inside the ranges openfdk solves its joint rows
(:func:`~openfdk.kinematics.coordinate_pose.pose_from_coordinates`) and OpenSim sets its
coordinates (or assembles, for constraints); compared are

* each body's frame in ground (openfdk's body origin is the centre of mass, so the
  OpenSim body origin is p_WB − R_WB·mass_center): 1e-9 m, 1e-9 (rotation matrix);
* marker positions 1e-9 m; for random coordinate speeds, body angular velocities
  1e-9 rad/s and marker and body-origin velocities 1e-9 m/s;
* the coordinate values read back from openfdk's coordinate measures (Python and
  compiled), which must equal the sampled ones (1e-9).

The largest error of each kind is printed (``pytest -s``). Also: Jacobians and biases of
the function rows (FunctionOf) against finite differences, an OpenSim 3.x file against
OpenSim and against OpenSim's own 4.x conversion of it, the round trip through
``export-opensim``, merged welded bodies against OpenSim's mass properties, and one-line
errors for malformed files.
"""

from pathlib import Path

import numpy as np
import pytest

opensim = pytest.importorskip("opensim")

import opensim_models as om  # noqa: E402  (needs opensim)
from lxml import etree  # noqa: E402

from openfdk.io.modelfile import load_model_and_settings  # noqa: E402
from openfdk.io.opensim import OsimError, read_osim  # noqa: E402
from openfdk.io.opensim.document import read_document  # noqa: E402
from openfdk.io.opensim.to_model import safe_name  # noqa: E402
from openfdk.io.opensim.tree import Tree  # noqa: E402
from openfdk.kinematics.coordinate_pose import driven_model, pose_from_coordinates  # noqa: E402
from openfdk.kinematics.determinate import solve_positions  # noqa: E402
from openfdk.kinematics.system import ConstraintSystem, KinematicsError  # noqa: E402
from openfdk.model.compiled import CompiledMeasures  # noqa: E402
from openfdk.model.function_measure import FunctionOf  # noqa: E402
from openfdk.model.timefunctions import Polynomial  # noqa: E402
from openfdk.numerics.numdiff import manifold_jacobian, second_derivative_along  # noqa: E402

TOL = 1e-9          # m, rad, m/s, rad/s: every comparison with OpenSim
SAME = 1e-12        # two openfdk reads of the same model (3.x file and its 4.x conversion)


# ----------------------------------------------------------------------------- fixtures


@pytest.fixture(scope="module")
def workdir(tmp_path_factory):
    """A folder for the model files, the cwd of the module's tests (OpenSim writes
    opensim.log into the cwd)."""
    d = tmp_path_factory.mktemp("osim")
    with pytest.MonkeyPatch.context() as mp:
        mp.chdir(d)
        yield d


@pytest.fixture(scope="module")
def files(workdir):
    """The models of tests/opensim_models.py, written by OpenSim."""
    return {
        "joints": om.joints_model(workdir / "joints.osim"),
        "custom": om.custom_model(workdir / "custom.osim"),
        "constraints": om.constraints_model(workdir / "constraints.osim"),
        "weld_chain": om.weld_chain_model(workdir / "weld_chain.osim"),
    }


@pytest.fixture(autouse=True)
def _in_workdir(workdir, monkeypatch):
    monkeypatch.chdir(workdir)


# ----------------------------------------------------------------------------- helpers


class Errors(dict):
    """The largest error of each kind."""

    def add(self, kind, a, b):
        self[kind] = max(self.get(kind, 0.0), float(np.max(np.abs(np.asarray(a) - np.asarray(b)))))

    def check(self, label, tol=TOL):
        print(f"\n{label}: " + ", ".join(f"{k} {v:.1e}" for k, v in sorted(self.items())))
        bad = {k: v for k, v in self.items() if not v <= tol}
        assert not bad, f"{label}: errors above {tol:g}: {bad}"


class Ours:
    """openfdk's model of an .osim with the reader's records (to map OpenSim bodies,
    merged ones included, to openfdk bodies)."""

    def __init__(self, path):
        self.model, _ = load_model_and_settings(path)
        self.doc = read_document(path)
        self.tree = Tree(self.doc)
        self.index = {b.name: b.index for b in self.model.bodies}
        self.program = CompiledMeasures([c.measure for c in self.model.coordinates])

    def body_pose(self, state, body):
        """OpenSim body ``body``'s frame (p, R) in ground from openfdk's state."""
        root = self.tree.root[body]
        if root == self.tree.ground:
            p, R = np.zeros(3), np.eye(3)
        else:
            i = self.index[safe_name(root)]
            _, com, _ = self.tree.mass_properties(root)
            R = state.R_WB[i]
            p = state.p_WB[i] - R @ com
        p_rB, R_rB = self.tree.X_root[body]
        return p + R @ p_rB, R @ R_rB

    def body_velocity(self, state, body):
        """(ω in ground, velocity of the OpenSim body origin in ground)."""
        i = self.index[safe_name(self.tree.root[body])]
        w = state.R_WB[i] @ state.w_BB[i]
        p, _ = self.body_pose(state, body)
        return w, state.v_WB[i] + np.cross(w, p - state.p_WB[i])

    def markers(self, state):
        """{OpenSim marker name: (position, velocity) in ground}."""
        mk = self.model.markers
        out = {}
        for j in range(mk.size):
            i = int(mk.body[j])
            r = state.R_WB[i] @ mk.p_BM[j]
            out[mk.labels[j]] = (state.p_WB[i] + r, state.v_WB[i] + np.cross(state.R_WB[i] @ state.w_BB[i], r))
        return out

    def coordinates(self, state):
        """{name: value} from the coordinates' measures: (Python, compiled)."""
        compiled = self.program.evaluate(state, 0)[0]
        return ({c.name: float(c.measure.evaluate(state, 0)[0][0]) for c in self.model.coordinates},
                {c.name: float(v) for c, v in zip(self.model.coordinates, compiled)})


FALLBACKS = []


def pose_at(model, q, qdot=None, t=0.0):
    """pose_from_coordinates at ``q``; when Newton's method from the reference pose does
    not converge (it is plain Newton, undamped: a few in 100 far samples of the
    joint-type model diverge, some into NaN, which the compiled kernel reports as
    numpy's LinAlgError), the same in steps from the defaults (continuation), counted in
    FALLBACKS."""
    try:
        return pose_from_coordinates(model, q, qdot, t=t)
    except (KinematicsError, np.linalg.LinAlgError):
        FALLBACKS.append(dict(q))
    q0 = {c.name: c.default for c in model.coordinates}
    state = None
    for k in np.linspace(0.0, 1.0, 9)[1:]:
        state, vdot = pose_from_coordinates(model, {n: q0[n] + k * (v - q0[n]) for n, v in q.items()}, qdot,
                                            t=t, state=state)
    return state, vdot


def solve_driven(model, q, state=None):
    """openfdk's pose with only the coordinates in ``q`` driven (the constraints place the
    rest): pose_from_coordinates needs every free coordinate, and with a coupler the
    dependent one must not be driven."""
    driven = driven_model(model, list(q))
    for con in driven.constraints[len(model.constraints):]:
        object.__setattr__(con, "function", Polynomial([q[con.name[: -len(".value")]]]))
    state = model.initial_state() if state is None else state
    result = solve_positions(ConstraintSystem(driven), state, 0.0, tol=1e-12, max_iter=100)
    assert result.converged, result.message
    return state


def compare_positions(errs, orc, ours, st, q=None):
    """Bodies, markers and (sampled) coordinates of openfdk's state vs OpenSim's."""
    for b in orc.bodies:
        p, R = ours.body_pose(st, b)
        po, Ro = orc.body_pose(b)
        errs.add("body position", p, po)
        errs.add("body rotation", R, Ro)
    for name, (x, _) in ours.markers(st).items():
        errs.add("marker position", x, orc.marker_position(name))
    py, compiled = ours.coordinates(st)
    for name, v in (q or {}).items():
        errs.add("coordinate (measure)", py[name], v)
        errs.add("coordinate (compiled)", compiled[name], v)


def opensim_fd_velocity(orc, q, qdot, h=1e-4):
    """Body (ω, origin velocity) and marker velocities as the time derivative of
    OpenSim's positions along q + t q̇ (fourth-order central differences)."""
    def at(t):
        orc.set({n: q[n] + t * qdot[n] for n in q})
        return ({b: orc.body_pose(b) for b in orc.bodies}, {m: orc.marker_position(m) for m in orc.markers})

    (b2, m2), (b1, m1), (b0, _), (bm1, mm1), (bm2, mm2) = at(2 * h), at(h), at(0.0), at(-h), at(-2 * h)

    def d(f2, f1, fm1, fm2):
        return (8 * (f1 - fm1) - (f2 - fm2)) / (12 * h)

    bodies = {}
    for b in orc.bodies:
        Rdot = d(b2[b][1], b1[b][1], bm1[b][1], bm2[b][1])
        W = Rdot @ b0[b][1].T
        bodies[b] = (np.array([W[2, 1], W[0, 2], W[1, 0]]), d(b2[b][0], b1[b][0], bm1[b][0], bm2[b][0]))
    markers = {m: d(m2[m], m1[m], mm1[m], mm2[m]) for m in orc.markers}
    orc.set(q)
    return bodies, markers


def check_free_model(path, n, seed, label, fd_velocity_bodies=()):
    """Poses, markers, coordinates and velocities at n random samples of a model without
    constraints; the velocities of ``fd_velocity_bodies`` (and their markers) against the
    derivative of OpenSim's positions (see test_custom_joints_match_opensim)."""
    ours = Ours(path)
    orc = om.Oracle(path)
    rng = np.random.default_rng(seed)
    errs = Errors()
    free = [c.name for c in ours.model.coordinates if not (c.locked or c.prescribed)]
    prescribed = [c.name for c in ours.model.coordinates if c.prescribed]
    before = len(FALLBACKS)
    body_of_marker = {m: orc.markers[m].getParentFrame().findBaseFrame().getName() for m in orc.markers}
    for _ in range(n):
        q = orc.sample(rng, free)
        u = {c: float(rng.normal()) * 0.5 * np.ptp(orc.ranges()[c]) for c in q}  # speeds on the ranges' scale
        t = float(rng.uniform(0.0, 1.5))
        qdot = orc.set(q, u, t)  # OpenSim's q̇ of speeds u (Ball and Free joints: u is not q̇)
        st, _ = pose_at(ours.model, q, {name: qdot[name] for name in q}, t)
        compare_positions(errs, orc, ours, st,
                          {**q, **{name: orc.coords[name].getValue(orc.state) for name in prescribed}})
        fd_bodies, fd_markers = (opensim_fd_velocity(orc, q, qdot) if fd_velocity_bodies else ({}, {}))
        orc.set(q, u)
        for b in orc.bodies:
            if ours.tree.root[b] == ours.tree.ground:
                continue
            w, v = ours.body_velocity(st, b)
            wo, vo = fd_bodies[b] if b in fd_velocity_bodies else orc.body_velocity(b)
            errs.add("body angular velocity", w, wo)
            errs.add("body origin velocity", v, vo)
        for name, (_, v) in ours.markers(st).items():
            vo = fd_markers[name] if body_of_marker[name] in fd_velocity_bodies else orc.marker_velocity(name)
            errs.add("marker velocity", v, vo)
    errs.check(f"{label} ({n} samples; Newton from the reference pose failed at {len(FALLBACKS) - before})")
    return ours, orc


def check_motion_types(ours, orc):
    """openfdk's motion type of each coordinate is OpenSim's where OpenSim says
    rotational or translational; where OpenSim says coupled (no axis is a LinearFunction
    of slope 1 of it), openfdk names the kind of axis that measures it; the unit follows."""
    kinds = {int(opensim.Coordinate.Rotational): "rotational", int(opensim.Coordinate.Translational): "translational",
             int(opensim.Coordinate.Coupled): "coupled"}
    for c in ours.model.coordinates:
        theirs = kinds[int(orc.coords[c.name].getMotionType())]
        assert theirs == "coupled" or c.motion == theirs, (c.name, c.motion, theirs)
        assert c.unit == {"rotational": "angle", "translational": "length"}[c.motion], c.name
        # OpenSim's own motion type, coupled included: it decides the .mot columns' unit
        assert (c.opensim_motion or c.motion) == theirs, (c.name, c.opensim_motion, theirs)
        assert c.opensim_rotational == (theirs == "rotational"), c.name


# ----------------------------------------------------------------------------- 1. joints


@pytest.mark.slow
def test_every_joint_type_matches_opensim(files):
    """Pin, Slider, Universal, Ball, Gimbal, Free, Planar and Weld joints (offset frames on
    both sides, a body welded to a moving body and one welded to the ground): poses,
    markers, velocities and coordinates at 60 random samples."""
    ours, orc = check_free_model(files["joints"], 60, 11, "joint types")
    check_motion_types(ours, orc)
    # the welded bodies are merged: into their parent, and into the ground
    assert ours.tree.root["welded"] == "planar" and ours.tree.root["on_ground"] == "ground"
    assert {b.name for b in ours.model.bodies} == {"ground"} | set(orc.bodies) - {"welded", "on_ground"}
    # every OpenSim coordinate is an openfdk coordinate, with its range and default
    assert [c.name for c in ours.model.coordinates] == list(orc.coords)
    for c in ours.model.coordinates:
        oc = orc.coords[c.name]
        assert c.range == (oc.getRangeMin(), oc.getRangeMax()) and c.default == oc.getDefaultValue()


@pytest.mark.slow
def test_custom_joints_match_opensim(files):
    """CustomJoints with every OpenSim function (Constant, LinearFunction with slope and
    intercept, SimmSpline, NaturalCubicSpline, GCVSpline, PiecewiseLinearFunction,
    MultiplierFunction, PolynomialFunction), non-unit axes (0 0 2, 0 2 0, 0 1.5 0.5),
    non-orthogonal constant axes, translational coordinates (one of them also turning a
    rotation axis through a spline) and markers on joint frames: 60 samples; the
    coordinates' motion types and units as OpenSim reports them.

    The foot's and toe's velocities are compared with the derivative of OpenSim's
    positions, not with OpenSim's velocities: the ankle starts with a constant rotation,
    and Simbody's MobilizedBody::FunctionBased builds its velocity Jacobian H with the
    constant rotation's angle left at 0 (``CacheInfo::buildH`` evaluates only the
    functions of axes with coordinates), so OpenSim's own velocities there are not the
    derivative of its positions (by tenths of a rad/s at speeds of 1 rad/s) while its
    positions are right."""
    ours, orc = check_free_model(files["custom"], 60, 12, "custom joints", fd_velocity_bodies=("foot", "toe"))
    check_motion_types(ours, orc)
    units = {c.name: c.unit for c in ours.model.coordinates}
    assert units["ankle_slide"] == units["mtp_slide"] == "length" and units["knee_angle"] == "angle"


@pytest.mark.slow
@pytest.mark.parametrize("constant_first", [False, True])
def test_non_orthogonal_rotation_axes_match_opensim(workdir, constant_first):
    """CustomJoints whose moving rotation axes are not orthogonal (two, completed by their
    cross product, with a constant rotation after or before them; three, one of slope
    −1), as opensim-models' WristModel writes its joints (refused until stop 65, "not
    orthogonal"): poses, markers, coordinates and velocities equal OpenSim's at 40
    random samples."""
    # (with the constant rotation first, velocities against the derivative of OpenSim's
    # positions: Simbody leaves that angle at 0 in its velocity Jacobian, see
    # test_custom_joints_match_opensim; OpenSim's own velocities then differ by 0.5 rad/s)
    path = om.oblique_model(workdir / f"oblique_{int(constant_first)}.osim", constant_first=constant_first)
    ours, orc = check_free_model(path, 40, 31, "oblique axes",
                                 fd_velocity_bodies=("metacarpal", "phalanx") if constant_first else ())
    check_motion_types(ours, orc)
    from openfdk.model.compiled import OP_AXIS_ANGLES

    # both joints' coordinates are angles about their own axes (not a Cardan sequence)
    assert np.count_nonzero(ours.program.program[0] == OP_AXIS_ANGLES) == 2


@pytest.mark.slow
def test_an_export_of_oblique_axes_places_the_markers_as_the_original(workdir, capsys):
    """``openfdk export-opensim`` of a run of the oblique-axes model writes joints that
    OpenSim turns as the original file does: markers at 10 random coordinate values equal
    the original model's in OpenSim to 1e-12 m."""
    from openfdk.cli import main

    src = om.oblique_model(workdir / "oblique_export.osim")
    t = np.arange(12) / 100.0
    names = ["cmc_flex", "cmc_abd", "mcp_flex", "mcp_abd", "mcp_rot", "mcp_slide"]
    om.write_motion(workdir / "oblique.mot", t, {n: 0.1 * np.sin(3 * t + k) * (0.01 if n == "mcp_slide" else 1)
                                                 for k, n in enumerate(names)})
    assert main(["kinematics", str(src), "--motion", str(workdir / "oblique.mot"), "--out",
                 str(workdir / "oblique_run"), "--force", "-q"]) == 0, capsys.readouterr().err
    assert main(["export-opensim", str(workdir / "oblique_run"), "--model", str(src), "--out",
                 str(workdir / "oblique_exp"), "-q"]) == 0, capsys.readouterr().err
    (exported,) = (workdir / "oblique_exp").glob("*.osim")
    models = [opensim.Model(str(f)) for f in (exported, src)]
    states = [m.initSystem() for m in models]
    rng = np.random.default_rng(4)
    seen = []
    for _ in range(10):
        q = {n: float(rng.uniform(-0.6, 0.6)) * (0.01 if n == "mcp_slide" else 1) for n in names}
        for m, s in zip(models, states):
            for n, v in q.items():
                m.getCoordinateSet().get(n).setValue(s, v, False)
            m.realizePosition(s)
        for k in range(models[1].getMarkerSet().getSize()):
            name = models[1].getMarkerSet().get(k).getName()
            a, b = (m.getMarkerSet().get(name).getLocationInGround(s).to_numpy() for m, s in zip(models, states))
            np.testing.assert_allclose(a, b, atol=1e-12, err_msg=name)
            seen.append(b)
    n_markers = models[1].getMarkerSet().getSize()
    spread = np.ptp(np.array(seen).reshape(10, n_markers, 3), axis=0)
    assert spread.max() > 0.01  # the markers move between the samples: the joints turn


@pytest.mark.slow
def test_a_coordinate_moving_its_axis_through_a_two_point_spline_matches_opensim(files, workdir):
    """The knee's rotation1 written as a SimmSpline through (−2π, 2π) and (2π, −2π), y =
    −x, as the left knee of jam-resources' full_body_healthy_knee.osim writes it: the
    spline is one line, so knee_angle is measured from that axis (it was refused: "moves
    no axis through a linear function"). Poses, markers and coordinates match OpenSim at
    30 samples."""
    tree = etree.parse(str(files["custom"]))
    (axis,) = tree.xpath("//CustomJoint[@name='knee']/SpatialTransform/TransformAxis[@name='rotation1']")
    (linear,) = axis.xpath("LinearFunction")
    spline = etree.SubElement(axis, "SimmSpline", name="function")
    etree.SubElement(spline, "x").text = "-6.28319 6.28319"
    etree.SubElement(spline, "y").text = "6.28319 -6.28319"
    axis.remove(linear)
    path = workdir / "two_point_spline.osim"
    tree.write(str(path), xml_declaration=True, encoding="UTF-8")
    ours, orc = check_free_model(path, 30, 21, "two-point spline", fd_velocity_bodies=("foot", "toe"))
    check_motion_types(ours, orc)  # knee_angle: coupled for OpenSim (a spline, not a LinearFunction)
    assert orc.coords["knee_angle"].getMotionType() == opensim.Coordinate.Coupled


@pytest.mark.slow
def test_coordinates_mot_gives_coupled_coordinates_in_the_units_opensim_reads(files, workdir):
    """coordinates.mot says inDegrees=yes, and OpenSim converts only its rotational
    coordinates' columns (SimbodyEngine::convertDegreesToRadians). A coupled coordinate —
    knee_angle through the two-point spline, hip_adduction through a LinearFunction of
    slope −2 — is written in rad: OpenSim's conversion of the file gives back every
    coordinate's value. (jam-resources' full_body_healthy_knee.osim: its left knee, ankle
    and subtalar coordinates were written in degrees and read by OpenSim as rad, 57×.)"""
    from types import SimpleNamespace

    from openfdk.io.coordinate_outputs import write_coordinates

    tree = etree.parse(str(files["custom"]))
    (axis,) = tree.xpath("//CustomJoint[@name='knee']/SpatialTransform/TransformAxis[@name='rotation1']")
    axis.remove(axis.find("LinearFunction"))
    spline = etree.SubElement(axis, "SimmSpline", name="function")
    etree.SubElement(spline, "x").text = "-6.28319 6.28319"
    etree.SubElement(spline, "y").text = "6.28319 -6.28319"
    path = workdir / "two_point_mot.osim"
    tree.write(str(path), xml_declaration=True, encoding="UTF-8")
    ours, orc = Ours(path), om.Oracle(path)
    rng = np.random.default_rng(31)
    free = [c.name for c in ours.model.coordinates if not (c.locked or c.prescribed)]
    samples = [orc.sample(rng, free) for _ in range(4)]
    q = np.array([pose_at(ours.model, s)[0].get_q() for s in samples])
    kin = SimpleNamespace(time=np.arange(4) * 0.01, q=q, converged=np.ones(4, bool))
    out = workdir / "mot_out"
    out.mkdir(exist_ok=True)
    write_coordinates(out, ours.model, kin)
    storage = opensim.Storage(str(out / "coordinates.mot"))
    assert storage.isInDegrees()
    orc.model.getSimbodyEngine().convertDegreesToRadians(storage)
    coupled = {n for n in free if orc.coords[n].getMotionType() == opensim.Coordinate.Coupled}
    assert {"knee_angle", "hip_adduction"} <= coupled
    labels = storage.getColumnLabels()
    assert {labels.get(i) for i in range(labels.getSize())} == {"time", *free}
    for name in free:
        column = opensim.ArrayDouble()
        storage.getDataColumn(name, column)
        got = np.array([column.get(i) for i in range(column.getSize())])
        np.testing.assert_allclose(got, [s[name] for s in samples], rtol=0, atol=1e-6, err_msg=name)


# ----------------------------------------------------------------------------- 7. merged bodies


@pytest.mark.slow
def test_weld_chain_is_merged_with_opensims_mass_properties(files):
    """A WeldJoint chain (a -Weld- b -Weld- c) is one openfdk body: its mass, centre of
    mass and inertia equal OpenSim's bodies a, b and c together, and the whole model's
    mass, centre of mass and central inertia equal OpenSim's (Simbody's system mass
    properties) at 10 random samples. Poses, velocities and coordinates match at 30
    samples — with a prescribed coordinate (a SimmSpline of time, at random times), a
    body-owned offset frame (``socket_parent`` ``..``), a model-level offset frame on it
    carrying a marker, and a joint on that frame."""
    path = files["weld_chain"]
    ours, orc = check_free_model(path, 30, 13, "weld chain")
    model = ours.model
    assert [b.name for b in model.bodies] == ["ground", "a", "d", "e", "g"]
    assert [c.name for c in model.coordinates if c.prescribed] == ["jd_coord_0"]
    assert "f2.M" in model.markers.labels
    _, info = read_osim(path)
    assert info["merged_bodies"] == {"b": "a", "c": "a"}
    rng = np.random.default_rng(14)
    errs = Errors()
    s = orc.state
    matter = orc.model.getMatterSubsystem()
    parts = [orc.bodies[n] for n in ("a", "b", "c")]
    a = model.bodies[ours.index["a"]]
    assert a.mass == pytest.approx(sum(b.getMass() for b in parts), rel=1e-15)
    assert sum(b.mass for b in model.bodies[1:]) == pytest.approx(orc.model.getTotalMass(s), rel=1e-15)
    free = [c.name for c in model.coordinates if not c.prescribed]
    for _ in range(10):
        q = orc.sample(rng, free)
        t = float(rng.uniform(0.0, 1.5))
        orc.set(q, t=t)
        st, _ = pose_from_coordinates(model, q, t=t)
        # the merged body from OpenSim's bodies a, b, c
        m = sum(b.getMass() for b in parts)
        c = sum(b.getMass() * om.np3(b.findStationLocationInGround(s, b.getMassCenter())) for b in parts) / m
        inertia = np.zeros((3, 3))
        for b in parts:
            R = om.np33(b.getTransformInGround(s).R())
            I = b.getInertia()
            mom, prod = om.np3(I.getMoments()), om.np3(I.getProducts())
            I_B = np.diag(mom) + np.array([[0, prod[0], prod[1]], [prod[0], 0, prod[2]], [prod[1], prod[2], 0]])
            d = om.np3(b.findStationLocationInGround(s, b.getMassCenter())) - c
            inertia += R @ I_B @ R.T + b.getMass() * ((d @ d) * np.eye(3) - np.outer(d, d))
        i = ours.index["a"]
        errs.add("merged centre of mass", st.p_WB[i], c)
        errs.add("merged inertia", st.R_WB[i] @ a.inertia_B @ st.R_WB[i].T, inertia)
        # the whole model (Simbody's own computation)
        M = sum(b.mass for b in model.bodies[1:])
        com = sum(b.mass * st.p_WB[b.index] for b in model.bodies[1:]) / M
        Ic = np.zeros((3, 3))
        for b in model.bodies[1:]:
            R = st.R_WB[b.index]
            d = st.p_WB[b.index] - com
            Ic += R @ b.inertia_B @ R.T + b.mass * ((d @ d) * np.eye(3) - np.outer(d, d))
        errs.add("system centre of mass", com, om.np3(matter.calcSystemMassCenterLocationInGround(s)))
        Io = matter.calcSystemCentralInertiaInGround(s)
        mom, prod = om.np3(Io.getMoments()), om.np3(Io.getProducts())
        errs.add("system central inertia", np.diag(Ic), mom)
        errs.add("system central inertia", [Ic[0, 1], Ic[0, 2], Ic[1, 2]], prod)
    errs.check("weld chain mass properties", tol=1e-12)


# ----------------------------------------------------------------------------- 2. constraints


def assemble_along(orc, q, step=0.05):
    """OpenSim's assembly at the coordinate values ``q`` (the others placed by the
    constraints), reached from the current state in steps of at most ``step`` rad
    (continuation: Simbody's weld condition has spurious solutions far away)."""
    s = orc.state
    start = {n: orc.coords[n].getValue(s) for n in q}
    k = max(1, int(np.ceil(max(abs(q[n] - start[n]) for n in q) / step)))
    for t in np.linspace(0.0, 1.0, k + 1)[1:]:
        for n in q:
            orc.coords[n].setValue(s, start[n] + t * (q[n] - start[n]), False)
        orc.model.assemble(s)
    orc.model.realizePosition(s)


def frames_coincide(errs, orc, constraint, kind):
    """OpenSim's own check of its assembly: its constraint errors vanish and (a weld) the
    two frames coincide in ground."""
    s = orc.state
    c = orc.model.getConstraintSet().get(constraint)
    if kind == "weld":
        w = opensim.WeldConstraint.safeDownCast(c)
        X1, X2 = w.getFrame1().getTransformInGround(s), w.getFrame2().getTransformInGround(s)
        errs.add("OpenSim weld frames", om.np3(X1.p()), om.np3(X2.p()))
        errs.add("OpenSim weld frames", om.np33(X1.R()), om.np33(X2.R()))
    errs.add("OpenSim constraint errors", np.asarray(s.getQErr().to_numpy()), 0.0)


@pytest.mark.slow
def test_constraints_match_opensims_assembly(files):
    """CoordinateCouplerConstraints (a SimmSpline and a scaled LinearFunction of q1), a
    WeldConstraint and a PointConstraint between offset frames: with q1 and p's rotations
    set, openfdk's constrained pose equals OpenSim's after ``model.assemble`` (assembly
    accuracy 1e-13) at 30 random samples; so do the coupled coordinates."""
    path = files["constraints"]
    ours = Ours(path)
    orc = om.Oracle(path, assembly_accuracy=1e-13)
    names = [c.name for c in ours.model.constraints]
    assert {"couple_b", "couple_s", "weld_bw", "pointconstraint"} <= set(names)
    rng = np.random.default_rng(21)
    indep = ["j1_coord_0", "jp_coord_0", "jp_coord_1", "jp_coord_2"]
    errs = Errors()
    samples = sorted((orc.sample(rng, indep) for _ in range(30)), key=lambda q: q["j1_coord_0"])
    for q in samples:
        assemble_along(orc, q)
        frames_coincide(errs, orc, "weld_bw", "weld")
        for n, v in q.items():
            errs.add("OpenSim kept the set coordinates", orc.coords[n].getValue(orc.state), v)
        st = solve_driven(ours.model, q)
        dependent = {n: orc.coords[n].getValue(orc.state) for n in ("j2_coord_0", "js_coord_0")}
        compare_positions(errs, orc, ours, st, {**q, **dependent})
        # w's free-joint coordinates: the same rotation (Euler angles modulo 2π and the
        # second branch), the same translation
        py, _ = ours.coordinates(st)
        errs.add("w translation coordinates", [py[f"jw_coord_{k}"] for k in (3, 4, 5)],
                 [orc.coords[f"jw_coord_{k}"].getValue(orc.state) for k in (3, 4, 5)])
    # the couplers' functions, independently: q2 = spline(q1), qs = 0.7 (0.2 q1 + 0.05)
    assert orc.coords["js_coord_0"].getValue(orc.state) == pytest.approx(
        0.7 * (0.2 * samples[-1]["j1_coord_0"] + 0.05), abs=1e-12)
    errs.check("constraints (30 samples)")


@pytest.mark.slow
@pytest.mark.parametrize("coupler", ["linear", "spline"])
def test_a_coordinate_moved_only_through_splines_follows_its_coupler_as_in_opensim(workdir, coupler):
    """Rajagopal 2016's patella (opensim_models.patella_model): its coordinate moves no
    axis linearly, so openfdk cannot measure it from the poses; a coupler makes it a
    function of the knee angle. The patella is then placed by the knee's angle through
    the coupler, the coupler needs no row, and the poses, markers and the coupled
    coordinate equal OpenSim's assembly at 30 samples; the joint's rows' Jacobian and
    bias equal central differences."""
    path = om.patella_model(workdir / f"patella_{coupler}.osim", coupler=coupler)
    ours = Ours(path)
    orc = om.Oracle(path, assembly_accuracy=1e-13)
    rows = {c.name: len(c.row_names) for c in ours.model.constraints}
    assert rows["patellofemoral"] == 6 and "patella_follows_knee" not in rows  # held by construction
    rng = np.random.default_rng(31)
    errs = Errors()
    indep = ["hip_coord_0", "knee_coord_0"]
    samples = sorted((orc.sample(rng, indep) for _ in range(30)), key=lambda q: q["knee_coord_0"])
    for q in samples:
        assemble_along(orc, q)
        st = solve_driven(ours.model, q)
        compare_positions(errs, orc, ours, st, {**q, "beta": orc.coords["beta"].getValue(orc.state)})
    errs.check(f"patella, {coupler} coupler (30 samples)")
    if coupler == "linear":  # independently: beta = knee
        assert orc.coords["beta"].getValue(orc.state) == pytest.approx(samples[-1]["knee_coord_0"], abs=1e-12)
    st = solve_driven(ours.model, samples[len(samples) // 2])
    st.set_v(np.random.default_rng(32).normal(size=st.n_coords))
    assert "patellofemoral" in _check_rows(ours.model, st, f"patella {coupler}")


# ----------------------------------------------------------------------------- 3. Jacobians


def _has_function(m):
    if isinstance(m, FunctionOf):
        return True
    return any(_has_function(t) for _, t in getattr(m, "terms", ()))


def _check_rows(model, state, label):
    """Each constraint with FunctionOf rows: compiled vs Python value, Jacobian and bias;
    Jacobian vs central differences on the manifold, bias vs the second difference along
    q ⊕ s v; non-zero Jacobian and bias. Returns the constraint names checked."""
    checked = []
    for con in model.constraints:
        if not _has_function(con.measure):
            continue
        m = con.measure
        prog = CompiledMeasures([m])
        val, M, b = prog.evaluate(state, 2)
        ref_val, ref_M, ref_b = m.evaluate(state, 2)
        np.testing.assert_allclose(val, ref_val, rtol=0, atol=1e-14, err_msg=f"{label} {con.name}")
        np.testing.assert_allclose(M, ref_M, rtol=0, atol=1e-13, err_msg=f"{label} {con.name}")
        np.testing.assert_allclose(b, ref_b, rtol=1e-12, atol=1e-12, err_msg=f"{label} {con.name}")
        rows = [k for k, r in enumerate(con.row_names) if _row_is_function(m, k)]
        assert rows, con.name
        assert np.min(np.max(np.abs(M[rows]), axis=1)) > 1e-4, f"{con.name}: a function row's Jacobian vanishes"
        assert np.min(np.abs(b[rows])) > 1e-6, f"{con.name}: a function row's bias vanishes"
        M_fd = manifold_jacobian(lambda s: prog.evaluate(s, 0)[0], state, eps=1e-6)
        np.testing.assert_allclose(M, M_fd, atol=1e-8, rtol=1e-6, err_msg=f"{label} {con.name}")
        b_fd = second_derivative_along(lambda s: prog.evaluate(s, 0)[0], state, state.get_v(), h=1e-4)
        np.testing.assert_allclose(b, b_fd, atol=2e-6, rtol=1e-5, err_msg=f"{label} {con.name}")
        checked.append(con.name)
    return checked


def _row_is_function(m, k):
    """Whether row k of a constraint's measure (a Linear of terms) holds a FunctionOf."""
    return any(np.any(C[k] != 0.0) and _has_function(sub) for C, sub in m.terms)


@pytest.mark.slow
def test_function_rows_jacobian_and_bias_against_finite_differences(files):
    """The rows holding FunctionOf measures — the knee's five spline/polynomial axes, the
    ankle's PolynomialFunction translation, the mtp's spline rotation of a translational
    coordinate and the two couplers — at random poses and
    random velocities: compiled = Python reference; Jacobian and bias = finite
    differences on the manifold; neither vanishes."""
    rng = np.random.default_rng(31)
    custom = Ours(files["custom"])
    orc = om.Oracle(files["custom"])
    checked = set()
    for _ in range(3):
        q = orc.sample(rng)
        st, _ = pose_from_coordinates(custom.model, q)
        st.set_v(rng.normal(size=custom.model.n_coords))
        checked |= set(_check_rows(custom.model, st, "custom"))
    assert checked == {"knee", "ankle", "mtp"}
    constrained = Ours(files["constraints"])
    model = constrained.model
    st = solve_driven(model, {"j1_coord_0": 0.4, "jp_coord_0": 0.2, "jp_coord_1": -0.3, "jp_coord_2": 0.5})
    st.set_v(rng.normal(size=model.n_coords))
    assert set(_check_rows(model, st, "constraints")) == {"couple_b", "couple_s"}


# ----------------------------------------------------------------------------- 4. OpenSim 3.x


@pytest.mark.slow
def test_opensim_3x_file_matches_opensim_and_its_4x_conversion(workdir):
    """A hand-written OpenSim 3.x file (tests/opensim_models.py: model_3x_text) read by
    openfdk equals OpenSim 4.6 reading it (which converts it) at 30 random samples
    (assembled: a coupler with a scale factor, a 3.x WeldConstraint and PointConstraint,
    a locked coordinate, a WeldJoint); and openfdk reading OpenSim's 4.x conversion of
    the file gives the same model: bodies, frames, markers, coordinates and the same
    poses (1e-12)."""
    p3 = workdir / "leg3x.osim"
    p3.write_text(om.model_3x_text())
    m = opensim.Model(str(p3))
    for name in om.FREE_3X:
        m.updCoordinateSet().get(name).set_is_free_to_satisfy_constraints(True)
    m.initSystem()
    p4 = workdir / "leg4x.osim"
    assert m.printToXML(str(p4))
    assert etree.parse(str(p4)).getroot().get("Version") >= "40000"
    ours3, ours4 = Ours(p3), Ours(p4)
    assert ours3.doc.version == 30000 and ours4.doc.version >= 40000
    m3, m4 = ours3.model, ours4.model
    assert [b.name for b in m3.bodies] == [b.name for b in m4.bodies]
    assert "toes_r" not in ours3.index and ours3.tree.root["toes_r"] == "foot_r"
    assert m3.markers.labels == m4.markers.labels
    assert [(c.name, c.unit, c.range, c.default, c.locked) for c in m3.coordinates] == \
        [(c.name, c.unit, c.range, c.default, c.locked) for c in m4.coordinates]
    for b3, b4 in zip(m3.bodies, m4.bodies):
        assert b3.mass == b4.mass
        np.testing.assert_allclose(b3.inertia_B, b4.inertia_B, rtol=0, atol=1e-15)
        np.testing.assert_allclose(b3.p_WB0, b4.p_WB0, rtol=0, atol=SAME)
    orc = om.Oracle(p3, assembly_accuracy=1e-13)
    for name in om.FREE_3X:
        orc.coords[name].set_is_free_to_satisfy_constraints(True)
    assert orc.coords["hip_rotation_r"].getLocked(orc.state)
    rng = np.random.default_rng(41)
    indep = [c.name for c in m3.coordinates if not c.locked and c.name != "patella_angle_r"
             and c.name not in om.FREE_3X]
    errs, same = Errors(), Errors()
    for _ in range(30):
        q = orc.sample(rng, indep)
        assemble_along(orc, q, step=0.2)
        frames_coincide(errs, orc, "brace_weld", "weld")
        st3, st4 = solve_driven(m3, q), solve_driven(m4, q)
        full = {**q, "patella_angle_r": orc.coords["patella_angle_r"].getValue(orc.state),
                "hip_rotation_r": orc.coords["hip_rotation_r"].getValue(orc.state)}
        compare_positions(errs, orc, ours3, st3, full)
        compare_positions(errs, orc, ours4, st4, full)
        same.add("body position", st3.p_WB, st4.p_WB)
        same.add("body rotation", st3.R_WB, st4.R_WB)
    errs.check("OpenSim 3.x file vs OpenSim (30 samples)")
    same.check("3.x file vs its 4.x conversion", tol=SAME)


# ----------------------------------------------------------------------------- 5. round trip


@pytest.mark.slow
def test_export_opensim_reads_back_to_the_same_poses(files, workdir):
    """``export_opensim`` (what ``openfdk export-opensim`` runs: an .osim with one
    FreeJoint per body, defaults at the first frame, and a .mot of the FreeJoint
    coordinates) of a three-frame run of the custom-joint model at random poses, read
    back with openfdk's reader: the reference pose is the first frame (bodies, markers;
    1e-12), the .mot's coordinates put every body where the run had it, masses and
    inertias are kept, and OpenSim reads the export to the same poses."""
    import pandas as pd

    from openfdk.io.osim import export_opensim
    from openfdk.io.storage import read_storage
    from openfdk.results.run import RunResults

    ours = Ours(files["custom"])
    model = ours.model
    orc = om.Oracle(files["custom"])
    rng = np.random.default_rng(51)
    states = [pose_at(model, orc.sample(rng))[0] for _ in range(3)]
    columns = {}
    for b in model.bodies[1:]:
        for k, c in enumerate("xyz"):
            columns[f"{b.name}.{c}_m"] = [st.p_WB[b.index, k] for st in states]
        for k in range(4):
            columns[f"{b.name}.e{k}"] = [st.quat_WB[b.index, k] for st in states]
    columns["converged"] = [1, 1, 1]
    kinematics = pd.DataFrame(columns, index=pd.Index([0.0, 0.01, 0.02], name="time"))
    out = export_opensim(RunResults(kinematics, None, {}, model=model), workdir / "export", model=model)
    assert out["frames"] == 3 and not out["skipped_frames"]
    back, _ = load_model_and_settings(out["osim"])
    assert [b.name for b in back.bodies] == [b.name for b in model.bodies]
    errs = Errors()
    for b, b2 in zip(model.bodies[1:], back.bodies[1:]):
        assert b2.mass == b.mass
        errs.add("inertia", b2.inertia_B, b.inertia_B)
    st0, ref = states[0], back.initial_state()
    errs.add("body position", ref.p_WB[1:], st0.p_WB[1:])
    errs.add("body rotation", ref.R_WB[1:], st0.R_WB[1:])
    mk, mk2 = model.markers, back.markers
    for j in range(mk.size):
        k = list(mk2.labels).index(mk.labels[j])
        errs.add("marker position", ref.p_WB[mk2.body[k]] + ref.R_WB[mk2.body[k]] @ mk2.p_BM[k],
                 st0.p_WB[mk.body[j]] + st0.R_WB[mk.body[j]] @ mk.p_BM[j])
    # every frame of the .mot: openfdk's read-back model at those coordinates
    time, values, in_degrees = read_storage(out["mot"])
    assert not in_degrees and len(time) == 3
    for i, st in enumerate(states):
        q = {c.name: float(values[c.name][i]) for c in back.coordinates}
        st2, _ = pose_from_coordinates(back, q)
        errs.add("body position", st2.p_WB[1:], st.p_WB[1:])
        errs.add("body rotation", st2.R_WB[1:], st.R_WB[1:])
    # and OpenSim reads the export to the first frame's poses
    exported = om.Oracle(out["osim"])
    for b in model.bodies[1:]:
        p, R = exported.body_pose(b.name)
        errs.add("OpenSim body position", p, st0.p_WB[b.index])
        errs.add("OpenSim body rotation", R, st0.R_WB[b.index])
    errs.check("export-opensim round trip (3 frames)", tol=1e-12)


# ----------------------------------------------------------------------------- 6. malformed files


def _one_line(exc, path, line=None):
    msg = str(exc.value)
    assert "\n" not in msg, msg
    assert path.name in msg, msg
    if line is not None:
        assert f"line {line}:" in msg, msg
    return msg


def _edit(src, dst, edit):
    """Copy the model file ``src`` to ``dst`` with ``edit(tree)`` applied; returns the
    edited element's line in the written file (``edit`` returns the element)."""
    tree = etree.parse(str(src))
    element = edit(tree)
    element.set("data-mark", "here")
    text = etree.tostring(tree, xml_declaration=True, encoding="UTF-8").decode()
    line = next(k + 1 for k, t in enumerate(text.splitlines()) if 'data-mark="here"' in t)
    dst.write_text(text.replace(' data-mark="here"', ""))
    return line


def _add_mesh(tree):
    body = tree.xpath("//Body[@name='pin']")[0]
    holder = etree.SubElement(body, "attached_geometry")
    mesh = etree.SubElement(holder, "Mesh", name="pin_geom")
    etree.SubElement(mesh, "socket_frame").text = ".."
    etree.SubElement(mesh, "mesh_file").text = "nothere.vtp"
    return mesh


def _unsort_knots(tree):
    spline = tree.xpath("//CustomJoint[@name='knee']//TransformAxis[@name='rotation2']/SimmSpline")[0]
    x = spline.find("x")
    values = x.text.split()
    values[2], values[3] = values[3], values[2]
    x.text = " ".join(values)
    return spline


def _unknown_coupler_coordinate(tree):
    c = tree.xpath("//CoordinateCouplerConstraint[@name='couple_b']")[0]
    c.find("independent_coordinate_names").text = "no_such_coordinate"
    return c


def _ellipsoid_joint(tree):
    joint = tree.xpath("//PinJoint[@name='pin_j']")[0]
    joint.tag = "EllipsoidJoint"
    return joint


#: a muscle class openfdk does not read (Thelen, both Millard muscles, RigidTendonMuscle and Schutte are read:
#: tests/test_opensim_muscles.py, tests/test_opensim_millard.py, tests/test_opensim_curve_muscles.py)
MUSCLE = """<DeGrooteFregly2016Muscle name="vastus">
  <GeometryPath name="path">
    <PathPointSet><objects>
      <PathPoint name="p1">
        <location>0 0 0</location><socket_parent_frame>/bodyset/pin</socket_parent_frame>
      </PathPoint>
      <PathPoint name="p2">
        <location>0 0.1 0</location><socket_parent_frame>/bodyset/slider</socket_parent_frame>
      </PathPoint>
    </objects></PathPointSet>
  </GeometryPath>
  <max_isometric_force>1000</max_isometric_force>
</DeGrooteFregly2016Muscle>"""


def _muscle(tree):
    objects = tree.xpath("//ForceSet/objects")[0]
    muscle = etree.fromstring(MUSCLE)
    objects.append(muscle)
    return muscle


@pytest.mark.parametrize("case,source,edit,words", [
    ("unsorted_knots", "custom", _unsort_knots, "SimmSpline"),
    ("unknown_coordinate", "constraints", _unknown_coupler_coordinate, "no_such_coordinate"),
    ("ellipsoid_joint", "joints", _ellipsoid_joint, "EllipsoidJoint"),
    ("muscle", "joints", _muscle, "DeGrooteFregly2016Muscle 'vastus'"),
])
def test_malformed_files_are_one_line_errors(files, workdir, case, source, edit, words):
    """Each malformed file raises OsimError (a ValueError) with one line naming the file,
    the offending element's line and what is wrong."""
    path = workdir / f"bad_{case}.osim"
    line = _edit(files[source], path, edit)
    with pytest.raises(OsimError) as exc:
        load_model_and_settings(path)
    assert isinstance(exc.value, ValueError)
    msg = _one_line(exc, path, line)
    assert words in msg, msg


def test_a_bare_ampersand_in_text_is_read_as_opensim_reads_it(workdir, recwarn):
    """jam-resources' full_body_healthy_knee.osim writes "Smith, C. R., Brandon, S. C.,
    & Thelen, D. G." in <publications>: not XML (an '&' starts an entity), but OpenSim's
    parser reads it. openfdk reads the model too, warns once naming that line (not the
    comments' '&', which XML allows), and the model equals the file with '&amp;'. An
    '&' in a file that has another syntax error leaves that error standing."""
    import warnings

    from openfdk.model.plausibility import PlausibilityWarning

    text = om.custom_model(workdir / "amp_base.osim").read_text()
    head, rest = text.split("<Model name=\"custom\">", 1)
    escaped = workdir / "escaped.osim"
    escaped.write_text(f"{head}<Model name=\"custom\">\n<!-- Bei & Fregly 2004 -->\n"
                       f"<publications>Smith &amp; Thelen (2019)</publications>{rest}")
    bare = workdir / "bare.osim"
    bare.write_text(escaped.read_text().replace("&amp;", "&"))
    line = bare.read_text().splitlines().index("<publications>Smith & Thelen (2019)</publications>") + 1
    assert opensim.Model(str(bare)).getPublications() != ""  # the oracle: OpenSim reads the file
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        data, _ = read_osim(bare)
    ours = [w for w in caught if issubclass(w.category, PlausibilityWarning)]
    assert len(ours) == 1, [str(w.message) for w in caught]
    message = str(ours[0].message)
    assert message.startswith(f"bare.osim: line {line}: '&'") and "as OpenSim reads" in message, message
    with warnings.catch_warnings():
        warnings.simplefilter("error", PlausibilityWarning)
        expected, _ = read_osim(escaped)  # (no warning: the escaped file is XML)
    assert data == expected
    broken = workdir / "bare_and_broken.osim"
    broken.write_text(bare.read_text().replace("</publications>", "</publication>"))
    with pytest.raises(OsimError) as exc:
        read_osim(broken)
    assert "not well-formed XML" in _one_line(exc, broken)


def test_a_display_mesh_not_found_is_left_out_with_one_warning(files, workdir, recwarn):
    """OpenSim reads a model whose display meshes are missing and warns; so does openfdk
    (stop 64: it had refused it). The mesh is listed as dropped and the rest reads."""
    tree = etree.parse(str(files["joints"]))
    _add_mesh(tree)
    path = workdir / "no_mesh.osim"
    tree.write(str(path))
    data, info = read_osim(path)
    messages = [str(w.message) for w in recwarn if "display mesh" in str(w.message)]
    assert len(messages) == 1 and "no_mesh.osim: 1 display mesh file(s) not found ('nothere.vtp'; looked in" in \
        messages[0], messages
    assert any(d["type"] == "Mesh" and d["name"] == "nothere.vtp" for d in info["dropped"]), info["dropped"]
    assert set(data["bodies"]) == set(read_osim(files["joints"])[0]["bodies"])


def test_an_ignored_type_that_looks_mistyped_is_named():
    """``--ignore CustomJont`` (a misspelt type the model has) or ``--ignore A,B`` (two
    types in one) matched nothing and passed unnoticed; now a warning names each. A real
    type the model lacks (``Thelen2003Muscle`` here) is no mistake and gives none, and
    ``Mesh`` of a model with display meshes and ``forces`` are matched."""
    import warnings

    from openfdk.bench.fuzz_inputs import OSIM_TEXT

    from openfdk.model.plausibility import PlausibilityWarning

    path = Path("leg_ignore.osim")
    path.write_text(OSIM_TEXT)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        read_osim(path, ignore=("Mesh", "forces", "Thelen2003Muscle", "CustomJont",
                                "Mesh,Millard2012EquilibriumMuscle"))
    messages = [str(w.message) for w in caught if issubclass(w.category, PlausibilityWarning)]
    assert messages == [
        "leg_ignore.osim: --ignore 'CustomJont': the model has no element of this type (did you mean "
        "'CustomJoint'?)",
        "leg_ignore.osim: --ignore 'Mesh,Millard2012EquilibriumMuscle': the model has no element of this type "
        "(one OpenSim type per --ignore, e.g. --ignore Mesh --ignore Thelen2003Muscle)"], messages


def test_not_xml_and_not_opensim_are_one_line_errors(workdir):
    bad = workdir / "broken.osim"
    bad.write_text('<?xml version="1.0"?>\n<OpenSimDocument Version="40000">\n<Model name="m">\n<BodySet>\n'
                   '</Model>\n</OpenSimDocument>\n')
    with pytest.raises(OsimError) as exc:
        read_osim(bad)
    msg = _one_line(exc, bad)
    assert "not well-formed XML" in msg and "line 5" in msg, msg
    other = workdir / "other.osim"
    other.write_text('<?xml version="1.0"?>\n<ModelSet>\n  <Model name="m"/>\n</ModelSet>\n')
    with pytest.raises(OsimError) as exc:
        read_osim(other)
    msg = _one_line(exc, other, 2)
    assert "<ModelSet>" in msg and "not an OpenSim model" in msg, msg


def test_cli_check_reports_bad_files_in_one_line_and_ignore_skips_muscles(files, workdir, capsys):
    """``openfdk check bad.osim`` exits 2 with one line on stderr; ``--ignore
    DeGrooteFregly2016Muscle`` reads the model without its muscle. A display mesh not
    found is one warning line, and the check succeeds (stop 64; OpenSim reads such a
    model too)."""
    from openfdk.cli import main

    bad = workdir / "cli_mesh.osim"
    _edit(files["joints"], bad, _add_mesh)
    capsys.readouterr()
    assert main(["check", str(bad)]) == 0
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "cli_mesh.osim: 1 display mesh file(s) not found ('nothere.vtp'" in err, err
    muscle = workdir / "cli_muscle.osim"
    line = _edit(files["joints"], muscle, _muscle)
    assert main(["check", str(muscle)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and f"line {line}:" in err and "--ignore DeGrooteFregly2016Muscle" in err, err
    ignored = workdir / "cli_muscle_ignored.osim"
    _edit(files["joints"], ignored, _muscle)
    assert main(["check", str(ignored), "--ignore", "DeGrooteFregly2016Muscle"]) == 0
    out = capsys.readouterr()
    assert "error" not in out.err
    _, info = read_osim(ignored, ignore=("DeGrooteFregly2016Muscle",))
    assert [d["type"] for d in info["dropped"]] == ["DeGrooteFregly2016Muscle"]


# ----------------------------------------------------------------------------- meshes

BONE_VTP = """<?xml version="1.0"?>
<VTKFile type="PolyData" version="0.1" byte_order="LittleEndian">
  <PolyData>
    <Piece NumberOfPoints="4" NumberOfVerts="0" NumberOfLines="0" NumberOfStrips="0" NumberOfPolys="2">
      <Points>
        <DataArray type="Float32" NumberOfComponents="3" format="ascii">0 0 0 0.1 0 0 0 0.2 0 0 0 0.05</DataArray>
      </Points>
      <Polys>
        <DataArray type="Int32" Name="connectivity" format="ascii">0 1 2 0 2 3</DataArray>
        <DataArray type="Int32" Name="offsets" format="ascii">3 6</DataArray>
      </Polys>
    </Piece>
  </PolyData>
</VTKFile>
"""


def _add_meshes(tree):
    """A scaled Mesh on the welded body b and one on the model-level frame f2."""
    for owner, scale in ((tree.xpath("//Body[@name='b']")[0], "1 2 0.5"),
                         (tree.xpath("/OpenSimDocument/Model/components/PhysicalOffsetFrame[@name='f2']")[0], "1 1 1")):
        holder = owner.find("attached_geometry")
        if holder is None:
            holder = etree.SubElement(owner, "attached_geometry")
        mesh = etree.SubElement(holder, "Mesh", name=f"{owner.get('name')}_bone")
        etree.SubElement(mesh, "socket_frame").text = ".."
        etree.SubElement(mesh, "scale_factors").text = scale
        etree.SubElement(mesh, "mesh_file").text = "bone.vtp"
    return mesh


def test_meshes_are_found_and_placed_as_opensim_places_them(files, workdir, monkeypatch):
    """Mesh files are looked for next to the model, in its Geometry folder and in
    ../Geometry — also for a model named relative to the cwd — and a mesh on a welded
    body and one on an offset frame of an offset frame land where OpenSim puts their
    frames (with the scale factors), at a random pose."""
    from openfdk.model.visuals import visual_mesh_B

    (workdir / "Geometry").mkdir(exist_ok=True)
    (workdir / "Geometry" / "bone.vtp").write_text(BONE_VTP)
    models = workdir / "models"
    models.mkdir(exist_ok=True)
    _edit(files["weld_chain"], models / "meshes.osim", _add_meshes)
    monkeypatch.chdir(models)
    model, _ = load_model_and_settings("meshes.osim")  # relative: ../Geometry from the cwd's parent
    assert len(model.visuals) == 2
    assert all(v.path == str((workdir / "Geometry" / "bone.vtp").resolve()) for v in model.visuals)
    orc = om.Oracle(models / "meshes.osim")
    rng = np.random.default_rng(61)
    free = [c.name for c in model.coordinates if not c.prescribed]
    q = orc.sample(rng, free)
    orc.set(q, t=0.7)
    st, _ = pose_from_coordinates(model, q, t=0.7)
    vertices = np.array([[0, 0, 0], [0.1, 0, 0], [0, 0.2, 0], [0, 0, 0.05]])
    errs = Errors()
    for vis, (frame, scale) in zip(model.visuals, ((orc.bodies["b"], [1, 2, 0.5]),
                                                   (opensim.PhysicalFrame.safeDownCast(orc.model.getComponent("/f2")),
                                                    [1, 1, 1]))):
        v_B, _ = visual_mesh_B(vis)
        i = [b.name for b in model.bodies].index(vis.body)
        ours = st.p_WB[i] + v_B @ st.R_WB[i].T
        X = frame.getTransformInGround(orc.state)
        theirs = om.np3(X.p()) + (vertices * scale) @ om.np33(X.R()).T
        errs.add("mesh vertices", ours, theirs)
    assert [v.body for v in model.visuals] == ["a", "d"]
    errs.check("meshes")


def test_disabled_constraint_is_left_out_and_listed(files, workdir):
    """A constraint with ``<isEnforced>false</isEnforced>`` is not applied by OpenSim, and
    openfdk leaves it out and lists it among the dropped elements; its dependent
    coordinate is then free in both."""
    path = workdir / "disabled.osim"

    def disable(tree):
        c = tree.xpath("//CoordinateCouplerConstraint[@name='couple_s']")[0]
        etree.SubElement(c, "isEnforced").text = "false"
        return c

    line = _edit(files["constraints"], path, disable)
    orc = om.Oracle(path)
    assert not orc.model.getConstraintSet().get("couple_s").isEnforced(orc.state)
    data, info = read_osim(path)
    assert "couple_s" not in data.get("couplers", {}) and "couple_b" in data["couplers"]
    assert {"type": "CoordinateCouplerConstraint", "name": "couple_s", "line": line} in info["dropped"]


def test_a_contact_force_s_scoped_tag_names_read_as_opensim_reads_them(workdir):
    """OpenSim writes a HuntCrossleyForce's parameters as ``<HuntCrossleyForce::
    ContactParametersSet>``, a tag name XML reads as an undeclared namespace prefix:
    lxml refused every such model (opensim-models' BouncingBlock, ToyLanding, Jumper,
    SoccerKick, WalkerModel). The file OpenSim 4.6 writes here now reads: the force and
    its contact geometry are refused by name, every type listed once for --ignore, and
    with them left out the model loads."""
    m = opensim.Model()
    m.setName("ball")
    ball = opensim.Body("ball", 2.0, opensim.Vec3(0), opensim.Inertia(0.01, 0.01, 0.01))
    m.addBody(ball)
    m.addJoint(opensim.FreeJoint("free", m.getGround(), ball))
    floor = opensim.ContactHalfSpace(opensim.Vec3(0), opensim.Vec3(0, 0, -1.5707963267949), m.getGround(), "floor")
    sphere = opensim.ContactSphere(0.05, opensim.Vec3(0), ball, "sphere")
    m.addContactGeometry(floor)
    m.addContactGeometry(sphere)
    force = opensim.HuntCrossleyForce()
    force.setName("contact")
    force.addGeometry("floor")
    force.addGeometry("sphere")
    force.setStiffness(1e6)
    m.addForce(force)
    m.addMarker(opensim.Marker("top", ball, opensim.Vec3(0, 0.05, 0)))
    m.finalizeConnections()
    path = workdir / "ball.osim"
    m.printToXML(str(path))
    assert "<HuntCrossleyForce::ContactParametersSet" in path.read_text()
    opensim.Model(str(path))  # OpenSim reads its own file
    with pytest.raises(OsimError) as exc:
        read_osim(path)
    msg = str(exc.value)
    assert "\n" not in msg and "ball.osim: line" in msg and "not supported" in msg, msg
    kinds = ["HuntCrossleyForce", "ContactHalfSpace", "ContactSphere"]
    assert all(f"--ignore {k}" in msg for k in kinds), msg
    data, info = read_osim(path, ignore=kinds)
    assert "ball" in data["bodies"] and sorted({d["type"] for d in info["dropped"]}) == sorted(kinds)
