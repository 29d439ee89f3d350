"""Newton–Euler equilibrium in the form C f = d (paper Eqs. 12–14).

For every moving body i whose equilibrium is analysed (6 rows: force in world, moment
about the centre of mass in the body frame — the generalised forces conjugate to
q̂ = [δr; δπ']):

    d_i = [ m_i (r̈_i − g) ; J'_i ω̇'_i + ω̃'_i J'_i ω'_i ] − Q_i^applied      (Eq. 13)

where Q^applied collects external loads and every passive element (ligaments, springs,
contacts, passive muscle tension). Unknown columns (Eq. 12):

* muscles: C^M = −(∂l/∂q̂)ᵀ (a tension shortens the path), 0 ≤ f^M ≤ s;
* unilateral reactions (one-sided joint rows): ±Φ_q̂ᵀ of the row, 0 ≤ f ≤ strength;
* joint reactions: C^R = Φ̃_q̂ᵀ for the rows of constraints that carry reactions (free);
* FDK residual forces: C^FDK = Φ^FDK_q̂ᵀ, one free column per FDK DOF (Eq. 14).

Column order: [muscles, unilateral reactions | joint reactions, FDK residuals], the
first group bounded (the recruitment's n_bounded).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np



def _cross(a, b):
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


@dataclass(frozen=True)
class EquilibriumLayout:
    """Rows and columns of C f = d for one model.

    eq_coords : (n_rows,) q̂ indices of the equilibrium rows; row_names;
    muscles : tuple of Muscle; unilateral : tuple of (system row, sign, strength, name);
    free_rows : (n_free_reactions,) system rows of free joint reactions;
    fdk_rows : system rows of the FDK DOFs; column_names; n_bounded.
    """

    eq_coords: np.ndarray
    row_names: tuple
    muscles: tuple
    unilateral: tuple
    free_rows: np.ndarray
    fdk_rows: np.ndarray
    column_names: tuple
    n_bounded: int

    @property
    def n_muscles(self):
        return len(self.muscles)

    @property
    def n_columns(self):
        return len(self.column_names)


def equilibrium_layout(model, system):
    """Build the layout from the model and its ConstraintSystem (with FDK rows)."""
    eq_coords, row_names = [], []
    for b in model.moving_bodies:
        if b.equilibrium:
            eq_coords += list(range(b.column, b.column + 6))
            row_names += [f"{b.name}.{c}" for c in ("Fx", "Fy", "Fz", "Mx", "My", "Mz")]
    muscles = model.muscles
    offsets, r = {}, 0
    for c in model.constraints:
        offsets[c.name] = r
        r += c.size
    unilateral = tuple(
        (offsets[u.constraint] + u.row, u.direction, u.strength, u.name)
        for u in model.unilateral_reactions
    )
    one_sided = {u[0] for u in unilateral}
    # a reaction acts in equilibrium only if its constraint touches a body with rows
    balanced = {b.index for b in model.moving_bodies if b.equilibrium}
    free_rows = [offsets[c.name] + k for c in model.constraints
                 if c.reaction and balanced.intersection(c.measure.bodies()) for k in range(c.size)
                 if offsets[c.name] + k not in one_sided]
    n_joint = sum(c.size for c in model.constraints)
    fdk_rows = list(range(n_joint, n_joint + len(model.fdk_dofs)))
    names = [m.name for m in muscles] + [u[3] for u in unilateral]
    names += [system.row_names[i] for i in free_rows] + [f"fdk.{d.name}" for d in model.fdk_dofs]
    return EquilibriumLayout(
        np.array(eq_coords, dtype=int), tuple(row_names), muscles, unilateral,
        np.array(free_rows, dtype=int), np.array(fdk_rows, dtype=int), tuple(names),
        len(muscles) + len(unilateral),
    )


def inertial_minus_gravity(model, state, vdot):
    """[m (r̈ − g); J ω̇' + ω̃' J ω'] per moving body, stacked (n,) [N, N m]."""
    out = np.zeros(model.n_coords)
    g = model.gravity_W
    for b in model.moving_bodies:
        c = b.column
        w = state.w_BB[b.index]
        out[c : c + 3] = b.mass * (vdot[c : c + 3] - g)
        out[c + 3 : c + 6] = b.inertia_B @ vdot[c + 3 : c + 6] + _cross(w, b.inertia_B @ w)
    return out


def assemble(layout, A, L_muscles, d_full):
    """C (n_rows, n_cols) and d (n_rows,) restricted to the equilibrium rows.

    A : (n_sys_rows, n) constraint Jacobian incl. FDK rows; L_muscles : (n_muscles, n)
    path-length Jacobians; d_full : (n,) right-hand side for all coordinates.
    """
    rows = layout.eq_coords
    cols = [-L_muscles.T] if layout.n_muscles else []
    if layout.unilateral:
        idx = np.array([u[0] for u in layout.unilateral], dtype=int)
        sign = np.array([u[1] for u in layout.unilateral], dtype=float)
        cols.append(A[idx].T * sign)
    cols.append(A[layout.free_rows].T)
    cols.append(A[layout.fdk_rows].T)
    C = np.concatenate(cols, axis=1)[rows]
    return C, d_full[rows]
