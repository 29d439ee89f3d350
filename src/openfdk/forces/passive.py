"""Passive force elements evaluated at a state: generalised forces Q (applied loads in
the equilibrium, paper Eq. 13) and per-element outputs.

* ligament along a path of length l with tension T(l) ≥ 0:  Q = −Lᵀ T,  L = ∂l/∂q̂;
* spring on a measure m:  Q = Mᵀ f,  f = −k (m − m_rest);
* muscle passive (parallel-elastic) tension f_P:  Q = −Lᵀ f_P (added by the caller, which
  knows the muscle states);
* external load (F, M) at a body point P:  Q = [F_W; R_WBᵀ (p̃_BP R_WBᵀ F_W) + M_B];
* contacts: generalised forces from :mod:`openfdk.contact` when the model has any.

Also returns, on request, the stiffness ∂Q/∂q̂ of ligaments and springs (for the analytic
FDK Jacobian): K = −Lᵀ (dT/dl) L − Σ T ∂Lᵀ/∂q̂; the second (geometric) term is one
batched forward difference of the analytic path Jacobians on the manifold (relative
error ~1e-7, far below what the FDK Jacobian needs).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..model.batched import ScalarRows
from ..numdiff import manifold_jacobian
from .blankevoort import Blankevoort1991Ligament


@dataclass
class PassiveOutputs:
    """Per-element outputs at one frame (SI units)."""

    ligament_length: np.ndarray
    ligament_strain: np.ndarray
    ligament_force: np.ndarray
    spring_value: np.ndarray
    spring_force: np.ndarray
    contact: dict
    ligament_L: np.ndarray = None  #: (n_ligaments, n) path Jacobians ∂l/∂q̂ (for the stiffness)
    spring_M: np.ndarray = None  #: (n_springs, n) measure Jacobians (for the stiffness)


def _cross(a, b):
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


def _blankevoort_arrays(length, l0, k_l0, k, eps_l):
    """Blankevoort1991Ligament (see :mod:`.blankevoort`) on arrays (n,): strain
    ε = (l − l0)/l0, tension f = 0 (ε < 0), k·l0·ε²/(4ε_l) (0 ≤ ε ≤ 2ε_l),
    k·l0·(ε − ε_l) (ε > 2ε_l) in N, and df/dl in N/m."""
    eps = (length - l0) / l0
    taut, linear = eps >= 0.0, eps > 2.0 * eps_l
    f = np.where(linear, k_l0 * (eps - eps_l), np.where(taut, k_l0 * eps * eps / (4.0 * eps_l), 0.0))
    df = np.where(linear, k, np.where(taut, k * eps / (2.0 * eps_l), 0.0))
    return eps, f, df


class PassiveElements:
    """All passive elements of a model (ligaments, springs, loads, contacts)."""

    def __init__(self, model):
        self.model = model
        self.ligaments = model.ligaments
        self.springs = model.springs
        self.loads = model.loads
        self.contacts = model.contacts
        from .pathset import PathSet

        self.ligament_paths = PathSet(self.ligaments) if self.ligaments else None
        laws = [lig.law for lig in self.ligaments]
        self._blankevoort = None
        if laws and all(type(x) is Blankevoort1991Ligament for x in laws):
            # (slack length l0 (n,) m, k·l0 (n,) N, k (n,) N/m, transition strain ε_l (n,))
            self._blankevoort = (np.array([x.slack_length for x in laws]),
                                 np.array([x.stiffness * x.slack_length for x in laws]),
                                 np.array([x.stiffness for x in laws]),
                                 np.array([x.transition_strain for x in laws]))
        # the springs' measures (one kernel call when they are relative-vector projections)
        self._spring_rows = ScalarRows([s.measure for s in self.springs])

    def _spring_measures(self, state):
        """(values (n_springs,), M (n_springs, n)) of the springs' measures (row 0 each)."""
        return self._spring_rows.evaluate(state, 1)[:2]

    def generalized_forces(self, state, t, want_stiffness=False, elements=True, loads=True):
        """Q (n,) [N, N m] of the passive elements (ligaments, springs, contacts; if
        ``elements``) and external loads (if ``loads``; gravity excluded), their outputs,
        and (if asked) K = ∂Q/∂q̂ (n, n) of the elements."""
        n = state.n_coords
        Q = np.zeros(n)
        K = np.zeros((n, n)) if want_stiffness else None
        nl, ns = len(self.ligaments), len(self.springs)
        out = PassiveOutputs(np.zeros(nl), np.zeros(nl), np.zeros(nl), np.zeros(ns), np.zeros(ns), {})
        ligaments, springs, contacts = (self.ligaments, self.springs, self.contacts) if elements else ((), (), ())
        if ligaments:
            lengths, L = self.ligament_paths.evaluate(state)
            out.ligament_length[:], out.ligament_L = lengths, L
            if self._blankevoort is not None:
                # all Blankevoort1991Ligament: the law on the (n_ligaments,) arrays at once
                strain, T, _ = _blankevoort_arrays(lengths, *self._blankevoort)
                out.ligament_strain[:], out.ligament_force[:] = strain, T
                Q -= L.T @ T
            for k, lig in enumerate(ligaments if self._blankevoort is None else ()):
                length = float(lengths[k])
                T = float(lig.law.force(length))
                out.ligament_strain[k] = float(lig.law.strain(length))
                out.ligament_force[k] = T
                Q -= L[k] * T
        if springs:
            m_s, M_s = self._spring_measures(state)
            out.spring_M = M_s
        for k, spr in enumerate(springs):
            f = float(spr.law.force(float(m_s[k])))
            out.spring_value[k] = float(m_s[k])
            out.spring_force[k] = f
            Q += M_s[k] * f
        for load in self.loads if loads else ():
            Q += self._load_Q(load, state, t)
        for contact in contacts:
            Qc, Kc, info = contact.generalized_forces(state, want_stiffness)
            Q += Qc
            if want_stiffness:
                K += Kc
            out.contact[contact.name] = info
        if want_stiffness:
            K += self.stiffness(state, out, contacts=False)
        return Q, out, K

    def stiffness(self, state, out, contacts=True):
        """K = ∂Q/∂q̂ (n, n) of the elements at ``state``, from the outputs ``out`` the
        forces stage left there (ligament lengths, forces and path Jacobians; spring
        values, forces and measure Jacobians), which are not evaluated again; the
        geometric terms differentiate the path/measure Jacobians at nearby poses. The
        contacts (if ``contacts``) are evaluated once more: their K comes from the same
        grid samples as their Q."""
        n = state.n_coords
        K = np.zeros((n, n))
        if self.ligaments and out.ligament_L is not None:
            L, lengths = out.ligament_L, out.ligament_length
            if self._blankevoort is not None:
                dT = _blankevoort_arrays(lengths, *self._blankevoort)[2]
                K -= L.T @ (L * dT[:, None])
            for k, lig in enumerate(self.ligaments if self._blankevoort is None else ()):
                K -= np.outer(L[k], L[k]) * float(lig.law.dforce_dlength(float(lengths[k])))
            if np.any(out.ligament_force):
                # geometric term −Σ T_k ∂L_kᵀ/∂q̂, one batched difference of the path kernel
                T = out.ligament_force.copy()
                K -= manifold_jacobian(lambda s: T @ self.ligament_paths.evaluate(s)[1], state, 1e-7, central=False,
                                       f0=T @ L)
        if self.springs and out.spring_M is not None:
            M_s = out.spring_M
            for k, spr in enumerate(self.springs):
                K += np.outer(M_s[k], M_s[k]) * float(spr.law.dforce_dmeasure(float(out.spring_value[k])))
            if np.any(out.spring_force):
                # geometric term Σ f_k ∂M_kᵀ/∂q̂
                f = out.spring_force.copy()
                K += manifold_jacobian(lambda s: f @ self._spring_measures(s)[1], state, 1e-7, central=False,
                                       f0=f @ M_s)
        for contact in self.contacts if contacts else ():
            K += contact.generalized_forces(state, True)[1]
        return K

    @staticmethod
    def _load_Q(load, state, t):
        """Generalised force of an external load (force in world/body, moment)."""
        i = load.body
        c = state.column[i]
        Q = np.zeros(state.n_coords)
        if c < 0:
            return Q
        R = state.R_WB[i]
        F, M = load.force.derivatives(t)[0], load.moment.derivatives(t)[0]
        if load.frame == "world":
            F_W, M_B = F, R.T @ M
        else:
            F_W, M_B = R @ F, M
        Q[c : c + 3] = F_W
        Q[c + 3 : c + 6] = _cross(load.p_BP, R.T @ F_W) + M_B
        return Q
