"""Tables 1 and 2 of the mandible study (Andersen et al. 2017): TMJ kinematics and forces.

Data layout (all arrays cycle-normalised by :func:`openfdk.mandible.cycles.normalize_cycles`):

* ``kinematics``: ``dict[model -> dict[side -> (n_cycles, n_points, 3) m]]`` with model in
  {"measured", "POP", "FDK"} and side in {"left", "right"}; the 3 components are AP (x,
  anterior), ML (y, to the left) and SI (z, up) of the condyle point in the skull frame
  (positions, or displacements from a reference pose — Sprague–Geers M and P depend on
  that origin, see docs/mandible-study-outputs.md). Tables report RMSD in mm.
* ``forces``: ``dict[model -> dict[side -> (n_cycles, n_points, 3) N]]`` for "POP" and
  "FDK": the TMJ reaction force on the mandible in the skull frame (AP, ML, SI).
* ``results_by_task``: ``dict[task -> kinematics]`` (for :func:`table1`) or
  ``dict[task -> forces]`` (for :func:`table2`); a task entry may also be
  ``{"kinematics": kinematics, "forces": forces}``, from which each table takes its part.
  Within a task every compared array has the same (n_cycles, n_points): cycle k of
  every model is the same time interval.

Tables (docs/mandible-study-outputs.md):

* Table 1, per task × side × direction: FDK vs measured and POP vs measured (c = model,
  m = measured): RMSD (mm), r², Sprague–Geers M and P.
* Table 2, per task × side × direction: POP vs FDK forces (c = POP, m = FDK, as in the
  paper: M < 0 means the POP force is smaller): RMSD (N), r², M, P.

Each metric is computed per cycle on the n_points samples (:mod:`openfdk.results.metrics`, NaN
pairs dropped) and summarised as mean ± SD over the cycles (sample SD, ddof = 1; cycles
whose metric is NaN are left out; SD is NaN with fewer than two finite cycles).

A row is a flat dict: ``task, side, direction, reference, unit, n_cycles`` and, for each
compared model label L (table 1: "FDK", "POP"; table 2: "POP"), ``L_RMSD_mean,
L_RMSD_sd, L_r2_mean, L_r2_sd, L_M_mean, L_M_sd, L_P_mean, L_P_sd``; ``reference`` is
the model compared against ("measured" or "FDK") and ``unit`` the RMSD unit ("mm" or "N").
"""

from __future__ import annotations

import csv
import math
import os
import sys

import numpy as np

from ..results.metrics import compare

__all__ = [
    "DIRECTIONS",
    "METRICS",
    "SIDES",
    "ReportInputError",
    "check_series",
    "cycle_metrics",
    "format_text",
    "print_table",
    "read_csv",
    "table1",
    "table2",
    "task_title",
    "to_markdown",
    "write_csv",
]

SIDES = ("left", "right")
DIRECTIONS = ("AP", "ML", "SI")          # components 0, 1, 2 (x, y, z of the skull frame)
METRICS = ("RMSD", "r2", "M", "P")
_KEY = {"RMSD": "rmsd", "r2": "r2", "M": "M", "P": "P"}   # → openfdk.results.metrics.compare keys
_HEADER = {"RMSD": "RMSD", "r2": "r²", "M": "M", "P": "P"}
_ID_COLUMNS = ("task", "side", "direction", "reference", "unit", "n_cycles")


class ReportInputError(ValueError):
    """Study results do not have the layout the tables and figures expect."""


# --------------------------------------------------------------------------------------
# Input checks and per-cycle metrics
# --------------------------------------------------------------------------------------

def check_series(where: str, array) -> np.ndarray:
    """``array`` as float (n_cycles, n_points, 3); ``where`` names it in the error."""
    a = np.asarray(array, dtype=float)
    if a.ndim != 3 or a.shape[2] != 3 or a.shape[0] < 1 or a.shape[1] < 2:
        raise ReportInputError(f"{where} must have shape (n_cycles, n_points, 3) "
                               f"(AP, ML, SI per normalised cycle); got {a.shape}")
    return a


def _section(task: str, entry, part: str) -> dict:
    """The kinematics or forces dict of a task entry (either layout of the docstring)."""
    if not isinstance(entry, dict):
        raise ReportInputError(f"task {task!r}: expected a dict of models, got {type(entry).__name__}")
    if part in entry and isinstance(entry[part], dict):
        return entry[part]
    return entry


def _side_array(task: str, models: dict, model: str, side: str) -> np.ndarray:
    if model not in models:
        raise ReportInputError(f"task {task!r}: model {model!r} missing; have {sorted(models)}")
    if side not in models[model]:
        raise ReportInputError(f"task {task!r}, model {model!r}: side {side!r} missing; "
                               f"have {sorted(models[model])}")
    return check_series(f"task {task!r}, model {model!r}, side {side!r}", models[model][side])


def cycle_metrics(c, m, scale: float = 1.0) -> dict:
    """Metrics of computed c against measured m, one value per cycle.

    Args: c, m : (n_cycles, n_points) same unit (one direction, cycle-normalised);
    scale : factor applied to both before the RMSD (e.g. 1e3 for m → mm).
    Returns: dict metric name ("RMSD", "r2", "M", "P") → (n_cycles,) values
    (RMSD in the scaled unit; NaN where undefined, see :mod:`openfdk.results.metrics`).
    """
    c, m = np.asarray(c, dtype=float), np.asarray(m, dtype=float)
    if c.shape != m.shape or c.ndim != 2:
        raise ReportInputError(f"computed and reference cycles must both be (n_cycles, "
                               f"n_points); got {c.shape} and {m.shape}")
    per_cycle = [compare(scale * c[k], scale * m[k]) for k in range(c.shape[0])]
    return {name: np.array([d[_KEY[name]] for d in per_cycle]) for name in METRICS}


def _mean_sd(values: np.ndarray) -> tuple[float, float]:
    """Mean and sample SD (ddof = 1) over the finite values; NaN when too few."""
    v = values[np.isfinite(values)]
    mean = float(v.mean()) if v.size else math.nan
    sd = float(v.std(ddof=1)) if v.size > 1 else math.nan
    return mean, sd


def _rows(results_by_task: dict, part: str, computed: tuple, reference: str,
          scale: float, unit: str) -> list[dict]:
    if not results_by_task:
        raise ReportInputError("no tasks given")
    rows = []
    for task, entry in results_by_task.items():
        models = _section(task, entry, part)
        for side in SIDES:
            m_all = _side_array(task, models, reference, side)
            c_all = {}
            for label in computed:
                c_all[label] = _side_array(task, models, label, side)
                if c_all[label].shape != m_all.shape:
                    raise ReportInputError(
                        f"task {task!r}, side {side!r}: model {label!r} has shape "
                        f"{c_all[label].shape} but {reference!r} has {m_all.shape}; cycles "
                        "must be split and normalised identically")
            for d, direction in enumerate(DIRECTIONS):
                row = {"task": task, "side": side, "direction": direction,
                       "reference": reference, "unit": unit, "n_cycles": m_all.shape[0]}
                for label in computed:
                    per_cycle = cycle_metrics(c_all[label][:, :, d], m_all[:, :, d], scale)
                    for name in METRICS:
                        row[f"{label}_{name}_mean"], row[f"{label}_{name}_sd"] = \
                            _mean_sd(per_cycle[name])
                rows.append(row)
    return rows


def table1(results_by_task: dict, models: tuple = ("FDK", "POP"),
           reference: str = "measured") -> list[dict]:
    """Table 1: condyle kinematics of each model vs the measured ones, per task/side/direction.

    Args: results_by_task : dict[task -> kinematics] (module docstring; arrays
    (n_cycles, n_points, 3) m); models : the computed models; reference : the measured one.
    Returns: one row per task × side (left, right) × direction (AP, ML, SI), in task
    order; RMSD in mm (columns in the module docstring).
    """
    return _rows(results_by_task, "kinematics", tuple(models), reference, 1e3, "mm")


def table2(results_by_task: dict, computed: str = "POP", reference: str = "FDK") -> list[dict]:
    """Table 2: TMJ reaction forces, POP (c) vs FDK (m), per task/side/direction.

    Args: results_by_task : dict[task -> forces] (module docstring; arrays
    (n_cycles, n_points, 3) N); computed, reference : the two models (paper: c = POP,
    m = FDK, so M < 0 means the POP force is smaller).
    Returns: one row per task × side × direction; RMSD in N.
    """
    return _rows(results_by_task, "forces", (computed,), reference, 1.0, "N")


# --------------------------------------------------------------------------------------
# Writers
# --------------------------------------------------------------------------------------

def _labels(rows: list[dict]) -> list[str]:
    """Compared model labels of the rows, in column order."""
    if not rows:
        raise ReportInputError("no table rows given")
    return [k[: -len("_RMSD_mean")] for k in rows[0] if k.endswith("_RMSD_mean")]


def write_csv(rows: list[dict], path) -> str:
    """Write table rows as CSV (one header line; floats at full precision, NaN as "nan").

    Args: rows from :func:`table1`/:func:`table2`; path : output file.
    Returns: the path.
    """
    if not rows:
        raise ReportInputError("no table rows given")
    columns = list(rows[0])
    with open(path, "w", newline="", encoding="utf-8") as f:
        writer = csv.DictWriter(f, fieldnames=columns)
        writer.writeheader()
        for row in rows:
            writer.writerow({k: repr(v) if isinstance(v, float) else v for k, v in row.items()})
    return os.fspath(path)


def read_csv(path) -> list[dict]:
    """Read rows written by :func:`write_csv` (metric columns as float, n_cycles as int)."""
    with open(path, newline="", encoding="utf-8") as f:
        rows = list(csv.DictReader(f))
    for row in rows:
        for key, value in row.items():
            if key == "n_cycles":
                row[key] = int(value)
            elif key not in _ID_COLUMNS:
                row[key] = float(value)
    return rows


def _number(x: float, decimals: int) -> str:
    """Fixed-point text; "nan" for NaN; no "-0.00"."""
    if not math.isfinite(x):
        return "nan"
    text = f"{x:.{decimals}f}"
    return text[1:] if text.startswith("-") and float(text) == 0.0 else text


def _cell(row: dict, label: str, name: str, decimals: int) -> str:
    """Paper style "0.79±0.06"."""
    return (f"{_number(row[f'{label}_{name}_mean'], decimals)}±"
            f"{_number(row[f'{label}_{name}_sd'], decimals)}")


def task_title(task: str) -> str:
    """Display name of a task: "open_close" → "Open-close"."""
    return task.replace("_", "-").capitalize()


def to_markdown(rows: list[dict], decimals: int = 2) -> str:
    """A Markdown table in the paper's style: one row per task/side/direction and
    "mean±SD" cells per compared model and metric; a footnote gives the RMSD unit.

    Args: rows from :func:`table1`/:func:`table2`. Returns: the Markdown text.
    """
    labels = _labels(rows)
    reference = rows[0]["reference"]
    unit = rows[0]["unit"]
    head = ["Task", "Side", "Direction"] + [
        f"{label} {_HEADER[name]}" + (f" ({unit})" if name == "RMSD" else "")
        for label in labels for name in METRICS]
    lines = ["| " + " | ".join(head) + " |", "|" + "|".join(["---"] * 3 + ["---:"] * (len(head) - 3)) + "|"]
    for row in rows:
        cells = [task_title(row["task"]), row["side"].capitalize(), row["direction"]]
        cells += [_cell(row, label, name, decimals) for label in labels for name in METRICS]
        lines.append("| " + " | ".join(cells) + " |")
    n = sorted({row["n_cycles"] for row in rows})
    lines.append("")
    lines.append(f"{' and '.join(labels)} vs {reference} (c = {' or '.join(labels)}, "
                 f"m = {reference}); mean ± SD over {'/'.join(map(str, n))} cycles; "
                 f"RMSD in {unit}.")
    return "\n".join(lines) + "\n"


def format_text(rows: list[dict], decimals: int = 2) -> str:
    """A compact fixed-width version of a table for the terminal.

    Args: rows from :func:`table1`/:func:`table2`. Returns: the text (lines ≤ ~130 chars
    for two compared models).
    """
    labels = _labels(rows)
    unit, reference = rows[0]["unit"], rows[0]["reference"]
    width = 2 * decimals + 8
    group = " ".join(f"{_HEADER[n] + (f'({unit})' if n == 'RMSD' else ''):>{width}}" for n in METRICS)
    lines = [f"{'':<12}" + " | ".join(f"{label + ' vs ' + reference:^{len(group)}}" for label in labels),
             f"{'':<12}" + " | ".join(group for _ in labels)]
    task = None
    for row in rows:
        if row["task"] != task:
            task = row["task"]
            lines.append(f"{task_title(task)} ({row['n_cycles']} cycles)")
        cells = " | ".join(" ".join(f"{_cell(row, label, n, decimals):>{width}}" for n in METRICS)
                           for label in labels)
        lines.append(f"  {row['side']:<6}{row['direction']:<4}" + cells)
    return "\n".join(lines) + "\n"


def print_table(rows: list[dict], file=None, decimals: int = 2) -> None:
    """Print :func:`format_text` of the rows (to ``file``, default stdout)."""
    print(format_text(rows, decimals), end="", file=file or sys.stdout)
