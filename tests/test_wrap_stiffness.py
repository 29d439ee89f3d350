"""Geometric stiffness of ligaments over one wrapping surface along directions
(forces/wrap_stiffness.py): the closed form with the tangent points' sliding against
central differences of the generalised forces on the manifold, for a cylinder, a sphere
and an ellipsoid on a moving body between two other moving bodies."""

from __future__ import annotations

import numpy as np
import pytest

from openfdk.forces.elements import add_ligament, add_wrap_surface
from openfdk.forces.forceset import ForceElements
from openfdk.forces.wrap_kernels import POINT
from openfdk.forces.wrap_stiffness import single_surface_paths
from openfdk.model.builder import ModelBuilder
from openfdk.numerics.numdiff import manifold_jacobian
from openfdk.numerics.spatial import quat_from_rotvec


def _model(kind, dims, side):
    """A ligament from body a over a surface on the drum to body b, all three free and
    rotated, taut (reference strain 5 %)."""
    b = ModelBuilder("wrapstiff", gravity=(0, 0, 0))
    b.add_body("drum", 1.0, [1, 1, 1], position=[0.002, -0.001, 0.003], orientation=quat_from_rotvec([0.1, -0.2, 0.15]))
    b.add_body("a", 1.0, [1, 1, 1], position=[-0.1, 0.05, 0.02], orientation=quat_from_rotvec([0.3, 0.1, -0.2]))
    b.add_body("b", 1.0, [1, 1, 1], position=[0.12, 0.0, -0.03], orientation=quat_from_rotvec([-0.2, 0.25, 0.1]))
    b.add_frame("drum", "S", [0.001, 0.0, -0.002], orientation=quat_from_rotvec([0.0, 0.1, 0.05]))
    b.add_frame("a", "p", [0.004, -0.003, 0.002])
    b.add_frame("b", "q", [-0.003, 0.002, 0.004])
    add_wrap_surface(b, "surf", kind, "drum.S", dims, side)
    add_ligament(b, "lig", ["a.p", "surf", "b.q"], stiffness=3000.0, reference_strain=0.05)
    return b.build()


@pytest.mark.parametrize("kind,dims,side", [
    ("cylinder", 0.03, [0, 1, 0]), ("sphere", 0.03, [0, 1, 0]), ("ellipsoid", [0.04, 0.03, 0.025], [0, 1, 0]),
])
def test_single_surface_stiffness_along_equals_differences_of_the_forces(kind, dims, side):
    model = _model(kind, dims, side)
    state = model.initial_state()
    paths = ForceElements(model).by_kind["ligaments"].paths
    l, L = paths.evaluate(state)
    assert paths.single_surface.tolist() == [True]
    T_W = paths.wrapped.evaluate(state, with_tangents=True)[2]
    assert np.all(np.isfinite(T_W[1])), "the surface is in contact"
    T = np.array([120.0])
    rng = np.random.default_rng(11)
    U = rng.normal(size=(state.n_coords, 4))
    KU = paths.geometric_stiffness_along(state, T, L, U)
    # independent: −∂(Lᵀ T)/∂q̂ by central differences on the manifold, times U
    K_ref = -manifold_jacobian(lambda s: T @ paths.evaluate(s)[1], state, 1e-7)
    KU_ref = K_ref @ U
    assert np.abs(KU_ref).max() > 10.0
    np.testing.assert_allclose(KU, KU_ref, atol=5e-5 * np.abs(KU_ref).max())  # (forward differences: ~1e-5)
    # the tangent points' sliding matters: holding them in the drum gives another K
    assert np.abs(KU_ref - _fixed_tangent_points(paths, state, T, U)).max() > 0.01 * np.abs(KU_ref).max()


def _fixed_tangent_points(paths, state, T, U):
    """−T (∂Lᵀ/∂q̂) U with the tangent points held in the drum: the closed form of the two
    straight segments P → T1 and T2 → Q alone."""
    from openfdk.forces.path_stiffness import add_path_geometric_stiffness

    w = paths.wrapped
    T_W = w.evaluate(state, with_tangents=True)[2][1]
    s = w.bodies[1]
    to_s = [state.R_WB[s].T @ (x - state.p_WB[s]) for x in T_W]
    K = np.zeros((state.n_coords, state.n_coords))
    add_path_geometric_stiffness(state.p_WB, state.R_WB, state.column, np.array([w.bodies[0], s]),
                                 np.array([w.p_B[0], to_s[1]]), np.array([s, w.bodies[2]]),
                                 np.array([to_s[0], w.p_B[2]]), np.array([0, 0]), T, K)
    return K @ U


def test_only_paths_over_one_surface_take_the_closed_form():
    """single_surface_paths: a point, one cylinder/sphere/ellipsoid, a point; not two
    surfaces, not a via point between, not OpenSim's planar ellipsoid rule."""
    from openfdk.forces.wrap_kernels import CYLINDER, ELLIPSOID, OPENSIM_PLANE, SPHERE, TORUS

    kinds = np.array([POINT, ELLIPSOID, POINT,  # 0: yes
                      POINT, CYLINDER, SPHERE, POINT,  # 1: two surfaces
                      POINT, ELLIPSOID, POINT,  # 2: OpenSim's planar rule
                      POINT, TORUS, POINT,  # 3: torus
                      POINT, SPHERE, POINT,  # 4: yes
                      POINT, POINT, CYLINDER, POINT])  # 5: a via point first
    limits = np.zeros((len(kinds), 3))
    limits[8, 1] = OPENSIM_PLANE
    start = np.array([0, 3, 7, 10, 13, 16, 20])
    assert single_surface_paths(kinds, limits, start).tolist() == [0, 4]


def test_ellipsoid_tangent_moves_equal_the_moved_anchors_solved_again():
    """ellipsoid_tangent_moves (the implicit function theorem on the shooting residual,
    from one solve) gives the tangent points' moves for anchor moves of the wrap
    stiffness's size (1e-6 of |P| + |Q|, across the segments' lines) equal to solving the
    moved anchors again to the Newton tolerance: to 1e-4 of the moves themselves, which
    are far from zero (solving again takes 2–5 shots a move, the implicit function
    theorem 2 for all and 1 a move)."""
    from openfdk.forces.wrap_kernels import (ELLIPSOID_TOL, WARM_SIZE, ellipsoid_tangent_moves, ellipsoid_wrap,
                                             ellipsoid_wrap_from)

    axes = np.array([0.02, 0.035, 0.013])  # DM's lateral patellofemoral ligament's ellipsoid
    none = np.zeros(3)
    rng = np.random.default_rng(4)
    for P, Q in ((np.array([0.03, 0.012, 0.01]), np.array([-0.028, -0.015, -0.004])),
                 (np.array([-0.01, 0.05, 0.012]), np.array([0.012, -0.045, -0.006]))):
        warm = np.zeros(WARM_SIZE)
        st, _, T1, T2, _ = ellipsoid_wrap_from(P, Q, axes, none, ELLIPSOID_TOL, warm)
        assert st == 1
        h = 1e-6 * (np.linalg.norm(P) + np.linalg.norm(Q))
        moves_P, moves_Q = np.zeros((6, 3)), np.zeros((6, 3))
        for q in range(6):
            d = rng.normal(size=3)
            (moves_P if q < 3 else moves_Q)[q] = h * d / np.linalg.norm(d)
        ok, dT1, dT2 = ellipsoid_tangent_moves(P, Q, axes, none, warm, moves_P, moves_Q)
        assert ok
        for q in range(6):
            row = warm.copy()
            st_q, _, T1_q, T2_q, _ = ellipsoid_wrap_from(P + moves_P[q], Q + moves_Q[q], axes, none, ELLIPSOID_TOL,
                                                         row)
            assert st_q == 1 and 2 <= row[15] <= 5  # solving again: 2–5 shots a move
            want1, want2 = T1_q - T1, T2_q - T2
            assert np.linalg.norm(want1) > 1e-2 * h and np.linalg.norm(want2) > 1e-2 * h
            assert np.linalg.norm(dT1[q] - want1) < 1e-4 * np.linalg.norm(want1)
            assert np.linalg.norm(dT2[q] - want2) < 1e-4 * np.linalg.norm(want2)
        # the cold solve of a moved pair agrees too (the warm start is the same geodesic)
        st_c, _, T1_c, T2_c, _ = ellipsoid_wrap(P + moves_P[0], Q + moves_Q[0], axes, none, ELLIPSOID_TOL)
        assert np.linalg.norm(T1 + dT1[0] - T1_c) < 1e-4 * np.linalg.norm(dT1[0])
