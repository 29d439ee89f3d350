"""End-to-end jobs behind the CLI: load inputs, run an analysis, return results.

These functions only use the public layers below them, so a user script can do the same.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .io.modelfile import load_model

DEFAULT_CUTOFF_HZ = 6.0


def load_trajectories(model, trial_path, cutoff_hz=None):
    """Read a C3D or TRC trial, pick the model's markers (by label, in model order) and build
    filtered, interpolated trajectories. A model marker absent from the file is an
    error naming it (MissingMarkerError)."""
    from .io.c3d import MarkerTrial
    from .io.markers import MarkerTrajectories
    from .io.trials import read_trial

    trial = trial_path if isinstance(trial_path, MarkerTrial) else read_trial(trial_path)
    if model.markers.size == 0:
        raise ValueError(f"model {model.name!r} has no markers; a trial cannot be tracked")
    trial = trial.select(list(model.markers.labels))
    if cutoff_hz is None:
        cutoff_hz = model.settings.kinematics.get("marker_cutoff_hz", DEFAULT_CUTOFF_HZ)
    cutoff = None if (cutoff_hz is None or float(cutoff_hz) <= 0) else float(cutoff_hz)
    return trial, MarkerTrajectories(trial, cutoff_hz=cutoff)


def _trial_label(trial):
    """The trial's file (its ``source``) for summary.json."""
    return str(Path(trial.source)) if trial.source != "<memory>" else trial.source


def analysis_window(model, times, start=None, end=None):
    """Sample times within [start, end] (defaults: model file ``analysis.start/end``)."""
    settings = model.settings.kinematics
    start = settings.get("start") if start is None else start
    end = settings.get("end") if end is None else end
    keep = np.ones(len(times), dtype=bool)
    if start is not None:
        keep &= times >= float(start) - 1e-9
    if end is not None:
        keep &= times <= float(end) + 1e-9
    if not keep.any():
        raise ValueError(f"no trial samples within the analysis window [{start}, {end}] s")
    return times[keep]


def kinematics_job(model_path, trial_path=None, cutoff_hz=None, progress=True, start=None, end=None, alpha=None):
    """Kinematics of a model file over a C3D trial (marker tracking), or over the model
    file's ``analysis`` interval (determinate) when ``trial_path`` is None.
    Returns (KinematicsResult, info dict for the summary)."""
    from .kinematics.analysis import run_determinate, run_tracking

    model = load_model(model_path) if not hasattr(model_path, "bodies") else model_path
    info = {"model": str(model_path) if not hasattr(model_path, "bodies") else model.name}
    traj, times, more = analysis_inputs(model, trial_path, cutoff_hz, start, end)
    info.update(more)
    if traj is None:
        return run_determinate(model, times, alpha=alpha, progress=progress), info
    return run_tracking(model, traj, times, alpha=alpha, progress=progress), info


def analysis_inputs(model, trial_path=None, cutoff_hz=None, start=None, end=None):
    """(trajectories or None, times (nf,) s, info): the trial's samples within the
    analysis window, or for determinate kinematics the model file's ``analysis``
    start/end/frames."""
    from .kinematics.analysis import analysis_times

    if trial_path is None:
        a = model.settings.kinematics
        t0 = float(a.get("start", 0.0) if start is None else start)
        t1 = float(a.get("end", 1.0) if end is None else end)
        return None, analysis_times(t0, t1, int(a.get("frames", 101))), {}
    trial, traj = load_trajectories(model, trial_path, cutoff_hz)
    times = analysis_window(model, np.asarray(trial.time, dtype=float), start, end)
    info = {"trial": _trial_label(trial), "rate_hz": trial.rate, "markers": list(trial.labels)}
    return traj, times, info


def run_job(model_path, trial_path=None, cutoff_hz=None, progress=True, start=None, end=None, checkpoints=None,
            resume=False):
    """Kinematics then inverse dynamics with muscle recruitment; when the model declares
    FDK DOFs, force-dependent kinematics (each frame's α found so that the FDK residual
    forces vanish). Returns (KinematicsResult, InverseDynamicsResult, info); for FDK,
    info["fdk"] holds the FDK summary. checkpoints, resume: see
    :func:`openfdk.analysis.run.run_trial` (Ctrl-C raises TrialInterrupted whose
    ``partial`` is (kin, dyn, info) of the finished frames)."""
    from .analysis.run import run_trial
    from .trial import TrialInterrupted

    model = load_model(model_path) if not hasattr(model_path, "bodies") else model_path
    label = str(model_path) if not hasattr(model_path, "bodies") else model.name
    traj, times, info = analysis_inputs(model, trial_path, cutoff_hz, start, end)
    info = {"model": label, **info}

    def with_info(kin, dyn, fdk):
        out = dict(info)
        if fdk is not None:
            out["fdk"] = fdk.summary()
        return kin, dyn, out

    try:
        kin, dyn, fdk = run_trial(model, traj, times, progress=progress, checkpoints=checkpoints, resume=resume)
    except TrialInterrupted as exc:
        exc.partial = with_info(*exc.partial)
        raise
    return with_info(kin, dyn, fdk)
