"""Coordinate tasks: soft rows of marker tracking beside the markers (paper Eq. 4).

Marker tracking minimises ½ Ψᵀ W Ψ over the soft constraints Ψ; markers give three
rows each, Ψ_M = p_WM(q) − x_M(t). A coordinate task adds one row Ψ_k = m_k(q) − f_k(t)
with weight w_k, where m_k is a scalar measure (usually a joint coordinate) and f_k a
function of time — OpenSim's IKCoordinateTask, whose cost term is w_k (q_k − f_k)².
Without the tasks of a setup file, OpenSim's IK and openfdk's tracking solve different
problems and give different answers (docs/opensim-import.md).

Model-file section::

    tasks:
      knee_angle_r: {weight: 10, value: 0}          # measure: the task's name by default
      pelvis_tilt: {measure: pelvis_tilt, weight: 1, value: {type: spline, times: [...], values: [...]}}

``value`` is a number (the file's unit of the measure) or a time function
(docs/model-file.md, drivers: constant, polynomial, fourier, spline).
"""

from __future__ import annotations

from dataclasses import dataclass

from .timefunctions import Constant, TimeFunction


@dataclass(frozen=True, eq=False)
class CoordinateTask:
    """name; measure : scalar Measure; weight : ≥ 0 (relative to the markers' weights,
    in 1/rad² or 1/m² where markers are 1/m²); function : TimeFunction target (SI)."""

    name: str
    measure: object
    weight: float
    function: TimeFunction


def load_tasks(b, spec, ctx, measure_of, function_of, wrap):
    """The ``tasks`` section into ``b.elements["tasks"]``; ``measure_of(spec, path)`` and
    ``function_of(spec, units, path)`` are the model file's measure and time-function
    readers."""
    out = []
    for name, t in ctx.mapping(spec or {}, "tasks").items():
        p = f"tasks.{name}"
        ctx.keys(t, p, ["measure", "weight", "value"], required=("value",))
        m = measure_of(t.get("measure", name), f"{p}.measure")
        if m.size != 1:
            raise ctx.error(f"{p}.measure", f"a task needs a scalar measure; {m.name!r} has {m.size} components")
        weight = ctx.number(t.get("weight", 1.0), f"{p}.weight", nonnegative=True)
        value = t["value"]
        scale = ctx.angle if m.units[0] == "angle" else ctx.length if m.units[0] == "length" else 1.0
        if isinstance(value, dict):
            fn = function_of(value, m.units, f"{p}.value")
        else:
            fn = Constant([ctx.number(value, f"{p}.value") * scale])
        out.append(CoordinateTask(name, m, weight, fn))
    if out and b._fdk:
        raise ctx.error("tasks", "coordinate tasks are not yet combined with FDK DOFs (the FDK Jacobian's kinematic "
                                 "sensitivity is of the markers only); leave the tasks out for FDK runs")
    b.elements["tasks"] = out
