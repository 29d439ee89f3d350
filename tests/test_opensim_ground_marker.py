"""A marker fixed to the ground (Arm26's ``r_acromion``) against OpenSim 4.6's IK.

OpenSim's IK keeps such a marker in its objective, but its distance to the trial's marker
is the same at every pose, so the optimum is the one without it. openfdk leaves it out of
the imported model, lists it as dropped in ``summary.json``, and accepts an
``IKMarkerTask`` naming it. A two-link arm built with OpenSim's API (a ground marker, one
marker on each link, unequal weights) is tracked by both programs on a noisy trial: the
coordinates agree row by row (OpenSim at accuracy 1e-10).
"""

from __future__ import annotations

import json

import numpy as np
import pytest

opensim = pytest.importorskip("opensim")

from openfdk.cli import main  # noqa: E402
from openfdk.io.storage import read_storage  # noqa: E402

MARKERS = ("shoulder_mark", "elbow_mark", "wrist_mark")


def _arm(path):
    """Ground - PinJoint - upper arm - PinJoint - forearm; a marker on the ground and one per link."""
    model = opensim.Model()
    model.setName("two_link")
    upper = opensim.Body("upper", 2.0, opensim.Vec3(0, -0.15, 0), opensim.Inertia(0.02, 0.005, 0.02))
    fore = opensim.Body("fore", 1.2, opensim.Vec3(0, -0.12, 0), opensim.Inertia(0.01, 0.003, 0.01))
    model.addBody(upper)
    model.addBody(fore)
    shoulder = opensim.PinJoint("shoulder", model.getGround(), opensim.Vec3(0, 1.0, 0), opensim.Vec3(0, 0, 0),
                                upper, opensim.Vec3(0, 0, 0), opensim.Vec3(0, 0, 0))
    elbow = opensim.PinJoint("elbow", upper, opensim.Vec3(0, -0.3, 0), opensim.Vec3(0, 0, 0),
                             fore, opensim.Vec3(0, 0, 0), opensim.Vec3(0, 0, 0))
    shoulder.updCoordinate().setName("q_shoulder")
    elbow.updCoordinate().setName("q_elbow")
    model.addJoint(shoulder)
    model.addJoint(elbow)
    model.addMarker(opensim.Marker(MARKERS[0], model.getGround(), opensim.Vec3(0.01, 1.02, 0.05)))
    model.addMarker(opensim.Marker(MARKERS[1], upper, opensim.Vec3(0.03, -0.28, 0.02)))
    model.addMarker(opensim.Marker(MARKERS[2], fore, opensim.Vec3(-0.02, -0.25, 0.03)))
    model.finalizeConnections()
    model.printToXML(str(path))
    return path


def _trial(model_path, trc_path, n=20, rate=50.0, seed=5):
    """Marker positions of a known motion (OpenSim's forward kinematics) plus 2 mm noise, as a TRC in mm."""
    model = opensim.Model(str(model_path))
    state = model.initSystem()
    rng = np.random.default_rng(seed)
    times = np.arange(n) / rate
    rows = []
    for t in times:
        model.getCoordinateSet().get("q_shoulder").setValue(state, 0.4 * np.sin(2 * t), False)
        model.getCoordinateSet().get("q_elbow").setValue(state, 0.2 + 1.2 * t, False)
        model.realizePosition(state)
        xyz = [model.getMarkerSet().get(m).getLocationInGround(state).to_numpy() for m in MARKERS]
        rows.append(np.concatenate(xyz) * 1000 + rng.normal(0, 2.0, 9))
    head = ["PathFileType\t4\t(X/Y/Z)\ttrial.trc",
            "DataRate\tCameraRate\tNumFrames\tNumMarkers\tUnits\tOrigDataRate\tOrigDataStartFrame\tOrigNumFrames",
            f"{rate:g}\t{rate:g}\t{n}\t3\tmm\t{rate:g}\t1\t{n}",
            "Frame#\tTime\t" + "\t\t\t".join(MARKERS) + "\t\t",
            "\t\t" + "\t".join(f"X{k}\tY{k}\tZ{k}" for k in range(1, 4)), ""]
    body = [f"{i + 1}\t{t:.6f}\t" + "\t".join(f"{v:.6f}" for v in row) for i, (t, row) in enumerate(zip(times, rows))]
    trc_path.write_text("\n".join(head + body) + "\n")
    return times


def _setup(folder, model, trc, t0, t1):
    tasks = "".join(f"<IKMarkerTask name=\"{m}\"><apply>true</apply><weight>{w}</weight></IKMarkerTask>"
                    for m, w in zip(MARKERS, (5.0, 1.0, 2.0)))
    path = folder / "Setup_IK.xml"
    path.write_text(f"""<?xml version="1.0" encoding="UTF-8" ?>
<OpenSimDocument Version="40000">
  <InverseKinematicsTool name="test">
    <model_file>{model.name}</model_file>
    <constraint_weight>Inf</constraint_weight>
    <accuracy>1e-10</accuracy>
    <IKTaskSet name="tasks"><objects>{tasks}</objects></IKTaskSet>
    <marker_file>{trc.name}</marker_file>
    <time_range>{t0!r} {t1!r}</time_range>
    <output_motion_file>opensim_ik.mot</output_motion_file>
  </InverseKinematicsTool>
</OpenSimDocument>
""")
    return path


def test_a_ground_marker_is_dropped_and_tracking_equals_opensims_ik(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    model = _arm(tmp_path / "two_link.osim")
    trc = tmp_path / "trial.trc"
    times = _trial(model, trc)
    setup = _setup(tmp_path, model, trc, float(times[0]), float(times[-1]))
    tool = opensim.InverseKinematicsTool(str(setup))
    osim_model = opensim.Model(str(model))  # kept alive while the tool runs
    tool.setModel(osim_model)
    tool.setResultsDir(str(tmp_path))
    tool.setOutputMotionFileName(str(tmp_path / "opensim_ik.mot"))
    assert tool.run()
    theirs = read_storage(tmp_path / "opensim_ik.mot")

    code = main(["kinematics", str(model), str(trc), "--ik-tasks", str(setup), "--cutoff", "0", "--out",
                 str(tmp_path / "ours"), "-q"])
    assert code == 0, capsys.readouterr().err
    ours = read_storage(tmp_path / "ours" / "coordinates.mot")
    assert len(ours[0]) == len(theirs[0]) == len(times)
    for name in ("q_shoulder", "q_elbow"):
        assert np.max(np.abs(ours[1][name] - theirs[1][name])) < 1e-4, name  # degrees
    dropped = json.loads((tmp_path / "ours" / "summary.json").read_text())["input"]["opensim_import"]["dropped"]
    assert [(d["type"], d["name"]) for d in dropped] == [("Marker", MARKERS[0])]
