"""``moment_arms.csv`` and ``.sto`` (``openfdk run --moment-arms``): each muscle's moment
arm about each independent coordinate it spans (:mod:`openfdk.dynamics.moment_arms`),
what OpenSim's MuscleAnalysis writes in its ``MomentArm_<coordinate>`` files.

Columns ``{muscle}.{coordinate}``: r = −dl/dq in m per rad (rotational coordinate) or
m per m (translational), one per pair whose moment arm exceeds :data:`SPANS` at some
frame (the muscle spans the coordinate). Failed frames are NaN in the CSV and left out of
the ``.sto``.
"""

from __future__ import annotations

import numpy as np

from .storage import write_run_table

#: a muscle spans a coordinate when |r| exceeds this somewhere (m, or m/m): a whole-body
#: motion of the root's coordinates changes no path by more than rounding
SPANS = 1e-9


def moment_arm_columns(model, kin):
    """{``muscle.coordinate``: (nf,)} of the spanning pairs (module docstring), failed
    frames NaN; {} without muscles or coordinates."""
    from ..dynamics.moment_arms import moment_arms

    r, coords, singular = moment_arms(model, kin.q)
    if singular:
        import warnings

        from ..model.plausibility import PlausibilityWarning

        times = np.asarray(kin.time, float)[singular]
        warnings.warn(f"moment arms: at {len(singular)} of {len(kin.time)} frames (the first at t = {times[0]:.4f} s) "
                      "the joints and the coordinates do not fix the bodies' velocities (a mobility no coordinate "
                      "measures): their moment arms are NaN", PlausibilityWarning, stacklevel=2)
    r[~np.asarray(kin.converged, bool)] = np.nan
    out = {}
    for i, m in enumerate(model.muscles):
        for j, c in enumerate(coords):
            column = r[:, i, j]
            if np.nanmax(np.abs(column), initial=0.0) > SPANS:
                out[f"{m.name}.{c.name}"] = column
    return out


def write_moment_arms(out_dir, model, kin):
    """Write moment_arms.csv and .sto of a run; returns {muscles, coordinates, pairs}
    for summary.json, or None (no muscle, no coordinate, no frame)."""
    if not model.muscles or not model.coordinates or not len(kin.time):
        return None
    columns = moment_arm_columns(model, kin)
    if not columns:
        return None
    write_run_table(out_dir, "moment_arms", kin.time, columns, "Muscle moment arms (openfdk)")
    return {"muscles": len(model.muscles), "coordinates": len({k.split(".", 1)[1] for k in columns}),
            "pairs": len(columns)}


__all__ = ["SPANS", "moment_arm_columns", "write_moment_arms"]
