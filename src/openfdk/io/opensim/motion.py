"""A model moved by a coordinate file (``--motion ik.mot``): every coordinate of an
OpenSim ``.mot``/``.sto`` becomes a driver with its reaction, so that inverse dynamics
gives the generalised force along each coordinate — what OpenSim's InverseDynamicsTool
computes from its ``coordinates_file``.

* Each driver is named ``{coordinate}_motion``; its function is the spline OpenSim's
  InverseDynamicsTool differentiates: the natural quintic spline through the file's
  samples (rotational columns converted from degrees where OpenSim converts them), after,
  with ``--motion-cutoff HZ`` (OpenSim's ``lowpass_cutoff_frequency_for_coordinates``;
  default none, as OpenSim's −1), OpenSim's padding and third-order IIR filter
  (:mod:`openfdk.io.opensim.coordinate_filter`). Its velocities and accelerations, and so
  the generalised forces, are OpenSim's.
* Its reaction is the generalised force that moves the coordinate (N m for rotational,
  N for translational): ``generalized_forces.csv`` names it ``{coordinate}_moment`` or
  ``{coordinate}_force`` as OpenSim does. The root joint's ones (``pelvis_tx_force``, …)
  are the residuals.
* Sample times within 5 % of a sample interval of a uniform grid are put on it (files
  that print times rounded, such as OpenSim's IK output of a 60 Hz TRC timed to 1 ms).
* The run's frames are the file's samples (``analysis`` start, end and ``rate_hz``), unless
  the model or overlay gives its own window; ``--start``/``--end`` keep the file's grid.
* Every free coordinate must be in the file (locked and prescribed ones follow their
  own rows, couplers' dependent coordinates follow the coupler and are not driven);
  a column naming no coordinate is ignored, as OpenSim ignores it. So are the FDK DOFs
  and the coordinates an overlay locks (:func:`given_otherwise`): a motion file with
  FDK DOFs is the two-stage pipeline, its columns for them may be absent.
* A column is named by the coordinate (``knee_angle_r``, an IK ``.mot``) or by its state
  variable's path (``/jointset/knee_r/knee_angle_r/value``, the states and coordinates
  files OpenSim 4 and Moco write; their ``/speed`` columns are not used: the rates come
  from the spline, as in OpenSim's InverseDynamicsTool). A coordinate given by two
  columns is refused by name.
"""

from __future__ import annotations

import re

from pathlib import Path

import numpy as np

from .document import in_degrees as opensim_in_degrees
from .errors import OsimError

SUFFIX = "_motion"


def motion_drivers(path, data, cutoff_hz=None, info=None):
    """The model mapping ``data`` with a driver per coordinate from the motion file
    ``path`` (module docstring); ``info['motion_not_driven']`` records the coordinates
    ``data`` gives otherwise (:func:`given_otherwise`)."""
    from ..storage import read_storage
    from .coordinate_filter import lowpass_iir3, pad_odd

    source = Path(path).name
    try:
        times, columns, in_degrees = read_storage(path)
    except ValueError as exc:
        raise OsimError(f"--motion: {exc}") from None
    columns = by_coordinate(columns, source)
    if len(times) > 2:  # times printed rounded (OpenSim's IK keeps the TRC's 1 ms times at 60 Hz): the grid
        grid = times[0] + np.arange(len(times)) * (times[-1] - times[0]) / (len(times) - 1)
        if np.max(np.abs(times - grid)) < 0.05 * (grid[1] - grid[0]):
            times = grid
    coords = data.get("coordinates") or {}
    dependent = {c["dependent"] for c in (data.get("couplers") or {}).values()}
    given = given_otherwise(data)
    if given and info is not None:
        info["motion_not_driven"] = {**info.get("motion_not_driven", {}), **given}
    drivers = dict(data.get("drivers") or {})
    rate = (len(times) - 1) / (times[-1] - times[0]) if len(times) > 1 else 0.0
    driven, missing = [], []
    for name, c in coords.items():
        if c.get("locked") or c.get("prescribed") is not None or name in dependent or name in given:
            continue
        if name not in columns:
            missing.append(name)
            continue
        values = np.asarray(columns[name], float)
        if not np.all(np.isfinite(values)):
            raise OsimError(f"{source}: column {name!r} has non-finite values")
        driven.append((name, np.radians(values) if in_degrees and opensim_in_degrees(c) else values))
    if missing:
        twice = [name for name in missing if name in columns.twice]
        if twice:
            raise OsimError(f"{source}: {columns.absent(twice[0])}; a motion file drives every free coordinate")
        raise OsimError(f"{source}: no column for the coordinates {missing}; a motion file drives every free coordinate "
                        "but the FDK DOFs and the locked ones (OpenSim's InverseDynamicsTool would hold them at their "
                        "default values: give them columns)")
    if len(times) < 6:
        raise OsimError(f"{source}: {len(times)} sample(s); a motion file needs at least 6 (OpenSim's quintic spline)")
    if cutoff_hz:
        if not 0 < cutoff_hz < rate / 2:
            raise OsimError(f"--motion-cutoff: {cutoff_hz:g} Hz must be positive and below the Nyquist frequency "
                            f"{rate / 2:g} Hz of {source}")
        if np.max(np.abs(np.diff(times) * rate - 1.0)) > 1e-6:
            raise OsimError(f"{source}: filtering needs uniformly spaced samples")
    knots = times
    if driven:
        block = np.column_stack([v for _, v in driven])
        if cutoff_hz:
            knots, block = pad_odd(times, block, len(times) // 2)
            block = lowpass_iir3(block, cutoff_hz, 1.0 / rate)
        for j, (name, _) in enumerate(driven):
            drivers[f"{name}{SUFFIX}"] = {"measure": name, "reaction": True,
                                          "function": {"type": "gcv_spline", "degree": 5, "times": knots.tolist(),
                                                       "values": block[:, j].tolist()}}
    out = dict(data)
    out["drivers"] = drivers
    analysis = dict(data.get("analysis") or {})
    if not any(k in analysis for k in ("start", "end", "frames", "rate_hz")):  # the file's samples
        analysis.update(start=float(times[0]), end=float(times[-1]), rate_hz=float(rate))
    out["analysis"] = analysis
    return out


#: a coordinate's value in an OpenSim 4 states file: /jointset/<joint>/<coordinate>/value
_STATE_VALUE = re.compile(r"/jointset/[^/]+/([^/]+)/value")


def by_coordinate(columns, source):
    """{coordinate name: (n,) values} of a storage file's ``columns``, their labels the
    coordinate's name or its value's state path (module docstring)."""
    out, label_of = {}, {}
    for label, values in columns.items():
        m = _STATE_VALUE.fullmatch(label)
        name = m.group(1) if m else label
        if name in out:
            raise OsimError(f"{source}: coordinate {name!r} is given twice, by columns {label_of[name]!r} and "
                            f"{label!r}")
        out[name], label_of[name] = values, label
    from ..storage import StorageColumns

    out = StorageColumns(out)
    out.twice = getattr(columns, "twice", frozenset())
    return out


def is_motion_driver(name, entry):
    """Whether the drivers entry ``name`` is a coordinate's driver made by
    :func:`motion_drivers` (``{coordinate}_motion`` on that coordinate)."""
    return (isinstance(entry, dict) and isinstance(entry.get("measure"), str)
            and name == f"{entry['measure']}{SUFFIX}")


def given_otherwise(data):
    """{coordinate: the entry that gives it} of the coordinates a motion file does not
    drive although they are free in the ``.osim``: an FDK DOF is solved by FDK (paper
    Eqs. 15–17), and a coordinate held by a constraint on it alone (an overlay's
    ``lock: [...]``) keeps that value. Their columns may be absent and are not used. This
    is the two-stage pipeline of the commercial FDK tool's MoCap models and of COMAK:
    the primary coordinates from a first tracking or IK pass, the secondary ones from
    FDK."""
    given = {}
    for name, entry in (data.get("fdk_dofs") or {}).items():
        if isinstance(entry, dict) and isinstance(entry.get("measure"), str):
            given[entry["measure"]] = f"fdk_dofs.{name}"
    coordinates = data.get("coordinates") or {}
    for name, entry in (data.get("constraints") or {}).items():
        if isinstance(entry, dict) and isinstance(entry.get("measure"), str) and entry["measure"] in coordinates:
            given.setdefault(entry["measure"], f"constraints.{name}")
    return given


def without_determined(model, data, path):
    """(``data`` (the mapping ``model`` was built from, of the model file ``path``) without
    the motion drivers of the coordinates ``model``'s own rows already determine
    (:func:`determined_motion_drivers`), those coordinates), with a warning naming them;
    None when there are none."""
    import warnings

    from ...analysis.model_check import reference_jacobian
    from ...model.plausibility import PlausibilityWarning

    try:
        A, row_names = reference_jacobian(model)
    except (FloatingPointError, ValueError):  # left to the run, whose frames report why
        return None
    determined = determined_motion_drivers(model, A, row_names)
    if not determined:
        return None
    names = [name[:-len(SUFFIX)] for name in determined]
    one = len(names) == 1
    warnings.warn(PlausibilityWarning(
        f"{Path(path).name}: the motion file's {', '.join(names)} {'is' if one else 'are'} not driven: the model's "
        f"constraints, with its other coordinates, already determine {'it' if one else 'them'} (the file's "
        f"{'column is' if one else 'columns are'} not used)"), stacklevel=4)
    drivers = data.get("drivers") or {}
    return {**data, "drivers": {name: entry for name, entry in drivers.items() if name not in determined}}, names


def determined_motion_drivers(model, A, row_names):
    """The motion drivers (:func:`is_motion_driver`) of ``model`` whose rows the other rows
    already determine: with Φ_q̂ ``A`` (m, n) at the reference pose and its ``row_names``,
    the model's own rows (joints, constraints, FDK DOFs) first, then the motion's in the
    model's coordinate order, each kept when it adds to the rank. A constraint of an
    overlay that fixes a coordinate's combination with others (an inextensible patellar
    tendon across the patella's coordinates) leaves one coordinate of the combination to
    the constraint. [] when the model's own rows are dependent already (that is the
    model's error, reported as such) or the motion adds no dependency."""
    drivers = {row for c in model.constraints if c.kind == "driver" and c.size == 1
               and c.name == f"{getattr(c.measure, 'name', None)}{SUFFIX}" for row in c.row_names}
    if not drivers:
        return []
    own = [i for i, name in enumerate(row_names) if name not in drivers]
    basis = _row_basis(A[own])
    if basis is None:
        return []
    determined = []
    for i, name in enumerate(row_names):
        if name not in drivers:
            continue
        row = A[i] - basis.T @ (basis @ A[i])
        size = float(np.linalg.norm(row))
        if size <= 1e-9 * max(float(np.linalg.norm(A[i])), 1.0):
            determined.append(name)
        else:
            basis = np.vstack([basis, row / size])
    return determined


def _row_basis(A, tol=1e-9):
    """(r, n) orthonormal basis of the row space of ``A`` (m, n), or None when its rows are
    dependent (r < m)."""
    if A.shape[0] == 0:
        return np.zeros((0, A.shape[1]))
    _, s, Vt = np.linalg.svd(A, full_matrices=False)
    scale = s[0] if s.size and s[0] > 0 else 1.0
    rank = int(np.sum(s > tol * scale))
    return Vt[:rank] if rank == A.shape[0] else None
