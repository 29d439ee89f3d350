"""Angles about any three axes (model/axis_angles.py, Davenport angles): values against
the rotation they compose (written out here), the Jacobian against finite differences on
the manifold, the acceleration bias against the second derivative along a velocity, the
compiled program against the measure, and Cardan angles where the axes are coordinate
axes. OpenSim's joints with such axes: tests/test_opensim_import.py."""

import numpy as np
import pytest

from openfdk.model.axis_angles import AxisAngles
from openfdk.model.builder import ModelBuilder
from openfdk.model.compiled import CompiledMeasures
from openfdk.model.rotation_angles import RotationAngles
from openfdk.numerics.numdiff import manifold_jacobian, second_derivative_along
from openfdk.numerics.spatial import quat_from_rotvec

AXES = [np.array([[1.0, 0.0, 0.0], [0.3, 0.9, -0.2], [0.1, 0.3, 1.0]]),   # all three oblique
        np.array([[0.0, 0.0, 1.0], [0.5, 0.8, 0.0], [-0.2, 1.0, 0.4]]),
        np.array([[1.0, 0.0, 0.0], [0.3, 0.9, -0.2], np.cross([1.0, 0.0, 0.0], [0.3, 0.9, -0.2])])]


def rot(axis, angle):
    """Rotation about ``axis`` (3,) by ``angle`` (Rodrigues), written out here."""
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * K @ K


def _model():
    b = ModelBuilder("axes")
    b.add_body("a", 1.0, [1, 1, 1], position=[0.0, 0.1, 0.0], orientation=quat_from_rotvec([0.2, -0.1, 0.3]))
    b.add_body("b", 1.0, [1, 1, 1], position=[0.0, -0.1, 0.0], orientation=quat_from_rotvec([0.5, 0.3, -0.2]))
    b.add_frame("a", "F", [0, -0.1, 0], orientation=quat_from_rotvec([0.1, 0.0, -0.2]))
    b.add_frame("b", "G", [0, 0.1, 0], orientation=quat_from_rotvec([0.0, 0.3, 0.1]))
    return b.build()


def _measure(model, axes):
    return AxisAngles(model.body("a").index, model.frame("a.F").R_BF, model.body("b").index,
                      model.frame("b.G").R_BF, axes, name="test")


def _pose(model, state, axes, theta):
    """Turn body b so that its frame G is Rot(n1, θ1) Rot(n2, θ2) Rot(n3, θ3) in a's F."""
    N = axes / np.linalg.norm(axes, axis=1)[:, None]
    R_FG = rot(N[0], theta[0]) @ rot(N[1], theta[1]) @ rot(N[2], theta[2])
    R_WF = state.R_WB[1] @ model.frame("a.F").R_BF
    R_WB = R_WF @ R_FG @ model.frame("b.G").R_BF.T
    from openfdk.numerics.spatial import quat_from_matrix

    state.R_WB[2] = R_WB
    state.quat_WB[2] = quat_from_matrix(R_WB)


def _connected_to_zero(axes, theta2):
    """Whether θ2 is reached from 0 without crossing a singularity of the angles: det B =
    det [n1, n2, Rot(n2, s) n3] keeps its sign for s from 0 to θ2 (a grid of 400)."""
    N = axes / np.linalg.norm(axes, axis=1)[:, None]
    d = [np.linalg.det(np.column_stack([N[0], N[1], rot(N[1], s) @ N[2]])) for s in np.linspace(0, theta2, 400)]
    return np.all(np.sign(d) == np.sign(d[0])) and np.min(np.abs(d)) > 1e-3


@pytest.mark.parametrize("k", range(len(AXES)))
def test_the_angles_compose_the_rotation(k):
    """At 200 random rotations: the angles always compose the rotation, and they are the
    angles it was made of wherever those are connected to the identity (past a
    singularity the other root composes it too, as Cardan's θ2 beyond ±90°)."""
    model, rng = _model(), np.random.default_rng(k)
    m = _measure(model, AXES[k])
    N = AXES[k] / np.linalg.norm(AXES[k], axis=1)[:, None]
    same = 0
    for _ in range(200):
        theta = rng.uniform(-2.0, 2.0, 3)
        state = model.initial_state()
        _pose(model, state, AXES[k], theta)
        got = m.evaluate(state, 0)[0]
        R = rot(N[0], theta[0]) @ rot(N[1], theta[1]) @ rot(N[2], theta[2])
        np.testing.assert_allclose(rot(N[0], got[0]) @ rot(N[1], got[1]) @ rot(N[2], got[2]), R, atol=1e-12)
        if _connected_to_zero(AXES[k], theta[1]):
            np.testing.assert_allclose(got, theta, atol=1e-12)
            same += 1
    assert same > 60


@pytest.mark.parametrize("k", range(len(AXES)))
def test_jacobian_and_bias_against_finite_differences(k):
    model = _model()
    m = _measure(model, AXES[k])
    state = model.initial_state()
    _pose(model, state, AXES[k], [0.4, -0.6, 0.3])
    _, M, _ = m.evaluate(state, 1)
    fd = manifold_jacobian(lambda s: m.evaluate(s, 0)[0], state, 1e-6)
    np.testing.assert_allclose(M, fd, atol=1e-8)
    assert np.linalg.norm(M) > 1.0
    v = np.random.default_rng(5 + k).normal(size=model.n_coords)
    state.set_v(v)
    _, _, b = m.evaluate(state, 2)
    expected = second_derivative_along(lambda s: m.evaluate(s, 0)[0], state, v, h=1e-4)
    assert np.abs(b).max() > 0.1
    np.testing.assert_allclose(b, expected, rtol=1e-5, atol=1e-6)
    # the compiled program gives the same value, Jacobian and bias
    value, Mc, bc = CompiledMeasures([m]).evaluate(state, 2)
    np.testing.assert_allclose(value, m.evaluate(state, 0)[0], atol=1e-15)
    np.testing.assert_allclose(Mc, M, atol=1e-14)
    np.testing.assert_allclose(bc, b, atol=1e-12)


def test_coordinate_axes_give_cardan_angles():
    """About x, y, z the angles are the x-y-z Cardan angles of rotation_angles.py."""
    model = _model()
    m = _measure(model, np.eye(3))
    cardan = RotationAngles(model.body("a").index, model.frame("a.F").R_BF, model.body("b").index,
                            model.frame("b.G").R_BF, "xyz")
    state = model.initial_state()
    state.set_v(np.random.default_rng(9).normal(size=model.n_coords))
    for a, c in zip(m.evaluate(state, 2), cardan.evaluate(state, 2)):
        np.testing.assert_allclose(a, c, atol=1e-12)


def test_axes_that_do_not_span_space_and_gimbal_lock_are_reported():
    model = _model()
    with pytest.raises(ValueError, match="do not span space"):
        _measure(model, [[1, 0, 0], [0.3, 0.9, 0], [1, 0, 0]])
    m = _measure(model, AXES[2])  # n3 = n1 × n2: Rot(n2, 90°) n3 lies in the plane of n1, n2
    state = model.initial_state()
    _pose(model, state, AXES[2], [0.2, np.pi / 2, 0.1])
    with pytest.raises(FloatingPointError, match="gimbal lock"):
        m.evaluate(state, 1)
