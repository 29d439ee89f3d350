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
  Times beyond 1e10 s (317 years), and times whose spacing cannot be resolved, are
  refused naming the file and the times: samples less than 1 µs apart (above the 1 MHz
  limit of ``analysis.rate_hz``), or less than 1e-9 of the times' magnitude apart (the
  outputs print times to 10 significant digits; a clock's offset such as Unix time,
  1.7e9 s, with samples 0.01 s apart: subtract the start time) (:func:`check_times`).
* The run's frames are the file's samples (``analysis`` start, end and ``rate_hz``), unless
  the model or overlay gives its own window; ``--start``/``--end`` keep the file's grid.
* Every free coordinate must be in the file (locked and prescribed ones follow their
  own rows, couplers' dependent coordinates follow the coupler and are not driven);
  a column naming no coordinate is ignored, as OpenSim ignores it (with a warning,
  below). So are the FDK DOFs and the coordinates an overlay locks
  (:func:`given_otherwise`): a motion file with FDK DOFs is the two-stage pipeline, its
  columns for them may be absent.
* A column is named by the coordinate (``knee_angle_r``, an IK ``.mot``) or by its state
  variable's path (``/jointset/knee_r/knee_angle_r/value``, the states and coordinates
  files OpenSim 4 and Moco write; their ``/speed`` columns are not used: the rates come
  from the spline, as in OpenSim's InverseDynamicsTool). A coordinate given by two
  columns is refused by name.
* What is read is checked against the model, each problem one line naming the file
  (:func:`check_columns`, :func:`check_values`): columns naming no coordinate of the
  model are a warning listing the first few and their count (a coordinate's ``/speed``
  column is not named: it is documented as unused, and so are the columns of locked,
  prescribed and FDK coordinates, which an IK file holds for every coordinate); a state
  path whose joint is not the coordinate's joint in the model is a warning naming the
  column and both joints (the file was written for another model?); a coupled
  coordinate's column that differs from what its coupler gives by more than 1e-4 (rad or
  m) is a warning (the coupler sets it, the column is not used). A driven value beyond
  1e5 rad (16 000 turns: a crank turning three times a second for 1.5 hours) or 1e4 m
  (ten kilometres, far beyond any capture volume or treadmill record) is refused naming
  the column and the time: no motion reaches it, and the spline and the Newton iteration
  break down on such numbers. A rotational coordinate whose samples leave its range (OpenSim's
  default [-10, 10] rad when the ``.osim`` gives none) by more than 1 rad is a warning
  (once per file) asking whether ``inDegrees`` is right: OpenSim drives an unclamped
  coordinate outside its range too, so it is not refused.
"""

from __future__ import annotations

import re

from pathlib import Path

import numpy as np

from .document import in_degrees as opensim_in_degrees
from .errors import OsimError

SUFFIX = "_motion"

#: the largest |value| of a driven coordinate (rad for rotational ones, else m): 1e5 rad
#: is 16 000 turns (a wheel or crank turning three times a second for 1.5 hours, where a
#: joint turns less than one); 1e4 m is ten kilometres, beyond any capture volume or
#: treadmill record. Beyond them a number is corrupt, and the quintic spline and the
#: kinematics' Newton iteration break down on it ("SVD did not converge" at 1e150 deg).
MAX_ROTATION, MAX_TRANSLATION = 1e5, 1e4
#: a rotational coordinate's samples this far (rad) outside its range are warned about:
#: degrees read as radians leave a joint's range by much more (30 deg read as 30 rad)
RANGE_MARGIN = 1.0
#: OpenSim's Coordinate range when the .osim gives none (Coordinate.cpp, rad or m)
OPENSIM_DEFAULT_RANGE = (-10.0, 10.0)
#: a coupled coordinate's column farther than this (rad or m) from its coupler's value is
#: warned about: well above the round-off of printed values (OpenSim prints 8 digits)
COUPLER_TOLERANCE = 1e-4
#: how many ignored columns a warning names before it counts the rest
LISTED = 5


def motion_drivers(path, data, cutoff_hz=None, info=None):
    """The model mapping ``data`` with a driver per coordinate from the motion file
    ``path`` (module docstring); ``info['motion_not_driven']`` records the coordinates
    ``data`` gives otherwise (:func:`given_otherwise`)."""
    import warnings

    from ..storage import count_mismatch, read_storage
    from .coordinate_filter import lowpass_iir3, pad_odd

    source = Path(path).name
    try:
        times, columns, in_degrees = read_storage(path)
    except ValueError as exc:
        raise OsimError(f"--motion: {exc}") from None
    check_times(times, source)
    # the warnings are given once nothing is refused: a refused file gets one line
    notes = [count_mismatch(source, columns.header, len(times), columns.n_labels)]
    columns = by_coordinate(columns, source)
    notes += check_columns(columns, data, source)
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
            raise OsimError(f"{source}: column {columns.label(name)!r} has non-finite values")
        driven.append((name, np.radians(values) if in_degrees and opensim_in_degrees(c) else values))
    notes += check_values(dict(driven), times, columns, in_degrees, data, source)
    if missing:
        twice = [name for name in missing if name in columns.twice]
        if twice:
            raise OsimError(f"{source}: {columns.absent(twice[0])}; a motion file drives every free coordinate")
        unknown = unknown_columns(columns, coords)
        also = f" (its columns that name no coordinate: {_listed(unknown)})" if unknown else ""
        raise OsimError(f"{source}: no column for the coordinates {missing}; a motion file drives every free coordinate "
                        "but the FDK DOFs and the locked ones (OpenSim's InverseDynamicsTool would hold them at their "
                        f"default values: give them columns){also}")
    if len(times) < 6:
        raise OsimError(f"{source}: {len(times)} sample(s); a motion file needs at least 6 (OpenSim's quintic spline)")
    if cutoff_hz:
        if not 0 < cutoff_hz < rate / 2:
            raise OsimError(f"--motion-cutoff: {cutoff_hz:g} Hz must be positive and below the Nyquist frequency "
                            f"{rate / 2:g} Hz of {source}")
        if np.max(np.abs(np.diff(times) * rate - 1.0)) > 1e-6:
            raise OsimError(f"{source}: filtering needs uniformly spaced samples")
    for note in filter(None, notes):
        warnings.warn(note, stacklevel=2)
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
_STATE_VALUE = re.compile(r"/jointset/([^/]+)/([^/]+)/value")
#: its speed: /jointset/<joint>/<coordinate>/speed (not used, module docstring)
_STATE_SPEED = re.compile(r"/jointset/([^/]+)/([^/]+)/speed")


def by_coordinate(columns, source):
    """{coordinate name: (n,) values} of a storage file's ``columns``, their labels the
    coordinate's name or its value's state path (module docstring); ``labels`` gives
    each name's label in the file."""
    out, label_of = {}, {}
    for label, values in columns.items():
        m = _STATE_VALUE.fullmatch(label)
        name = m.group(2) if m else label
        if name in out:
            raise OsimError(f"{source}: coordinate {name!r} is given twice, by columns {label_of[name]!r} and "
                            f"{label!r}")
        out[name], label_of[name] = values, label
    from ..storage import StorageColumns

    out = StorageColumns(out)
    out.twice = getattr(columns, "twice", frozenset())
    out.header = getattr(columns, "header", {})
    out.n_labels = getattr(columns, "n_labels", 0)
    out.labels = label_of
    return out


def _listed(labels):
    """``'a', 'b', 'c'`` of the first :data:`LISTED` labels, ``and N more`` for the rest."""
    shown = ", ".join(repr(label) for label in labels[:LISTED])
    return shown + (f" and {len(labels) - LISTED} more" if len(labels) > LISTED else "")


def check_times(times, source):
    """Refuse the motion file ``source``'s times (n,) s (finite, increasing) that a run
    cannot resolve (:func:`openfdk.io.storage.sample_times_problem`)."""
    from ..storage import sample_times_problem

    problem = sample_times_problem(times, source)
    if problem:
        raise OsimError(problem)


def unknown_columns(columns, coords):
    """The labels of the motion file's ``columns`` (:func:`by_coordinate`) that name no
    coordinate of ``coords`` (the model's ``coordinates``), a known coordinate's
    ``/speed`` column left out (documented as not used)."""
    unknown = []
    for name in columns:
        if name in coords:
            continue
        speed = _STATE_SPEED.fullmatch(columns.label(name))
        if speed is None or speed.group(2) not in coords:
            unknown.append(columns.label(name))
    return unknown


def check_columns(columns, data, source):
    """The warnings (one line each) about the motion file ``source``'s columns
    (:func:`by_coordinate`) that name no coordinate of the model mapping ``data``, and
    about state paths whose joint is not the coordinate's joint there (module
    docstring)."""
    notes = []
    unknown = unknown_columns(columns, data.get("coordinates") or {})
    if unknown:
        notes.append(f"{source}: {len(unknown)} column(s) name no coordinate of the model and are not used: "
                     f"{_listed(unknown)}")
    joints_of = {}
    for joint, spec in (data.get("joints") or {}).items():
        for axis in ((spec.get("rotations") or []) + (spec.get("translations") or []) if isinstance(spec, dict)
                     else []):
            if isinstance(axis, dict) and isinstance(axis.get("coordinate"), str):
                joints_of.setdefault(axis["coordinate"], set()).add(joint)
    elsewhere = []
    for name in columns:
        m = _STATE_VALUE.fullmatch(columns.label(name))
        if m and name in joints_of and m.group(1) not in joints_of[name]:
            elsewhere.append(f"{m.group(0)!r} (the model's {name!r} is in joint "
                             f"{' or '.join(repr(j) for j in sorted(joints_of[name]))})")
    if elsewhere:
        more = f" and {len(elsewhere) - LISTED} more" if len(elsewhere) > LISTED else ""
        notes.append(f"{source}: column(s) naming another joint than the model's: {', '.join(elsewhere[:LISTED])}"
                     f"{more}; they are read by the coordinate's name: was the file written for another model?")
    return notes


def check_values(driven, times, columns, in_degrees, data, source):
    """Check the values of the motion file ``source`` (module docstring): ``driven``
    {coordinate: (n,) values, rad or m} of the driven coordinates at ``times`` (n,) s,
    ``columns`` the file's (:func:`by_coordinate`, as written), ``in_degrees`` its
    ``inDegrees``. Refuses (OsimError) a value beyond MAX_ROTATION / MAX_TRANSLATION;
    returns the warnings (one line each): one about the rotational coordinates that leave
    their range by RANGE_MARGIN, one about coupled coordinates' columns that their
    couplers contradict."""
    notes = []
    if len(times) == 0:  # no samples: refused as too few (motion_drivers)
        return notes
    coords = data.get("coordinates") or {}
    for name, values in driven.items():
        rotational = coords[name].get("motion", "rotational") != "translational"
        bound, unit = (MAX_ROTATION, "rad") if rotational else (MAX_TRANSLATION, "m")
        k = int(np.argmax(np.abs(values)))
        if abs(values[k]) > bound:
            as_written = f"{columns[name][k]:g} deg, " if in_degrees and opensim_in_degrees(coords[name]) else ""
            raise OsimError(f"{source}: column {columns.label(name)!r} at time {times[k]:.10g} s: {as_written}"
                            f"{values[k]:g} {unit}, beyond the {bound:g} {unit} a "
                            f"{'rotational' if rotational else 'translational'} coordinate can reach")
    outside = []
    for name, values in driven.items():
        c = coords[name]
        if c.get("motion", "rotational") != "rotational":
            continue
        low, high = c.get("range") or OPENSIM_DEFAULT_RANGE
        k = int(np.argmax(np.maximum(low - values, values - high)))
        if values[k] < low - RANGE_MARGIN or values[k] > high + RANGE_MARGIN:
            default = "" if c.get("range") else ", OpenSim's default"
            outside.append(f"{columns.label(name)!r} {values[k]:.4g} rad at {times[k]:.10g} s "
                           f"(range [{low:g}, {high:g}]{default})")
    if outside:
        line = (columns.header or {}).get("indegrees")
        said = (f"inDegrees={'yes' if in_degrees else 'no'} on line {line[0]}" if line
                else "no inDegrees line: read as radians")
        more = f" and {len(outside) - LISTED} more" if len(outside) > LISTED else ""
        notes.append(f"{source}: rotational column(s) more than {RANGE_MARGIN:g} rad outside the coordinate's range: "
                     f"{', '.join(outside[:LISTED])}{more}; {said}: is that right? (the motion is followed as given, "
                     "as OpenSim follows an unclamped coordinate)")
    contradicted = _contradicted_couplers(driven, times, columns, in_degrees, data)
    if contradicted:
        more = f" and {len(contradicted) - LISTED} more" if len(contradicted) > LISTED else ""
        notes.append(f"{source}: column(s) of coupled coordinates that their couplers contradict, not used (the "
                     f"coupler sets them): {', '.join(contradicted[:LISTED])}{more}")
    return notes


def _contradicted_couplers(driven, times, columns, in_degrees, data):
    """["'column' (coupler 'name' from 'independent': X rad off at t s)"] of the
    columns of coupled (dependent) coordinates farther than COUPLER_TOLERANCE from what
    their couplers give from ``driven`` {coordinate: (n,) rad or m} (and the locked
    coordinates' defaults); couplers whose inputs are not known (an FDK DOF's) are left
    out. ``data`` is the model mapping (SI, as :mod:`.to_model` writes it)."""
    from ...model.coordinate_functions import function_from_spec

    units = data.get("units") or {}
    if units.get("length", "m") != "m" or units.get("angle", "rad") != "rad":
        return []
    coords = data.get("coordinates") or {}
    known = dict(driven)
    for name, c in coords.items():
        if c.get("locked") and isinstance(c.get("default"), (int, float)):
            known.setdefault(name, np.full(len(times), float(c["default"])))
    couplers = {n: c for n, c in (data.get("couplers") or {}).items() if isinstance(c, dict)}
    found, done = [], set()
    for _ in range(len(couplers)):  # chains: a coupler's independent coordinate may be another's dependent
        for cname, c in couplers.items():
            dep, ind = c.get("dependent"), c.get("independent")
            if cname in done or ind not in known or dep in driven:
                continue
            try:
                fn = function_from_spec(c.get("function"), f"couplers.{cname}", lambda path, msg: ValueError(msg))
                value = np.asarray(fn.evaluate(np.asarray(known[ind], float))[0], float).reshape(-1)
            except (ValueError, TypeError):
                done.add(cname)
                continue
            done.add(cname)
            known[dep] = value
            if dep not in columns or dep not in coords:
                continue
            written = np.asarray(columns[dep], float)
            column = np.radians(written) if in_degrees and opensim_in_degrees(coords[dep]) else written
            with np.errstate(invalid="ignore", over="ignore"):
                off = np.abs(column - value)
            off = np.where(np.isfinite(off), off, np.inf)
            k = int(np.argmax(off))
            if off[k] > COUPLER_TOLERANCE:
                unit = "m" if coords[dep].get("motion") == "translational" else "rad"
                found.append(f"{columns.label(dep)!r} (coupler {cname!r} from {ind!r}: {off[k]:.3g} {unit} off at "
                             f"{times[k]:.10g} s)")
    return found


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
