"""Massless bodies and point masses, as OpenSim reads them (io/opensim/tree.py,
``opensim_inertia``).

OpenSim models use bodies without mass as intermediate links of compound joints (the
wrist model's ulna, many upper-limb models) and point masses without inertia
(opensim-models' pendulums); a massless body's inertia OpenSim takes as zero, with a
warning. openfdk refused both until stop 65. A chain written here with OpenSim's API: a
massless link given inertia, a point mass, an end body, and a massless marker plate
welded to the point mass, moved along a coordinate file: the generalised forces of
``openfdk run --motion`` equal OpenSim 4.6's InverseDynamicsTool's to 1e-6 of their
range at every frame, and openfdk warns of the inertia it took as zero. A negative
principal moment is still refused by name.
"""

from __future__ import annotations

import numpy as np
import pytest

opensim = pytest.importorskip("opensim")

from openfdk.cli import main  # noqa: E402
from openfdk.io.storage import read_storage, write_storage  # noqa: E402

RATE, N = 100.0, 41


def _chain(path):
    m = opensim.Model()
    m.setName("massless_chain")
    link = opensim.Body("link", 0.0, opensim.Vec3(0, -0.2, 0), opensim.Inertia(0.01, 0.02, 0.015))
    bob = opensim.Body("bob", 2.0, opensim.Vec3(0.02, -0.3, 0.01), opensim.Inertia(0, 0, 0))
    tip = opensim.Body("tip", 0.5, opensim.Vec3(0, -0.1, 0), opensim.Inertia(0.004, 0.002, 0.005))
    plate = opensim.Body("plate", 0.0, opensim.Vec3(0, 0, 0), opensim.Inertia(0, 0, 0))
    for b in (link, bob, tip, plate):
        m.addBody(b)
    joints = [
        opensim.PinJoint("j1", m.getGround(), opensim.Vec3(0, 1.2, 0), opensim.Vec3(0.1, 0, 0), link,
                         opensim.Vec3(0, 0, 0), opensim.Vec3(0, 0, 0)),
        opensim.PinJoint("j2", link, opensim.Vec3(0, -0.4, 0), opensim.Vec3(0, 0.3, 0), bob,
                         opensim.Vec3(0, 0, 0), opensim.Vec3(0, 0, 0)),
        opensim.PinJoint("j3", bob, opensim.Vec3(0, -0.35, 0), opensim.Vec3(0, 0, 0.2), tip,
                         opensim.Vec3(0, 0, 0), opensim.Vec3(0, 0, 0)),
        opensim.WeldJoint("weld", bob, opensim.Vec3(0.05, -0.1, 0), opensim.Vec3(0, 0, 0), plate,
                          opensim.Vec3(0, 0, 0), opensim.Vec3(0, 0, 0)),
    ]
    for j in joints:
        m.addJoint(j)
    for k, j in enumerate(joints[:3]):
        j.updCoordinate().setName(f"q{k + 1}")
    m.finalizeConnections()
    m.initSystem()
    assert m.printToXML(str(path))
    return path


def _motion(path):
    t = np.round(0.1 + np.arange(N) / RATE, 10)
    cols = {"q1": 0.3 * np.sin(2 * np.pi * 0.8 * t), "q2": 0.5 + 0.4 * np.cos(2 * np.pi * 1.1 * t),
            "q3": -0.2 + 0.6 * np.sin(2 * np.pi * 1.3 * t + 0.5)}
    write_storage(path, t, cols, name="motion", in_degrees=False)
    return t


def test_massless_bodies_and_point_masses_have_opensims_generalised_forces(tmp_path, capsys):
    model = _chain(tmp_path / "chain.osim")
    t = _motion(tmp_path / "motion.mot")
    tool = opensim.InverseDynamicsTool()
    osim_model = opensim.Model(str(model))
    tool.setModel(osim_model)
    tool.setCoordinatesFileName(str(tmp_path / "motion.mot"))
    tool.setLowpassCutoffFrequency(-1)
    tool.setStartTime(float(t[0]))
    tool.setEndTime(float(t[-1]))
    tool.setResultsDir(str(tmp_path / "opensim"))
    tool.setOutputGenForceFileName("id.sto")
    tool.setExcludedForces(opensim.ArrayStr("Muscles", 1))
    assert tool.run()
    _, theirs, _ = read_storage(tmp_path / "opensim" / "id.sto")

    capsys.readouterr()
    code = main(["run", str(model), "--motion", str(tmp_path / "motion.mot"), "--out", str(tmp_path / "ours"),
                 "--no-plots", "-q"])
    err = capsys.readouterr().err
    assert code == 0, err
    assert "the inertia of 1 body(ies) replaced as OpenSim replaces it: 'link'" in err, err
    assert "massless with inertia: inertia taken as zero" in err, err
    t_ours, ours, _ = read_storage(tmp_path / "ours" / "generalized_forces.sto")
    assert len(t_ours) == N
    for name in ("q1_moment", "q2_moment", "q3_moment"):
        scale = np.ptp(theirs[name])
        assert scale > 0.05, name  # each moves: the point mass's weight and the tip's inertia act
        np.testing.assert_allclose(ours[name], theirs[name], atol=1e-6 * max(scale, 1.0), rtol=0, err_msg=name)
    # the link's inertia as the file gives it (0.015 kg m² about z) would add I_zz q̈₁ to
    # q1's moment, far above the tolerance: OpenSim's zero is the one taken
    q1 = read_storage(tmp_path / "motion.mot")[1]["q1"]
    assert 0.015 * np.max(np.abs(np.gradient(np.gradient(q1, t), t))) > 1e-2


def test_a_negative_principal_moment_is_refused_by_name(tmp_path, capsys):
    path = _chain(tmp_path / "chain.osim")
    text = path.read_text()
    start = text.index('<Body name="tip">')
    end = text.index("</Body>", start)
    body = text[start:end]
    i0 = body.index("<inertia>")
    bad = body[:i0] + "<inertia>0.01 0.02 0.015 0 0 0.03</inertia>" + body[body.index("</inertia>") + 10:]
    (tmp_path / "bad.osim").write_text(text[:start] + bad + text[end:])
    assert main(["check", str(tmp_path / "bad.osim")]) == 2
    err = [line for line in capsys.readouterr().err.strip().splitlines() if "openfdk: error" in line]
    assert len(err) == 1 and "bad.osim: line " in err[0] and "Body 'tip': its inertia about the centre of mass" \
        in err[0] and "has a negative principal moment" in err[0], err
