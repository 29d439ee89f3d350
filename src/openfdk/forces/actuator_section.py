"""Model-file sections ``actuators`` and ``reserves``: coordinate, point and torque
actuators, recruited beside the muscles and weighted by their optimal force
(:mod:`.actuators`). Points are in the file's length unit; forces N, moments N m.

::

    actuators:
      hip_flexion_r_reserve:
        coordinate: hip_flexion_r      # a joint coordinate or a named scalar measure
        optimal_force: 1.0             # N m (rotation) or N (translation): the weight
        min_control: -100              # bounds of τ / optimal_force (default: none)
        max_control: 100
      FX:                              # a force at a body point (residual force)
        type: point
        body: pelvis
        point: [-0.07, 0, 0]           # in the body frame (point_frame: world: in the world)
        direction: [-1, 0, 0]          # in the world (direction_frame: body: in the body)
        optimal_force: 100             # N
        min_control: -1
        max_control: 1
      MX:                              # a torque between two bodies (residual moment)
        type: torque
        body: pelvis
        reaction_body: ground          # gets the opposite torque (default: the ground)
        axis: [-1, 0, 0]               # in the world (axis_frame: body: in body's frame)
        optimal_force: 80              # N m

    reserves:                          # shorthand: one actuator per free coordinate
      optimal_force: 1.0               # the non-root coordinates (N m or N)
      residual_force: 1.0              # the root joint's translations (N): residuals
      residual_moment: 1.0             # the root joint's rotations (N m)
      residuals: true                  # false: none on the root joint (e.g. the residual
                                       # actuators come from --actuators, FX … MZ)
      coordinates: [hip_flexion_r, …]  # optional: only these (default: every coordinate
                                       # that is neither locked, prescribed, held by a
                                       # constraint (an overlay's lock) nor an FDK DOF)

``reserves`` makes actuators named ``reserve_<coordinate>``, and ``residual_<coordinate>``
on the coordinates of the joint whose parent is the ground (the root body's residual
forces and moments, OpenSim's residual actuators), without control bounds.
"""

from __future__ import annotations

import numpy as np

from ..model.builder import _check_name
from ..model.model import ModelError
from .actuators import CoordinateActuator, PointActuator, TorqueActuator

COMMON = ["type", "optimal_force", "min_control", "max_control"]
KEYS = {"coordinate": COMMON + ["coordinate"],
        "point": COMMON + ["body", "point", "point_frame", "direction", "direction_frame"],
        "torque": COMMON + ["body", "reaction_body", "axis", "axis_frame"]}
REQUIRED = {"coordinate": ("coordinate", "optimal_force"), "point": ("body", "direction", "optimal_force"),
            "torque": ("body", "axis", "optimal_force")}
RESERVE_KEYS = ["optimal_force", "residual_force", "residual_moment", "residuals", "coordinates"]


def _scalar_measure(b, name, path, ctx):
    try:
        m = b.measure(name)
    except Exception:
        raise ctx.error(path, f"unknown coordinate or measure {name!r}") from None
    if m.size != 1:
        raise ctx.error(path, f"{name!r} has {m.size} rows; an actuator acts along one scalar coordinate")
    return m


def _control(ctx, spec, key, path, default):
    value = spec.get(key)
    if value is None:
        return default
    return ctx.number(value, f"{path}.{key}")


def load_actuators(b, data, ctx):
    """The ``actuators`` section into ``b.elements["actuators"]``."""
    out = list(b.elements.get("actuators", ()))
    for name, spec in ctx.mapping(data or {}, "actuators").items():
        p = f"actuators.{name}"
        ctx.mapping(spec, p)
        kind = ctx.choice(spec.get("type", "coordinate"), f"{p}.type", tuple(KEYS), "actuator type")
        ctx.keys(spec, p, KEYS[kind], required=REQUIRED[kind])
        try:
            _check_name(name, "actuator")
        except ModelError as exc:
            raise ctx.error(p, str(exc)) from None
        force = ctx.number(spec["optimal_force"], f"{p}.optimal_force", positive=True)
        low = _control(ctx, spec, "min_control", p, -np.inf)
        high = _control(ctx, spec, "max_control", p, np.inf)
        if low > 0.0 or high < 0.0 or low == high:
            raise ctx.error(p, f"controls [{low:g}, {high:g}] must contain 0 and be an interval (an actuator "
                               "that cannot be idle would push the model whatever its motion)")
        if kind == "coordinate":
            coordinate = ctx.string(spec["coordinate"], f"{p}.coordinate")
            measure = _scalar_measure(b, coordinate, f"{p}.coordinate", ctx)
            out.append(CoordinateActuator(str(name), coordinate, measure, force, low, high))
        elif kind == "point":
            body = _body(b, spec["body"], f"{p}.body", ctx)
            in_world = _frame(ctx, spec, "point_frame", p, "body") == "world"
            point = ctx.position(spec.get("point", [0.0, 0.0, 0.0]), f"{p}.point")
            direction = _unit(ctx, spec["direction"], f"{p}.direction")
            force_world = _frame(ctx, spec, "direction_frame", p, "world") == "world"
            out.append(PointActuator(str(name), body, point, in_world, direction, force_world, force, low, high))
        else:
            body = _body(b, spec["body"], f"{p}.body", ctx)
            other = _body(b, spec.get("reaction_body", "ground"), f"{p}.reaction_body", ctx, allow_ground=True)
            if other == body:
                raise ctx.error(f"{p}.reaction_body", "the torque and its reaction act on the same body")
            axis = _unit(ctx, spec["axis"], f"{p}.axis")
            world = _frame(ctx, spec, "axis_frame", p, "world") == "world"
            out.append(TorqueActuator(str(name), body, other, axis, world, force, low, high))
    _check_unique(out, ctx)
    b.elements["actuators"] = out


def _body(b, name, path, ctx, allow_ground=False):
    if not isinstance(name, str):
        raise ctx.error(path, f"expected a body name, got {name!r}")
    try:
        index = b._body_index(name, path)
    except ValueError as exc:
        raise ctx.error(path, str(exc)) from None
    if index == 0 and not allow_ground:
        raise ctx.error(path, "an actuator on the ground does nothing; name the body it acts on")
    return index


def _frame(ctx, spec, key, path, default):
    return ctx.choice(spec.get(key, default), f"{path}.{key}", ("world", "body"), "frame")


def _unit(ctx, value, path):
    v = ctx.vector(value, path, n=3)
    norm = float(np.linalg.norm(v))
    if not (np.isfinite(norm) and norm > 0.0):
        raise ctx.error(path, f"expected a non-zero direction, got {value!r}")
    return v / norm


def load_reserves(b, data, ctx):
    """The ``reserves`` shorthand (module docstring) into ``b.elements["actuators"]``."""
    if data is None:
        return
    ctx.keys(data, "reserves", RESERVE_KEYS)
    records = b.elements.get("coordinates", ())
    if not records:
        raise ctx.error("reserves", "the model has no joint coordinates (an OpenSim model or joints of type "
                                    "custom); name each actuator under actuators: instead")
    force = ctx.number(data.get("optimal_force", 1.0), "reserves.optimal_force", positive=True)
    residual = {"translational": ctx.number(data.get("residual_force", force), "reserves.residual_force",
                                            positive=True),
                "rotational": ctx.number(data.get("residual_moment", force), "reserves.residual_moment",
                                         positive=True)}
    free = [c for c in records if not c.locked and not c.prescribed and not _held(b, c)]
    names = data.get("coordinates")
    if names is not None:
        if not isinstance(names, list) or not all(isinstance(x, str) for x in names):
            raise ctx.error("reserves.coordinates", f"expected a list of coordinate names, got {names!r}")
        known = {c.name: c for c in free}
        for x in names:
            if x not in known:
                raise ctx.error("reserves.coordinates", f"{x!r} is not a free coordinate; free: {sorted(known)}")
        free = [known[x] for x in names]
    roots = _root_joints(b, records)
    with_residuals = ctx.boolean(data.get("residuals", True), "reserves.residuals")
    out = list(b.elements.get("actuators", ()))
    for c in free:
        if c.joint in roots:
            if not with_residuals:
                continue
            kind = "translational" if c.unit == "length" else "rotational"
            out.append(CoordinateActuator(f"residual_{c.name}", c.name, c.measure, residual[kind]))
        else:
            out.append(CoordinateActuator(f"reserve_{c.name}", c.name, c.measure, force))
    _check_unique(out, ctx)
    b.elements["actuators"] = out


def _held(b, coordinate):
    """Whether a constraint (an overlay's ``lock``, a ``constraints`` entry on the
    coordinate itself) holds the coordinate, or it is an FDK DOF: such a coordinate is
    not free, and a reserve on it would carry what FDK must balance (the FDK residual of
    Eq. 15 is the load nothing else takes in that direction). Drivers do not hold: with
    actuators, a driven coordinate is moved by the muscles and reserves."""
    from ..model.constraints import JOINT

    measure = coordinate.measure
    return (any(c.kind == JOINT and c.measure is measure for c in b._constraints)
            or any(d.measure is measure for d in b._fdk))


def _root_joints(b, records):
    """Names of the joints that connect a body to the ground (the ground is body 0;
    a joint of six coordinates has no constraint rows, so its coordinates tell)."""
    joints = {c.name for c in b._constraints if 0 in c.measure.bodies()}
    return joints | {c.joint for c in records if 0 in c.measure.bodies()}


def _check_unique(actuators, ctx):
    seen = set()
    for a in actuators:
        if a.name in seen:
            raise ctx.error(f"actuators.{a.name}", "defined twice (reserves: makes reserve_<coordinate> and "
                                                   "residual_<coordinate>)")
        seen.add(a.name)
