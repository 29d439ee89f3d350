"""A run's coordinates against measured kinematics over one gait cycle
(``openfdk validate-kinematics``, docs/outputs.md#validation-against-measured-kinematics).

One algorithm:

1. **The run** (a result folder of ``openfdk run`` / ``kinematics``): each compared model
   quantity is read as a time series in SI units (m, rad), from the first file that has
   it: ``coordinates.csv`` (``<coordinate>_m`` / ``_rad``, OpenSim models),
   ``forces.csv`` (``fdk.<dof>.alpha``, the FDK DOFs of any model) or ``measures.csv``
   (``<measure>_m``, ``<measure>[k]_rad``; named without the unit suffix). A frame is
   usable when its value is finite and it converged (``forces.csv`` ``converged``, else
   ``kinematics.csv`` ``converged``): the values of failed frames are not solutions.
2. **The gait cycle.** ``cycle = (T0, T1)`` s, a heel strike and the next one of the same
   foot, maps the run's time onto % of the cycle: ``p = 100 (t − T0) / (T1 − T0)``.
3. **The reference** (an OpenSim storage file, ``.sto`` / ``.mot``) has its time column
   either in % of the gait cycle or in seconds (then mapped as the run is). ``auto``
   reads it as % when every time lies in [0, 100] and they span at least 50 (a cycle
   sampled in %), else as seconds. Only reference samples within 0–100 % are compared.
4. **The map** (YAML) names, per reference column, the model quantity, the column's unit
   in the file (``m``, ``mm``, ``rad``, ``deg``), a ``scale`` (default 1; e.g. −1 for a
   column whose sign convention is the opposite of the model's) and an optional
   ``label``. The reference in the model's convention is ``scale × column`` (SI).
5. **Comparison** at the reference's samples inside the run's covered range: the model
   is interpolated linearly in % between two adjacent usable frames (never across a
   failed frame). Per DOF, with d = model − reference (display units: mm, deg):
   mean offset = mean(d); RMSD = sqrt(mean(d²)); RMSD with the offset removed =
   sqrt(mean((d − mean d)²)); r² = the squared Pearson correlation of model and
   reference (NaN when either is constant).

Errors are :class:`ValidationError` (a ``ValueError``) with a one-line message naming
the file and the entry.
"""

from __future__ import annotations

import csv
import io
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..results.run import COORDINATES_CSV

__all__ = ["ValidationError", "MapEntry", "Reference", "RunSeries", "DofComparison", "ValidationResult",
           "read_map", "read_reference", "read_run_series", "compare", "agreement", "validate_kinematics",
           "write_validation", "table_rows", "csv_text", "markdown_table", "text_table", "describe", "cycle_percent",
           "check_cycle", "interpolate_usable",
           "REFERENCE_TIME_MODES", "UNITS"]

#: the unit of a reference column in its file -> (kind, factor to SI)
UNITS = {"m": ("length", 1.0), "mm": ("length", 1e-3), "rad": ("angle", 1.0), "deg": ("angle", math.pi / 180.0)}
#: kind -> (factor from SI to the reported unit, reported unit)
DISPLAY = {"length": (1e3, "mm"), "angle": (180.0 / math.pi, "deg")}
#: the unit suffix of a run column -> kind
_SUFFIX_KIND = {"m": "length", "rad": "angle", "1": "dimensionless"}
MAP_KEYS = ("coordinate", "unit", "scale", "label")
#: the bounds of a map entry's |scale| (a sign, a unit factor)
MIN_SCALE, MAX_SCALE = 1e-6, 1e6
REFERENCE_TIME_MODES = ("auto", "percent", "seconds")
#: ``auto``: a time column within [0, 100] spanning at least this much is % of the cycle
PERCENT_MIN_SPAN = 50.0
#: the files written by :func:`write_validation`
OUTPUT_FILES = ("validation.csv", "validation.md", "validation.png")


class ValidationError(ValueError):
    """Bad input of a kinematics validation: one line naming the file and the entry."""


@dataclass(frozen=True)
class MapEntry:
    """One compared DOF: reference ``column`` <-> model ``coordinate``; ``unit`` of the
    column in the reference file (a key of :data:`UNITS`); ``scale``: the reference in
    the model's convention is ``scale × column``; ``label`` for tables and figures."""

    column: str
    coordinate: str
    unit: str
    scale: float = 1.0
    label: str = ""

    @property
    def kind(self) -> str:
        """``length`` or ``angle``."""
        return UNITS[self.unit][0]

    @property
    def display(self):
        """(factor from SI, unit): (1e3, "mm") or (180/π, "deg")."""
        return DISPLAY[self.kind]

    @property
    def name(self) -> str:
        return self.label or self.column


@dataclass
class Reference:
    """The reference file read: ``percent`` (n,) % of the gait cycle of each sample,
    ``columns`` {column: (n,) file values}, ``time_mode`` (``percent`` or ``seconds``,
    as read), ``in_degrees`` (the file header's), ``path``."""

    path: Path
    percent: np.ndarray
    columns: dict
    time_mode: str
    in_degrees: bool


@dataclass
class RunSeries:
    """Model quantities of a run: ``time`` (nf,) s; ``values`` {name: (nf,) SI};
    ``kinds`` {name: length / angle / dimensionless / None (unknown)}; ``sources``
    {name: file}; ``converged`` (nf,) bool (the frame's analysis succeeded)."""

    directory: Path
    time: np.ndarray
    values: dict
    kinds: dict
    sources: dict
    converged: np.ndarray


@dataclass
class DofComparison:
    """One DOF compared, in display units (mm or deg): ``percent`` (k,) % of the cycle
    and ``model``, ``reference`` (k,) at the compared samples; ``model_curve`` (nf,) the
    model at the run's frames (NaN where unusable) at ``run_percent``; the agreement
    ``stats`` (:func:`agreement`)."""

    entry: MapEntry
    unit: str
    percent: np.ndarray
    model: np.ndarray
    reference: np.ndarray
    reference_percent_all: np.ndarray
    reference_all: np.ndarray
    run_percent: np.ndarray
    model_curve: np.ndarray
    stats: dict

    @property
    def covered(self):
        """(first, last) % of the compared samples (NaN, NaN when none)."""
        return (float(self.percent[0]), float(self.percent[-1])) if self.percent.size else (math.nan, math.nan)


@dataclass
class ValidationResult:
    """Every DOF's comparison, and the inputs: ``cycle`` (T0, T1) s, ``toe_off`` s or
    None, ``covered`` (first, last) % of the cycle that the run's usable frames cover,
    ``run_dir``, ``reference`` path, reference ``time_mode`` and how it was chosen."""

    dofs: list
    cycle: tuple
    toe_off: float | None
    covered: tuple
    run_dir: Path
    reference_path: Path
    time_mode: str
    time_mode_rule: str
    notes: list = field(default_factory=list)
    shift: float = 0.0  # % of the cycle the reference's phase was moved by (validate_kinematics, align_by)
    alignment: str = ""  # how the shift was chosen

    @property
    def toe_off_percent(self):
        return None if self.toe_off is None else cycle_percent(self.toe_off, self.cycle)


# -- inputs ---------------------------------------------------------------------------

def read_map(path) -> list:
    """The map file (YAML) as a list of :class:`MapEntry`, in file order. Top level: a
    mapping reference column -> ``{coordinate: NAME, unit: m|mm|rad|deg, scale: NUMBER
    (default 1; |scale| in [1e-6, 1e6]), label: TEXT}``."""
    from ..io.yamlfile import YamlContext, read_yaml

    path = Path(path)
    data = read_yaml(path, ValidationError, "map file")
    ctx = YamlContext(path.name, error_type=ValidationError)
    if data is None:
        raise ctx.error("", "empty; expected a mapping of reference columns to {coordinate, unit}")
    ctx.mapping(data, "")
    entries = []
    for column, spec in data.items():
        key = str(column)
        if not isinstance(column, str) or not column.strip():
            raise ctx.error(key, "a reference column name must be text")
        ctx.mapping(spec, key, allowed=MAP_KEYS, required=("coordinate", "unit"))
        coordinate = ctx.string(spec["coordinate"], f"{key}.coordinate")
        unit = ctx.choice(spec["unit"], f"{key}.unit", tuple(UNITS), what="unit")
        scale = ctx.number(spec.get("scale", 1.0), f"{key}.scale")
        if not MIN_SCALE <= abs(scale) <= MAX_SCALE:
            raise ctx.error(f"{key}.scale", f"|scale| must be in [{MIN_SCALE:g}, {MAX_SCALE:g}] (a sign and a unit "
                                            f"factor), got {scale:g}")
        label = ctx.string(spec["label"], f"{key}.label") if "label" in spec else ""
        entries.append(MapEntry(column, coordinate, unit, scale, label))
    if not entries:
        raise ctx.error("", "no entries; expected a mapping of reference columns to {coordinate, unit}")
    return entries


def cycle_percent(time, cycle):
    """% of the gait cycle (T0, T1) s of ``time`` (s): 100 (t − T0) / (T1 − T0)."""
    t0, t1 = cycle
    return 100.0 * (np.asarray(time, dtype=float) - t0) / (t1 - t0)


def check_cycle(cycle, toe_off=None):
    """ValidationError unless T0 < T1 (finite) and T0 < toe_off < T1."""
    t0, t1 = (float(c) for c in cycle)
    if not (math.isfinite(t0) and math.isfinite(t1)):
        raise ValidationError(f"--cycle: expected two finite times in s, got {t0:g} {t1:g}")
    if t1 <= t0:
        raise ValidationError(f"--cycle: the next heel strike ({t1:g} s) must come after the first ({t0:g} s)")
    if toe_off is not None and not t0 < toe_off < t1:
        raise ValidationError(f"--toe-off: {toe_off:g} s is not inside the cycle {t0:g}–{t1:g} s")
    return t0, t1


def _time_mode(time, mode):
    """(mode used, the rule as a phrase) for a reference time column ``time``."""
    if mode not in REFERENCE_TIME_MODES:
        raise ValidationError(f"--reference-time: expected one of {list(REFERENCE_TIME_MODES)}, got {mode!r}")
    if mode != "auto":
        return mode, "as given (--reference-time)"
    percent = time.size > 1 and time[0] >= 0.0 and time[-1] <= 100.0 and time[-1] - time[0] >= PERCENT_MIN_SPAN
    rule = (f"detected: times {time[0]:g}..{time[-1]:g} within [0, 100] spanning >= {PERCENT_MIN_SPAN:g}" if percent
            else f"detected: times {time[0]:g}..{time[-1]:g} are not a 0-100 % cycle")
    return ("percent" if percent else "seconds"), rule


def read_reference(path, entries, cycle, time_mode="auto", map_name="map"):
    """The reference file (OpenSim storage) as a :class:`Reference` whose ``percent``
    holds only the samples within 0–100 % of ``cycle``; the mapped columns must exist
    and hold finite numbers (``map_name`` names the map file in messages). Returns
    (Reference, rule): how the time column was read."""
    from ..io.storage import read_storage
    from ..io.yamlfile import did_you_mean

    path = Path(path)
    if not path.is_file():
        raise ValidationError(f"reference file {str(path)!r} does not exist")
    try:
        time, columns, in_degrees = read_storage(path)
    except ValueError as exc:
        raise ValidationError(str(exc)) from None
    if time.size == 0:
        raise ValidationError(f"{path.name}: no rows after the column labels")
    for e in entries:
        if e.column not in columns:
            raise ValidationError(f"{path.name}: {columns.absent(e.column)} (entry {e.column!r} of {map_name})"
                                  f"{did_you_mean(e.column, columns)}")
        bad = ~np.isfinite(columns[e.column])
        if bad.any():
            i = int(np.argmax(bad))
            raise ValidationError(f"{path.name}: column {e.column!r}: {columns[e.column][i]} at time {time[i]:g} "
                                  "is not a finite number")
        if in_degrees and e.unit == "rad":
            raise ValidationError(f"{path.name}: column {e.column!r}: the map says rad but the file's header says "
                                  "inDegrees=yes; give unit: deg")
    mode, rule = _time_mode(time, time_mode)
    percent = time.astype(float) if mode == "percent" else cycle_percent(time, cycle)
    keep = (percent >= 0.0) & (percent <= 100.0)
    if not keep.any():
        where = (f"times {time[0]:g}..{time[-1]:g} s are outside the cycle {cycle[0]:g}–{cycle[1]:g} s"
                 if mode == "seconds" else f"times {time[0]:g}..{time[-1]:g} % are outside 0–100 %")
        raise ValidationError(f"{path.name}: no sample within the gait cycle: {where} (time read as {mode}; "
                              "--reference-time percent|seconds to choose)")
    cols = {e.column: columns[e.column][keep] for e in entries}
    return Reference(path, percent[keep], cols, mode, in_degrees), rule


def _run_columns(results, coordinates):
    """{name: (column values (nf,), kind or None, file)} of every model quantity the run
    folder holds, in the order of precedence (coordinates.csv, FDK DOFs, measures.csv)."""
    out = {}

    def add(name, values, kind, source):
        out.setdefault(name, (np.asarray(values, dtype=float), kind, source))

    if coordinates is not None:
        for c in coordinates.columns:
            base, _, suffix = c.rpartition("_")
            if base and suffix in ("m", "rad"):
                add(base, coordinates[c].to_numpy(), _SUFFIX_KIND[suffix], COORDINATES_CSV)
    if results.forces is not None:
        for dof in results.fdk_dofs():
            add(dof, results.forces[f"fdk.{dof}.alpha"].to_numpy(), None, "forces.csv")
    if results.measures is not None:
        for c in results.measures.columns:
            base, _, suffix = c.rpartition("_")
            if base and suffix in _SUFFIX_KIND:
                add(base, results.measures[c].to_numpy(), _SUFFIX_KIND[suffix], "measures.csv")
    return out


def read_run_series(run_dir, entries, map_name="map"):
    """The model quantities that ``entries`` name, from the result folder ``run_dir``
    (:class:`RunSeries`); ``map_name`` names the map file in messages."""
    from ..io.yamlfile import did_you_mean
    from ..results.run import read_results

    d = Path(run_dir)
    if not d.is_dir():
        raise ValidationError(f"run folder {str(d)!r} does not exist")
    try:  # coordinates.csv checked against kinematics.csv's frames there
        results = read_results(d)
    except (ValueError, OSError) as exc:  # the results layer's one-line errors name the file
        raise ValidationError(" ".join(str(exc).split())) from None
    time = results.time.astype(float)
    available = _run_columns(results, results.coordinates)
    values, kinds, sources = {}, {}, {}
    for e in entries:
        if e.coordinate not in available:
            raise ValidationError(
                f"{map_name}: {e.column}.coordinate: {e.coordinate!r} is not in the run {d} (coordinates.csv, FDK "
                f"DOFs of forces.csv, measures.csv){did_you_mean(e.coordinate, available)}")
        v, kind, source = available[e.coordinate]
        if kind is not None and kind != e.kind:
            raise ValidationError(f"{map_name}: {e.column}: unit {e.unit} (a {e.kind}) but {e.coordinate!r} in "
                                  f"{source} is a{'n' if kind[0] in 'aeiou' else ''} {kind}")
        values[e.coordinate], kinds[e.coordinate], sources[e.coordinate] = v, kind, source
    converged = results.kinematics["converged"].to_numpy() == 1
    if results.forces is not None:
        converged &= results.forces["converged"].to_numpy() == 1
    return RunSeries(d, time, values, kinds, sources, converged)


# -- the comparison -------------------------------------------------------------------

def agreement(model, reference) -> dict:
    """Agreement of ``model`` and ``reference`` (k,) (same unit): ``n``; ``mean_offset``
    = mean(model − reference); ``rmsd`` = sqrt(mean((model − reference)²));
    ``rmsd_offset_removed`` = sqrt(mean((d − mean d)²)); ``r2`` = squared Pearson
    correlation (NaN when either is constant or k < 2); ``reference_range``,
    ``model_range`` = max − min. NaN everywhere when k = 0."""
    m, r = np.asarray(model, dtype=float), np.asarray(reference, dtype=float)
    n = int(m.size)
    if n == 0:
        return {"n": 0, **{k: math.nan for k in ("mean_offset", "rmsd", "rmsd_offset_removed", "r2",
                                                  "reference_range", "model_range")}}
    d = m - r
    offset = float(np.mean(d))
    # r² on the series divided by their largest magnitude (it does not change r², and
    # keeps the sums finite); a constant series (round-off aside) has no correlation
    scale = max(float(np.max(np.abs(m))), float(np.max(np.abs(r))))
    r2 = math.nan
    if n >= 2 and 0.0 < scale < math.inf:
        dm, dr = (m - m.mean()) / scale, (r - r.mean()) / scale
        smm, srr = float(dm @ dm), float(dr @ dr)
        if min(smm, srr) > 1e-24 * n:
            r2 = float((dm @ dr) ** 2 / (smm * srr))
    return {"n": n, "mean_offset": offset, "rmsd": float(np.sqrt(np.mean(d * d))),
            "rmsd_offset_removed": float(np.sqrt(np.mean((d - offset) ** 2))), "r2": r2,
            "reference_range": float(np.ptp(r)), "model_range": float(np.ptp(m))}


def interpolate_usable(x, values, usable, at):
    """Linear interpolation of ``values`` (nf,) given at increasing ``x`` (nf,) onto
    ``at`` (k,), only between two adjacent ``usable`` (nf,) bool samples (or at a usable
    sample itself). Returns (values (k,), ok (k,) bool); NaN where not ok."""
    x, v, at = np.asarray(x, float), np.asarray(values, float), np.asarray(at, float)
    ok_frame = np.asarray(usable, bool) & np.isfinite(v)
    out, ok = np.full(at.shape, np.nan), np.zeros(at.shape, bool)
    if x.size == 0:
        return out, ok
    if x.size == 1:
        hit = (at == x[0]) & ok_frame[0]
        out[hit], ok[hit] = v[0], True
        return out, ok
    j = np.clip(np.searchsorted(x, at, side="right") - 1, 0, x.size - 2)
    inside = (at >= x[0]) & (at <= x[-1])
    w = (at - x[j]) / (x[j + 1] - x[j])
    ok = inside & (((w > 0) & (w < 1) & ok_frame[j] & ok_frame[j + 1]) | ((w <= 0) & ok_frame[j])
                   | ((w >= 1) & ok_frame[j + 1]))
    vj, vk = np.where(ok_frame[j], v[j], 0.0), np.where(ok_frame[j + 1], v[j + 1], 0.0)
    out[ok] = np.where(w[ok] <= 0, vj[ok], np.where(w[ok] >= 1, vk[ok], (1 - w[ok]) * vj[ok] + w[ok] * vk[ok]))
    return out, ok


def compare(run: RunSeries, reference: Reference, entries, cycle, toe_off=None, time_mode_rule=""):
    """Compare the run with the reference per map entry (module docstring, step 5).
    Returns a :class:`ValidationResult`."""
    t0, t1 = check_cycle(cycle, toe_off)
    if run.time.size < 2:
        raise ValidationError(f"{run.directory}: {run.time.size} frame(s); the comparison needs at least 2")
    run_pct = cycle_percent(run.time, (t0, t1))
    usable_any = run.converged.copy()
    if not usable_any.any():
        raise ValidationError(f"{run.directory}: no frame of the run converged; nothing to compare")
    first, last = run_pct[usable_any][[0, -1]]
    covered = (max(0.0, float(first)), min(100.0, float(last)))
    if covered[0] > covered[1]:
        raise ValidationError(
            f"{run.directory}: the run's converged frames (t = {run.time[usable_any][0]:g}–"
            f"{run.time[usable_any][-1]:g} s) lie outside the cycle {t0:g}–{t1:g} s")
    in_range = (reference.percent >= covered[0]) & (reference.percent <= covered[1])
    if not in_range.any():
        raise ValidationError(
            f"{reference.path.name}: no sample within the part of the cycle the run covers ({covered[0]:.1f}–"
            f"{covered[1]:.1f} %; reference samples at {reference.percent[0]:.3g}–{reference.percent[-1]:.3g} %)")
    dofs, notes = [], []
    for e in entries:
        factor, unit = e.display
        ref_all = factor * e.scale * UNITS[e.unit][1] * reference.columns[e.column]
        v = run.values[e.coordinate]
        model_at, ok = interpolate_usable(run_pct, v, run.converged, reference.percent)
        ok &= in_range
        curve = np.where(run.converged & np.isfinite(v), factor * v, np.nan)
        m, r = factor * model_at[ok], ref_all[ok]
        stats = agreement(m, r)
        if stats["n"] == 0:
            notes.append(f"{e.column}: no usable frame of {e.coordinate!r} at the reference's samples")
        dofs.append(DofComparison(e, unit, reference.percent[ok], m, r, reference.percent, ref_all, run_pct, curve,
                                  stats))
    return ValidationResult(dofs, (t0, t1), toe_off, covered, run.directory, reference.path, reference.time_mode,
                            time_mode_rule, notes)


#: phase shifts searched by :func:`phase_shift`: ±MAX_SHIFT % of the cycle in SHIFT_STEP steps
MAX_SHIFT, SHIFT_STEP = 25.0, 0.1


def shifted(reference: Reference, shift) -> Reference:
    """The reference with its cycle phase moved by ``shift`` % (periodic): the sample
    measured at p % is compared with the model at (p − shift) mod 100 %."""
    percent = np.mod(reference.percent - shift, 100.0)
    order = np.argsort(percent, kind="stable")
    return Reference(reference.path, percent[order], {k: v[order] for k, v in reference.columns.items()},
                     reference.time_mode, reference.in_degrees)


def phase_shift(run: RunSeries, reference: Reference, entry, cycle):
    """The shift (%, :func:`shifted`) within ±MAX_SHIFT that maximises r² between the
    model and the reference in ``entry`` (a map entry, best a DOF the model does not
    compute itself, e.g. the tracked flexion): for references whose cycle is not timed
    as the run's (another session, another definition of 0 %). Returns (shift, r²)."""
    run_pct = cycle_percent(run.time, cycle)
    best = (0.0, -1.0)
    for shift in np.arange(-MAX_SHIFT, MAX_SHIFT + 0.5 * SHIFT_STEP, SHIFT_STEP):
        ref = shifted(reference, shift)
        m, ok = interpolate_usable(run_pct, run.values[entry.coordinate], run.converged, ref.percent)
        r2 = agreement(m[ok], ref.columns[entry.column][ok])["r2"] if ok.sum() >= 3 else math.nan
        if r2 > best[1]:
            best = (float(shift), float(r2))
    return best


def validate_kinematics(run_dir, reference_path, map_path, cycle, toe_off=None, reference_time="auto",
                        align_by=None):
    """Read the map, the reference and the run, and compare them (module docstring);
    ``align_by`` (a reference column of the map): shift the reference's phase first
    (:func:`phase_shift`), noted in the result. Returns a :class:`ValidationResult`; bad
    input raises :class:`ValidationError`."""
    cycle = check_cycle(cycle, toe_off)
    entries = read_map(map_path)
    reference, rule = read_reference(reference_path, entries, cycle, reference_time, Path(map_path).name)
    run = read_run_series(run_dir, entries, Path(map_path).name)
    note = None
    if align_by is not None:
        from ..io.yamlfile import did_you_mean

        entry = next((e for e in entries if e.column == align_by), None)
        if entry is None:
            raise ValidationError(f"--align-by: {align_by!r} is not a column of {Path(map_path).name}"
                                  f"{did_you_mean(align_by, [e.column for e in entries])}")
        shift, r2 = phase_shift(run, reference, entry, cycle)
        if not r2 >= 0.0:
            raise ValidationError(f"--align-by {align_by}: no phase shift within ±{MAX_SHIFT:g} % leaves 3 "
                                  "samples to correlate")
        reference = shifted(reference, shift)
        note = (f"the reference's phase is shifted by {shift:+.1f} % of the cycle (the shift within "
                f"±{MAX_SHIFT:g} % that maximises r² of {align_by}, r² = {r2:.3f}): a sample measured at p % is "
                f"compared with the model at p {'−' if shift >= 0 else '+'} {abs(shift):.1f} %")
    result = compare(run, reference, entries, cycle, toe_off, rule)
    if note:
        result.shift, result.alignment = shift, note
    return result


# -- tables ---------------------------------------------------------------------------

#: (key, header) of the validation table's columns
COLUMNS = (("dof", "DOF"), ("reference_column", "reference column"), ("coordinate", "model coordinate"),
           ("scale", "scale"), ("unit", "unit"), ("n", "n"), ("cycle_from_pct", "from %"),
           ("cycle_to_pct", "to %"), ("mean_offset", "mean offset"), ("rmsd", "RMSD"),
           ("rmsd_offset_removed", "RMSD offset removed"), ("r2", "r²"), ("reference_range", "reference range"),
           ("model_range", "model range"))


def table_rows(result: ValidationResult) -> list:
    """One dict per DOF with the keys of :data:`COLUMNS` (offsets, RMSDs and ranges in
    the DOF's ``unit``, mm or deg; offset = model − reference)."""
    rows = []
    for c in result.dofs:
        lo, hi = c.covered
        rows.append({"dof": c.entry.name, "reference_column": c.entry.column, "coordinate": c.entry.coordinate,
                     "scale": c.entry.scale, "unit": c.unit, "n": c.stats["n"], "cycle_from_pct": lo,
                     "cycle_to_pct": hi, **{k: c.stats[k] for k in ("mean_offset", "rmsd", "rmsd_offset_removed",
                                                                     "r2", "reference_range", "model_range")}})
    return rows


def _cell(value, digits=3):
    if isinstance(value, str):
        return value
    if isinstance(value, (int, np.integer)):
        return str(int(value))
    return "–" if not math.isfinite(value) else f"{value:.{digits}f}"


def _cells(row):
    return [row["dof"], row["reference_column"], row["coordinate"], f"{row['scale']:g}", row["unit"], _cell(row["n"]),
            _cell(row["cycle_from_pct"], 1), _cell(row["cycle_to_pct"], 1), _cell(row["mean_offset"], 2),
            _cell(row["rmsd"], 2), _cell(row["rmsd_offset_removed"], 2), _cell(row["r2"], 3),
            _cell(row["reference_range"], 2), _cell(row["model_range"], 2)]


def csv_text(result: ValidationResult) -> str:
    """validation.csv: one row per DOF, the keys of :data:`COLUMNS` as header, numbers
    with 10 significant digits (NaN as ``nan``)."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow([k for k, _ in COLUMNS])
    for row in table_rows(result):
        w.writerow([row[k] if isinstance(row[k], str) else (str(row[k]) if isinstance(row[k], int)
                    else f"{row[k]:.10g}") for k, _ in COLUMNS])
    return buf.getvalue()


def describe(result: ValidationResult) -> str:
    t0, t1 = result.cycle
    text = (f"Gait cycle {t0:g}–{t1:g} s (heel strike to heel strike); the run covers {result.covered[0]:.1f}–"
            f"{result.covered[1]:.1f} % of it; reference time read as {result.time_mode} ({result.time_mode_rule})")
    if result.toe_off is not None:
        text += f"; toe-off {result.toe_off:g} s = {result.toe_off_percent:.1f} %"
    if result.alignment:
        text += f"; {result.alignment}"
    return text + "."


def markdown_table(result: ValidationResult) -> str:
    """validation.md: the table of :func:`table_rows` in Markdown, with what was compared."""
    head = [h for _, h in COLUMNS]
    lines = [f"# Kinematics validation: `{result.run_dir}` against `{result.reference_path.name}`", "",
             describe(result) + " Offset = model − reference; RMSD offset removed = RMSD of (model − reference − "
             "mean offset); r² = squared Pearson correlation; lengths in mm, angles in degrees. A model value is "
             "interpolated linearly between two adjacent converged frames.", "",
             "| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    lines += ["| " + " | ".join(_cells(row)) + " |" for row in table_rows(result)]
    lines += [f"- {n}" for n in result.notes]
    return "\n".join(lines) + "\n"


def text_table(result: ValidationResult) -> str:
    """The short table printed by the command: DOF, unit, n, covered %, mean offset,
    RMSD, RMSD offset removed, r²."""
    keep = (0, 4, 5, 6, 7, 8, 9, 10, 11)
    head = ["DOF", "unit", "n", "from %", "to %", "offset", "RMSD", "RMSD-offset", "r²"]
    body = [[_cells(row)[i] for i in keep] for row in table_rows(result)]
    widths = [max(len(x) for x in col) for col in zip(head, *body)]
    fmt = lambda cells: "  ".join(c.ljust(w) if i == 0 else c.rjust(w)  # noqa: E731
                                  for i, (c, w) in enumerate(zip(cells, widths)))
    return "\n".join([fmt(head), *map(fmt, body)])


def write_validation(result: ValidationResult, out_dir, figure=None) -> list:
    """Write validation.csv, validation.md and, given a matplotlib ``figure`` (e.g.
    :func:`openfdk.plots.kinematics_validation.validation_figure`), validation.png into
    ``out_dir`` (created; a symbolic link at one of these names is refused, an earlier
    file replaced). Returns the paths written."""
    from ..io.outdir import png_bytes, write_files

    files = [("validation.csv", csv_text(result).encode("utf-8")),
             ("validation.md", markdown_table(result).encode("utf-8"))]
    if figure is not None:
        files.append(("validation.png", png_bytes(figure)))
    return write_files(out_dir, files, ValidationError)