"""Elastic-foundation contact against closed forms and physical invariants.

Closed forms used (p = pressure modulus, R = sphere radius, δ = indentation):
* sphere's vertices against a plane: each vertex at polar angle θ has depth
  d = R cos θ − (R − δ) along the plane normal and tributary area dS on the sphere, so
  F → p ∫ d dS = 2πR²p ∫_{u0}^{1} (R u − R + δ) du = π p R δ²  (u0 = (R − δ)/R);
  the spherical-cap volume gives p π δ² (R − δ/3), a relative difference δ/(3R − δ).
* plane's vertices against the sphere: a plane point at radius ρ has radial depth
  d = R − D, D = √(ρ² + c²), c = R − δ, normal component c/D, so with ρ dρ = D dD
  F = 2π p c ∫_c^R (R − D) dD = π p δ² (R − δ).
  Swapping the roles of the surfaces therefore changes the force by the factor
  (R − δ)/R, i.e. by δ/R (1 % at δ = 0.1 mm, R = 10 mm).
* flat face of area A at depth δ under a plane: F = p A δ, centre of pressure at the
  face centroid (Σ a_i x_i = Σ_f A_f x̄_f for tributary areas).
"""

import numpy as np
import pytest

from openfdk.contact import ElasticFoundation, surface_mesh
from openfdk.contact.shapes import ellipsoid_cap, flat_patch, fossa_surface, sphere_cap
from openfdk.numerics.spatial import quat_from_rotvec, rotation_matrix, rotation_matrix_xyz

P_MOD = 1e10  # N/m³, the paper's pressure modulus
I3 = np.eye(3)
# relative precision of each mode: the grid stores φ and ∇φ as float32 (≈ 1e-10 m)
RTOL = {"exact": 1e-9, "grid": 1e-6}


def _exp(rotvec):
    return rotation_matrix(quat_from_rotvec(rotvec))


def _contact_radius(R, delta):
    return np.sqrt(2.0 * R * delta - delta * delta)


@pytest.fixture(scope="module")
def plane():
    return flat_patch(0.012, 0.012, 1e-3, name="plane")  # z = 0, normals +z


@pytest.mark.parametrize("mode", ["exact", "grid"])
def test_sphere_vertices_on_plane_match_cap_volume(plane, mode):
    R, delta = 10e-3, 0.1e-3
    a = _contact_radius(R, delta)
    # resolution: edge length a/5 (about 7 triangles across the contact radius)
    ball = sphere_cap(R, 1.5 * a / R, a / 5.0)  # pole −z, normals outward
    ef = ElasticFoundation(ball, plane, P_MOD, mode=mode, max_depth=1e-3)
    res = ef.evaluate([0.0, 0.0, R - delta], I3, np.zeros(3), I3)
    F_cap = P_MOD * np.pi * delta**2 * (R - delta / 3.0)
    F_limit = P_MOD * np.pi * R * delta**2
    assert res.force_W[2] == pytest.approx(F_cap, rel=0.01)
    assert res.force_W[2] == pytest.approx(F_limit, rel=0.0035)
    np.testing.assert_allclose(res.force_W[:2], 0.0, atol=1e-9 * F_cap)
    # centre of pressure on the plane below the sphere centre; peak at the pole vertex
    np.testing.assert_allclose(res.cop_W, 0.0, atol=1e-9)
    assert res.peak_pressure == pytest.approx(P_MOD * delta, rel=RTOL[mode])
    assert res.max_penetration == pytest.approx(delta, rel=RTOL[mode])
    # contact area → spherical-cap surface 2πRδ (boundary vertices: ±5 %)
    assert res.area == pytest.approx(2.0 * np.pi * R * delta, rel=0.05)
    # generalized force on b (the plane) is the reaction; no net moment about the line
    np.testing.assert_allclose(res.Q[6:9], -res.force_W, atol=1e-12)


def test_sphere_on_plane_converges_with_refinement(plane):
    R, delta = 10e-3, 0.1e-3
    a = _contact_radius(R, delta)
    F_limit = P_MOD * np.pi * R * delta**2
    errors = []
    for divisions in (3.5, 10.0, 20.0):
        ball = sphere_cap(R, 1.5 * a / R, a / divisions)
        ef = ElasticFoundation(ball, plane, P_MOD, mode="exact", max_depth=1e-3)
        res = ef.evaluate([0.0, 0.0, R - delta], I3, np.zeros(3), I3)
        errors.append(abs(res.force_W[2] / F_limit - 1.0))
    assert errors[0] > 0.01  # coarse: edge a/3.5 is not enough for 1 %
    assert errors[2] < errors[0] / 10.0
    assert errors[2] < 1e-3


def test_swapping_roles_changes_force_by_delta_over_R():
    R, delta = 10e-3, 0.1e-3
    a = _contact_radius(R, delta)
    ball = sphere_cap(R, 1.5 * a / R, a / 5.0)
    ball_fine = sphere_cap(R, 1.5 * a / R, 0.05e-3)  # B: fine, its facets sit inside R
    patch = flat_patch(2.4 * a, 2.4 * a, a / 20.0)
    r_ball = np.array([0.0, 0.0, R - delta])
    # sphere's vertices (body a) against the plane (body b)
    F_sphere = ElasticFoundation(ball, patch, P_MOD, mode="exact", max_depth=1e-3).evaluate(
        r_ball, I3, np.zeros(3), I3).force_W
    # plane's vertices (body a) against the sphere (body b)
    F_plane = ElasticFoundation(patch, ball_fine, P_MOD, mode="exact", max_depth=1e-3).evaluate(
        np.zeros(3), I3, r_ball, I3).force_W
    assert F_sphere[2] > 0.0 and F_plane[2] < 0.0  # each pushes its vertex body out
    assert -F_plane[2] == pytest.approx(P_MOD * np.pi * delta**2 * (R - delta), rel=0.003)
    ratio = -F_plane[2] / F_sphere[2]
    assert ratio == pytest.approx((R - delta) / R, abs=0.003)
    assert abs(1.0 - ratio) < 0.015  # the stated change: δ/R = 1 % (+ discretisation)


@pytest.mark.parametrize("mode", ["exact", "grid"])
def test_flat_face_on_plane(plane, mode):
    delta = 0.2e-3
    lx, ly = 6e-3, 4e-3
    face = flat_patch(lx, ly, 0.5e-3)  # normals +z in its own frame
    # body a's centre of mass is 20 mm from the face centroid: s = v + s0
    s0 = np.array([0.01, -0.015, 0.005])
    face_a = surface_mesh(face.vertices_B + s0, face.faces, name="box face", repair=False)
    ef = ElasticFoundation(face_a, plane, P_MOD, mode=mode, max_depth=1e-3)
    # turn body a upside down (face normal −z), face centroid at (x0, y0, −δ), spun by ψ
    R_Wa = rotation_matrix_xyz([np.pi, 0.0, 0.7])
    centroid_W = np.array([0.5e-3, -0.8e-3, -delta])
    r_Wa = centroid_W - R_Wa @ s0
    res = ef.evaluate(r_Wa, R_Wa, np.zeros(3), I3, want_vertex_pressure=True)
    A = lx * ly
    rtol = RTOL[mode]
    F = P_MOD * A * delta
    np.testing.assert_allclose(res.force_W, [0.0, 0.0, F], rtol=rtol, atol=1e-9)
    np.testing.assert_allclose(res.cop_W, [centroid_W[0], centroid_W[1], 0.0], atol=1e-10)
    assert res.area == pytest.approx(A, rel=1e-12)
    assert res.n_contact == face.n_vertices
    assert res.peak_pressure == pytest.approx(P_MOD * delta, rel=rtol)
    np.testing.assert_allclose(res.vertex_pressure, P_MOD * delta, rtol=rtol)
    # moment about a's centre of mass: (cop − r_Wa) × F, and Q_a's moment is it in a's frame
    M_expected = np.cross([centroid_W[0], centroid_W[1], 0.0] - r_Wa, [0.0, 0.0, F])
    np.testing.assert_allclose(res.moment_W, M_expected, rtol=rtol, atol=1e-12)
    np.testing.assert_allclose(res.Q[3:6], R_Wa.T @ M_expected, rtol=rtol, atol=1e-12)
    # on b (the plane, COM at the origin): −F at the same line of action
    np.testing.assert_allclose(res.Q[9:12], np.cross(res.cop_W, -res.force_W), atol=1e-12)
    assert res.energy == pytest.approx(0.5 * P_MOD * A * delta**2, rel=rtol)


def test_rim_and_band_rules():
    """Vertices beyond the rim of an open B, or deeper than max_depth, do not count."""
    small = flat_patch(2e-3, 2e-3, 0.5e-3)  # B: 2 × 2 mm, normals +z
    h = 0.1e-3
    big = flat_patch(4e-3, 4e-3, h)  # A: 4 × 4 mm, vertices every 0.1 mm
    ef = ElasticFoundation(big, small, P_MOD, mode="exact", max_depth=1e-3)
    delta = 0.1e-3
    res = ef.evaluate([0.0, 0.0, -delta], I3, np.zeros(3), I3)
    # vertices strictly inside the 2 × 2 mm footprint: 19 × 19, each carrying h²
    assert res.n_contact == 19 * 19
    assert res.force_W[2] == pytest.approx(P_MOD * delta * (19 * h) ** 2, rel=1e-9)
    deep = ef.evaluate([0.0, 0.0, -1.5e-3], I3, np.zeros(3), I3)
    assert deep.n_contact == 0 and np.all(deep.force_W == 0.0) and np.all(np.isnan(deep.cop_W))
    grid = ElasticFoundation(big, small, P_MOD, mode="grid", max_depth=1e-3)
    res_g = grid.evaluate([0.0, 0.0, -delta], I3, np.zeros(3), I3)
    # the grid trims up to one cell (0.3 mm) at the rim, never adds vertices beyond it
    assert set(grid.penetration([0, 0, -delta], I3, np.zeros(3), I3)[0]) <= set(
        ef.penetration([0, 0, -delta], I3, np.zeros(3), I3)[0])
    assert res_g.n_contact >= 13 * 13
    assert grid.evaluate([0.0, 0.0, -1.5e-3], I3, np.zeros(3), I3).n_contact == 0


@pytest.fixture(scope="module")
def tmj_pair():
    """Condyle-like cap (body a, COM 40 mm away) against a fossa-like surface (body b)."""
    cap = ellipsoid_cap((4.5e-3, 10e-3, 4e-3), 0.4e-3)
    s0 = np.array([-0.01, 0.03, -0.025])  # condyle relative to the mandible's COM
    condyle = surface_mesh(cap.vertices_B + s0, cap.faces, name="condyle", repair=False)
    fossa = fossa_surface(edge_length=0.5e-3, ml_radius=35e-3)
    grid = ElasticFoundation(condyle, fossa, P_MOD, mode="grid")
    exact = ElasticFoundation(condyle, fossa, P_MOD, mode="exact")
    return grid, exact, s0


def _random_contact_pose(rng, s0):
    """Poses (r_Wa, R_Wa, r_Wb, R_Wb): condyle top 0.05–0.3 mm into the fossa roof,
    tilted by up to 4°, shifted by up to 1 mm, then both bodies moved rigidly."""
    R_ba = _exp(rng.uniform(-1.0, 1.0, 3) * np.radians(4.0))
    top_in_b = np.array([rng.uniform(-1, 1) * 1e-3, rng.uniform(-1, 1) * 1e-3,
                         -4e-3 + rng.uniform(0.05e-3, 0.3e-3)])
    r_ba = top_in_b - R_ba @ s0  # COM of a in b's frame (cap base centre at top_in_b)
    R_Wb = _exp(rng.normal(size=3))
    r_Wb = rng.normal(size=3) * 0.05
    return r_Wb + R_Wb @ r_ba, R_Wb @ R_ba, r_Wb, R_Wb


def test_grid_matches_exact_on_random_contact_poses(tmj_pair):
    grid, exact, s0 = tmj_pair
    rng = np.random.default_rng(20170)
    for _ in range(8):
        pose = _random_contact_pose(rng, s0)
        i_g, d_g, _, _ = grid.penetration(*pose)
        i_x, d_x, _, _ = exact.penetration(*pose)
        assert i_x.size > 50
        common, cg, cx = np.intersect1d(i_g, i_x, return_indices=True)
        # depth agreement on every vertex in contact in both modes: < 0.01 mm
        assert np.max(np.abs(d_g[cg] - d_x[cx])) < 1e-5
        # vertices in contact in one mode only are at the edge of contact (< 0.01 mm)
        assert np.all(d_g[~np.isin(i_g, common)] < 1e-5)
        assert np.all(d_x[~np.isin(i_x, common)] < 1e-5)
        r_g, r_x = grid.evaluate(*pose), exact.evaluate(*pose)
        F = np.linalg.norm(r_x.force_W)
        # stated agreement: force within 1 %, moment within 1 % of |F|·40 mm, CoP 10 µm
        assert np.linalg.norm(r_g.force_W - r_x.force_W) < 0.01 * F
        assert np.linalg.norm(r_g.moment_W - r_x.moment_W) < 0.01 * F * 0.04
        assert np.linalg.norm(r_g.cop_W - r_x.cop_W) < 1e-5
        assert r_g.area == pytest.approx(r_x.area, rel=0.02)


@pytest.mark.parametrize("mode", ["exact", "grid"])
def test_invariance_under_a_common_rigid_motion(tmj_pair, mode):
    grid, exact, s0 = tmj_pair
    ef = grid if mode == "grid" else exact
    rng = np.random.default_rng(11)
    r_Wa, R_Wa, r_Wb, R_Wb = _random_contact_pose(rng, s0)
    base = ef.evaluate(r_Wa, R_Wa, r_Wb, R_Wb)
    assert base.n_contact > 50
    for _ in range(3):
        R_T = _exp(rng.normal(size=3) * 2.0)
        t_T = rng.normal(size=3) * 0.2
        moved = ef.evaluate(R_T @ r_Wa + t_T, R_T @ R_Wa, R_T @ r_Wb + t_T, R_T @ R_Wb)
        F = np.linalg.norm(base.force_W)
        assert np.linalg.norm(moved.force_W) == pytest.approx(F, rel=1e-9)
        np.testing.assert_allclose(moved.force_W, R_T @ base.force_W, atol=1e-9 * F)
        np.testing.assert_allclose(moved.moment_W, R_T @ base.moment_W, atol=1e-9 * F)
        # body-frame moments in Q are unchanged
        np.testing.assert_allclose(moved.Q[3:6], base.Q[3:6], atol=1e-9 * F)
        np.testing.assert_allclose(moved.Q[9:12], base.Q[9:12], atol=1e-9 * F)
        # centre of pressure relative to body b
        np.testing.assert_allclose(R_Wb.T @ (base.cop_W - r_Wb),
                                   (R_T @ R_Wb).T @ (moved.cop_W - (R_T @ r_Wb + t_T)),
                                   atol=1e-12)
        assert moved.area == pytest.approx(base.area, rel=1e-12)
        assert moved.n_contact == base.n_contact


def test_bad_arguments_are_named():
    patch = flat_patch(1e-3, 1e-3, 0.5e-3, name="condyle_r")
    with pytest.raises(ValueError, match="condyle_r.*pressure_modulus"):
        ElasticFoundation(patch, patch, -1.0)
    with pytest.raises(ValueError, match="mode must be 'grid' or 'exact'"):
        ElasticFoundation(patch, patch, P_MOD, mode="fast")
    with pytest.raises(ValueError, match="max_depth"):
        ElasticFoundation(patch, patch, P_MOD, max_depth=0.0)


def test_block_mask_marks_exactly_the_blocks_with_a_valid_cell(tmj_pair):
    """block_occupancy against a direct loop over blocks, on a random mask with sizes
    that are not multiples of the block edge; and the grid's own block mask covers
    every valid cell (so the query's block test cannot drop a point)."""
    from openfdk.contact.distance_grid import BLOCK, block_occupancy

    rng = np.random.default_rng(3)
    cells = (rng.random((9, 6, 13)) < 0.05).astype(np.uint8)
    blocks = block_occupancy(cells, 4)
    assert blocks.shape == (3, 2, 4)
    for I, J, K in np.ndindex(blocks.shape):
        expect = cells[4 * I : 4 * I + 4, 4 * J : 4 * J + 4, 4 * K : 4 * K + 4].any()
        assert blocks[I, J, K] == expect
    assert 0 < blocks.sum() < blocks.size
    grid = tmj_pair[0].grid
    i, j, k = np.nonzero(grid.cell_valid)
    assert np.all(grid.block_valid[i // BLOCK, j // BLOCK, k // BLOCK] == 1)
    assert grid.block_valid.mean() < 0.5  # and it rejects most of the box
