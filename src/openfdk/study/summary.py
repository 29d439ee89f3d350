"""The study summary table and aggregation over cases.

``summary.csv`` has one row per case: ``case_id``, ``status`` (completed / failed),
``reused`` (1 when the case was complete before this run), the input names (e.g.
``model``, ``trial``), one column per parameter (value as written in the study file),
``frames``, ``convergence_rate`` (FDK frames converged for FDK models; frames whose
kinematics and inverse dynamics converged otherwise), ``mean_fdk_evaluations`` (residual
evaluations per frame), ``rms_marker_residual_m``, ``wall_time_s``, ``attempts``,
``error``, then the key metrics of the results:

* per contact ``<contact>.peak_force_N`` and ``.mean_force_N`` (|F| over frames);
* per FDK DOF ``fdk.<dof>.alpha_min`` and ``.alpha_max`` (SI: m or rad);
* per ligament ``<ligament>.peak_force_N``;
* for each column named in the study's ``run.metrics`` (a column of forces.csv or
  kinematics.csv): ``<column>.mean``, ``.min`` and ``.max``.

``summary.json`` holds the same records plus the study, the execution (scheduler,
workers) and, for failed cases, the traceback. Metrics are computed by
:func:`case_metrics` from the case folders, so a reused case is summarised the same way
as a new one: for a case run now, by the worker right after it wrote the folder
(:func:`openfdk.study.case.with_metrics`), else by the driver.
"""

from __future__ import annotations

import csv
import io
import json
import math
import os
from pathlib import Path

import numpy as np

from ..io.results import atomic_write_text, read_table, write_json
from .defaults import CASES  # (not from .case, which imports this module)


def _stat(fn, x):
    x = np.asarray(x, dtype=float)
    return float(fn(x)) if np.any(np.isfinite(x)) else math.nan


def case_metrics(folder, extra_columns=()):
    """(metrics dict, warnings list) of a complete case folder (module docstring)."""
    folder = Path(folder)
    summary = json.loads((folder / "summary.json").read_text())
    forces = read_table(folder / "forces.csv")
    m = {"frames": summary["inverse_dynamics"]["frames"]}
    fdk = summary.get("fdk")
    if fdk is not None:
        m["convergence_rate"] = fdk["convergence_rate"]
        m["mean_fdk_evaluations"] = fdk["mean_residual_evaluations_per_frame"]
    else:
        ok = np.asarray(forces.get("converged", []), dtype=float)
        m["convergence_rate"] = float(ok.mean()) if ok.size else math.nan
        m["mean_fdk_evaluations"] = math.nan
    rms = summary["kinematics"].get("rms_marker_residual_m")
    m["rms_marker_residual_m"] = math.nan if rms is None else rms
    for name in forces:
        if name.endswith(".Fx_N"):
            c = name[: -len(".Fx_N")]
            F = np.sqrt(sum(np.asarray(forces[f"{c}.F{a}_N"], dtype=float) ** 2 for a in "xyz"))
            m[f"{c}.peak_force_N"] = _stat(np.nanmax, F)
            m[f"{c}.mean_force_N"] = _stat(np.nanmean, F)
    for name in forces:
        if name.startswith("fdk.") and name.endswith(".alpha"):
            m[f"{name}_min"] = _stat(np.nanmin, forces[name])
            m[f"{name}_max"] = _stat(np.nanmax, forces[name])
    for name in forces:
        if name.endswith(".strain") and f"{name[:-7]}.force_N" in forces:
            m[f"{name[:-7]}.peak_force_N"] = _stat(np.nanmax, forces[f"{name[:-7]}.force_N"])
    warnings = []
    kin = None
    for col in extra_columns:
        values = forces.get(col)
        if values is None:
            kin = read_table(folder / "kinematics.csv") if kin is None else kin
            values = kin.get(col)
        if values is None or not isinstance(values, np.ndarray):
            warnings.append(f"metric column {col!r} is not a numeric column of forces.csv or kinematics.csv")
            values = np.full(1, np.nan)
        m[f"{col}.mean"] = _stat(np.nanmean, values)
        m[f"{col}.min"] = _stat(np.nanmin, values)
        m[f"{col}.max"] = _stat(np.nanmax, values)
    return m, warnings


BASE_COLUMNS = ("case_id", "status", "reused")
RUN_COLUMNS = ("frames", "convergence_rate", "mean_fdk_evaluations", "rms_marker_residual_m", "wall_time_s",
               "attempts", "error")


def summary_rows(study, records):
    """(header, rows) of summary.csv; records are the driver's per-case dicts."""
    inputs = []
    for c in study.cases:
        inputs += [s for s in c.names if s not in inputs]
    params = study.parameter_names
    metric_names = []
    for r in records:
        metric_names += [k for k in r.get("metrics", {}) if k not in RUN_COLUMNS and k not in metric_names]
    header = list(BASE_COLUMNS) + [_singular(s) for s in inputs] + params + list(RUN_COLUMNS) + metric_names
    rows = []
    for r in records:
        metrics = r.get("metrics", {})
        row = [r["case_id"], r["status"], int(bool(r.get("reused")))]
        row += [r["names"].get(s, "") for s in inputs]
        row += [r["parameters"].get(p, "") for p in params]
        row += [metrics.get("frames", ""), metrics.get("convergence_rate", ""), metrics.get("mean_fdk_evaluations", ""),
                metrics.get("rms_marker_residual_m", ""), r.get("wall_time_s", ""), r.get("attempts", ""),
                r.get("error", "")]
        row += [metrics.get(k, "") for k in metric_names]
        rows.append([_cell(x) for x in row])
    return header, rows


def _singular(section):
    return section.removesuffix("s")


def _cell(x):
    if isinstance(x, float):
        return "nan" if math.isnan(x) else f"{x:.10g}"
    if isinstance(x, (list, dict)):
        return json.dumps(x)
    return "" if x is None else str(x)


def write_summary(out_dir, study, records, execution, wall_time):
    """Write summary.csv and summary.json into ``out_dir`` (atomically). Returns the
    summary dict."""
    out = Path(out_dir)
    header, rows = summary_rows(study, records)
    buf = io.StringIO()
    w = csv.writer(buf)
    w.writerow(header)
    w.writerows(rows)
    atomic_write_text(out / "summary.csv", buf.getvalue())
    counts = {
        "cases": len(study.cases),
        "completed": sum(r["status"] == "completed" for r in records),
        "reused": sum(bool(r.get("reused")) for r in records),
        "failed": sum(r["status"] == "failed" for r in records),
        "not_run": len(study.cases) - len(records),
    }
    doc = {"study": study.name, "study_file": str(study.source) if study.source else None, "kind": study.kind,
           "parameters": [{"name": p.name, "paths": list(p.paths), "scale": p.scale, "mode": p.mode}
                          for p in study.parameters],
           "counts": counts, "wall_time_s": wall_time, "execution": execution, "cases": records}
    write_json(out / "summary.json", doc)
    return doc


def load_summary(out_dir):
    """The summary.json of a study output folder."""
    return json.loads((Path(out_dir) / "summary.json").read_text())


def case_series(out_dir, column, where=None):
    """Time series of one result column over the completed cases of a study.

    column : a forces.csv or kinematics.csv column (e.g. ``tmj_r.Fz_N``,
    ``fdk.tmj_r_normal.alpha``); where : optional {input section or parameter: value}
    filter, e.g. {"trials": "open_close"}. Returns (time (nf,) s, values (n_cases, nf),
    case ids). All selected cases must share the same time samples."""
    doc = load_summary(out_dir)
    ids, series, time = [], [], None
    for r in doc["cases"]:
        if r["status"] != "completed":
            continue
        if where and any(r["names"].get(k, r["parameters"].get(k)) != v for k, v in where.items()):
            continue
        folder = Path(out_dir) / CASES / r["case_id"]
        table = read_table(folder / "forces.csv")
        if column not in table:
            table = read_table(folder / "kinematics.csv")
        if column not in table or not isinstance(table[column], np.ndarray):
            raise ValueError(f"case {r['case_id']}: column {column!r} is not in forces.csv or kinematics.csv")
        t = table["time"]
        if time is not None and (len(t) != len(time) or np.max(np.abs(t - time)) > 1e-9):
            raise ValueError(f"case {r['case_id']} has other time samples than {ids[0]}; select one trial with `where`")
        time = t
        ids.append(r["case_id"])
        series.append(table[column])
    if not ids:
        raise ValueError(f"no completed case in {os.fspath(out_dir)!r} matches {where}")
    return time, np.vstack(series), ids


def parameter_band(out_dir, column, where=None):
    """The parameter-study band of one column: (time (nf,) s, lower (nf,), upper (nf,),
    mean (nf,)) — the envelope (min/max over cases, NaN ignored) and the mean, in the
    column's unit."""
    time, values, _ = case_series(out_dir, column, where)
    with np.errstate(all="ignore"):
        return time, np.nanmin(values, axis=0), np.nanmax(values, axis=0), np.nanmean(values, axis=0)
