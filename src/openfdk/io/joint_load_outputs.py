"""``joint_loads.csv`` and ``.sto``: the load each joint transmits to its child body
(:mod:`openfdk.dynamics.joint_loads`), in the columns of OpenSim's ``JointReaction``
analysis with its defaults (on the child body, expressed in the ground):
``{joint}_on_{child}_in_ground_fx, _fy, _fz`` (N), ``_mx, _my, _mz`` (N m, about the
joint's child frame origin) and ``_px, _py, _pz`` (m, that origin in the ground).

The model file's ``joint_reaction`` section (:mod:`openfdk.dynamics.joint_reaction_settings`,
OpenSim's ``apply_on_bodies`` and ``express_in_frame``) adds its reports' columns,
``{joint}_on_{body}_in_{frame}_…`` (:mod:`openfdk.dynamics.joint_reports`), to the CSV;
the ``.sto`` then holds those reports only, the columns OpenSim's JointReaction writes
with the same options. The CSV keeps the ground columns, which the viewer, the plots and
the summary read.

``summary.json``'s ``joint_loads`` gives, per joint, the peak of the force's magnitude
in N and in body weights (the model's total mass times g), and the time of the peak.
Frames that failed are NaN in the CSV and left out of the ``.sto``, as in
``generalized_forces.sto``.
"""

from __future__ import annotations

import numpy as np

from .storage import write_run_table

COMPONENTS = ("fx", "fy", "fz", "mx", "my", "mz", "px", "py", "pz")


def joint_load_columns(model, kin, dyn, reports=()):
    """{column: (nf,)} in OpenSim's JointReaction labels (module docstring): every joint's
    load on its child in the ground, then the columns of ``reports`` (JointReports, the
    settings' ``joint_reaction``) not among them; failed frames NaN. {} when the model
    has no joint with a moving child body."""
    from ..dynamics.joint_loads import joint_loads
    from ..dynamics.joint_reaction_settings import default_reports
    from ..dynamics.joint_reports import reported_loads

    loads = joint_loads(model, kin.q, dyn)
    failed = ~(np.asarray(dyn.converged, bool) & np.asarray(kin.converged, bool))
    wanted = [r for r in default_reports(model) if r.joint in loads]
    defaults = {r.base for r in wanted}
    wanted += [r for r in reports if r.joint in loads and r.base not in defaults]
    out = {}
    for base, values in reported_loads(model, kin.q, loads, wanted).items():
        values[failed] = np.nan
        for k, comp in enumerate(COMPONENTS):
            out[f"{base}_{comp}"] = values[:, k]
    return out


def joint_load_bases(columns):
    """(each joint's load on its child in the ground, the other reports): the column
    bases ``{joint}_on_{body}_in_{frame}`` of joint_loads.csv's ``columns``. The CSV
    gives every joint's ground columns first, then the model file's ``joint_reaction``
    reports (:func:`joint_load_columns`)."""
    defaults, reports, seen = [], [], set()
    for c in columns:
        if not c.endswith("_fx"):
            continue
        base = c[:-len("_fx")]
        joint = base.rsplit("_on_", 1)[0]
        if joint not in seen and base.endswith("_in_ground"):
            seen.add(joint)
            defaults.append(base)
        else:
            reports.append(base)
    return defaults, reports


def joint_load_summary(model, time, columns):
    """{joint: {peak_N, peak_BW, time_s}} of the force magnitudes in ``columns``
    (:func:`joint_load_columns`), and the body weight (N) they are divided by."""
    weight = float(sum(b.mass for b in model.moving_bodies) * np.linalg.norm(model.gravity_W))
    out = {}
    for j in model.joints:
        base = f"{j.name}_on_{model.frame(j.child).body}_in_ground" if j.child else ""
        if f"{base}_fx" not in columns:
            continue
        F = np.column_stack([columns[f"{base}_f{c}"] for c in "xyz"])
        norm = np.linalg.norm(F, axis=1)
        if not np.isfinite(norm).any():
            continue
        k = int(np.nanargmax(norm))
        out[j.name] = {"peak_N": float(norm[k]), "peak_BW": float(norm[k] / weight) if weight > 0 else None,
                      "time_s": float(time[k])}
    return {"joints": out, "body_weight_N": weight}


def write_joint_loads(out_dir, model, kin, dyn, reports=()):
    """Write joint_loads.csv and .sto of a run of a model with joint coordinates (an
    OpenSim model, or a model file with a ``coordinates:`` section: a joint carries the
    rows on its own coordinates, :mod:`openfdk.dynamics.joint_loads`), the ``.sto`` with
    the columns of ``reports`` when given (module docstring); returns the summary, or
    None (no coordinates, no joint with a moving child body, no frame)."""
    if not model.coordinates or not len(dyn.time):
        return None
    columns = joint_load_columns(model, kin, dyn, reports)
    if not columns:
        return None
    asked = {f"{r.base}_{c}": columns[f"{r.base}_{c}"] for r in reports if f"{r.base}_fx" in columns
             for c in COMPONENTS} if reports else columns
    write_run_table(out_dir, "joint_loads", dyn.time, columns, "Joint Reaction Loads (openfdk)", sto_columns=asked)
    return joint_load_summary(model, np.asarray(dyn.time, float), columns)  # the peaks of every joint, from its ground columns


__all__ = ["COMPONENTS", "joint_load_bases", "joint_load_columns", "joint_load_summary", "write_joint_loads"]
