"""Contacts as one force set (:mod:`.forceset`): each
:class:`~openfdk.contact.element.ContactElement` gives its generalised forces Q and, from
the same grid samples, its stiffness K (:mod:`openfdk.contact.elastic_foundation`).
Outputs: dict contact name -> :class:`~openfdk.contact.elastic_foundation.ContactResult`.
"""

from __future__ import annotations


class ContactForces:
    """The contacts (tuple of ContactElement) of a model."""

    kind = "contacts"

    def __init__(self, contacts):
        self.contacts = tuple(contacts)
        #: whether K is the exact derivative of Q: grid-mode pairs only (exact mode omits B's
        #: curvature, :mod:`openfdk.contact.elastic_foundation`)
        self.exact_stiffness = all(c.pair.mode == "grid" for c in self.contacts)

    def accumulate(self, state, t, Q, K=None):
        out = {}
        for contact in self.contacts:
            Qc, Kc, out[contact.name] = contact.generalized_forces(state, K is not None)
            Q += Qc
            if K is not None:
                K += Kc
        return out

    def stiffness(self, state, out, K):
        # K comes with Q from the same samples: the contacts are evaluated once more
        for contact in self.contacts:
            K += contact.generalized_forces(state, True)[1]
