"""The start of a cold determinate position solve on the near root of a closed loop.

Newton–Raphson on Φ(q, t) = 0 (Eq. 1) from the model's reference pose moves every
coordinate at once. Where a row other than a coordinate's own closes a loop, Φ has more
than one root, and a long first step can land on the far one. The DM knee's patellar
tendon is such a row: an inextensible distance |p_P − p_T| = L between the patella and
the tibial tuberosity, the only row that sets ``pf_ty_r``. The squared distance is a
quadratic in ``pf_ty_r``, with two roots: the patella above the tuberosity, and the
patella pulled down through the tibia. From the extended reference pose to the first
frame of a crouch cycle (28° of flexion), Newton's first step took ``pf_ty_r`` from
+8 mm to −124 mm, the far root; the tracked FDK has it at −13 mm (docs/gait.md, "Every
one of DM's 17 cycles in two stages").

The seeded start removes the long step: a tree pass from the root
(:func:`.tree_kinematics.tree_forward`) sets every coordinate that has a row of its own
(a driver, a lock, an FDK DOF's Φ^FDK(q) = α) to its target at t, and keeps every
other coordinate at its value in the given pose. The rows of no coordinate (the
tendon) are then the only ones Newton's method has to satisfy, and it starts from the
pose's own value of their coordinates: for the convex quadratic above, Newton's
iterates stay on the side of its vertex where they start, the patella above the
tuberosity. At that crouch frame the seeded solve puts ``pf_ty_r`` at −13.6 mm in 5
iterations.

Only for models whose moving bodies are each the child of one OpenSim-style joint
(:func:`.tree_kinematics.partial_tree_plan`); other models start from the pose as
given.
"""

from __future__ import annotations

import numpy as np

from .tree_kinematics import partial_tree_plan, tree_forward


def seed_start(system, state, t, alpha=None):
    """Move ``state`` (BodyStates, in place) to the seeded start of the position solve
    at time ``t`` (s): the coordinates with rows of their own at their targets (α
    (n_fdk,) SI for the FDK rows of ``system``, a ConstraintSystem), the others at
    their values in ``state``. Returns True when the state was moved, False when the
    model is not a tree of OpenSim-style joints (the state is unchanged). Velocities
    are left at the tree pass's (the free coordinates at rest); the rates solve (Eqs.
    2–3) sets them after the positions."""
    plan, _ = partial_tree_plan(system.model, system)
    if plan is None:
        return False
    f, df, ddf = system.targets(t, alpha)
    q_free = np.array([m.evaluate(state, 0)[0][0] for m in plan.free], float)
    zeros = np.zeros(len(plan.free))
    vdot = np.empty(system.n_coords)
    tree_forward(*plan.args, state.column, np.concatenate([f, q_free]), np.concatenate([df, zeros]),
                 np.concatenate([ddf, zeros]), state.p_WB, state.quat_WB, state.R_WB, state.w_BB, state.v_WB, vdot)
    return True
