"""The load each joint transmits to its child body: OpenSim's ``JointReaction`` analysis.

A joint J between parent P and child C carries, on C, the sum of the loads of every row
that acts across it (paper Eq. 12: the rows' load is C^R λ = Φ_q̂ᵀ λ):

* J's own constraint rows (the directions the joint does not allow), λ their reactions;
* the rows on J's coordinates: a driver (``--motion``: the coordinate's generalised
  force), a locked or prescribed coordinate, an FDK DOF (its residual: zero once
  converged);
* the coordinate actuators on J's coordinates (reserves, OpenSim's CoordinateActuators),
  τ ∂m/∂q̂ with m the coordinate's measure and τ the recruited force.

* the part of a muscle's load that comes from a path point moving with one of J's
  coordinates u (OpenSim's MovingPathPoint: Gait2392's vasti over the knee),
  −f (∂l/∂u)_p ∂u/∂q̂, with f the tension and (∂l/∂u)_p the change of the path's length
  with u at fixed bodies. OpenSim applies it as a generalised force on u.

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


def moving_point_muscles(model):
    """[(muscle index, CoordinatePath)] of the muscles whose path has a point that moves
    with a coordinate (OpenSim's MovingPathPoint)."""
    from ..forces.coordinate_path import CoordinatePath

    return [(i, m.path) for i, m in enumerate(model.muscles)
            if isinstance(m.path, CoordinatePath) and any(n.moving is not None for n in m.path.nodes)]


def moving_point_terms(path, state):
    """[(coordinate name, (∂l/∂u)_p, ∂u/∂q̂ (n,))] of a CoordinatePath at ``state``: the
    change of its length (m per m or rad) with each coordinate u its points move with,
    the bodies held (the moving points' term of ∂l/∂q̂, split by coordinate)."""
    kernel = path.kernel
    _, U, _ = kernel.program.evaluate(state, 1)
    rigid = kernel.evaluate(state, coordinate_rows=())[1][0]
    out = []
    for j, measure in enumerate(kernel.coordinates):
        g = U[j]
        gg = float(g @ g)
        if gg == 0.0:
            continue
        part = kernel.evaluate(state, coordinate_rows=(j,))[1][0] - rigid  # = (∂l/∂u)_p ∂u/∂q̂
        out.append((getattr(measure, "name", ""), float(part @ g) / gg, g))
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
    moving = moving_point_muscles(model) if passive is not None else []
    joint_of = {c.name: c.joint for c in model.coordinates}
    by_name = {j.name: j for j in loads}
    nf = len(q)
    out = {j.name: tuple(np.full((nf, 3), np.nan) for _ in range(3)) for j in loads}
    state = model.initial_state()
    for k in range(nf):
        if not (np.isfinite(q[k]).all() and np.isfinite(forces[k]).all()):
            continue
        state.set_q(q[k])
        A = system.jacobian(state)
        extra = {}  # joint -> (n,) generalised load of the moving points' terms on its coordinates
        for i, path in moving:
            tension = forces[k, i] + passive[k, i]  # the muscle's columns come first
            for coordinate, dl_du, g in moving_point_terms(path, state):
                joint = joint_of.get(coordinate)
                if joint in by_name:
                    extra[joint] = extra.get(joint, 0.0) - tension * dl_du * g
        for j in loads:
            b = model.body(j.child)
            cols = slice(b.column, b.column + 6)
            g = A[list(j.rows), cols].T @ forces[k, list(j.row_columns)] if j.rows else np.zeros(6)
            for col, measure in j.actuators:
                g = g + forces[k, col] * np.asarray(measure.evaluate(state, 1)[1])[0, cols]
            if j.name in extra:
                g = g + extra[j.name][cols]
            i = b.index
            R_WB, p_WB = state.R_WB[i], state.p_WB[i]
            p_WP = p_WB + R_WB @ model.frame(j.frame).p_BF
            F_W = g[:3]
            M_WP = R_WB @ g[3:] + np.cross(p_WB - p_WP, F_W)
            out[j.name][0][k], out[j.name][1][k], out[j.name][2][k] = F_W, M_WP, p_WP
    return out


__all__ = ["JointLoadRows", "joint_load_rows", "joint_loads", "moving_point_muscles", "moving_point_terms"]
