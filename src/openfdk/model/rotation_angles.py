"""Euler and Cardan angles in any sequence, and joint-coordinate-system (JCS) angles.

``RotationAngles`` is the orientation of frame F_b relative to frame F_a as three angles
of an intrinsic (body-fixed, rotating-axes) sequence (i, j, k) of axes x=0, y=1, z=2:

    R_FaFb = R_i(θ1) R_j(θ2) R_k(θ3).

Cardan (Tait–Bryan) sequences have three different axes (xyz, zxy, …); proper Euler
sequences repeat the first axis (zxz, yxy, …). The relative angular velocity in F_a is
ω_rel = R_FaFb ω'_Fb − ω'_Fa = B(θ) θ̇ with the columns of B

    c1 = e_i,  c2 = R_i(θ1) e_j,  c3 = R_i(θ1) R_j(θ2) e_k,

so M = B⁻¹ [−R_aFaᵀ in a's rotation columns, R_FaFb R_bFbᵀ in b's] and the acceleration
bias b = B⁻¹ (−ω'_Fa × (R_FaFb ω'_Fb) − Ḃ θ̇), with
Ḃ θ̇ = θ̇2 θ̇1 (e_i × c2) + θ̇3 [θ̇1 (e_i × c3) + θ̇2 R_i(θ1) (e_j × R_j(θ2) e_k)].
B is singular at θ2 = ±90° (Cardan) or θ2 ∈ {0, 180°} (Euler): gimbal lock, reported.

Joint coordinate system (Grood & Suntay 1983, J Biomech Eng 105:136; ISB: Wu et al.
2002, J Biomech 35:543, and 2005, J Biomech 38:981): the first rotation is about a
parent-fixed axis e1, the last about a child-fixed axis e3, the middle one about the
floating axis e2 ⟂ e1, e3 — exactly a Cardan sequence of the two anatomical frames:

* knee (and hip, ankle, ISB frames X anterior, Y superior, Z right): sequence z-x-y,
  angles (flexion, adduction, internal rotation) for the right side. Knee flexion moves
  the tibia's distal end posterior, a *negative* right-hand rotation about Z, so the knee's
  first angle is negated (Grood & Suntay: flexion positive); hip flexion and ankle
  dorsiflexion are positive rotations about Z;
* shoulder (glenohumeral, ISB 2005): sequence y-x-y, angles (plane of elevation,
  elevation, axial rotation).

For a left limb the ISB frames keep Z to the right, so adduction and internal rotation
change sign (Grood & Suntay's convention): ``side="left"`` negates angles 2 and 3.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .measures import Measure

AXES = {"x": 0, "y": 1, "z": 2}
#: named JCS conventions: (sequence, angle names, signs for the right side)
JCS_CONVENTIONS = {
    "knee": ("zxy", ("flexion", "adduction", "internal_rotation"), (-1.0, 1.0, 1.0)),
    "hip": ("zxy", ("flexion", "adduction", "internal_rotation"), (1.0, 1.0, 1.0)),
    "ankle": ("zxy", ("dorsiflexion", "inversion", "internal_rotation"), (1.0, 1.0, 1.0)),
    "shoulder": ("yxy", ("plane_of_elevation", "elevation", "axial_rotation"), (1.0, 1.0, 1.0)),
}


def parse_sequence(sequence):
    """'zxy' -> (2, 0, 1); valid: three axes, none equal to its neighbour."""
    if not isinstance(sequence, str) or len(sequence) != 3 or any(c not in AXES for c in sequence.lower()):
        raise ValueError(f"rotation sequence {sequence!r}: expected three of x, y, z such as 'xyz' or 'zxz'")
    axes = tuple(AXES[c] for c in sequence.lower())
    if axes[0] == axes[1] or axes[1] == axes[2]:
        raise ValueError(f"rotation sequence {sequence!r}: neighbouring axes must differ")
    return axes


@njit(cache=True)
def _axis_rotation_into(axis, angle, R):
    """R (3, 3) ← the rotation by ``angle`` about the coordinate axis ``axis``."""
    c, s = np.cos(angle), np.sin(angle)
    for r in range(3):
        for q in range(3):
            R[r, q] = 1.0 if r == q else 0.0
    j, k = (axis + 1) % 3, (axis + 2) % 3
    R[j, j] = c
    R[j, k] = -s
    R[k, j] = s
    R[k, k] = c


@njit(cache=True)
def _angles_into(R, i, j, k, theta):
    """theta (3,) ← θ rad of R = R_i(θ1) R_j(θ2) R_k(θ3) (k == i: proper Euler, θ2 ∈
    [0, π]; else Cardan, θ2 ∈ [−π/2, π/2])."""
    m = 3 - i - j
    eps = 1.0 if (j - i) % 3 == 1 else -1.0
    if k != i:  # m == k
        theta[1] = np.arcsin(min(1.0, max(-1.0, eps * R[i, m])))
        theta[0] = np.arctan2(-eps * R[j, m], R[m, m])
        theta[2] = np.arctan2(-eps * R[i, j], R[i, i])
    else:
        theta[1] = np.arccos(min(1.0, max(-1.0, R[i, i])))
        theta[0] = np.arctan2(R[j, i], -eps * R[m, i])
        theta[2] = np.arctan2(R[i, j], eps * R[i, m])


@njit(cache=True)
def angles_from_matrix(R, i, j, k):
    """θ (3,) rad of R = R_i(θ1) R_j(θ2) R_k(θ3) (k == i: proper Euler, θ2 ∈ [0, π];
    else Cardan, θ2 ∈ [−π/2, π/2])."""
    theta = np.zeros(3)
    _angles_into(R, i, j, k, theta)
    return theta


@njit(cache=True)
def _mat3_into(A, B, transpose_a, transpose_b, out):
    """out (3, 3) ← A·B, Aᵀ·B or A·Bᵀ, as plain loops (numba's ``@`` calls BLAS, whose
    call costs more than these 27 products)."""
    for r in range(3):
        for c in range(3):
            s = 0.0
            for j in range(3):
                s += (A[j, r] if transpose_a else A[r, j]) * (B[c, j] if transpose_b else B[j, c])
            out[r, c] = s


@njit(cache=True)
def _vec3_into(A, x0, x1, x2, transpose, out):
    """out (3,) ← A x or Aᵀ x for a 3×3 A and x = (x0, x1, x2)."""
    for r in range(3):
        if transpose:
            out[r] = A[0, r] * x0 + A[1, r] * x1 + A[2, r] * x2
        else:
            out[r] = A[r, 0] * x0 + A[r, 1] * x1 + A[r, 2] * x2


@njit(cache=True)
def _cross3(a0, a1, a2, b0, b1, b2):
    return a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0


@njit(cache=True)
def inverse3_into(B, out):
    """out (3, 3) ← B⁻¹ by cofactors (adj B / det B; NaN if det B = 0); returns det B."""
    det = (B[0, 0] * (B[1, 1] * B[2, 2] - B[1, 2] * B[2, 1])
           - B[0, 1] * (B[1, 0] * B[2, 2] - B[1, 2] * B[2, 0])
           + B[0, 2] * (B[1, 0] * B[2, 1] - B[1, 1] * B[2, 0]))
    inv = 1.0 / det if det != 0.0 else np.nan
    out[0, 0] = (B[1, 1] * B[2, 2] - B[1, 2] * B[2, 1]) * inv
    out[0, 1] = (B[0, 2] * B[2, 1] - B[0, 1] * B[2, 2]) * inv
    out[0, 2] = (B[0, 1] * B[1, 2] - B[0, 2] * B[1, 1]) * inv
    out[1, 0] = (B[1, 2] * B[2, 0] - B[1, 0] * B[2, 2]) * inv
    out[1, 1] = (B[0, 0] * B[2, 2] - B[0, 2] * B[2, 0]) * inv
    out[1, 2] = (B[0, 2] * B[1, 0] - B[0, 0] * B[1, 2]) * inv
    out[2, 0] = (B[1, 0] * B[2, 1] - B[1, 1] * B[2, 0]) * inv
    out[2, 1] = (B[0, 1] * B[2, 0] - B[0, 0] * B[2, 1]) * inv
    out[2, 2] = (B[0, 0] * B[1, 1] - B[0, 1] * B[1, 0]) * inv
    return det


@njit(cache=True)
def angle_rates_into(R, R1, B, Binv, R_aFa, R_bFb, w_a, w_b, n2x, n2y, n2z, p0, p1, p2, order, T, V, Ma, Mb, b):
    """The Jacobian blocks and bias of three angles R_FaFb = Rot(n1, θ1) Rot(n2, θ2)
    Rot(n3, θ3), into Ma, Mb (3, 3) and b (3,) (order 2), given R = R_FaFb, R1 = Rot(n1,
    θ1), B (3, 3) with columns c1 = n1, c2 = R1 n2, c3 = R1 Rot(n2, θ2) n3, its inverse
    Binv, the frames R_aFa, R_bFb, the bodies' angular velocities w_a, w_b (3,) rad/s
    (body frames), n2 and p = Rot(n2, θ2) n3 as scalars; T, V (3, 3) scratch. Shared by
    the Cardan/Euler angles (n_i = e_i) and :mod:`.axis_angles`; the maths: the module
    docstring (M = B⁻¹ [−R_aFaᵀ, R_FaFb R_bFbᵀ], b = B⁻¹ (−ω_Fa × R ω_Fb − Ḃ θ̇))."""
    _mat3_into(Binv, R_aFa, np.bool_(False), np.bool_(True), Ma)  # −B⁻¹ R_aFaᵀ (negated below)
    _mat3_into(R, R_bFb, np.bool_(False), np.bool_(True), T)
    _mat3_into(Binv, T, np.bool_(False), np.bool_(False), Mb)     # B⁻¹ R_FaFb R_bFbᵀ
    for r in range(3):
        for c in range(3):
            Ma[r, c] = -Ma[r, c]
    if order < 2:
        return
    _vec3_into(R_aFa, w_a[0], w_a[1], w_a[2], np.bool_(True), T[0])     # ω_Fa
    _vec3_into(R_bFb, w_b[0], w_b[1], w_b[2], np.bool_(True), T[1])     # ω_Fb
    _vec3_into(R, T[1, 0], T[1, 1], T[1, 2], np.bool_(False), T[2])      # R_FaFb ω_Fb
    _vec3_into(Binv, T[2, 0] - T[0, 0], T[2, 1] - T[0, 1], T[2, 2] - T[0, 2], np.bool_(False), V[1])  # θ̇
    d0, d1, d2 = V[1, 0], V[1, 1], V[1, 2]
    x0, x1, x2 = _cross3(B[0, 0], B[1, 0], B[2, 0], B[0, 1], B[1, 1], B[2, 1])  # n1 × c2
    y0, y1, y2 = _cross3(B[0, 0], B[1, 0], B[2, 0], B[0, 2], B[1, 2], B[2, 2])  # n1 × c3
    z0, z1, z2 = _cross3(n2x, n2y, n2z, p0, p1, p2)                             # n2 × Rot(n2, θ2) n3
    _vec3_into(R1, z0, z1, z2, np.bool_(False), V[0])                           # R1 (n2 × Rot(n2, θ2) n3)
    # Ḃ θ̇ = θ̇2 θ̇1 (n1 × c2) + θ̇3 [θ̇1 (n1 × c3) + θ̇2 R1 (n2 × Rot(n2, θ2) n3)]
    g0 = d1 * d0 * x0 + d2 * (d0 * y0 + d1 * V[0, 0])
    g1 = d1 * d0 * x1 + d2 * (d0 * y1 + d1 * V[0, 1])
    g2 = d1 * d0 * x2 + d2 * (d0 * y2 + d1 * V[0, 2])
    c0, c1, c2 = _cross3(T[0, 0], T[0, 1], T[0, 2], T[2, 0], T[2, 1], T[2, 2])  # ω_Fa × R ω_Fb
    _vec3_into(Binv, -c0 - g0, -c1 - g1, -c2 - g2, np.bool_(False), b)


@njit(cache=True)
def rotation_angle_blocks(R_Wa, R_aFa, w_a, R_Wb, R_bFb, w_b, seq, sign, order, work, theta, Ma, Mb, b):
    """The angles of :func:`rotation_angles` with their Jacobian as its two non-zero
    blocks, into preallocated outputs (no allocation: the compiled program evaluates
    this for every joint at every evaluation): θ (3,) rad, M_a (3, 3) on body a's
    rotation columns δπ'_a, M_b (3, 3) on body b's, b (3,) rad/s² (order 2; zero
    below). R_Wa, R_Wb (3, 3) the bodies' orientations, w_a, w_b (3,) rad/s their
    body-frame angular velocities, work (9, 3, 3) scratch. Returns ok: False at gimbal
    lock (|det B| < 1e-9). The maths: the module docstring."""
    i, j, k = seq[0], seq[1], seq[2]
    R_WFa, R_WFb, R, R1, R2, B, Binv, T, V = (work[0], work[1], work[2], work[3], work[4], work[5], work[6],
                                                work[7], work[8])
    _mat3_into(R_Wa, R_aFa, np.bool_(False), np.bool_(False), R_WFa)
    _mat3_into(R_Wb, R_bFb, np.bool_(False), np.bool_(False), R_WFb)
    _mat3_into(R_WFa, R_WFb, np.bool_(True), np.bool_(False), R)  # R_FaFb
    _angles_into(R, i, j, k, theta)
    for r in range(3):
        b[r] = 0.0
        for c in range(3):
            Ma[r, c] = 0.0
            Mb[r, c] = 0.0
    ok = True
    if order >= 1:
        _axis_rotation_into(i, theta[0], R1)
        _axis_rotation_into(j, theta[1], R2)
        # B's columns: c1 = e_i, c2 = R1 e_j, c3 = R1 R2 e_k (V rows 0, 1, 2: c2, R2 e_k, c3)
        for r in range(3):
            V[0, r] = R1[r, j]
            V[1, r] = R2[r, k]
        _vec3_into(R1, V[1, 0], V[1, 1], V[1, 2], np.bool_(False), V[2])
        for r in range(3):
            B[r, 0] = 1.0 if r == i else 0.0
            B[r, 1] = V[0, r]
            B[r, 2] = V[2, r]
        if abs(inverse3_into(B, Binv)) < 1e-9:
            ok = False
        else:
            angle_rates_into(R, R1, B, Binv, R_aFa, R_bFb, w_a, w_b, 1.0 if j == 0 else 0.0, 1.0 if j == 1 else 0.0,
                             1.0 if j == 2 else 0.0, R2[0, k], R2[1, k], R2[2, k], order, T, V, Ma, Mb, b)
    for r in range(3):
        theta[r] *= sign[r]
        for c in range(3):
            Ma[r, c] *= sign[r]
            Mb[r, c] *= sign[r]
        b[r] *= sign[r]
    return ok


@njit(cache=True)
def rotation_angles(R_WB, w_BB, column, ia, R_aFa, ib, R_bFb, seq, sign, n_coords, order):
    """Angles θ (3,) rad of F_b in F_a for the sequence ``seq`` (3,) int, multiplied by
    ``sign`` (3,); M (3, n_coords); b (3,) (see the module docstring). Returns
    (θ, M, b, ok) with ok False at gimbal lock (|det B| < 1e-9). The blocks of M come
    from :func:`rotation_angle_blocks`."""
    theta, Ma, Mb, b = np.empty(3), np.empty((3, 3)), np.empty((3, 3)), np.empty(3)
    ok = rotation_angle_blocks(R_WB[ia], R_aFa, w_BB[ia], R_WB[ib], R_bFb, w_BB[ib], seq, sign, order,
                               np.empty((9, 3, 3)), theta, Ma, Mb, b)
    M = np.zeros((3, n_coords))
    if order == 0 or not ok:
        return theta, M, np.zeros(3), ok
    ca, cb = column[ia], column[ib]
    for r in range(3):
        for c in range(3):
            if ca >= 0:
                M[r, ca + 3 + c] += Ma[r, c]
            if cb >= 0:
                M[r, cb + 3 + c] += Mb[r, c]
    return theta, M, b, ok


class RotationAngles(Measure):
    """Three angles (rad) of frame F_b relative to F_a in the sequence ``sequence``
    ('xyz', 'zxy', 'zxz', …; intrinsic). body_a, body_b: body indices; R_aFa, R_bFb
    (3, 3): the frames in their bodies; sign (3,): ±1 per angle (JCS side convention).
    """

    size = 3
    units = ("angle",) * 3

    def __init__(self, body_a, R_aFa, body_b, R_bFb, sequence="xyz", sign=(1.0, 1.0, 1.0), name=""):
        self.body_a, self.body_b = int(body_a), int(body_b)
        self.R_aFa = np.ascontiguousarray(R_aFa, dtype=float)
        self.R_bFb = np.ascontiguousarray(R_bFb, dtype=float)
        self.sequence = sequence
        self.seq = np.array(parse_sequence(sequence), dtype=np.int64)
        self.sign = np.asarray(sign, dtype=float)
        self.name = name

    def bodies(self):
        return tuple(sorted({self.body_a, self.body_b}))

    def evaluate(self, state, order=1):
        theta, M, b, ok = rotation_angles(state.R_WB, state.w_BB, state.column, self.body_a, self.R_aFa,
                                          self.body_b, self.R_bFb, self.seq, self.sign, state.n_coords, order)
        if not ok:
            raise FloatingPointError(f"angles {self.name!r} ({self.sequence}): gimbal lock, the middle angle is "
                                     f"{np.degrees(theta[1]):.1f} deg")
        return theta, (M if order >= 1 else None), (b if order >= 2 else None)


__all__ = ["RotationAngles", "JCS_CONVENTIONS", "parse_sequence", "angles_from_matrix", "rotation_angles",
           "rotation_angle_blocks", "angle_rates_into", "inverse3_into"]
