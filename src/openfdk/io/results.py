"""Writing analysis results: CSV tables (first column ``time``) and summary JSON.

Files are written to a temporary name and renamed when complete, so an interrupted run
never leaves a half-written file under the final name.
"""

from __future__ import annotations

import csv
import json
import math
import os
from pathlib import Path

import numpy as np


def atomic_write_text(path, text):
    """Write ``text`` to ``path`` atomically (temporary file + rename)."""
    path = Path(path)
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    tmp.write_text(text)
    os.replace(tmp, path)


def write_table(path, columns: dict, time_key="time"):
    """CSV with one column per entry of ``columns`` (name -> (nf,) array or list of str);
    ``time`` first. Floats written with 10 significant digits; NaN as 'nan'."""
    path = Path(path)
    names = [time_key] + [k for k in columns if k != time_key]
    nf = len(columns[time_key])
    for k in names:
        if len(columns[k]) != nf:
            raise ValueError(f"column {k!r} has {len(columns[k])} rows, expected {nf}")
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    with open(tmp, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(names)
        w.writerows(zip(*(_format_column(columns[k]) for k in names)))
    os.replace(tmp, path)


def _format_column(values):
    """The cells of one column, formatted as :func:`_fmt` formats each value, a whole
    numeric array at once (one ``tolist`` instead of a numpy scalar per cell)."""
    if isinstance(values, np.ndarray) and values.ndim == 1:
        kind = values.dtype.kind
        if kind == "f":
            return [f"{v:.10g}" for v in values.tolist()]
        if kind == "b":
            return [int(v) for v in values.tolist()]
        if kind in "iu":
            return values.tolist()
    return [_fmt(v) for v in values]


def _fmt(x):
    if isinstance(x, (str, bytes)):
        return x
    if isinstance(x, (bool, np.bool_)):
        return int(x)
    if isinstance(x, (int, np.integer)):
        return int(x)
    return f"{float(x):.10g}"


def read_rows(path) -> list[list[str]]:
    """The rows of a CSV file as lists of str (OSError if it cannot be read)."""
    with open(path, newline="") as fh:
        return list(csv.reader(fh))


def table_columns(header, body, empty_is_nan=False) -> dict:
    """{name: column} of a table read by :func:`read_rows` (header row, body rows): a
    ``(nf,)`` float array where every cell is a number ('nan' and 'inf' included; with
    ``empty_is_nan`` an empty cell too, as NaN), else the cells as a list of str. Rows
    shorter than the header count as empty cells. Each column is converted by numpy at
    once (the same strings parse as with ``float``)."""
    n = len(header)
    if any(len(r) != n for r in body):
        body = [(list(r) + [""] * n)[:n] for r in body]
    cells = list(zip(*body)) if body else [()] * n
    return {name: _numeric(col, empty_is_nan) for name, col in zip(header, cells)}


def _numeric(col, empty_is_nan):
    """A column of cells (str) as a float array, or the cells as a list of str when one
    is not a number (with ``empty_is_nan`` an empty cell reads as NaN)."""
    try:
        return np.array([c or "nan" for c in col] if empty_is_nan else col, dtype=float)
    except ValueError:
        return list(col)


def read_table(path, empty_is_nan=False) -> dict:
    """A CSV written by :func:`write_table` (or ``summary.csv``) as {name: column}, the
    columns as in :func:`table_columns`; {} for an empty file."""
    rows = read_rows(path)
    return table_columns(rows[0], rows[1:], empty_is_nan) if rows else {}


def write_json(path, data):
    """Write ``data`` (dicts, lists, tuples, numbers, str, None, numpy arrays and scalars)
    to ``path`` as strict JSON (RFC 8259), atomically: a non-finite number (NaN, ±inf)
    is written as ``null``, never as the ``NaN``/``Infinity`` that strict parsers refuse."""
    text = json.dumps(_finite_or_null(data), indent=2, allow_nan=False)
    atomic_write_text(path, text + "\n")


def _finite_or_null(o):
    """``o`` with numpy values as Python ones and every non-finite float as None."""
    if isinstance(o, dict):
        return {k: _finite_or_null(v) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [_finite_or_null(v) for v in o]
    if isinstance(o, np.ndarray):
        return _finite_or_null(o.tolist())
    if isinstance(o, np.bool_):
        return bool(o)
    if isinstance(o, (np.floating, np.integer)):
        o = o.item()
    if isinstance(o, float) and not math.isfinite(o):
        return None
    if o is None or isinstance(o, (str, int, float)):
        return o
    raise TypeError(f"not JSON serialisable: {type(o).__name__}")


def kinematics_columns(result):
    """Columns of kinematics.csv for a KinematicsResult (SI units, names say which)."""
    cols = {"time": result.time}
    cols["converged"] = result.converged.astype(int)
    cols["iterations"] = result.iterations
    cols["constraint_violation"] = result.constraint_violation
    for k, b in enumerate(result.body_names):
        q, v, a = result.q[:, 7 * k : 7 * k + 7], result.v[:, 6 * k : 6 * k + 6], result.vdot[:, 6 * k : 6 * k + 6]
        for j, c in enumerate(("x", "y", "z")):
            cols[f"{b}.{c}_m"] = q[:, j]
        for j in range(4):
            cols[f"{b}.e{j}"] = q[:, 3 + j]
        for j, c in enumerate(("vx", "vy", "vz")):
            cols[f"{b}.{c}_m_s"] = v[:, j]
        for j, c in enumerate(("wx", "wy", "wz")):
            cols[f"{b}.{c}_rad_s"] = v[:, 3 + j]
        for j, c in enumerate(("ax", "ay", "az")):
            cols[f"{b}.{c}_m_s2"] = a[:, j]
        for j, c in enumerate(("dwx", "dwy", "dwz")):
            cols[f"{b}.{c}_rad_s2"] = a[:, 3 + j]
    res = result.marker_residual
    for k, m in enumerate(result.marker_names):
        if res.shape[1] == 0:
            break
        for j, c in enumerate("xyz"):
            cols[f"{m}.residual_{c}_m"] = res[:, k, j]
    cols["message"] = list(result.messages)
    return cols


def write_kinematics(out_dir, result, extra_summary=None):
    """Write ``kinematics.csv`` and ``summary.json`` into ``out_dir`` (created)."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    write_table(out / "kinematics.csv", kinematics_columns(result))
    summary = {"kinematics": result.summary()}
    if extra_summary:
        summary.update(extra_summary)
    write_json(out / "summary.json", summary)
    return out


def forces_columns(res):
    """Columns of forces.csv for an InverseDynamicsResult (N; activation = f/s)."""
    cols = {"time": res.time, "converged": res.converged.astype(int), "status": list(res.status),
            "recruitment_iterations": res.iterations}
    nm = len(res.muscle_names)
    for k, name in enumerate(res.muscle_names):
        cols[f"{name}.force_N"] = res.forces[:, k]
        with np.errstate(invalid="ignore", divide="ignore"):
            cols[f"{name}.activation"] = res.forces[:, k] / res.muscle_strength[:, k]
        cols[f"{name}.passive_N"] = res.muscle_passive[:, k]
        cols[f"{name}.strength_N"] = res.muscle_strength[:, k]
        cols[f"{name}.length_m"] = res.muscle_length[:, k]
    na = len(res.actuator_names)
    for j, name in enumerate(res.actuator_names):  # signed, N or N m; control = τ / optimal force
        cols[f"{name}.actuator"] = res.forces[:, nm + j]
        cols[f"{name}.control"] = res.forces[:, nm + j] / res.actuator_optimal_force[j]
    for k in range(nm + na, len(res.column_names)):
        cols[f"{res.column_names[k]}.reaction"] = res.forces[:, k]
    for k, name in enumerate(res.ligament_names):
        cols[f"{name}.force_N"] = res.ligament_force[:, k]
        cols[f"{name}.strain"] = res.ligament_strain[:, k]
        cols[f"{name}.length_m"] = res.ligament_length[:, k]
    for k, name in enumerate(res.spring_names):
        cols[f"{name}.force"] = res.spring_force[:, k]
    for key, arr in res.extra.get("columns", {}).items():
        cols[key] = arr
    cols["message"] = list(res.messages)
    return cols


def write_forces(out_dir, res):
    """Write ``forces.csv`` into ``out_dir``."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    write_table(out / "forces.csv", forces_columns(res))
