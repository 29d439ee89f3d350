"""Numba kernels of wrapped paths: the shortest path over one surface (surface frame S,
SI units), and whole paths through points and surfaces.

A path from point P to point Q that must pass around a convex surface is a straight
segment P→T1, a geodesic arc T1→T2 on the surface, and a straight segment T2→Q, with
both segments tangent to the arc at T1 and T2 (the path is locally shortest). When the
straight segment P→Q does not cross the surface the path is that segment (lift-off).

* circle (the 2-D core):    tangent points at angles α ± acos(r/ρ), arc r θ;
* cylinder (axis z_S):      unrolled onto the tangent plane the path is straight, so
                            l = sqrt((d1 + r θ + d2)² + Δz²) (helical arc, closed form);
* sphere (centre o_S):      the path lies in the plane through o_S, P and Q, a great
                            circle arc (closed form);
* ellipsoid x²/a²+y²/b²+z²/c² = 1: the map X' = D X, D = diag(1/a, 1/b, 1/c), sends the
  ellipsoid to the unit sphere and keeps straight lines, tangency and intersections, so
  the sphere solution gives the lift-off test, the side and an initial guess; then the
  geodesic ODE x'' = −(x'ᵀ A x' / |A x|²) A x, A = D², is shot from the tangent point
  T1(φ) on P's horizon (the conic {X on the ellipsoid : Pᵀ A X = 1}) over an arc length
  s, and Newton on (φ, s) makes the end tangent line pass through Q.

Side: ``side`` (3,) is a direction in S: the path passes the axis (cylinder; only the
x_S, y_S part counts) or the centre (sphere, ellipsoid) on the side where ``side``
points; the zero vector means the shorter way (the side the straight line passes on).
In the plane of the wrap, the arc turning counter-clockwise from P to Q is chosen when its
bisector points along ``side`` (positive dot product), else the clockwise one. With the
direction fixed, γ is the angle swept from P to Q in that direction and the arc between
the tangent points is θ = γ − acos(r/ρ_P) − acos(r/ρ_Q): the path wraps iff θ > 0 (an
obstacle-set rule: the path never crosses to the other side, so it wraps the long way
round when the straight line passes on the other side). Lift-off is θ → 0, continuous in
length and slope; the direction can only flip where the bisector is perpendicular to
``side``, i.e. with both points on one flank of the surface. With a side the
path stays on that side and wraps the long way round when the straight line passes on
the other side of the axis/centre; lift-off (θ → 0) is continuous in length and slope.

Every single-surface kernel returns ``(status, length, T1 (3,), T2 (3,), arc)``: status
0 = no contact (straight), 1 = wrapping, −1 = P or Q inside the surface, −2 = geodesic
not converged. :func:`wrapped_path_lengths` assembles whole paths through points and
surfaces (see :mod:`.wrapping`). All jitted code of the wrapping lives in this module
except OpenSim's planar ellipsoid rule (:mod:`.wrap_ellipsoid_plane`, flag
OPENSIM_PLANE): numba's on-disk cache checks only a kernel's own file, so a change there
must change this file too (here: the plane rule's 43-length Hessian).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .wrap_ellipsoid_plane import PLANE_ROW, plane_wrap_gradients, plane_wrap_stashed

TWO_PI = 2.0 * np.pi


@njit(cache=True)
def circle_wrap(px, py, qx, qy, r, sigma):
    """Planar wrap of P→Q around the circle |x| = r (centre at the origin).

    sigma : +1 counter-clockwise, −1 clockwise, 0 the side of the straight line.
    Returns (status, d1, theta, d2, t1x, t1y, t2x, t2y): tangent lengths d1 = |P − T1|,
    d2 = |T2 − Q| (m), wrap angle θ ∈ [0, 2π) (rad), tangent points T1, T2 (m).
    """
    rho_p = np.sqrt(px * px + py * py)
    rho_q = np.sqrt(qx * qx + qy * qy)
    if rho_p <= r or rho_q <= r:
        return -1, 0.0, 0.0, 0.0, px, py, qx, qy
    if sigma == 0:  # the shorter way: the side of the centre the straight line leaves
        sigma = 1 if px * qy - py * qx >= 0.0 else -1
    # γ: angle swept from P to Q in the wrap direction; θ = γ − acos(r/ρ_P) − acos(r/ρ_Q)
    # is the arc between the tangent points, θ ≤ 0 means the straight line clears
    a_p, a_q = np.arctan2(py, px), np.arctan2(qy, qx)
    gamma = np.mod(sigma * (a_q - a_p), TWO_PI)
    theta = gamma - np.arccos(r / rho_p) - np.arccos(r / rho_q)
    if theta <= 0.0:
        return 0, 0.0, 0.0, 0.0, px, py, qx, qy
    phi1 = a_p + sigma * np.arccos(r / rho_p)
    phi2 = a_q - sigma * np.arccos(r / rho_q)
    d1 = np.sqrt(rho_p * rho_p - r * r)
    d2 = np.sqrt(rho_q * rho_q - r * r)
    return 1, d1, theta, d2, r * np.cos(phi1), r * np.sin(phi1), r * np.cos(phi2), r * np.sin(phi2)


@njit(cache=True)
def _side_sigma(px, py, qx, qy, sx, sy):
    """+1 when the counter-clockwise arc from the direction of P to that of Q has its
    bisector along (sx, sy), −1 otherwise, 0 when no side is given."""
    if sx == 0.0 and sy == 0.0:
        return 0
    a_p = np.arctan2(py, px)
    beta = np.mod(np.arctan2(qy, qx) - a_p, TWO_PI)
    mid = a_p + 0.5 * beta
    return 1 if np.cos(mid) * sx + np.sin(mid) * sy >= 0.0 else -1


@njit(cache=True)
def cylinder_wrap(P, Q, r, side):
    """Wrap of P→Q (3,) m around the infinite cylinder x² + y² = r² (axis z): a helix.
    side (3,): the path passes the axis on this side (x, y part; zero: the shorter way).

    Unrolled, the path is the straight line of horizontal length H = d1 + r θ + d2 and
    rise Δz = Q_z − P_z, so l = sqrt(H² + Δz²) and T1_z, T2_z divide Δz like H.
    """
    sigma = _side_sigma(P[0], P[1], Q[0], Q[1], side[0], side[1])
    st, d1, theta, d2, t1x, t1y, t2x, t2y = circle_wrap(P[0], P[1], Q[0], Q[1], r, sigma)
    T1 = np.empty(3)
    T2 = np.empty(3)
    if st != 1:
        T1[:] = P
        T2[:] = Q
        dx, dy, dz = Q[0] - P[0], Q[1] - P[1], Q[2] - P[2]
        return st, np.sqrt(dx * dx + dy * dy + dz * dz), T1, T2, 0.0
    H = d1 + r * theta + d2
    dz = Q[2] - P[2]
    length = np.sqrt(H * H + dz * dz)
    T1[0], T1[1], T1[2] = t1x, t1y, P[2] + dz * d1 / H
    T2[0], T2[1], T2[2] = t2x, t2y, P[2] + dz * (d1 + r * theta) / H
    return 1, length, T1, T2, length * r * theta / H


@njit(cache=True)
def _plane_basis(P, Q, side):
    """Orthonormal e1 = P/|P|, e2 ⟂ e1 in the plane of (0, P, Q), e2·Q ≥ 0; when Q is
    (nearly) on the line through 0 and P, e2 comes from ``side`` (or any perpendicular)."""
    e1 = P / np.sqrt(P @ P)
    q_perp = Q - (Q @ e1) * e1
    nq = np.sqrt(q_perp @ q_perp)
    if nq > 1e-12 * np.sqrt(Q @ Q):
        return e1, q_perp / nq
    d = side - (side @ e1) * e1
    if np.sqrt(d @ d) < 1e-12:
        d = np.array([1.0, 0.0, 0.0]) if abs(e1[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
        d = d - (d @ e1) * e1
    return e1, d / np.sqrt(d @ d)


@njit(cache=True)
def sphere_wrap(P, Q, r, side):
    """Wrap of P→Q (3,) m around the sphere |x| = r: a great-circle arc in the plane
    through the centre, P and Q. side (3,): direction the path must pass (0: shorter)."""
    T1 = np.empty(3)
    T2 = np.empty(3)
    e1, e2 = _plane_basis(P, Q, side)
    qx, qy = Q @ e1, Q @ e2
    sigma = _side_sigma(1.0, 0.0, qx, qy, side @ e1, side @ e2)
    st, d1, theta, d2, t1x, t1y, t2x, t2y = circle_wrap(np.sqrt(P @ P), 0.0, qx, qy, r, sigma)
    if st != 1:
        T1[:] = P
        T2[:] = Q
        u = Q - P
        return st, np.sqrt(u @ u), T1, T2, 0.0
    T1[:] = t1x * e1 + t1y * e2
    T2[:] = t2x * e1 + t2y * e2
    return 1, d1 + r * theta + d2, T1, T2, r * theta


# --- ellipsoid ----------------------------------------------------------------------


@njit(cache=True)
def _geodesic_accel(x0, x1, x2, v0, v1, v2, A0, A1, A2):
    """v' of the geodesic ODE on xᵀ A x = 1: x' = v, v' = −(vᵀ A v / |A x|²) A x, in
    scalars (no array is allocated in the integrator's inner loop)."""
    n0, n1, n2 = A0 * x0, A1 * x1, A2 * x2
    lam = (A0 * v0 * v0 + A1 * v1 * v1 + A2 * v2 * v2) / (n0 * n0 + n1 * n1 + n2 * n2)
    return -lam * n0, -lam * n1, -lam * n2


#: the Dormand–Prince 5(4) pair's fifth-order solution (Dormand & Prince, J. Comput.
#: Appl. Math. 6, 1980; Hairer, Nørsett & Wanner, *Solving ODEs I*, §II.5, Table 5.2):
#: stage coefficients a_ij (row i: stage i's increments) and weights b_i; the embedded
#: fourth-order one is not used (the step count is fixed, so that a finite difference of
#: a shot differences one discretisation)
DP_A = np.array([
    [0.0, 0.0, 0.0, 0.0, 0.0],
    [1.0 / 5.0, 0.0, 0.0, 0.0, 0.0],
    [3.0 / 40.0, 9.0 / 40.0, 0.0, 0.0, 0.0],
    [44.0 / 45.0, -56.0 / 15.0, 32.0 / 9.0, 0.0, 0.0],
    [19372.0 / 6561.0, -25360.0 / 2187.0, 64448.0 / 6561.0, -212.0 / 729.0, 0.0],
    [9017.0 / 3168.0, -355.0 / 33.0, 46732.0 / 5247.0, 49.0 / 176.0, -5103.0 / 18656.0],
])
DP_B = np.array([35.0 / 384.0, 0.0, 500.0 / 1113.0, 125.0 / 192.0, -2187.0 / 6784.0, 11.0 / 84.0])


@njit(cache=True)
def shoot_geodesic(x0, v0, A, s, n_steps):
    """Integrate the geodesic from x0 (3,) with unit direction v0 (3,) over arc length s
    (m) in ``n_steps`` equal steps of the Dormand–Prince fifth-order Runge–Kutta method
    (six stages; :data:`DP_A`, :data:`DP_B`). A (3,) = (1/a², 1/b², 1/c²). Returns
    (x(s), x'(s)).

    In a quarter of the steps that classical RK4 took until stop 60, it errs less on the
    DM knee's ligament ellipsoids (7.5e-15 against RK4's 4.2e-14 m over 1.2 smallest
    semi-axes of the medial collateral one, 7.7e-12 against 4.8e-11 m over 3.6 of the
    lateral patellofemoral one), at 1.5 instead of 4 evaluations of the geodesic
    equation per RK4 step (tests/test_wrapping.py)."""
    h = s / n_steps
    A0, A1, A2 = A[0], A[1], A[2]
    y = np.empty(6)
    y[0], y[1], y[2] = x0[0], x0[1], x0[2]
    y[3], y[4], y[5] = v0[0], v0[1], v0[2]
    k = np.empty((6, 6))  # stage i's rates (x', v')
    z = np.empty(6)
    for _ in range(n_steps):
        for i in range(6):
            for c in range(6):
                acc = y[c]
                for j in range(i):
                    acc += h * DP_A[i, j] * k[j, c]
                z[c] = acc
            k[i, 0], k[i, 1], k[i, 2] = z[3], z[4], z[5]
            k[i, 3], k[i, 4], k[i, 5] = _geodesic_accel(z[0], z[1], z[2], z[3], z[4], z[5], A0, A1, A2)
        for c in range(6):
            acc = 0.0
            for i in range(6):
                acc += DP_B[i] * k[i, c]
            y[c] += h * acc
    return y[:3].copy(), y[3:].copy()


@njit(cache=True)
def _horizon_point(phi, c0, rho, u1, u2, axes):
    """T1(φ) on P's horizon: the circle c0 + ρ(cos φ u1 + sin φ u2) on the unit sphere of
    the mapped space, mapped back by D⁻¹ = diag(a, b, c)."""
    return axes * (c0 + rho * (np.cos(phi) * u1 + np.sin(phi) * u2))


@njit(cache=True)
def _shoot_residual(phi, s, P, Q, c0, rho, u1, u2, axes, A, n_steps):
    """Residual of the end condition: Q on the tangent line of the geodesic end, as
    [(Q − x)·n̂, (Q − x)·(n̂ × x')] (m), with n̂ the unit surface normal at x."""
    T1 = _horizon_point(phi, c0, rho, u1, u2, axes)
    d = T1 - P
    v0 = d / np.sqrt(d @ d)
    x, v = shoot_geodesic(T1, v0, A, s, n_steps)
    n = A * x
    n = n / np.sqrt(n @ n)
    w = Q - x
    b = np.array([n[1] * v[2] - n[2] * v[1], n[2] * v[0] - n[0] * v[2], n[0] * v[1] - n[1] * v[0]])
    return np.array([w @ n, w @ b]), T1, x


#: planes of the fan searched for the ellipsoid's initial path, and chords per arc
FAN_PLANES, FAN_CHORDS = 72, 24


@njit(cache=True)
def _plane_fan(P1, Q1, axes, side):
    """The shortest planar path over the ellipsoid among the planes through P and Q
    (mapped points P1, Q1 (3,) on either side of the unit sphere, the segment crossing
    it): each plane cuts the sphere in a circle, the path goes round it on one side of
    the line (2-D tangents, :func:`circle_wrap`) and maps back to a planar path on the
    ellipsoid (tangency is kept by the affine map). With a ``side`` only paths whose arc
    midpoint lies on that side count. Returns (length m, T1 (3,) mapped, arc length m,
    arc angle rad) of the shortest, length inf when none qualifies; then the same four
    of the shortest other local minimum of the length over the fan (cyclic in the
    planes' angle; length inf when there is none): the start of the geodesic the other
    way round (:func:`ellipsoid_wrap_from`).

    Planes through the centre alone (the sphere's great circle) miss the shortest path
    when the line passes near the centre of an elongated ellipsoid: the path then goes
    round the narrowest girth, whose plane holds the line but not the centre."""
    d = Q1 - P1
    d = d / np.sqrt(d @ d)
    a = np.array([1.0, 0.0, 0.0]) if abs(d[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    ea = a - (a @ d) * d
    ea = ea / np.sqrt(ea @ ea)
    eb = np.array([d[1] * ea[2] - d[2] * ea[1], d[2] * ea[0] - d[0] * ea[2], d[0] * ea[1] - d[1] * ea[0]])
    has_side = side @ side > 0.0
    lengths = np.full(FAN_PLANES, np.inf)
    T1s = np.zeros((FAN_PLANES, 3))
    arcs = np.zeros(FAN_PLANES)
    thetas = np.zeros(FAN_PLANES)
    P = axes * P1
    Q = axes * Q1
    for k in range(FAN_PLANES):
        psi = 2.0 * np.pi * k / FAN_PLANES
        u = np.cos(psi) * ea + np.sin(psi) * eb
        n = np.array([d[1] * u[2] - d[2] * u[1], d[2] * u[0] - d[0] * u[2], d[0] * u[1] - d[1] * u[0]])
        delta = n @ P1
        if abs(delta) >= 1.0:
            continue
        c = delta * n
        rho = np.sqrt(1.0 - delta * delta)
        # in the plane: x along d, y along u; the path passes on the +u side of the line,
        # clockwise from P to Q in (x, y)
        st, _, th, _, t1x, t1y, t2x, t2y = circle_wrap((P1 - c) @ d, (P1 - c) @ u, (Q1 - c) @ d, (Q1 - c) @ u,
                                                       rho, np.int64(-1))
        if st != 1:
            continue
        a1 = np.arctan2(t1y, t1x)
        T1 = c + t1x * d + t1y * u
        # the arc T1→T2 in FAN_CHORDS chords, mapped back (scalars: no allocation per chord)
        p0, p1, p2 = axes[0] * T1[0], axes[1] * T1[1], axes[2] * T1[2]
        arc = 0.0
        mid_side = 0.0
        # angle a1 − θ j / FAN_CHORDS by a fixed rotation per chord (no trig in the loop)
        cd, sd = np.cos(th / FAN_CHORDS), np.sin(th / FAN_CHORDS)
        ca, sa = rho * np.cos(a1), rho * np.sin(a1)
        for j in range(1, FAN_CHORDS + 1):
            ca, sa = ca * cd + sa * sd, sa * cd - ca * sd
            q0 = axes[0] * (c[0] + ca * d[0] + sa * u[0])
            q1 = axes[1] * (c[1] + ca * d[1] + sa * u[1])
            q2 = axes[2] * (c[2] + ca * d[2] + sa * u[2])
            if 2 * j == FAN_CHORDS:
                mid_side = q0 * side[0] + q1 * side[1] + q2 * side[2]
            arc += np.sqrt((q0 - p0) ** 2 + (q1 - p1) ** 2 + (q2 - p2) ** 2)
            p0, p1, p2 = q0, q1, q2
        if has_side and mid_side < 0.0:
            continue
        w1 = axes * T1 - P
        w2 = Q - np.array([p0, p1, p2])
        lengths[k] = np.sqrt(w1 @ w1) + arc + np.sqrt(w2 @ w2)
        T1s[k] = T1
        arcs[k], thetas[k] = arc, th
    # the two shortest local minima over the fan (cyclic; a plateau counts once)
    i1, i2 = -1, -1
    for k in range(FAN_PLANES):
        lk = lengths[k]
        if lk == np.inf or lk > lengths[k - 1] or lk >= lengths[(k + 1) % FAN_PLANES]:
            continue
        if i1 < 0 or lk < lengths[i1]:
            i1, i2 = k, i1
        elif i2 < 0 or lk < lengths[i2]:
            i2 = k
    if i1 < 0:  # (every plane the same length: the first)
        i1 = int(np.argmin(lengths))
    if lengths[i1] == np.inf:
        return np.inf, np.zeros(3), 0.0, 0.0, np.inf, np.zeros(3), 0.0, 0.0
    if i2 < 0:
        return lengths[i1], T1s[i1], arcs[i1], thetas[i1], np.inf, np.zeros(3), 0.0, 0.0
    return lengths[i1], T1s[i1], arcs[i1], thetas[i1], lengths[i2], T1s[i2], arcs[i2], thetas[i2]


@njit(cache=True)
def ellipsoid_wrap(P, Q, axes, side, tol):
    """Wrap of P→Q (3,) m around the ellipsoid with semi-axes ``axes`` (3,) m along
    x_S, y_S, z_S. side (3,) as for the sphere, in S. ``tol`` (m): Newton stops when the
    end residual is below it (1e-12 m gives lengths to ~1e-10 relative)."""
    return ellipsoid_wrap_from(P, Q, axes, side, tol, np.zeros(WARM_SIZE))


#: a node's row of the path kernel's ``warm``: a geodesic's warm start of
#: :func:`ellipsoid_wrap_from` [T1 (3,) m in S and arc length s m of the last solve, the
#: integrator's step count and the anchors P, Q (3,) m in S of the last cold solve, the
#: shooting residual's derivatives D (4,), the last solve's shots, the warm start's reach
#: m (at REACH)] in its first 17, or an OpenSim-rule ellipsoid's last core and gradient
#: model (:data:`~openfdk.forces.wrap_ellipsoid_plane.PLANE_ROW`)
REACH = 16
#: the other way round's warm start while both ways are followed (the ways' lengths
#: within BLEND_SPAN at the last cold solve): T1 (3,) m, s m, step count, D (4,)
OTHER = 17
#: 1 while both ways round are followed (their warm starts at 0 and OTHER)
BOTH = 26
#: the blend's outputs of the last solve: the other way's tangent points T1, T2 (3,) m in
#: S and arc m, its weight w (0: no blend) and the soft-min length minus the shorter
#: way's (m, ≤ 0)
BLEND_T1, BLEND_T2, BLEND_ARC, BLEND_W, BLEND_DL = 27, 30, 33, 34, 35
WARM_SIZE = max(36, PLANE_ROW)
#: the length scale δ (m) of the soft minimum of the two ways round,
#: l = −δ ln(exp(−l₁/δ) + exp(−l₂/δ)): where the two ways' lengths are within a few δ,
#: the path is both, weighted w_i = exp(−l_i/δ)/Σ, so its length and its Jacobian
#: w₁ L₁ + w₂ L₂ (the gradient of l) are continuous where the shorter way changes sides.
#: With the plain minimum, f^FDK jumps there and Newton may have no root to find (DM's
#: lPFL5 over lPFL_r, tm_med1 at 2.708 s: docs/fdk.md, "A wrapped path's way round").
#: At a tie the length is δ ln 2 = 1.4 µm shorter than either way
BLEND = 2e-6
#: beyond this difference of the two ways' lengths (40 δ) the weight, exp(−40) ≈ 4e−18,
#: is taken as zero and only the shorter way is followed
BLEND_SPAN = 40.0 * BLEND
#: a chord step (:func:`_shoot_newton` with a kept derivative) is accepted when it cuts
#: the end residual at least this much; else the derivative is differenced again
CHORD_RATE = 0.1
#: a warm start is used only while both anchors lie within this fraction of the smallest
#: semi-axis of where it was solved (farther, the geodesic may have changed branch), and
#: within a quarter of the margin by which the other way round was longer there. Without
#: that second bound the path depended on the poses evaluated before: where the two
#: ways round are nearly as long, a warm start kept the way the last cold solve took.
#: On DM's lateral patellofemoral ligament (lPFL5 over the ellipsoid lPFL_r, quadrant
#: ``all``; tm_med1 at 2.708 s) the two ways round differed by 7 µm, the same pose gave
#: a residual 1 N apart along pf_tx_r depending on the pose evaluated before it, and
#: Newton stalled there (docs/knee-gait-solver-history.md, stop 73)
WARM_REACH = 0.05
#: two geodesics whose first tangent points are closer than this fraction of the
#: anchors' distances from the centre are the same (the fan's two minima found one path)
SAME_GEODESIC = 1e-6


@njit(cache=True)
def _horizon_angle(T1, Dinv, c0, u1, u2):
    """The horizon angle φ (rad) of a geodesic's start T1 (3,) m in S on P's horizon
    circle (centre c0, unit vectors u1, u2, on the unit sphere: :func:`_horizon`)."""
    g = T1 / Dinv - c0
    return np.arctan2(g @ u2, g @ u1)


@njit(cache=True)
def _way_length(P, Q, T1, x, s):
    """|T1 − P| + s + |Q − x| (m): the length of P→Q (3,) m over the geodesic from T1 to
    x (3,) m of arc s m."""
    a1 = T1 - P
    a2 = Q - x
    return np.sqrt(a1 @ a1) + s + np.sqrt(a2 @ a2)


@njit(cache=True)
def _blended(P, Q, T1a, xa, sa, T1b, xb, sb, warm):
    """The wrap of P→Q (3,) m in S over two ways round, geodesics (T1, end x (3,) m,
    arc s m) a and b: returns the shorter way as :func:`ellipsoid_wrap_from` does, and
    writes the other way's tangent points and arc, its weight w = exp(−l_o/δ)/Σ (0 when
    the lengths differ by BLEND_SPAN or more) and the soft minimum's length minus the
    shorter way's, −δ ln(1 + exp(−|l_a − l_b|/δ)), to warm (BLEND_*; δ = BLEND)."""
    la = _way_length(P, Q, T1a, xa, sa)
    lb = _way_length(P, Q, T1b, xb, sb)
    if lb < la:
        T1a, xa, sa, la, T1b, xb, sb, lb = T1b, xb, sb, lb, T1a, xa, sa, la
    gap = lb - la
    if gap < BLEND_SPAN:
        e = np.exp(-gap / BLEND)
        warm[BLEND_W] = e / (1.0 + e)
        warm[BLEND_DL] = -BLEND * np.log1p(e)
        warm[BLEND_T1:BLEND_T1 + 3] = T1b
        warm[BLEND_T2:BLEND_T2 + 3] = xb
        warm[BLEND_ARC] = sb
    T1 = T1a.copy()
    T2 = xa.copy()
    return 1, la + warm[BLEND_DL], T1, T2, sa


@njit(cache=True)
def ellipsoid_wrap_from(P, Q, axes, side, tol, warm):
    """:func:`ellipsoid_wrap` with a warm start ``warm`` (WARM_SIZE,), read and written:
    the tangent point T1 (m, S) and arc length s (m) of the last solve, the integrator step
    count and anchors of the last cold solve (s = 0: none), the shooting's derivatives.
    When s > 0 and both anchors lie within the last cold solve's reach of its anchors
    (WARM_REACH × the smallest semi-axis, or a quarter of the margin by which the other
    way round was longer), Newton starts from the last geodesic, with the same step count
    and chord steps (:func:`_shoot_newton`), and the cold starts (the plane fan, the
    great circle) are used only if it does not converge. Between nearby poses (the
    Newton iterations and finite differences of a frame, successive frames) this is the
    same geodesic as the cold solve, to the Newton tolerance, at a fraction of the cost;
    the step count is kept so the discretisation is the same along a finite difference,
    and the reach is measured from the cold solve, so that drifting anchors are decided
    cold again (the shorter way round may have changed sides). A cold solve shoots the
    geodesic from each of the plane fan's two shortest local minima (the two ways round)
    and takes the shorter, so the path is a function of the anchors alone, whatever was
    evaluated before. warm[15]: the shots of this solve (a diagnostic)."""
    T1 = np.empty(3)
    T2 = np.empty(3)
    warm[15] = 0.0
    warm[BLEND_W] = 0.0
    warm[BLEND_DL] = 0.0
    Dinv = axes
    P1 = P / Dinv
    Q1 = Q / Dinv
    st, T1s, T2s, c0, rho, u1, u2 = _horizon(P, Q, axes, side)
    if st != 1:
        warm[3] = 0.0
        T1[:] = P
        T2[:] = Q
        u = Q - P
        return st, np.sqrt(u @ u), T1, T2, 0.0
    A = 1.0 / (axes * axes)
    scale = np.sqrt(P @ P) + np.sqrt(Q @ Q)
    tol = max(tol, 1e-13 * scale)  # (round-off of the residual of far anchors)
    reach = warm[REACH]  # (WARM_REACH, or less where the other way round is nearly as short)
    if warm[3] > 0.0 and warm[BOTH] > 0.0 and _within(P, warm[5:8], reach) and _within(Q, warm[8:11], reach):
        # both ways round are followed: each from its own warm start
        okA, _, sA, T1A, xA, shots = _shoot_newton(_horizon_angle(warm[:3], Dinv, c0, u1, u2), warm[3], P, Q, c0,
                                                   rho, u1, u2, Dinv, A, int(warm[4]), scale, tol, warm[11:15])
        warm[15] += shots
        okB = False
        if okA:
            okB, _, sB, T1B, xB, shots = _shoot_newton(_horizon_angle(warm[OTHER:OTHER + 3], Dinv, c0, u1, u2),
                                                       warm[OTHER + 3], P, Q, c0, rho, u1, u2, Dinv, A,
                                                       int(warm[OTHER + 4]), scale, tol, warm[OTHER + 5:OTHER + 9])
            warm[15] += shots
        if okB:
            eAB = T1A - T1B
            if eAB @ eAB >= (SAME_GEODESIC * scale) ** 2:
                warm[:3] = T1A
                warm[3] = sA
                warm[OTHER:OTHER + 3] = T1B
                warm[OTHER + 3] = sB
                if _way_length(P, Q, T1B, xB, sB) < _way_length(P, Q, T1A, xA, sA):
                    # the shorter way's warm start is kept first (read by ellipsoid_tangent_moves)
                    for i in range(5):
                        warm[i], warm[OTHER + i] = warm[OTHER + i], warm[i]
                    for i in range(4):
                        warm[11 + i], warm[OTHER + 5 + i] = warm[OTHER + 5 + i], warm[11 + i]
                return _blended(P, Q, T1A, xA, sA, T1B, xB, sB, warm)
        warm[3] = 0.0  # a way was lost or the two met: solved cold below
    elif warm[3] > 0.0 and _within(P, warm[5:8], reach) and _within(Q, warm[8:11], reach):
        converged, phi, s, T1c, x, shots = _shoot_newton(_horizon_angle(warm[:3], Dinv, c0, u1, u2), warm[3], P, Q,
                                                         c0, rho, u1, u2, Dinv, A, int(warm[4]), scale, tol,
                                                         warm[11:15])
        warm[15] += shots
        if converged:
            warm[:3] = T1c
            warm[3] = s
            T1[:] = T1c
            T2[:] = x
            return 1, _way_length(P, Q, T1c, x, s), T1, T2, s
    warm[BOTH] = 0.0
    # initial arc length: the mapped great-circle arc T1s→T2s sampled in 64 chords
    theta = np.arccos(min(1.0, max(-1.0, T1s @ T2s)))
    e2 = T2s - (T2s @ T1s) * T1s
    ne2 = np.sqrt(e2 @ e2)
    s = 0.0
    if ne2 > 0.0:
        e2 = e2 / ne2
        prev = Dinv * T1s
        for k in range(1, 65):
            a = theta * k / 64.0
            cur = Dinv * (np.cos(a) * T1s + np.sin(a) * e2)
            d = cur - prev
            s += np.sqrt(d @ d)
            prev = cur
    # starts (horizon angle, arc length): the shortest planar path of the fan of planes
    # through P and Q on the side, the great circle, the shortest planar path on any side
    # (when no geodesic on the side is found near the first two)
    # starts (horizon angle, arc length, the arc angle its integrator steps cover)
    starts = np.zeros((4, 3))
    n_starts = 0
    n_fan = 0  # the first n_fan starts: the fan's local minima (one per way round)
    other = -1  # the start of the fan's other minimum (the other way round)
    if crosses(P, Q, axes):
        best, T1f, s_f, theta_f, best2, T1g, s_g, theta_g = _plane_fan(P1, Q1, Dinv, side)
        if best < np.inf:
            starts[n_starts, 0] = np.arctan2((T1f - c0) @ u2, (T1f - c0) @ u1)
            starts[n_starts, 1] = s_f
            n_starts += 1
            theta = max(theta, theta_f)
            if best2 < np.inf:
                starts[n_starts, 0] = np.arctan2((T1g - c0) @ u2, (T1g - c0) @ u1)
                starts[n_starts, 1] = s_g
                starts[n_starts, 2] = theta_g
                other = n_starts
                n_starts += 1
        n_fan = n_starts
    starts[n_starts, 1] = s
    n_starts += 1
    if crosses(P, Q, axes) and side @ side > 0.0:
        best, T1f, s_f, theta_f, _, _, _, _ = _plane_fan(P1, Q1, Dinv, np.zeros(3))
        if best < np.inf:
            starts[n_starts, 0] = np.arctan2((T1f - c0) @ u2, (T1f - c0) @ u1)
            starts[n_starts, 1] = s_f
            n_starts += 1
            theta = max(theta, theta_f)
    # integrator steps: a quarter of RK4's 48 + 300 θ/π (shoot_geodesic) for the arc of
    # the great circle and the fan's shortest path, and of the other way round's for it
    for k in range(n_starts):
        starts[k, 2] = 12 + int(75.0 * max(theta, starts[k, 2] if k == other else 0.0) / np.pi)
    # the geodesic from each start until one converges, and from both of the fan's
    # minima: the shorter way round is the path, and the two lengths' margin bounds the
    # warm start's reach (WARM_REACH)
    converged = False
    length, margin = np.inf, np.inf
    s_c = 0.0
    n_steps = 0
    T1c = np.zeros(3)
    xc = np.zeros(3)
    Dc = np.zeros(4)
    # the other way round's geodesic (l_o = inf: none found)
    l_o, s_o, steps_o = np.inf, 0.0, 0
    T1o = np.zeros(3)
    xo = np.zeros(3)
    Do = np.zeros(4)
    for k in range(n_starts):
        if converged and k >= n_fan:
            break
        D = np.zeros(4)
        steps = int(starts[k, 2])
        ok, _, s_k, T1k, xk, shots = _shoot_newton(starts[k, 0], starts[k, 1], P, Q, c0, rho, u1, u2, Dinv, A,
                                                   steps, scale, tol, D)
        warm[15] += shots
        if not ok:
            continue
        l_k = _way_length(P, Q, T1k, xk, s_k)
        if converged:
            e = T1k - T1c
            if e @ e < (SAME_GEODESIC * scale) ** 2:
                continue  # both starts found the same geodesic
            margin = abs(l_k - length)
            if l_k >= length:
                l_o, s_o, T1o, xo, Do, steps_o = l_k, s_k, T1k, xk, D, steps
                continue
            l_o, s_o, T1o, xo, Do, steps_o = length, s_c, T1c, xc, Dc, n_steps
        converged = True
        length, s_c, T1c, xc, Dc, n_steps = l_k, s_k, T1k, xk, D, steps
    if not converged:
        warm[3] = 0.0
        T1[:] = P
        T2[:] = Q
        return -2, np.nan, T1, T2, 0.0
    warm[:3] = T1c
    warm[3] = s_c
    warm[4] = n_steps
    warm[5:8] = P
    warm[8:11] = Q
    warm[11:15] = Dc
    reach = WARM_REACH * min(axes[0], min(axes[1], axes[2]))
    if margin < BLEND_SPAN:
        # both ways round are followed from here, each from its own warm start
        warm[BOTH] = 1.0
        warm[OTHER:OTHER + 3] = T1o
        warm[OTHER + 3] = s_o
        warm[OTHER + 4] = steps_o
        warm[OTHER + 5:OTHER + 9] = Do
        warm[REACH] = reach
        return _blended(P, Q, T1c, xc, s_c, T1o, xo, s_o, warm)
    # each way round's length moves by at most |ΔP| + |ΔQ|: within a quarter of the
    # margin the shorter one stays the shorter
    warm[REACH] = min(reach, 0.25 * (margin - BLEND_SPAN))
    T1[:] = T1c
    T2[:] = xc
    return 1, length, T1, T2, s_c


@njit(cache=True)
def _horizon(P, Q, axes, side):
    """The wrap of P→Q (3,) m mapped to the unit sphere (P' = P/axes, Q' = Q/axes;
    :func:`sphere_wrap`'s status and tangent points T1s, T2s) and P's horizon circle
    there: centre c0 = P'/|P'|², radius ρ = sqrt(1 − 1/|P'|²), unit vectors u1 (towards
    T1s) and u2 = P'/|P'| × u1 in its plane, the parametrisation of the geodesic's start
    T1(φ) (:func:`_horizon_point`). Returns (status, T1s, T2s, c0, ρ, u1, u2); the
    circle is zero unless status is 1."""
    P1 = P / axes
    Q1 = Q / axes
    st, _, T1s, T2s, _ = sphere_wrap(P1, Q1, 1.0, side / axes)
    if st != 1:
        return st, T1s, T2s, np.zeros(3), 0.0, np.zeros(3), np.zeros(3)
    pp = P1 @ P1
    c0 = P1 / pp
    rho = np.sqrt(1.0 - 1.0 / pp)
    u1 = T1s - c0
    u1 = u1 / np.sqrt(u1 @ u1)
    n1 = P1 / np.sqrt(pp)
    u2 = np.array([n1[1] * u1[2] - n1[2] * u1[1], n1[2] * u1[0] - n1[0] * u1[2], n1[0] * u1[1] - n1[1] * u1[0]])
    return st, T1s, T2s, c0, rho, u1, u2


#: the shooting residual's derivative in :func:`ellipsoid_tangent_moves` is a forward
#: difference of this step (rad of horizon angle; times |P| + |Q| for the arc length)
SHOT_STEP = 1e-7


@njit(cache=True)
def ellipsoid_tangent_moves(P, Q, axes, side, warm, moves_P, moves_Q):
    """The moves (m, 3) m of the geodesic's tangent points T1 and T2 when the anchors
    P, Q (3,) m move by moves_P[q], moves_Q[q] (m, 3) m (small: finite-difference steps),
    to first order, from the geodesic of ``warm`` (the node's last solve, at P, Q:
    :func:`ellipsoid_wrap_from`) by the implicit function theorem on the shooting
    residual r(φ, s; P, Q) = 0 instead of a Newton solve per move.

    With z = (φ, s) and D = ∂r/∂z (two forward-difference shots, step SHOT_STEP): a move
    of the anchors leaves r' = r(z; P', Q') at the same geodesic start (T1 held on the
    moved horizon, one shot), and z' = z − D⁻¹ r'; T1' = T1(φ') on the moved horizon,
    T2' = x' + ∂x/∂z (z' − z), x the shot's end. 2 + m shots where solving again takes
    m Newton solves of 3–4 shots each (:func:`~.wrap_stiffness.single_wrap_stiffness_along`:
    m = 4). The step count is the last cold solve's, as for every warm solve. Returns
    (ok, ΔT1 (m, 3), ΔT2 (m, 3)); ok False when the mapped wrap (:func:`_horizon`) is not
    in contact at P, Q or a moved pair, or D is singular (then solve each move instead)."""
    m = moves_P.shape[0]
    dT1 = np.zeros((m, 3))
    dT2 = np.zeros((m, 3))
    st, _, _, c0, rho, u1, u2 = _horizon(P, Q, axes, side)
    if st != 1 or warm[3] <= 0.0:
        return False, dT1, dT2
    A = 1.0 / (axes * axes)
    n_steps = int(warm[4])
    s = warm[3]
    g = warm[:3] / axes - c0
    phi = np.arctan2(g @ u2, g @ u1)
    r0, T1, x0 = _shoot_residual(phi, s, P, Q, c0, rho, u1, u2, axes, A, n_steps)
    h_phi = SHOT_STEP
    h_s = SHOT_STEP * (np.sqrt(P @ P) + np.sqrt(Q @ Q))
    r_a, _, x_a = _shoot_residual(phi + h_phi, s, P, Q, c0, rho, u1, u2, axes, A, n_steps)
    r_b, _, x_b = _shoot_residual(phi, s + h_s, P, Q, c0, rho, u1, u2, axes, A, n_steps)
    d00, d10 = (r_a[0] - r0[0]) / h_phi, (r_a[1] - r0[1]) / h_phi  # ∂r/∂φ
    d01, d11 = (r_b[0] - r0[0]) / h_s, (r_b[1] - r0[1]) / h_s  # ∂r/∂s
    det = d00 * d11 - d01 * d10
    if det == 0.0:
        return False, dT1, dT2
    x_phi = (x_a - x0) / h_phi
    x_s = (x_b - x0) / h_s
    for q in range(m):
        Pm = P + moves_P[q]
        Qm = Q + moves_Q[q]
        st, _, _, cm, rhom, v1, v2 = _horizon(Pm, Qm, axes, side)
        if st != 1:
            return False, dT1, dT2
        gm = T1 / axes - cm
        phim = np.arctan2(gm @ v2, gm @ v1)
        rm, _, xm = _shoot_residual(phim, s, Pm, Qm, cm, rhom, v1, v2, axes, A, n_steps)
        d_phi = -(d11 * rm[0] - d01 * rm[1]) / det
        d_s = -(-d10 * rm[0] + d00 * rm[1]) / det
        dT1[q] = _horizon_point(phim + d_phi, cm, rhom, v1, v2, axes) - T1
        dT2[q] = xm + x_phi * d_phi + x_s * d_s - x0
    return True, dT1, dT2


@njit(cache=True)
def _within(a, b, r):
    """|a − b| < r for a, b (3,) m."""
    d = a - b
    return d @ d < r * r


@njit(cache=True)
def _shoot_newton(phi, s, P, Q, c0, rho, u1, u2, Dinv, A, n_steps, scale, tol, D):
    """Newton on (horizon angle φ, arc length s) from the given start until the end
    residual is below ``tol`` (m): (converged, φ, s, T1, geodesic end, shots taken).

    D (4,): the residual's derivatives [∂r/∂φ (2,) m/rad, ∂r/∂s (2,)], read and written;
    all zero: none. With D given, steps are first taken with it (chord Newton, one shot
    each) while each cuts the residual by at least CHORD_RATE: from a warm start a
    finite-difference step away, the shooting's derivative has barely changed, and two
    or three shots converge where Newton's differenced steps take seven. Otherwise each
    step differences the derivative (two shots), is damped (at most 0.3 rad of horizon
    angle, half the arc), then halved until the residual decreases (a backtracking line
    search; the accepted shot is the next iterate's residual)."""
    converged = False
    res, T1c, x = _shoot_residual(phi, s, P, Q, c0, rho, u1, u2, Dinv, A, n_steps)
    shots = 1
    chord = D[0] != 0.0 or D[1] != 0.0 or D[2] != 0.0 or D[3] != 0.0
    for _ in range(60):
        norm = np.sqrt(res @ res)
        if norm < tol:
            converged = True
            break
        if chord:
            det = D[0] * D[3] - D[1] * D[2]
            if det != 0.0:
                d_phi = -(D[3] * res[0] - D[2] * res[1]) / det
                d_s = -(-D[1] * res[0] + D[0] * res[1]) / det
                if abs(d_phi) <= 0.3 and s + d_s >= 0.5 * s:
                    res_t, T1_t, x_t = _shoot_residual(phi + d_phi, s + d_s, P, Q, c0, rho, u1, u2, Dinv, A, n_steps)
                    shots += 1
                    if np.sqrt(res_t @ res_t) < CHORD_RATE * norm:
                        phi += d_phi
                        s += d_s
                        res, T1c, x = res_t, T1_t, x_t
                        continue
            chord = False  # the derivative is differenced again at this iterate
        h_phi = 1e-7
        h_s = 1e-7 * scale
        r_phi = (_shoot_residual(phi + h_phi, s, P, Q, c0, rho, u1, u2, Dinv, A, n_steps)[0] - res) / h_phi
        r_s = (_shoot_residual(phi, s + h_s, P, Q, c0, rho, u1, u2, Dinv, A, n_steps)[0] - res) / h_s
        shots += 2
        D[0], D[1], D[2], D[3] = r_phi[0], r_phi[1], r_s[0], r_s[1]
        det = r_phi[0] * r_s[1] - r_phi[1] * r_s[0]
        if det == 0.0:
            break
        d_phi = -(r_s[1] * res[0] - r_s[0] * res[1]) / det
        d_s = -(-r_phi[1] * res[0] + r_phi[0] * res[1]) / det
        f = 1.0
        if abs(d_phi) > 0.3:
            f = 0.3 / abs(d_phi)
        if s + f * d_s < 0.5 * s:
            f = min(f, 0.5 * s / abs(d_s))
        for _ in range(12):
            res_t, T1_t, x_t = _shoot_residual(phi + f * d_phi, s + f * d_s, P, Q, c0, rho, u1, u2, Dinv, A,
                                               n_steps)
            shots += 1
            if np.sqrt(res_t @ res_t) < norm:
                break
            f *= 0.5
        phi += f * d_phi
        s += f * d_s
        res, T1c, x = res_t, T1_t, x_t
    return converged, phi, s, T1c, x, shots


@njit(cache=True)
def _placement_grad(a, d, R):
    """g = ∇h(a)·d of h(a) = |a|² − 4R ρ(a), ρ = sqrt(a_x² + a_y²), the Hessian H (3, 3)
    of h and ∇h (3,) at a; d = Q − P (:func:`torus_placement`)."""
    rho = np.sqrt(a[0] * a[0] + a[1] * a[1])
    gh = 2.0 * a
    gh[0] -= 4.0 * R * a[0] / rho
    gh[1] -= 4.0 * R * a[1] / rho
    H = 2.0 * np.eye(3)
    for i in range(2):
        for j in range(2):
            H[i, j] -= 4.0 * R * ((1.0 if i == j else 0.0) / rho - a[i] * a[j] / rho ** 3)
    return gh @ d, H, gh


@njit(cache=True)
def torus_placement(P, Q, R):
    """OpenSim's placement of the cylinder on a torus (centre circle radius R m, axis z)
    for the line P→Q (3,) m: (φ rad, t). WrapTorus.cpp searches, from each end of the
    line, for a root of its residual c2 + 2u − 2R (2 c4 u + 2 c3)/ρ, which is
    d/du [|a|² − 4R ρ(a)] at a = P + u n (n the unit direction; ρ the distance of a from
    the axis): the line point nearest the circle of radius 2R, not R (a factor 2 of its
    derivative). Of the two roots it keeps the one nearer the circle of radius R, and
    places the cylinder at the azimuth φ of that line point a = P + t (Q − P).
    Here each root is found by damped Newton on g(t) = ∇h(a)·(Q − P) from t = 0 and t = 1
    (h = |a|² − 4R ρ); converged to round-off (OpenSim: Levenberg–Marquardt, tolerance
    1e-4, whose result agrees to 1e-6 rad in tests)."""
    d = Q - P
    best, phi_b, t_b = np.inf, 0.0, 0.0
    for t in (0.0, 1.0):
        lam = 0.0
        g, H, _ = _placement_grad(P + t * d, d, R)
        for _ in range(100):
            gp = d @ (H @ d)
            step = -g * gp / (gp * gp + lam)
            g_new, H_new, _ = _placement_grad(P + (t + step) * d, d, R)
            if abs(g_new) < abs(g):
                t += step
                g, H = g_new, H_new
                lam *= 0.1
                if abs(step) < 1e-15:
                    break
            else:
                lam = max(10.0 * lam, 1e-8 * gp * gp + 1e-300)
                if lam > 1e30:
                    break
        a = P + t * d
        rho = np.sqrt(a[0] * a[0] + a[1] * a[1])
        dist = a @ a + R * R - 2.0 * R * rho
        if dist < best:
            best, phi_b, t_b = dist, np.arctan2(a[1], a[0]), t
    return phi_b, t_b


@njit(cache=True)
def _torus_frame(phi, R):
    """Origin C (3,) and axes (rows x, y, z) of OpenSim's cylinder on a torus at the
    circle point of angle φ: x towards the torus axis, y = −z_torus, z = x × y."""
    c, s = np.cos(phi), np.sin(phi)
    A = np.array([[-c, -s, 0.0], [0.0, 0.0, -1.0], [s, -c, 0.0]])
    return np.array([R * c, R * s, 0.0]), A


@njit(cache=True)
def torus_wrap(P, Q, R, r):
    """OpenSim's WrapTorus (outer radius R = the tube's centre circle, inner radius r =
    the tube's radius, axis z) for P→Q (3,) m: the infinite cylinder of radius r whose
    axis is tangent to the centre circle at C(φ), φ by OpenSim's placement rule
    (:func:`torus_placement`), wrapped on the side facing the torus axis (OpenSim's
    quadrant +x of that cylinder)."""
    phi, _ = torus_placement(P, Q, R)
    C, A = _torus_frame(phi, R)
    out = cylinder_wrap(A @ (P - C), A @ (Q - C), r, np.array([1.0, 0.0, 0.0]))
    if out[0] != 1:
        return out[0], out[1], P.copy(), Q.copy(), 0.0
    return 1, out[1], C + A.T @ out[2], C + A.T @ out[3], out[4]


@njit(cache=True)
def torus_gradients(P, Q, R, T1, T2):
    """The parts of ∂l/∂P and ∂l/∂Q (3,) of a torus wrap (surface frame) that come from
    the cylinder's placement φ(P, Q): ∂l/∂φ ∂φ/∂P, ∂l/∂φ ∂φ/∂Q. The cylinder turns about
    the torus axis with φ, as if P and Q turned the other way, so ∂l/∂φ = e1·(ẑ × P)
    − e2·(ẑ × Q) (e1, e2 the unit directions P→T1, T2→Q). φ is the azimuth of the line
    point a = P + t d, d = Q − P, where g(t, P, Q) = ∇h(a)·d = 0 (:func:`torus_placement`);
    by the implicit function theorem dt/dX = −(∂g/∂X)/(dᵀ H d) with ∂g/∂P = (1 − t) H d −
    ∇h, ∂g/∂Q = t H d + ∇h, and dφ/dP = (1 − t) ∇φ + (d·∇φ) dt/dP, dφ/dQ = t ∇φ +
    (d·∇φ) dt/dQ, ∇φ = (−a_y, a_x, 0)/ρ²."""
    phi, t = torus_placement(P, Q, R)
    d = Q - P
    a = P + t * d
    _, H, gh = _placement_grad(a, d, R)
    Hd = H @ d
    g_t = d @ Hd
    dt_dP = -((1.0 - t) * Hd - gh) / g_t
    dt_dQ = -(t * Hd + gh) / g_t
    rho2 = a[0] * a[0] + a[1] * a[1]
    gphi = np.array([-a[1] / rho2, a[0] / rho2, 0.0])
    dg = d @ gphi
    e1 = (T1 - P) / np.sqrt((T1 - P) @ (T1 - P))
    e2 = (Q - T2) / np.sqrt((Q - T2) @ (Q - T2))
    l_phi = e1 @ np.array([-P[1], P[0], 0.0]) - e2 @ np.array([-Q[1], Q[0], 0.0])
    return l_phi * ((1.0 - t) * gphi + dg * dt_dP), l_phi * (t * gphi + dg * dt_dQ)


# --- paths through points and surfaces (see openfdk.forces.wrapping) -----------------

POINT, CYLINDER, SPHERE, ELLIPSOID, TORUS = 0, 1, 2, 3, 4
SURFACE_KINDS = {"cylinder": CYLINDER, "sphere": SPHERE, "ellipsoid": ELLIPSOID, "torus": TORUS}
#: Newton tolerance of the ellipsoid geodesic end condition (m)
ELLIPSOID_TOL = 1e-13
#: status codes of :func:`wrapped_path_lengths`
STATUS_TEXT = {-1: "a path point lies inside the wrapping surface", -2: "the ellipsoid geodesic did not converge",
               -3: "adjacent wrapping surfaces did not settle"}


@njit(cache=True)
def crosses(P, Q, axes):
    """Whether the straight segment P→Q (3,) m, both ends outside, crosses the ellipsoid
    (or sphere) with semi-axes ``axes`` (3,) m: mapped to the unit sphere, the point of
    the segment nearest the centre lies strictly between the ends and inside."""
    P1 = P / axes
    d = Q / axes - P1
    dd = d @ d
    if dd == 0.0:
        return False
    t = -(P1 @ d) / dd
    if t <= 0.0 or t >= 1.0:
        return False
    x = P1 + t * d
    return x @ x < 1.0


#: flags of a surface (``limits[:, 1]`` of :func:`wrapped_path_lengths`); OPENSIM_PLANE: an
#: ellipsoid follows OpenSim's planar rule (:mod:`.wrap_ellipsoid_plane`)
CROSSING_ONLY, INSIDE_STRAIGHT, OPENSIM_PLANE = 1, 2, 4


@njit(cache=True)
def _wrap_one(kind, P_S, Q_S, dims, side, half_length, flags, warm):
    """One surface: the kernel of ``kind``; a cylinder of finite ``half_length`` (m) is
    left (status 0, straight) when both tangent points lie beyond ±half_length along
    its axis. ``flags``: CROSSING_ONLY, a sphere or ellipsoid wraps only while the
    straight segment crosses it (OpenSim's rule), ``side`` then only picks the way
    round; INSIDE_STRAIGHT, an anchor inside the surface leaves the path straight
    (OpenSim's rule) instead of status −1; OPENSIM_PLANE, an ellipsoid's path is OpenSim's
    planar curve (:func:`~openfdk.forces.wrap_ellipsoid_plane.plane_wrap`, ``side`` its
    quadrant). ``warm`` (WARM_SIZE,): the node's warm start (:func:`ellipsoid_wrap_from`), or
the OpenSim-rule ellipsoid's row (its last core and gradient model)."""
    if kind == ELLIPSOID and flags & OPENSIM_PLANE:
        out = plane_wrap_stashed(P_S, Q_S, dims, side, warm)
    else:
        out = _wrap_rules(kind, P_S, Q_S, dims, side, half_length, flags & CROSSING_ONLY, warm)
    if out[0] == -1 and flags & INSIDE_STRAIGHT:
        u = Q_S - P_S
        return 0, np.sqrt(u @ u), P_S.copy(), Q_S.copy(), 0.0
    return out


@njit(cache=True)
def _wrap_rules(kind, P_S, Q_S, dims, side, half_length, crossing_only, warm):
    if kind == TORUS:
        return torus_wrap(P_S, Q_S, dims[0], dims[1])
    if kind == CYLINDER:
        out = cylinder_wrap(P_S, Q_S, dims[0], side)
        if out[0] == 1 and abs(out[2][2]) > half_length and abs(out[3][2]) > half_length:
            u = Q_S - P_S
            return 0, np.sqrt(u @ u), P_S.copy(), Q_S.copy(), 0.0
        return out
    if crossing_only != 0 and (P_S / dims) @ (P_S / dims) > 1.0 and (Q_S / dims) @ (Q_S / dims) > 1.0 \
            and not crosses(P_S, Q_S, dims):
        warm[3] = 0.0  # lifted off: the next wrap starts cold
        u = Q_S - P_S
        return 0, np.sqrt(u @ u), P_S.copy(), Q_S.copy(), 0.0
    if kind == SPHERE:
        return sphere_wrap(P_S, Q_S, dims[0], side)
    return ellipsoid_wrap_from(P_S, Q_S, dims, side, ELLIPSOID_TOL, warm)


@njit(cache=True)
def _mandatory(kind, P, Q, dims, side):
    """Whether OpenSim counts the wrap of P→Q (surface frame, m) as mandatory (the
    straight line crosses the surface; with a quadrant, an end on its side): an
    ellipsoid always (it wraps only where crossed), a sphere with a side, a cylinder
    whose straight line crosses its circle in projection."""
    if kind == ELLIPSOID:
        return True
    if kind == TORUS:
        return False  # OpenSim's WrapTorus answers "wrapped", never "mandatory"
    sided = side @ side > 0.0
    on_side = (P @ side > 0.0) or (Q @ side > 0.0)
    if kind == SPHERE:
        return sided and on_side and crosses(P, Q, dims)
    dx, dy = Q[0] - P[0], Q[1] - P[1]
    dd = dx * dx + dy * dy
    if dd == 0.0:
        return False
    t = -(P[0] * dx + P[1] * dy) / dd
    if t <= 0.0 or t >= 1.0:
        return False
    x, y = P[0] + t * dx, P[1] + t * dy
    return x * x + y * y < dims[0] * dims[0] and (not sided or on_side)


@njit(cache=True)
def _anchor(j, step, kinds, active, present, X_W, T1_W, T2_W):
    """Nearest node before (step −1) or after (+1) node j that the path touches: a present
    point's position, or T2 (before) / T1 (after) of a surface in contact."""
    k = j + step
    while (kinds[k] != POINT and not active[k]) or (kinds[k] == POINT and not present[k]):
        k += step
    if kinds[k] == POINT:
        return X_W[k]
    return T2_W[k] if step < 0 else T1_W[k]


@njit(cache=True)
def _in_span(j, kinds, present, span):
    """Whether surface node j may wrap: its nearest present points before and after lie
    within its span (node indices of its PathWrap range's first and last points, −1: no
    span). With conditional points, OpenSim wraps between the first and last *active*
    points of the range, so a segment reaching outside the range is not a candidate."""
    if span[j, 0] < 0:
        return True
    a = j - 1
    while kinds[a] != POINT or not present[a]:
        a -= 1
    b = j + 1
    while kinds[b] != POINT or not present[b]:
        b += 1
    return a >= span[j, 0] and b <= span[j, 1]


@njit(cache=True)
def _add_moving(L, p, e, node, move, dX_W, U, sign):
    """L[p] += sign eᵀ dX_W[node] ∂u/∂q̂ of a moving point (move[node] ≥ 0: its
    coordinate's row of U (n_c, n); dX_W (N, 3) m per unit coordinate, world)."""
    if node < 0 or move[node] < 0:
        return
    s = sign * (e @ dX_W[node])
    if s != 0.0:
        for c in range(U.shape[1]):
            L[p, c] += s * U[move[node], c]


@njit(cache=True)
def _add_point_gradient(L, p, column, p_WB, R_WB, i, x, g):
    """L[p] += gᵀ M of the point x (3,) m fixed in body i (g (3,) world)."""
    c = column[i]
    if c < 0:
        return
    sW = x - p_WB[i]
    x0 = sW[1] * g[2] - sW[2] * g[1]
    x1 = sW[2] * g[0] - sW[0] * g[2]
    x2 = sW[0] * g[1] - sW[1] * g[0]
    R = R_WB[i]
    for r in range(3):
        L[p, c + r] += g[r]
        L[p, c + 3 + r] += R[0, r] * x0 + R[1, r] * x1 + R[2, r] * x2


@njit(cache=True)
def _add_placement(L, p, j, kinds, present, column, p_WB, R_WB, bodies, X_W, R_WS, dims, sides, move, dX_W,
                   U, warm):
    """L[p] += the terms of surface j's length that holding its tangent points misses: a
    torus's placement (:func:`torus_gradients`), an OpenSim-rule ellipsoid's
    non-stationary plane (:func:`~openfdk.forces.wrap_ellipsoid_plane.plane_wrap_gradients`),
    for its anchors, the nearest present points a, b (such a surface is not next to
    another): g_Pᵀ (M_a − M_{surface at a}) + g_Qᵀ (M_b − M_{surface at b})."""
    a = j - 1
    while kinds[a] != POINT or not present[a]:
        a -= 1
    b = j + 1
    while kinds[b] != POINT or not present[b]:
        b += 1
    R = R_WS[j]
    P_S = R.T @ (X_W[a] - X_W[j])
    Q_S = R.T @ (X_W[b] - X_W[j])
    if kinds[j] == TORUS:
        st, _, T1, T2, _ = torus_wrap(P_S, Q_S, dims[j, 0], dims[j, 1])
        if st != 1:
            return
        gP, gQ = torus_gradients(P_S, Q_S, dims[j, 0], T1, T2)
    else:
        st, gP, gQ = plane_wrap_gradients(P_S, Q_S, dims[j], sides[j], warm[j])
        if st != 1:
            return
    for node, g in ((a, R @ gP), (b, R @ gQ)):
        _add_point_gradient(L, p, column, p_WB, R_WB, bodies[node], X_W[node], g)
        _add_point_gradient(L, p, column, p_WB, R_WB, bodies[j], X_W[node], -g)
        if move[node] >= 0:
            s = g @ dX_W[node]
            for c in range(U.shape[1]):
                L[p, c] += s * U[move[node], c]


@njit(cache=True)
def _add_segment(L, p, column, p_WB, R_WB, ia, xa, ib, xb, w):
    """L[p] += w eᵀ (M_B − M_A) for the segment from xa (fixed in body ia) to xb (in ib);
    returns its length (m)."""
    u = xb - xa
    length = np.sqrt(u @ u)
    if length == 0.0:
        return 0.0
    e = u / length
    for side in range(2):
        i = ia if side == 0 else ib
        c = column[i]
        if c < 0:
            continue
        sign = -w if side == 0 else w
        sW = (xa if side == 0 else xb) - p_WB[i]
        x0 = sW[1] * e[2] - sW[2] * e[1]
        x1 = sW[2] * e[0] - sW[0] * e[2]
        x2 = sW[0] * e[1] - sW[1] * e[0]
        R = R_WB[i]
        for r in range(3):
            L[p, c + r] += sign * e[r]
            L[p, c + 3 + r] += sign * (R[0, r] * x0 + R[1, r] * x1 + R[2, r] * x2)
    return length


@njit(cache=True)
def _add_leg(L, p, column, p_WB, R_WB, ia, xa, na, ib, xb, nb, move, dX_W, U, w):
    """L[p] += w (eᵀ (M_B − M_A) + the moving points' terms) for the segment from xa
    (3,) m, fixed in body ia or a moving point's node na (−1: none), to xb in ib (node
    nb); returns its length (m). w: the way round's weight (1 but for a blended wrap)."""
    d = _add_segment(L, p, column, p_WB, R_WB, ia, xa, ib, xb, w)
    if d > 0.0:
        e = (xb - xa) / d
        _add_moving(L, p, e, nb, move, dX_W, U, w)
        _add_moving(L, p, e, na, move, dX_W, U, -w)
    return d


@njit(cache=True)
def _blend_of(j, j1, kinds, limits, active, present, last_node, warm):
    """The weight (0–1) of surface node j's other way round (:func:`_blended`) when it
    applies: j a geodesic ellipsoid whose anchors are path points (the last node a point,
    the next node the path touches a point), else 0."""
    if kinds[j] != ELLIPSOID or int(limits[j, 1]) & OPENSIM_PLANE or last_node < 0:
        return 0.0
    k = j + 1
    while k < j1 - 1 and ((kinds[k] == POINT and not present[k]) or (kinds[k] != POINT and not active[k])):
        k += 1
    if kinds[k] != POINT:
        return 0.0
    return warm[j, BLEND_W]


@njit(cache=True)
def wrapped_path_lengths(p_WB, R_WB, column, kinds, bodies, p_B, R_BS, dims, sides, limits, start, n_coords, warm):
    """Paths of fixed points and surfaces (:func:`wrapped_moving_path_lengths` with every
    point present, none moving and no spans)."""
    N = kinds.shape[0]
    return wrapped_moving_path_lengths(p_WB, R_WB, column, kinds, bodies, p_B, R_BS, dims, sides, limits, start,
                                       n_coords, np.ones(N, dtype=np.bool_), np.zeros((N, 3)),
                                       np.full(N, -1, dtype=np.int64), np.zeros((1, n_coords)),
                                       np.full((N, 2), -1, dtype=np.int64), warm)


@njit(cache=True)
def wrapped_moving_path_lengths(p_WB, R_WB, column, kinds, bodies, p_B, R_BS, dims, sides, limits, start, n_coords,
                                present, dX_W, move, U, span, warm):
    """Lengths, Jacobians and tangent points of paths through points and surfaces.

    p_WB (nb, 3) m, R_WB (nb, 3, 3); column (nb,) first q̂ column of each body (−1 fixed);
    nodes of all paths concatenated: kinds (N,) (POINT, CYLINDER, SPHERE, ELLIPSOID),
    bodies (N,), p_B (N, 3) m (point, or surface origin, in the body frame), R_BS (N, 3, 3),
    dims (N, 3) m, sides (N, 3); limits (N, 3): a cylinder's half length (m, inf: infinite),
    the surface's flags (CROSSING_ONLY, INSIDE_STRAIGHT; :func:`_wrap_one`) and its group
    (−1: none; the nodes of one group in a path are one surface listed in several
    segments, of which one wraps: OpenSim's PathWrap over a range of points, see
    :func:`_mandatory`); path k owns nodes start[k]:start[k+1].
    Coordinate-dependent points (OpenSim's ConditionalPathPoint, MovingPathPoint):
    present (N,) bool, a point not present is left out of the path; p_B of a moving point
    is its current location, dX_W (N, 3) m its world velocity per unit of its coordinate
    (zero where clamped), move (N,) the coordinate's row of U (n_c, n) = ∂u/∂q̂ (−1: a
    fixed point); span (N, 2) node indices of a surface's PathWrap range ends (−1: none,
    :func:`_in_span`). warm (N, WARM_SIZE): each ellipsoid node's warm start, read and
    written (:func:`ellipsoid_wrap_from`; zeros: none); the results equal cold solves to
    the geodesic's Newton tolerance.
    Returns l (n_paths,) m, L (n_paths, n_coords), status (n_paths,) (0 ok, < 0 see
    ``STATUS_TEXT``), T_W (N, 2, 3) m the world tangent points of each surface in
    contact (NaN when not in contact or for points).
    """
    n_paths = start.shape[0] - 1
    N = kinds.shape[0]
    l = np.zeros(n_paths)
    L = np.zeros((n_paths, n_coords))
    status = np.zeros(n_paths, dtype=np.int64)
    T_W = np.full((N, 2, 3), np.nan)
    X_W = np.zeros((N, 3))
    R_WS = np.zeros((N, 3, 3))
    for j in range(N):
        i = bodies[j]
        X_W[j] = p_WB[i] + R_WB[i] @ p_B[j]
        R_WS[j] = R_WB[i] @ R_BS[j]
    active = np.zeros(N, dtype=np.bool_)
    T1_W = np.zeros((N, 3))
    T2_W = np.zeros((N, 3))
    arc = np.zeros(N)
    group = np.empty(N, dtype=np.int64)
    for j in range(N):
        group[j] = int(limits[j, 2])
    for p in range(n_paths):
        j0, j1 = start[p], start[p + 1]
        adjacent = False
        grouped = False
        for j in range(j0 + 1, j1 - 1):
            if kinds[j] != POINT:
                k = j + 1
                while kinds[k] == POINT and not present[k] and k < j1 - 1:
                    k += 1
                if kinds[k] != POINT:
                    adjacent = True
            if kinds[j] != POINT and group[j] >= 0:
                grouped = True
        scale = 0.0
        for j in range(j0, j1):
            scale = max(scale, np.sqrt((X_W[j] - X_W[j0]) @ (X_W[j] - X_W[j0])))
        settled = False
        for sweep in range(200 if adjacent or grouped else 1):
            change = 0.0
            for j in range(j0 + 1, j1 - 1):
                if kinds[j] == POINT:
                    continue
                g = group[j]
                if g >= 0:
                    first = j
                    for k in range(j0 + 1, j):
                        if kinds[k] != POINT and group[k] == g:
                            first = k
                            break
                    if first != j:
                        continue  # a candidate of a group already decided in this sweep
                    # one segment of the group wraps (OpenSim's PathWrap): the first whose straight
                    # line crosses the surface ("mandatory"), else the one that lengthens least
                    was = -1
                    for k in range(j, j1 - 1):
                        if kinds[k] != POINT and group[k] == g:
                            if active[k]:
                                was = k
                            active[k] = False
                    win, best = -1, np.inf
                    wT1, wT2, wa = np.zeros(3), np.zeros(3), 0.0
                    for k in range(j, j1 - 1):
                        if kinds[k] == POINT or group[k] != g or not _in_span(k, kinds, present, span):
                            continue
                        P_W = _anchor(k, np.int64(-1), kinds, active, present, X_W, T1_W, T2_W)
                        Q_W = _anchor(k, np.int64(1), kinds, active, present, X_W, T1_W, T2_W)
                        R = R_WS[k]
                        P_S = R.T @ (P_W - X_W[k])
                        Q_S = R.T @ (Q_W - X_W[k])
                        st, total, T1, T2, a = _wrap_one(kinds[k], P_S, Q_S, dims[k], sides[k], limits[k, 0],
                                                         int(limits[k, 1]), warm[k])
                        if st < 0:
                            status[p] = st
                            break
                        if st != 1:
                            continue
                        u = Q_S - P_S
                        grow = total - np.sqrt(u @ u)
                        if _mandatory(kinds[k], P_S, Q_S, dims[k], sides[k]):
                            win, wT1, wT2, wa = k, X_W[k] + R @ T1, X_W[k] + R @ T2, a
                            break
                        if grow < best:
                            win, best, wT1, wT2, wa = k, grow, X_W[k] + R @ T1, X_W[k] + R @ T2, a
                    if status[p] < 0:
                        break
                    if win != was:
                        change = np.inf
                    elif win >= 0:
                        change = max(change, np.sqrt((wT1 - T1_W[win]) @ (wT1 - T1_W[win])),
                                     np.sqrt((wT2 - T2_W[win]) @ (wT2 - T2_W[win])))
                    if win >= 0:
                        active[win] = True
                        T1_W[win] = wT1
                        T2_W[win] = wT2
                        arc[win] = wa
                    continue
                if not _in_span(j, kinds, present, span):
                    if active[j]:
                        change = np.inf
                    active[j] = False
                    continue
                P_W = _anchor(j, np.int64(-1), kinds, active, present, X_W, T1_W, T2_W)
                Q_W = _anchor(j, np.int64(1), kinds, active, present, X_W, T1_W, T2_W)
                R = R_WS[j]
                st, _, T1, T2, a = _wrap_one(kinds[j], R.T @ (P_W - X_W[j]), R.T @ (Q_W - X_W[j]), dims[j], sides[j],
                                             limits[j, 0], int(limits[j, 1]), warm[j])
                if st < 0:
                    status[p] = st
                    break
                new_active = st == 1
                t1 = X_W[j] + R @ T1
                t2 = X_W[j] + R @ T2
                if new_active != active[j]:
                    change = np.inf
                elif new_active:
                    change = max(change, np.sqrt((t1 - T1_W[j]) @ (t1 - T1_W[j])), np.sqrt((t2 - T2_W[j]) @ (t2 - T2_W[j])))
                active[j] = new_active
                T1_W[j] = t1
                T2_W[j] = t2
                arc[j] = a
            if status[p] < 0:
                break
            if change <= 1e-14 * scale:
                settled = True
                break
        if status[p] < 0:
            l[p] = np.nan
            continue
        if adjacent and not grouped and not settled:
            status[p] = -3
            l[p] = np.nan
            continue
        # l = Σ segments + Σ arcs;  L = Σ eᵀ (M_B − M_A), tangent points fixed in their bodies
        # a moving point's segments add eᵀ dX_W ∂u/∂q̂ (last_node: the point the segment starts at, −1: a
        # tangent point)
        # a blended wrap (both ways round, :func:`_blended`) adds each way's legs with its
        # weight (the soft minimum's gradient) and the soft minimum's length: w_b the
        # weight of the surface just passed, T2b its other way's T2 (world)
        last_body, last_x, last_node = bodies[j0], X_W[j0], j0
        total = 0.0
        w_b = 0.0
        T2b = np.zeros(3)
        for j in range(j0 + 1, j1):
            if kinds[j] == POINT:
                if not present[j]:
                    continue
                total += _add_leg(L, p, column, p_WB, R_WB, last_body, last_x, last_node, bodies[j], X_W[j], j, move,
                                  dX_W, U, 1.0 - w_b)
                if w_b > 0.0:
                    _add_leg(L, p, column, p_WB, R_WB, last_body, T2b, np.int64(-1), bodies[j], X_W[j], j, move, dX_W, U, w_b)
                    w_b = 0.0
                last_body, last_x, last_node = bodies[j], X_W[j], j
            elif active[j]:
                w = _blend_of(j, j1, kinds, limits, active, present, last_node, warm)
                total += _add_leg(L, p, column, p_WB, R_WB, last_body, last_x, last_node, bodies[j], T1_W[j],
                                  np.int64(-1), move, dX_W, U, 1.0 - w) + arc[j]
                if w > 0.0:
                    R = R_WS[j]
                    _add_leg(L, p, column, p_WB, R_WB, last_body, last_x, last_node, bodies[j],
                             X_W[j] + R @ warm[j, BLEND_T1:BLEND_T1 + 3], np.int64(-1), move, dX_W, U, w)
                    T2b = X_W[j] + R @ warm[j, BLEND_T2:BLEND_T2 + 3]
                    total += warm[j, BLEND_DL]
                    w_b = w
                if kinds[j] == TORUS or (kinds[j] == ELLIPSOID and int(limits[j, 1]) & OPENSIM_PLANE):
                    _add_placement(L, p, j, kinds, present, column, p_WB, R_WB, bodies, X_W, R_WS, dims, sides, move,
                                   dX_W, U, warm)
                T_W[j, 0] = T1_W[j]
                T_W[j, 1] = T2_W[j]
                last_body, last_x, last_node = bodies[j], T2_W[j], -1
        l[p] = total
    return l, L, status, T_W


