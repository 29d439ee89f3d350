"""A contact pair as a model force element: scatter Q (12,) and K (12, 12) into q̂.

The contacts' force set (:mod:`openfdk.forces.contact_forces`) calls
``element.generalized_forces(state, want_stiffness)`` on every entry of
``model.contacts``; this adapter evaluates an :class:`ElasticFoundation`
at the two bodies' poses from a :class:`~openfdk.model.state.BodyStates` workspace and
places the blocks at the bodies' columns (a fixed body, column −1, gets none).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .elastic_foundation import ContactResult, ElasticFoundation

__all__ = ["ContactElement"]


@dataclass(frozen=True, eq=False)
class ContactElement:
    """Elastic-foundation contact between body ``body_a`` (vertices) and ``body_b``.

    Attributes: name (str); body_a, body_b (int body indices of the model);
    pair (:class:`ElasticFoundation`, surfaces in the two bodies' frames).
    """

    name: str
    body_a: int
    body_b: int
    pair: ElasticFoundation

    def evaluate(self, state, want_stiffness: bool = False) -> ContactResult:
        """:meth:`ElasticFoundation.evaluate` at the poses in ``state`` (BodyStates)."""
        a, b = self.body_a, self.body_b
        return self.pair.evaluate(state.p_WB[a], state.R_WB[a], state.p_WB[b], state.R_WB[b],
                                  want_stiffness=want_stiffness)

    def generalized_forces(self, state, want_stiffness: bool = False):
        """Q (n,) [N, N·m], K (n, n) or None, and the :class:`ContactResult`.

        n = state.n_coords; body i's block starts at state.column[i] (6 columns:
        δr_W, δπ_B), as everywhere in openfdk.
        """
        res = self.evaluate(state, want_stiffness)
        n = state.n_coords
        Q = np.zeros(n)
        K = np.zeros((n, n)) if want_stiffness else None
        cols = [(k, int(state.column[body])) for k, body in enumerate((self.body_a, self.body_b))]
        cols = [(k, c) for k, c in cols if c >= 0]
        for k, c in cols:
            Q[c : c + 6] += res.Q[6 * k : 6 * k + 6]
            if want_stiffness:
                for m, d in cols:
                    K[c : c + 6, d : d + 6] += res.K[6 * k : 6 * k + 6, 6 * m : 6 * m + 6]
        return Q, K, res
