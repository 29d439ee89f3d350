"""Finite differences on the manifold of body poses (derivative checks, FD Jacobians).

The perturbation of coordinate k is q ⊕ ε e_k: r ← r + ε e (translations) or
R_WB ← R_WB Exp(ε e) (body-frame rotations), matching q̂ (docs/design.md §1).
"""

from __future__ import annotations

import numpy as np


def manifold_jacobian(fun, state, eps=1e-6, central=True, f0=None, columns=None):
    """Jacobian ∂fun/∂q̂ (m, 6 n_moving) of ``fun(state) -> (m,)`` by central (error
    O(ε²)) or forward (O(ε), half the evaluations) differences on the manifold.

    f0 : fun(state) when the caller has it (not evaluated again). columns : the
    coordinates (indices into q̂) to perturb when the caller knows that ``fun`` does not
    depend on the others (their columns are left zero); all by default. ``state``
    (BodyStates) is restored on return.
    """
    base = state.copy()
    f0 = np.atleast_1d(fun(state) if f0 is None else f0)
    J = np.zeros((f0.size, state.n_coords))
    for k in (range(state.n_coords) if columns is None else columns):
        e = np.zeros(state.n_coords)
        e[k] = eps
        _restore(state, base)
        state.displace(e)
        fp = np.atleast_1d(fun(state))
        if central:
            _restore(state, base)
            state.displace(-e)
            fm = np.atleast_1d(fun(state))
            J[:, k] = (fp - fm) / (2 * eps)
        else:
            J[:, k] = (fp - f0) / eps
    _restore(state, base)
    return J


def second_derivative_along(fun, state, v, h=1e-4):
    """d²/ds² fun(q(s)) at s = 0 along q(s) = q ⊕ s v (constant world ṙ and body ω',
    so v̇ = 0 and the result equals the acceleration bias b). v (6 n_moving,)."""
    base = state.copy()
    f0 = np.atleast_1d(fun(state))
    state.displace(h * np.asarray(v))
    fp = np.atleast_1d(fun(state))
    _restore(state, base)
    state.displace(-h * np.asarray(v))
    fm = np.atleast_1d(fun(state))
    _restore(state, base)
    return (fp - 2 * f0 + fm) / h**2


def _restore(state, base):
    state.p_WB[:] = base.p_WB
    state.quat_WB[:] = base.quat_WB
    state.R_WB[:] = base.R_WB
    state.w_BB[:] = base.w_BB
    state.v_WB[:] = base.v_WB
