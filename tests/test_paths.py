"""Muscle/ligament paths through via points: length against the path geometry,
lengthening speed against finite differences in time, and generalised forces."""

import numpy as np
import pytest

from openfdk.forces.elements import add_muscle
from openfdk.forces.hill import ConstantStrengthMuscle
from openfdk.model.builder import ModelBuilder
from openfdk.numerics.numdiff import manifold_jacobian
from openfdk.numerics.spatial import quat_from_rotvec, rotation_matrix


def _three_body_path():
    rng = np.random.default_rng(4)
    b = ModelBuilder("path")
    pts = {}
    for name in ("a", "b", "c"):
        b.add_body(name, 1.0, [1, 1, 1], position=rng.normal(size=3) * 0.1,
                   orientation=quat_from_rotvec(rng.normal(size=3) * 0.5))
        p = rng.normal(size=3) * 0.05
        b.add_frame(name, "p", p)
        pts[name] = p
    b.add_frame("ground", "o", [0.2, 0.1, -0.1])
    add_muscle(b, "m", ["ground.o", "a.p", "b.p", "c.p"], ConstantStrengthMuscle(100.0, "m"))
    model = b.build()
    return model, pts


def _world_points(model, state, pts):
    out = [np.array([0.2, 0.1, -0.1])]
    for name in ("a", "b", "c"):
        i = model.body(name).index
        out.append(state.p_WB[i] + rotation_matrix(state.quat_WB[i]) @ pts[name])
    return out


def test_path_length_equals_sum_of_segments():
    model, pts = _three_body_path()
    state = model.initial_state()
    path = model.muscles[0].path
    P = _world_points(model, state, pts)
    expected = sum(np.linalg.norm(P[k + 1] - P[k]) for k in range(3))
    assert path.evaluate(state, 0)[0][0] == pytest.approx(expected, rel=1e-14)


def test_lengthening_speed_is_time_derivative_of_length():
    """Move all bodies along q(s) = q0 ⊕ s v: dl/ds by central differences = L v."""
    model, pts = _three_body_path()
    state = model.initial_state()
    v = np.random.default_rng(1).normal(size=model.n_coords)
    path = model.muscles[0].path
    _, L, _ = path.evaluate(state, 1)
    h = 1e-6
    sp, sm = state.copy(), state.copy()
    sp.displace(h * v)
    sm.displace(-h * v)
    dl = (path.evaluate(sp, 0)[0][0] - path.evaluate(sm, 0)[0][0]) / (2 * h)
    assert abs(L[0] @ v) > 1e-3
    assert L[0] @ v == pytest.approx(dl, rel=1e-7)
    np.testing.assert_allclose(L, manifold_jacobian(lambda s: path.evaluate(s, 0)[0], state), atol=1e-9)


def test_tension_generalized_force_is_virtual_work():
    """Q = −Lᵀ T: the virtual work of the tension over δq̂ equals −T δl; and on each body
    the force is T times the unit vectors toward the neighbouring path points."""
    model, pts = _three_body_path()
    state = model.initial_state()
    path = model.muscles[0].path
    _, L, _ = path.evaluate(state, 1)
    T = 50.0
    Q = -L[0] * T
    P = _world_points(model, state, pts)
    # body "b" (middle via point): pulled toward a.p and c.p
    u = lambda x, y: (y - x) / np.linalg.norm(y - x)  # noqa: E731
    F_b = T * (u(P[2], P[1]) + u(P[2], P[3]))
    c = model.body("b").column
    np.testing.assert_allclose(Q[c : c + 3], F_b, atol=1e-10)
    R = rotation_matrix(state.quat_WB[model.body("b").index])
    np.testing.assert_allclose(Q[c + 3 : c + 6], R.T @ np.cross(R @ pts["b"], F_b), atol=1e-10)
