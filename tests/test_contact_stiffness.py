"""Contact stiffness K = ∂Q/∂q̂ against central finite differences on the manifold.

q̂ = [δr_a, δπ_a, δr_b, δπ_b]; the finite-difference column k perturbs r by ±ε e_k or
R by R·Exp(±ε e_k) and differences Q. In exact mode the analytic K neglects only the
Hessian of B's distance field (B's curvature κ), a relative error of order d·κ
(d = penetration); in grid mode K is exact (the interpolants are differentiated):
* against a flat B (sphere cap's vertices on a plane) nothing is neglected and the
  check is tight (float32 grid storage limits grid mode to ~1e-6);
* against a curved B (ball of radius 10 mm in a 12 mm cup, κ = 1/12 mm) the bound is
  1.5·d_max·κ relative to the largest entry of K.
Blocks are compared in N/m after scaling rotations by a 40 mm lever.
Also Q = −∂U/∂q̂ for the elastic energy U = ½ Σ p a_i d_i² (conservative loads).
"""

import numpy as np
import pytest

from openfdk.contact import ElasticFoundation, surface_mesh
from openfdk.contact.shapes import flat_patch, sphere_cap
from openfdk.numerics.spatial import quat_from_rotvec, rotation_matrix

P_MOD = 1e10


def _exp(rotvec):
    return rotation_matrix(quat_from_rotvec(rotvec))


def _perturbed(pose, k, eps):
    """Pose with coordinate k of q̂ = [δr_a, δπ_a, δr_b, δπ_b] moved by eps (manifold)."""
    r_Wa, R_Wa, r_Wb, R_Wb = (np.array(x, dtype=float) for x in pose)
    block, axis = divmod(k, 3)
    e = np.zeros(3)
    e[axis] = eps
    if block == 0:
        r_Wa = r_Wa + e
    elif block == 1:
        R_Wa = R_Wa @ _exp(e)
    elif block == 2:
        r_Wb = r_Wb + e
    else:
        R_Wb = R_Wb @ _exp(e)
    return r_Wa, R_Wa, r_Wb, R_Wb


def _finite_difference(fun, pose, eps_r=1e-8, eps_t=1e-6):
    """Central differences of fun(pose) (array) over the 12 manifold coordinates."""
    columns = []
    for k in range(12):
        eps = eps_r if (k // 3) % 2 == 0 else eps_t
        plus = fun(_perturbed(pose, k, +eps))
        minus = fun(_perturbed(pose, k, -eps))
        columns.append((plus - minus) / (2.0 * eps))
    return np.stack(columns, axis=-1)


def _in_newton_per_metre(K, L=0.04):
    """S K S with S = diag(1, 1/L, 1, 1/L) per 3-block: every block in N/m (L = lever, m)."""
    S = np.repeat([1.0, 1.0 / L, 1.0, 1.0 / L], 3)
    return S[:, None] * K * S[None, :]


def _with_com_offset(mesh, s0, name):
    return surface_mesh(mesh.vertices_B + s0, mesh.faces, name=name, repair=False)


def _world(rng, r_ba, R_ba):
    """Put body b anywhere in the world, body a at (r_ba, R_ba) relative to it."""
    R_Wb = _exp(rng.normal(size=3))
    r_Wb = rng.normal(size=3) * 0.05
    return r_Wb + R_Wb @ r_ba, R_Wb @ R_ba, r_Wb, R_Wb


@pytest.fixture(scope="module")
def ball_on_plane():
    R = 10e-3
    ball = sphere_cap(R, 0.3, 0.25e-3)  # centre at the origin of its mesh frame
    s0 = np.array([0.02, -0.01, 0.03])  # sphere centre relative to body a's COM
    plane = flat_patch(0.02, 0.02, 1e-3)
    b0 = np.array([-0.01, 0.02, -0.015])  # plane relative to body b's COM
    return _with_com_offset(ball, s0, "ball"), _with_com_offset(plane, b0, "plane"), R, s0, b0


@pytest.mark.parametrize("mode", ["exact", "grid"])
def test_stiffness_sphere_on_plane_is_exact(ball_on_plane, mode):
    ball, plane, R, s0, b0 = ball_on_plane
    ef = ElasticFoundation(ball, plane, P_MOD, mode=mode, max_depth=1e-3)
    rng = np.random.default_rng(42 if mode == "exact" else 43)
    delta = 0.12e-3
    # a tilted, shifted sphere pressed δ into the plane (sphere centre at b0 + (x, y, R − δ))
    R_ba = _exp([0.05, -0.03, 0.4])
    centre_b = b0 + np.array([0.7e-3, -0.4e-3, R - delta])
    pose = _world(rng, centre_b - R_ba @ s0, R_ba)
    res = ef.evaluate(*pose, want_stiffness=True)
    assert res.n_contact > 100
    # no vertex within 1e-6 m of the contact boundary: FD steps (≤ 1e-6·0.04 m) stay inside
    r_Wa, R_Wa, r_Wb, R_Wb = pose
    z = (R_Wb.T @ ((r_Wa + ball.vertices_B @ R_Wa.T) - r_Wb).T)[2] - b0[2]
    assert np.min(np.abs(z)) > 1e-6
    K_fd = _in_newton_per_metre(_finite_difference(lambda q: ef.evaluate(*q).Q, pose))
    K = _in_newton_per_metre(res.K)
    scale = np.abs(K_fd).max()
    assert scale > 1e4  # N/m: non-zero
    # every block coupling is exercised: rotations of both bodies matter
    for rows in (slice(0, 3), slice(3, 6), slice(6, 9), slice(9, 12)):
        for cols in (slice(0, 3), slice(3, 6), slice(6, 9), slice(9, 12)):
            assert np.abs(K_fd[rows, cols]).max() > 1e-2 * scale
    tol = 1e-7 if mode == "exact" else 1e-6
    np.testing.assert_allclose(K, K_fd, rtol=0, atol=tol * scale)
    # the terms from the lever arms and the normal turning with b (p a d ∂u/∂q̂) are
    # needed: −Σ p a u uᵀ alone, built here from the contact vertices, misses by far more
    idx, _, g_B, y_B = ef.penetration(*pose)
    n_W = g_B @ R_Wb.T
    s_A = ball.vertices_B[idx]
    u = np.hstack([n_W, np.cross(s_A, n_W @ R_Wa), -n_W, -np.cross(y_B, g_B)])
    K_uu = _in_newton_per_metre(-(P_MOD * ball.vertex_areas[idx] * u.T) @ u)
    assert np.abs(K_uu - K_fd).max() > 100 * tol * scale
    # the normal stiffness of the pair: ∂F_z/∂z_a = −Σ p a_i (vertices in contact)
    n_W = R_Wb[:, 2]
    assert n_W @ res.K[0:3, 0:3] @ n_W == pytest.approx(-P_MOD * res.area, rel=1e-6)


@pytest.fixture(scope="module")
def ball_in_cup():
    R_ball, R_cup = 10e-3, 12e-3
    ball = sphere_cap(R_ball, 0.5, 0.25e-3, pole=(0, 0, -1))
    cup = sphere_cap(R_cup, 0.6, 0.25e-3, pole=(0, 0, -1), inward=True)  # normals → centre
    s0 = np.array([0.0, 0.02, 0.03])
    return _with_com_offset(ball, s0, "ball"), cup, R_ball, R_cup, s0


def test_stiffness_ball_in_cup_within_curvature_bound(ball_in_cup):
    ball, cup, R_ball, R_cup, s0 = ball_in_cup
    ef = ElasticFoundation(ball, cup, P_MOD, mode="exact", max_depth=1e-3)
    rng = np.random.default_rng(7)
    delta = 0.12e-3
    R_ba = _exp([0.05, -0.03, 0.2])
    # ball centre 2 mm + δ below the cup centre (the cup's lowest point is at −12 mm)
    centre_b = np.array([0.3e-3, -0.2e-3, -(R_cup - R_ball) - delta])
    pose = _world(rng, centre_b - R_ba @ s0, R_ba)
    res = ef.evaluate(*pose, want_stiffness=True)
    assert res.n_contact > 300
    K_fd = _in_newton_per_metre(_finite_difference(lambda q: ef.evaluate(*q).Q, pose))
    K = _in_newton_per_metre(res.K)
    scale = np.abs(K_fd).max()
    assert scale > 1e5
    bound = 1.5 * res.max_penetration / R_cup  # neglected d·κ terms
    assert 0.005 < bound < 0.03
    assert np.abs(K - K_fd).max() < bound * scale


def test_grid_stiffness_ball_in_cup_is_exact(ball_in_cup):
    """Grid mode differentiates its own interpolants (curvature included): K equals
    central differences of Q on a curved B to the differences' accuracy, where the
    exact mode's K is off by its curvature bound (about 1 %)."""
    ball, cup, R_ball, R_cup, s0 = ball_in_cup
    ef = ElasticFoundation(ball, cup, P_MOD, mode="grid", max_depth=1e-3)
    rng = np.random.default_rng(7)
    R_ba = _exp([0.05, -0.03, 0.2])
    centre_b = np.array([0.3e-3, -0.2e-3, -(R_cup - R_ball) - 0.12e-3])
    pose = _world(rng, centre_b - R_ba @ s0, R_ba)
    res = ef.evaluate(*pose, want_stiffness=True)
    assert res.n_contact > 300
    # small steps: a vertex crossing a grid cell face (where the slopes jump) is unlikely
    K_fd = _in_newton_per_metre(_finite_difference(lambda q: ef.evaluate(*q).Q, pose, 3e-9, 3e-7))
    K = _in_newton_per_metre(res.K)
    scale = np.abs(K_fd).max()
    assert scale > 1e5
    assert np.abs(K - K_fd).max() < 1e-7 * scale
    K_exact = _in_newton_per_metre(ElasticFoundation(ball, cup, P_MOD, mode="exact", max_depth=1e-3)
                                   .evaluate(*pose, want_stiffness=True).K)
    assert np.abs(K_exact - K).max() > 1e-3 * scale  # the curvature the exact mode omits


@pytest.mark.parametrize("mode, rtol", [("exact", 1e-6), ("grid", 5e-4)])
def test_generalized_forces_are_minus_energy_gradient(ball_in_cup, mode, rtol):
    ball, cup, R_ball, R_cup, s0 = ball_in_cup
    ef = ElasticFoundation(ball, cup, P_MOD, mode=mode, max_depth=1e-3)
    rng = np.random.default_rng(3)
    R_ba = _exp([-0.04, 0.02, 0.1])
    centre_b = np.array([-0.2e-3, 0.4e-3, -(R_cup - R_ball) - 0.1e-3])
    pose = _world(rng, centre_b - R_ba @ s0, R_ba)
    res = ef.evaluate(*pose)
    assert res.energy > 0.0
    dU = _finite_difference(lambda q: np.array([ef.evaluate(*q).energy]), pose)[0]
    np.testing.assert_allclose(res.Q, -dU, rtol=0, atol=rtol * np.abs(res.Q).max())


def test_stiffness_zero_without_contact(ball_on_plane):
    ball, plane, R, s0, b0 = ball_on_plane
    ef = ElasticFoundation(ball, plane, P_MOD, mode="grid", max_depth=1e-3)
    I3 = np.eye(3)
    res = ef.evaluate(b0 + np.array([0, 0, R + 1e-4]) - s0, I3, np.zeros(3), I3,
                      want_stiffness=True)
    assert res.n_contact == 0
    assert np.all(res.K == 0.0) and np.all(res.Q == 0.0)


def test_contact_element_scatters_into_model_columns(ball_on_plane):
    from openfdk.contact import ContactElement
    from openfdk.model.state import BodyStates
    from openfdk.numerics.spatial import quat_from_matrix

    ball, plane, R, s0, b0 = ball_on_plane
    pair = ElasticFoundation(ball, plane, P_MOD, mode="grid", max_depth=1e-3)
    rng = np.random.default_rng(5)
    R_ba = _exp([0.02, 0.01, -0.3])
    r_Wa, R_Wa, r_Wb, R_Wb = _world(rng, b0 + np.array([0, 0, R - 1e-4]) - R_ba @ s0, R_ba)
    quats = [quat_from_matrix(np.eye(3)), quat_from_matrix(R_Wb), quat_from_matrix(R_Wa)]
    # body 0 fixed (ground), body 1 = plane (columns 0..5), body 2 = ball (6..11)
    state = BodyStates([np.zeros(3), r_Wb, r_Wa], quats, [-1, 0, 6])
    element = ContactElement("tmj", body_a=2, body_b=1, pair=pair)
    Q, K, res = element.generalized_forces(state, want_stiffness=True)
    direct = pair.evaluate(r_Wa, R_Wa, r_Wb, R_Wb, want_stiffness=True)
    assert res.n_contact > 0
    np.testing.assert_allclose(Q[6:12], direct.Q[0:6], rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(Q[0:6], direct.Q[6:12], rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(K[6:12, 0:6], direct.K[0:6, 6:12], rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(K[0:6, 0:6], direct.K[6:12, 6:12], rtol=1e-9, atol=1e-9)
    # the plane fixed: only the ball's block remains
    fixed = BodyStates([np.zeros(3), r_Wb, r_Wa], quats, [-1, -1, 0])
    Q2, K2, _ = element.generalized_forces(fixed, want_stiffness=True)
    np.testing.assert_allclose(Q2, direct.Q[0:6], rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(K2, direct.K[0:6, 0:6], rtol=1e-9, atol=1e-9)


@pytest.mark.parametrize("pole", [(0.0, 0.0, -1.0), (-0.6, -0.48, -0.64)])
def test_candidate_vertices_give_the_rows_of_all_vertices(pole):
    """Grid mode samples only the candidate vertices found at a reference pose while no
    vertex has moved farther than NEAR_REACH spacings from it (ElasticFoundation.
    _candidates; distance_grid.grid_candidates keeps the vertices whose φ̂ can reach the
    band within such a move): at poses near the reference, at the reach limit (a's
    translations of 0.999 reach, into the cup and sideways; rotations about its
    vertices' centroid whose move bound is 0.999 reach) and far from it, the vertices in
    contact and their depths equal those of sampling every vertex. Pressed 0.999 reach
    into the cup, vertices that were more than 0.95 reach in front of it are in contact:
    a bound of φ̂'s change 10 % short would have dropped them. The cup's axis along the
    grid's z or oblique to it: then the cube within reach of a vertex in front of the cup
    reaches the band's invalid outer cells, and the candidates are found cell by cell."""
    from openfdk.contact.elastic_foundation import NEAR_REACH, _largest_move

    R_ball, R_cup = 10e-3, 12e-3
    pole = np.array(pole)
    s0 = np.array([0.0, 0.02, 0.03])
    ball = _with_com_offset(sphere_cap(R_ball, 0.5, 0.25e-3, pole=pole), s0, "ball")
    cup = sphere_cap(R_cup, 0.6, 0.25e-3, pole=pole, inward=True)  # normals → centre
    cached = ElasticFoundation(ball, cup, P_MOD, mode="grid", max_depth=1e-3)
    fresh = ElasticFoundation(ball, cup, P_MOD, mode="grid", max_depth=1e-3)
    rng = np.random.default_rng(11)
    R_ba = _exp([0.05, -0.03, 0.2])
    centre_b = np.array([0.3e-3, -0.2e-3, 0.0]) + (R_cup - R_ball + 0.12e-3) * pole
    pose0 = _world(rng, centre_b - R_ba @ s0, R_ba)
    n_contact0 = len(cached.penetration(*pose0)[0])
    reference = cached._near
    # every vertex has a valid cell within reach; those in front of the cup by more than
    # about reach, or behind its band, are not candidates
    assert n_contact0 < len(reference[2]) < 0.97 * ball.vertices_B.shape[0]
    reach = NEAR_REACH * cached.grid.spacing
    r_Wa, R_Wa, r_Wb, R_Wb = pose0

    def rows_of_all_vertices(pose):
        """The rows of ``fresh`` (every vertex sampled) at pose, asserted equal to those of
        ``cached`` from the reference's candidates; also whether those were used."""
        cached._near = reference
        got = cached.penetration(*pose)
        fresh._near = None
        want = fresh.penetration(*pose)
        assert len(want[0]) > 100
        for x, y in zip(got, want):
            np.testing.assert_array_equal(x, y)
        return want, cached._near is reference

    used = 0
    sideways = np.cross(pole, [1.0, 0.0, 0.0])
    for scale in (1e-7, 1e-6, 1e-5, 3e-5, 1e-3):  # m of translation, rad/40 mm of rotation
        for _ in range(6):
            move = rng.normal(size=3) * scale
            if scale >= 1e-3:  # sideways in the cup
                move = R_Wb @ (0.6 * scale * sideways / np.linalg.norm(sideways))
            pose = (r_Wa + move, R_Wa @ _exp(rng.normal(size=3) * min(scale, 1e-5) / 0.04), r_Wb, R_Wb)
            used += rows_of_all_vertices(pose)[1]
    assert 12 <= used < 30  # the small moves used the reference's candidates, the 1 mm ones not
    assert reach < 1e-3
    # at the reach limit: translations (every vertex moves 0.999 reach) into the cup, up
    # to 25° from its axis, and sideways ...
    y0 = ball.vertices_B @ (R_Wb.T @ R_Wa).T + R_Wb.T @ (r_Wa - r_Wb)
    phi0 = cached.grid.query(y0)[0]  # at the reference
    in_front = []
    for direction in [pole, sideways, np.cross(pole, sideways)] + list(pole + 0.45 * rng.normal(size=(8, 3))):
        pressed = (r_Wa + R_Wb @ (0.999 * reach * direction / np.linalg.norm(direction)), R_Wa, r_Wb, R_Wb)
        want, reused = rows_of_all_vertices(pressed)
        assert reused
        if direction @ pole > 0.9 * np.linalg.norm(direction):
            assert len(want[0]) > 1.3 * n_contact0
            in_front.append(np.nanmax(phi0[want[0]]) / reach)
    assert len(in_front) >= 4 and max(in_front) > 0.95
    # ... and rotations about the vertices' centroid c, bound 2√2 sin(θ/2) ρ = 0.999 reach
    c_W = r_Wa + R_Wa @ cached._centre_A
    theta = 2.0 * np.arcsin(0.999 * reach / (2.0 * np.sqrt(2.0) * cached._radius_A))
    for axis in rng.normal(size=(3, 3)):
        R_d = _exp(theta * axis / np.linalg.norm(axis))
        turned = (c_W + R_d @ (r_Wa - c_W), R_d @ R_Wa, r_Wb, R_Wb)
        R0, p0 = reference[:2]
        R1, p1 = R_Wb.T @ turned[1], R_Wb.T @ (turned[0] - r_Wb)
        assert 0.99 * reach < _largest_move(R1, p1, R0, p0, cached._centre_A, cached._radius_A) <= reach
        assert rows_of_all_vertices(turned)[1]


def test_candidate_vertices_at_the_rim_of_b(ball_on_plane):
    """The ball pressed into the flat patch across the patch's edge, then slid 0.999 reach
    inward: vertices that were beyond the rim, in cells without values (their nodes'
    closest points on the rim), come into contact. They are candidates, found from the
    points of the valid cells within reach nearest them (distance_grid.grid_candidates),
    and the rows equal those of sampling every vertex."""
    from openfdk.contact.elastic_foundation import NEAR_REACH

    ball, plane, R, s0, b0 = ball_on_plane
    cached = ElasticFoundation(ball, plane, P_MOD, mode="grid", max_depth=1e-3)
    fresh = ElasticFoundation(ball, plane, P_MOD, mode="grid", max_depth=1e-3)
    reach = NEAR_REACH * cached.grid.spacing
    rng = np.random.default_rng(17)
    R_ba = _exp([0.05, -0.03, 0.4])
    centre_b = b0 + np.array([0.01 - 0.5e-3, 0.0, R - 0.12e-3])  # the patch's edge is at x = b0_x + 10 mm
    r_Wa, R_Wa, r_Wb, R_Wb = _world(rng, centre_b - R_ba @ s0, R_ba)
    cached.penetration(r_Wa, R_Wa, r_Wb, R_Wb)
    reference = cached._near
    slid = (r_Wa + R_Wb @ np.array([-0.999 * reach, 0.0, 0.0]), R_Wa, r_Wb, R_Wb)
    got = cached.penetration(*slid)
    assert cached._near is reference
    want = fresh.penetration(*slid)
    assert len(want[0]) > 50
    for x, y in zip(got, want):
        np.testing.assert_array_equal(x, y)
    y0 = ball.vertices_B[want[0]] @ (R_Wb.T @ R_Wa).T + R_Wb.T @ (r_Wa - r_Wb)  # at the reference
    assert np.isnan(cached.grid.query(y0)[0]).sum() >= 5


def test_slope_bound_bounds_the_interpolants_gradient(ball_in_cup):
    """distance_grid.slope_bound, which bounds how far φ̂ changes as the candidate vertices
    move, exceeds |∇φ̂| (grid_derivatives' exact gradient) at random points of random
    valid cells, is about 1 (φ is a distance) and the block array holds its largest."""
    from openfdk.contact.distance_grid import BLOCK, grid_derivatives, slope_bound

    ball, cup = ball_in_cup[:2]
    grid = ElasticFoundation(ball, cup, P_MOD, mode="grid", max_depth=1e-3).grid
    _, ny, nz = grid.shape
    flat, inv_h = grid.values.reshape(-1), 1.0 / grid.spacing
    rng = np.random.default_rng(2)
    cells = np.argwhere(grid.cell_valid)
    cells = cells[rng.choice(len(cells), 3000, replace=False)]
    y = grid.origin_B + (cells + rng.uniform(0.0, 1.0, size=cells.shape)) * grid.spacing
    dphi, Dg = np.empty((len(y), 3)), np.empty((len(y), 3, 3))
    grid_derivatives(y, flat, ny, nz, grid.origin_B, inv_h, dphi, Dg)
    L = np.array([slope_bound(flat, ny, nz, i, j, k, inv_h) for i, j, k in cells])
    slope = np.linalg.norm(dphi, axis=1)
    assert np.all(slope <= L)
    assert 0.95 < np.median(slope) and np.median(L) < 1.05
    assert np.all(grid.block_slope[tuple((cells // BLOCK).T)] >= L)
