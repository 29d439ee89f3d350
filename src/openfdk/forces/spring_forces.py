"""Springs on scalar measures as one force set (:mod:`.forceset`): a generalised force
f(m) − c ṁ along the measure m (c the viscosity of a parallel damper, ṁ = M v) acts as
Q = Mᵀ f, M = ∂m/∂q̂ (n_springs, n); its stiffness (v held, as the FDK Jacobian takes
it) is

    K = Mᵀ diag(df/dm) M + Σ_k f_k ∂M_kᵀ/∂q̂,

the second (geometric) term one batched forward difference of the analytic measure
Jacobians on the manifold. The measures go through one compiled call
(:class:`~openfdk.model.batched.ScalarRows`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..model.batched import ScalarRows
from ..numerics.numdiff import manifold_jacobian


@dataclass
class SpringOutputs:
    """value (n_springs,) m or rad; force (n_springs,) N or N m; M (n_springs, n)."""

    value: np.ndarray
    force: np.ndarray
    M: np.ndarray


class SpringForces:
    """The springs (tuple of :class:`~.elements.Spring`) of a model."""

    kind = "springs"

    def __init__(self, springs):
        self.springs = tuple(springs)
        self.rows = ScalarRows([s.measure for s in self.springs])
        self.viscosity = np.array([s.viscosity for s in self.springs], float)
        self.damped = bool(np.any(self.viscosity))
        #: springs whose law has its own damper (damping_force(m, ṁ), e.g. a coordinate limit)
        self.law_damped = [k for k, s in enumerate(self.springs) if hasattr(s.law, "damping_force")]

    def _measures(self, state):
        """(values (n_springs,), M (n_springs, n)) of the springs' measures (row 0 each)."""
        return self.rows.evaluate(state, 1)[:2]

    def accumulate(self, state, t, Q, K=None):
        m, M = self._measures(state)
        f = np.array([float(spr.law.force(float(x))) for spr, x in zip(self.springs, m)])
        if self.damped or self.law_damped:
            rate = M @ state.get_v()
            f -= self.viscosity * rate  # damper: −c ṁ
            for k in self.law_damped:
                f[k] += self.springs[k].law.damping_force(m[k], rate[k])
        Q += M.T @ f
        out = SpringOutputs(m, f, M)
        if K is not None:
            self.stiffness(state, out, K)
        return out

    def stiffness(self, state, out, K):
        M = out.M
        df = np.array([float(spr.law.dforce_dmeasure(float(x))) for spr, x in zip(self.springs, out.value)])
        K += M.T @ (M * df[:, None])
        if np.any(out.force):
            # geometric term Σ f_k ∂M_kᵀ/∂q̂
            f = out.force.copy()
            K += manifold_jacobian(lambda s: f @ self._measures(s)[1], state, 1e-7, central=False, f0=f @ M)

    def stiffness_along(self, state, out, U):
        """K U (n, m) for directions U (n, m) [m, rad]: :meth:`stiffness` times U, the
        geometric term by one forward difference of the measure Jacobians along each
        column of U (step 1e-7 of its largest entry) instead of one per coordinate group
        (on the DM knee's 11 coordinate springs: 10 FDK directions instead of the 138
        coordinates, 3.3 ms of the analytic Jacobian's 35)."""
        M = out.M
        df = np.array([float(spr.law.dforce_dmeasure(float(x))) for spr, x in zip(self.springs, out.value)])
        KU = M.T @ (df[:, None] * (M @ U))
        if np.any(out.force):
            f = out.force.copy()
            g0 = f @ M
            for j in range(U.shape[1]):
                h = 1e-7 / max(float(np.max(np.abs(U[:, j]))), 1e-12)
                moved = state.copy()
                moved.displace(h * U[:, j])
                KU[:, j] += (f @ self._measures(moved)[1] - g0) / h
        return KU
