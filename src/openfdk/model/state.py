"""The pose/velocity workspace of all bodies (Pinocchio's *Data*; the model stays const).

``BodyStates`` holds, for every body of a model (fixed ones and ground included):
``p_WB`` (nb, 3) m centre-of-mass positions, ``quat_WB`` (nb, 4) Euler parameters,
``R_WB`` (nb, 3, 3) rotation matrices (kept in sync), ``w_BB`` (nb, 3) rad/s angular
velocities in the body frame (ω'), ``v_WB`` (nb, 3) m/s centre-of-mass velocities, and
the column offset of each body's virtual displacement in q̂ (``column``, -1 if fixed).

The generalised velocity vector is ``v = [ṙ_1; ω'_1; ṙ_2; ω'_2; …]`` (6 n_moving,).
"""

from __future__ import annotations

import numpy as np

from ..numerics.spatial import rotation_matrix
from .kernels import displace_poses, get_poses, get_velocities, set_poses, set_velocities


def pose_error(q):
    """'' or why the positions q (7 n_moving,) [r_1, p_1, …] (m, -) are not a pose that
    :meth:`BodyStates.set_q` can set: not 7 entries per body, entries partly NaN or not
    finite, or a quaternion whose norm is zero or overflows, as in ``set_q``'s kernel
    (all NaN: a frame without a pose, which readers skip). For values read back from a
    file (a checkpoint's frames)."""
    q = np.asarray(q, dtype=float).ravel()
    if q.size % 7:
        return f"{q.size} entries, not 7 per moving body"
    if np.isnan(q).all():
        return ""
    if not np.isfinite(q).all():
        return "entries that are not finite in a pose"
    with np.errstate(over="ignore"):
        norm = np.sqrt((q.reshape(-1, 7)[:, 3:] ** 2).sum(axis=1))
    bad = np.flatnonzero(~np.isfinite(norm) | (norm == 0.0))
    return f"the quaternion of moving body {bad[0]} cannot be normalised" if len(bad) else ""


class BodyStates:
    """Mutable workspace: poses and velocities of every body. See module docstring."""

    __slots__ = ("p_WB", "quat_WB", "R_WB", "w_BB", "v_WB", "column", "n_coords", "moving")

    def __init__(self, p_WB, quat_WB, column):
        self.p_WB = np.array(p_WB, dtype=float)
        self.quat_WB = np.array(quat_WB, dtype=float)
        self.column = np.asarray(column, dtype=int)
        self.moving = np.flatnonzero(self.column >= 0)
        self.n_coords = 6 * len(self.moving)
        self.R_WB = np.empty((len(self.column), 3, 3))
        for i in range(len(self.column)):
            self.R_WB[i] = rotation_matrix(self.quat_WB[i])
        nb = len(self.column)
        self.w_BB = np.zeros((nb, 3))
        self.v_WB = np.zeros((nb, 3))

    def copy(self):
        """Deep copy of the workspace."""
        other = BodyStates.__new__(BodyStates)
        other.p_WB = self.p_WB.copy()
        other.quat_WB = self.quat_WB.copy()
        other.R_WB = self.R_WB.copy()
        other.w_BB = self.w_BB.copy()
        other.v_WB = self.v_WB.copy()
        other.column = self.column
        other.moving = self.moving
        other.n_coords = self.n_coords
        return other

    # -- coordinates --------------------------------------------------------------
    def get_q(self):
        """Positions as a flat vector [r_1, p_1, r_2, p_2, …] (7 n_moving,) (m, -)."""
        q = np.empty(7 * len(self.moving))
        get_poses(self.p_WB, self.quat_WB, self.moving, q)
        return q

    def set_q(self, q):
        """Inverse of :meth:`get_q`; q (7 n_moving,). Quaternions are normalised (scalar
        part ≥ 0); a zero or non-finite one raises ValueError."""
        q = np.ascontiguousarray(q, dtype=float).reshape(-1)
        if q.shape != (7 * len(self.moving),):
            raise ValueError(f"q must have {7 * len(self.moving)} entries (7 per moving body), got {q.shape}")
        k = set_poses(q, self.moving, self.p_WB, self.quat_WB, self.R_WB)
        if k >= 0:
            raise ValueError(f"cannot normalise quaternion {q[7 * k + 3 : 7 * k + 7]!r}")

    def displace(self, dq_hat):
        """Finite displacement on the manifold: r ← r + δr, p ← p ⊗ exp(½ δπ').

        dq_hat : (6 n_moving,) [m, rad] in the q̂ convention of docs/design.md §1.
        """
        displace_poses(self.p_WB, self.quat_WB, self.R_WB, self.moving, self.column,
                       np.ascontiguousarray(dq_hat, dtype=float))

    def get_v(self):
        """Generalised velocity (6 n_moving,) [m/s, rad/s]."""
        v = np.empty(self.n_coords)
        get_velocities(self.v_WB, self.w_BB, self.column, self.moving, v)
        return v

    def set_v(self, v):
        """Set body velocities from a generalised velocity (6 n_moving,) [m/s, rad/s]."""
        v = np.ascontiguousarray(v, dtype=float)
        if v.shape != (self.n_coords,):
            raise ValueError(f"v must have {self.n_coords} entries (6 per moving body), got {v.shape}")
        set_velocities(v, self.column, self.moving, self.v_WB, self.w_BB)
