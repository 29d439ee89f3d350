"""Model files: the YAML slider-crank equals the builder one; bad input is reported
with the file and the entry that is wrong."""

import textwrap

import numpy as np
import pytest

from models import slider_crank, slider_crank_closed_form
from openfdk.kinematics.analysis import run_determinate
from openfdk.kinematics.system import KinematicsError
from openfdk.model.model import ModelError
from openfdk.io.modelfile import load_model, model_from_dict

EXAMPLE = "examples/slider_crank.yaml"


def test_yaml_slider_crank_matches_closed_form_and_builder(request):
    path = request.config.rootpath / EXAMPLE
    model = load_model(path)
    times = np.linspace(0, 1, 51)
    res = run_determinate(model, times)
    x, xd, xdd, _ = slider_crank_closed_form(times)
    col = model.body("slider").column
    np.testing.assert_allclose(res.v[:, col], xd, atol=1e-9)
    np.testing.assert_allclose(res.vdot[:, col], xdd, atol=1e-9)
    ref = run_determinate(slider_crank(), times)
    np.testing.assert_allclose(res.q, ref.q, atol=1e-12)


def write(tmp_path, text, name="model.yaml"):
    p = tmp_path / name
    p.write_text(textwrap.dedent(text))
    return p


BASE = """
openfdk: 1
units: {length: mm, angle: deg}
bodies:
  arm:
    mass: 1.0
    inertia: [0.01, 0.01, 0.01]
    position: [0, 0, -100]
    frames:
      pivot: [0, 0, 100]
joints:
  hinge: {type: revolute, parent: ground.origin, child: arm.pivot}
measures:
  arm_angles: {type: angles, frame: ground.origin, of: arm.origin}
drivers:
  swing:
    measure: arm_angles
    components: [2]
    function: {type: fourier, frequency: 1.0, a: [0, 30], b: [0]}
"""


def test_units_are_converted_at_the_boundary(tmp_path):
    model = load_model(write(tmp_path, BASE))
    assert model.body("arm").p_WB0[2] == pytest.approx(-0.1)
    res = run_determinate(model, np.array([0.0, 0.25]))
    # θ(0) = 30° about z -> the arm hangs, spinning about the vertical axis
    q = res.q[0, 3:7]
    assert 2 * np.degrees(np.arctan2(q[3], q[0])) == pytest.approx(30.0, abs=1e-8)
    # θ̇(0.25) = −2π·30° ... velocity of a Fourier driver: a1 cos -> −a1 ω sin(ω t)
    assert res.v[1, 5] == pytest.approx(-np.radians(30) * 2 * np.pi, rel=1e-9)


@pytest.mark.parametrize(
    "bad, expected",
    [
        ("bodies: {arm: {mass: 1.0, inertia: [1, 1, 1], positon: [0, 0, 0]}}", "bodies.arm.positon: unknown key; did you mean 'position'"),
        ("units: {length: mmm}\nbodies: {arm: {mass: 1, inertia: [1, 1, 1]}}", "units.length: unknown length unit 'mmm'"),
        ("units: {angle: degree}\nbodies: {arm: {mass: 1, inertia: [1, 1, 1]}}", "units.angle: unknown angle unit 'degree'"),
        ("bodies: {arm: {mass: -1, inertia: [1, 1, 1]}}", "bodies.arm.mass: must be >= 0"),
        ("bodies: {arm: {inertia: [1, 1, 1]}}", "bodies.arm: missing required key 'mass'"),
        ("bodies: {arm: {mass: 1, inertia: [1, 1]}}", "bodies.arm"),
        ("bodies: {arm: {mass: one, inertia: [1, 1, 1]}}", "bodies.arm.mass: expected a number"),
        ("bodies: {arm: {mass: 1, inertia: [1, 1, 1]}}\njoints: {j: {type: hinge, parent: ground.origin, child: arm.origin}}", "joints.j: joint 'j': unknown type 'hinge'"),
        ("bodies: {arm: {mass: 1, inertia: [1, 1, 1]}}\njoints: {j: {type: spherical, parent: ground.origin, child: leg.origin}}", "unknown frame/point 'leg.origin'"),
        ("bodies: {arm: {mass: 1, inertia: [1, 1, 1]}}\nmeasures: {m: {type: distance, from: ground.origin, to: arm.tip}}", "measures.m: unknown frame/point 'arm.tip'"),
        ("bodies: {arm: {mass: 1, inertia: [1, 1, 1]}}\ndrivers: {d: {measure: nothing, function: {type: constant, value: 0}}}", "drivers.d.measure: unknown measure 'nothing'"),
        ("bodies: {arm: {mass: 1, inertia: [1, 1, 1]}}\nmeasures: {a: {type: angles, frame: ground.origin, of: arm.origin}}\ndrivers: {d: {measure: a, components: [5], function: {type: constant, value: 0}}}", "drivers.d.components: indices [5] out of range"),
        ("bodies: {arm: {mass: 1, inertia: [1, 1, 1]}}\nmeasures: {a: {type: angles, frame: ground.origin, of: arm.origin}}\ndrivers: {d: {measure: a, function: {type: polynom, coefficients: [0]}}}", "drivers.d.function.type: unknown function type 'polynom'"),
        ("bodies: {arm: {mass: 1, inertia: [1, 1, 1], markers: {M1: [0, 0]}}}", "bodies.arm.markers.M1: expected 3 numbers"),
        ("bodies: {arm: {mass: 1, inertia: [1, 1, 1]}}\nspring: {}", "(top level).spring: unknown key; did you mean 'springs'"),
        ("openfdk: 7\nbodies: {arm: {mass: 1, inertia: [1, 1, 1]}}", "openfdk: unsupported format version 7"),
        ("bodies: {arm: {mass: 1, inertia: [1, 1, 1]}}\nfdk: {restart: sometimes}", "fdk.restart: expected true or false, got 'sometimes'"),
    ],
)
def test_bad_entries_are_named(tmp_path, bad, expected):
    with pytest.raises(ModelError) as err:
        load_model(write(tmp_path, bad))
    assert "model.yaml" in str(err.value)
    assert expected in str(err.value)


def test_malformed_yaml_reports_line(tmp_path):
    p = write(tmp_path, "bodies:\n  arm: {mass: 1, inertia: [1, 1, 1]\n  leg: 3\n")
    with pytest.raises(ModelError, match=r"model.yaml: malformed YAML at line \d+"):
        load_model(p)


def test_missing_file():
    with pytest.raises(ModelError, match="does not exist"):
        load_model("no/such/model.yaml")


def test_yaml_is_data_not_code(tmp_path):
    p = write(tmp_path, "bodies: !!python/object/apply:os.system ['echo hacked']\n")
    with pytest.raises(ModelError, match="malformed YAML"):
        load_model(p)


def _arm(constraints, joints):
    return {
        "bodies": {"arm": {"mass": 1, "inertia": [1, 1, 1], "position": [0, 0, 0.5], "frames": {"p": [0, 0, 0.5]}}},
        "joints": joints,
        "measures": {"tip": {"type": "point", "point": "arm.p"}, "d": {"type": "vector", "from": "ground.origin", "to": "arm.origin"}},
        "constraints": constraints,
    }


def test_too_few_constraints_for_determinate_kinematics():
    model = model_from_dict(_arm({}, {"ball": {"type": "spherical", "parent": "ground.origin", "child": "arm.origin"}}), "few.yaml")
    with pytest.raises(KinematicsError, match=r"needs 6 constraint rows .* has 3 \(too few\)"):
        run_determinate(model, np.array([0.0]))


def test_redundant_constraints_are_reported_with_rows():
    """A spherical joint and a point constraint on the same point: 6 rows, rank 3."""
    data = _arm({"again": {"measure": "tip", "components": [0, 1, 2], "value": [0, 0, 1.0]}},
                {"ball": {"type": "spherical", "parent": "ground.origin", "child": "arm.p"}})
    data["bodies"]["ground"] = {"frames": {"top": [0, 0, 1.0]}}
    data["joints"]["ball"]["parent"] = "ground.top"
    res = run_determinate(model_from_dict(data, "redundant.yaml"), np.array([0.0]))
    assert not res.converged[0]
    msg = res.messages[0]
    assert "singular (rank 3 of 6 rows)" in msg
    for row in ("ball.x", "ball.z", "again[0]", "again[2]", "arm.rx", "arm.rz"):
        assert row in msg


def test_inconsistent_constraints_are_reported():
    """A prismatic joint along z fixes x = 0; a second constraint asks x = 0.5."""
    joints = {"slide": {"type": "prismatic", "parent": "ground.origin", "child": "arm.origin"}}
    ok = _arm({"z": {"measure": "d", "components": [2], "value": 0.7}}, joints)
    res = run_determinate(model_from_dict(ok, "ok.yaml"), np.array([0.0]))
    assert res.converged.all() and res.q[0, 2] == pytest.approx(0.7, abs=1e-12)
    bad = _arm({"x": {"measure": "d", "components": [0], "value": 0.5}}, joints)
    res = run_determinate(model_from_dict(bad, "bad.yaml"), np.array([0.0]))
    assert not res.converged[0]
    assert "slide.x" in res.messages[0] and "'x'" in res.messages[0] and "arm.z" in res.messages[0]


def test_a_gcv_spline_driver_reproduces_a_quintic_through_its_samples(tmp_path):
    """The natural quintic through samples of a parabola is the parabola (its 3rd and 4th
    derivatives vanish at the ends, as the natural spline's must): the driver's angle,
    rate and acceleration equal the closed form, the samples given in degrees."""
    times = np.linspace(0.0, 1.0, 11)
    # p(t) = 10 + 20 t − 15 t² (degrees): p‴ = p⁗ = 0 everywhere
    values = 10 + 20 * times - 15 * times ** 2
    text = BASE.replace("{type: fourier, frequency: 1.0, a: [0, 30], b: [0]}",
                        f"{{type: gcv_spline, degree: 5, times: {times.tolist()}, values: {values.tolist()}}}")
    model = load_model(write(tmp_path, text))
    t = np.array([0.0, 0.37, 1.0])
    res = run_determinate(model, t)
    angle = 2 * np.degrees(np.arctan2(res.q[:, 6], res.q[:, 3]))
    np.testing.assert_allclose(angle, 10 + 20 * t - 15 * t ** 2, atol=1e-9)
    np.testing.assert_allclose(res.v[:, 5], np.radians(20 - 30 * t), atol=1e-9)
    np.testing.assert_allclose(res.vdot[:, 5], np.radians(-30.0), atol=1e-8)
    bad = BASE.replace("{type: fourier, frequency: 1.0, a: [0, 30], b: [0]}",
                       "{type: gcv_spline, degree: 4, times: [0, 1, 2, 3, 4, 5], values: [0, 1, 2, 3, 4, 5]}")
    with pytest.raises(ModelError, match=r"drivers.swing.function.degree: expected 1, 3 or 5, got 4"):
        load_model(write(tmp_path, bad, "bad.yaml"))


def test_coordinates_that_follow_each_other_through_couplers_are_refused_by_name(tmp_path):
    """Two joints moved only through splines, each coordinate the other's coupler's
    dependent: neither can be placed; the error names the coupler and the joint."""
    text = """
    openfdk: 1
    bodies:
      a: {mass: 1, inertia: [1, 1, 1]}
      b: {mass: 1, inertia: [1, 1, 1]}
    coordinates: {qa: {}, qb: {}}
    joints:
      ja: {type: custom, parent: ground.origin, child: a.origin,
           rotations: [{axis: [0, 0, 1], coordinate: qa, function: {type: simm_spline, x: [0, 1, 2], y: [0, 1, 4]}}]}
      jb: {type: custom, parent: a.origin, child: b.origin,
           rotations: [{axis: [0, 0, 1], coordinate: qb, function: {type: simm_spline, x: [0, 1, 2], y: [0, 1, 4]}}]}
    couplers:
      c1: {independent: qb, dependent: qa, function: {type: linear, slope: 1, intercept: 0}}
      c2: {independent: qa, dependent: qb, function: {type: linear, slope: 1, intercept: 0}}
    """
    with pytest.raises(ModelError, match=r"model.yaml: couplers.c1.independent: coordinate 'qb' is moved by no joint, "
                                         r"so 'qa' \(joint 'ja'\) cannot follow it"):
        load_model(write(tmp_path, text))
