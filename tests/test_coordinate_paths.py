"""Muscle paths with conditional and moving points written in the model file (in mm and
degrees), against a closed form, a finite difference on the manifold and one-line
errors. OpenSim's own points are tested in test_opensim_muscles.py."""

from __future__ import annotations

import numpy as np
import pytest

from openfdk.io.modelfile import model_from_dict
from openfdk.kinematics.coordinate_pose import pose_from_coordinates
from openfdk.model.model import ModelError
from openfdk.numerics.numdiff import manifold_jacobian


def _model(path_entries, extra_coordinate=None):
    data = {
        "openfdk": 1, "units": {"length": "mm", "angle": "deg"},
        "bodies": {"link": {"mass": 1.0, "inertia": [0.01, 0.01, 0.01],
                            "points": {"c": [50, -200, 0], "m": [0, 0, 0], "e": [0, -400, 10]}},
                   "base": {"mass": 1.0, "inertia": [0.01, 0.01, 0.01], "position": [0, 0, 300]}},
        "coordinates": {"q": {"default": 0.0, "range": [-90, 60]}, "s": {"default": 0.0}},
        "joints": {"hinge": {"type": "custom", "parent": "ground", "child": "link",
                             "rotations": [{"axis": [0, 0, 1], "coordinate": "q"}]},
                   "base_joint": {"type": "custom", "parent": "ground.base_at", "child": "base",
                                  "rotations": [{"axis": [1, 0, 0], "coordinate": "s"}]}},
        "muscles": {"mu": {"path": path_entries, "strength": 100.0}},
    }
    data["bodies"]["ground"] = {"points": {"a": [100, 0, 0], "base_at": [0, 0, 300]}}
    return model_from_dict(data, source="paths.yaml")


PATH = ["ground.a",
        {"point": "link.c", "active": {"coordinate": "q", "range": [0, 30]}},
        {"frame": "link.m", "moving": {"coordinate": "q", "x": {"type": "linear", "slope": 0.5, "intercept": 10},
                                       "y": -300, "z": {"type": "polynomial", "coefficients": [0.01, 0, 0]}}},
        "link.e"]


def _closed_form(q_deg):
    """Length (m) from the file's numbers: rotation about z by q, points in the link."""
    q = np.radians(q_deg)
    R = np.array([[np.cos(q), -np.sin(q), 0], [np.sin(q), np.cos(q), 0], [0, 0, 1]])
    a = np.array([0.1, 0, 0])
    c = R @ np.array([0.05, -0.2, 0])
    # moving point, mm of the angle in degrees (clamped to the coordinate's range)
    qc = min(max(q_deg, -90.0), 60.0)
    m = R @ (1e-3 * np.array([0.5 * qc + 10, -300.0, 0.01 * qc * qc]))
    e = R @ np.array([0, -0.4, 0.01])
    points = [a] + ([c] if -1e-5 <= q <= np.radians(30) + 1e-5 else []) + [m, e]
    return sum(np.linalg.norm(points[k + 1] - points[k]) for k in range(len(points) - 1))


@pytest.mark.parametrize("q_deg", [-40.0, -5.0, 0.0, 12.0, 30.0, 31.0, 55.0, 70.0])  # 70: the moving point clamped
def test_length_and_moment_arm_match_the_closed_form(q_deg):
    model = _model(PATH)
    muscle = model.muscles[0]
    state, _ = pose_from_coordinates(model, {"q": np.radians(q_deg), "s": 0.0})
    l, L, _ = muscle.path.evaluate(state, 1)
    assert float(l[0]) == pytest.approx(_closed_form(q_deg), abs=1e-12)
    # the Jacobian against a central difference on the manifold, and a moment arm that is not zero
    fd = manifold_jacobian(lambda s: muscle.path.evaluate(s, 0)[0], state, 1e-7)
    np.testing.assert_allclose(L, fd, atol=1e-7)
    dq = np.radians(1e-4)
    numeric = (_closed_form(q_deg + 1e-4) - _closed_form(q_deg - 1e-4)) / (2 * dq)
    st, _ = pose_from_coordinates(model, {"q": np.radians(q_deg), "s": 0.0}, qdot={"q": 1.0})
    assert float((L @ st.get_v())[0]) == pytest.approx(numeric, abs=1e-7)
    assert abs(numeric) > 1e-3


def test_bad_points_name_the_entry():
    cases = [
        ({"point": "link.c", "active": {"coordinate": "nope", "range": [0, 1]}}, "muscles.mu.path[1].active.coordinate"),
        ({"point": "link.c", "active": {"coordinate": "q", "range": [5, 1]}}, "muscles.mu.path[1].active.range"),
        ({"frame": "link.m", "moving": {"coordinate": "q", "w": 1}}, "muscles.mu.path[1].moving.w"),
        ({"frame": "link.m", "moving": {"coordinate": "q", "x": {"type": "spline"}}}, "muscles.mu.path[1].moving.x"),
        ({"point": "link.nope", "active": {"coordinate": "q", "range": [0, 1]}}, "link.nope"),
    ]
    for entry, where in cases:
        with pytest.raises(ModelError) as exc:
            _model(["ground.a", entry, "link.e"])
        msg = str(exc.value)
        assert "\n" not in msg and "paths.yaml" in msg and where in msg, msg
    with pytest.raises(ModelError, match="wrapping surface"):
        _model(["ground.a", "cyl", PATH[1], "link.e"])
