"""A joint's load as OpenSim's ``JointReaction`` analysis reports it with its options
``apply_on_bodies`` and ``express_in_frame`` (the model file's ``joint_reaction``
section, :mod:`.joint_reaction_settings`).

From the load on the child, F_W (N) and M_WP (N m) about the child frame's origin P in
the ground (:func:`~openfdk.dynamics.joint_loads.joint_loads`):

* on the child: F = F_W, M = M_WP, the point P;
* on the parent (Newton's third law): F = −F_W, about the origin Q of the joint's parent
  frame M = −M_WP + (p_WP − p_WQ) × (−F_W), the point Q;
* expressed in a frame F fixed on a body: the vectors turned by R_WFᵀ, the point
  R_WFᵀ (p_W − p_WF), the point's location in that frame.
"""

from __future__ import annotations

import numpy as np


def _frame_pose(model, state, body, p_BF, R_BF):
    """(R_WF (3, 3), p_WF (3,) m) of a frame fixed on ``body`` ("ground": the world, whose
    frame an OpenSim model's ground body keeps)."""
    if body == "ground":
        return R_BF, p_BF
    i = model.body(body).index
    R_WB = state.R_WB[i]
    return R_WB @ R_BF, state.p_WB[i] + R_WB @ p_BF


def _in_world(r):
    """Whether the report is expressed in the world's own axes at its origin."""
    return r.frame_body == "ground" and not np.any(r.p_BF) and np.array_equal(r.R_BF, np.eye(3))


def _poses(model, q, reports):
    """(R_WF (nr, nf, 3, 3), p_WF (nr, nf, 3) m, p_WQ (nr, nf, 3) m): each report's frame
    and, on the parent, the joint's parent frame origin, at the poses ``q``; NaN where a
    pose is not finite."""
    nf = len(q)
    parents = {j.name: j.parent for j in model.joints}
    R_WF, p_WF = np.full((len(reports), nf, 3, 3), np.nan), np.full((len(reports), nf, 3), np.nan)
    p_WQ = np.full((len(reports), nf, 3), np.nan)
    state = model.initial_state()
    for k in range(nf):
        if not np.isfinite(q[k]).all():
            continue
        state.set_q(q[k])
        for n, r in enumerate(reports):
            R_WF[n, k], p_WF[n, k] = _frame_pose(model, state, r.frame_body, r.p_BF, r.R_BF)
            if r.on == "parent":
                parent = parents[r.joint]
                frame = model.frame(parent) if parent else None
                p_WQ[n, k] = _frame_pose(model, state, frame.body, frame.p_BF, frame.R_BF)[1] if frame else 0.0
    return R_WF, p_WF, p_WQ


def reported_loads(model, q, loads, reports):
    """{report base label: (nf, 9) [F (N), M (N m), p (m)]} of each JointReport in
    ``reports`` (module docstring), from ``loads`` ({joint: (F_W, M_WP, p_WP)}, each
    (nf, 3), :func:`~openfdk.dynamics.joint_loads.joint_loads`) at the poses ``q``
    (nf, 7 n_moving). A frame whose pose or load is not finite gives NaN. A report on the
    child in the ground is the load itself (OpenSim's defaults: no pose is needed)."""
    q = np.asarray(q, float)
    posed = [r for r in reports if r.on == "parent" or not _in_world(r)]
    R_WF, p_WF, p_WQ = _poses(model, q, posed) if posed else (None, None, None)
    slot = {id(r): n for n, r in enumerate(posed)}
    out = {}
    for r in reports:
        F, M, P = (np.asarray(x, float) for x in loads[r.joint])
        n = slot.get(id(r))
        if n is None:
            out[r.base] = np.hstack([F, M, P])
            continue
        if r.on == "parent":
            F, M, P = -F, -M + np.cross(P - p_WQ[n], -F), p_WQ[n]
        R = R_WF[n]
        out[r.base] = np.hstack([np.einsum("kji,kj->ki", R, F), np.einsum("kji,kj->ki", R, M),
                                 np.einsum("kji,kj->ki", R, P - p_WF[n])])
    return out


__all__ = ["reported_loads"]
