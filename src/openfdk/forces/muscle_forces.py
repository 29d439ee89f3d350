"""Muscles as one force set (:mod:`.forceset`): path lengths l (n_m,) m, Jacobians
L = ∂l/∂q̂ (n_m, n), lengthening speeds L v, strengths s and passive (parallel-elastic)
tensions f_P(l) of the strength models (:class:`.hill.MuscleSet`). The active forces are
unknowns of the recruitment (columns −Lᵀ of C, paper Eq. 12); the passive tension is an
applied load (Eq. 13):

    Q = −Lᵀ f_P,   K = −Lᵀ diag(df_P/dl) L − Σ_k f_P,k ∂L_kᵀ/∂q̂,

df_P/dl from the strength model's implicit derivative of its passive equilibrium, the
geometric term from :meth:`.pathset.PathSet.add_geometric_stiffness` (only when some
f_P ≠ 0).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .hill import MuscleSet
from .pathset import PathSet

#: strengths below this (N) are raised to it so that the recruitment stays defined; a
#: muscle shorter than its tendon slack length thus delivers (numerically) nothing.
MIN_STRENGTH = 1e-6


@dataclass
class MuscleOutputs:
    """length (n_m,) m; L (n_m, n) ∂l/∂q̂; speed (n_m,) m/s; strength (n_m,) N (≥
    MIN_STRENGTH); passive (n_m,) N, f_P; dpassive (n_m,) N/m, df_P/dl."""

    length: np.ndarray
    L: np.ndarray
    speed: np.ndarray
    strength: np.ndarray
    passive: np.ndarray
    dpassive: np.ndarray

    @classmethod
    def empty(cls, n):
        """No muscles, n coordinates."""
        z = np.zeros(0)
        return cls(z, np.zeros((0, n)), z, z, z, z)


class MuscleForces:
    """The muscles (tuple of :class:`~.elements.Muscle`) of a model. rule : "openfdk"
    (strengths and passive forces of :mod:`.hill`) or "opensim" (OpenSim's static
    optimisation: :mod:`.rigid_tendon` strengths, no passive force)."""

    kind = "muscles"

    def __init__(self, muscles, rule="openfdk"):
        self.muscles = tuple(muscles)
        self.paths = PathSet(self.muscles)
        self.strength_models = MuscleSet([m.law for m in self.muscles])
        self.rule = rule

    def states(self, state):
        """The muscles' :class:`MuscleOutputs` at ``state`` (q and v)."""
        l, L = self.paths.evaluate(state)
        speed = L @ state.get_v()
        if self.rule == "opensim":
            from .rigid_tendon import opensim_strengths

            zero = np.zeros(len(self.muscles))
            return MuscleOutputs(l, L, speed, np.maximum(opensim_strengths(self.strength_models, l, speed),
                                                         MIN_STRENGTH), zero, zero.copy())
        s, f_p, df_p = self.strength_models.evaluate_with_passive_slope(l, speed)
        return MuscleOutputs(l, L, speed, np.maximum(s, MIN_STRENGTH), f_p, df_p)

    def slopes(self, out):
        """(∂s/∂l (n_m,) N/m, ∂s/∂l̇ (n_m,) N s/m, ∂f_P/∂l (n_m,) N/m) at the outputs ``out``
        (MuscleOutputs): the strengths' and passive tensions' rates along the muscle–tendon
        length and speed, from the strength model's implicit derivatives (rule "openfdk";
        zero where the strength is raised to MIN_STRENGTH) or by central differences of
        the OpenSim rule's strengths (1e-7 m, 1e-7 m/s; no passive tension)."""
        if self.rule == "opensim":
            from .rigid_tendon import opensim_strengths

            h = 1e-7
            models, l, v = self.strength_models, out.length, out.speed
            raised = out.strength <= MIN_STRENGTH
            ds_dl = (opensim_strengths(models, l + h, v) - opensim_strengths(models, l - h, v)) / (2 * h)
            ds_dv = (opensim_strengths(models, l, v + h) - opensim_strengths(models, l, v - h)) / (2 * h)
            zero = np.zeros(len(self.muscles))
            return np.where(raised, 0.0, ds_dl), np.where(raised, 0.0, ds_dv), zero
        st = self.strength_models.evaluate_states(out.length, out.speed)
        raised = st.strength <= MIN_STRENGTH
        return (np.where(raised, 0.0, st.dstrength_dlength), np.where(raised, 0.0, st.dstrength_dspeed),
                st.dpassive_dlength)

    def moved(self, state, out, slopes):
        """MuscleOutputs at ``state`` (q and v), a small displacement from the pose of
        ``out``: the paths evaluated there, the strengths and passive tensions carried to
        first order along the change of l and l̇ = L v with ``slopes`` (:meth:`slopes` at
        ``out``). For the differences of the analytic FDK Jacobian along dq̂/dα: to first
        order the same as :meth:`states` there, without solving the strength models
        again (their fibre equilibria)."""
        l, L = self.paths.evaluate(state)
        speed = L @ state.get_v()
        ds_dl, ds_dv, dfp_dl = slopes
        dl, dv = l - out.length, speed - out.speed
        return MuscleOutputs(l, L, speed, np.maximum(out.strength + ds_dl * dl + ds_dv * dv, MIN_STRENGTH),
                             out.passive + dfp_dl * dl, out.dpassive)

    def accumulate(self, state, t, Q, K=None):
        out = self.states(state)
        Q -= out.L.T @ out.passive  # passive tension is an applied load
        if K is not None:
            self.stiffness(state, out, K)
        return out

    def stiffness(self, state, out, K):
        L = out.L
        K -= L.T @ (L * out.dpassive[:, None])
        if np.any(out.passive):
            self.paths.add_geometric_stiffness(state, out.passive, L, K)  # −Σ f_P,k ∂L_kᵀ/∂q̂
