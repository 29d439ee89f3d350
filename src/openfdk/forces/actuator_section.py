"""Model-file sections ``actuators`` and ``reserves``: coordinate actuators, recruited
beside the muscles and weighted by their optimal force (:mod:`.actuators`).

::

    actuators:
      hip_flexion_r_reserve:
        coordinate: hip_flexion_r      # a joint coordinate or a named scalar measure
        optimal_force: 1.0             # N m (rotation) or N (translation): the weight
        min_control: -100              # bounds of τ / optimal_force (default: none)
        max_control: 100

    reserves:                          # shorthand: one actuator per free coordinate
      optimal_force: 1.0               # the non-root coordinates (N m or N)
      residual_force: 1.0              # the root joint's translations (N): residuals
      residual_moment: 1.0             # the root joint's rotations (N m)
      coordinates: [hip_flexion_r, …]  # optional: only these (default: every coordinate
                                       # that is neither locked nor prescribed)

``reserves`` makes actuators named ``reserve_<coordinate>``, and ``residual_<coordinate>``
on the coordinates of the joint whose parent is the ground (the root body's residual
forces and moments, OpenSim's residual actuators), without control bounds.
"""

from __future__ import annotations

import numpy as np

from ..model.builder import _check_name
from ..model.model import ModelError
from .actuators import CoordinateActuator

KEYS = ["coordinate", "optimal_force", "min_control", "max_control"]
RESERVE_KEYS = ["optimal_force", "residual_force", "residual_moment", "coordinates"]


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
        ctx.keys(spec, p, KEYS, required=("coordinate", "optimal_force"))
        try:
            _check_name(name, "actuator")
        except ModelError as exc:
            raise ctx.error(p, str(exc)) from None
        coordinate = ctx.string(spec["coordinate"], f"{p}.coordinate")
        measure = _scalar_measure(b, coordinate, f"{p}.coordinate", ctx)
        force = ctx.number(spec["optimal_force"], f"{p}.optimal_force", positive=True)
        low = _control(ctx, spec, "min_control", p, -np.inf)
        high = _control(ctx, spec, "max_control", p, np.inf)
        if low > 0.0 or high < 0.0 or low == high:
            raise ctx.error(p, f"controls [{low:g}, {high:g}] must contain 0 and be an interval (an actuator "
                               "that cannot be idle would push the model whatever its motion)")
        out.append(CoordinateActuator(str(name), coordinate, measure, force, low, high))
    _check_unique(out, ctx)
    b.elements["actuators"] = out


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
    free = [c for c in records if not c.locked and not c.prescribed]
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
    out = list(b.elements.get("actuators", ()))
    for c in free:
        if c.joint in roots:
            kind = "translational" if c.unit == "length" else "rotational"
            out.append(CoordinateActuator(f"residual_{c.name}", c.name, c.measure, residual[kind]))
        else:
            out.append(CoordinateActuator(f"reserve_{c.name}", c.name, c.measure, force))
    _check_unique(out, ctx)
    b.elements["actuators"] = out


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
