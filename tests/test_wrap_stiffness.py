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
