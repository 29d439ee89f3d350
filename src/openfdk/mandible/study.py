"""The mandible study end to end (docs/design.md §2), and its steps as a Python API.

Only public openfdk layers and ordinary model files are used, so a real subject folder
(CT-segmented STL files, landmarks, C3D recordings named in ``trials:``) runs the same
way:

    run_study("my_subject", "out")   # or: openfdk subject study my_subject --out out

The steps, each usable alone (docs/mandible-study.md, "Python API"):

* :func:`register_subject` — the brace registration the subject folder asks for
  (:mod:`.registration`);
* :func:`.models.write_models` — the POP and FDK model files;
* :func:`measured_series` — marker-only condyle and incisor positions over a whole trial;
* :func:`task_cycles` — the cycles of a task, found on the whole record;
* :func:`analyse_trial` — POP and FDK over a trial or a time window of it;
* :func:`analyse_task` — the cycles of a task, then POP and FDK over them;
* :func:`cycle_arrays` — every series normalised to 0–100 % of each cycle;
* :func:`study_tables`, :func:`write_tables`, :func:`write_figures` — Tables 1–2 and
  Figures 5–7.

Outputs of :func:`run_study` in ``out``: ``registration.yaml``, ``models/pop.yaml``,
``models/fdk.yaml``, per task ``<task>/{pop,fdk}/{kinematics,forces}.csv``,
``table1.{csv,md}``, ``table2.{csv,md}``, ``figures/<task>_{kinematics,forces}.png``,
``parameter_study/`` (an openfdk.study output folder), ``summary.json``.
"""

from __future__ import annotations

import math
import time as _time
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yaml

from ..io.c3d import MarkerTrial
from ..io.trials import read_trial
from ..io.markers import MarkerTrajectories
from ..io.results import write_forces, write_json, write_kinematics
from ..analysis.jobs import run_job
from .cycles import CycleError, find_cycles, normalize_cycles
from .experiment import mandible_points_in_skull
from .extract import SIDE_TAGS, compared_condyle_point, condyle_kinematics, fdk_forces, pop_forces
from .ml_jumps import continuation_check, ml_jumps
from .models import DEFAULT_STIFFNESS, DEFAULT_STRAIN, MARKER_CUTOFF_HZ, write_models
from .protocol import TrialSpec
from .registration import StaticPose, register
from .subject import load_subject

TASKS = ("chewing", "protrusion", "open_close")
CYCLE_MARGIN_S = 0.05


class StudyError(ValueError):
    """The subject folder cannot be studied (e.g. a trial is missing); names the file."""


class CycleWarning(UserWarning):
    """A task has fewer complete cycles than requested; those found are analysed."""


def _spec(subject, task) -> TrialSpec:
    """The TrialSpec of ``task`` (a name or a TrialSpec); StudyError naming the task."""
    if isinstance(task, TrialSpec):
        return task
    try:
        return subject.protocol.trial(task)
    except KeyError as exc:
        raise StudyError(str(exc).strip("'\"")) from None


def check_trials(subject, tasks=None):
    """Raise StudyError naming the task and the file of every missing trial of ``tasks``
    (default every task of the subject; the static trial only when the registration
    needs it or it was declared in ``trials:``)."""
    protocol = subject.protocol
    missing = protocol.missing_files(tasks)
    static = protocol.trials.get(protocol.static_trial) if protocol.static_trial else None
    if static is not None and not static.declared and protocol.registration_method == "braces":
        missing = [m for m in missing if f"task {static.task!r}" not in m]
    if missing:
        raise StudyError("; ".join(missing))


# --------------------------------------------------------------------------------------
# Registration
# --------------------------------------------------------------------------------------

def static_pose(subject) -> StaticPose | None:
    """The known static pose of the subject's ``registration.static_pose``, or None."""
    pose = subject.protocol.static_pose
    if pose is None:
        return None
    if "incisal_gap" in pose:
        return StaticPose.from_incisal_gap(subject, pose["incisal_gap"])
    if "rotation" in pose:      # x_S = R_SM x_M + p_SM, as registration.yaml reports it
        t_mm = ", ".join(f"{1e3 * v:.4g}" for v in pose["translation"])
        return StaticPose(np.array(pose["rotation"]), np.array(pose["translation"]),
                          f"rotation R_SM and translation p_SM [{t_mm}] mm")
    return StaticPose.from_opening(subject, np.rad2deg(pose["opening"]), pose["translation"])


def register_subject(subject, method: str | None = None, pose: StaticPose | None = None):
    """The brace registration of a subject (:mod:`.registration`).

    Args: subject (Subject); method: "braces" or "static_trial" (default the subject's
    ``registration.method``); pose: the mandible's static pose for "static_trial"
    (default the subject's ``registration.static_pose``; None = occlusion, stated).
    The static trial (``registration.static_trial``) checks the braces when its file
    exists. Returns a :class:`~.registration.Registration`."""
    protocol = subject.protocol
    method = method or protocol.registration_method
    static = protocol.trials.get(protocol.static_trial) if protocol.static_trial else None
    path = static.file if static is not None and static.file.is_file() else None
    if method == "static_trial":
        if path is None:
            raise StudyError(f"{protocol.file}: the static_trial registration needs the static trial "
                             f"{static.relative if static else '(none declared)'}, which is missing")
        return register(subject, path, "static_trial", pose if pose is not None else static_pose(subject))
    return register(subject, path, "braces", max_incisal_gap=protocol.max_incisal_gap)


# --------------------------------------------------------------------------------------
# One trial
# --------------------------------------------------------------------------------------

def measured_series(subject, registration, trial, cutoff_hz=MARKER_CUTOFF_HZ):
    """Marker-only estimate over a whole trial (the paper's "measured" kinematics).

    The brace markers are low-pass filtered as the models' marker tracking filters them
    (zero-lag 2nd-order Butterworth at ``cutoff_hz``, Hz; None = raw; gaps stay gaps,
    :class:`openfdk.io.markers.MarkerTrajectories`), then each brace is fitted rigidly.

    Args: subject; registration (:func:`register_subject`); trial: C3D (or TRC) path or
    MarkerTrial, read by :func:`openfdk.io.trials.read_trial` (its checks: a coordinate
    beyond 1 km is refused).
    Returns: time (n,) s, condyle points {side: (n, 3) m} (positions in the skull frame,
    NaN where a brace has < 3 markers) and the incisal point (n, 3) m."""
    trial = trial if isinstance(trial, MarkerTrial) else read_trial(trial)  # checked as every trial is
    labels = registration["skull"][0] + registration["mandible"][0]
    trial = trial.select(labels)
    if cutoff_hz is not None:
        filtered = MarkerTrajectories(trial, cutoff_hz).filtered_positions
        trial = MarkerTrial(trial.labels, trial.rate, trial.time, filtered, trial.source)
    tags = list(SIDE_TAGS.values())
    points = [compared_condyle_point(subject, tag) for tag in tags] + [subject.landmarks["incisal_point"]]
    time, p = mandible_points_in_skull(subject, trial, points, registration)
    return time, {side: p[:, k] for k, side in enumerate(SIDE_TAGS)}, p[:, -1]


#: share of a record's frames, those with the condyles nearest their reference
#: positions, whose median incisal point is the record's rest pose (:func:`rest_incisor`)
REST_SHARE = 0.10


def rest_incisor(subject, condyles, incisor, share=REST_SHARE):
    """The record's own rest incisal point (3,) m, in the skull frame.

    At rest the condyles sit in their fossae whatever the incisal opening (braces
    between the teeth hold the mouth a few degrees open, a rotation about the
    intercondylar axis that leaves the condyles in place), and every task moves them
    forward, down or sideways from there. So the rest frames are the ``share`` of the
    record's frames whose condyle points are nearest their reference positions (the
    mean of both sides' distances), and the rest incisal point is the median incisal
    point over them. A registration error shifts every frame alike and does not change
    which frames these are.

    Args: subject; condyles {side: (n, 3) m} and incisor (n, 3) m as
    :func:`measured_series` returns them (NaN where unmeasured).
    Returns (3,) m; the reference (CT) incisal point when no frame is measured."""
    ref = {side: compared_condyle_point(subject, tag) for side, tag in SIDE_TAGS.items()}
    shift = np.mean([np.linalg.norm(np.asarray(p) - ref[side], axis=1) for side, p in condyles.items()], axis=0)
    ok = np.isfinite(shift) & np.all(np.isfinite(incisor), axis=1)
    if not ok.any():
        return np.array(subject.landmarks["incisal_point"], dtype=float)
    limit = np.quantile(shift[ok], share)
    return np.median(np.asarray(incisor)[ok & (shift <= limit)], axis=0)


def opening_signal(subject, incisor, rest=None):
    """Incisal displacement (n,) m from the rest incisal point ``rest`` (3,) m
    (:func:`rest_incisor`; default the reference-pose (CT) incisal point), the signal
    whose minima separate the cycles of every task; incisor (n, 3) m."""
    rest = subject.landmarks["incisal_point"] if rest is None else np.asarray(rest, dtype=float)
    return np.linalg.norm(incisor - rest, axis=1)


@dataclass(frozen=True)
class TaskCycles:
    """Cycles of one task found on its whole record (or its ``window``).

    ``time`` (n,) s of the record; ``cycles`` (start, stop) indices into ``time``, the
    ones analysed; ``found`` complete cycles on the record; ``requested`` int or None
    (all); ``window`` (start, end) s analysed: the chosen cycles ± the margin;
    ``message``: a warning when fewer than requested were found, else "";
    ``rest_offset`` (3,) m: the record's rest incisal point (:func:`rest_incisor`, the
    point the cycle signal is measured from) minus the reference (CT) incisal point."""

    time: np.ndarray
    cycles: list
    found: int
    requested: int | None
    window: tuple
    message: str
    rest_offset: np.ndarray | None = None


def task_cycles(subject, registration, task, n_cycles=5, margin=CYCLE_MARGIN_S) -> TaskCycles:
    """Find the cycles of ``task`` (name or TrialSpec) on its whole record (within the
    task's ``window`` when given) and choose the first ``n_cycles`` (None or "all":
    every complete one; the task's ``cycles`` entry wins over ``n_cycles``). The cycle
    signal is the incisal displacement from the record's own rest pose
    (:func:`rest_incisor`), not from the CT's occlusion. Fewer than requested: those
    found are kept and ``message`` says so. Raises StudyError when none is found."""
    spec = _spec(subject, task)
    if not spec.file.is_file():
        raise StudyError(f"task {spec.task!r}: trial file {spec.relative} not found in {spec.file.parent}")
    requested = spec.cycles if spec.cycles is not None else n_cycles
    requested = None if requested in (None, "all") else int(requested)
    time, condyles, incisor = measured_series(subject, registration, spec.file)
    keep = np.ones(len(time), dtype=bool)
    if spec.window is not None:
        keep = (time >= spec.window[0] - 1e-9) & (time <= spec.window[1] + 1e-9)
    offset = int(np.argmax(keep))
    rest = rest_incisor(subject, {side: p[keep] for side, p in condyles.items()}, incisor[keep])
    try:
        split = find_cycles(time[keep], opening_signal(subject, incisor[keep], rest))
    except CycleError as exc:
        raise StudyError(f"task {spec.task!r} ({spec.relative}): {exc}") from None
    if not split.cycles:
        raise StudyError(f"task {spec.task!r} ({spec.relative}): {split.describe()}")
    chosen = split.cycles if requested is None else split.cycles[:requested]
    message = ""
    if requested is not None and len(chosen) < requested:
        message = (f"task {spec.task!r} ({spec.relative}): {len(chosen)} complete cycle(s) of the {requested} "
                   f"requested; analysing {len(chosen)} ({split.describe()})")
    cycles = [(a + offset, b + offset) for a, b in chosen]
    lo = max(time[cycles[0][0]] - margin, time[offset])
    hi = min(time[cycles[-1][1]] + margin, time[offset + int(keep.sum()) - 1])
    return TaskCycles(time, cycles, len(split.cycles), requested, (float(lo), float(hi)), message,
                      rest - subject.landmarks["incisal_point"])


def _task_warnings(caught, task, label):
    """Re-issue the warnings ``caught`` during one analysis, a contact's depth warning
    with the task and model named and the subject.yaml setting that raises the depth;
    returns the messages (for summary.json)."""
    from ..contact.limits import ContactDepthWarning

    messages = []
    for w in caught:
        message = str(w.message)
        if issubclass(w.category, ContactDepthWarning):
            message = (f"task {task!r}, {label} model: {message.split('; vertices deeper')[0]}; vertices deeper than "
                       "max_depth are ignored: raise it in subject.yaml, contact: {max_depth: MM} (length unit), "
                       "or run_study(contact_max_depth=m)")
        warnings.warn(message, w.category, stacklevel=3)
        messages.append(message)
    return messages


def _failed_frames(ok, time, opening):
    """Where a run failed: {"frames": n, "spans_s": [[t0, t1], ...] (consecutive failed
    frames), "incisal_opening_mm": [min, max] at them (None without failures)};
    ok (n,) bool, time (n,) s, opening (n,) m."""
    bad = ~np.asarray(ok, dtype=bool)
    if not bad.any():
        return {"frames": 0, "spans_s": [], "incisal_opening_mm": None}
    idx = np.flatnonzero(bad)
    breaks = np.flatnonzero(np.diff(idx) > 1)
    starts, stops = np.r_[idx[0], idx[breaks + 1]], np.r_[idx[breaks], idx[-1]]
    o = 1e3 * opening[bad]
    return {"frames": int(bad.sum()), "spans_s": [[round(float(time[a]), 4), round(float(time[b]), 4)]
                                                  for a, b in zip(starts, stops)],
            "incisal_opening_mm": [round(float(np.nanmin(o)), 2), round(float(np.nanmax(o)), 2)]}


def analyse_trial(subject, registration, models, trial, out_dir, *, start=None, end=None, progress=False,
                  task=None):
    """POP and FDK over a trial (whole, or ``start``…``end`` s).

    Args: models {"pop": path, "fdk": path} (:func:`.models.write_models`); trial C3D
    path; out_dir: ``{pop,fdk}/{kinematics,forces}.csv`` and ``summary.json`` are
    written there. Returns (series, runs): series = {"time" (n,) s, "kinematics":
    {"measured"|"POP"|"FDK": {side: (n, 3) m}} condyle-point displacements from the
    reference pose in the skull frame, "forces": {"POP"|"FDK": {side: (n, 3) N}},
    "incisor" (n, 3) m}; runs = per model frames, converged frames, feasible share,
    wall time, the FDK medio-lateral DOF's frame-to-frame jumps (``ml_jumps``:
    largest, when, how many, and the continuation check at the largest,
    :mod:`.ml_jumps`), the warnings issued (``warnings``; a contact-depth warning names
    ``task``, default the trial file's name, and the model) and where the run failed
    (``failed_frames``: count, time spans, incisal opening from the record's rest pose
    at those frames; never hidden: their forces are NaN in the series)."""
    time, measured, incisor = measured_series(subject, registration, trial)
    keep = np.ones(len(time), dtype=bool)
    if start is not None:
        keep &= time >= start - 1e-9
    if end is not None:
        keep &= time <= end + 1e-9
    ref = {side: compared_condyle_point(subject, tag) for side, tag in SIDE_TAGS.items()}
    rest = rest_incisor(subject, {side: p[keep] for side, p in measured.items()}, incisor[keep])
    opening = np.linalg.norm(incisor[keep] - rest, axis=1)
    series = {"time": time[keep], "incisor": incisor[keep], "forces": {},
              "kinematics": {"measured": {side: p[keep] - ref[side] for side, p in measured.items()}}}
    runs = {}
    for kind in ("pop", "fdk"):
        t0 = _time.perf_counter()
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            kin, dyn, info = run_job(models[kind], trial, progress=progress, start=start, end=end)
        issued = _task_warnings(caught, task or Path(trial).stem, kind.upper())
        if len(kin.time) != int(keep.sum()) or np.max(np.abs(kin.time - series["time"])) > 1e-6:
            raise StudyError(f"{trial}: the analysis window has {len(kin.time)} frames, the markers {int(keep.sum())}")
        out = Path(out_dir) / kind
        write_kinematics(out, kin, {"input": info})
        write_forces(out, dyn)
        label = kind.upper()
        series["kinematics"][label] = {side: p - ref[side] for side, p in condyle_kinematics(kin, subject).items()}
        forces = (pop_forces if kind == "pop" else fdk_forces)(dyn, kin, subject)
        # a failed frame's forces (the recruitment's closest, infeasible solution) are
        # not forces of the model: NaN in the series, so the tables and figures leave
        # them out; the frames are listed in failed_frames and forces.csv keeps them
        failed = ~np.asarray(dyn.converged, dtype=bool)
        series["forces"][label] = {side: np.where(failed[:, None], np.nan, F) for side, F in forces.items()}
        n = int(len(kin.time))
        runs[label] = {"frames": n, "kinematics_converged": int(kin.converged.sum()),
                       "forces_converged": int(dyn.converged.sum()),
                       "feasible_share": float(dyn.converged.sum()) / max(n, 1),
                       "wall_time_s": _time.perf_counter() - t0, "warnings": issued,
                       "failed_frames": _failed_frames(dyn.converged, series["time"], opening)}
        if "fdk" in info:
            runs[label]["fdk"] = {k: info["fdk"][k] for k in ("convergence_rate", "mean_residual_evaluations_per_frame",
                                                               "frames_per_second")}
            alpha_ml = dyn.extra["columns"].get("fdk.tmj_ml.alpha")
            if alpha_ml is not None:        # the medio-lateral DOF's jumps (issue 28, :mod:`.ml_jumps`)
                jumps = ml_jumps(kin.time, alpha_ml)
                jumps["continuation_check"] = continuation_check(models[kind], trial, kin.time, jumps.pop("frames"))
                runs[label]["ml_jumps"] = jumps
        write_json(out / "summary.json", {"input": info, "kinematics": kin.summary(), "inverse_dynamics": dyn.summary(),
                                          **({"fdk": info["fdk"]} if "fdk" in info else {})})
    return series, runs


def analyse_task(subject, registration, models, task, out_dir, progress=False, n_cycles=5,
                 margin=CYCLE_MARGIN_S, log=None):
    """The cycles of one task (:func:`task_cycles`), then POP and FDK over them.

    Args: task: a task name of the subject's ``trials`` or a TrialSpec; out_dir: the
    study folder (``<task>/{pop,fdk}/`` is written); n_cycles int, None or "all".
    Returns (series, runs, cycles): :func:`analyse_trial`'s series and runs, the
    :class:`TaskCycles` with ``cycles`` as index pairs into ``series["time"]``. A
    shortfall of cycles is warned (CycleWarning) and logged."""
    spec = _spec(subject, task)
    found = task_cycles(subject, registration, spec, n_cycles, margin)
    if found.message:
        warnings.warn(found.message, CycleWarning, stacklevel=2)
        if log is not None:
            log(f"  warning: {found.message}")
    series, runs = analyse_trial(subject, registration, models, spec.file, Path(out_dir) / spec.task,
                                 start=found.window[0], end=found.window[1], progress=progress, task=spec.task)
    if log is not None:
        for label in ("POP", "FDK"):
            for message in runs[label]["warnings"]:
                if message.startswith("task "):            # the contact-depth warning of this task
                    log(f"  warning: {message}")
            jumps = runs[label].get("ml_jumps")
            if jumps and jumps["count"]:
                checks = jumps["continuation_check"]
                second = [c for c in checks if c["second_root"]]
                verdict = (f"a second root at t = {', '.join(str(c['t_s']) for c in second)} s: continuing from the "
                           "previous frame converges elsewhere (summary.json ml_jumps.continuation_check)" if second
                           else f"continuation from the previous frame finds no second root at the {len(checks)} "
                                "largest (the branch ends there: the jumps are the model's)")
                log(f"  {spec.task}: FDK medio-lateral DOF: largest frame-to-frame jump {jumps['max_mm']:.2f} mm at "
                    f"t = {jumps['at_s']:g} s ({jumps['count']} jumps > {jumps['threshold_mm']:g} mm); {verdict}")
            failed = runs[label]["failed_frames"]
            if failed["frames"]:
                spans = ", ".join(f"{a:g}–{b:g}" for a, b in failed["spans_s"][:6])
                more = f" and {len(failed['spans_s']) - 6} more" if len(failed["spans_s"]) > 6 else ""
                lo, hi = failed["incisal_opening_mm"]
                log(f"  {spec.task}: {label} failed on {failed['frames']} of {runs[label]['frames']} frames "
                    f"(t = {spans}{more} s; incisal opening {lo:.1f}–{hi:.1f} mm from rest); their forces are "
                    f"left out of Table 2 and the figures, listed in summary.json "
                    f"(runs.{spec.task}.{label}.failed_frames)")
    first = int(np.argmin(np.abs(found.time - series["time"][0])))
    cycles = [(a - first, b - first) for a, b in found.cycles]
    found = TaskCycles(series["time"], cycles, found.found, found.requested, found.window, found.message,
                       found.rest_offset)
    return series, runs, found


def cycle_arrays(series, cycles, n_points=101):
    """Every signal of ``series`` normalised to 0–100 % of each cycle.

    Args: series from :func:`analyse_trial`; cycles: index pairs into series["time"]
    (e.g. :func:`analyse_task`'s ``cycles.cycles``, or :func:`.cycles.split_cycles` of
    :func:`opening_signal`). Returns {"cycles": cycles, "kinematics"/"forces": model ->
    side -> (n_cycles, n_points, 3)}."""
    t = series["time"]
    out = {"cycles": [tuple(c) for c in cycles]}
    for group in ("kinematics", "forces"):
        out[group] = {model: {side: normalize_cycles(t, arr, cycles, n_points) for side, arr in sides.items()}
                      for model, sides in series[group].items()}
    return out


# --------------------------------------------------------------------------------------
# Tables and figures
# --------------------------------------------------------------------------------------

def study_tables(per_task):
    """Table 1 and Table 2 rows from {task: cycle_arrays(...)} (:mod:`.tables`)."""
    from .tables import table1, table2

    results = {task: {"kinematics": c["kinematics"], "forces": c["forces"]} for task, c in per_task.items()}
    return table1(results), table2(results)


def write_tables(rows1, rows2, out_dir):
    """``table1.{csv,md}`` and ``table2.{csv,md}`` in out_dir; returns their paths."""
    from .tables import to_markdown, write_csv

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = [write_csv(rows1, out / "table1.csv"), write_csv(rows2, out / "table2.csv")]
    for name, rows in (("table1.md", rows1), ("table2.md", rows2)):
        (out / name).write_text(to_markdown(rows) + "\n")
        paths.append(str(out / name))
    return paths


def write_figures(per_task, out_dir, bands=None):
    """``figures/<task>_{kinematics,forces}.png`` from {task: cycle_arrays(...)} with the
    parameter-study ``bands`` {task: {"kinematics"/"forces": ...}}; returns the paths."""
    from .figures import plot_forces, plot_kinematics

    folder = Path(out_dir) / "figures"
    folder.mkdir(parents=True, exist_ok=True)
    figures = []
    for task, c in per_task.items():
        band = (bands or {}).get(task, {})
        figures.append(plot_kinematics(task, c["kinematics"], folder / f"{task}_kinematics.png",
                                       band=band.get("kinematics")))
        figures.append(plot_forces(task, c["forces"], folder / f"{task}_forces.png", band=band.get("forces")))
    return figures


# --------------------------------------------------------------------------------------
# The whole study
# --------------------------------------------------------------------------------------

def _parameter_study(subject, models, out, per_task, series, quick, workers, scheduler, progress, log):
    from .parameter_study import parameter_bands, parameter_grid, run_parameter_study

    tasks = list(per_task)
    study_tasks = tasks if not quick else tasks[-1:]  # quick: the band on one task only
    n_models = int(np.prod([len(v) for v in parameter_grid(quick).values()]))
    log(f"  parameter study: {n_models} FDK models × {len(study_tasks)} task(s) -> {out / 'parameter_study'}/ ...")
    windows = {task: (subject.protocol.trial(task).file, series[task]["time"][0], series[task]["time"][-1])
               for task in study_tasks}
    result = run_parameter_study(models["fdk"], windows, out / "parameter_study", quick=quick, workers=workers,
                                 scheduler=scheduler, progress=progress)
    for rec in result.failed:
        log(f"  parameter study case {rec['case_id']} failed: {rec.get('error', '')}")
    bands = parameter_bands(result, subject, {task: (series[task]["time"], per_task[task]["cycles"])
                                              for task in study_tasks})
    run = {"cases": len(result.records), "failed": [r["case_id"] for r in result.failed],
           "wall_time_s": result.wall_time, "execution": result.summary["execution"],
           "convergence_rate": {r["case_id"]: r.get("metrics", {}).get("convergence_rate") for r in result.records}}
    return bands, run


def run_study(subject_dir, out_dir, tasks=None, n_cycles=5, quick=False, parameter_study=True, progress=True,
              log=print, workers=None, scheduler=None, contact_max_depth=None):
    """The whole study; returns {"summary", "table1", "table2", "figures", "failed"}
    (the summary is also written to summary.json).

    Args: tasks: names of the subject's tasks (default all its movement tasks);
    n_cycles: cycles per task (int, None or "all"; a task's ``cycles`` entry wins).
    A task with fewer cycles is analysed on those (warned; n per task in the tables and
    summary.json). A task that fails is reported in ``summary.json["failed"]`` and the
    log, and the others' tables and figures are still written. The parameter study runs
    as an :mod:`openfdk.study` study in ``out/parameter_study`` on a LocalCluster of
    ``workers`` processes (default one per CPU; 0 = in this process) or on the Dask
    scheduler at ``scheduler``; a rerun skips its complete cases. ``contact_max_depth``
    (m): the FDK contacts' max_depth (default the subject's ``contact.max_depth``, else
    3 mm); a penetration within 10 % of it is warned with the task named."""
    t_start = _time.perf_counter()
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    subject = load_subject(subject_dir)
    tasks = tuple(tasks) if tasks is not None else subject.protocol.tasks
    for task in tasks:
        _spec(subject, task)
    check_trials(subject, tasks)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        registration = register_subject(subject)
    for w in caught:
        log(f"  warning: {w.message}")
    (out / "registration.yaml").write_text(yaml.safe_dump(registration.to_dict(), sort_keys=False, width=120))
    models = write_models(subject, registration, out / "models",
                          **({} if contact_max_depth is None else {"contact_max_depth": contact_max_depth}))
    rms = ", ".join(f"{body} {'-' if v is None else f'{1e3 * v:.3f} mm'}" for body, v in registration.rms_m.items())
    log(f"  registration: {registration.method} (fit RMS {rms}); models: {models['pop']}, {models['fdk']}")
    per_task, series, runs, failed, cycle_info = {}, {}, {}, {}, {}
    for task in tasks:
        log(f"  {task}: POP and FDK ...")
        try:
            with warnings.catch_warnings(record=True):      # logged by analyse_task, not repeated
                warnings.simplefilter("always")
                s, task_runs, cycles = analyse_task(subject, registration, models, task, out, progress,
                                                    n_cycles=n_cycles, log=log)
        except (ValueError, OSError) as exc:   # report the task, go on with the others
            failed[task] = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
            log(f"  {task} failed: {failed[task]}")
            continue
        series[task], runs[task] = s, task_runs
        per_task[task] = cycle_arrays(s, cycles.cycles)
        cycle_info[task] = {"analysed": len(cycles.cycles), "found": cycles.found, "requested": cycles.requested,
                            "window_s": list(cycles.window), "warning": cycles.message or None,
                            "rest_incisal_offset_mm": np.round(1e3 * cycles.rest_offset, 3).tolist()}
    seen = []                       # the models' other warnings (e.g. plausibility), once each
    for task_runs in runs.values():
        for label in ("POP", "FDK"):
            seen += [m for m in task_runs[label]["warnings"] if not m.startswith("task ") and m not in seen]
    for message in seen:
        log(f"  warning: {message}")
    bands = {}
    if parameter_study and per_task:
        bands, runs["parameter_study"] = _parameter_study(subject, models, out, per_task, series, quick, workers,
                                                          scheduler, progress, log)
    rows1 = rows2 = []
    figures = []
    if per_task:
        rows1, rows2 = study_tables(per_task)
        write_tables(rows1, rows2, out)
        figures = write_figures(per_task, out, bands)
    summary = {
        "subject": str(subject_dir), "tasks": list(tasks), "completed": list(per_task), "failed": failed,
        "task_kinds": {task: subject.protocol.trial(task).kind for task in tasks},
        "cycles": cycle_info, "n_cycles_requested": n_cycles, "quick": quick,
        "registration": registration.to_dict(),
        "registration_rms_mm": (registration.rms_m["skull"] or math.nan) * 1e3,
        "feasible_share": {task: {k: r[k]["feasible_share"] for k in ("POP", "FDK")} for task, r in runs.items()
                           if task in per_task},
        "fdk_ml_jump_max_mm": {task: r["FDK"].get("ml_jumps", {}).get("max_mm") for task, r in runs.items()
                               if task in per_task},
        "runs": runs, "figures": [str(f) for f in figures], "wall_time_s": _time.perf_counter() - t_start,
    }
    write_json(out / "summary.json", summary)
    return {"summary": summary, "table1": rows1, "table2": rows2, "figures": figures, "failed": failed}


__all__ = ["CycleWarning", "StudyError", "TASKS", "TaskCycles", "DEFAULT_STIFFNESS", "DEFAULT_STRAIN",
           "analyse_task", "analyse_trial", "check_trials", "cycle_arrays", "measured_series", "opening_signal",
           "register_subject", "rest_incisor", "run_study", "static_pose", "study_tables", "task_cycles", "write_figures",
           "write_tables"]
