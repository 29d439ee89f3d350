"""The mandible study end to end (DESIGN.md §2): registration, POP and FDK models,
every task, cycles, Tables 1–2, Figures 5–7 and the ligament parameter study.

Only public openfdk layers and ordinary model files are used, so a real subject folder
(CT-segmented STL files, landmarks, C3D recordings in ``trials/``) runs the same way:

    run_study("my_subject", "out")   # or: openfdk subject study my_subject --out out

Outputs in ``out``: ``models/pop.yaml``, ``models/fdk.yaml``, per task
``<task>/{pop,fdk}/{kinematics,forces}.csv``, ``table1.{csv,md}``, ``table2.{csv,md}``,
``figures/<task>_{kinematics,forces}.png``, ``parameter_study/`` (an openfdk.study
output folder: ``summary.csv``, ``cases/<case>/``), ``summary.json``.
"""

from __future__ import annotations

import time as _time
from pathlib import Path

import numpy as np

from ..io.results import write_forces, write_json, write_kinematics
from ..jobs import run_job
from .experiment import mandible_points_in_skull
from .extract import condyle_kinematics, fdk_forces, pop_forces
from .models import DEFAULT_STIFFNESS, DEFAULT_STRAIN, write_models
from .registration import register_braces
from .subject import load_subject

TASKS = ("chewing", "protrusion", "open_close")
REFERENCE_TRIAL = "reference"


class StudyError(ValueError):
    """The subject folder cannot be studied (e.g. a trial is missing); names the file."""


def _trial(subject_dir, name):
    p = Path(subject_dir) / "trials" / f"{name}.c3d"
    if not p.is_file():
        raise StudyError(f"subject folder {str(subject_dir)!r}: trial file trials/{name}.c3d is missing")
    return p


def analyse_task(subject, registration, models, task, out_dir, progress=False, n_cycles=None, margin=0.05):
    """POP and FDK on one task; returns time series (skull frame) and run summaries.

    With ``n_cycles``, only the first ``n_cycles`` complete cycles of the measured
    movement (± ``margin`` s) are analysed, as the paper extracted them."""
    trial = _trial(subject.directory, task)
    time, measured = mandible_points_in_skull(
        subject, trial, [subject.condyle_top("r"), subject.condyle_top("l"), subject.landmarks["incisal_point"]],
        registration)
    start = end = None
    if n_cycles is not None:
        from .cycles import split_cycles

        cycles = split_cycles(time, _opening_signal(measured[:, 2], subject.landmarks["incisal_point"]), n_cycles=n_cycles)
        start, end = time[cycles[0][0]] - margin, time[min(cycles[-1][1], len(time) - 1)] + margin
        keep = (time >= start - 1e-9) & (time <= end + 1e-9)
        time, measured = time[keep], measured[keep]
    # TMJ kinematics as displacements of the condyle tops from the reference (CT) pose
    ref = {"right": subject.condyle_top("r"), "left": subject.condyle_top("l")}
    series = {"time": np.asarray(time),
              "kinematics": {"measured": {"right": measured[:, 0] - ref["right"], "left": measured[:, 1] - ref["left"]}},
              "forces": {}, "incisor": measured[:, 2], "incisor_closed": subject.landmarks["incisal_point"]}
    runs = {}
    for kind in ("pop", "fdk"):
        t0 = _time.perf_counter()
        kin, dyn, info = run_job(models[kind], trial, progress=progress, start=start, end=end)
        if len(kin.time) != len(time):
            raise StudyError(f"{trial}: the analysis window has {len(kin.time)} frames, the markers {len(time)}")
        out = Path(out_dir) / task / kind
        write_kinematics(out, kin, {"input": info})
        write_forces(out, dyn)
        label = kind.upper()
        series["kinematics"][label] = {side: p - ref[side] for side, p in condyle_kinematics(kin, subject).items()}
        series["forces"][label] = (pop_forces if kind == "pop" else fdk_forces)(dyn, kin, subject)
        runs[label] = {"frames": int(len(kin.time)), "kinematics_converged": int(kin.converged.sum()),
                       "forces_converged": int(dyn.converged.sum()), "wall_time_s": _time.perf_counter() - t0}
        if "fdk" in info:
            runs[label]["fdk"] = {k: info["fdk"][k] for k in ("convergence_rate", "mean_residual_evaluations_per_frame",
                                                               "frames_per_second")}
        write_json(out / "summary.json", {"input": info, "kinematics": kin.summary(), "inverse_dynamics": dyn.summary(),
                                          **({"fdk": info["fdk"]} if "fdk" in info else {})})
    return series, runs


def _opening_signal(incisor, closed):
    """Incisal displacement (m) from its closed (reference-pose) position ``closed`` (3,):
    the signal whose minima separate the cycles of every task."""
    return np.linalg.norm(incisor - closed, axis=1)


def cycle_arrays(series, n_cycles, n_points=101):
    """Split on the measured incisal displacement from its closed position and normalise
    every signal to 0–100 % of each cycle: dict kinematics/forces model -> side ->
    (n_cycles, n_points, 3)."""
    from .cycles import normalize_cycles, split_cycles

    t = series["time"]
    cycles = split_cycles(t, _opening_signal(series["incisor"], series["incisor_closed"]), n_cycles=n_cycles)
    out = {"cycles": cycles}
    for group in ("kinematics", "forces"):
        out[group] = {model: {side: normalize_cycles(t, arr, cycles, n_points) for side, arr in sides.items()}
                      for model, sides in series[group].items()}
    return out


def run_study(subject_dir, out_dir, tasks=TASKS, n_cycles=5, quick=False, parameter_study=True, progress=True,
              log=print, workers=None, scheduler=None):
    """The whole study; returns a dict summary (also written to summary.json).

    The parameter study runs as an :mod:`openfdk.study` study in ``out/parameter_study``
    on a LocalCluster of ``workers`` processes (default one per CPU; 0 = in this
    process) or on the Dask scheduler at ``scheduler``; a rerun skips its complete cases."""
    from .figures import plot_forces, plot_kinematics
    from .tables import table1, table2, to_markdown, write_csv

    t_start = _time.perf_counter()
    out = Path(out_dir)
    subject = load_subject(subject_dir)
    registration = register_braces(subject, _trial(subject_dir, REFERENCE_TRIAL))
    models = write_models(subject, registration, out / "models")
    log(f"  registered the braces (skull fit RMS {registration['rms_m'] * 1e3:.3f} mm); models: {models['pop']}, {models['fdk']}")
    per_task, runs = {}, {}
    for task in tasks:
        log(f"  {task}: POP and FDK ...")
        series, task_runs = analyse_task(subject, registration, models, task, out, progress, n_cycles=n_cycles)
        per_task[task] = (series, cycle_arrays(series, n_cycles))
        runs[task] = task_runs
    bands = {}
    if parameter_study:
        from .parameter_study import parameter_bands, parameter_grid, run_parameter_study

        study_tasks = tasks if not quick else tasks[-1:]  # quick: the band on one task only
        n_models = int(np.prod([len(v) for v in parameter_grid(quick).values()]))
        log(f"  parameter study: {n_models} FDK models × {len(study_tasks)} task(s) -> {out / 'parameter_study'}/ ...")
        windows = {task: (_trial(subject_dir, task), per_task[task][0]["time"][0], per_task[task][0]["time"][-1])
                   for task in study_tasks}
        result = run_parameter_study(models["fdk"], windows, out / "parameter_study", quick=quick, workers=workers,
                                     scheduler=scheduler, progress=progress)
        for rec in result.failed:
            log(f"  parameter study case {rec['case_id']} failed: {rec.get('error', '')}")
        bands = parameter_bands(result, subject, {task: (per_task[task][0]["time"], per_task[task][1]["cycles"])
                                                  for task in study_tasks})
        runs["parameter_study"] = {
            "cases": len(result.records), "failed": [r["case_id"] for r in result.failed],
            "wall_time_s": result.wall_time, "execution": result.summary["execution"],
            "convergence_rate": {r["case_id"]: r.get("metrics", {}).get("convergence_rate") for r in result.records},
        }
    results = {task: {"kinematics": c["kinematics"], "forces": c["forces"]} for task, (_, c) in per_task.items()}
    rows1, rows2 = table1(results), table2(results)
    write_csv(rows1, out / "table1.csv")
    write_csv(rows2, out / "table2.csv")
    (out / "table1.md").write_text(to_markdown(rows1) + "\n")
    (out / "table2.md").write_text(to_markdown(rows2) + "\n")
    figures = []
    (out / "figures").mkdir(parents=True, exist_ok=True)
    for task, (_, c) in per_task.items():
        band = bands.get(task, {})
        figures.append(plot_kinematics(task, c["kinematics"], out / "figures" / f"{task}_kinematics.png",
                                       band=band.get("kinematics")))
        figures.append(plot_forces(task, c["forces"], out / "figures" / f"{task}_forces.png", band=band.get("forces")))
    summary = {
        "subject": str(subject_dir), "tasks": list(tasks), "cycles": n_cycles, "quick": quick,
        "registration_rms_mm": registration["rms_m"] * 1e3, "runs": runs,
        "figures": [str(f) for f in figures], "wall_time_s": _time.perf_counter() - t_start,
    }
    write_json(out / "summary.json", summary)
    return {"summary": summary, "table1": rows1, "table2": rows2, "figures": figures}


__all__ = ["run_study", "analyse_task", "cycle_arrays", "StudyError", "TASKS",
           "DEFAULT_STIFFNESS", "DEFAULT_STRAIN"]
