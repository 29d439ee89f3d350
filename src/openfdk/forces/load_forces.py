"""External loads as one force set (:mod:`.forceset`): a force F and a moment M (time
functions) at a point P of body B (p_BP, m) give, on the body's 6 columns
(q̂ = [δr_W; δπ_B]),

    Q = [F_W ; p̃_BP R_WBᵀ F_W + M_B]        (N, N m)

with F_W = F, M_B = R_WBᵀ M for components in the world frame, and F_W = R_WB F,
M_B = M in the body frame. A rotation δπ_B turns R_WB into R_WB (I + δπ̃_B), so
∂(R_WBᵀ x)/∂δπ_B = (R_WBᵀ x)~ and ∂(R_WB y)/∂δπ_B = −R_WB ỹ; the stiffness is, in the
body's rotation columns,

    world components:  K_rot = [0 ; p̃_BP (R_WBᵀ F)~ + (R_WBᵀ M)~]
    body components:   K_rot = [−R_WB F̃ ; 0].
"""

from __future__ import annotations

import numpy as np

from ..numerics.spatial import skew


def _cross(a, b):
    """a × b of two (3,) arrays (np.cross is slow on single vectors)."""
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


class LoadForces:
    """The external loads (tuple of :class:`~.elements.ExternalLoad`) of a model.
    Outputs: dict load name -> (F_W (3,) N, M_B (3,) N m, F (3,), M (3,) as given)."""

    kind = "loads"

    def __init__(self, loads):
        self.loads = tuple(loads)

    def accumulate(self, state, t, Q, K=None):
        out = {}
        for load in self.loads:
            i = load.body
            c = state.column[i]
            if c < 0:
                continue
            R = state.R_WB[i]
            F, M = load.force.derivatives(t)[0], load.moment.derivatives(t)[0]
            F_W, M_B = (F, R.T @ M) if load.frame == "world" else (R @ F, M)
            Q[c : c + 3] += F_W
            Q[c + 3 : c + 6] += _cross(load.p_BP, R.T @ F_W) + M_B
            out[load.name] = (F_W, M_B, F, M)
            if K is not None:
                self._add_stiffness(load, c, R, F, M, K)
        return out

    def stiffness(self, state, out, K):
        for load in self.loads:
            if load.name in out:
                c = state.column[load.body]
                _, _, F, M = out[load.name]
                self._add_stiffness(load, c, state.R_WB[load.body], F, M, K)

    @staticmethod
    def _add_stiffness(load, c, R, F, M, K):
        """K += ∂Q/∂δπ_B of one load (module docstring); F, M as given (3,)."""
        if load.frame == "world":
            K[c + 3 : c + 6, c + 3 : c + 6] += skew(load.p_BP) @ skew(R.T @ F) + skew(R.T @ M)
        else:
            K[c : c + 3, c + 3 : c + 6] -= R @ skew(F)
