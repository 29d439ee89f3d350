"""Rotations, Euler parameters (unit quaternions) and the manifold update.

Conventions (docs/design.md §1, §4):

* A unit quaternion (Euler parameters) is ``p = [e0, e1, e2, e3]``, scalar first.
* ``R_WB = rotation_matrix(p)`` maps vectors expressed in body frame B to the world
  frame W: ``v_W = R_WB @ v_B``.
* Angular velocity ``w_B`` (ω' in the paper) is expressed in the body frame, and the
  virtual rotation ``δπ'`` likewise; a finite body-frame rotation vector ``dpi_B`` is
  applied on the manifold as ``p ← p ⊗ exp(½ dpi_B)`` (``R_WB ← R_WB · Exp(dpi_B)``).

All functions are pure; angles in rad.
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "skew",
    "quat_multiply",
    "quat_conjugate",
    "quat_from_rotvec",
    "rotvec_from_quat",
    "rotation_matrix",
    "quat_from_matrix",
    "rotation_matrix_xyz",
    "xyz_angles_from_matrix",
    "manifold_update",
    "normalize_quat",
]


def skew(v):
    """Skew-symmetric (cross-product) matrix ``ṽ`` with ``ṽ @ u = v × u``.

    Parameters: v (3,). Returns (3, 3).
    """
    x, y, z = v
    return np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])


def quat_multiply(p, q):
    """Quaternion product ``p ⊗ q``; both (4,) scalar first. Returns (4,)."""
    p0, p1, p2, p3 = p
    q0, q1, q2, q3 = q
    return np.array(
        [
            p0 * q0 - p1 * q1 - p2 * q2 - p3 * q3,
            p0 * q1 + p1 * q0 + p2 * q3 - p3 * q2,
            p0 * q2 - p1 * q3 + p2 * q0 + p3 * q1,
            p0 * q3 + p1 * q2 - p2 * q1 + p3 * q0,
        ]
    )


def quat_conjugate(p):
    """Conjugate (inverse of a unit quaternion), (4,) -> (4,)."""
    return np.array([p[0], -p[1], -p[2], -p[3]])


def normalize_quat(p):
    """Unit quaternion with non-negative scalar part, (4,) -> (4,)."""
    p = np.asarray(p, dtype=float)
    n = np.linalg.norm(p)
    if not np.isfinite(n) or n == 0.0:
        raise ValueError(f"cannot normalise quaternion {p!r}")
    p = p / n
    return p if p[0] >= 0.0 else -p


def quat_from_rotvec(phi):
    """Unit quaternion of the rotation vector ``phi`` (3,) rad: ``exp(½ phi)``."""
    phi = np.asarray(phi, dtype=float)
    angle = np.linalg.norm(phi)
    half = 0.5 * angle
    if angle < 1e-8:
        # Taylor series of sin(|φ|/2)/|φ| = ½ − |φ|²/48
        s = 0.5 - angle * angle / 48.0
        return np.array([np.cos(half), s * phi[0], s * phi[1], s * phi[2]])
    s = np.sin(half) / angle
    return np.array([np.cos(half), s * phi[0], s * phi[1], s * phi[2]])


def rotvec_from_quat(p):
    """Rotation vector (3,) rad of the unit quaternion ``p`` (4,); angle in [0, π]."""
    p = normalize_quat(p)
    v = p[1:]
    sin_half = np.linalg.norm(v)
    if sin_half < 1e-12:
        return 2.0 * v
    angle = 2.0 * np.arctan2(sin_half, p[0])
    return v * (angle / sin_half)


def rotation_matrix(p):
    """Rotation matrix ``R`` (3, 3) of the Euler parameters ``p`` (4,)."""
    e0, e1, e2, e3 = p
    return np.array(
        [
            [1 - 2 * (e2 * e2 + e3 * e3), 2 * (e1 * e2 - e0 * e3), 2 * (e1 * e3 + e0 * e2)],
            [2 * (e1 * e2 + e0 * e3), 1 - 2 * (e1 * e1 + e3 * e3), 2 * (e2 * e3 - e0 * e1)],
            [2 * (e1 * e3 - e0 * e2), 2 * (e2 * e3 + e0 * e1), 1 - 2 * (e1 * e1 + e2 * e2)],
        ]
    )


def quat_from_matrix(R):
    """Euler parameters (4,) of a rotation matrix ``R`` (3, 3) (Shepperd's method)."""
    R = np.asarray(R, dtype=float)
    tr = np.trace(R)
    diag = np.diag(R)
    k = int(np.argmax([tr, *diag]))
    if k == 0:
        e0 = 0.5 * np.sqrt(max(1.0 + tr, 0.0))
        f = 0.25 / e0
        p = [e0, f * (R[2, 1] - R[1, 2]), f * (R[0, 2] - R[2, 0]), f * (R[1, 0] - R[0, 1])]
    else:
        i = k - 1
        j, m = (i + 1) % 3, (i + 2) % 3
        ei = 0.5 * np.sqrt(max(1.0 + 2.0 * R[i, i] - tr, 0.0))
        f = 0.25 / ei
        p = [0.0, 0.0, 0.0, 0.0]
        p[0] = f * (R[m, j] - R[j, m])
        p[1 + i] = ei
        p[1 + j] = f * (R[j, i] + R[i, j])
        p[1 + m] = f * (R[m, i] + R[i, m])
    return normalize_quat(p)


def rotation_matrix_xyz(angles):
    """``R = Rx(a0) Ry(a1) Rz(a2)`` (body-fixed x-y-z Cardan sequence); angles (3,) rad."""
    a, b, c = angles
    ca, sa, cb, sb, cc, sc = np.cos(a), np.sin(a), np.cos(b), np.sin(b), np.cos(c), np.sin(c)
    Rx = np.array([[1, 0, 0], [0, ca, -sa], [0, sa, ca]])
    Ry = np.array([[cb, 0, sb], [0, 1, 0], [-sb, 0, cb]])
    Rz = np.array([[cc, -sc, 0], [sc, cc, 0], [0, 0, 1]])
    return Rx @ Ry @ Rz


def xyz_angles_from_matrix(R):
    """Inverse of :func:`rotation_matrix_xyz`: angles (3,) rad with a1 in [-π/2, π/2]."""
    b = np.arcsin(np.clip(R[0, 2], -1.0, 1.0))
    a = np.arctan2(-R[1, 2], R[2, 2])
    c = np.arctan2(-R[0, 1], R[0, 0])
    return np.array([a, b, c])


def manifold_update(p, dpi_B):
    """Apply a body-frame rotation vector on the manifold: ``p ⊗ exp(½ dpi_B)``.

    p (4,) unit quaternion, dpi_B (3,) rad. Returns the normalised (4,) quaternion.
    """
    return normalize_quat(quat_multiply(p, quat_from_rotvec(dpi_B)))
