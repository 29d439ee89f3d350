"""Body poses from joint-coordinate values: the pose an OpenSim user sets with
``Coordinate.setValue`` (and its speeds and accelerations), solved on openfdk's rows.

The model's coordinates (``model.coordinates``, OpenSim-style joints) are driven as
q(τ) = q + q̇ (τ − t) + ½ q̈ (τ − t)² and determinate kinematics (Eqs. 1–3) is solved at
τ = t (t matters to prescribed coordinates, functions of time):
the bodies' poses, velocities v (Eq. 2) and accelerations v̇ (Eq. 3). Used by the tests
against OpenSim and by users who want the model at given coordinates.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..model.constraints import DRIVER, Constraint
from ..model.model import ModelError
from ..model.timefunctions import Polynomial
from .determinate import solve_positions, solve_velocities_accelerations
from .system import ConstraintSystem, KinematicsError


def driven_model(model, names):
    """The model with a driver row ``{name}.value`` on each named coordinate (target
    a polynomial of t set by :func:`pose_from_coordinates`)."""
    by_name = {c.name: c for c in model.coordinates}
    extra = []
    for name in names:
        if name not in by_name:
            raise ModelError(f"model {model.name!r} has no coordinate {name!r}; its coordinates are {list(by_name)}")
        c = by_name[name]
        if c.locked or c.prescribed:
            continue
        extra.append(Constraint(f"{name}.value", c.measure, DRIVER, np.zeros(1), Polynomial([0.0]), False,
                                (f"{name}.value",), "driver"))
    return replace(model, constraints=tuple(model.constraints) + tuple(extra))


def pose_from_coordinates(model, q, qdot=None, qddot=None, t=0.0, state=None, tol=1e-12):
    """The state (BodyStates, poses and velocities set) and v̇ (6 n_moving,) of ``model``
    at coordinate values ``q`` {name: rad or m}, speeds ``qdot`` and accelerations
    ``qddot`` (same keys; default 0). The given coordinates are driven: give every
    independent one (a coupler's dependent coordinate follows its coupler and is left
    out; locked and prescribed coordinates follow their rows). ``state``: the starting
    pose (default: the model's reference pose). Raises KinematicsError when the rows
    cannot be solved, ModelError when the given coordinates do not determine the pose."""
    qdot, qddot = qdot or {}, qddot or {}
    free = [c.name for c in model.coordinates if not (c.locked or c.prescribed) and c.name in q]
    unknown = sorted(set(q) - {c.name for c in model.coordinates})
    if unknown:
        raise ModelError(f"pose_from_coordinates: model {model.name!r} has no coordinates {unknown}")
    driven = driven_model(model, free)
    rows = sum(c.size for c in driven.constraints)
    if rows != driven.n_coords:
        given = set(q)
        missing = [c.name for c in model.coordinates if c.name not in given and not (c.locked or c.prescribed)]
        raise ModelError(f"pose_from_coordinates: the given coordinates and the model's rows fix {rows} of "
                         f"{driven.n_coords} pose components; coordinates not given: {missing}")
    for con in driven.constraints[len(model.constraints):]:
        name = con.name[: -len(".value")]
        # q(τ) = q + q̇ (τ − t) + ½ q̈ (τ − t)², in powers of τ: the values at τ = t
        a, v, c = q[name], qdot.get(name, 0.0), 0.5 * qddot.get(name, 0.0)
        object.__setattr__(con, "function", Polynomial([a - v * t + c * t * t, v - 2.0 * c * t, c]))
    system = ConstraintSystem(driven)
    state = model.initial_state() if state is None else state
    solve = solve_positions(system, state, t, tol=tol, max_iter=100)
    if not solve.converged:
        raise KinematicsError(f"pose_from_coordinates: {solve.message}")
    _, vdot = solve_velocities_accelerations(system, state, t)
    return state, vdot
