"""Dynamic stages of a frame (docs/design.md §3, :mod:`openfdk.model.framedata`): forces and
equilibrium C f = d (Eqs. 12–14) from the position stage's Φ_q̂, then the recruitment
(Eq. 11)."""

from __future__ import annotations


def equilibrium_stage(solver, data, state):
    """Forces (every force set of the model: path lengths and Jacobians, strengths,
    applied loads) and C, d, s from the data's Φ_q̂ and v̇ (``state`` holds q and v);
    solver : InverseDynamics."""
    C, d, s, muscles, outputs = solver.equilibrium(state, data.vdot, data.t, data.alpha, data.Phi_q)
    data.C, data.d, data.s = C, d, s
    data.muscle_length, data.L, data.muscle_speed = muscles.length, muscles.L, muscles.speed
    data.muscle_strength, data.muscle_passive = muscles.strength, muscles.passive
    data.forces = outputs
    return data


def recruitment_stage(solver, data, warm=None):
    """The recruitment of data.C, data.d, data.s (warm: a previous RecruitmentResult)."""
    data.recruitment = solver.recruit(data.C, data.d, data.s, warm)
    return data
