"""Force plates of a C3D trial as loads on the model's feet (model-file or overlay
section ``ground_reactions``), with each plate assigned to a body explicitly or, per
stance, automatically.

::

    ground_reactions:
      plates:                       # explicit: plate (name "plate1"… or number) -> body
        plate1: {body: calcn_r}
      feet:                         # automatic: for each stance of an unassigned plate, the
        calcn_r: [R_HEEL, R_MT1]    # foot whose markers are nearest the centre of pressure
        calcn_l: [L_HEEL, L_MT1]
      threshold_n: 20               # vertical force below which the plate is unloaded (N)
      cutoff_hz: 6                  # plate low-pass (default: the markers' cut-off)

A plate's reading (:func:`openfdk.io.force_plates.read_force_plates`: force on the
subject, centre of pressure and free moment, in the lab frame, at the marker rate) acts
on its body as a load expressed in the ground at the centre of pressure, with the free
moment as its torque (:mod:`openfdk.forces.data_loads`), exactly as OpenSim applies a
GRF ``ExternalForce``. Below the threshold the plate is unloaded: its load is zero.
Frames with non-finite analog data on a plate fail with that reason (the reaction is
unknown there, never taken as zero).

Automatic assignment, per stance (a run of loaded frames): the mean distance of each
foot's marker centroid to the centre of pressure over the stance; the nearest foot takes
the stance. When at more than 10 % of the stance's frames another foot is nearer, both
feet were on the plate: the stance is not assigned, and its frames fail with that
reason (never split between the feet). The choice of every stance is reported.
"""

from __future__ import annotations

import numpy as np

from ..model.errors import ModelError
from ..model.timefunctions import SplineThroughData

KEYS = ("plates", "feet", "threshold_n", "cutoff_hz")
BOTH_FEET_FRACTION = 0.10


def check_spec(spec, model, source):
    """Validate a ``ground_reactions`` mapping against the model (bodies, markers);
    returns it normalised: {plates: {name: body}, feet: {body: [marker labels]},
    threshold_n, cutoff_hz}."""
    where = f"{source}: ground_reactions"
    if not isinstance(spec, dict):
        raise ModelError(f"{where}: expected a mapping with keys {list(KEYS)}")
    bad = [k for k in spec if k not in KEYS]
    if bad:
        from .yamlfile import unknown_key

        raise ModelError(f"{where}.{bad[0]}: {unknown_key(bad[0], KEYS)}")
    bodies = {b.name for b in model.moving_bodies}
    labels = dict(zip(model.markers.names, model.markers.labels))
    plates = {}
    for name, entry in (spec.get("plates") or {}).items():
        body = entry.get("body") if isinstance(entry, dict) else None
        if body not in bodies:
            raise ModelError(f"{where}.plates.{name}.body: expected a moving body of the model, got {body!r}")
        plates[str(name)] = body
    feet = {}
    for body, markers in (spec.get("feet") or {}).items():
        if body not in bodies:
            raise ModelError(f"{where}.feet.{body}: not a moving body of the model")
        if not isinstance(markers, list) or not markers or not all(isinstance(m, str) for m in markers):
            raise ModelError(f"{where}.feet.{body}: expected a list of marker names")
        unknown = [m for m in markers if m not in labels and m not in labels.values()]
        if unknown:
            raise ModelError(f"{where}.feet.{body}: unknown markers {unknown}")
        feet[body] = [labels.get(m, m) for m in markers]
    out = {"plates": plates, "feet": feet}
    for key, default in (("threshold_n", 20.0), ("cutoff_hz", None)):
        value = spec.get(key, default)
        if value is not None and (isinstance(value, bool) or not isinstance(value, (int, float)) or value < 0):
            raise ModelError(f"{where}.{key}: expected a number >= 0, got {value!r}")
        out[key] = value
    if not plates and not feet:
        raise ModelError(f"{where}: give plates (plate -> body) or feet (body -> markers) to assign them")
    return out


def _plate_key(plate):
    number = plate.name[2:]          # FP<k>: a plate left out keeps the others' numbers
    return {plate.name, f"plate{number}", number}


def _stances(loaded):
    """[(first, last)] frame ranges of the runs of True in ``loaded`` (n,)."""
    out, start = [], None
    for i, on in enumerate(loaded):
        if on and start is None:
            start = i
        if not on and start is not None:
            out.append((start, i - 1))
            start = None
    if start is not None:
        out.append((start, len(loaded) - 1))
    return out


def plate_loads(model, trial_path, spec, marker_trial, default_cutoff_hz):
    """(loads, report, notes): DataLoads (one per plate and body) of the trial's plates,
    {plate: [{start_s, end_s, body or None, reason}]} of every stance, and {plate: [what
    the reading assumed or flagged]} (ForcePlateData.notes) for the plates with notes."""
    from ..forces.data_loads import DataLoad
    from .force_plates import read_force_plates

    cutoff = spec["cutoff_hz"] if spec["cutoff_hz"] is not None else default_cutoff_hz
    plates = read_force_plates(trial_path, threshold_n=spec["threshold_n"], cutoff_hz=cutoff or 0)
    if all(plate.never_loaded for plate in plates):
        import warnings

        what = (f"none of its {len(plates)} force plates is ever loaded above {spec['threshold_n']:g} N"
                if plates else "it has no force plates (FORCE_PLATFORM:USED is 0 or absent)")
        warnings.warn(f"{trial_path}: {what}; ground_reactions applies no load")
    index = {b.name: b.index for b in model.bodies}
    loads, report = [], {}
    notes = {plate.name: list(plate.notes) for plate in plates if plate.notes}
    for plate in plates:
        explicit = next((body for key, body in spec["plates"].items() if key in _plate_key(plate)), None)
        loaded = np.asarray(plate.loaded, bool) & np.all(np.isfinite(plate.force), axis=1)
        stances = _stances(loaded)
        owner = np.full(len(plate.time), None, dtype=object)
        entries = []
        for a, b in stances:
            body, reason = explicit, "assigned in ground_reactions.plates"
            if body is None:
                body, reason = _nearest_foot(spec["feet"], marker_trial, plate, a, b)
            owner[a : b + 1] = body
            entries.append({"start_s": float(plate.time[a]), "end_s": float(plate.time[b]), "body": body,
                            "reason": reason})
        report[plate.name] = entries
        if not stances:
            entries.append({"start_s": None, "end_s": None, "body": None, "reason": "never loaded"})
        invalid = tuple((e["start_s"], e["end_s"], f"force plate {plate.name}: {e['reason']}")
                        for e in entries if e["body"] is None and e["start_s"] is not None)
        # frames with NaN analog data: the ground reaction is unknown there, never taken as 0
        bad = np.asarray(plate.invalid, bool) | ~np.all(np.isfinite(plate.force), axis=1)
        invalid += tuple((float(plate.time[a]), float(plate.time[b]),
                          f"force plate {plate.name}: non-finite analog data") for a, b in _stances(bad))
        for body in sorted({o for o in owner if o is not None}):
            on = owner == body
            F = np.where(on[:, None], plate.force, 0.0)
            cop = np.where(on[:, None] & np.isfinite(plate.cop), plate.cop, 0.0)
            T = np.where(on[:, None] & np.isfinite(plate.free_moment), plate.free_moment, 0.0)
            loads.append(DataLoad(f"{plate.name}_{body}", index[body], SplineThroughData(plate.time, F),
                                  SplineThroughData(plate.time, cop), SplineThroughData(plate.time, T),
                                  "world", "world", np.zeros(3), np.eye(3), invalid))
        if invalid and not any(o is not None for o in owner):  # carry the reasons on a zero load
            some = next(b.index for b in model.moving_bodies)
            z = np.zeros((len(plate.time), 3))
            loads.append(DataLoad(f"{plate.name}_unassigned", some, SplineThroughData(plate.time, z),
                                  SplineThroughData(plate.time, z), SplineThroughData(plate.time, z),
                                  "world", "world", np.zeros(3), np.eye(3), invalid))
    return tuple(loads), report, notes


def _nearest_foot(feet, trial, plate, a, b):
    """(body or None, reason) of the stance [a, b] of ``plate`` (module docstring)."""
    if not feet:
        return None, "no body assigned (give ground_reactions.plates or feet)"
    times = plate.time[a : b + 1]
    cop = plate.cop[a : b + 1]
    names, dist = [], []
    for body, labels in feet.items():
        cols = [trial.labels.index(m) for m in labels if m in trial.labels]
        if not cols:
            continue
        P = trial.positions[:, cols, :]
        centroid = np.nanmean(P, axis=1)  # (n_frames, 3)
        c = np.column_stack([np.interp(times, trial.time, centroid[:, j]) for j in range(3)])
        names.append(body)
        dist.append(np.linalg.norm(c - cop, axis=1))
    if not names:
        return None, "none of the feet's markers is in the trial"
    D = np.array(dist)  # (n_feet, n)
    ok = np.all(np.isfinite(D), axis=0)
    if not ok.any():
        return None, "the feet's markers are not visible during the stance"
    mean = np.nanmean(np.where(ok, D, np.nan), axis=1)
    best = int(np.argmin(mean))
    other_nearer = np.mean(np.argmin(D[:, ok], axis=0) != best)
    if len(names) > 1 and other_nearer > BOTH_FEET_FRACTION:
        return None, (f"struck by both feet ({names[best]} nearest on average, another foot nearer at "
                      f"{100 * other_nearer:.0f} % of the stance's frames); not split between them")
    return names[best], f"nearest foot (mean distance of its markers to the centre of pressure {mean[best]:.3f} m)"


def write_grf(out_dir, trial_path, spec, report, times, default_cutoff_hz):
    """``grf.csv`` (and ``grf.sto``, numbers only) at the run's frame ``times`` (nf,) s:
    per plate the force on the subject (N), the centre of pressure (m), the free moment
    (N m), all in the lab frame, and the body the stance was assigned to ('' when
    unloaded or not assigned). Returns the path."""
    from pathlib import Path

    from .force_plates import read_force_plates
    from .results import write_table
    from .storage import write_storage

    cutoff = spec["cutoff_hz"] if spec["cutoff_hz"] is not None else default_cutoff_hz
    plates = read_force_plates(trial_path, threshold_n=spec["threshold_n"], cutoff_hz=cutoff or 0)
    times = np.asarray(times, float)
    cols = {"time": times}
    for plate in plates:
        idx = np.clip(np.searchsorted(plate.time, times - 1e-9), 0, len(plate.time) - 1)
        for label, arr in (("F", plate.force), ("cop", plate.cop), ("T", plate.free_moment)):
            unit = {"F": "N", "cop": "m", "T": "N_m"}[label]
            for j, c in enumerate("xyz"):
                cols[f"{plate.name}.{label}{c}_{unit}"] = arr[idx, j]
        body = np.full(len(times), "", dtype=object)
        for e in report.get(plate.name, []):
            if e["start_s"] is not None:
                body[(times >= e["start_s"] - 1e-9) & (times <= e["end_s"] + 1e-9)] = e["body"] or "unassigned"
        cols[f"{plate.name}.body"] = list(body)
    path = Path(out_dir) / "grf.csv"
    write_table(path, cols)
    write_storage(Path(out_dir) / "grf.sto", times, {k: np.asarray(v, float) for k, v in cols.items()
                                                      if k != "time" and not k.endswith(".body")}, name="ground reactions")
    return path


def grf_figure(grf_csv):
    """A matplotlib Figure of grf.csv: per plate the three force components and the
    centre of pressure's path in the lab's x-y plane."""
    from matplotlib.figure import Figure

    from .results import read_table

    data = read_table(grf_csv)
    plates = sorted({k.split(".")[0] for k in data if k != "time" and k.endswith("_N") and ".F" in k})
    fig = Figure(figsize=(11.0, 1.5 + 2.6 * max(1, len(plates))))
    axes = fig.subplots(max(1, len(plates)), 2, squeeze=False)
    t = np.asarray(data["time"], float)
    for row, name in zip(axes, plates):
        for c in "xyz":
            row[0].plot(t, data[f"{name}.F{c}_N"], label=f"F{c}")
        row[0].set_title(f"{name}: force on the subject (lab frame)", fontsize=9)
        row[0].set_xlabel("time (s)")
        row[0].set_ylabel("N")
        row[0].legend(fontsize=7)
        row[1].plot(data[f"{name}.copx_m"], data[f"{name}.copy_m"], ".-", ms=2)
        row[1].set_title(f"{name}: centre of pressure (lab x-y)", fontsize=9)
        row[1].set_xlabel("x (m)")
        row[1].set_ylabel("y (m)")
        row[1].set_aspect("equal", adjustable="datalim")
    fig.suptitle("Ground reactions (grf.csv)", fontsize=11)
    fig.set_layout_engine("constrained")
    return fig
