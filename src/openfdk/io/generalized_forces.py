"""``generalized_forces.csv`` and ``.sto``: the generalised force along each OpenSim
coordinate of a run driven by a coordinate file (``--motion``), with OpenSim's column
names, so that they compare column by column with OpenSim's inverse dynamics output
(``InverseDynamics.sto``): ``{coordinate}_moment`` (N m) for rotational coordinates,
``{coordinate}_force`` for translational (N) and coupled ones (OpenSim's motion type,
:func:`column_name`).

Each value is the reaction of the coordinate's driver (:mod:`openfdk.io.opensim.motion`):
the generalised force an actuator on that coordinate must apply, conjugate to the
coordinate (the virtual work τ δq), as OpenSim's InverseDynamicsSolver reports it.

The root joint's coordinates (the joint whose parent is the ground) carry the residuals:
the forces and moments the ground reaction and the model's loads do not balance. When
actuators act on a root coordinate (``reserves:`` makes ``residual_<coordinate>``, or
OpenSim's residual CoordinateActuators), that coordinate's driver carries no reaction
and the residual is the sum of its actuators' recruited forces, weighted by their
optimal force as in OpenSim's static optimisation.
``summary.json`` reports their RMS and peak (``residuals``), and a warning is given when
a residual force exceeds 5 % of the body weight (total mass · g), the usual threshold
for a dynamically consistent gait trial.
"""

from __future__ import annotations

import warnings
import numpy as np

from .storage import write_run_table

SUFFIX = "_motion"
RESIDUAL_FORCE_FRACTION = 0.05


def column_name(coordinate):
    """OpenSim's name of a coordinate's generalised force: ``_moment`` for the
    coordinates it calls rotational, ``_force`` for the others — translational ones, and
    coupled ones (a CustomJoint coordinate moved through a spline), whatever their unit."""
    return f"{coordinate.name}_{'moment' if coordinate.opensim_rotational else 'force'}"


def generalized_forces(model, dyn):
    """{OpenSim column name: (nf,) N m or N} of the driven coordinates of ``dyn`` (an
    InverseDynamicsResult), in the model's coordinate order; {} without driven ones."""
    index = {name: k for k, name in enumerate(dyn.column_names)}
    out = {}
    for c in model.coordinates:
        k = index.get(f"{c.name}{SUFFIX}")
        if k is None:
            k = index.get(f"{c.name}{SUFFIX}.reaction")
        if k is None:
            continue
        out[column_name(c)] = np.asarray(dyn.forces[:, k], float)
    return out


def actuator_forces(model, dyn):
    """{column name: (nf,) N m or N} of the actuators' recruited forces
    (``dyn``: an InverseDynamicsResult): per coordinate that coordinate actuators act on,
    their sum (OpenSim's column name); a point or torque actuator on the root body by its
    own name (``FX_force``, ``MX_moment``: OpenSim's residual actuators)."""
    from ..forces.actuators import CoordinateActuator, PointActuator

    index = {name: k for k, name in enumerate(dyn.column_names)}
    coords = {c.name: c for c in model.coordinates}
    roots = {b for c in model.coordinates if _is_root(model, c) for b in c.measure.bodies()} - {0}
    out = {}
    for a in model.actuators:
        if a.name not in index:
            continue
        if isinstance(a, CoordinateActuator):
            if a.coordinate not in coords:
                continue
            key = column_name(coords[a.coordinate])
        elif a.body in roots:
            key = f"{a.name}_{'force' if isinstance(a, PointActuator) else 'moment'}"
        else:
            continue
        out[key] = out.get(key, 0.0) + np.asarray(dyn.forces[:, index[a.name]], float)
    return out


def residual_summary(model, columns):
    """RMS and peak of the root joint's generalised forces {column: {rms, peak}}, the
    body weight (N) and the threshold of the residual forces (N)."""
    roots = {c.joint for c in model.coordinates if _is_root(model, c)}
    weight = float(sum(b.mass for b in model.moving_bodies) * np.linalg.norm(model.gravity_W))
    keys = [column_name(c) for c in model.coordinates if c.joint in roots]
    keys += [f"{a.name}_{kind}" for a in model.actuators for kind in ("force", "moment")]
    out = {}
    for key in keys:
        if key in columns:
            v = columns[key][np.isfinite(columns[key])]
            if v.size:
                out[key] = {"rms": float(np.sqrt(np.mean(v * v))), "peak": float(np.max(np.abs(v)))}
    return {"columns": out, "body_weight_N": weight, "force_threshold_N": RESIDUAL_FORCE_FRACTION * weight}


def _is_root(model, coordinate):
    """Whether the coordinate's joint connects a body to the ground."""
    con = next((c for c in model.constraints if c.name == coordinate.joint), None)
    bodies = coordinate.measure.bodies()
    return 0 in bodies or (con is not None and 0 in con.measure.bodies())


def write_generalized_forces(out_dir, model, dyn):
    """Write generalized_forces.csv and .sto when the run drove coordinates; returns the
    residual summary (or None), and warns when a residual force is above threshold."""
    columns = generalized_forces(model, dyn)
    actuated = actuator_forces(model, dyn)
    if not columns and not actuated:
        return None
    if columns:
        write_run_table(out_dir, "generalized_forces", dyn.time, columns, "Inverse Dynamics (openfdk)",
                        ok=dyn.converged)
    summary = residual_summary(model, {**actuated, **columns})
    threshold = summary["force_threshold_N"]
    for key, stats in summary["columns"].items():
        if key.endswith("_force") and stats["peak"] > threshold:
            warnings.warn(f"residual {key} peaks at {stats['peak']:.4g} N (RMS {stats['rms']:.4g} N), above 5 % of the "
                          f"body weight ({threshold:.4g} N): the ground reactions and the motion are not dynamically "
                          "consistent (check the force-plate assignment, the model's mass and the filtering)")
    return summary
