"""Muscles that FDK can never recruit: columns absorbed by the free FDK residual forces.

In the recruitment (paper Eq. 11) the reactions and the FDK residual forces f^FDK are
free columns of C f = d (Eq. 14). Eliminating them (:mod:`openfdk.recruitment.reduction`)
projects every muscle's column c_i onto the orthogonal complement of their span; the
bounded problem sees only that projection. When a muscle's column lies in the span of the
free columns, its projection is zero, its dual g_i = c_iᵀλ vanishes identically, and the
polynomial criterion gives it no force at any α (the reduction zeroes such a column:
with p = 3 a round-off g_i ≈ ±1e-12 gave ≈ sqrt(g_i) noise instead, a few mN). FDK then balances the FDK DOFs
without it: f^FDK(α) = 0 is reached, if at all, by the passive forces alone.

This happens when a muscle acts only on a body whose every DOF is force-dependent, besides
bodies whose loads go to reactions: the vasti of a knee whose six patellofemoral
coordinates are FDK DOFs (femur → patella; the patellar tendon is a passive ligament) act
on the patella, where f^FDK takes their force at no cost, and on the femur, where the
reactions do. Muscles absorbed by the reactions alone (e.g. one spanning only a locked
joint) are not this module's concern: that is not caused by FDK.

:func:`fdk_absorbed_muscles` finds them at one pose; ``openfdk check`` lists them and
:func:`openfdk.fdk.analysis.run_fdk` warns once per run.
"""

from __future__ import annotations

import numpy as np

# a muscle is absorbed when the part of its column outside the free columns' span is
# below ABSORBED_RTOL of the column's norm (the reduction zeroes such a column)
from ..recruitment.reduction import ABSORBED_RTOL


def _outside(C_F, C):
    """‖c − P c‖ / ‖c‖ of every column c of C (m, k) for P the orthogonal projector onto
    range(C_F) (C_F (m, j)); 1 where C_F is empty, 0 for a zero column. Returns (k,)."""
    norms = np.linalg.norm(C, axis=0)
    if C_F.shape[1] == 0:
        return np.where(norms > 0.0, 1.0, 0.0)
    U, sv, _ = np.linalg.svd(C_F, full_matrices=False)
    Q = U[:, sv > sv.max() * 1e-11]
    rest = np.linalg.norm(C - Q @ (Q.T @ C), axis=0)
    return np.where(norms > 0.0, rest / np.where(norms > 0.0, norms, 1.0), 0.0)


def fdk_absorbed_muscles(solver, state, t=0.0, alpha=None):
    """Names of the muscles whose equilibrium column at ``state`` lies in the span of the
    free columns (reactions and FDK residual forces) but not in the span of the reactions
    alone: FDK can never recruit them (module docstring). ``solver``: InverseDynamics whose
    system has the FDK rows; ``alpha`` (n_fdk,) SI, default the DOFs' initial values.
    Returns [] for a model without FDK DOFs or muscles."""
    lay = solver.layout
    model = solver.model
    if not model.fdk_dofs or lay.n_muscles == 0:
        return []
    if alpha is None:
        alpha = np.array([d.initial for d in model.fdk_dofs])
    C, _, _, _, _ = solver.equilibrium(state, np.zeros(state.n_coords), t, alpha, forces=False)
    names = lay.column_names
    free = np.arange(lay.n_bounded, C.shape[1])
    reactions = np.array([j for j in free if not names[j].startswith("fdk.")], dtype=int)
    M = C[:, : lay.n_muscles]
    absorbed = (_outside(C[:, free], M) < ABSORBED_RTOL) & (_outside(C[:, reactions], M) >= ABSORBED_RTOL)
    return [names[i] for i in np.flatnonzero(absorbed & (np.linalg.norm(M, axis=0) > 0.0))]


def absorbed_message(names, fdk_bodies=()):
    """The one-line warning for :func:`fdk_absorbed_muscles`'s ``names``."""
    where = f" (FDK bodies: {', '.join(fdk_bodies)})" if fdk_bodies else ""
    return (f"FDK will never recruit muscle(s) {', '.join(names)}: they act only where the FDK residual forces are "
            f"free{where}, so the recruitment (paper Eq. 11) gives them no force at any α and FDK balances those "
            "DOFs with the passive forces alone (docs/fdk.md, 'Muscles FDK cannot recruit')")


__all__ = ["fdk_absorbed_muscles", "absorbed_message", "ABSORBED_RTOL"]
