"""OpenSim's Blankevoort1991Ligament imported (issue 25: "forces equal to OpenSim's at
random strains, ≤ 1e-9 N"), against OpenSim 4.6 as the oracle: a two-joint model built
with OpenSim's API, three ligaments (one over a wrapping cylinder, non-default
transition strain and damping), compared at random poses and speeds — the length, the
lengthening speed and the total force (spring + OpenSim's damping rule: only while taut
and lengthening, faded in over the first 1 % of strain)."""

from __future__ import annotations

import re

import numpy as np
import pytest

opensim = pytest.importorskip("opensim")

from openfdk.forces.ligament_forces import LigamentForces  # noqa: E402
from openfdk.io.modelfile import model_from_dict  # noqa: E402
from openfdk.io.opensim import OsimError, read_osim  # noqa: E402
from openfdk.kinematics.coordinate_pose import pose_from_coordinates  # noqa: E402

LIGAMENTS = {  # name: (point on upper, point on lower, linear stiffness N/strain, slack m, transition, damping)
    "acl": ((0.02, -0.28, 0.01), (0.01, 0.03, 0.0), 2500.0, 0.02, 0.06, 0.003),
    "pcl": ((-0.02, -0.27, -0.01), (-0.015, 0.02, 0.01), 3000.0, 0.03, 0.1, 0.5),
    "mcl": ((0.0, -0.2, 0.04), (0.0, 0.08, 0.035), 1800.0, 0.08, 0.06, 2.0),
}


def _model(path):
    m = opensim.Model()
    m.setName("knee")
    upper = opensim.Body("upper", 5.0, opensim.Vec3(0, -0.15, 0), opensim.Inertia(0.05, 0.01, 0.05))
    lower = opensim.Body("lower", 3.0, opensim.Vec3(0, -0.15, 0), opensim.Inertia(0.03, 0.005, 0.03))
    m.addBody(upper)
    m.addBody(lower)
    hip = opensim.PinJoint("hip", m.getGround(), opensim.Vec3(0, 1, 0), opensim.Vec3(0, 0, 0), upper,
                           opensim.Vec3(0, 0, 0), opensim.Vec3(0, 0, 0))
    knee = opensim.PinJoint("knee", upper, opensim.Vec3(0, -0.3, 0), opensim.Vec3(0.05, 0, 0), lower,
                            opensim.Vec3(0, 0, 0), opensim.Vec3(0, 0, 0))
    hip.updCoordinate().setName("hip_q")
    knee.updCoordinate().setName("knee_q")
    m.addJoint(hip)
    m.addJoint(knee)
    cyl = opensim.WrapCylinder()
    cyl.setName("condyle")
    cyl.set_radius(0.02)
    cyl.set_length(0.2)
    cyl.set_translation(opensim.Vec3(0.0, -0.3, 0.0))
    upper.addWrapObject(cyl)
    for name, (a, b, k, l0, eps_t, c) in LIGAMENTS.items():
        lig = opensim.Blankevoort1991Ligament(name, upper, opensim.Vec3(*a), lower, opensim.Vec3(*b), k, l0)
        lig.set_transition_strain(eps_t)
        lig.set_damping_coefficient(c)
        if name == "mcl":
            lig.updGeometryPath().addPathWrap(cyl)
        m.addForce(lig)
    m.finalizeConnections()
    m.initSystem()
    m.printToXML(str(path))
    return path


def test_ligament_forces_equal_opensims(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    path = _model(tmp_path / "knee.osim")
    data, _ = read_osim(path)
    ours = model_from_dict(data, source=str(path))
    assert [lig.name for lig in ours.ligaments] == list(LIGAMENTS)
    forces = LigamentForces(ours.ligaments)
    theirs = opensim.Model(str(path))
    state = theirs.initSystem()
    cs = theirs.getCoordinateSet()
    ligs = [opensim.Blankevoort1991Ligament.safeDownCast(theirs.getForceSet().get(n)) for n in LIGAMENTS]
    rng = np.random.default_rng(5)
    worst = np.zeros(3)
    taut = lengthening = 0
    for _ in range(80):
        q = {"hip_q": float(rng.uniform(-0.5, 0.5)), "knee_q": float(rng.uniform(-1.6, 0.3))}
        u = {"hip_q": float(rng.uniform(-3, 3)), "knee_q": float(rng.uniform(-6, 6))}
        for name in q:
            cs.get(name).setValue(state, q[name], False)
            cs.get(name).setSpeedValue(state, u[name])
        theirs.realizeVelocity(state)
        st, _ = pose_from_coordinates(ours, q, qdot=u)
        out = forces.accumulate(st, 0.0, np.zeros(st.n_coords))
        speed = out.L @ st.get_v()
        for k, lig in enumerate(ligs):
            worst = np.maximum(worst, [abs(out.length[k] - lig.getLength(state)),
                                       abs(speed[k] - lig.getLengtheningSpeed(state)),
                                       abs(out.force[k] - lig.getTotalForce(state))])
            taut += out.strain[k] > 0
            lengthening += (out.strain[k] > 0) and speed[k] > 0
    print("largest differences: length, speed, force", worst)
    assert worst[0] < 1e-9 and worst[1] < 1e-8 and worst[2] < 1e-9
    assert taut > 40 and lengthening > 15  # the toe, linear and damped regions are all visited


def test_bad_ligaments_are_one_line_errors(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    text = _model(tmp_path / "knee.osim").read_text()
    for old, new, words in ((r"<slack_length>[^<]*", "<slack_length>-0.02", "slack_length -0.02 is out of range"),
                            (r"<transition_strain>[^<]*", "<transition_strain>0", "transition_strain 0 is out of range"),
                            (r"<linear_stiffness>", "<stiffness_typo>1</stiffness_typo><linear_stiffness>",
                             "property <stiffness_typo> is not read")):
        bad = tmp_path / "bad.osim"
        bad.write_text(re.sub(old, new, text, count=1))
        with pytest.raises(OsimError) as exc:
            read_osim(bad)
        msg = str(exc.value)
        assert "\n" not in msg and "bad.osim: line" in msg and words in msg, msg
