"""Paths over wrapping surfaces: lengths against closed forms written here (cylinder helix,
sphere great circle, two cylinders), the ellipsoid against an independent discretised
shortest path, moment arms against finite differences on the manifold, lift-off
continuity, and the model-file section."""

import numpy as np
import pytest
from scipy.optimize import minimize

from openfdk.forces.elements import add_ligament, add_muscle, add_wrap_surface
from openfdk.forces.hill import ConstantStrengthMuscle
from openfdk.forces.forceset import ForceElements
from openfdk.forces.pathset import PathSet
from openfdk.model.builder import ModelBuilder
from openfdk.numerics.numdiff import manifold_jacobian
from openfdk.numerics.spatial import quat_from_rotvec, rotation_matrix

from models import q_difference_along


def _set_pose(model, state, body, p, rotvec):
    i = model.body(body).index
    state.p_WB[i] = p
    state.quat_WB[i] = quat_from_rotvec(np.asarray(rotvec, dtype=float))
    state.R_WB[i] = rotation_matrix(state.quat_WB[i])


def _wrap_model(kind, dims, side=None, frame_rot=(0.0, 0.0, 0.0)):
    """A drum body carrying the surface (frame rotated by ``frame_rot``), a fixed origin
    point on ground and an insertion on an arm body."""
    b = ModelBuilder("wrap", gravity=(0, 0, 0))
    b.add_body("drum", 1.0, [1, 1, 1])
    b.add_body("arm", 1.0, [1, 1, 1])
    b.add_frame("drum", "S", [0.0, 0.0, 0.0], orientation=quat_from_rotvec(np.asarray(frame_rot)))
    b.add_frame("ground", "o", [-0.1, 0.05, 0.02])
    b.add_frame("arm", "i", [0.12, 0.0, -0.03])
    add_wrap_surface(b, "surf", kind, "drum.S", dims, side)
    add_muscle(b, "m", ["ground.o", "surf", "arm.i"], ConstantStrengthMuscle(100.0, "m"))
    model = b.build()
    return model, model.muscles[0].path


# --- independent closed forms -----------------------------------------------------


def cylinder_length(P, Q, r, over_positive_y=True):
    """Straight segments + helix for a path passing the z axis on the +y side (P on the
    left, x < 0, so the path turns clockwise), written from angles: γ = angle from P to
    Q going over +y, θ = γ − acos(r/ρ_P) − acos(r/ρ_Q) is the
    wrap angle (≤ 0: no contact); unrolled, l = sqrt(H² + Δz²), H = d_P + r θ + d_Q."""
    rho_p, rho_q = np.hypot(P[0], P[1]), np.hypot(Q[0], Q[1])
    a_p, a_q = np.arctan2(P[1], P[0]), np.arctan2(Q[1], Q[0])
    gamma = np.mod(a_p - a_q, 2 * np.pi) if over_positive_y else np.mod(a_q - a_p, 2 * np.pi)
    theta = gamma - np.arccos(r / rho_p) - np.arccos(r / rho_q)
    if theta <= 0:
        return np.linalg.norm(Q - P), 0.0
    H = np.sqrt(rho_p**2 - r**2) + r * theta + np.sqrt(rho_q**2 - r**2)
    return np.hypot(H, Q[2] - P[2]), theta


def sphere_length(P, Q, r):
    """Great circle: γ = ∠POQ, θ = γ − acos(r/|P|) − acos(r/|Q|), l = d_P + r θ + d_Q."""
    nP, nQ = np.linalg.norm(P), np.linalg.norm(Q)
    gamma = np.arccos(np.clip(P @ Q / (nP * nQ), -1, 1))
    theta = gamma - np.arccos(r / nP) - np.arccos(r / nQ)
    if theta <= 0:
        return np.linalg.norm(Q - P)
    return np.sqrt(nP**2 - r**2) + r * theta + np.sqrt(nQ**2 - r**2)


def _surface_frame_points(model, state, path):
    """P (origin) and Q (insertion) in the drum's surface frame S."""
    i_d, i_a = model.body("drum").index, model.body("arm").index
    R_WS = state.R_WB[i_d] @ model.frame("drum.S").R_BF
    P_W = np.array([-0.1, 0.05, 0.02])
    Q_W = state.p_WB[i_a] + state.R_WB[i_a] @ np.array([0.12, 0.0, -0.03])
    return R_WS.T @ (P_W - state.p_WB[i_d]), R_WS.T @ (Q_W - state.p_WB[i_d])


# --- cylinder ----------------------------------------------------------------------


def test_cylinder_length_is_segments_plus_helix_at_many_poses_with_lift_off():
    r = 0.03
    model, path = _wrap_model("cylinder", r, side=[0, 1, 0], frame_rot=(0.2, -0.1, 0.3))
    state = model.initial_state()
    _set_pose(model, state, "drum", [0.004, -0.002, 0.001], [0.05, 0.1, -0.2])
    n_wrap = n_free = 0
    for psi in np.linspace(-1.2, 2.4, 73):
        _set_pose(model, state, "arm", [0.0, 0.0, 0.01], [0.1, -0.05, psi])
        P, Q = _surface_frame_points(model, state, path)
        expected, theta = cylinder_length(P, Q, r)
        n_wrap += theta > 0
        n_free += theta <= 0
        assert path.evaluate(state, 0)[0][0] == pytest.approx(expected, rel=1e-13, abs=1e-15)
    assert n_wrap > 10 and n_free > 10  # the sweep covers contact and lift-off


def test_cylinder_side_picks_the_long_way_round():
    """With side −y the same pose wraps under the cylinder (the straight line passes just
    above the axis): γ measured counter-clockwise, longer than the wrap over the top."""
    r = 0.03
    model, path = _wrap_model("cylinder", r, side=[0, -1, 0])
    state = model.initial_state()
    _set_pose(model, state, "arm", [0, 0, 0], [0, 0, 0.0])
    P, Q = _surface_frame_points(model, state, path)
    rho_p, rho_q = np.hypot(*P[:2]), np.hypot(*Q[:2])
    gamma = np.mod(np.arctan2(Q[1], Q[0]) - np.arctan2(P[1], P[0]), 2 * np.pi)
    theta = gamma - np.arccos(r / rho_p) - np.arccos(r / rho_q)
    H = np.sqrt(rho_p**2 - r**2) + r * theta + np.sqrt(rho_q**2 - r**2)
    assert theta > 0.5
    assert path.evaluate(state, 0)[0][0] == pytest.approx(np.hypot(H, Q[2] - P[2]), rel=1e-13)
    assert np.hypot(H, Q[2] - P[2]) > cylinder_length(P, Q, r)[0] + 0.01


def test_lift_off_has_no_jump_in_length_or_slope():
    r = 0.03
    model, path = _wrap_model("cylinder", r, side=[0, 1, 0])
    state = model.initial_state()
    psis = np.linspace(-1.0, 2.0, 3001)
    ls, thetas = [], []
    for psi in psis:
        _set_pose(model, state, "arm", [0, 0, 0], [0, 0, psi])
        ls.append(path.evaluate(state, 0)[0][0])
        thetas.append(cylinder_length(*_surface_frame_points(model, state, path), r)[1])
    ls, thetas = np.array(ls), np.array(thetas)
    k = np.flatnonzero(np.diff(thetas > 0))
    assert len(k) == 1  # one lift-off inside the sweep
    dl = np.diff(ls)
    h = psis[1] - psis[0]
    # no jump: neighbouring steps differ by O(h²) around the lift-off (slope continuous)
    assert np.max(np.abs(np.diff(dl[k[0] - 3 : k[0] + 4]))) < 50 * h**2
    assert np.max(np.abs(dl)) < 0.2 * h


# --- sphere ------------------------------------------------------------------------


def test_sphere_length_is_great_circle_arc():
    r = 0.035
    model, path = _wrap_model("sphere", r)
    state = model.initial_state()
    rng = np.random.default_rng(7)
    n_wrap = 0
    for _ in range(40):
        _set_pose(model, state, "drum", rng.normal(size=3) * 0.005, rng.normal(size=3) * 0.3)
        _set_pose(model, state, "arm", rng.normal(size=3) * 0.01, [0, 0, rng.uniform(-1.5, 2.0)])
        P, Q = _surface_frame_points(model, state, path)
        expected = sphere_length(P, Q, r)
        n_wrap += expected > np.linalg.norm(Q - P) + 1e-9
        assert path.evaluate(state, 0)[0][0] == pytest.approx(expected, rel=1e-13)
    assert n_wrap > 5


# --- ellipsoid ---------------------------------------------------------------------


def discrete_shortest_path_length(P, Q, axes, n, bump):
    """Independent reference: n free points x_k between P and Q, all outside the
    ellipsoid (x_kᵀ A x_k ≥ 1, A = diag(a⁻², b⁻², c⁻²)), minimising the discrete energy
    Σ |x_{k+1} − x_k|² (SLSQP); its minimiser is an evenly spaced shortest path, whose
    polyline length converges like 1/n² (chords cut the surface). ``bump`` (3,) m bends
    the straight-line start to the side the path must pass."""
    A = 1.0 / np.asarray(axes) ** 2
    t = np.linspace(0.0, 1.0, n + 2)[1:-1]
    X0 = P + t[:, None] * (Q - P) + np.sin(np.pi * t)[:, None] * bump

    def energy(z):
        X = np.vstack([P, z.reshape(-1, 3), Q])
        d = np.diff(X, axis=0)
        g = np.zeros_like(X)
        g[:-1] -= 2 * d
        g[1:] += 2 * d
        return (d * d).sum(), g[1:-1].ravel()

    def outside_jac(z):
        Z = z.reshape(-1, 3)
        J = np.zeros((n, 3 * n))
        for k in range(n):
            J[k, 3 * k : 3 * k + 3] = 2 * A * Z[k]
        return J

    cons = {"type": "ineq", "fun": lambda z: (z.reshape(-1, 3) ** 2) @ A - 1.0, "jac": outside_jac}
    res = minimize(energy, X0.ravel(), jac=True, constraints=[cons], method="SLSQP",
                   options={"ftol": 1e-16, "maxiter": 2000})
    assert res.success, res.message
    X = np.vstack([P, res.x.reshape(-1, 3), Q])
    return np.linalg.norm(np.diff(X, axis=0), axis=1).sum()


def test_ellipsoid_length_matches_independent_discrete_geodesic():
    axes = np.array([0.045, 0.03, 0.025])
    model, path = _wrap_model("ellipsoid", axes, side=[0, 1, 0], frame_rot=(0.0, 0.0, 0.1))
    state = model.initial_state()
    for psi in (-0.5,):  # one pose (the SLSQP reference takes ~10 s); wrap arc ≈ 19 mm
        _set_pose(model, state, "arm", [0, 0.0, 0.005], [0.1, 0.05, psi])
        P, Q = _surface_frame_points(model, state, path)
        length = path.evaluate(state, 0)[0][0]
        l1 = discrete_shortest_path_length(P, Q, axes, 40, np.array([0, 0.06, 0]))
        l2 = discrete_shortest_path_length(P, Q, axes, 80, np.array([0, 0.06, 0]))
        richardson = (4 * l2 - l1) / 3  # the 1/n² error removed
        assert length > np.linalg.norm(Q - P) + 5e-4  # really wrapping
        assert length == pytest.approx(richardson, rel=1e-6)


def test_ellipsoid_with_equal_axes_is_the_sphere():
    r = 0.03
    m_e, p_e = _wrap_model("ellipsoid", [r, r, r])
    state = m_e.initial_state()
    for psi in np.linspace(-1.0, 1.5, 11):
        _set_pose(m_e, state, "arm", [0, 0, 0], [0.2, 0.1, psi])
        P, Q = _surface_frame_points(m_e, state, p_e)
        assert p_e.evaluate(state, 0)[0][0] == pytest.approx(sphere_length(P, Q, r), rel=1e-9)


def _geodesic_rk4(x0, v0, A, s, n):
    """The geodesic x'' = −(x'ᵀAx'/|Ax|²) Ax by classical RK4 in n steps, written here
    (numpy) as the independent reference of the kernel's Dormand–Prince shots."""
    def rate(y):
        x, v = y[:3], y[3:]
        g = A * x
        return np.concatenate([v, -(v @ (A * v)) / (g @ g) * g])

    y, h = np.concatenate([x0, v0]), s / n
    for _ in range(n):
        k1 = rate(y)
        k2 = rate(y + 0.5 * h * k1)
        k3 = rate(y + 0.5 * h * k2)
        k4 = rate(y + h * k3)
        y = y + h / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
    return y[:3]


def test_geodesic_shots_are_great_circles_on_a_sphere_and_fifth_order_on_an_ellipsoid():
    """shoot_geodesic at the step count a cold solve gives it (12 + 75 θ/π): on a sphere
    the great circle x0 cos(s/r) + r v0 sin(s/r) to 1e-10 r (2e-12 m, up to 3 rad of arc); on a DM-sized ellipsoid the
    end point of an independent fine RK4 (3 000 steps) to 1e-11 m over up to 3.6 smallest
    semi-axes, with the error falling ~32-fold when the steps double (fifth order: a
    fourth-order method would give 16, RK4's old count of 48 + 300 θ/π four times the work)."""
    from openfdk.forces.wrap_kernels import shoot_geodesic

    r = 0.02
    x0, v0 = np.array([r, 0.0, 0.0]), np.array([0.0, 0.6, 0.8])
    for s in (0.01, 0.03, 0.06):
        x, v = shoot_geodesic(x0, v0, np.full(3, r ** -2), s, 12 + int(75 * min(s / r, np.pi) / np.pi))
        assert np.max(np.abs(x - (x0 * np.cos(s / r) + r * v0 * np.sin(s / r)))) < 1e-10 * r
        assert np.max(np.abs(v - (-x0 / r * np.sin(s / r) + v0 * np.cos(s / r)))) < 1e-10
    axes = np.array([0.032, 0.02, 0.019])  # DM's medial collateral ellipsoid
    A = axes ** -2.0
    rng = np.random.default_rng(1)
    ratios = []
    for turns in (1.2, 2.4, 3.6):
        u = rng.normal(size=3)
        x0 = u / np.sqrt(u @ (A * u))
        g = A * x0 / np.linalg.norm(A * x0)
        t = rng.normal(size=3)
        t = (t - (t @ g) * g) / np.linalg.norm(t - (t @ g) * g)
        s = turns * axes.min()
        n = 12 + int(75 * min(turns, np.pi) / np.pi)
        ref = _geodesic_rk4(x0, t, A, s, 3000)
        e1 = np.max(np.abs(shoot_geodesic(x0, t, A, s, n)[0] - ref))
        e2 = np.max(np.abs(shoot_geodesic(x0, t, A, s, 2 * n)[0] - ref))
        assert 1e-16 < e1 < 1e-11
        ratios.append(e1 / e2)
    assert 20.0 < np.median(ratios) < 50.0, ratios


def test_wraps_of_an_elongated_ellipsoid_end_where_a_fine_rk4_geodesic_ends():
    """On a 6 : 1 ellipsoid (DM's gastrocnemius one), the wrap's geodesic from T1 along the
    incoming segment over the arc s the solve found, integrated again by an independent
    RK4 in 3 000 steps, ends at the solve's T2 to 1e-10 m: the step count from the mapped
    angle (12 + 75 θ/π) also holds where the arc runs along the long axis."""
    from openfdk.forces.wrap_kernels import ELLIPSOID_TOL, ellipsoid_wrap

    axes = np.array([0.0316, 0.0264, 0.1583])
    rng = np.random.default_rng(11)
    wraps = 0
    while wraps < 8:
        d1 = rng.normal(size=3)
        d1 /= np.linalg.norm(d1)
        d2 = -d1 + 0.8 * rng.normal(size=3)
        d2 /= np.linalg.norm(d2)
        P, Q = d1 * axes * rng.uniform(1.3, 3.0), d2 * axes * rng.uniform(1.3, 3.0)
        status, _, T1, T2, s = ellipsoid_wrap(P, Q, axes, np.zeros(3), ELLIPSOID_TOL)
        if status != 1:
            continue
        wraps += 1
        v0 = (T1 - P) / np.linalg.norm(T1 - P)
        assert np.max(np.abs(_geodesic_rk4(T1, v0, axes ** -2.0, s, 3000) - T2)) < 1e-10


# --- moment arms -------------------------------------------------------------------


@pytest.mark.parametrize("kind,dims,side", [
    ("cylinder", 0.03, [0, 1, 0]), ("sphere", 0.03, None), ("ellipsoid", [0.04, 0.03, 0.025], [0, 1, 0]),
])
def test_moment_arms_match_finite_differences_on_manifold(kind, dims, side):
    model, path = _wrap_model(kind, dims, side, frame_rot=(0.3, 0.2, -0.1))
    state = model.initial_state()
    _set_pose(model, state, "drum", [0.002, 0.001, -0.003], [0.1, -0.2, 0.1])
    _set_pose(model, state, "arm", [0.0, 0.003, 0.0], [0.05, 0.1, -0.4])
    assert np.all(np.isfinite(path.tangent_points(state)[1]))  # in contact
    _, L, _ = path.evaluate(state, 1)
    fd = manifold_jacobian(lambda s: path.evaluate(s, 0)[0], state, 1e-6)
    assert np.linalg.norm(L) > 0.5
    tol = 1e-8 if kind != "ellipsoid" else 1e-7
    np.testing.assert_allclose(L, fd, atol=tol)
    # a pure rotation of the arm about the drum axis has a moment arm > the radius/2
    assert np.max(np.abs(L[0, 9:12])) > 0.015


def test_acceleration_bias_is_second_derivative_along_velocity():
    from openfdk.numerics.numdiff import second_derivative_along

    model, path = _wrap_model("cylinder", 0.03, [0, 1, 0])
    state = model.initial_state()
    _set_pose(model, state, "arm", [0.0, 0.0, 0.0], [0.0, 0.0, 0.1])
    v = np.random.default_rng(3).normal(size=model.n_coords)
    state.set_v(v)
    _, _, b = path.evaluate(state, 2)
    expected = second_derivative_along(lambda s: path.evaluate(s, 0)[0], state, v, h=1e-4)
    assert abs(b[0]) > 1e-3
    assert b[0] == pytest.approx(expected[0], rel=1e-4)


# --- several surfaces and via points ----------------------------------------------


def test_two_cylinders_and_a_via_point_closed_form():
    """Two parallel cylinders of radius r centred at x = ±d, a path over their tops from
    P = (−d − a, 0) to Q = (d + a, 0): l = 2 sqrt(a² − r²) + 2 r (π/2 − acos(r/a)) + 2d
    (the common tangent on top is 2d long). Then a via point above the middle splits it."""
    r, d, a = 0.02, 0.05, 0.06
    b = ModelBuilder("two", gravity=(0, 0, 0))
    b.add_body("arm", 1.0, [1, 1, 1])
    b.add_frame("ground", "c1", [-d, 0, 0])
    b.add_frame("ground", "c2", [d, 0, 0])
    b.add_frame("ground", "P", [-d - a, 0, 0])
    b.add_frame("arm", "Q", [d + a, 0, 0])
    b.add_frame("ground", "V", [0.0, r + 0.01, 0])
    add_wrap_surface(b, "cyl1", "cylinder", "ground.c1", r, [0, 1, 0])
    add_wrap_surface(b, "cyl2", "cylinder", "ground.c2", r, [0, 1, 0])
    add_muscle(b, "two", ["ground.P", "cyl1", "cyl2", "arm.Q"], ConstantStrengthMuscle(1.0, "two"))
    add_muscle(b, "via", ["ground.P", "cyl1", "ground.V", "cyl2", "arm.Q"], ConstantStrengthMuscle(1.0, "via"))
    model = b.build()
    state = model.initial_state()
    paths = PathSet(model.muscles)
    l, L = paths.evaluate(state)
    expected = 2 * np.sqrt(a**2 - r**2) + 2 * r * (np.pi / 2 - np.arccos(r / a)) + 2 * d
    assert l[0] == pytest.approx(expected, rel=1e-12)
    # via point V: tangents from V to each circle, wraps from the P/Q tangents
    V = np.array([d, r + 0.01])  # V relative to cylinder 2's centre (mirror for cylinder 1)
    nV = np.linalg.norm(V)
    theta = (np.pi - np.arccos(r / a)) - (np.arctan2(V[1], V[0]) + np.arccos(r / nV))
    half = np.sqrt(a**2 - r**2) + r * theta + np.sqrt(nV**2 - r**2)
    assert l[1] == pytest.approx(2 * half, rel=1e-12)
    fd = manifold_jacobian(lambda s: paths.evaluate(s)[0], state, 1e-6)
    np.testing.assert_allclose(L, fd, atol=1e-8)
    assert abs(L[0, 0]) > 0.5


def test_ligament_stiffness_over_a_wrap_matches_finite_differences():
    b = ModelBuilder("lig", gravity=(0, 0, 0))
    b.add_body("arm", 1.0, [1, 1, 1])
    b.add_frame("ground", "o", [-0.1, 0.05, 0.0])
    b.add_frame("arm", "i", [0.1, 0.0, 0.01])
    add_wrap_surface(b, "drum", "cylinder", "ground", 0.03, [0, 1, 0])
    add_ligament(b, "lig", ["ground.o", "drum", "arm.i"], stiffness=2000.0, reference_strain=0.05)
    model = b.build()
    state = model.initial_state()
    passive = ForceElements(model)
    Q, out, K = passive.generalized_forces(state, 0.0, want_stiffness=True)
    assert out["ligaments"].force[0] > 1.0
    K_fd = manifold_jacobian(lambda s: passive.generalized_forces(s, 0.0)[0], state, 1e-6)
    np.testing.assert_allclose(K, K_fd, atol=1e-4 * np.abs(K_fd).max())
    assert np.abs(K).max() > 10
    # along given directions only (the analytic FDK Jacobian's K u_j): differences along
    # each direction, against the generalised forces' own central differences along it
    U = np.random.default_rng(5).normal(size=(state.n_coords, 3))
    KU = passive.stiffness_along(state, out, U)
    for j in range(3):
        dQ = q_difference_along(passive, state, U[:, j])
        np.testing.assert_allclose(KU[:, j], dQ, atol=1e-4 * np.abs(dQ).max())
        assert np.abs(dQ).max() > 10


def test_wrapped_stiffness_perturbs_only_the_bodies_the_path_touches():
    """The wrapped paths' geometric stiffness is differenced over the bodies whose
    Jacobian columns are non-zero (points' bodies, the surface's body in contact); it
    must still equal finite differences of the whole Q over every body, a body the path
    does not touch included (its rows and columns zero)."""
    b = ModelBuilder("lig3", gravity=(0, 0, 0))
    b.add_body("arm", 1.0, [1, 1, 1])
    b.add_body("hub", 1.0, [1, 1, 1], position=(0.0, 0.005, 0.0))
    b.add_body("idle", 1.0, [1, 1, 1], position=(1.0, 0.0, 0.0))
    b.add_frame("ground", "o", [-0.1, 0.05, 0.0])
    b.add_frame("arm", "i", [0.1, 0.0, 0.01])
    add_wrap_surface(b, "drum", "cylinder", "hub", 0.03, [0, 1, 0])
    add_ligament(b, "lig", ["ground.o", "drum", "arm.i"], stiffness=2000.0, reference_strain=0.05)
    # a slack strand over the same drum: left out of the difference (the tensed subset)
    add_ligament(b, "slack", ["ground.o", "drum", "arm.i"], stiffness=2000.0, reference_strain=-0.5)
    model = b.build()
    state = model.initial_state()
    passive = ForceElements(model)
    Q, out, K = passive.generalized_forces(state, 0.0, want_stiffness=True)
    assert out["ligaments"].force[0] > 1.0 and out["ligaments"].force[1] == 0.0
    K_fd = manifold_jacobian(lambda s: passive.generalized_forces(s, 0.0)[0], state, 1e-6)
    np.testing.assert_allclose(K, K_fd, atol=1e-4 * np.abs(K_fd).max())
    hub = slice(6, 12)
    assert np.abs(K[hub, hub]).max() > 10  # the surface's body is differenced
    assert np.abs(K_fd[12:, :]).max() == 0.0 and np.abs(K[:, 12:]).max() == 0.0


def test_point_inside_surface_is_reported_by_name():
    model, path = _wrap_model("sphere", 0.2)
    with pytest.raises(FloatingPointError, match="path 'm'.*inside"):
        path.evaluate(model.initial_state(), 0)


def test_model_file_wrapping_section(tmp_path):
    from openfdk.io.modelfile import load_model

    text = """
units: {length: mm, angle: deg}
bodies:
  ground:
    frames:
      o: [-100, 50, 20]
      axis: {position: [0, 0, 0], orientation: [0, 0, 0]}
  arm:
    mass: 1.0
    inertia: [1, 1, 1]
    frames:
      i: [120, 0, -30]
wrapping:
  condyle: {type: cylinder, frame: ground.axis, radius: 30, side: +y}
muscles:
  quad: {path: [ground.o, condyle, arm.i], strength: 100}
"""
    f = tmp_path / "m.yaml"
    f.write_text(text)
    model = load_model(str(f))
    state = model.initial_state()
    path = model.muscles[0].path
    expected, theta = cylinder_length(np.array([-0.1, 0.05, 0.02]), np.array([0.12, 0.0, -0.03]), 0.03)
    assert theta > 0
    assert path.evaluate(state, 0)[0][0] == pytest.approx(expected, rel=1e-13)


@pytest.mark.parametrize("entry,words", [
    ("{type: ellipsoid, frame: ground.axis, semi_axes: [30, 20, 25], rule: geodesic}", "expected 'shortest' or 'opensim'"),
    ("{type: ellipsoid, frame: ground.axis, semi_axes: [30, 20, 25], rule: opensim, side: [1, 1, 0]}", "quadrant"),
    ("{type: cylinder, frame: ground.axis, radius: 30, rule: opensim}", "rule"),
])
def test_model_file_bad_wrapping_rule_is_one_line(tmp_path, entry, words):
    """A bad ``rule`` of a wrapping surface (unknown, a non-axis side with OpenSim's rule,
    on a cylinder): one line naming the file and the entry."""
    from openfdk.io.modelfile import load_model

    f = tmp_path / "bad_rule.yaml"
    f.write_text(f"""
units: {{length: mm, angle: deg}}
bodies:
  ground:
    frames:
      o: [-100, 50, 20]
      axis: {{position: [0, 0, 0], orientation: [0, 0, 0]}}
  arm:
    mass: 1.0
    inertia: [1, 1, 1]
    frames:
      i: [120, 0, -30]
wrapping:
  condyle: {entry}
muscles:
  quad: {{path: [ground.o, condyle, arm.i], strength: 100}}
""")
    with pytest.raises(Exception) as exc:
        load_model(str(f))
    msg = str(exc.value)
    assert "\n" not in msg and "bad_rule.yaml" in msg and "condyle" in msg and words in msg, msg


def test_ellipsoid_warm_start_equals_the_cold_solve_and_falls_back_far_away():
    """ellipsoid_wrap_from carries the last geodesic of a node as the next solve's start.
    Along a sweep of the anchors in 0.1 mm steps (the warm start in use: within 5 % of
    the smallest semi-axis) every length and tangent point equals the cold solve's to the
    geodesic Newton tolerance; with the anchors moved past the reach, or with the
    shorter way round flipped to the other side of the centre, the cold starts decide,
    and the answer is again the cold one (not the geodesic the old start leads to)."""
    from openfdk.forces.wrap_kernels import ELLIPSOID_TOL, WARM_SIZE, ellipsoid_wrap, ellipsoid_wrap_from

    axes = np.array([0.04, 0.03, 0.025])
    none = np.zeros(3)
    warm = np.zeros(WARM_SIZE)
    P0, Q0 = np.array([-0.07, 0.012, 0.004]), np.array([0.065, 0.01, -0.006])
    used = 0
    for k in range(40):
        P = P0 + np.array([0.0, 1e-4 * k, 0.0])
        Q = Q0 + np.array([0.0, 0.5e-4 * k, 1e-4 * k])
        before = warm.copy()
        st_w, l_w, T1_w, T2_w, s_w = ellipsoid_wrap_from(P, Q, axes, none, ELLIPSOID_TOL, warm)
        st_c, l_c, T1_c, T2_c, s_c = ellipsoid_wrap(P, Q, axes, none, ELLIPSOID_TOL)
        assert st_w == st_c == 1
        assert abs(l_w - l_c) < 1e-12 and np.max(np.abs(T1_w - T1_c)) < 1e-9 and np.max(np.abs(T2_w - T2_c)) < 1e-9
        used += int(np.array_equal(warm[5:11], before[5:11]))  # the cold solve's anchors kept: solved warm
    assert used >= 30  # most solves of the sweep started warm (the anchors drift out of reach now and then)
    # the straight line crosses near the centre; moving it across flips the shorter way round
    sides = []
    for dy in (0.0, -0.004, -0.008, -0.012, -0.016, -0.020, -0.024):
        P, Q = P0 + np.array([0.0, dy, 0.0]), Q0 + np.array([0.0, dy, 0.0])
        st_w, l_w, T1_w, _, _ = ellipsoid_wrap_from(P, Q, axes, none, ELLIPSOID_TOL, warm)
        st_c, l_c, T1_c, _, _ = ellipsoid_wrap(P, Q, axes, none, ELLIPSOID_TOL)
        assert st_w == st_c and abs(l_w - l_c) < 1e-12 and np.max(np.abs(T1_w - T1_c)) < 1e-9
        sides.append(np.sign(T1_c[1]))
    assert sides[0] > 0 > sides[-1]  # the sweep did cross the branch change



def test_ellipsoid_path_is_the_shorter_way_round_whatever_was_solved_before():
    """Where the two ways round an ellipsoid are nearly as long, the warm start must not
    keep the way its last cold solve took (stop 73: on DM's lPFL5 the same pose gave two
    paths 7 µm apart in length, and f^FDK 1 N apart, depending on the pose before). The
    anchors lie 0.1 mm above the ellipsoid's x–y plane, so the +z way is the shorter;
    moved 0.2 mm down (within WARM_REACH of the first solve) the −z way is. Solved
    after the first pose, the path is the shorter of the two one-sided geodesics (sides
    ±z, each solved cold) and equals the cold solve; solved again at the first pose, it
    is the +z way again."""
    from openfdk.forces.wrap_kernels import ELLIPSOID_TOL, WARM_SIZE, ellipsoid_wrap, ellipsoid_wrap_from

    axes = np.array([0.02, 0.035, 0.013])
    up, down, none = np.array([0.0, 0.0, 1.0]), np.array([0.0, 0.0, -1.0]), np.zeros(3)
    warm = np.zeros(WARM_SIZE)
    for dz, way in ((1e-4, up), (-1e-4, down), (1e-4, up)):
        P, Q = np.array([-0.05, 0.0, dz]), np.array([0.05, 0.003, dz])
        ways = [ellipsoid_wrap(P, Q, axes, side, ELLIPSOID_TOL) for side in (up, down)]
        assert all(w[0] == 1 for w in ways) and 0.0 < abs(ways[0][1] - ways[1][1]) < 1e-3
        shorter = min(ways, key=lambda w: w[1])
        assert np.sign(shorter[2] @ way) > 0  # the expected way is the shorter one
        st, l, T1, T2, _ = ellipsoid_wrap_from(P, Q, axes, none, ELLIPSOID_TOL, warm)
        assert st == 1 and abs(l - shorter[1]) < 1e-11, (dz, l - shorter[1])
        assert np.max(np.abs(T1 - shorter[2])) < 1e-8 and np.max(np.abs(T2 - shorter[3])) < 1e-8
        st_c, l_c, _, _, _ = ellipsoid_wrap(P, Q, axes, none, ELLIPSOID_TOL)
        assert abs(l - l_c) < 1e-12


def test_ellipsoid_warm_solve_takes_chord_steps_with_the_kept_derivative():
    """A warm solve a finite-difference step (1e-6 m) from the last geodesic reuses the
    shooting residual's derivative kept in the warm row (chord Newton): it converges in
    at most 3 shots, where differencing the derivative again (the row's D cleared) takes
    at least 7, and both equal the cold solve to the Newton tolerance. The warm row then
    holds this solve's geodesic, but still the cold solve's anchors (the reach is
    measured from those)."""
    from openfdk.forces.wrap_kernels import ELLIPSOID_TOL, WARM_SIZE, ellipsoid_wrap, ellipsoid_wrap_from

    axes = np.array([0.04, 0.03, 0.025])
    none = np.zeros(3)
    P0, Q0 = np.array([-0.07, 0.012, 0.004]), np.array([0.065, 0.01, -0.006])
    warm = np.zeros(WARM_SIZE)
    ellipsoid_wrap_from(P0, Q0, axes, none, ELLIPSOID_TOL, warm)
    assert warm[15] >= 4 and np.any(warm[11:15] != 0.0)  # cold: the derivative differenced, and kept
    d = np.array([0.3, -0.5, 0.8]) * 1e-6
    P, Q = P0 + d, Q0 - d
    plain = warm.copy()
    plain[11:15] = 0.0
    st_c, l_c, T1_c, T2_c, _ = ellipsoid_wrap(P, Q, axes, none, ELLIPSOID_TOL)
    for row, shots in ((warm, (1, 3)), (plain, (7, 60))):
        st, l, T1, T2, s = ellipsoid_wrap_from(P, Q, axes, none, ELLIPSOID_TOL, row)
        assert st == st_c == 1 and shots[0] <= row[15] <= shots[1], row[15]
        assert abs(l - l_c) < 1e-12 and np.max(np.abs(T1 - T1_c)) < 1e-9 and np.max(np.abs(T2 - T2_c)) < 1e-9
        assert np.allclose(row[:3], T1, atol=0.0) and row[3] == s  # this solve's geodesic, the next start
        assert np.array_equal(row[5:8], P0) and np.array_equal(row[8:11], Q0)  # the cold solve's anchors


def _nearest_by_bisection(axes, x):
    """The point of the ellipsoid (semi-axes ``axes`` (3,) m) nearest x (3,) m inside it:
    c = A⁻¹-weighted x, c_i = a_i² x_i/(t + a_i²), with the multiplier t in (−min a_i², 0]
    found by bisection on the monotone constraint Σ (a_i x_i/(t + a_i²))² = 1."""
    lo, hi = -np.min(axes ** 2), 0.0
    for _ in range(200):
        t = 0.5 * (lo + hi)
        lo, hi = (t, hi) if np.sum((axes * x / (t + axes ** 2)) ** 2) > 1.0 else (lo, t)
    return axes ** 2 * x / (0.5 * (lo + hi) + axes ** 2)


def test_opensim_plane_fan_sums_the_unit_vectors_to_the_nearest_points():
    """OpenSim's fan (wrap_ellipsoid_plane, docstring 2): the sum over the chord's sample
    points of the unit vectors to their nearest surface points, with warm-started
    Newton multipliers, equals the sum from nearest points found by bisection; and a
    bisection point is the nearest (no surface point sampled densely is nearer)."""
    from openfdk.forces.wrap_ellipsoid_plane import FAN_SAMPLES, _fan_sum

    axes = np.array([0.9, 1.1, 1.6])  # the scaled frame of a 3:3:5 ellipsoid (m)
    r1, r2 = np.array([-0.5, 0.9, -0.6]), np.array([-0.2, -0.7, 0.8])
    r1, r2 = (r / np.sqrt(np.sum((r / axes) ** 2)) for r in (r1, r2))  # the chord's ends on the surface
    d = r2 - r1
    expected = np.zeros(3)
    for i in range(1, FAN_SAMPLES - 1):
        x = r1 + (i / FAN_SAMPLES) * d
        u = _nearest_by_bisection(axes, x) - x
        expected += u / np.linalg.norm(u)
    th, ph = np.meshgrid(np.linspace(0, np.pi, 400), np.linspace(-np.pi, np.pi, 800))
    surface = axes * np.stack([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)], -1).reshape(-1, 3)
    x = r1 + 0.4 * d
    assert np.linalg.norm(_nearest_by_bisection(axes, x) - x) <= np.min(np.linalg.norm(surface - x, axis=1))
    assert np.linalg.norm(expected) > 50.0  # 298 unit vectors, mostly aligned
    np.testing.assert_allclose(_fan_sum(r1, d, axes), expected, atol=1e-9)


def test_opensim_plane_gradient_model_agrees_with_differences_near_its_reference():
    """OpenSim's planar ellipsoid rule has no closed-form gradient: it is differenced, and
    between nearby calls (a Jacobian's differences, a converging Newton step) a quadratic
    model about a reference stands in (wrap_ellipsoid_plane.plane_wrap_gradients). Near
    the reference the model's gradient equals fresh differences, and its change along a
    direction equals the second difference of the length itself (a 5-point stencil with
    ten times the step, the chord count held)."""
    from openfdk.forces.wrap_ellipsoid_plane import PLANE_ROW, plane_wrap_core, plane_wrap_gradients

    axes, side = np.array([0.03, 0.03, 0.05]), np.array([-1.0, 0.0, 0.0])
    P0, Q0 = np.array([-0.0175, 0.026, -0.024]), np.array([-0.1669, -0.3950, -0.0007])
    st, _, _, _, _, count, far = plane_wrap_core(P0, Q0, axes, side, -1, -1)
    assert st == 1 and count >= 1
    rng = np.random.default_rng(7)
    v = rng.normal(size=6)
    v /= np.linalg.norm(v)
    row = np.zeros(PLANE_ROW)
    plane_wrap_gradients(P0, Q0, axes, side, row)  # the reference
    eps = 5e-7
    g = {}
    for sign in (1.0, -1.0, 1.0):  # the third: the model, H already built
        X = np.concatenate((P0, Q0)) + sign * eps * v
        got = np.concatenate(plane_wrap_gradients(X[:3], X[3:], axes, side, row)[1:])
        fresh = np.concatenate(plane_wrap_gradients(X[:3], X[3:], axes, side, np.zeros(PLANE_ROW))[1:])
        np.testing.assert_allclose(got, fresh, atol=2e-8)
        g[sign] = got
    assert row[16] == 2.0  # the model (H) was used
    # the directional change of ∇l·v (the held-point parts have their own closed form):
    # compare vᵀ H v with the length's own second difference along v
    X0 = np.concatenate((P0, Q0))
    h = 3e-5

    def l(s):
        X = X0 + s * v
        return plane_wrap_core(X[:3], X[3:], axes, side, count, far)[1]

    d2 = (-l(2 * h) + 16 * l(h) - 30 * l(0.0) + 16 * l(-h) - l(-2 * h)) / (12 * h * h)
    Hv = np.asarray(row[32:68]).reshape(6, 6) @ v
    assert abs(d2) > 1.0  # the path bends: a second derivative of order 1/(semi-axis)
    assert abs(v @ Hv - d2) < 1e-4 * abs(d2)


def _tie_model():
    """A ligament from ground to an arm over an ellipsoid (any side) whose two ways round
    are as long when the arm sits at z = 0: both anchors lie in the ellipsoid's x–y plane
    (semi-axes 20, 35, 13 mm; anchors at x = ∓50 mm), so the path over +z mirrors the
    path over −z. Moving the arm by dz makes the +z way shorter for dz > 0."""
    b = ModelBuilder("tie", gravity=(0, 0, 0))
    b.add_body("arm", 1.0, [1, 1, 1])
    b.add_frame("ground", "o", [-0.05, 0.0, 0.0])
    b.add_frame("arm", "i", [0.05, 0.003, 0.0])
    add_wrap_surface(b, "egg", "ellipsoid", "ground", [0.02, 0.035, 0.013], None)
    add_ligament(b, "lig", ["ground.o", "egg", "arm.i"], stiffness=2000.0, reference_strain=0.05)
    model = b.build()
    return model, model.ligaments[0].path


def test_two_ways_round_as_long_blend_into_a_smooth_soft_minimum():
    """Where an ellipsoid's two ways round are nearly as long, the path is their soft
    minimum l = −δ ln(e^(−l₊/δ) + e^(−l₋/δ)) (δ = BLEND), with l₊, l₋ the one-sided
    geodesics (each solved cold with its side): the length is continuous where the
    shorter way changes sides, and its Jacobian is the weighted sum of the ways'. At the
    tie (arm at z = 0) the mirror symmetry makes the arm's z moment arm zero, where
    either way alone has |∂l/∂z| > 0.1; the Jacobian agrees with central differences
    of the length (step 10 nm, inside the 2 µm blend) across the band; and the
    ligament's stiffness, which falls back to differences for a blend, agrees with
    differences of its generalised forces."""
    from openfdk.forces.wrap_kernels import BLEND, ELLIPSOID_TOL, ellipsoid_wrap

    model, path = _tie_model()
    up, down = np.array([0.0, 0.0, 1.0]), np.array([0.0, 0.0, -1.0])
    P = np.array([-0.05, 0.0, 0.0])
    arm_z = 2  # the arm's z translation column
    for dz in (-1e-4, -3e-6, -1e-6, 0.0, 1e-6, 3e-6, 1e-4):
        state = _posed(model, dz)
        Q = np.array([0.05, 0.003, dz])
        l_up, l_down = (ellipsoid_wrap(P, Q, np.array([0.02, 0.035, 0.013]), side, ELLIPSOID_TOL)[1]
                        for side in (up, down))
        soft = -BLEND * np.logaddexp(-l_up / BLEND, -l_down / BLEND)
        l, L, _ = path.evaluate(state, 1)
        assert l[0] == pytest.approx(soft, abs=1e-12), dz
        fd = manifold_jacobian(lambda s: path.evaluate(s, 0)[0], state, 1e-8)
        np.testing.assert_allclose(L, fd, atol=2e-5)
        if dz == 0.0:
            assert abs(l_up - l_down) < 1e-12 and l[0] == pytest.approx(l_up - BLEND * np.log(2.0), abs=1e-12)
            assert abs(L[0, arm_z]) < 1e-9
        else:
            assert abs(L[0, arm_z]) > 0.1 or abs(dz) < 1e-5
    # the shorter way alone jumps: its z moment arm changes sign across the tie
    L_lo = path.evaluate(_posed(model, -1e-4), 1)[1][0, arm_z]
    L_hi = path.evaluate(_posed(model, 1e-4), 1)[1][0, arm_z]
    assert L_lo * L_hi < 0.0 and min(abs(L_lo), abs(L_hi)) > 0.1
    # the ligament's stiffness in the blend (its closed form is left for differences)
    passive = ForceElements(model)
    state = _posed(model, 1e-6)
    Q_f, out, K = passive.generalized_forces(state, 0.0, want_stiffness=True)
    assert out["ligaments"].force[0] > 1.0
    K_fd = manifold_jacobian(lambda s: passive.generalized_forces(s, 0.0)[0], state, 1e-8)
    # (the stiffness's forward difference, step 0.1 µm, against the blend's 2 µm: 0.2 %)
    np.testing.assert_allclose(K, K_fd, atol=3e-3 * np.abs(K_fd).max())
    assert np.abs(K_fd[arm_z, arm_z]) > 50 * np.abs(K_fd[0, 0])  # the blend's steep stiffness across the tie


def _posed(model, dz):
    state = model.initial_state()
    _set_pose(model, state, "arm", [0.0, 0.0, dz], [0.0, 0.0, 0.0])
    return state
