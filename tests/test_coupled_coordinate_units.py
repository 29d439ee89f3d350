"""OpenSim's ``.mot`` files in degrees (``inDegrees=yes``) hold only its rotational
coordinates in degrees: a coupled coordinate (a CustomJoint coordinate that moves no axis
through a LinearFunction of slope ±1, e.g. the left knee of jam-resources'
full_body_healthy_knee.osim, rotation1 = SimmSpline(−x)) is in rad there, as OpenSim's IK
writes it. ``--motion`` and an IK task file's coordinate values read such a column as
it is; a rotational one is converted. (OpenSim's side: tests/test_opensim_import.py,
the motion types and coordinates.mot read back by OpenSim.)"""

import numpy as np

from openfdk.io.opensim.document import OsimAxis, opensim_motion_type
from openfdk.io.opensim.motion import SUFFIX, motion_drivers
from openfdk.io.storage import write_storage


def _axis(name, coordinate, function):
    return OsimAxis(name, np.array([0.0, 0.0, 1.0]), (coordinate,) if coordinate else (), function)


LINE = {"type": "linear", "slope": 1.0, "intercept": 0.0}
SPLINE = {"type": "simm_spline", "x": [-6.28319, 6.28319], "y": [6.28319, -6.28319]}
CONST = {"type": "constant", "value": 0.0}


def test_opensims_motion_type_rule():
    rot = [_axis("rotation1", "q", SPLINE), _axis("rotation2", None, CONST), _axis("rotation3", None, CONST)]
    tra = [_axis(f"translation{k}", None, CONST) for k in (1, 2, 3)]
    assert opensim_motion_type(rot, tra, "q") == "coupled"  # a spline, even one through a line
    rot[0] = _axis("rotation1", "q", {"type": "linear", "slope": -1.0, "intercept": 0.2})
    assert opensim_motion_type(rot, tra, "q") == "rotational"  # slope ±1, any intercept
    rot[0] = _axis("rotation1", "q", {"type": "linear", "slope": -2.0, "intercept": 0.0})
    assert opensim_motion_type(rot, tra, "q") == "coupled"
    # a pure axis after a coupled one makes it pure; a spline after a pure one does not undo it
    tra[0] = _axis("translation1", "q", LINE)
    assert opensim_motion_type(rot, tra, "q") == "translational"
    rot[0], tra[0] = _axis("rotation1", "q", LINE), _axis("translation1", "q", SPLINE)
    assert opensim_motion_type(rot, tra, "q") == "rotational"


def test_motion_file_columns_follow_opensims_motion_type(tmp_path):
    t = np.linspace(0.0, 0.1, 11)
    deg = 20.0 + 5.0 * t
    rad = 0.3 + 0.1 * t
    path = write_storage(tmp_path / "ik.mot", t, {"hip": deg, "knee_l": rad}, name="ik", in_degrees=True)
    data = {"coordinates": {"hip": {"motion": "rotational"},
                            "knee_l": {"motion": "rotational", "opensim_motion": "coupled"}}}
    drivers = motion_drivers(path, data)["drivers"]
    np.testing.assert_allclose(drivers[f"hip{SUFFIX}"]["function"]["values"], np.radians(deg), rtol=1e-15)
    np.testing.assert_allclose(drivers[f"knee_l{SUFFIX}"]["function"]["values"], rad, rtol=1e-15)


def test_generalized_force_columns_are_named_as_opensims_inverse_dynamics_names_them():
    """OpenSim's InverseDynamicsTool: ``_moment`` for rotational coordinates, ``_force``
    for all others — a coupled knee angle's too (OpenSim 4.6's own rule for its output,
    bench/full_body_id.py)."""
    from openfdk.io.generalized_forces import column_name
    from openfdk.model.coordinate_joint import Coordinate

    def coordinate(motion, unit, opensim_motion=""):
        return Coordinate("q", "j", motion, unit, None, opensim_motion=opensim_motion)

    assert column_name(coordinate("rotational", "angle")) == "q_moment"
    assert column_name(coordinate("translational", "length")) == "q_force"
    assert column_name(coordinate("rotational", "angle", "coupled")) == "q_force"
    assert column_name(coordinate("translational", "length", "coupled")) == "q_force"
