"""Every measure's Jacobian and acceleration bias against finite differences on the
manifold (q ⊕ ε e_k), asserting the derivatives are non-zero."""

import numpy as np
import pytest

from openfdk.model.builder import ModelBuilder
from openfdk.numerics.numdiff import manifold_jacobian, second_derivative_along
from openfdk.numerics.spatial import quat_from_rotvec


def _model_and_state(seed=0):
    rng = np.random.default_rng(seed)
    b = ModelBuilder("fd")
    for name in ("a", "b"):
        b.add_body(name, 1.0, [1, 2, 3], position=rng.normal(size=3) * 0.1,
                   orientation=quat_from_rotvec(rng.normal(size=3) * 0.4))
        b.add_frame(name, "p", rng.normal(size=3) * 0.05,
                    orientation=quat_from_rotvec(rng.normal(size=3) * 0.3))
        b.add_frame(name, "q", rng.normal(size=3) * 0.05)
        b.add_marker(f"m_{name}", name, rng.normal(size=3) * 0.05)
        b.add_marker(f"n_{name}", name, rng.normal(size=3) * 0.05)
    b.add_frame("ground", "g", [0.02, -0.01, 0.03], orientation=quat_from_rotvec([0.1, 0.2, -0.1]))
    measures = {
        "point": b.point("a.p"),
        "vector_world": b.vector("a.p", "b.q"),
        "vector_in_a": b.vector("a.p", "b.q", expressed_in="a"),
        "vector_in_b_ground_point": b.vector("ground.g", "a.q", expressed_in="b"),
        "distance": b.distance("a.q", "b.p"),
        "axis_dot": b.axis_dot("a.p", np.array([0, 0, 1.0]), "b.p", np.array([0.6, 0.8, 0])),
        "angles": b.angles("a.p", "b.p"),
        "angles_ground": b.angles("ground.g", "b.p"),
        "plane_distance": b.plane_distance("a.p", "b.q"),
    }
    # a linear combination of heterogeneous measures
    from openfdk.model.measures import Linear

    measures["linear"] = Linear(
        [(np.array([[1.0, -2.0, 0.5]]), measures["vector_in_a"]), (np.array([[3.0]]), measures["distance"])]
    )
    model = b.build()
    state = model.initial_state()
    state.set_v(rng.normal(size=model.n_coords))
    return model, state, measures


ALL = ["point", "vector_world", "vector_in_a", "vector_in_b_ground_point", "distance",
       "axis_dot", "angles", "angles_ground", "plane_distance", "linear"]


@pytest.mark.parametrize("name", ALL)
def test_jacobian_matches_manifold_finite_differences(name):
    model, state, measures = _model_and_state()
    m = measures[name]
    _, M, _ = m.evaluate(state, 1)
    M_fd = manifold_jacobian(lambda s: m.evaluate(s, 0)[0], state, eps=1e-6)
    assert np.max(np.abs(M)) > 1e-3, "Jacobian must not vanish"
    np.testing.assert_allclose(M, M_fd, atol=1e-8, rtol=1e-6)


@pytest.mark.parametrize("name", ALL)
def test_acceleration_bias_matches_second_difference(name):
    """Along q(s) = q ⊕ s v (v̇ = 0), m̈ = M v̇ + b = b."""
    model, state, measures = _model_and_state(seed=3)
    m = measures[name]
    _, _, b = m.evaluate(state, 2)
    v = state.get_v()
    b_fd = second_derivative_along(lambda s: m.evaluate(s, 0)[0], state, v, h=1e-4)
    assert np.max(np.abs(b)) > 1e-4, "bias must not vanish for a non-zero velocity"
    np.testing.assert_allclose(b, b_fd, atol=1e-6, rtol=1e-5)


def test_velocity_equals_jacobian_times_v():
    """ṁ = M v: the first derivative along q ⊕ s v equals M v."""
    model, state, measures = _model_and_state(seed=5)
    v = state.get_v()
    for name in ALL:
        m = measures[name]
        _, M, _ = m.evaluate(state, 1)
        base = state.copy()
        h = 1e-6
        state.displace(h * v)
        fp = m.evaluate(state, 0)[0]
        state = base.copy()
        state.displace(-h * v)
        fm = m.evaluate(state, 0)[0]
        state = base
        np.testing.assert_allclose(M @ v, (fp - fm) / (2 * h), atol=1e-7, err_msg=name)


def test_marker_set_matches_point_measures():
    model, state, _ = _model_and_state(seed=2)
    from openfdk.model.measures import PointPosition

    ms = model.markers
    val, M, b = ms.evaluate(state, 2)
    for k in range(ms.size):
        pv, pM, pb = PointPosition(ms.body[k], ms.p_BM[k]).evaluate(state, 2)
        np.testing.assert_allclose(val[3 * k : 3 * k + 3], pv, atol=1e-15)
        np.testing.assert_allclose(M[3 * k : 3 * k + 3], pM, atol=1e-15)
        np.testing.assert_allclose(b[3 * k : 3 * k + 3], pb, atol=1e-15)
    M_fd = manifold_jacobian(lambda s: ms.evaluate(s, 0)[0], state)
    np.testing.assert_allclose(M, M_fd, atol=1e-8)


def _add_two_bodies_with_frame_j(b, rng):
    """Bodies a and b at random poses, each with a randomly placed and turned frame 'j'."""
    for name in ("a", "b"):
        b.add_body(name, 1.0, [1, 1, 1], position=rng.normal(size=3) * 0.1,
                   orientation=quat_from_rotvec(rng.normal(size=3) * 0.3))
        b.add_frame(name, "j", rng.normal(size=3) * 0.05, orientation=quat_from_rotvec(rng.normal(size=3) * 0.3))


def test_joint_constraint_rows_fd():
    """Each joint type's rows (built from measures) differentiate correctly."""
    rng = np.random.default_rng(7)
    b = ModelBuilder("joints")
    _add_two_bodies_with_frame_j(b, rng)
    for k, jt in enumerate(["weld", "spherical", "revolute", "prismatic", "point_on_plane"]):
        b.add_joint(f"j{k}", jt, parent="a.j", child="b.j")
    model = b.build()
    state = model.initial_state()
    state.set_v(rng.normal(size=model.n_coords))
    for c in model.constraints:
        _, M, bias = c.measure.evaluate(state, 2)
        M_fd = manifold_jacobian(lambda s: c.measure.evaluate(s, 0)[0], state)
        np.testing.assert_allclose(M, M_fd, atol=1e-8, err_msg=c.name)
        b_fd = second_derivative_along(lambda s: c.measure.evaluate(s, 0)[0], state, state.get_v())
        np.testing.assert_allclose(bias, b_fd, atol=1e-5, err_msg=c.name)
        assert np.linalg.matrix_rank(M) == c.size, f"{c.name}: rows must be independent"


def test_constraint_system_batched_equals_measure_by_measure():
    """A point-on-plane joint and two FDK DOFs along relative-vector projections: the
    system's batched evaluation equals the measure-by-measure one (Φ, Φ_q̂, ν, γ)."""
    from openfdk.kinematics.system import ConstraintSystem

    rng = np.random.default_rng(5)
    b = ModelBuilder("batched")
    _add_two_bodies_with_frame_j(b, rng)
    b.add_joint("slide", "point_on_plane", parent="a.j", child="b.j")
    b.add_joint("hold", "spherical", parent="ground", child="a.j")
    gap = b.vector("a.j", "b.j", expressed_in="a")
    b.add_fdk_dof("normal", gap, component=2)
    b.add_fdk_dof("side", gap, component=0)
    model = b.build()
    state = model.initial_state()
    state.set_v(rng.normal(size=model.n_coords))
    system = ConstraintSystem(model)
    alpha = np.array([0.01, -0.02])
    for x, y in zip(system.evaluate(state, 0.3, alpha, order=2), system.evaluate_reference(state, 0.3, alpha, order=2)):
        np.testing.assert_allclose(x, y, rtol=0, atol=1e-14)
