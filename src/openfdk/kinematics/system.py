"""Assembly of the hard constraints Φ(q, t) = 0 (paper Eq. 1) with FDK rows Φ^FDK − α.

``ConstraintSystem.evaluate`` returns, in the paper's conventions,
``Φ`` (m,), ``Φ_q̂`` (m, 6 n_moving), ``ν`` (m,) with Φ_q̂ v = ν = −Φ_t (Eq. 2) and
``γ`` (m,) with Φ_q̂ v̇ = γ = f̈ − b (Eq. 3).
"""

from __future__ import annotations

import numpy as np

from ..model.batched import RelativeVectorRows, ScalarRows
from ..model.model import Model


class KinematicsError(ValueError):
    """The kinematic problem is ill-posed (redundant, inconsistent or too few constraints)."""


class ConstraintSystem:
    """All constraint rows of a model: joints and drivers, then FDK DOF rows.

    include_fdk : append one row per FDK DOF, Φ^FDK(q) − α = 0 (α given at evaluation).
    """

    def __init__(self, model: Model, include_fdk=True):
        self.model = model
        self.blocks = list(model.constraints)
        self.fdk = list(model.fdk_dofs) if include_fdk else []
        self.row_names = model.constraint_row_names() + [f"fdk.{d.name}" for d in self.fdk]
        self.n_rows = len(self.row_names)
        self.n_coords = model.n_coords
        units = [u for c in self.blocks for u in c.measure.units] + [d.measure.units[0] for d in self.fdk]
        # angle rows are compared modulo 2π: a driver may prescribe θ beyond ±π while
        # the Cardan-angle measure returns values in (−π, π]
        self.angle_rows = np.array([u == "angle" for u in units], dtype=bool)
        self.has_angles = bool(self.angle_rows.any())
        # joint and FDK rows that are projections of relative vectors: one kernel call
        # each for all of them (None: evaluated measure by measure)
        self._block_rows = RelativeVectorRows.from_measures([c.measure for c in self.blocks])
        self._fdk_rows = ScalarRows([d.measure for d in self.fdk])  # row 0 of each

    def evaluate(self, state, t, alpha=None, order=1):
        """Φ, Φ_q̂, ν, γ at time t (s) for FDK inputs α (n_fdk,) in m or rad.

        order 0: (Φ, None, None, None); order 1 adds Φ_q̂ and ν; order 2 adds γ (needs
        the state's velocities).
        """
        return self._evaluate(state, t, alpha, order, True)

    def bias(self, state, t, alpha=None):
        """γ (m,) alone, Φ_q̂ v̇ = γ (Eq. 3), at a pose whose Φ_q̂ is already known (the
        velocity stage; needs the state's velocities). Φ_q̂ is not assembled again (the
        measure kernels still return their rows with the bias)."""
        return self._evaluate(state, t, alpha, 2, False)[3]

    def _evaluate(self, state, t, alpha, order, jacobian):
        m, n = self.n_rows, self.n_coords
        Phi = np.empty(m)
        Phi_q = None if (order == 0 or not jacobian) else np.empty((m, n))
        nu = None if (order == 0 or not jacobian) else np.empty(m)
        gamma = None if order < 2 else np.empty(m)
        r = 0
        if self._block_rows is not None:
            vals, Ms, bs = self._block_rows.evaluate(state, order)
        for c in self.blocks:
            k = c.size
            if self._block_rows is not None:
                val, M = vals[r : r + k], (None if order == 0 else Ms[r : r + k])
                b = None if order < 2 else bs[r : r + k]
            else:
                val, M, b = c.measure.evaluate(state, order)
            f, df, ddf = c.target_derivatives(t)
            Phi[r : r + k] = val - f
            if order >= 1 and jacobian:
                Phi_q[r : r + k] = M
                nu[r : r + k] = df  # Eq. 2: Φ_t = −ḟ
            if order >= 2:
                gamma[r : r + k] = ddf - b  # Eq. 3
            r += k
        if self.fdk:
            alpha = np.zeros(len(self.fdk)) if alpha is None else np.asarray(alpha, dtype=float)
            vals, Ms, bs = self._fdk_rows.evaluate(state, order)
            Phi[r:] = vals - alpha  # Φ^FDK − α (Eq. 1); α̇ = α̈ = 0
            if order >= 1 and jacobian:
                Phi_q[r:] = Ms
                nu[r:] = 0.0
            if order >= 2:
                gamma[r:] = -bs
        if self.has_angles:
            a = self.angle_rows
            Phi[a] = (Phi[a] + np.pi) % (2.0 * np.pi) - np.pi
        return Phi, Phi_q, nu, gamma


def dependent_rows(A, row_names, tol=1e-9):
    """Names of constraint rows that take part in a linear dependency of A (m, n).

    Uses the left null space of A (SVD): a row is reported when it has a significant
    weight in a left-null vector. Returns (rank, list of row names).
    """
    if A.shape[0] == 0:
        return 0, []
    U, s, _ = np.linalg.svd(A)
    scale = s[0] if s.size and s[0] > 0 else 1.0
    rank = int(np.sum(s > tol * scale))
    left_null = U[:, rank:]
    if left_null.shape[1] == 0:
        return rank, []
    weight = np.sqrt(np.sum(left_null**2, axis=1))
    return rank, [row_names[i] for i in np.flatnonzero(weight > 1e-6)]


def undetermined_coordinates(A, coord_names, tol=1e-9):
    """Names of q̂ components that A (m, n) leaves free (right null space)."""
    if A.shape[0] == 0:
        return list(coord_names)
    _, s, Vt = np.linalg.svd(A)
    scale = s[0] if s.size and s[0] > 0 else 1.0
    rank = int(np.sum(s > tol * scale))
    null = Vt[rank:].T
    if null.shape[1] == 0:
        return []
    weight = np.sqrt(np.sum(null**2, axis=1))
    return [coord_names[i] for i in np.flatnonzero(weight > 1e-6)]
