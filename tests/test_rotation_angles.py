"""Euler/Cardan angles in every sequence and Grood–Suntay JCS angles: values against
hand-built rotations, Jacobian against finite differences on the manifold, acceleration
bias against the second derivative along a velocity."""

import itertools

import numpy as np
import pytest

from openfdk.model.builder import ModelBuilder
from openfdk.model.model import ModelError
from openfdk.numerics.numdiff import manifold_jacobian, second_derivative_along
from openfdk.numerics.spatial import quat_from_rotvec, rotation_matrix

SEQUENCES = [a + b + c for a, b, c in itertools.product("xyz", repeat=3) if a != b and b != c]


def rot(axis, angle):
    """Rotation about a unit axis (3,) by ``angle`` (Rodrigues), written out here."""
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * K @ K


def _two_bodies(sequence=None, jcs=None, side="right"):
    b = ModelBuilder("angles")
    b.add_body("femur", 1.0, [1, 1, 1], position=[0.0, 0.1, 0.0], orientation=quat_from_rotvec([0.2, -0.1, 0.3]))
    b.add_body("tibia", 1.0, [1, 1, 1], position=[0.0, -0.1, 0.0], orientation=quat_from_rotvec([0.5, 0.3, -0.2]))
    b.add_frame("femur", "F", [0, -0.1, 0], orientation=quat_from_rotvec([0.1, 0.0, -0.2]))
    b.add_frame("tibia", "T", [0, 0.1, 0], orientation=quat_from_rotvec([0.0, 0.3, 0.1]))
    if jcs:
        m = b.add_measure("a", b.jcs_angles("femur.F", "tibia.T", jcs, side))
    else:
        m = b.add_measure("a", b.angles("femur.F", "tibia.T", sequence=sequence))
    model = b.build()
    return model, m


def _relative(model, state):
    R_WF = state.R_WB[1] @ model.frame("femur.F").R_BF
    R_WT = state.R_WB[2] @ model.frame("tibia.T").R_BF
    return R_WF, R_WT


@pytest.mark.parametrize("sequence", SEQUENCES)
def test_angles_reproduce_the_rotation_for_every_sequence(sequence):
    model, m = _two_bodies(sequence)
    state = model.initial_state()
    R_WF, R_WT = _relative(model, state)
    theta = m.evaluate(state, 0)[0]
    e = np.eye(3)
    R = rot(e["xyz".index(sequence[0])], theta[0]) @ rot(e["xyz".index(sequence[1])], theta[1]) @ rot(
        e["xyz".index(sequence[2])], theta[2])
    np.testing.assert_allclose(R, R_WF.T @ R_WT, atol=1e-14)


@pytest.mark.parametrize("sequence", ["zxy", "yxy", "zxz", "xzy"])
def test_angle_jacobian_and_bias_against_finite_differences(sequence):
    model, m = _two_bodies(sequence)
    state = model.initial_state()
    _, M, _ = m.evaluate(state, 1)
    fd = manifold_jacobian(lambda s: m.evaluate(s, 0)[0], state, 1e-6)
    np.testing.assert_allclose(M, fd, atol=1e-8)
    assert np.linalg.norm(M) > 1.0
    v = np.random.default_rng(2).normal(size=model.n_coords)
    state.set_v(v)
    _, _, b = m.evaluate(state, 2)
    expected = second_derivative_along(lambda s: m.evaluate(s, 0)[0], state, v, h=1e-4)
    assert np.abs(b).max() > 0.1
    np.testing.assert_allclose(b, expected, rtol=1e-5, atol=1e-6)


def test_knee_jcs_against_hand_built_flexion_adduction_rotation():
    """Tibia frame from the femur frame by Grood & Suntay's three rotations, about axes
    written in the world: flexion α about the femur's z (e1, lateral; flexion moves the
    tibia's distal end posterior, i.e. −α about +z), adduction β about the floating axis
    (the femur x after flexion, e2), internal rotation γ about the tibia's long axis y
    (e3)."""
    alpha, beta, gamma = np.radians([60.0, 8.0, -15.0])
    b = ModelBuilder("knee")
    R_WF = rotation_matrix(quat_from_rotvec([0.3, -0.2, 0.4]))
    b.add_body("femur", 1.0, [1, 1, 1], orientation=R_WF)
    R1 = rot(R_WF[:, 2], -alpha) @ R_WF  # after flexion about e1
    R2 = rot(R1[:, 0], beta) @ R1  # adduction about the floating axis e2
    R_WT = rot(R2[:, 1], gamma) @ R2  # rotation about the tibia's long axis e3
    b.add_body("tibia", 1.0, [1, 1, 1], position=[0, -0.4, 0], orientation=R_WT)
    right = b.jcs_angles("femur.origin", "tibia.origin", "knee", "right")
    left = b.jcs_angles("femur.origin", "tibia.origin", "knee", "left")
    model = b.build()
    state = model.initial_state()
    np.testing.assert_allclose(right.evaluate(state, 0)[0], [alpha, beta, gamma], atol=1e-14)
    np.testing.assert_allclose(left.evaluate(state, 0)[0], [alpha, -beta, -gamma], atol=1e-14)
    # Grood & Suntay's geometric definitions: e2 = e3 × e1 / |e3 × e1|
    e1, e3 = R_WF[:, 2], R_WT[:, 1]
    e2 = np.cross(e3, e1) / np.linalg.norm(np.cross(e3, e1))
    assert np.arcsin(e1 @ e3) == pytest.approx(beta, abs=1e-14)
    assert np.arctan2(np.cross(R_WF[:, 0], e2) @ e1, R_WF[:, 0] @ e2) == pytest.approx(-alpha, abs=1e-14)
    # flexion moves the tibia's distal end (−y) posterior (−x of the femur)
    assert (R_WF.T @ R_WT @ [0, -1, 0])[0] < -0.5
    _, M, _ = right.evaluate(state, 1)
    np.testing.assert_allclose(M, manifold_jacobian(lambda s: right.evaluate(s, 0)[0], state), atol=1e-8)


def test_shoulder_jcs_is_y_x_y():
    model, m = _two_bodies(jcs="shoulder")
    state = model.initial_state()
    R_WF, R_WT = _relative(model, state)
    t = m.evaluate(state, 0)[0]
    np.testing.assert_allclose(rot([0, 1, 0], t[0]) @ rot([1, 0, 0], t[1]) @ rot([0, 1, 0], t[2]), R_WF.T @ R_WT, atol=1e-14)


def test_gimbal_lock_and_bad_sequence_are_reported():
    b = ModelBuilder("lock")
    b.add_body("a", 1.0, [1, 1, 1], orientation=rot([0, 1, 0], np.pi / 2))
    m = b.angles("ground.origin", "a.origin", sequence="zyx")
    model = b.build()
    with pytest.raises(FloatingPointError, match="gimbal lock"):
        m.evaluate(model.initial_state(), 1)
    with pytest.raises(ModelError, match="neighbouring axes"):
        b.angles("ground.origin", "a.origin", sequence="xxy")


def test_model_file_jcs_and_sequence(tmp_path):
    from openfdk.io.modelfile import load_model

    f = tmp_path / "m.yaml"
    f.write_text("""
units: {length: m, angle: deg}
bodies:
  tibia: {mass: 1, inertia: [1, 1, 1], orientation: [20, 0, 0]}
measures:
  knee_jcs: {type: jcs, frame: ground.origin, of: tibia.origin, joint: knee, side: left}
  zyx: {type: angles, frame: ground.origin, of: tibia.origin, sequence: zyx}
""")
    model = load_model(str(f))
    state = model.initial_state()
    # a rotation of 20° about x: zxy gives adduction 20°, negated on the left
    np.testing.assert_allclose(model.measures["knee_jcs"].evaluate(state, 0)[0], [0, -np.radians(20), 0], atol=1e-14)
    np.testing.assert_allclose(model.measures["zyx"].evaluate(state, 0)[0], [0, 0, np.radians(20)], atol=1e-14)
