"""One interface for every kind of force element: the applied loads Q^applied of the
equilibrium (paper Eq. 13) and, when asked, their stiffness ∂Q/∂q̂ (for the analytic FDK
Jacobian).

A *force set* holds all elements of one kind of a model (one field of
:class:`~openfdk.model.model.Model`) and evaluates them at once::

    outputs = fs.accumulate(state, t, Q, K=None)  # Q (n,) += Q_set; K (n, n) += ∂Q_set/∂q̂ if not None
    fs.stiffness(state, outputs, K)               # K += ∂Q_set/∂q̂ from the outputs accumulate left

Q in N (force rows) and N m (moment rows), conjugate to q̂ = [δr_W; δπ_B] of each moving
body (6 columns per body, docs/design.md §1); K in N/m, N, N m/rad. ``outputs`` is the set's
per-frame record (lengths, tensions, contact results, …).

The forces stage (:meth:`ForceElements.accumulate`, called by
:func:`openfdk.dynamics.stages.equilibrium_stage`) loops over the model's sets with no
branch per kind. Adding a force kind = one class with ``kind``, ``accumulate`` and
``stiffness`` + one Model field + one model-file section loader + its line in
:data:`FORCE_KINDS` (docs/architecture.md).
"""

from __future__ import annotations

from typing import Protocol

import numpy as np

from .contact_forces import ContactForces
from .data_loads import DataLoadForces
from .ligament_forces import LigamentForces
from .load_forces import LoadForces
from .muscle_forces import MuscleForces
from .spring_forces import SpringForces

#: (Model field, force-set class), in the order their outputs are recorded
FORCE_KINDS = (
    ("muscles", MuscleForces),
    ("ligaments", LigamentForces),
    ("springs", SpringForces),
    ("loads", LoadForces),
    ("external_loads", DataLoadForces),
    ("contacts", ContactForces),
)


class ForceSet(Protocol):
    """All force elements of one kind of a model (see the module docstring)."""

    kind: str  #: the Model field the elements come from, e.g. "ligaments"

    def accumulate(self, state, t, Q, K=None):
        """Add the set's generalised forces to Q (n,) [N, N m] at ``state`` (BodyStates)
        and time t (s), and ∂Q/∂q̂ to K (n, n) if K is not None; return the outputs."""

    def stiffness(self, state, outputs, K):
        """Add ∂Q/∂q̂ (n, n) to K at ``state`` from the outputs :meth:`accumulate`
        returned there (not evaluated again where the set can avoid it)."""


def force_sets(model, muscle_rule="openfdk"):
    """The model's force sets, one per non-empty kind of :data:`FORCE_KINDS`;
    muscle_rule: the muscles' strength rule (:class:`~.muscle_forces.MuscleForces`)."""
    return tuple(cls(getattr(model, kind), muscle_rule) if cls is MuscleForces else cls(getattr(model, kind))
                 for kind, cls in FORCE_KINDS if getattr(model, kind))


class ForceElements:
    """Every force set of a model; outputs are a dict kind -> the set's outputs."""

    def __init__(self, model, muscle_rule="openfdk"):
        self.model = model
        self.sets = force_sets(model, muscle_rule)
        self.by_kind = {fs.kind: fs for fs in self.sets}

    def accumulate(self, state, t, Q, K=None):
        """Add every set's Q (n,) [N, N m] (and K (n, n) if not None); outputs by kind."""
        return {fs.kind: fs.accumulate(state, t, Q, K) for fs in self.sets}

    def prepare(self, times):
        """Tell the sets that have a ``prepare(times)`` (time-sampled loads) the trial's
        frame times (nf,) s, so that they evaluate their data for all frames at once."""
        for fs in self.sets:
            if hasattr(fs, "prepare"):
                fs.prepare(times)

    def stiffness(self, state, outputs, exclude=()):
        """K = ∂Q/∂q̂ (n, n) of all sets but the kinds in ``exclude`` from the outputs the
        forces stage left."""
        n = state.n_coords
        K = np.zeros((n, n))
        for fs in self.sets:
            if fs.kind not in exclude:
                fs.stiffness(state, outputs[fs.kind], K)
        return K

    def stiffness_along(self, state, outputs, U, exclude=()):
        """K U (n, m) for directions U (n, m) [m, rad] of all sets but the kinds in
        ``exclude``: a set with its own ``stiffness_along`` differences only along U,
        the others give their K times U."""
        KU = np.zeros((state.n_coords, U.shape[1]))
        K = None
        for fs in self.sets:
            if fs.kind in exclude:
                continue
            if hasattr(fs, "stiffness_along"):
                KU += fs.stiffness_along(state, outputs[fs.kind], U)
            else:
                K = np.zeros((state.n_coords, state.n_coords)) if K is None else K
                fs.stiffness(state, outputs[fs.kind], K)
        return KU if K is None else KU + K @ U

    def generalized_forces_of(self, kinds, state, t):
        """Q (n,) [N, N m] of the sets of the given kinds only, at ``state`` and t (s)."""
        Q = np.zeros(state.n_coords)
        for fs in self.sets:
            if fs.kind in kinds:
                fs.accumulate(state, t, Q)
        return Q

    def generalized_forces(self, state, t, want_stiffness=False):
        """(Q (n,), outputs by kind, K (n, n) or None) of all sets (gravity excluded)."""
        n = state.n_coords
        Q = np.zeros(n)
        K = np.zeros((n, n)) if want_stiffness else None
        return Q, self.accumulate(state, t, Q, K), K


__all__ = ["FORCE_KINDS", "ForceSet", "ForceElements", "force_sets"]
