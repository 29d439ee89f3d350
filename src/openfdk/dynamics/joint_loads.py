"""The load each joint transmits to its child body: OpenSim's ``JointReaction`` analysis.

A joint J between a parent body and a child body C carries, on C, the sum of the loads of
every row that acts across it (paper Eq. 12: the rows' load is C^R λ = Φ_q̂ᵀ λ):

* J's own constraint rows (the directions the joint does not allow), λ their reactions;
* the rows on J's coordinates: a driver (``--motion``: the coordinate's generalised
  force), a locked or prescribed coordinate, an FDK DOF (its residual: zero once
  converged);
* the coordinate actuators on J's coordinates (reserves, OpenSim's CoordinateActuators),
  τ ∂m/∂q̂ with m the coordinate's measure and τ the recruited force;
* the part of a muscle's load that comes from a path point moving with one of J's
  coordinates u (OpenSim's MovingPathPoint: Gait2392's vasti over the knee),
  −f (∂l/∂u)_p ∂u/∂q̂, with f the tension and (∂l/∂u)_p the change of the path's length
  with u at fixed bodies. OpenSim applies it as a generalised force on u;
* a coordinate coupler's rows (OpenSim's CoordinateCouplerConstraint) on J's child, when
  one of its coordinates is J's: OpenSim applies the coupler's force as generalised
  forces on its coordinates, each carried by that coordinate's joint;
* the rows of another joint K that move with one of J's coordinates, on J's child: a
  patella placed by the knee angle (a coupler that openfdk's rows of K express through
  the knee angle, as for Rajagopal's patella), the same generalised force.

Forces applied at points of the bodies (muscles, ligaments, contacts, point and torque
actuators, the ground reactions) are not transmitted by the joint: they are loads on
the bodies, as in OpenSim, whose JointReaction reports Simbody's mobilizer reaction
(everything the mobilizer carries, its mobility forces included). Other constraints
(a distance constraint, a weld) belong to no joint.

With the generalised velocity of a body [ṙ_W; ω'_B] (centre of mass, body frame), the
child's six columns of Σ Φ_q̂ᵀ λ are the force F_W (3,) N at the centre of mass in the
world frame and the moment M_B (3,) N m about it in the body frame. The load is
reported as OpenSim does by default: on the child, at the origin P of the joint's child
frame, force and moment about P in the ground frame, M_P = R_WB M_B + (p_WB − p_WP) × F_W.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..model.constraints import DRIVER


@dataclass(frozen=True)
class JointLoadRows:
    """What acts across one joint. name : the joint; child : its child body's name;
    frame : the child frame (qualified ``body.frame``); rows : indices into the
    ConstraintSystem's rows; row_columns : for each row, its column in the forces (the
    row's reaction); actuators : [(column, coordinate measure)] of the coordinate
    actuators on its coordinates."""

    name: str
    child: str
    frame: str
    rows: tuple
    row_columns: tuple
    actuators: tuple


def joint_load_rows(model, system, column_names):
    """[JointLoadRows] of the joints of ``model`` that have a moving child body, in model
    order; ``system`` the model's ConstraintSystem (FDK rows included), ``column_names``
    the InverseDynamicsResult's. A row without a reaction column (a driver that carries
    none) adds nothing."""
    index = {name: k for k, name in enumerate(column_names)}
    joint_of = {c.name: c.joint for c in model.coordinates}  # a coordinate's rows measure it by name
    records = [j for j in model.joints if j.type not in ("coupler",) and j.child]
    couplers = {j.name: [x for x in (j.independent, j.dependent) if x] for j in model.joints if j.type == "coupler"}
    by_name = {j.name: j for j in records}
    rows = {j.name: [] for j in records}
    own = {}  # a joint's own rows: {joint: ([(row, column)], bodies its rows move)}
    coupled = []  # the couplers' rows: ([(row, column)], bodies, the joints of their coordinates)
    actuators = {j.name: [] for j in records}
    r = 0
    for c in model.constraints:
        mine = c.name in by_name and c.kind != DRIVER
        owner = c.name if mine else joint_of.get(getattr(c.measure, "name", ""))
        found = [(r + k, index[row]) for k, row in enumerate(c.row_names) if row in index]
        if owner in rows:
            rows[owner] += found
            if mine:
                own[owner] = (found, c.measure.bodies())
        elif c.name in couplers:  # OpenSim's CoordinateCouplerConstraint: each coordinate's joint carries its part
            coupled.append((found, c.measure.bodies(), [joint_of.get(x) for x in couplers[c.name]]))
        r += c.size
    for d in getattr(system, "fdk", ()):
        owner = joint_of.get(d.name)
        col = index.get(f"fdk.{d.name}")
        if owner in rows and col is not None:
            rows[owner].append((r, col))
        r += 1
    coords = {c.name: c for c in model.coordinates}
    for a in getattr(model, "actuators", ()):
        c = coords.get(getattr(a, "coordinate", None))
        if c is not None and c.joint in actuators and a.name in index:
            actuators[c.joint].append((index[a.name], c.measure))
    # a joint whose rows move with another joint's coordinate (a patella placed by the
    # knee angle through OpenSim's CoordinateCouplerConstraint) loads that joint's child
    # through the coordinate: OpenSim applies that part as a generalised force on the
    # coordinate, carried by the other joint, so its rows' load on that child counts there
    child_of = {j.name: model.frame(j.child).body for j in records}
    parent_of = {j.name: model.frame(j.parent).body if j.parent else "ground" for j in records}
    joint_with_child = {}
    for j in records:
        joint_with_child.setdefault(child_of[j.name], j.name)
    names = [b.name for b in model.bodies]
    for name, (found, bodies) in own.items():
        for b in bodies:
            other = joint_with_child.get(names[b])
            if other is not None and names[b] not in (parent_of[name], child_of[name]):
                rows[other] += [rc for rc in found if rc not in rows[other]]
    for found, bodies, joints in coupled:
        for joint in joints:
            if joint in rows and model.body(child_of[joint]).index in bodies:
                rows[joint] += [rc for rc in found if rc not in rows[joint]]
    out = []
    for j in records:
        child = child_of[j.name]
        if model.body(child).column < 0:
            continue
        out.append(JointLoadRows(j.name, child, j.child, tuple(r for r, _ in rows[j.name]),
                                 tuple(c for _, c in rows[j.name]), tuple(actuators[j.name])))
    return out


class MovingPoints:
    """The muscles whose path has a point that moves with a coordinate (OpenSim's
    MovingPathPoint), all paths in one kernel (:class:`~openfdk.forces.coordinate_path.CoordinatePathNodes`).

    ``muscles``: their indices in ``model.muscles``; :meth:`generalized_forces` gives, at a
    state, each such coordinate's generalised force from the moving points' term of the
    muscles' loads."""

    def __init__(self, model):
        from ..forces.coordinate_path import CoordinatePath, CoordinatePathNodes

        picked = [(i, m) for i, m in enumerate(model.muscles)
                  if isinstance(m.path, CoordinatePath) and any(n.moving is not None for n in m.path.nodes)]
        self.muscles = np.asarray([i for i, _ in picked], int)
        self.kernel = CoordinatePathNodes([m.path.nodes for _, m in picked], [m.name for _, m in picked]) \
            if picked else None
        self.moving = np.unique(self.kernel.move[self.kernel.move >= 0]) if picked else np.zeros(0, int)

    def generalized_forces(self, state, tension):
        """[(coordinate name, τ (n,))] at ``state`` for the muscles' tensions ``tension``
        (n_muscles,) N (the model's muscle order): τ = −Σ f (∂l/∂u)_p ∂u/∂q̂ over the
        muscles, with (∂l/∂u)_p the change of a path's length with the coordinate u its
        points move with, the bodies held (the moving points' term of ∂l/∂q̂)."""
        if self.kernel is None:
            return []
        u, U, _ = self.kernel.program.evaluate(state, 1)
        held = np.zeros_like(U)
        rigid = self.kernel.evaluate_with(state, u, held)[1]
        f = np.asarray(tension, float)[self.muscles]
        out = []
        for j in self.moving:
            g = U[j]
            gg = float(g @ g)
            if gg == 0.0:
                continue
            held[j] = g
            part = self.kernel.evaluate_with(state, u, held)[1] - rigid  # (n_paths, n) = (∂l/∂u)_p ∂u/∂q̂
            held[j] = 0.0
            out.append((getattr(self.kernel.coordinates[j], "name", ""), -float(f @ (part @ g)) / gg * g))
        return out


def joint_loads(model, q, dyn):
    """{joint name: (F_W (nf, 3) N, M_WP (nf, 3) N m, p_WP (nf, 3) m)}: the load each
    joint transmits to its child body at every frame (module docstring), the moment
    about the child frame's origin P, all in the ground frame. ``q`` (nf, 7 n_moving)
    the frames' poses (KinematicsResult.q), ``dyn`` the InverseDynamicsResult (its
    forces, columns and muscle passive forces). A frame whose pose or forces are not
    finite gives NaN."""
    from ..kinematics.system import ConstraintSystem

    system = ConstraintSystem(model)
    loads = joint_load_rows(model, system, dyn.column_names)
    q = np.asarray(q, float)
    forces = np.asarray(dyn.forces, float)
    passive = getattr(dyn, "muscle_passive", None)
    moving = MovingPoints(model) if passive is not None else None
    slot = {j.name: n for n, j in enumerate(loads)}
    joint_of = {c.name: slot[c.joint] for c in model.coordinates if c.joint in slot}
    bodies = [model.body(j.child) for j in loads]
    cols = [slice(b.column, b.column + 6) for b in bodies]
    rows = [np.asarray(j.rows, int) for j in loads]
    row_columns = [np.asarray(j.row_columns, int) for j in loads]
    index = np.asarray([b.index for b in bodies], int)
    p_BP = np.asarray([model.frame(j.frame).p_BF for j in loads], float).reshape(-1, 3)
    nf, nj = len(q), len(loads)
    G = np.full((nf, nj, 6), np.nan)  # the generalised load on each child: [F_W; M_B] at its centre of mass
    R_WB, p_WB = np.full((nf, nj, 3, 3), np.nan), np.full((nf, nj, 3), np.nan)
    state = model.initial_state()
    for k in range(nf):
        if not (np.isfinite(q[k]).all() and np.isfinite(forces[k]).all()):
            continue
        state.set_q(q[k])
        A = system.jacobian(state)
        for n, j in enumerate(loads):
            G[k, n] = A[rows[n], cols[n]].T @ forces[k, row_columns[n]]
            for col, measure in j.actuators:
                G[k, n] += forces[k, col] * np.asarray(measure.evaluate(state, 1)[1])[0, cols[n]]
        if moving is not None and len(moving.muscles):  # the moving points' generalised forces
            nm = len(model.muscles)
            for coordinate, tau in moving.generalized_forces(state, forces[k, :nm] + passive[k]):
                n = joint_of.get(coordinate)  # the muscles' columns come first
                if n is not None:
                    G[k, n] += tau[cols[n]]
        R_WB[k], p_WB[k] = state.R_WB[index], state.p_WB[index]
    F_W = G[..., :3]
    p_WP = p_WB + np.einsum("knij,nj->kni", R_WB, p_BP)
    M_WP = np.einsum("knij,knj->kni", R_WB, G[..., 3:]) + np.cross(p_WB - p_WP, F_W)
    return {j.name: (F_W[:, n], M_WP[:, n], p_WP[:, n]) for n, j in enumerate(loads)}


__all__ = ["JointLoadRows", "MovingPoints", "joint_load_rows", "joint_loads"]
