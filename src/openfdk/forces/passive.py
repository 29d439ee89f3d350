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


@dataclass
class PassiveOutputs:
    """Per-element outputs at one frame (SI units)."""

    ligament_length: np.ndarray
    ligament_strain: np.ndarray
    ligament_force: np.ndarray
    spring_value: np.ndarray
    spring_force: np.ndarray
    contact: dict


def _cross(a, b):
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


class LigamentSet:
    """The ligaments of a model along their paths (one batched path kernel call).

    Force-element interface (shared by every set here): ``accumulate(state, t, Q, K,
    out)`` adds the generalised forces to Q (n,) [N, N m] and, when K (n, n) is given,
    the stiffness ∂Q/∂q̂ to K; per-element outputs go into ``out`` (PassiveOutputs)."""

    def __init__(self, ligaments):
        from .pathset import PathSet

        self.ligaments = tuple(ligaments)
        self.paths = PathSet(self.ligaments) if self.ligaments else None

    def accumulate(self, state, t, Q, K, out):
        if not self.ligaments:
            return
        lengths, L = self.paths.evaluate(state)
        for k, lig in enumerate(self.ligaments):
            length = float(lengths[k])
            T = float(lig.law.force(length))
            out.ligament_length[k] = length
            out.ligament_strain[k] = float(lig.law.strain(length))
            out.ligament_force[k] = T
            Q -= L[k] * T  # Q = −Lᵀ T
            if K is not None:
                K -= np.outer(L[k], L[k]) * float(lig.law.dforce_dlength(length))
        if K is not None and np.any(out.ligament_force):
            # geometric term −Σ T_k ∂L_kᵀ/∂q̂, one batched difference of the path kernel
            T = out.ligament_force.copy()
            K -= manifold_jacobian(lambda s: T @ self.paths.evaluate(s)[1], state, 1e-7, central=False)


class SpringSet:
    """Linear springs on scalar measures (one kernel call when they are relative-vector
    projections): Q = Mᵀ f, f = −k (m − m_rest). Interface of :class:`LigamentSet`."""

    def __init__(self, springs):
        self.springs = tuple(springs)
        self._rows = ScalarRows([s.measure for s in self.springs])

    def measures(self, state):
        """(values (n_springs,), M (n_springs, n)) of the springs' measures (row 0 each)."""
        return self._rows.evaluate(state, 1)[:2]

    def accumulate(self, state, t, Q, K, out):
        if not self.springs:
            return
        m_s, M_s = self.measures(state)
        for k, spr in enumerate(self.springs):
            f = float(spr.law.force(float(m_s[k])))
            out.spring_value[k] = float(m_s[k])
            out.spring_force[k] = f
            Q += M_s[k] * f
            if K is not None:
                K += np.outer(M_s[k], M_s[k]) * float(spr.law.dforce_dmeasure(float(m_s[k])))
        if K is not None and np.any(out.spring_force):
            # geometric term Σ f_k ∂M_kᵀ/∂q̂
            f = out.spring_force.copy()
            K += manifold_jacobian(lambda s: f @ self.measures(s)[1], state, 1e-7, central=False)


class LoadSet:
    """External loads (F, M) at body points: Q = [F_W; p̃_BP R_WBᵀ F_W + M_B]. Their
    stiffness is not modelled (K unchanged). Interface of :class:`LigamentSet`."""

    def __init__(self, loads):
        self.loads = tuple(loads)

    def accumulate(self, state, t, Q, K, out):
        for load in self.loads:
            Q += self.load_Q(load, state, t)

    @staticmethod
    def load_Q(load, state, t):
        """Generalised force (n,) of an external load (force in world/body, moment)."""
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


class ContactSet:
    """Elastic-foundation contacts (:class:`openfdk.contact.element.ContactElement`),
    analytic stiffness. Interface of :class:`LigamentSet`."""

    def __init__(self, contacts):
        self.contacts = tuple(contacts)

    def accumulate(self, state, t, Q, K, out):
        for contact in self.contacts:
            Qc, Kc, info = contact.generalized_forces(state, K is not None)
            Q += Qc
            if K is not None:
                K += Kc
            out.contact[contact.name] = info


class PassiveElements:
    """All passive elements of a model: the ligament, spring, load and contact sets, each
    with the force-element interface (generalised forces, stiffness when asked)."""

    def __init__(self, model):
        self.model = model
        self.ligaments = model.ligaments
        self.springs = model.springs
        self.loads = model.loads
        self.contacts = model.contacts
        self.ligament_set = LigamentSet(model.ligaments)
        self.spring_set = SpringSet(model.springs)
        self.load_set = LoadSet(model.loads)
        self.contact_set = ContactSet(model.contacts)

    @property
    def _spring_rows(self):
        """The springs' rows (batched when possible; tests switch the batching off)."""
        return self.spring_set._rows

    def generalized_forces(self, state, t, want_stiffness=False, elements=True, loads=True):
        """Q (n,) [N, N m] of the passive elements (ligaments, springs, contacts; if
        ``elements``) and external loads (if ``loads``; gravity excluded), their outputs,
        and (if asked) K = ∂Q/∂q̂ (n, n) of the elements."""
        n = state.n_coords
        Q = np.zeros(n)
        K = np.zeros((n, n)) if want_stiffness else None
        nl, ns = len(self.ligaments), len(self.springs)
        out = PassiveOutputs(np.zeros(nl), np.zeros(nl), np.zeros(nl), np.zeros(ns), np.zeros(ns), {})
        if elements:
            self.ligament_set.accumulate(state, t, Q, K, out)
            self.spring_set.accumulate(state, t, Q, K, out)
        if loads:
            self.load_set.accumulate(state, t, Q, K, out)
        if elements:
            self.contact_set.accumulate(state, t, Q, K, out)
        return Q, out, K
