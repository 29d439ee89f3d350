"""Finite differences on the manifold of body poses (derivative checks, FD Jacobians).

The perturbation of coordinate k is q ⊕ ε e_k: r ← r + ε e (translations) or
R_WB ← R_WB Exp(ε e) (body-frame rotations), matching q̂ (docs/design.md §1).
"""

from __future__ import annotations

import numpy as np


def manifold_jacobian(fun, state, eps=1e-6, central=True, f0=None, columns=None, pattern=None, groups=None):
    """Jacobian ∂fun/∂q̂ (m, 6 n_moving) of ``fun(state) -> (m,)`` by central (error
    O(ε²)) or forward (O(ε), half the evaluations) differences on the manifold.

    f0 : fun(state) when the caller has it (not evaluated again). columns : the
    coordinates (indices into q̂) to perturb when the caller knows that ``fun`` does not
    depend on the others (their columns are left zero); all by default. pattern :
    (m, 6 n_moving) bool, the entries that can be non-zero: columns whose rows do not
    overlap are then perturbed together, one evaluation per group of
    :func:`column_groups` (Curtis, Powell & Reid 1974), and each column's rows are read
    off that evaluation. Where an entry outside the pattern is exactly zero — the rows
    of ``fun`` are computed only from the coordinates the pattern gives them — the
    result equals the one-column-at-a-time differences. groups : the pattern's
    :func:`column_groups` when the caller keeps them. ``state`` (BodyStates) is
    restored on return.
    """
    if pattern is None:  # one column per evaluation, all its rows
        groups = [[k] for k in (range(state.n_coords) if columns is None else columns)]
    else:
        pattern = np.asarray(pattern, dtype=bool)
        groups = column_groups(pattern) if groups is None else groups
    base = state.copy()
    f0 = np.atleast_1d(fun(state) if f0 is None else f0)
    J = np.zeros((f0.size, state.n_coords))
    for group in groups:
        e = np.zeros(state.n_coords)
        e[group] = eps
        _restore(state, base)
        state.displace(e)
        fp = np.atleast_1d(fun(state))
        if central:
            _restore(state, base)
            state.displace(-e)
            d = (fp - np.atleast_1d(fun(state))) / (2 * eps)
        else:
            d = (fp - f0) / eps
        for k in group:
            rows = slice(None) if pattern is None else pattern[:, k]
            J[rows, k] = d[rows]
    _restore(state, base)
    return J


def column_groups(pattern):
    """Columns of ``pattern`` (m, n) bool in groups (list of index arrays) whose rows do
    not overlap: greedily, each column into the first group it fits. Differencing a
    group's columns together then separates their entries exactly."""
    pattern = np.asarray(pattern, dtype=bool)
    groups, rows = [], []
    for j in range(pattern.shape[1]):
        for g, used in enumerate(rows):
            if not np.any(used & pattern[:, j]):
                groups[g].append(j)
                used |= pattern[:, j]
                break
        else:
            groups.append([j])
            rows.append(pattern[:, j].copy())
    return [np.array(g, dtype=np.int64) for g in groups]


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
