"""OpenSim's WrapEllipsoid path (numba): a curve in a plane through both anchors, measured
as a polyline of about 1 mm chords, with OpenSim's ``quadrant``.

OpenSim 4.6's WrapEllipsoid.cpp (method ``hybrid``, its default) does not compute the
geodesic. Its rule, re-derived here (own code) in the scaled frame X' = f X,
f = 3/(a + b + c), semi-axes a_i' = f a_i:

1. No wrap unless both anchors are outside and the segment P→Q crosses the ellipsoid at
   r_P, r_Q (the entry and exit points, both strictly between P and Q).
2. A point c1 on the surface picks the wrapping plane (through P, Q and c1):
   * "Frans": on the coordinate axis k most parallel to P→Q (largest |u_k|, u the unit
     direction), the chord point s_k where x_k = 0, and c1 its nearest surface point in
     that coordinate plane (a 2-D ellipse problem);
   * "fan": the unit vectors from 298 chord points r_P + (i/300)(r_Q − r_P) to their
     nearest surface points are summed; c1 is the surface point nearest the chord
     midpoint plus that unit sum;
   * blend: |u_k| is first faded towards 0.7073 when s_k lies within 0.3 of the chord's
     ends (0 outside it); |u_k| ≥ 0.9 gives Frans, ≤ 0.7073 gives the fan, between them
     c1 is the surface point nearest the mix w c1_Frans + (1 − w) c1_fan,
     w = (|u_k| − 0.7073)/(0.9 − 0.7073).
3. Quadrant (axis j, sign σ): when c1_j has the other sign, c1_j is negated and then, with
   the fan weight ω = 1 − w (1 for the fan alone; none for Frans alone), moved towards 0 by
   ω, and projected onto the surface again.
4. The plane through P, Q and c1 cuts an ellipse; r1, r2 are the tangent points of P and
   Q on it on c1's side of the line P Q (the points of the ellipse on P's polar plane
   A P·x = 1, A = diag(1/a_i'²)). OpenSim finds them by a damped least-squares search from
   c1 (tolerance 1e-8 on the squared residuals); here the line of the two planes is cut
   with the ellipsoid (closed form).
5. The arc r1→r2: n = ⌊|r1 − r2|/1 mm⌋ chords (≤ 499; none below 1 mm: the chord
   r1 r2), the directions from a0 (the plane's point on the coordinate axis of its
   normal's largest component) turned in n equal angles from r1's to r2's, each cut
   with the ellipsoid. With a quadrant, if the first or last chord turns back towards its
   anchor the arc is redone the other way round (2π minus the angle).

Length l = |P − r1| + Σ chords + |r2 − Q| (m). The rule is not a shortest path and the
count n jumps (by ~1e-7 relative), so l is not stationary in r1, r2: its gradient is
taken by central differences with n and the way round held
(:func:`plane_wrap_gradients`, with a local quadratic model of the length between nearby
calls).
"""

from __future__ import annotations

import numpy as np
from numba import njit

#: OpenSim's constants: blend bounds of |u_k|, fan samples, end fade, chord length (m)
MU_MIN, MU_MAX, FAN_SAMPLES, END_FADE, CHORD = 0.7073, 0.9, 300, 0.3, 0.001
#: a coordinate this close to 0 makes the nearest-point problem 2-D (OpenSim's roundoff)
NEAR_PLANE = 2e-13


@njit(cache=True)
def _ellipse_nearest(a, b, u, v):
    """Nearest point (x, y) of the ellipse x²/a² + y²/b² = 1 to (u, v) (Eberly, Graphics
    Gems IV: Newton on the quartic in the multiplier t, x = a² u/(t + a²); from 0 inside,
    from max(a, b)|(u, v)| outside); points on an axis solved directly."""
    on_u, on_v = abs(u) <= NEAR_PLANE, abs(v) <= NEAR_PLANE
    if on_u and on_v:
        if a < b:
            return (-a if u < 0.0 else a), v
        return u, (-b if v < 0.0 else b)
    if on_u:
        if a >= b or abs(v) >= b - a * a / b:
            return u, (b if v >= 0.0 else -b)
        y = b * b * v / (b * b - a * a)
        return a * np.sqrt(abs(1.0 - (y / b) ** 2)), y
    if on_v:
        if b >= a or abs(u) >= a - b * b / a:
            return (a if u >= 0.0 else -a), v
        x = a * a * u / (a * a - b * b)
        return x, b * np.sqrt(abs(1.0 - (x / a) ** 2))
    a2, b2 = a * a, b * b
    t = 0.0 if (u / a) ** 2 + (v / b) ** 2 < 1.0 else max(a, b) * np.sqrt(u * u + v * v)
    for _ in range(100):
        P, Q = t + a2, t + b2
        f = P * P * Q * Q - a2 * u * u * Q * Q - b2 * v * v * P * P
        fp = 2.0 * (P * Q * (P + Q) - a2 * u * u * Q - b2 * v * v * P)
        step = f / fp
        t -= step
        if abs(step) <= 1e-15 * (abs(t) + a2):
            break
    return a2 * u / (t + a2), b2 * v / (t + b2)


@njit(cache=True)
def _nearest(ax, x, axis):
    """Nearest point (3,) of the ellipsoid with semi-axes ax (3,) to x (3,): in the plane
    x_axis = const when ``axis`` ≥ 0 (or when a coordinate is ~0: the narrowest such
    section), else Eberly's Newton on the sextic in the multiplier."""
    if axis < 0:
        best = np.inf
        for i in range(3):
            if abs(x[i]) <= NEAR_PLANE:
                s = ax[0] + ax[1] + ax[2] - ax[i]
                if s < best:
                    best, axis = s, i
    out = x.copy()
    if axis >= 0:
        i, j = (axis + 1) % 3, (axis + 2) % 3
        out[i], out[j] = _ellipse_nearest(ax[i], ax[j], x[i], x[j])
        return out
    a2 = ax * ax
    t = 0.0 if np.sum((x / ax) ** 2) < 1.0 else np.max(ax) * np.sqrt(x @ x)
    t = _multiplier(a2[0], a2[1], a2[2], x[0], x[1], x[2], t, 1e-15)
    return a2 * x / (t + a2)


@njit(cache=True)
def _multiplier(A0, A1, A2, x0, x1, x2, t, tol=1e-15):
    """The multiplier t of the nearest point a_i² x_i/(t + a_i²) of the ellipsoid with
    squared semi-axes A0, A1, A2 (m²) to (x0, x1, x2) (m): Eberly's Newton on the sextic
    (t + A0)²(t + A1)²(t + A2)² − Σ A_i x_i² Π_(k≠i) (t + A_k)² from ``t`` (m²), until the
    step is below ``tol`` of |t| + max A_i. From a start in the quadratic regime (a
    neighbour's root) a step below 1e-8 leaves an error below 1e-16 after it, so such
    starts need not take the confirming step the default 1e-15 asks for. In scalars: no
    array is allocated."""
    w0, w1, w2 = A0 * x0 * x0, A1 * x1 * x1, A2 * x2 * x2
    top = max(A0, max(A1, A2))
    for _ in range(100):
        P, Q, R = t + A0, t + A1, t + A2
        f = P * P * Q * Q * R * R - w0 * Q * Q * R * R - w1 * P * P * R * R - w2 * P * P * Q * Q
        fp = 2.0 * (P * Q * R * (Q * R + P * R + P * Q) - w0 * Q * R * (Q + R) - w1 * P * R * (P + R)
                    - w2 * P * Q * (P + Q))
        step = f / fp
        t -= step
        if abs(step) <= tol * (abs(t) + top):
            break
    return t


@njit(cache=True)
def _fan_sum(r1, d, ax):
    """Σ over the chord points x_i = r1 + (i/FAN_SAMPLES) d, i = 1 … FAN_SAMPLES − 2, of the
    unit vectors from x_i to their nearest surface points (module docstring, 2: "fan").
    The points lie inside, so each multiplier is negative; Newton starts from the linear
    extrapolation of the two previous points' roots (error ~1e-7 relative: two steps,
    against four from the neighbour's root and five cold from t = 0) and is redone cold
    if it leaves (−min a_i², 0]. Points with a coordinate within NEAR_PLANE of 0 go to
    :func:`_nearest` (its 2-D sections)."""
    A0, A1, A2 = ax[0] * ax[0], ax[1] * ax[1], ax[2] * ax[2]
    low = -min(A0, min(A1, A2))
    s0, s1, s2 = 0.0, 0.0, 0.0
    t, t1, t2 = 0.0, 0.0, 0.0  # the last root, and the two before it (roots = number of them)
    roots = 0
    for i in range(1, FAN_SAMPLES - 1):
        f = i / FAN_SAMPLES
        x0, x1, x2 = r1[0] + f * d[0], r1[1] + f * d[1], r1[2] + f * d[2]
        if abs(x0) <= NEAR_PLANE or abs(x1) <= NEAR_PLANE or abs(x2) <= NEAR_PLANE \
                or (x0 * x0 / A0 + x1 * x1 / A1 + x2 * x2 / A2) >= 1.0:
            c = _nearest(ax, np.array([x0, x1, x2]), np.int64(-1))
            y0, y1, y2 = c[0] - x0, c[1] - x1, c[2] - x2
        else:
            if roots >= 2:
                t = _multiplier(A0, A1, A2, x0, x1, x2, 2.0 * t1 - t2, 1e-8)
            else:
                t = _multiplier(A0, A1, A2, x0, x1, x2, t1 if roots else 0.0, 1e-15)
            if not (low < t <= 0.0):
                t = _multiplier(A0, A1, A2, x0, x1, x2, 0.0, 1e-15)
            t2, t1 = t1, t
            roots += 1
            y0, y1, y2 = A0 * x0 / (t + A0) - x0, A1 * x1 / (t + A1) - x1, A2 * x2 / (t + A2) - x2
        n = np.sqrt(y0 * y0 + y1 * y1 + y2 * y2)
        if n > 0.0:
            s0 += y0 / n
            s1 += y1 / n
            s2 += y2 / n
    return np.array([s0, s1, s2])


@njit(cache=True)
def _unit(v):
    n = np.sqrt(v @ v)
    return v / n if n > 0.0 else v


@njit(cache=True)
def _cross(u, v):
    return np.array([u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]])


@njit(cache=True)
def _plane_point(p1, p2, r1, r2, ax, q_axis, q_sign):
    """c1 (3,): the surface point that fixes the wrapping plane (module docstring, 2–3)."""
    d = r2 - r1
    u = np.abs(_unit(p1 - p2))
    k = np.int64(0)
    for i in range(1, 3):
        if u[i] > u[k]:
            k = i
    mu = u[k]
    t = -r1[k] / d[k]
    c_frans = _nearest(ax, r1 + t * d, k)
    if mu > MU_MIN:
        s = 1.0
        if t < 0.0 or t > 1.0:
            s = 0.0
        elif t < END_FADE:
            s = t / END_FADE
        elif t > 1.0 - END_FADE:
            s = (1.0 - t) / END_FADE
        if s < 1.0:
            mu = MU_MIN + s * (mu - MU_MIN)
    c1 = c_frans
    fan_weight = -np.inf
    if mu < MU_MAX:
        c_fan = _nearest(ax, r1 + 0.5 * d + _unit(_fan_sum(r1, d, ax)), np.int64(-1))
        if mu <= MU_MIN:
            c1, fan_weight = c_fan, 1.0
        else:
            w = (mu - MU_MIN) / (MU_MAX - MU_MIN)
            c1, fan_weight = _nearest(ax, w * c_frans + (1.0 - w) * c_fan, np.int64(-1)), 1.0 - w
    if q_sign != 0 and (1 if c1[q_axis] >= 0.0 else -1) != q_sign:
        c1 = c1.copy()
        c1[q_axis] = -c1[q_axis]
        if fan_weight == -np.inf:
            fan_weight = 1.0 - (mu - MU_MIN) / (MU_MAX - MU_MIN)
        fan_weight = min(fan_weight, 1.0)
        if fan_weight > 0.0:
            c1[q_axis] -= fan_weight * c1[q_axis]
            c1 = _nearest(ax, c1, np.int64(-1))
    return c1


@njit(cache=True)
def _tangent_point(p, n, n4, ax, c1, p2):
    """The tangent point of p (3,) on the ellipse cut by the plane n·x + n4 = 0, on c1's
    side of the line p p2: the ellipsoid points on the plane and on p's polar plane."""
    A = 1.0 / (ax * ax)
    m = A * p  # polar plane m·x = 1
    w = _cross(n, m)
    # a point on both planes: x0 = α n + β m
    nn, nm, mm = n @ n, n @ m, m @ m
    det = nn * mm - nm * nm
    alpha = (-n4 * mm - nm) / det
    beta = (nn + nm * n4) / det
    x0 = alpha * n + beta * m
    qa = w @ (A * w)
    qb = 2.0 * (x0 @ (A * w))
    qc = x0 @ (A * x0) - 1.0
    disc = qb * qb - 4.0 * qa * qc
    root = np.sqrt(max(disc, 0.0))
    ta = x0 + ((-qb + root) / (2.0 * qa)) * w
    tb = x0 + ((-qb - root) / (2.0 * qa)) * w
    e = p2 - p
    ref = _cross(c1 - p, e) @ n
    return ta if (_cross(ta - p, e) @ n) * ref > 0.0 else tb


@njit(cache=True)
def _arc(r1, r2, n, n4, ax, far, n_fixed, chord):
    """The polyline over the surface from r1 to r2 in the plane (module docstring, 5),
    chords of about ``chord`` (scaled frame): (points (k, 3), number of chords)."""
    gap = np.sqrt((r1 - r2) @ (r1 - r2))
    if n_fixed >= 0:
        count = n_fixed
    else:
        count = min(int(gap / chord), 499) if gap >= chord else 0
    if count <= 1:
        pts = np.empty((2, 3))
        pts[0], pts[1] = r1, r2
        return pts, count
    k = np.int64(0)
    for i in range(1, 3):
        if abs(n[i]) > abs(n[k]):
            k = i
    a0 = np.zeros(3)
    a0[k] = -n4 / n[k]
    e1 = _unit(r1 - a0)
    e2 = _unit(r2 - a0)
    phi0 = np.arccos(min(1.0, max(-1.0, e1 @ e2)))
    dphi = -(2.0 * np.pi - phi0) / count if far else phi0 / count
    ez = _unit(_cross(e1, e2))
    ey = _cross(ez, e1)
    pts = np.empty((count + 1, 3))
    pts[0], pts[count] = r1, r2
    A = 1.0 / (ax * ax)
    for i in range(1, count):
        v = np.cos(i * dphi) * e1 + np.sin(i * dphi) * ey
        qa = v @ (A * v)
        qb = 2.0 * (v @ (A * a0))
        qc = a0 @ (A * a0) - 1.0
        pts[i] = a0 + ((-qb + np.sqrt(qb * qb - 4.0 * qa * qc)) / (2.0 * qa)) * v
    return pts, count


@njit(cache=True)
def _polyline_length(pts):
    total = 0.0
    for i in range(pts.shape[0] - 1):
        d = pts[i + 1] - pts[i]
        total += np.sqrt(d @ d)
    return total


@njit(cache=True)
def plane_wrap_core(P, Q, axes, side, n_fixed, far_fixed):
    """OpenSim's ellipsoid wrap of P→Q (3,) m (surface frame, semi-axes ``axes`` (3,) m);
    ``side`` (3,): the quadrant, a coordinate axis ±e_j (zeros: none). n_fixed ≥ 0 and
    far_fixed ≥ 0 hold the chord count and the way round (for differences), −1: OpenSim's
    choice. Returns (status, length m, T1 (3,) m, T2 (3,) m, arc m, chords, far)."""
    T1 = P.copy()
    T2 = Q.copy()
    u = Q - P
    straight = np.sqrt(u @ u)
    f = 3.0 / (axes[0] + axes[1] + axes[2])
    p1, p2, ax = f * P, f * Q, f * axes
    e1 = np.sum((p1 / ax) ** 2) - 1.0
    e2 = np.sum((p2 / ax) ** 2) - 1.0
    if e1 < -1e-4 or e2 < -1e-4:
        return -1, straight, T1, T2, 0.0, 0, 0
    if abs(_unit(p1) @ _unit(p2) - 1.0) < 1e-4:
        return 0, straight, T1, T2, 0.0, 0, 0
    d = p1 - p2
    g1, g2 = d / ax, p2 / ax
    qa, qb, qc = g1 @ g1, 2.0 * (g1 @ g2), g2 @ g2 - 1.0
    disc = qb * qb - 4.0 * qa * qc
    if disc < 0.0:
        return 0, straight, T1, T2, 0.0, 0, 0
    l1 = (-qb + np.sqrt(disc)) / (2.0 * qa)
    l2 = (-qb - np.sqrt(disc)) / (2.0 * qa)
    if not (0.0 < l1 < 1.0) or not (0.0 < l2 < 1.0):
        return 0, straight, T1, T2, 0.0, 0, 0
    q_axis, q_sign = np.int64(0), np.int64(0)  # (typed int64: a literal 0 compiles the callees again)
    for j in range(3):
        if side[j] != 0.0:
            q_axis, q_sign = j, (1 if side[j] > 0.0 else -1)
    c1 = _plane_point(p1, p2, p2 + l1 * d, p2 + l2 * d, ax, q_axis, q_sign)
    n = _unit(_cross(d, p1 - c1))
    n4 = -(n @ c1)
    r1 = p1.copy() if abs(e1) < 1e-4 else _tangent_point(p1, n, n4, ax, c1, p2)
    r2 = p2.copy() if abs(e2) < 1e-4 else _tangent_point(p2, n, n4, ax, c1, p1)
    far = far_fixed == 1
    pts, count = _arc(r1, r2, n, n4, ax, far, n_fixed, CHORD * f)
    if far_fixed < 0 and q_sign != 0 and pts.shape[0] > 2:
        k = pts.shape[0]
        if _unit(p1 - r1) @ _unit(pts[1] - r1) > 0.0 or _unit(p2 - r2) @ _unit(pts[k - 2] - r2) > 0.0:
            far = np.bool_(True)
            pts, count = _arc(r1, r2, n, n4, ax, far, n_fixed, CHORD * f)
    arc = _polyline_length(pts)
    length = (np.sqrt((p1 - r1) @ (p1 - r1)) + arc + np.sqrt((p2 - r2) @ (p2 - r2))) / f
    return 1, length, r1 / f, r2 / f, arc / f, count, 1 if far else 0


@njit(cache=True)
def plane_wrap(P, Q, axes, side):
    """(status, length m, T1 (3,), T2 (3,), arc m) of :func:`plane_wrap_core`, OpenSim's
    choices; status −1: an anchor inside, 0: straight, 1: wrapped."""
    st, length, T1, T2, arc, _, _ = plane_wrap_core(P, Q, axes, side, np.int64(-1), np.int64(-1))
    return st, length, T1, T2, arc


#: a plane node's row of the path kernel's ``warm`` (N, WARM_SIZE) array: the last core
#: solved [0 valid, P (3) m, Q (3) m, status, chords, far, T1 (3) m, T2 (3) m] and the
#: gradient model [REF + 0 state (0 none, 1 reference, 2 with H), hits, P0 (3) m, Q0 (3) m,
#: chords, far, ∇l (6), H (6, 6) 1/m]
LAST, REF = 0, 16
PLANE_ROW = REF + 12 + 6 + 36
#: the model's reach: fraction of the smallest semi-axis the anchors may move from the
#: reference; the second differences' step, the same fraction
MODEL_REACH = 1e-4


@njit(cache=True)
def plane_wrap_stashed(P, Q, axes, side, row):
    """:func:`plane_wrap`, its core (chords, way round) stashed in ``row`` (PLANE_ROW,)."""
    st, length, T1, T2, arc, count, far = plane_wrap_core(P, Q, axes, side, np.int64(-1), np.int64(-1))
    row[LAST] = 1.0
    row[LAST + 1:LAST + 4] = P
    row[LAST + 4:LAST + 7] = Q
    row[LAST + 7], row[LAST + 8], row[LAST + 9] = st, count, far
    row[LAST + 10:LAST + 13] = T1
    row[LAST + 13:LAST + 16] = T2
    return st, length, T1, T2, arc


@njit(cache=True)
def _length_held(X, axes, side, count, far):
    """l (m) at anchors X (6,) = (P, Q) m with the chord count and the way round held."""
    return plane_wrap_core(X[:3], X[3:], axes, side, count, far)[1]


@njit(cache=True)
def _gradient_held(X, axes, side, count, far):
    """∇l (6,) at X = (P, Q) m by central differences (step 1e-7 of |P| + |Q|), the
    chord count and the way round held."""
    h = 1e-7 * (np.sqrt(X[:3] @ X[:3]) + np.sqrt(X[3:] @ X[3:]))
    g = np.zeros(6)
    for i in range(6):
        Xp, Xm = X.copy(), X.copy()
        Xp[i] += h
        Xm[i] -= h
        g[i] = (_length_held(Xp, axes, side, count, far) - _length_held(Xm, axes, side, count, far)) / (2.0 * h)
    return g


@njit(cache=True)
def _hessian_held(X, axes, side, count, far):
    """∇²l (6, 6) 1/m at X = (P, Q) m by central second differences of the length (step
    h = MODEL_REACH × the smallest semi-axis), count and way round held: the diagonal
    from l(X ± h e_i), each off-diagonal entry from those and l(X ± h (e_i + e_j)),
        H_ij = [l(+ij) − l(+i) − l(+j) + 2 l₀ − l(−i) − l(−j) + l(−ij)] / 2h²  (error O(h²)),
    43 lengths in all."""
    h = MODEL_REACH * min(axes[0], min(axes[1], axes[2]))
    l0 = _length_held(X, axes, side, count, far)
    lp = np.empty(6)
    lm = np.empty(6)
    H = np.zeros((6, 6))
    for i in range(6):
        Y = X.copy()
        Y[i] += h
        lp[i] = _length_held(Y, axes, side, count, far)
        Y[i] -= 2.0 * h
        lm[i] = _length_held(Y, axes, side, count, far)
        H[i, i] = (lp[i] - 2.0 * l0 + lm[i]) / (h * h)
    for i in range(6):
        for j in range(i):
            Y = X.copy()
            Y[i] += h
            Y[j] += h
            lpp = _length_held(Y, axes, side, count, far)
            Y[i] -= 2.0 * h
            Y[j] -= 2.0 * h
            lmm = _length_held(Y, axes, side, count, far)
            H[i, j] = H[j, i] = (lpp - lp[i] - lp[j] + 2.0 * l0 - lm[i] - lm[j] + lmm) / (2.0 * h * h)
    return H


@njit(cache=True)
def plane_wrap_gradients(P, Q, axes, side, row):
    """The parts of ∂l/∂P and ∂l/∂Q (3,) (surface frame) beyond those with T1 and T2 held
    (−e1 and e2, e1, e2 the unit directions P→T1, T2→Q): (status, g_P, g_Q), zeros
    unless wrapped (status 1).

    OpenSim's rule is not a shortest path, so ∇l has no closed form here: it is taken
    by central differences of the length with the chord count and the way round held
    (:func:`_gradient_held`, 12 lengths). ``row`` (PLANE_ROW,), the node's row of the
    path kernel's ``warm``, keeps the last core (:func:`plane_wrap_stashed`; reused when
    P and Q are the same) and a reference gradient. Anchors within MODEL_REACH × the
    smallest semi-axis of the reference, with the same count and way round, are a
    finite difference or a converging Newton step away: from the second such call on,
    ∇l = ∇l₀ + H (X − X₀), H the Hessian at the reference (:func:`_hessian_held`, 43 lengths once;
    model error ½ |δ|² |∇³l| ≲ 1e-8 against ~2e-9 of the differences' round-off), and
    the differences of ∇l along a direction (the analytic FDK Jacobian's change of the
    moment arms) are H's, exactly."""
    gP = np.zeros(3)
    gQ = np.zeros(3)
    if row[LAST] == 1.0 and np.all(row[LAST + 1:LAST + 4] == P) and np.all(row[LAST + 4:LAST + 7] == Q):
        st, count, far = int(row[LAST + 7]), int(row[LAST + 8]), int(row[LAST + 9])
        T1, T2 = row[LAST + 10:LAST + 13].copy(), row[LAST + 13:LAST + 16].copy()
    else:
        st, _, T1, T2, _, count, far = plane_wrap_core(P, Q, axes, side, np.int64(-1), np.int64(-1))
    if st != 1:
        return st, gP, gQ
    X = np.concatenate((P, Q))
    reach = MODEL_REACH * min(axes[0], min(axes[1], axes[2]))
    X0 = row[REF + 2:REF + 8]
    near = row[REF] > 0.0 and row[REF + 8] == count and row[REF + 9] == far
    if near:
        for i in range(6):
            near = near and abs(X[i] - X0[i]) <= reach
    g0 = row[REF + 10:REF + 16]
    if near and row[REF + 1] >= 1.0:
        if row[REF] == 1.0:
            row[REF + 16:REF + 52] = _hessian_held(X0.copy(), axes, side, count, far).ravel()
            row[REF] = 2.0
        g = g0 + row[REF + 16:REF + 52].reshape(6, 6) @ (X - X0)
    elif near:
        row[REF + 1] = 1.0  # the first call near the reference: differences, and H at the next
        g = _gradient_held(X, axes, side, count, far)
    else:
        g = _gradient_held(X, axes, side, count, far)
        row[REF], row[REF + 1] = 1.0, 0.0
        row[REF + 2:REF + 8] = X
        row[REF + 8], row[REF + 9] = count, far
        row[REF + 10:REF + 16] = g
    return st, g[:3] + _unit(T1 - P), g[3:] - _unit(Q - T2)
