"""OpenSim's ConstantDistanceConstraint and PointOnLineConstraint, read as openfdk
constraints (a distance; a vector's two components normal to the line), against
OpenSim 4.6.

A pendulum arm and a free block, written with OpenSim's API: a rod of constant length
joins the arm's tip to the block, and a point of the block runs on a rail fixed in the
ground. OpenSim's assembler places the block at 30 arm angles; openfdk tracks the
markers of those poses and must find OpenSim's coordinates, and its poses must keep the
rod's length and the rail, both measured on OpenSim's model.
"""

from __future__ import annotations

import numpy as np
import pytest

osim = pytest.importorskip("opensim")

from openfdk.cli import main  # noqa: E402
from openfdk.fixtures.full_body_osim import write_trc  # noqa: E402
from openfdk.io.opensim import read_osim  # noqa: E402

TIP_ARM = (0.0, -0.4, 0.0)             # m, arm frame: the rod's end on the arm
ROD_BLOCK = (0.0, 0.05, 0.0)           # m, block frame: the rod's end on the block
ROD_LENGTH = 0.3
RAIL_POINT, RAIL_DIRECTION = (0.02, 0.22, 0.0), (1.0, 0.3, 0.1)   # m, ground
FOLLOWER = (0.02, -0.03, 0.0)          # m, block frame
MARKERS = {"A1": ("arm", (0.05, -0.1, 0.02)), "A2": ("arm", (-0.04, -0.35, -0.03)),
           "B1": ("block", (0.05, 0.0, 0.0)), "B2": ("block", (0.0, 0.05, 0.01)),
           "B3": ("block", (-0.03, -0.02, 0.04))}
FREE = ("b_rx", "b_ry", "b_rz", "b_tx", "b_ty", "b_tz")
N_FRAMES, RATE_HZ = 30, 50.0


def _model(path):
    m = osim.Model()
    m.setName("rod_and_rail")
    arm = osim.Body("arm", 1.5, osim.Vec3(0, -0.2, 0), osim.Inertia(0.02, 0.004, 0.02))
    block = osim.Body("block", 0.8, osim.Vec3(0.01, 0, 0), osim.Inertia(0.003, 0.004, 0.005))
    m.addBody(arm)
    m.addBody(block)
    pin = osim.PinJoint("shoulder", m.getGround(), osim.Vec3(0, 1, 0), osim.Vec3(0, 0, 0), arm,
                        osim.Vec3(0, 0, 0), osim.Vec3(0, 0, 0))
    free = osim.FreeJoint("block_free", m.getGround(), block)
    m.addJoint(pin)
    m.addJoint(free)
    pin.updCoordinate().setName("q1")
    for k, name in enumerate(FREE):
        free.upd_coordinates(k).setName(name)
    free.upd_coordinates(4).setDefaultValue(0.25)
    rod = osim.ConstantDistanceConstraint(arm, osim.Vec3(*TIP_ARM), block, osim.Vec3(*ROD_BLOCK), ROD_LENGTH)
    rod.setName("rod")
    rail = osim.PointOnLineConstraint(m.getGround(), osim.Vec3(*RAIL_DIRECTION), osim.Vec3(*RAIL_POINT), block,
                                      osim.Vec3(*FOLLOWER))
    rail.setName("rail")
    m.addConstraint(rod)
    m.addConstraint(rail)
    for name, (body, p) in MARKERS.items():
        m.addMarker(osim.Marker(name, m.getBodySet().get(body), osim.Vec3(*p)))
    m.set_assembly_accuracy(1e-12)
    m.finalizeConnections()
    m.initSystem()
    assert m.printToXML(str(path))
    return path


def _errors(model, state):
    """(rod length − ROD_LENGTH, distance of the follower from the rail) m at ``state``,
    from OpenSim's frames."""
    arm, block = model.getBodySet().get("arm"), model.getBodySet().get("block")
    tip = arm.findStationLocationInGround(state, osim.Vec3(*TIP_ARM)).to_numpy()
    end = block.findStationLocationInGround(state, osim.Vec3(*ROD_BLOCK)).to_numpy()
    follower = block.findStationLocationInGround(state, osim.Vec3(*FOLLOWER)).to_numpy()
    u = np.array(RAIL_DIRECTION) / np.linalg.norm(RAIL_DIRECTION)
    d = follower - np.array(RAIL_POINT)
    return np.linalg.norm(end - tip) - ROD_LENGTH, np.linalg.norm(d - (d @ u) * u)


@pytest.fixture(scope="module")
def rod_and_rail(tmp_path_factory):
    folder = tmp_path_factory.mktemp("rod")
    path = _model(folder / "rod_and_rail.osim")
    model = osim.Model(str(path))
    state = model.initSystem()
    coords = model.getCoordinateSet()
    t = np.arange(N_FRAMES) / RATE_HZ
    q_true, x = [], []
    for tk in t:
        coords.get("q1").setValue(state, 0.5 * np.sin(2 * np.pi * 1.1 * tk), False)
        coords.get("b_rz").setValue(state, 0.2 * np.sin(2 * np.pi * 0.7 * tk), False)
        model.assemble(state)
        model.realizePosition(state)
        q_true.append([coords.get(n).getValue(state) for n in ("q1",) + FREE])
        x.append([model.getMarkerSet().get(n).getLocationInGround(state).to_numpy() for n in MARKERS])
        assert max(map(abs, _errors(model, state))) < 1e-9           # OpenSim's poses keep both
    write_trc(folder / "trial.trc", list(MARKERS), t, np.array(x), RATE_HZ, digits=9)
    code = main(["kinematics", str(path), str(folder / "trial.trc"), "--cutoff", "0", "--out",
                 str(folder / "ours"), "-q"])
    assert code == 0
    data = np.genfromtxt(folder / "ours" / "coordinates.csv", delimiter=",", names=True)
    units = {"q1": "rad", "b_rx": "rad", "b_ry": "rad", "b_rz": "rad", "b_tx": "m", "b_ty": "m", "b_tz": "m"}
    ours = np.stack([data[f"{n}_{units[n]}"] for n in ("q1",) + FREE], axis=1)
    return path, model, state, np.array(q_true), ours


def test_read_as_a_distance_and_a_line(rod_and_rail):
    data, _ = read_osim(rod_and_rail[0])
    rod, rail = data["constraints"]["rod"], data["constraints"]["rail"]
    assert rod["measure"]["type"] == "distance" and rod["value"] == ROD_LENGTH
    assert rail["measure"]["type"] == "vector" and rail["components"] == [1, 2]


def test_tracking_finds_opensim_s_assembled_poses(rod_and_rail):
    _, _, _, q_true, ours = rod_and_rail
    assert np.ptp(q_true[:, 0]) > 0.5 and np.ptp(q_true[:, 3:], axis=0).max() > 0.05   # the block moves
    np.testing.assert_allclose(ours, q_true, atol=1e-7, rtol=0)


def test_openfdk_s_poses_keep_the_rod_and_the_rail(rod_and_rail):
    _, model, state, _, ours = rod_and_rail
    coords = model.getCoordinateSet()
    for row in ours:
        for name, value in zip(("q1",) + FREE, row):
            coords.get(name).setValue(state, float(value), False)
        model.realizePosition(state)
        rod, rail = _errors(model, state)
        assert abs(rod) < 1e-9 and rail < 1e-9


def test_a_direction_of_zero_is_one_line(tmp_path, rod_and_rail):
    from openfdk.io.opensim import OsimError

    text = rod_and_rail[0].read_text()
    bad = tmp_path / "bad.osim"
    bad.write_text(text.replace("<line_direction_vec>1 0.29999999999999999 0.10000000000000001</line_direction_vec>",
                                "<line_direction_vec>0 0 0</line_direction_vec>"))
    assert "<line_direction_vec>0 0 0<" in bad.read_text()
    with pytest.raises(OsimError, match=r"bad.osim: line \d+: PointOnLineConstraint 'rail': line_direction_vec "
                                        r"\[0.0, 0.0, 0.0\] has no direction"):
        read_osim(bad)


@pytest.mark.parametrize("extra", [0.0, 0.01])
def test_both_points_on_one_welded_body(tmp_path, extra):
    """The block welded to the arm: openfdk merges the two bodies, so a rod between them
    holds by the geometry, or never. The rod's true length (0.35 m from the weld's
    offsets) is read; 1 cm more is refused by name."""
    from openfdk.io.opensim import OsimError

    m = osim.Model()
    arm = osim.Body("arm", 1.5, osim.Vec3(0, -0.2, 0), osim.Inertia(0.02, 0.004, 0.02))
    block = osim.Body("block", 0.8, osim.Vec3(0), osim.Inertia(0.003, 0.004, 0.005))
    m.addBody(arm)
    m.addBody(block)
    m.addJoint(osim.PinJoint("shoulder", m.getGround(), osim.Vec3(0, 1, 0), osim.Vec3(0), arm, osim.Vec3(0),
                             osim.Vec3(0)))
    m.addJoint(osim.WeldJoint("glue", arm, osim.Vec3(0, -0.3, 0), osim.Vec3(0), block, osim.Vec3(0), osim.Vec3(0)))
    # arm point (0, 0, 0), block point (0, -0.05, 0): 0.35 m apart
    rod = osim.ConstantDistanceConstraint(arm, osim.Vec3(0), block, osim.Vec3(0, -0.05, 0), 0.35 + extra)
    rod.setName("rod")
    m.addConstraint(rod)
    m.finalizeConnections()
    path = tmp_path / "welded.osim"
    assert m.printToXML(str(path))
    if extra == 0.0:
        data, _ = read_osim(path)
        assert "rod" not in (data.get("constraints") or {})
        return
    with pytest.raises(OsimError, match=r"welded.osim: line \d+: ConstantDistanceConstraint 'rod': both points are on "
                                        r"one body \(welded\), and its geometry misses the constraint by 0.01 m"):
        read_osim(path)
