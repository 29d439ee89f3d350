"""Muscle moment arms about the joint coordinates: OpenSim's ``computeMomentArm`` and its
MuscleAnalysis ``MomentArm`` files.

The moment arm of a muscle about a coordinate q_c is r_c = −dl/dq_c, the path's
shortening per unit of q_c while every other independent coordinate is held and the
model's constraints hold (a coupler's dependent coordinate follows its independent one,
as OpenSim's MomentArmSolver projects the speeds onto the constraints).

In openfdk's maximal coordinates (paper Eqs. 1–2) the bodies' velocities u_c = dq̂/dq_c
(n,) solve

    [ Φ_q̂ ]          [ 0   ]
    [ G_I ]  u_c  =  [ e_c ]

with Φ_q̂ the rows of the joints and constraints (not the drivers, locks or prescribed
motions on coordinates, nor the FDK rows, which the coordinate rows replace), G_I the
gradients of the independent coordinates' measures (every coordinate but a coupler's
dependent one) and e_c selecting q_c. Then r_c = −L u_c with L = ∂l/∂q̂ (n_m, n) the
paths' Jacobian, which includes a moving path point's dependence on its coordinate.
"""

from __future__ import annotations

import numpy as np

from ..model.constraints import DRIVER


def independent_coordinates(model):
    """The model's coordinates but the dependent ones of its couplers (OpenSim's
    CoordinateCouplerConstraint), in model order."""
    dependent = {j.dependent for j in model.joints if j.type == "coupler"}
    return [c for c in model.coordinates if c.name not in dependent]


def _kept_rows(model):
    """Indices of the ConstraintSystem's rows that stay in Φ_q̂ (module docstring)."""
    on_coordinates = {c.name for c in model.coordinates}
    rows, r = [], 0
    for c in model.constraints:
        if c.kind != DRIVER and getattr(c.measure, "name", None) not in on_coordinates:
            rows += range(r, r + c.size)
        r += c.size
    return np.asarray(rows, int)


def moment_arms(model, q):
    """(r (nf, n_m, n_i): m per rad about a rotational coordinate, m per m about a
    translational one; the independent coordinates (list); the frames (list of indices)
    whose pose is finite but where the rows do not fix the bodies' velocities) of every
    muscle about every independent coordinate at the poses ``q`` (nf, 7 n_moving)
    (module docstring). A frame whose pose is not finite, or one of those frames (a
    rank-deficient system: a mobility no coordinate measures), gives NaN."""
    from ..forces.pathset import PathSet
    from ..kinematics.system import ConstraintSystem

    coords = independent_coordinates(model)
    q = np.asarray(q, float)
    nf, nm, ni = len(q), len(model.muscles), len(coords)
    out = np.full((nf, nm, ni), np.nan)
    singular = []
    if not nm or not ni:
        return out, coords, singular
    system = ConstraintSystem(model)
    paths = PathSet(model.muscles)
    rows = _kept_rows(model)
    state = model.initial_state()
    n = model.n_coords
    rhs = np.zeros((len(rows) + ni, ni))
    rhs[len(rows):] = np.eye(ni)
    for k in range(nf):
        if not np.isfinite(q[k]).all():
            continue
        state.set_q(q[k])
        A = np.vstack([system.jacobian(state)[rows]] +
                      [np.asarray(c.measure.evaluate(state, 1)[1], float).reshape(1, n) for c in coords])
        if A.shape[0] != n:
            U, _, rank, _ = np.linalg.lstsq(A, rhs, rcond=None)
            if rank < n:
                singular.append(k)
                continue
        else:
            try:
                U = np.linalg.solve(A, rhs)
            except np.linalg.LinAlgError:
                singular.append(k)
                continue
        _, L = paths.evaluate(state)
        out[k] = -(L @ U)
    return out, coords, singular


__all__ = ["moment_arms", "independent_coordinates"]
