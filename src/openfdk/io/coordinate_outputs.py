"""``coordinates.csv`` and ``coordinates.mot``: a model's joint coordinates (OpenSim's,
for a model read from an ``.osim``) over a trial, so that openfdk's marker tracking can
be compared with OpenSim's IK ``.mot`` column by column.

* ``coordinates.csv``: ``time`` then one column per coordinate, ``name_rad`` or
  ``name_m`` (SI); a frame whose kinematics did not converge is NaN.
* ``coordinates.mot``: OpenSim's motion file (``inDegrees=yes``): rotational
  coordinates in degrees, translational in metres, coupled ones (OpenSim's motion type:
  a CustomJoint coordinate that moves no axis through a LinearFunction of slope ±1) in
  rad or m as OpenSim writes and reads them, columns named exactly as the
  model's coordinates; frames that did not converge are left out (their poses are not
  solutions) and a header comment says how many.

Angles are unwrapped along time (a coordinate measured as a Cardan angle is returned in
(−π, π]; OpenSim's coordinate continues past ±π), starting from the first converged
frame's value taken nearest the coordinate's default.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .results import write_table
from .storage import write_storage


def coordinate_values(model, kinematics):
    """{name: (nf,) rad or m} of every coordinate at the poses of ``kinematics`` (a
    KinematicsResult: time (nf,), q (nf, 7 n_moving), converged (nf,)); NaN where a
    frame did not converge."""
    from ..model.compiled import CompiledMeasures

    coords = list(model.coordinates)
    nf = len(kinematics.time)
    out = np.full((nf, len(coords)), np.nan)
    if not coords:
        return {}
    program = CompiledMeasures([c.measure for c in coords])
    state = model.initial_state()
    for i in range(nf):
        if kinematics.converged[i]:
            state.set_q(kinematics.q[i])
            out[i] = program.evaluate(state, 0)[0]
    for k, c in enumerate(coords):
        if c.unit == "angle":
            ok = np.isfinite(out[:, k])
            if ok.any():
                col = np.unwrap(out[ok, k])
                # the branch nearest the default value (a coordinate beyond ±π)
                col += 2 * np.pi * np.round((c.default - col[0]) / (2 * np.pi))
                out[ok, k] = col
    return {c.name: out[:, k] for k, c in enumerate(coords)}


def coordinate_columns(model, kinematics, values=None):
    """The columns of ``coordinates.csv``: {"time": (nf,) s, ``name_rad`` or ``name_m``:
    (nf,) SI} of every coordinate (``values``: :func:`coordinate_values` when the
    caller has them)."""
    values = coordinate_values(model, kinematics) if values is None else values
    units = {c.name: c.unit for c in model.coordinates}
    cols = {"time": np.asarray(kinematics.time, float)}
    for name, v in values.items():
        cols[f"{name}_{'rad' if units[name] == 'angle' else 'm'}"] = v
    return cols


def write_coordinates(out_dir, model, kinematics):
    """Write ``coordinates.csv`` and ``coordinates.mot`` into ``out_dir`` when the model
    has joint coordinates; returns the paths written."""
    values = coordinate_values(model, kinematics)
    if not values:
        return []
    out_dir = Path(out_dir)
    degrees = {c.name: c.opensim_rotational for c in model.coordinates}
    cols = coordinate_columns(model, kinematics, values)
    _warn_ranges(model, kinematics, values)
    csv_path = out_dir / "coordinates.csv"
    write_table(csv_path, cols)
    ok = np.asarray(kinematics.converged, bool)
    mot = {name: np.degrees(v[ok]) if degrees[name] else v[ok] for name, v in values.items()}
    comments = [] if ok.all() else [f"openfdk: {int((~ok).sum())} frames whose kinematics failed are left out"]
    mot_path = write_storage(out_dir / "coordinates.mot", np.asarray(kinematics.time, float)[ok], mot,
                             name=f"{model.name} coordinates (openfdk)", in_degrees=True, comments=comments)
    return [csv_path, mot_path]


def coordinates_at_bounds(model, kinematics, values=None, tol=1e-9):
    """Where the clamped coordinates rest on a bound of their range (marker tracking holds
    them there, :mod:`openfdk.kinematics.coordinate_bounds`): {name: {"lower" or "upper":
    {"value_rad" or "value_m": the bound (SI), "frames": converged frames within ``tol``
    of it, "first_time_s": the first of them}}}, only the coordinates and bounds reached.
    ``values``: {name: (nf,)} of :func:`coordinate_values` if the caller has them."""
    values = coordinate_values(model, kinematics) if values is None else values
    ok = np.asarray(kinematics.converged, bool)
    time = np.asarray(kinematics.time, float)
    out = {}
    for c in model.coordinates:
        if not c.clamped or c.name not in values:
            continue
        v = np.asarray(values[c.name], float)
        for side, bound in (("lower", c.range[0]), ("upper", c.range[1])):
            at = ok & np.isfinite(v) & (np.abs(v - bound) <= tol) if np.isfinite(bound) else np.zeros_like(ok)
            if at.any():
                unit = "value_rad" if c.unit == "angle" else "value_m"
                out.setdefault(c.name, {})[side] = {unit: float(bound), "frames": int(at.sum()),
                                                    "first_time_s": float(time[at][0])}
    return out


def _warn_ranges(model, kinematics, values):
    """One warning per clamped coordinate that leaves its range. OpenSim's IK keeps a
    clamped coordinate within its range (a bound of its optimiser), and so does openfdk's
    marker tracking (:mod:`openfdk.kinematics.coordinate_bounds`); FDK's position solves,
    a coordinate file (``--motion``) and drivers do not bound it."""
    import warnings

    for c in model.coordinates:
        v = values[c.name]
        lo, hi = c.range
        out = np.isfinite(v) & ((v < lo - 1e-9) | (v > hi + 1e-9))
        if c.clamped and out.any():
            scale, unit = (180 / np.pi, "deg") if c.unit == "angle" else (1.0, "m")
            worst = v[out][np.argmax(np.maximum(lo - v[out], v[out] - hi))]
            warnings.warn(f"coordinate {c.name!r} (clamped to [{lo * scale:.4g}, {hi * scale:.4g}] {unit}) leaves its "
                          f"range at {int(out.sum())} of {len(v)} frames (up to {worst * scale:.4g} {unit}, first at "
                          f"t = {np.asarray(kinematics.time)[out][0]:.4g} s); OpenSim's IK would bound it, as openfdk's "
                          "marker tracking does; FDK's position solves, --motion files and drivers do not")
