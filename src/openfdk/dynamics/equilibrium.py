"""Newton–Euler equilibrium in the form C f = d (paper Eqs. 12–14).

For every moving body i whose equilibrium is analysed (6 rows: force in world, moment
about the centre of mass in the body frame — the generalised forces conjugate to
q̂ = [δr; δπ']):

    d_i = [ m_i (r̈_i − g) ; J'_i ω̇'_i + ω̃'_i J'_i ω'_i ] − Q_i^applied      (Eq. 13)

where Q^applied collects external loads and every passive element (ligaments, springs,
contacts, passive muscle tension). Unknown columns (Eq. 12):

* muscles: C^M = −(∂l/∂q̂)ᵀ (a tension shortens the path), 0 ≤ f^M ≤ s;
* actuators (:mod:`openfdk.forces.actuators`): C^A = +(∂u/∂q̂)ᵀ of the coordinate u they
  act along, weighted by their optimal force, signed (split in two by the recruitment);
* unilateral reactions (one-sided joint rows): ±Φ_q̂ᵀ of the row, 0 ≤ f ≤ strength;
* joint reactions: C^R = Φ̃_q̂ᵀ for the rows of constraints that carry reactions (free);
* FDK residual forces: C^FDK = Φ^FDK_q̂ᵀ, one free column per FDK DOF (Eq. 14).

Column order: [muscles, actuators, unilateral reactions | joint reactions, FDK
residuals], the first group bounded (the recruitment's n_bounded).

In a model with actuators, the drivers of joint coordinates (a ``--motion``, prescribed
coordinates) carry no reaction column: the muscles and the actuators move the model, as
in OpenSim's static optimisation, and a coordinate nothing can move makes the frame
infeasible, with its row named. Without actuators each such driver carries its reaction,
an ideal cost-free actuator: the coordinate's generalised force (inverse dynamics).
Other drivers (of measures) keep their ``reaction`` setting.
"""

from __future__ import annotations

import weakref
from dataclasses import dataclass

import numpy as np
from numba import njit

from ..model.constraints import DRIVER



@dataclass(frozen=True, eq=False)
class EquilibriumLayout:
    """Rows and columns of C f = d for one model.

    eq_coords : (n_rows,) q̂ indices of the equilibrium rows; row_names;
    muscles : tuple of Muscle; actuators : tuple of actuators (forces.actuators; columns right
    after the muscles'); unilateral : tuple of (system row, sign, strength, name);
    free_rows : (n_free_reactions,) system rows of free joint reactions;
    fdk_rows : system rows of the FDK DOFs; column_names; n_bounded.
    """

    eq_coords: np.ndarray
    row_names: tuple
    muscles: tuple
    actuators: tuple
    unilateral: tuple
    free_rows: np.ndarray
    fdk_rows: np.ndarray
    column_names: tuple
    n_bounded: int

    @property
    def n_muscles(self):
        return len(self.muscles)

    @property
    def n_actuators(self):
        return len(self.actuators)

    @property
    def n_columns(self):
        return len(self.column_names)


_LAYOUTS = weakref.WeakKeyDictionary()


def equilibrium_layout(model, system):
    """The layout of the model and its ConstraintSystem (with FDK rows), built once per
    model and system rows (a trial's solver is built per run: a study's cases, a bench's
    repeats)."""
    key = tuple(system.row_names)
    cached = _LAYOUTS.get(model)
    if cached is not None and cached[0] == key:
        return cached[1]
    layout = _build_layout(model, system)
    _LAYOUTS[model] = (key, layout)
    return layout


def _build_layout(model, system):
    """The layout (:func:`equilibrium_layout`), built."""
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
    # with actuators, the drivers of coordinates carry no reaction (module docstring)
    actuated = {id(c.measure) for c in model.coordinates} if model.actuators else set()
    free_rows = [offsets[c.name] + k for c in model.constraints
                 if c.reaction and balanced.intersection(c.measure.bodies())
                 and not (c.kind == DRIVER and id(c.measure) in actuated)
                 for k in range(c.size) if offsets[c.name] + k not in one_sided]
    n_joint = sum(c.size for c in model.constraints)
    fdk_rows = list(range(n_joint, n_joint + len(model.fdk_dofs)))
    names = [m.name for m in muscles] + [a.name for a in model.actuators] + [u[3] for u in unilateral]
    names += [system.row_names[i] for i in free_rows] + [f"fdk.{d.name}" for d in model.fdk_dofs]
    return EquilibriumLayout(
        np.array(eq_coords, dtype=int), tuple(row_names), muscles, tuple(model.actuators), unilateral,
        np.array(free_rows, dtype=int), np.array(fdk_rows, dtype=int), tuple(names),
        len(muscles) + len(model.actuators) + len(unilateral),
    )


_BODY_ARRAYS = weakref.WeakKeyDictionary()


def _body_arrays(model):
    """(column (nm,), mass (nm,) kg, inertia (nm, 3, 3) kg m², body index (nm,)) of the
    moving bodies, built once per model."""
    arrays = _BODY_ARRAYS.get(model)
    if arrays is None:
        moving = model.moving_bodies
        arrays = (np.array([b.column for b in moving], np.int64), np.array([b.mass for b in moving], float),
                  np.array([b.inertia_B for b in moving], float).reshape(-1, 3, 3),
                  np.array([b.index for b in moving], np.int64))
        _BODY_ARRAYS[model] = arrays
    return arrays


@njit(cache=True)
def _inertial_minus_gravity(column, mass, inertia, index, w_BB, vdot, g, out):
    for k in range(column.shape[0]):
        c = column[k]
        J = inertia[k]
        w0, w1, w2 = w_BB[index[k], 0], w_BB[index[k], 1], w_BB[index[k], 2]
        for r in range(3):
            out[c + r] = mass[k] * (vdot[c + r] - g[r])
        # J ω̇' + ω̃' J ω'  (Eq. 13)
        h0 = J[0, 0] * w0 + J[0, 1] * w1 + J[0, 2] * w2
        h1 = J[1, 0] * w0 + J[1, 1] * w1 + J[1, 2] * w2
        h2 = J[2, 0] * w0 + J[2, 1] * w1 + J[2, 2] * w2
        out[c + 3] = J[0, 0] * vdot[c + 3] + J[0, 1] * vdot[c + 4] + J[0, 2] * vdot[c + 5] + w1 * h2 - w2 * h1
        out[c + 4] = J[1, 0] * vdot[c + 3] + J[1, 1] * vdot[c + 4] + J[1, 2] * vdot[c + 5] + w2 * h0 - w0 * h2
        out[c + 5] = J[2, 0] * vdot[c + 3] + J[2, 1] * vdot[c + 4] + J[2, 2] * vdot[c + 5] + w0 * h1 - w1 * h0


def inertial_minus_gravity(model, state, vdot):
    """[m (r̈ − g); J ω̇' + ω̃' J ω'] per moving body, stacked (n,) [N, N m] (Eq. 13)."""
    column, mass, inertia, index = _body_arrays(model)
    out = np.zeros(state.n_coords)
    _inertial_minus_gravity(column, mass, inertia, index, state.w_BB,
                            np.ascontiguousarray(vdot, dtype=float), np.asarray(model.gravity_W, float), out)
    return out


def assemble(layout, A, L_muscles, d_full, U_actuators=None):
    """C (n_rows, n_cols) and d (n_rows,) restricted to the equilibrium rows (Eq. 12).

    A : (n_sys_rows, n) constraint Jacobian incl. FDK rows; L_muscles : (n_muscles, n)
    path-length Jacobians; d_full : (n,) right-hand side for all coordinates;
    U_actuators : (n_actuators, n) ∂u/∂q̂ of the actuators' coordinates.
    Columns: −Lᵀ (muscles), +Uᵀ (actuators), ±Φ_q̂ᵀ (unilateral reactions), Φ̃_q̂ᵀ (joint
    reactions), Φ^FDK_q̂ᵀ (FDK residual forces). One compiled loop (:func:`_assemble`).
    """
    rows = layout.eq_coords
    sel, sign = _reaction_rows(layout)
    nm = layout.n_muscles
    L = L_muscles if nm else np.zeros((0, A.shape[1]))
    if layout.n_actuators:
        L = np.concatenate([L, -np.asarray(U_actuators, float)])  # −(−U)ᵀ = +Uᵀ
        nm += layout.n_actuators
    C = np.empty((len(rows), nm + len(sel)))
    d = np.empty(len(rows))
    _assemble(np.asarray(L, dtype=float), np.asarray(A, dtype=float), rows, sel, sign,
              np.asarray(d_full, dtype=float), C, d)
    return C, d


@njit(cache=True)
def _assemble(L, A, rows, sel, sign, d_full, C, d):
    """C[r] ← [−L[:, c]ᵀ, sign ∘ A[sel, c]ᵀ], d[r] ← d_full[c] for each equilibrium row
    r with coordinate c = rows[r] (Eq. 12). L (n_muscles, n) m/m or m/rad; A (m_rows, n);
    rows (n_eq,), sel (n_react,) int; sign (n_react,) ±1; d_full (n,) [N, N m];
    outputs C (n_eq, n_muscles + n_react), d (n_eq,)."""
    nm = L.shape[0]
    for r in range(rows.shape[0]):
        c = rows[r]
        for j in range(nm):
            C[r, j] = -L[j, c]
        for k in range(sel.shape[0]):
            C[r, nm + k] = A[sel[k], c] * sign[k]
        d[r] = d_full[c]


_REACTION_ROWS = weakref.WeakKeyDictionary()


def _reaction_rows(layout):
    """System rows of the reaction columns (unilateral, free, FDK) and their signs."""
    out = _REACTION_ROWS.get(layout)
    if out is None:
        uni = [u[0] for u in layout.unilateral]
        sel = np.array(uni + list(layout.free_rows) + list(layout.fdk_rows), np.int64)
        sign = np.ones(len(sel))
        sign[: len(uni)] = [u[1] for u in layout.unilateral]
        out = (sel, sign)
        _REACTION_ROWS[layout] = out
    return out
