"""Angles about any three axes (Davenport angles): the rotations of a joint whose moving
axes are not orthogonal (OpenSim CustomJoints of the wrist and the thumb).

``AxisAngles`` is the orientation of frame F_b relative to frame F_a as three angles about
the unit axes n1, n2, n3 (constant vectors of F_a's coordinates, each applied in the frame
the previous rotations left, as OpenSim's SpatialTransform applies them):

    R_FaFb = Rot(n1, θ1) Rot(n2, θ2) Rot(n3, θ3).

Cardan and Euler angles (:mod:`.rotation_angles`) are the case of coordinate axes. Any
rotation near the identity has such angles when n1 · (n2 × n3) ≠ 0 (Shuster and Markley
2003, J Astronaut Sci 51:123, "Generalization of the Euler angles"):

* θ2 from n1ᵀ R n3 = n1ᵀ Rot(n2, θ2) n3 = A cos θ2 + B sin θ2 + C (Rodrigues) with
  A = n1·n3 − (n1·n2)(n2·n3), B = n1·(n2 × n3), C = (n1·n2)(n2·n3). Its roots φ ± α
  (φ = atan2(B, A)) meet where B(θ) below is singular, at θ2 = φ and φ ± π; the root taken
  is the one between those that holds θ2 = 0, φ − α for φ > 0 and φ + α otherwise (for
  coordinate axes φ = π/2: Cardan's θ2 = asin, in [−π/2, π/2]);
* θ1 turns v = Rot(n2, θ2) n3 into R n3 about n1, and θ3 turns Rᵀ n1 into Rot(n2, θ2)ᵀ n1
  about n3: θ = atan2(n·(p × q), p·q − (n·p)(n·q)) for p turned into q about n.

The relative angular velocity in F_a is ω_rel = B(θ) θ̇ with the columns

    c1 = n1,  c2 = Rot(n1, θ1) n2,  c3 = Rot(n1, θ1) Rot(n2, θ2) n3,

so M = B⁻¹ [−R_aFaᵀ in a's rotation columns, R_FaFb R_bFbᵀ in b's] and the acceleration
bias b = B⁻¹ (−ω_Fa × (R_FaFb ω_Fb) − Ḃ θ̇), with (Ṙot(n, θ) = θ̇ [n×] Rot(n, θ))

    Ḃ θ̇ = θ̇2 θ̇1 (n1 × c2) + θ̇3 [θ̇1 (n1 × c3) + θ̇2 Rot(n1, θ1) (n2 × Rot(n2, θ2) n3)],

the formulas of :mod:`.rotation_angles` with n_i for e_i. B is singular where the two
roots for θ2 meet (gimbal lock), reported as there.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .measures import Measure
from .rotation_angles import _mat3_into, _vec3_into, angle_rates_into, inverse3_into

#: |n1 · (n2 × n3)| below this: the axes do not span space (no angles), refused
MIN_TRIPLE_PRODUCT = 1e-6


@njit(cache=True)
def _rodrigues_into(n, angle, R):
    """R (3, 3) ← Rot(n, angle) for a unit axis n (3,)."""
    c, s = np.cos(angle), np.sin(angle)
    t = 1.0 - c
    x, y, z = n[0], n[1], n[2]
    R[0, 0], R[0, 1], R[0, 2] = c + t * x * x, t * x * y - s * z, t * x * z + s * y
    R[1, 0], R[1, 1], R[1, 2] = t * x * y + s * z, c + t * y * y, t * y * z - s * x
    R[2, 0], R[2, 1], R[2, 2] = t * x * z - s * y, t * y * z + s * x, c + t * z * z


@njit(cache=True)
def _turn(n, p, q):
    """The angle (rad) about the unit axis n that turns p into q (their parts across n)."""
    np_, nq = n[0] * p[0] + n[1] * p[1] + n[2] * p[2], n[0] * q[0] + n[1] * q[1] + n[2] * q[2]
    x0, x1, x2 = p[1] * q[2] - p[2] * q[1], p[2] * q[0] - p[0] * q[2], p[0] * q[1] - p[1] * q[0]
    return np.arctan2(n[0] * x0 + n[1] * x1 + n[2] * x2, p[0] * q[0] + p[1] * q[1] + p[2] * q[2] - np_ * nq)


@njit(cache=True)
def _wrap(a):
    return a - 2.0 * np.pi * np.floor((a + np.pi) / (2.0 * np.pi))


@njit(cache=True)
def axis_angles_into(R, N, R2, theta):
    """theta (3,) ← θ rad of R = Rot(n1, θ1) Rot(n2, θ2) Rot(n3, θ3), N (3, 3) rows n1, n2,
    n3; R2 (3, 3) ← Rot(n2, θ2) (scratch the caller reuses). Module docstring."""
    n1, n2, n3 = N[0], N[1], N[2]
    d = 0.0
    for r in range(3):
        for c in range(3):
            d += n1[r] * R[r, c] * n3[c]
    d12 = n1[0] * n2[0] + n1[1] * n2[1] + n1[2] * n2[2]
    d23 = n2[0] * n3[0] + n2[1] * n3[1] + n2[2] * n3[2]
    d13 = n1[0] * n3[0] + n1[1] * n3[1] + n1[2] * n3[2]
    A = d13 - d12 * d23
    B = n1[0] * (n2[1] * n3[2] - n2[2] * n3[1]) + n1[1] * (n2[2] * n3[0] - n2[0] * n3[2]) \
        + n1[2] * (n2[0] * n3[1] - n2[1] * n3[0])
    rho = np.sqrt(A * A + B * B)
    phi = np.arctan2(B, A)
    a = np.arccos(min(1.0, max(-1.0, (d - d12 * d23) / rho)))
    # the root on the identity's side of the singularities φ and φ ± π (where the roots meet)
    theta[1] = _wrap(phi - a) if phi > 0.0 else _wrap(phi + a)
    _rodrigues_into(n2, theta[1], R2)
    v, w, u, z = np.empty(3), np.empty(3), np.empty(3), np.empty(3)
    _vec3_into(R2, n3[0], n3[1], n3[2], np.bool_(False), v)   # Rot(n2, θ2) n3
    _vec3_into(R, n3[0], n3[1], n3[2], np.bool_(False), w)    # R n3
    _vec3_into(R2, n1[0], n1[1], n1[2], np.bool_(True), u)    # Rot(n2, θ2)ᵀ n1
    _vec3_into(R, n1[0], n1[1], n1[2], np.bool_(True), z)     # Rᵀ n1
    theta[0] = _turn(n1, v, w)
    theta[2] = _turn(n3, z, u)


@njit(cache=True)
def axis_angle_blocks(R_Wa, R_aFa, w_a, R_Wb, R_bFb, w_b, N, order, work, theta, Ma, Mb, b):
    """The angles of :class:`AxisAngles` with their Jacobian as its two non-zero blocks,
    into preallocated outputs: θ (3,) rad, M_a (3, 3) on body a's rotation columns, M_b
    (3, 3) on body b's, b (3,) rad/s² (order 2; zero below). R_Wa, R_Wb (3, 3) the
    bodies' orientations, w_a, w_b (3,) rad/s their body-frame angular velocities, N (3, 3)
    the axes (rows, unit, in F_a), work (9, 3, 3) scratch. Returns ok: False at gimbal
    lock (|det B| < 1e-9). As :func:`.rotation_angles.rotation_angle_blocks`."""
    R_WFa, R_WFb, R, R1, R2, B, Binv, T, V = (work[0], work[1], work[2], work[3], work[4], work[5], work[6],
                                                work[7], work[8])
    _mat3_into(R_Wa, R_aFa, np.bool_(False), np.bool_(False), R_WFa)
    _mat3_into(R_Wb, R_bFb, np.bool_(False), np.bool_(False), R_WFb)
    _mat3_into(R_WFa, R_WFb, np.bool_(True), np.bool_(False), R)  # R_FaFb
    axis_angles_into(R, N, R2, theta)
    for r in range(3):
        b[r] = 0.0
        for c in range(3):
            Ma[r, c] = 0.0
            Mb[r, c] = 0.0
    if order < 1:
        return True
    _rodrigues_into(N[0], theta[0], R1)
    # B's columns: c1 = n1, c2 = R1 n2, c3 = R1 R2 n3 (V rows 0, 1, 2: c2, R2 n3, c3)
    _vec3_into(R1, N[1, 0], N[1, 1], N[1, 2], np.bool_(False), V[0])
    _vec3_into(R2, N[2, 0], N[2, 1], N[2, 2], np.bool_(False), V[1])
    _vec3_into(R1, V[1, 0], V[1, 1], V[1, 2], np.bool_(False), V[2])
    for r in range(3):
        B[r, 0] = N[0, r]
        B[r, 1] = V[0, r]
        B[r, 2] = V[2, r]
    if abs(inverse3_into(B, Binv)) < 1e-9:
        return False
    angle_rates_into(R, R1, B, Binv, R_aFa, R_bFb, w_a, w_b, N[1, 0], N[1, 1], N[1, 2], V[1, 0], V[1, 1], V[1, 2],
                     order, T, V, Ma, Mb, b)
    return True


class AxisAngles(Measure):
    """Three angles (rad) of frame F_b relative to F_a about the axes ``axes`` (3, 3),
    rows n1, n2, n3 in F_a's coordinates (normalised here; module docstring). body_a,
    body_b: body indices; R_aFa, R_bFb (3, 3): the frames in their bodies."""

    size = 3
    units = ("angle",) * 3

    def __init__(self, body_a, R_aFa, body_b, R_bFb, axes, name=""):
        self.body_a, self.body_b = int(body_a), int(body_b)
        self.R_aFa = np.ascontiguousarray(R_aFa, dtype=float)
        self.R_bFb = np.ascontiguousarray(R_bFb, dtype=float)
        N = np.asarray(axes, dtype=float)
        self.axes = np.ascontiguousarray(N / np.linalg.norm(N, axis=1)[:, None])
        if not abs(np.linalg.det(self.axes)) >= MIN_TRIPLE_PRODUCT:  # (a zero axis: NaN)
            raise ValueError(f"angles {name!r}: the axes {np.round(self.axes, 6).tolist()} do not span space")
        self.name = name

    def bodies(self):
        return tuple(sorted({self.body_a, self.body_b}))

    def evaluate(self, state, order=1):
        theta, Ma, Mb, b = np.empty(3), np.empty((3, 3)), np.empty((3, 3)), np.empty(3)
        ia, ib = self.body_a, self.body_b
        ok = axis_angle_blocks(state.R_WB[ia], self.R_aFa, state.w_BB[ia], state.R_WB[ib], self.R_bFb,
                               state.w_BB[ib], self.axes, order, np.empty((9, 3, 3)), theta, Ma, Mb, b)
        if not ok:
            raise FloatingPointError(f"angles {self.name!r}: gimbal lock, the middle angle is "
                                     f"{np.degrees(theta[1]):.1f} deg")
        M = np.zeros((3, state.n_coords))
        ca, cb = state.column[ia], state.column[ib]
        if order >= 1:
            if ca >= 0:
                M[:, ca + 3:ca + 6] += Ma
            if cb >= 0:
                M[:, cb + 3:cb + 6] += Mb
        return theta, (M if order >= 1 else None), (b if order >= 2 else None)


__all__ = ["AxisAngles", "axis_angles_into", "axis_angle_blocks"]
