"""``openfdk run --moment-arms`` on a model file of openfdk's own (a pendulum): the moment
arm of a straight muscle equals its closed form, and where the joints and coordinates
leave a mobility unmeasured (a slider driven through a distance, not a coordinate) the
moment arms are not known: the run says so and writes none."""

from __future__ import annotations

import numpy as np
import yaml

from openfdk.cli import main
from openfdk.io.results import read_table

#: the muscle's ground anchor a (m)
ANCHOR = np.array([0.3, 0.0, 0.0])


def _pendulum(folder, slider=False):
    """A link on a hinge (coordinate q about z at the origin, driven), a bob at its end
    (welded, or on a slider along the link's end frame's z, driven through the distance),
    and a muscle from the ground anchor to the link's end."""
    data = {
        "openfdk": 1, "units": {"length": "m", "angle": "rad"},
        "bodies": {"ground": {"points": {"anchor": ANCHOR.tolist()}},
                   "link": {"mass": 1.0, "inertia": [0.01, 0.01, 0.01], "position": [0, -0.25, 0],
                            "points": {"end": [0, -0.25, 0]}},
                   "bob": {"mass": 0.5, "inertia": [0.001, 0.001, 0.001], "position": [0, -0.5, 0.1],
                           "points": {"top": [0, 0, 0]}}},
        "coordinates": {"q": {"default": 0.0}},
        "joints": {"hinge": {"type": "custom", "parent": "ground", "child": "link",
                             "rotations": [{"axis": [0, 0, 1], "coordinate": "q"}]},
                   "bob_joint": {"type": "prismatic" if slider else "weld", "parent": "link.end",
                                 "child": "bob.top"}},
        "drivers": {"q_motion": {"measure": "q", "reaction": True,
                                 "function": {"type": "fourier", "frequency": 1.0, "a": [0.0, 0.6],
                                                               "b": [0.0]}}},
        "muscles": {"m": {"path": ["ground.anchor", "link.end"], "strength": 100.0}},
        "analysis": {"start": 0.0, "end": 0.5, "frames": 6},
    }
    if slider:
        data["measures"] = {"gap": {"type": "distance", "from": "link.end", "to": "bob.top"}}
        data["drivers"]["gap_motion"] = {"measure": "gap", "reaction": True, "function": {"type": "constant", "value": 0.1}}
    (folder / "pendulum.yaml").write_text(yaml.safe_dump(data, sort_keys=False))
    return folder / "pendulum.yaml"


def test_a_straight_muscle_has_the_closed_form_moment_arm(tmp_path, capsys):
    """The link turns about z through the hinge's centre o (the link's frame origin at
    q = 0); its end p moves with dp/dq = ẑ × (p − o), so the path l = |p − a| has
    r = −dl/dq = −(ẑ × (p − o))·(p − a)/l, from the run's own poses."""
    from openfdk.numerics.spatial import rotation_matrix

    assert main(["run", str(_pendulum(tmp_path)), "--out", str(tmp_path / "out"), "--no-plots", "-q",
                 "--moment-arms"]) == 0, capsys.readouterr().err
    ours = read_table(tmp_path / "out" / "moment_arms.csv")
    kin = read_table(tmp_path / "out" / "kinematics.csv")
    q = read_table(tmp_path / "out" / "coordinates.csv")["q_rad"]
    assert [c for c in ours if c != "time"] == ["m.q"]
    r_link = np.column_stack([kin[f"link.{a}_m"] for a in "xyz"])
    R = [rotation_matrix(e) for e in np.column_stack([kin[f"link.e{k}"] for k in range(4)])]
    p = np.array([x + Rk @ np.array([0.0, -0.25, 0.0]) for x, Rk in zip(r_link, R)])
    o = r_link[0] - R[0] @ np.zeros(3)  # the hinge: the link frame's origin, which does not move
    np.testing.assert_allclose(r_link, np.tile(o, (len(q), 1)), atol=1e-12)
    d = p - ANCHOR
    r = -np.einsum("ij,ij->i", np.cross([0.0, 0.0, 1.0], p - o), d) / np.linalg.norm(d, axis=1)
    assert np.ptp(q) > 0.5 and np.ptp(r) > 0.01  # the arm changes along the swing
    np.testing.assert_allclose(ours["m.q"], r, atol=1e-12)
    # the joints name their body frames by the bodies' names: the joint loads are written too
    assert "hinge_on_link_in_ground_fx" in read_table(tmp_path / "out" / "joint_loads.csv")


def test_an_unmeasured_mobility_leaves_the_moment_arms_unknown(tmp_path, capsys):
    path = _pendulum(tmp_path, slider=True)
    assert main(["run", str(path), "--out", str(tmp_path / "out"), "--no-plots", "--moment-arms"]) == 0
    err = capsys.readouterr().err
    assert ("moment arms: at 6 of 6 frames (the first at t = 0.0000 s) the joints and the coordinates do not fix "
            "the bodies' velocities") in err
    assert not (tmp_path / "out" / "moment_arms.csv").exists()
    assert "--moment-arms: the model has no converged frame where a muscle spans a coordinate" in err


def test_moment_arms_of_a_model_without_muscles_say_so(tmp_path, capsys):
    path = _pendulum(tmp_path)
    data = yaml.safe_load(path.read_text())
    del data["muscles"]
    path.write_text(yaml.safe_dump(data))
    assert main(["run", str(path), "--out", str(tmp_path / "out"), "--no-plots", "--moment-arms"]) == 0
    assert "--moment-arms: the model has no muscles: no moment_arms.csv written" in capsys.readouterr().err


def test_a_joint_with_one_rotation_exports_to_a_model_opensim_loads(tmp_path, capsys):
    """A custom joint that names one rotation (about z): the axes the file leaves out are
    completed to independent ones (constant 0: they move nothing), so that the exported
    CustomJoint loads in OpenSim; its coordinate there turns the link as openfdk's does."""
    opensim = __import__("pytest").importorskip("opensim")
    from openfdk.numerics.spatial import rotation_matrix

    assert main(["run", str(_pendulum(tmp_path)), "--out", str(tmp_path / "out"), "--no-plots", "-q"]) == 0
    assert main(["export-opensim", str(tmp_path / "out"), "--out", str(tmp_path / "osim"), "-q"]) == 0
    model = opensim.Model(str(tmp_path / "osim" / "pendulum_yaml.osim"))
    state = model.initSystem()
    kin = read_table(tmp_path / "out" / "kinematics.csv")
    q = read_table(tmp_path / "out" / "coordinates.csv")["q_rad"]
    link = model.getBodySet().get("link")
    for k in (0, len(q) - 1):
        model.getCoordinateSet().get("q").setValue(state, float(q[k]))
        R = link.getTransformInGround(state).R()
        theirs = np.array([[R.get(i, j) for j in range(3)] for i in range(3)])
        ours = rotation_matrix(np.array([kin[f"link.e{i}"][k] for i in range(4)]))
        np.testing.assert_allclose(theirs, ours, atol=1e-9)
    assert abs(q[0] - q[len(q) - 1]) > 0.3
