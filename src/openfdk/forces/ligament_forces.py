"""Ligaments as one force set (:mod:`.forceset`): a tension T(l, l̇) ≥ 0 along a path of
length l acts on the bodies as Q = −Lᵀ T, L = ∂l/∂q̂ (n_ligaments, n), l̇ = L v (the
damping of :func:`.blankevoort.damped_tension`, when a ligament has any); its stiffness
(v held) is

    K = −Lᵀ diag(dT/dl) L − Σ_k T_k ∂L_kᵀ/∂q̂,

the second (geometric) term in closed form for straight paths and one batched forward
difference of the analytic Jacobians for wrapped ones (:meth:`.pathset.PathSet.add_geometric_stiffness`).
All paths go through one kernel call (:class:`.pathset.PathSet`); when every law is a
:class:`~.blankevoort.Blankevoort1991Ligament` the law runs on the arrays at once.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .blankevoort import Blankevoort1991Ligament, damped_tension
from .pathset import PathSet


@dataclass
class LigamentOutputs:
    """length (n_lig,) m; strain (n_lig,); force (n_lig,) N; L (n_lig, n) ∂l/∂q̂."""

    length: np.ndarray
    strain: np.ndarray
    force: np.ndarray
    L: np.ndarray


def blankevoort_arrays(length, l0, k_l0, k, eps_l):
    """Blankevoort1991Ligament (see :mod:`.blankevoort`) on arrays (n,): strain
    ε = (l − l0)/l0, tension f = 0 (ε < 0), k·l0·ε²/(4ε_l) (0 ≤ ε ≤ 2ε_l),
    k·l0·(ε − ε_l) (ε > 2ε_l) in N, and df/dl in N/m."""
    eps = (length - l0) / l0
    taut, linear = eps >= 0.0, eps > 2.0 * eps_l
    f = np.where(linear, k_l0 * (eps - eps_l), np.where(taut, k_l0 * eps * eps / (4.0 * eps_l), 0.0))
    df = np.where(linear, k, np.where(taut, k * eps / (2.0 * eps_l), 0.0))
    return eps, f, df


class LigamentForces:
    """The ligaments (tuple of :class:`~.elements.Ligament`) of a model."""

    kind = "ligaments"

    def __init__(self, ligaments):
        self.ligaments = tuple(ligaments)
        self.paths = PathSet(self.ligaments)
        laws = [lig.law for lig in self.ligaments]
        #: (slack length l0 (n,) m, k·l0 (n,) N, k (n,) N/m, transition strain ε_l (n,)),
        #: or None to evaluate law object by law object (the reference used by tests)
        self.blankevoort = None
        #: damping c (n,) N·s/m and OpenSim's rule (n,) bool, or None when no ligament is damped
        self.damping = None
        if all(type(x) is Blankevoort1991Ligament for x in laws) and any(x.damping > 0.0 for x in laws):
            self.damping = (np.array([x.damping for x in laws]), np.array([x.damping_rule == "opensim" for x in laws]))
        if all(type(x) is Blankevoort1991Ligament for x in laws):
            self.blankevoort = (np.array([x.slack_length for x in laws]),
                                np.array([x.stiffness * x.slack_length for x in laws]),
                                np.array([x.stiffness for x in laws]),
                                np.array([x.transition_strain for x in laws]))

    def _laws(self, lengths):
        """strain, tension T (N) and dT/dl (N/m) at the path lengths (n_lig,) m."""
        if self.blankevoort is not None:
            return blankevoort_arrays(lengths, *self.blankevoort)
        laws = [lig.law for lig in self.ligaments]
        return (np.array([float(x.strain(float(l))) for x, l in zip(laws, lengths)]),
                np.array([float(x.force(float(l))) for x, l in zip(laws, lengths)]),
                np.array([float(x.dforce_dlength(float(l))) for x, l in zip(laws, lengths)]))

    def accumulate(self, state, t, Q, K=None):
        lengths, L = self.paths.evaluate(state)
        strain, T, _ = self._laws(lengths)
        if self.damping is not None:
            T = damped_tension(T, strain, L @ state.get_v(), *self.damping)
        Q -= L.T @ T
        out = LigamentOutputs(lengths, strain, T, L)
        if K is not None:
            self.stiffness(state, out, K)
        return out

    def stiffness(self, state, out, K):
        L = out.L
        dT = self._laws(out.length)[2]
        K -= L.T @ (L * dT[:, None])
        if np.any(out.force):
            self.paths.add_geometric_stiffness(state, out.force, L, K)  # −Σ T_k ∂L_kᵀ/∂q̂

    def stiffness_along(self, state, out, U):
        """K U (n, m) for directions U (n, m) [m, rad]: :meth:`stiffness` times U, the
        wrapped strands' geometric part differenced along U's columns only."""
        L = out.L
        dT = self._laws(out.length)[2]
        KU = -(L.T @ (dT[:, None] * (L @ U)))
        if np.any(out.force):
            KU += self.paths.geometric_stiffness_along(state, out.force, L, U)
        return KU
