"""OpenSim 1.x/2.x models (OpenSimDocument Version < 30000) upgraded by OpenSim itself
(openfdk.io.opensim.upgrade), and the other quirks of opensim-core's own model files:
an unnamed 3.x joint, ``Unassigned`` length units, ``motion_type`` in capitals, and text
in Windows-1252 in a file declared UTF-8.

The 2.x model is written here, in the 2.x layout (a Thelen2003Muscle with the 2.x
property names ``Vmax``, ``Vmax0``, ``FmaxTendonStrain`` …); OpenSim 4.6 loads the same
file as the oracle for the muscle's path length.
"""

from __future__ import annotations

import numpy as np
import pytest

from openfdk.io.opensim import OsimError, read_osim
from openfdk.model.plausibility import PlausibilityWarning

OLD_PENDULUM = """<?xml version="1.0" encoding="UTF-8"?>
<OpenSimDocument Version="20302">
  <Model name="old_pendulum">
    <ForceSet name="">
      <objects>
        <Thelen2003Muscle name="flexor">
          <min_control> 0 </min_control>
          <max_control> 1 </max_control>
          <GeometryPath name="flexor">
            <PathPointSet name="">
              <objects>
                <PathPoint name="origin"><location> 0.06 0.10 0.01 </location><body> ground </body></PathPoint>
                <PathPoint name="insertion"><location> 0.04 -0.30 0.00 </location><body> link </body></PathPoint>
              </objects>
            </PathPointSet>
          </GeometryPath>
          <max_isometric_force> 500 </max_isometric_force>
          <optimal_fiber_length> 0.12 </optimal_fiber_length>
          <tendon_slack_length> 0.2 </tendon_slack_length>
          <pennation_angle_at_optimal> 0 </pennation_angle_at_optimal>
          <activation_time_constant> 0.01 </activation_time_constant>
          <deactivation_time_constant> 0.04 </deactivation_time_constant>
          <Vmax> 8 </Vmax>
          <Vmax0> 4 </Vmax0>
          <FmaxTendonStrain> 0.033 </FmaxTendonStrain>
          <FmaxMuscleStrain> 0.6 </FmaxMuscleStrain>
          <KshapeActive> 0.5 </KshapeActive>
          <KshapePassive> 4 </KshapePassive>
          <damping> 0.05 </damping>
          <Af> 0.3 </Af>
          <Flen> 1.8 </Flen>
        </Thelen2003Muscle>
      </objects>
    </ForceSet>
    <BodySet name="">
      <objects>
        <Body name="ground">
          <mass> 0 </mass>
          <mass_center> 0 0 0 </mass_center>
          <inertia_xx> 0 </inertia_xx><inertia_yy> 0 </inertia_yy><inertia_zz> 0 </inertia_zz>
          <inertia_xy> 0 </inertia_xy><inertia_xz> 0 </inertia_xz><inertia_yz> 0 </inertia_yz>
        </Body>
        <Body name="link">
          <mass> 2 </mass>
          <mass_center> 0 -0.25 0 </mass_center>
          <inertia_xx> 0.05 </inertia_xx><inertia_yy> 0.01 </inertia_yy><inertia_zz> 0.05 </inertia_zz>
          <inertia_xy> 0 </inertia_xy><inertia_xz> 0 </inertia_xz><inertia_yz> 0 </inertia_yz>
          <Joint>
            <PinJoint name="pin">
              <parent_body> ground </parent_body>
              <location_in_parent> 0 0 0 </location_in_parent>
              <orientation_in_parent> 0 0 0 </orientation_in_parent>
              <location> 0 0 0 </location>
              <orientation> 0 0 0 </orientation>
              <CoordinateSet name="">
                <objects>
                  <Coordinate name="q">
                    <motion_type> rotational </motion_type>
                    <default_value> 0 </default_value>
                    <range> -2 2 </range>
                  </Coordinate>
                </objects>
              </CoordinateSet>
              <reverse> false </reverse>
            </PinJoint>
          </Joint>
        </Body>
      </objects>
    </BodySet>
  </Model>
</OpenSimDocument>
"""


def test_a_2x_model_is_read_as_opensim_upgrades_it(tmp_path):
    """The muscle's 2.x ``Vmax`` becomes its maximum contraction velocity, and its path
    length equals OpenSim's at 9 angles, to round-off."""
    opensim = pytest.importorskip("opensim")
    from openfdk.io.modelfile import model_from_dict
    from openfdk.kinematics.coordinate_pose import pose_from_coordinates

    path = tmp_path / "old_pendulum.osim"
    path.write_text(OLD_PENDULUM)
    with pytest.warns(PlausibilityWarning, match=r"old_pendulum.osim: OpenSimDocument Version 20302 \(OpenSim "
                                                 r"2.x\): read as OpenSim 4\.\d+ upgrades it"):
        data, _ = read_osim(path)
    theirs = opensim.Model(str(path))
    flexor, thelen = data["muscles"]["flexor"], opensim.Thelen2003Muscle.safeDownCast(theirs.getMuscles().get(0))
    assert flexor["max_isometric_force"] == 500.0
    # OpenSim's upgrade keeps FmaxTendonStrain but not Vmax: the velocity is its default
    assert flexor["max_contraction_velocity"] == thelen.getMaxContractionVelocity() == 10.0
    assert flexor["tendon_strain_at_max_force"] == thelen.get_FmaxTendonStrain() == 0.033
    ours = model_from_dict(data, source=str(path))
    state = theirs.initSystem()
    muscle, coordinate = theirs.getMuscles().get(0), theirs.getCoordinateSet().get("q")
    lengths = []
    for q in np.linspace(-1.0, 1.0, 9):
        coordinate.setValue(state, float(q))
        theirs.realizePosition(state)
        pose, _ = pose_from_coordinates(ours, {"q": float(q)})
        length = float(np.ravel(ours.muscles[0].path.evaluate(pose, 0)[0])[0])
        assert length == pytest.approx(muscle.getLength(state), abs=1e-12)
        lengths.append(length)
    assert np.ptp(lengths) > 0.05                               # the angle moves the path


def test_without_opensim_the_message_says_how_to_upgrade(tmp_path, monkeypatch):
    import importlib.util

    from openfdk.io.opensim import upgrade

    real = importlib.util.find_spec
    monkeypatch.setattr(upgrade.importlib.util, "find_spec",
                        lambda name, *a: None if name == "opensim" else real(name, *a))
    path = tmp_path / "old_pendulum.osim"
    path.write_text(OLD_PENDULUM)
    with pytest.raises(OsimError) as info:
        read_osim(path)
    message = str(info.value)
    assert message.startswith("old_pendulum.osim: OpenSimDocument Version 20302 is an OpenSim 2.x file; openfdk "
                              "reads Version 30000 (OpenSim 3.0) and later.")
    assert "pip install opensim" in message and "\n" not in message


def test_a_file_opensim_cannot_upgrade_is_one_line(tmp_path, monkeypatch):
    """OpenSim's upgrade failing (its child process exits with an error) is one line
    with OpenSim's last words; what it upgrades but openfdk cannot read names the file
    as upgraded."""
    pytest.importorskip("opensim")
    from openfdk.io.opensim import upgrade

    path = tmp_path / "broken.osim"
    path.write_text(OLD_PENDULUM.replace("<parent_body> ground </parent_body>", "<parent_body> nowhere </parent_body>"))
    with pytest.raises(OsimError) as info, pytest.warns(PlausibilityWarning, match="upgrades it"):
        read_osim(path)
    message = str(info.value)
    assert message.startswith("broken.osim (as OpenSim 4.") and "'nowhere'" in message and "\n" not in message
    monkeypatch.setattr(upgrade, "_CHILD", "import sys\nsys.exit('RuntimeError: Body nowhere not found')")
    with pytest.raises(OsimError) as info:
        read_osim(path)
    assert str(info.value) == ("broken.osim: OpenSimDocument Version 20302 is an OpenSim 2.x file, and OpenSim "
                               "could not upgrade it: RuntimeError: Body nowhere not found")


def _current(tmp_path, edit, name="current.osim"):
    """A current pendulum (the 2.x one as OpenSim 4 writes it), edited by ``edit(text)``."""
    opensim = pytest.importorskip("opensim")
    old = tmp_path / "old.osim"
    old.write_text(OLD_PENDULUM)
    opensim.Model(str(old)).printToXML(str(tmp_path / name))
    path = tmp_path / name
    path.write_bytes(edit(path.read_bytes()))
    return path


def test_quirks_of_opensim_s_own_files(tmp_path):
    """``Unassigned`` length units (its Pendulum.osim), ``motion_type`` 'Rotational'
    (Moco's example models write 'Coupled'), and an en dash written in Windows-1252 in a
    file declared UTF-8 (subject1_abdbonepin.osim): read as OpenSim reads them."""
    reference, _ = read_osim(_current(tmp_path, lambda b: b, "reference.osim"))

    def edit(text):
        text = text.replace(b'<Coordinate name="q">', b'<Coordinate name="q"><motion_type>Rotational</motion_type>', 1)
        return text.replace(b'<Model name="old_pendulum">', b'<Model name="old_pendulum"><publications>Seth A, '
                            b'829\x96840</publications><length_units>Unassigned</length_units>', 1)

    path = _current(tmp_path, edit)
    assert b"Unassigned" in path.read_bytes() and b"Rotational" in path.read_bytes()
    with pytest.warns(PlausibilityWarning, match=r"current.osim: line 3: bytes that are not UTF-8, read as "
                                                 r"Windows-1252 text"):
        data, _ = read_osim(path)
    assert data["coordinates"] == reference["coordinates"] and data["muscles"] == reference["muscles"]


def test_unnamed_3x_joints_and_constraints_are_named_by_type_as_opensim_names_them(tmp_path):
    """opensim-core's BushingForceModel_30000.osim nests a SliderJoint without a name in
    its body, its CoupledCoordinatesMPPsMomentArmTest.osim has a WeldConstraint without
    one; OpenSim 4.6 names them 'sliderjoint' and 'weldconstraint'. The pendulum in the
    3.x layout (without the 2.x muscle), its PinJoint unnamed, and a bob on a FreeJoint
    held to the link by an unnamed WeldConstraint."""
    opensim = pytest.importorskip("opensim")
    text = OLD_PENDULUM.replace('Version="20302"', 'Version="30000"').replace('<PinJoint name="pin">', "<PinJoint>")
    text = text[:text.index("<ForceSet")] + text[text.index("</ForceSet>") + len("</ForceSet>"):]
    free = "".join(f"<Coordinate name=\"bob_{a}\"><default_value> 0 </default_value><range> -5 5 </range></Coordinate>"
                   for a in ("rx", "ry", "rz", "tx", "ty", "tz"))
    bob = f"""<Body name="bob"><mass> 1 </mass><mass_center> 0 0 0 </mass_center>
          <inertia_xx> 0.01 </inertia_xx><inertia_yy> 0.01 </inertia_yy><inertia_zz> 0.01 </inertia_zz>
          <inertia_xy> 0 </inertia_xy><inertia_xz> 0 </inertia_xz><inertia_yz> 0 </inertia_yz>
          <Joint><FreeJoint name="bob_free"><parent_body> ground </parent_body>
            <location_in_parent> 0 0 0 </location_in_parent><orientation_in_parent> 0 0 0 </orientation_in_parent>
            <location> 0 0 0 </location><orientation> 0 0 0 </orientation>
            <CoordinateSet name=""><objects>{free}</objects></CoordinateSet></FreeJoint></Joint></Body>"""
    weld = """<ConstraintSet><objects><WeldConstraint><isDisabled> false </isDisabled>
          <body_1> link </body_1><body_2> bob </body_2>
          <location_body_1> 0 -0.5 0 </location_body_1><orientation_body_1> 0 0 0 </orientation_body_1>
          <location_body_2> 0 0 0 </location_body_2><orientation_body_2> 0 0 0 </orientation_body_2>
        </WeldConstraint></objects></ConstraintSet>"""
    text = text.replace("</objects>\n    </BodySet>", bob + "</objects>\n    </BodySet>" + weld)
    path = tmp_path / "unnamed.osim"
    path.write_text(text)
    data, _ = read_osim(path)
    theirs = opensim.Model(str(path))
    names = [theirs.getJointSet().get(k).getName() for k in range(theirs.getJointSet().getSize())]
    assert "pinjoint" in names and theirs.getConstraintSet().get(0).getName() == "weldconstraint"
    assert {"pinjoint", "bob_free", "weldconstraint"} <= set(data["joints"])
    assert data["joints"]["weldconstraint"]["type"] == "weld"


def test_thelen_properties_left_in_a_millard_muscle_are_ignored_as_opensim_ignores_them(tmp_path):
    """OpenSim's walk_gait1018_subject01.osim (a Moco test model) has Millard muscles that
    still carry the Thelen2003Muscle properties FmaxTendonStrain, KshapeActive … OpenSim
    4.6 has no such property on the Millard muscle: the tendon curve keeps its default
    strain 0.049. openfdk reads the muscle as without them, with one warning."""
    opensim = pytest.importorskip("opensim")
    m = opensim.Model()
    body = opensim.Body("link", 1.0, opensim.Vec3(0, -0.2, 0), opensim.Inertia(0.01))
    m.addBody(body)
    m.addJoint(opensim.PinJoint("pin", m.getGround(), opensim.Vec3(0), opensim.Vec3(0), body, opensim.Vec3(0),
                                opensim.Vec3(0)))
    muscle = opensim.Millard2012EquilibriumMuscle("flexor", 400.0, 0.1, 0.2, 0.0)
    muscle.addNewPathPoint("o", m.getGround(), opensim.Vec3(0.05, 0.1, 0))
    muscle.addNewPathPoint("i", body, opensim.Vec3(0.04, -0.3, 0))
    m.addForce(muscle)
    m.finalizeConnections()
    clean = tmp_path / "clean.osim"
    assert m.printToXML(str(clean))
    text = clean.read_text()
    leftover = text.replace("<tendon_slack_length>", "<FmaxTendonStrain>0.033</FmaxTendonStrain>"
                            "<KshapeActive>0.5</KshapeActive><Af>0.3</Af><tendon_slack_length>", 1)
    assert leftover != text
    path = tmp_path / "leftover.osim"
    path.write_text(leftover)
    model = opensim.Model(str(path))
    model.initSystem()
    theirs = opensim.Millard2012EquilibriumMuscle.safeDownCast(model.getMuscles().get(0))
    assert theirs.getTendonForceLengthCurve().getStrainAtOneNormForce() == 0.049
    with pytest.warns(PlausibilityWarning, match=r"leftover.osim: Thelen2003Muscle properties in "
                                                 r"Millard2012EquilibriumMuscles, which have no such property: OpenSim "
                                                 r"ignores them, and so does openfdk: <FmaxTendonStrain> in 1 muscle "
                                                 r"\(flexor\); <KshapeActive>"):
        data, _ = read_osim(path)
    assert data["muscles"] == read_osim(clean)[0]["muscles"]
