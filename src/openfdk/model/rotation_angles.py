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
def _axis_rotation(axis, angle):
    c, s = np.cos(angle), np.sin(angle)
    R = np.eye(3)
    j, k = (axis + 1) % 3, (axis + 2) % 3
    R[j, j] = c
    R[j, k] = -s
    R[k, j] = s
    R[k, k] = c
    return R


@njit(cache=True)
def _cross(a, b):
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


@njit(cache=True)
def angles_from_matrix(R, i, j, k):
    """θ (3,) rad of R = R_i(θ1) R_j(θ2) R_k(θ3) (k == i: proper Euler, θ2 ∈ [0, π];
    else Cardan, θ2 ∈ [−π/2, π/2])."""
    theta = np.zeros(3)
    if k != i:
        m = 3 - i - j  # == k
        eps = 1.0 if (j - i) % 3 == 1 else -1.0
        theta[1] = np.arcsin(min(1.0, max(-1.0, eps * R[i, m])))
        theta[0] = np.arctan2(-eps * R[j, m], R[m, m])
        theta[2] = np.arctan2(-eps * R[i, j], R[i, i])
    else:
        m = 3 - i - j
        eps = 1.0 if (j - i) % 3 == 1 else -1.0
        theta[1] = np.arccos(min(1.0, max(-1.0, R[i, i])))
        theta[0] = np.arctan2(R[j, i], -eps * R[m, i])
        theta[2] = np.arctan2(R[i, j], eps * R[i, m])
    return theta


@njit(cache=True)
def _mat3(A, B, transpose_a, transpose_b):
    """A·B, Aᵀ·B or A·Bᵀ of 3×3 matrices as plain loops: numba's ``@`` calls BLAS, whose
    call costs more than these 27 products."""
    out = np.empty((3, 3))
    for r in range(3):
        for c in range(3):
            s = 0.0
            for j in range(3):
                s += (A[j, r] if transpose_a else A[r, j]) * (B[c, j] if transpose_b else B[j, c])
            out[r, c] = s
    return out


@njit(cache=True)
def _vec3(A, x, transpose):
    """A x or Aᵀ x for a 3×3 A and x (3,)."""
    out = np.empty(3)
    for r in range(3):
        if transpose:
            out[r] = A[0, r] * x[0] + A[1, r] * x[1] + A[2, r] * x[2]
        else:
            out[r] = A[r, 0] * x[0] + A[r, 1] * x[1] + A[r, 2] * x[2]
    return out


@njit(cache=True)
def inverse3(B):
    """(B⁻¹ (3, 3), det B) by cofactors (B⁻¹ = adj B / det B); B⁻¹ is NaN if det B = 0."""
    det = (B[0, 0] * (B[1, 1] * B[2, 2] - B[1, 2] * B[2, 1])
           - B[0, 1] * (B[1, 0] * B[2, 2] - B[1, 2] * B[2, 0])
           + B[0, 2] * (B[1, 0] * B[2, 1] - B[1, 1] * B[2, 0]))
    out = np.empty((3, 3))
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
    return out, det


@njit(cache=True)
def rotation_angle_blocks(R_Wa, R_aFa, w_a, R_Wb, R_bFb, w_b, seq, sign, order):
    """The angles of :func:`rotation_angles` with their Jacobian as its two non-zero
    blocks: θ (3,) rad, M_a (3, 3) on body a's rotation columns δπ'_a, M_b (3, 3) on body
    b's, b (3,) rad/s² (order 2), ok. R_Wa, R_Wb (3, 3) the bodies' orientations, w_a,
    w_b (3,) rad/s their body-frame angular velocities (module docstring for the maths)."""
    i, j, k = seq[0], seq[1], seq[2]
    R_WFa = _mat3(R_Wa, R_aFa, False, False)
    R_WFb = _mat3(R_Wb, R_bFb, False, False)
    R = _mat3(R_WFa, R_WFb, True, False)  # R_FaFb
    theta = angles_from_matrix(R, i, j, k)
    Ma = np.zeros((3, 3))
    Mb = np.zeros((3, 3))
    b = np.zeros(3)
    if order == 0:
        return theta * sign, Ma, Mb, b, True
    e = np.eye(3)
    R1 = _axis_rotation(i, theta[0])
    R2 = _axis_rotation(j, theta[1])
    c2 = _vec3(R1, e[j], False)
    r2k = _vec3(R2, e[k], False)
    c3 = _vec3(R1, r2k, False)
    B = np.empty((3, 3))
    B[:, 0] = e[i]
    B[:, 1] = c2
    B[:, 2] = c3
    Binv, det = inverse3(B)
    if abs(det) < 1e-9:
        return theta * sign, Ma, Mb, b, False
    Ma = -_mat3(Binv, R_aFa, False, True)                       # −B⁻¹ R_aFaᵀ
    Mb = _mat3(Binv, _mat3(R, R_bFb, False, True), False, False)  # B⁻¹ R_FaFb R_bFbᵀ
    if order >= 2:
        w_Fa = _vec3(R_aFa, w_a, True)
        w_Fb = _vec3(R_bFb, w_b, True)
        Rw = _vec3(R, w_Fb, False)
        dtheta = _vec3(Binv, Rw - w_Fa, False)
        dB = dtheta[1] * dtheta[0] * _cross(e[i], c2) + dtheta[2] * (
            dtheta[0] * _cross(e[i], c3) + dtheta[1] * _vec3(R1, _cross(e[j], r2k), False))
        b = _vec3(Binv, -_cross(w_Fa, Rw) - dB, False)
    for r in range(3):
        for c in range(3):
            Ma[r, c] *= sign[r]
            Mb[r, c] *= sign[r]
        b[r] *= sign[r]
    return theta * sign, Ma, Mb, b, True


@njit(cache=True)
def rotation_angles(R_WB, w_BB, column, ia, R_aFa, ib, R_bFb, seq, sign, n_coords, order):
    """Angles θ (3,) rad of F_b in F_a for the sequence ``seq`` (3,) int, multiplied by
    ``sign`` (3,); M (3, n_coords); b (3,) (see the module docstring). Returns
    (θ, M, b, ok) with ok False at gimbal lock (|det B| < 1e-9). The blocks of M come
    from :func:`rotation_angle_blocks`."""
    theta, Ma, Mb, b, ok = rotation_angle_blocks(R_WB[ia], R_aFa, w_BB[ia], R_WB[ib], R_bFb, w_BB[ib], seq, sign,
                                                 order)
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
           "rotation_angle_blocks", "inverse3"]
