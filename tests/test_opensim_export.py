"""``export-opensim`` of joints, coordinates, couplers, markers, muscles and ligaments
(docs/opensim.md, "Exporting a run"), with OpenSim 4.6 as the oracle.

Models built with OpenSim's own API (tests/opensim_models.py) are imported by openfdk,
exported again (:func:`openfdk.io.osim.export_model`) and loaded by OpenSim, which must
log no warning. At random coordinate values both OpenSim models — the original and the
export — place every marker, and give every muscle and ligament path length and moment
arm (``computeMomentArm``), to 1e-9 m. openfdk's own example models export and load in
OpenSim without warnings, and what OpenSim cannot hold is named, one line per kind."""

from __future__ import annotations

import numpy as np
import pytest

osim = pytest.importorskip("opensim")

import opensim_models as om  # noqa: E402  (tests/opensim_models.py)

from openfdk.io.modelfile import load_model  # noqa: E402
from openfdk.io.osim import export_model, note_lines  # noqa: E402
from openfdk.io.osim_joints import joint_coordinates, plan_joints  # noqa: E402
from openfdk.model.state import BodyStates  # noqa: E402
from openfdk.numerics.spatial import quat_from_matrix  # noqa: E402

TOL = 1e-9


def arm_with_forces(path):
    """Two pin joints (q1, q2), two markers per body, a Thelen2003Muscle over both joints
    with a ConditionalPathPoint, a Millard2012EquilibriumMuscle, a
    Blankevoort1991Ligament, a SpringGeneralizedForce and a CoordinateActuator,
    non-default parameters."""
    m, upper, lower = om.two_link_arm("arm_forces")
    g = m.getGround()
    rng = np.random.default_rng(7)
    for b in (upper, lower):
        om.add_markers(m, b, rng)
    th = osim.Thelen2003Muscle("biceps", 700.0, 0.12, 0.25, 0.1)
    th.set_Af(0.3)
    th.set_FmaxTendonStrain(0.05)
    th.set_KshapeActive(0.5)
    th.addNewPathPoint("o", g, osim.Vec3(0.03, 1.02, 0.01))
    th.addNewPathPoint("via", upper, osim.Vec3(0.03, -0.2, 0.02))
    th.addNewPathPoint("i", lower, osim.Vec3(0.02, -0.06, 0.0))
    m.addForce(th)
    mi = osim.Millard2012EquilibriumMuscle("triceps", 900.0, 0.09, 0.2, 0.05)
    mi.addNewPathPoint("o", upper, osim.Vec3(-0.03, -0.05, 0.0))
    mi.addNewPathPoint("i", lower, osim.Vec3(-0.02, 0.03, -0.01))
    m.addForce(mi)
    lig = osim.Blankevoort1991Ligament("collateral", upper, osim.Vec3(0.01, -0.28, 0.03), lower,
                                       osim.Vec3(0.0, 0.02, 0.03))
    lig.set_linear_stiffness(2500.0)
    lig.set_slack_length(0.05)
    m.addForce(lig)
    spring = osim.SpringGeneralizedForce("q1")
    spring.setName("shoulder_spring")
    spring.setStiffness(12.5)
    spring.setRestLength(0.2)
    spring.setViscosity(0.3)
    m.addForce(spring)
    reserve = osim.CoordinateActuator("q2")
    reserve.setName("elbow_reserve")
    reserve.setOptimalForce(2.5)
    reserve.setMinControl(-40.0)
    reserve.setMaxControl(35.0)
    m.addForce(reserve)
    m.finalizeConnections()
    om.write(m, path)
    # one ConditionalPathPoint (active for q2 in [-0.5, 1.0]) in the biceps, by editing the file
    from lxml import etree

    tree = etree.parse(str(path))
    (pt,) = tree.xpath("//Thelen2003Muscle[@name='biceps']//PathPoint[@name='via']")
    pt.tag = "ConditionalPathPoint"
    etree.SubElement(pt, "range").text = "-0.5 1.0"
    etree.SubElement(pt, "socket_coordinate").text = "/jointset/elbow/q2"
    tree.write(str(path), xml_declaration=True, encoding="UTF-8")
    return path


def load_quietly(path):
    """OpenSim's Model of ``path`` (initialised) and its log lines other than the two
    usual ones (format update, "Loaded model")."""
    old = osim.Logger.getLevelString()
    sink = osim.StringLogSink()
    osim.Logger.setLevelString("info")
    osim.Logger.addSink(sink)
    try:
        model = osim.Model(str(path))
        model.initSystem()
    finally:
        osim.Logger.removeSink(sink)
        osim.Logger.setLevelString(old)
    usual = ("Updating Model file from", "Loaded model ")
    return model, [x for x in sink.getString().splitlines() if x.strip() and not x.startswith(usual)]


def _path(force):
    cls = osim.Muscle if osim.Muscle.safeDownCast(force) else osim.Blankevoort1991Ligament
    return cls.safeDownCast(force).getGeometryPath()


def differing_properties(a, b, prefix=""):
    """Names of the properties (recursively, paths and appearance aside) whose values
    differ between two OpenSim objects of one class."""
    out = []
    for i in range(a.getNumProperties()):
        pa = a.getPropertyByIndex(i)
        name = pa.getName()
        if name in ("path", "GeometryPath", "Appearance"):
            continue
        pb = b.getPropertyByName(name)
        if pa.isObjectProperty() and pa.size() == 1 and pb.size() == 1:
            out += differing_properties(pa.getValueAsObject(0), pb.getValueAsObject(0), f"{prefix}{name}.")
        elif pa.toString() != pb.toString():
            out.append(f"{prefix}{name}: {pa.toString()} != {pb.toString()}")
    return out


def compare(original, exported, n=25, seed=3):
    """Largest |Δ| of marker positions, path lengths and moment arms (m) between two
    OpenSim models at ``n`` random poses (the original's coordinates uniform in their
    ranges, assembled under its constraints, then copied into the export)."""
    a, b = om.Oracle(original), om.Oracle(exported)
    assert sorted(a.coords) == sorted(b.coords)
    assert sorted(a.markers) == sorted(b.markers)
    forces_a = {f.getName(): f for f in (a.model.getForceSet().get(k) for k in range(a.model.getForceSet().getSize()))}
    forces_b = {f.getName(): f for f in (b.model.getForceSet().get(k) for k in range(b.model.getForceSet().getSize()))}
    assert sorted(forces_a) == sorted(forces_b)
    for name, f in forces_a.items():  # every muscle and ligament parameter, curves included
        assert f.getConcreteClassName() == forces_b[name].getConcreteClassName()
        assert differing_properties(f, forces_b[name]) == [], name
    rng = np.random.default_rng(seed)
    worst = {"marker": 0.0, "length": 0.0, "moment arm": 0.0}
    for _ in range(n):
        q = a.sample(rng)
        for name, v in q.items():
            if not a.coords[name].getLocked(a.state):
                a.coords[name].setValue(a.state, v, False)
        a.model.assemble(a.state)
        a.model.realizePosition(a.state)
        for name, c in b.coords.items():
            c.setValue(b.state, a.coords[name].getValue(a.state), False)
        b.model.realizePosition(b.state)
        for name in a.markers:
            worst["marker"] = max(worst["marker"], np.abs(a.marker_position(name) - b.marker_position(name)).max())
        for name, fa in forces_a.items():
            if not (osim.Muscle.safeDownCast(fa) or osim.Blankevoort1991Ligament.safeDownCast(fa)):
                continue  # (a spring or actuator on a coordinate: its parameters are compared above)
            pa, pb = _path(fa), _path(forces_b[name])
            worst["length"] = max(worst["length"], abs(pa.getLength(a.state) - pb.getLength(b.state)))
            for cname, c in a.coords.items():
                arm = pa.computeMomentArm(a.state, c) - pb.computeMomentArm(b.state, b.coords[cname])
                worst["moment arm"] = max(worst["moment arm"], abs(arm))
    return worst


@pytest.fixture
def _in_tmp(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # OpenSim writes opensim.log into the cwd


@pytest.mark.slow
@pytest.mark.parametrize("build", [arm_with_forces, om.custom_model, om.constraints_model],
                         ids=["pins_muscles_ligament", "custom_joints", "couplers_and_constraints"])
def test_import_export_round_trip_equals_the_original_in_opensim(build, tmp_path, _in_tmp):
    original = build(tmp_path / "original.osim")
    model = load_model(original)
    out = export_model(model, tmp_path / "export")
    assert not out["notes"], note_lines(out["notes"])
    exported, log = load_quietly(out["osim"])
    assert log == []
    worst = compare(original, out["osim"])
    print({k: f"{v:.1e}" for k, v in worst.items()})
    assert max(worst.values()) <= TOL, worst


EXAMPLE_JOINTS = {
    "slider_crank.yaml": {"crank_pin": "PinJoint", "big_end": "PinJoint", "rail": "CustomJoint"},
    # the knee's FDK rows x, y become the coordinates knee_tx, knee_ty of a CustomJoint
    "knee/knee_springs.yaml": {"hip": "PinJoint", "knee": "CustomJoint"},
}


@pytest.mark.parametrize("example", sorted(EXAMPLE_JOINTS))
def test_example_models_load_in_opensim_without_warnings(example, tmp_path, _in_tmp):
    """openfdk's example models: their joints as OpenSim joints, loaded without a
    warning; the slider-crank's loop-closing constraint on a measure and its driver are
    named as not exported, one line per kind."""
    from pathlib import Path

    model = load_model(Path(__file__).resolve().parents[1] / "examples" / example)
    out = export_model(model, tmp_path / "export")
    exported, log = load_quietly(out["osim"])
    assert log == []
    kinds = {j.getName(): j.getConcreteClassName() for j in (exported.getJointSet().get(k)
                                                              for k in range(exported.getJointSet().getSize()))}
    assert kinds == EXAMPLE_JOINTS[example]
    joints = plan_joints(model)[0]
    coords = {exported.getCoordinateSet().get(k).getName() for k in range(exported.getCoordinateSet().getSize())}
    assert coords == {c.name for j in joints for c in j.coordinates}
    # the .mot's coordinates from body poses: OpenSim places the bodies at random
    # coordinates, openfdk reads the coordinates back from those poses
    orc = om.Oracle(out["osim"])
    rng = np.random.default_rng(5)
    for _ in range(5):
        q = {n: float(rng.uniform(-1.2, 1.2) if n.split("_")[-1][0] == "r" else rng.uniform(-0.05, 0.05))
             for n in coords}
        orc.set(q)
        poses = [orc.body_pose(b.name) if b.index else (np.zeros(3), np.eye(3)) for b in model.bodies]
        state = BodyStates([p for p, _ in poses], [quat_from_matrix(R) for _, R in poses],
                           [b.column for b in model.bodies])
        back = joint_coordinates(joints, state)
        assert max(abs(back[n] - q[n]) for n in q) <= 1e-12
    if example == "slider_crank.yaml":
        assert note_lines(out["notes"]) == [
            "not exported: constraint on an openfdk measure (1): small_end",
            "not exported: driver (its motion is in the .mot) (1): crank_drive"]
    else:
        assert coords == {"hip_rz", "knee_rz", "knee_tx", "knee_ty"}
