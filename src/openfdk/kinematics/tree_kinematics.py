"""Forward kinematics of a tree of OpenSim-style joints driven by their coordinates: the
bodies' poses, velocities and accelerations in one pass from the root, no Newton.

When every moving body is the child of one joint of type ``custom`` (an OpenSim
SpatialTransform, :mod:`openfdk.model.coordinate_joint`, recorded in ``model.joints``)
and every coordinate of those joints is set by one row of its own — a driver (``--motion``,
prescribed) or a lock — the determinate kinematics (Eqs. 1–3) has a closed form. For a
joint with parent frame F on body a and child frame M on body b, with the coordinates'
targets q, q̇, q̈ (the rows' f, ḟ, f̈) and each axis' function h(q) (h, h′, h″; constant
axes h = value):

    θ_i = h_i(q),  θ̇_i = h′_i q̇,  θ̈_i = h″_i q̇² + h′_i q̈          (chain rule)
    R_FM = Rot(a_1, θ_1) Rot(a_2, θ_2) Rot(a_3, θ_3)                   (intrinsic)
    ω_FM = Σ_i u_i θ̇_i,  u_i = R_1…R_{i−1} a_i                         (in F)
    α_FM = Σ_i [u_i θ̈_i + ω_{<i} × u_i θ̇_i],  ω_{<i} = Σ_{j<i} u_j θ̇_j
    p_FM = Σ_i g_i t_i,  ṗ_FM = Σ ġ_i t_i,  p̈_FM = Σ g̈_i t_i          (in F)

then, in the world, with r_aF = R_a p_aF, r_FM = R_F p_FM and r_Mb = −R_b p_bM (to the
child's centre of mass):

    R_F = R_a R_aF,  R_b = R_F R_FM R_bMᵀ,  ω_b = ω_a + R_F ω_FM,
    α_b = α_a + R_F α_FM + ω_a × R_F ω_FM,
    p_b = p_a + r_aF + r_FM + r_Mb,
    ṗ_b = ṗ_a + ω_a × (r_aF + r_FM) + R_F ṗ_FM + ω_b × r_Mb,
    p̈_b = p̈_a + α_a × (r_aF + r_FM) + ω_a × (ω_a × (r_aF + r_FM)) + 2 ω_a × R_F ṗ_FM
          + R_F p̈_FM + α_b × r_Mb + ω_b × (ω_b × r_Mb).

The state gets ω' = R_bᵀ ω_b and ω̇' = R_bᵀ α_b (docs/design.md §1). The quaternion of
R_b is taken in the hemisphere of the body's previous one (Newton's iterates move it
continuously from the reference pose), so a trial's q is continuous.

The pose is the one Newton's method finds (the rows of the joint and of its
coordinates vanish there); the caller checks it: :mod:`openfdk.analysis.tree_trial`
evaluates Φ at every frame and falls back to Newton when it is not ≈ 0.
"""

from __future__ import annotations

import weakref
from dataclasses import dataclass

import numpy as np
from numba import njit

from ..model.coordinate_functions import pp_evaluate

_JOINT_TYPE = "custom"


@dataclass(frozen=True, eq=False)
class TreePlan:
    """A model's joints in the order of a pass from the root (nj joints).

    parent, child : (nj,) body indices; R_aF (nj, 3, 3), p_aF (nj, 3) m: F in the
    parent's body frame; R_bM, p_bM: M in the child's; axis (nj, 6, 3): the three
    rotation axes then the three translation axes; row (nj, 6): the constraint row whose
    target is the axis' coordinate (−1: a constant axis); value (nj, 6): a constant
    axis' value (rad or m); fstart (nj, 6): where the axis' function starts in
    ``fparams`` (PiecewisePolynomial.to_params layout)."""

    parent: np.ndarray
    child: np.ndarray
    R_aF: np.ndarray
    p_aF: np.ndarray
    R_bM: np.ndarray
    p_bM: np.ndarray
    axis: np.ndarray
    row: np.ndarray
    value: np.ndarray
    fstart: np.ndarray
    fparams: np.ndarray
    #: a partial plan's coordinates without a row of their own (:func:`partial_tree_plan`):
    #: their measures, whose values are the targets of pseudo rows n_rows, n_rows + 1, …
    free: tuple = ()

    @property
    def args(self):
        """The arrays in :func:`tree_forward`'s argument order."""
        return (self.parent, self.child, self.R_aF, self.p_aF, self.R_bM, self.p_bM, self.axis, self.row,
                self.value, self.fstart, self.fparams)


_PLANS = weakref.WeakKeyDictionary()


def tree_plan(model, system):
    """(TreePlan, "") when ``model``'s determinate kinematics is a tree of custom joints
    driven by their coordinates (module docstring), else (None, the reason). Built once
    per model; ``system`` is its ConstraintSystem."""
    cached = _PLANS.get(model)
    if cached is None:
        cached = _PLANS[model] = _build_plan(model, system)
    return cached


_PARTIAL_PLANS = weakref.WeakKeyDictionary()


def partial_tree_plan(model, system):
    """(TreePlan, "") of the tree pass that sets every coordinate with a row of its own
    (a driver, a lock, an FDK DOF's row Φ^FDK = α) to its target and every other
    coordinate to a given value (``TreePlan.free``, in the order of pseudo rows after
    ``system``'s), skipping the rows of no coordinate (closed loops, distance
    constraints); (None, the reason) when the model is not a tree of custom joints.
    Built once per model and FDK rows (:mod:`.seeded_start` uses it)."""
    plans = _PARTIAL_PLANS.setdefault(model, {})
    key = bool(system.fdk)
    if key not in plans:
        plans[key] = _build_plan(model, system, partial=True)
    return plans[key]


def _build_plan(model, system, partial=False):
    if model.fdk_dofs and not partial:
        return None, "the model has FDK DOFs"
    if system.n_rows != system.n_coords and not partial:
        return None, f"{system.n_rows} constraint rows for {system.n_coords} coordinates"
    joints = [j for j in getattr(model, "joints", ()) if j.type == _JOINT_TYPE]
    others = [j.name for j in getattr(model, "joints", ()) if j.type != _JOINT_TYPE]
    if not joints or others:
        return None, f"joints other than OpenSim's ({others[:3]})" if others else "no OpenSim-style joint"
    coordinate = {id(c.measure): c.name for c in model.coordinates}
    names = {j.name for j in joints}
    driving, r = {}, 0  # coordinate -> its row
    for c in model.constraints:
        if c.name in names and c.kind == "joint":
            pass
        elif c.size == 1 and id(c.measure) in coordinate and coordinate[id(c.measure)] not in driving:
            driving[coordinate[id(c.measure)]] = r
        elif not partial:
            return None, f"constraint {c.name!r} is neither an OpenSim joint nor its coordinate's only driver"
        r += c.size
    for d in system.fdk if partial else ():  # the FDK rows follow the constraints' (system.py)
        if id(d.measure) in coordinate and coordinate[id(d.measure)] not in driving:
            driving[coordinate[id(d.measure)]] = r
        r += 1
    by_measure = {c.name: c.measure for c in model.coordinates}
    free = []
    by_child, bodies = {}, model.bodies
    for j in joints:
        a, b = model.frame(j.parent), model.frame(j.child)
        ia, ib = model.body(a.body).index, model.body(b.body).index
        if bodies[ib].column < 0 or ib in by_child:
            return None, f"body {b.body!r} is fixed or the child of two joints"
        by_child[ib] = (j, a, b, ia)
    moving = [b.index for b in model.moving_bodies]
    if sorted(by_child) != moving:
        return None, "a moving body is the child of no OpenSim joint"
    order, placed = [], {b.index for b in bodies if b.column < 0}
    while len(order) < len(by_child):
        ready = [ib for ib, (_, _, _, ia) in by_child.items() if ib not in placed and ia in placed]
        if not ready:
            return None, "the joints form a loop"
        for ib in sorted(ready):
            order.append(by_child[ib])
            placed.add(ib)
    nj = len(order)
    axis, row = np.zeros((nj, 6, 3)), np.full((nj, 6), -1, np.int64)
    value, fstart, fparams = np.zeros((nj, 6)), np.zeros((nj, 6), np.int64), [0.0]
    for k, (j, _, _, _) in enumerate(order):
        for s, ax in enumerate(tuple(j.rotations) + tuple(j.translations)):
            axis[k, s] = ax.axis
            if ax.coordinate is None:
                value[k, s] = float(ax.function)
                continue
            if ax.coordinate not in driving and partial:
                driving[ax.coordinate] = system.n_rows + len(free)
                free.append(by_measure[ax.coordinate])
            elif ax.coordinate not in driving:
                return None, f"coordinate {ax.coordinate!r} is not set by a driver or a lock of its own"
            row[k, s] = driving[ax.coordinate]
            fstart[k, s] = len(fparams)
            fparams.extend(ax.function.to_params())
    plan = TreePlan(
        np.array([ia for _, _, _, ia in order], np.int64),
        np.array([model.body(b.body).index for _, _, b, _ in order], np.int64),
        np.array([a.R_BF for _, a, _, _ in order], float).reshape(nj, 3, 3),
        np.array([a.p_BF for _, a, _, _ in order], float).reshape(nj, 3),
        np.array([b.R_BF for _, _, b, _ in order], float).reshape(nj, 3, 3),
        np.array([b.p_BF for _, _, b, _ in order], float).reshape(nj, 3),
        axis, row, value, fstart, np.array(fparams, float), tuple(free))
    return plan, ""


@njit(cache=True)
def _cross(a, b, out):
    out[0] = a[1] * b[2] - a[2] * b[1]
    out[1] = a[2] * b[0] - a[0] * b[2]
    out[2] = a[0] * b[1] - a[1] * b[0]


@njit(cache=True)
def _rotate_by(R, a, angle, out):
    """out ← R Rot(a, angle), Rot = I + sin θ K + (1 − cos θ) K² (Rodrigues; K = ã, a (3,)
    unit in R's rotated frame; K² = a aᵀ − I)."""
    s, c1 = np.sin(angle), 1.0 - np.cos(angle)
    a0, a1, a2 = a[0], a[1], a[2]
    m00, m01, m02 = 1.0 + c1 * (a0 * a0 - 1.0), c1 * a0 * a1 - s * a2, c1 * a0 * a2 + s * a1
    m10, m11, m12 = c1 * a1 * a0 + s * a2, 1.0 + c1 * (a1 * a1 - 1.0), c1 * a1 * a2 - s * a0
    m20, m21, m22 = c1 * a2 * a0 - s * a1, c1 * a2 * a1 + s * a0, 1.0 + c1 * (a2 * a2 - 1.0)
    for i in range(3):
        r0, r1, r2 = R[i, 0], R[i, 1], R[i, 2]
        out[i, 0] = r0 * m00 + r1 * m10 + r2 * m20
        out[i, 1] = r0 * m01 + r1 * m11 + r2 * m21
        out[i, 2] = r0 * m02 + r1 * m12 + r2 * m22


@njit(cache=True)
def quat_near(R, prev, out):
    """out (4,) ← the Euler parameters (scalar first) of R (3, 3), Shepperd's method, in
    the hemisphere of ``prev`` (4,) (out · prev ≥ 0; out may be prev)."""
    p0, p1, p2, p3 = prev[0], prev[1], prev[2], prev[3]
    tr = R[0, 0] + R[1, 1] + R[2, 2]
    if tr >= R[0, 0] and tr >= R[1, 1] and tr >= R[2, 2]:
        s = 2.0 * np.sqrt(1.0 + tr)
        out[0], out[1], out[2], out[3] = 0.25 * s, (R[2, 1] - R[1, 2]) / s, (R[0, 2] - R[2, 0]) / s, \
            (R[1, 0] - R[0, 1]) / s
    elif R[0, 0] >= R[1, 1] and R[0, 0] >= R[2, 2]:
        s = 2.0 * np.sqrt(1.0 + R[0, 0] - R[1, 1] - R[2, 2])
        out[0], out[1], out[2], out[3] = (R[2, 1] - R[1, 2]) / s, 0.25 * s, (R[0, 1] + R[1, 0]) / s, \
            (R[0, 2] + R[2, 0]) / s
    elif R[1, 1] >= R[2, 2]:
        s = 2.0 * np.sqrt(1.0 + R[1, 1] - R[0, 0] - R[2, 2])
        out[0], out[1], out[2], out[3] = (R[0, 2] - R[2, 0]) / s, (R[0, 1] + R[1, 0]) / s, 0.25 * s, \
            (R[1, 2] + R[2, 1]) / s
    else:
        s = 2.0 * np.sqrt(1.0 + R[2, 2] - R[0, 0] - R[1, 1])
        out[0], out[1], out[2], out[3] = (R[1, 0] - R[0, 1]) / s, (R[0, 2] + R[2, 0]) / s, \
            (R[1, 2] + R[2, 1]) / s, 0.25 * s
    norm = np.sqrt(out[0] ** 2 + out[1] ** 2 + out[2] ** 2 + out[3] ** 2)
    sign = 1.0 if out[0] * p0 + out[1] * p1 + out[2] * p2 + out[3] * p3 >= 0.0 else -1.0
    for r in range(4):
        out[r] *= sign / norm


@njit(cache=True)
def tree_forward(parent, child, R_aF, p_aF, R_bM, p_bM, axis, row, value, fstart, fparams, column,
                 f, df, ddf, p_WB, quat_WB, R_WB, w_BB, v_WB, vdot):
    """The module docstring's pass, one joint after the other (parents first).

    Plan arrays: :class:`TreePlan`; column (nb,) first q̂ column of each body (−1:
    fixed); f, ḟ, f̈ (m,): the constraint rows' targets at this time (m or rad and
    their rates). Writes the children's p_WB (nb, 3) m, quat_WB (nb, 4), R_WB
    (nb, 3, 3), w_BB (nb, 3) rad/s (body frame), v_WB (nb, 3) m/s and vdot (n,)
    [m/s², rad/s² body frame]; fixed bodies keep their pose, at rest."""
    th, dth, ddth = np.empty(6), np.empty(6), np.empty(6)
    R_FM, R_tmp, R_F, R_b = np.empty((3, 3)), np.empty((3, 3)), np.empty((3, 3)), np.empty((3, 3))
    u, w_FM, al_FM, x = np.empty(3), np.empty(3), np.empty(3), np.empty(3)
    p_FM, dp_FM, ddp_FM = np.empty(3), np.empty(3), np.empty(3)
    w_a, al_a, a_a = np.empty(3), np.empty(3), np.empty(3)
    r_aM, wF, w_b, al_b, r_Mb = np.empty(3), np.empty(3), np.empty(3), np.empty(3), np.empty(3)
    t1, t2, acc = np.empty(3), np.empty(3), np.empty(3)
    for k in range(parent.shape[0]):
        # θ, θ̇, θ̈ of the six axes (chain rule through each axis' function)
        for s in range(6):
            r = row[k, s]
            if r < 0:
                th[s], dth[s], ddth[s] = value[k, s], 0.0, 0.0
            else:
                h, dh, d2h = pp_evaluate(fparams, fstart[k, s], f[r])
                th[s], dth[s], ddth[s] = h, dh * df[r], d2h * df[r] * df[r] + dh * ddf[r]
        # R_FM, ω_FM, α_FM in F
        for i in range(3):
            for j in range(3):
                R_FM[i, j] = 1.0 if i == j else 0.0
            w_FM[i] = 0.0
            al_FM[i] = 0.0
        for s in range(3):
            for i in range(3):
                u[i] = R_FM[i, 0] * axis[k, s, 0] + R_FM[i, 1] * axis[k, s, 1] + R_FM[i, 2] * axis[k, s, 2]
            _cross(w_FM, u, x)
            for i in range(3):
                al_FM[i] += u[i] * ddth[s] + x[i] * dth[s]
                w_FM[i] += u[i] * dth[s]
            _rotate_by(R_FM, axis[k, s], th[s], R_tmp)
            R_FM[:, :] = R_tmp
        for i in range(3):
            p_FM[i] = th[3] * axis[k, 3, i] + th[4] * axis[k, 4, i] + th[5] * axis[k, 5, i]
            dp_FM[i] = dth[3] * axis[k, 3, i] + dth[4] * axis[k, 4, i] + dth[5] * axis[k, 5, i]
            ddp_FM[i] = ddth[3] * axis[k, 3, i] + ddth[4] * axis[k, 4, i] + ddth[5] * axis[k, 5, i]
        # the parent in the world: R_a, ω_a, α_a, p̈_a
        a, b = parent[k], child[k]
        R_a = R_WB[a]
        ca = column[a]
        for i in range(3):
            if ca >= 0:
                w_a[i] = R_a[i, 0] * w_BB[a, 0] + R_a[i, 1] * w_BB[a, 1] + R_a[i, 2] * w_BB[a, 2]
                al_a[i] = R_a[i, 0] * vdot[ca + 3] + R_a[i, 1] * vdot[ca + 4] + R_a[i, 2] * vdot[ca + 5]
                a_a[i] = vdot[ca + i]
            else:
                w_a[i], al_a[i], a_a[i] = 0.0, 0.0, 0.0
        for i in range(3):
            for j in range(3):
                R_F[i, j] = R_a[i, 0] * R_aF[k, 0, j] + R_a[i, 1] * R_aF[k, 1, j] + R_a[i, 2] * R_aF[k, 2, j]
        for i in range(3):
            for j in range(3):
                R_tmp[i, j] = R_F[i, 0] * R_FM[0, j] + R_F[i, 1] * R_FM[1, j] + R_F[i, 2] * R_FM[2, j]
        for i in range(3):
            for j in range(3):  # R_b = R_F R_FM R_bMᵀ
                R_b[i, j] = R_tmp[i, 0] * R_bM[k, j, 0] + R_tmp[i, 1] * R_bM[k, j, 1] + R_tmp[i, 2] * R_bM[k, j, 2]
        # r_aM = r_aF + r_FM (parent's centre of mass to M's origin), ω_b, α_b, r_Mb
        for i in range(3):
            r_aM[i] = (R_a[i, 0] * p_aF[k, 0] + R_a[i, 1] * p_aF[k, 1] + R_a[i, 2] * p_aF[k, 2]
                       + R_F[i, 0] * p_FM[0] + R_F[i, 1] * p_FM[1] + R_F[i, 2] * p_FM[2])
            wF[i] = R_F[i, 0] * w_FM[0] + R_F[i, 1] * w_FM[1] + R_F[i, 2] * w_FM[2]
            w_b[i] = w_a[i] + wF[i]
            r_Mb[i] = -(R_b[i, 0] * p_bM[k, 0] + R_b[i, 1] * p_bM[k, 1] + R_b[i, 2] * p_bM[k, 2])
        _cross(w_a, wF, x)
        for i in range(3):
            al_b[i] = al_a[i] + R_F[i, 0] * al_FM[0] + R_F[i, 1] * al_FM[1] + R_F[i, 2] * al_FM[2] + x[i]
        # positions and velocities
        cb = column[b]
        _cross(w_a, r_aM, t1)
        _cross(w_b, r_Mb, t2)
        for i in range(3):
            p_WB[b, i] = p_WB[a, i] + r_aM[i] + r_Mb[i]
            vF = R_F[i, 0] * dp_FM[0] + R_F[i, 1] * dp_FM[1] + R_F[i, 2] * dp_FM[2]
            v_WB[b, i] = (v_WB[a, i] if ca >= 0 else 0.0) + t1[i] + vF + t2[i]
            u[i] = vF  # R_F ṗ_FM, for the Coriolis term
        # p̈_b = p̈_a + α_a × r_aM + ω_a × (ω_a × r_aM) + 2 ω_a × R_F ṗ_FM + R_F p̈_FM
        #       + α_b × r_Mb + ω_b × (ω_b × r_Mb)
        _cross(w_a, r_aM, t1)
        _cross(w_a, t1, t2)
        _cross(al_a, r_aM, x)
        for i in range(3):
            acc[i] = a_a[i] + x[i] + t2[i] + R_F[i, 0] * ddp_FM[0] + R_F[i, 1] * ddp_FM[1] + R_F[i, 2] * ddp_FM[2]
        _cross(w_a, u, x)
        for i in range(3):
            acc[i] += 2.0 * x[i]
        _cross(al_b, r_Mb, x)
        _cross(w_b, r_Mb, t1)
        _cross(w_b, t1, t2)
        for i in range(3):
            vdot[cb + i] = acc[i] + x[i] + t2[i]
        # the child's orientation and body-frame rates
        R_WB[b, :, :] = R_b
        quat_near(R_b, quat_WB[b], quat_WB[b])
        for i in range(3):
            w_BB[b, i] = R_b[0, i] * w_b[0] + R_b[1, i] * w_b[1] + R_b[2, i] * w_b[2]
            vdot[cb + 3 + i] = R_b[0, i] * al_b[0] + R_b[1, i] * al_b[1] + R_b[2, i] * al_b[2]
