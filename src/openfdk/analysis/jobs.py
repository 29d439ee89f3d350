"""End-to-end jobs behind the CLI: load inputs, run an analysis, return results.

These functions only use the public layers below them, so a user script can do the same.
They take the model file's analysis settings (``settings``: an
:class:`~openfdk.model.settings.AnalysisSettings`, kept apart from the Model); a job
given a model file path reads them from the file.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..io.modelfile import load_model_and_settings
from ..model.settings import AnalysisSettings

DEFAULT_CUTOFF_HZ = 6.0


def model_and_settings(model, settings=None):
    """(Model, AnalysisSettings, label) of a model file path (its settings unless
    ``settings`` is given) or of a Model (``settings`` or the defaults)."""
    if hasattr(model, "bodies"):
        return model, settings or AnalysisSettings(), model.name
    loaded, file_settings = load_model_and_settings(model)
    return loaded, settings or file_settings, str(model)


def _refuse_redundant_rows(model, label):
    """``openfdk check``'s rank test before any frame (:func:`openfdk.analysis.model_check.refuse_redundant_rows`)."""
    from .model_check import refuse_redundant_rows

    refuse_redundant_rows(model, label)


def contact_mesh_checks(model, label):
    """``openfdk check``'s contact-mesh check before a run (:mod:`openfdk.contact.mesh_check`):
    a ModelError naming ``label`` (the model file), the contact and the mesh when a
    mesh is refused; else its warnings issued, and the checks' records for summary.json."""
    import warnings

    from ..contact.mesh_check import check_contacts
    from ..model.model import ModelError
    from ..model.plausibility import PlausibilityWarning

    checks = check_contacts(model)
    for chk in checks:
        if chk.errors:
            raise ModelError(f"{label}: {chk.errors[0]} (see `openfdk check`)")
    for chk in checks:
        for text in chk.warnings:
            warnings.warn(text, PlausibilityWarning, stacklevel=2)
    return [chk.as_dict() for chk in checks]


def load_trajectories(model, trial_path, cutoff_hz=None, settings=None):
    """Read a C3D or TRC trial, pick the model's markers (by label, in model order) and build
    filtered, interpolated trajectories (cut-off: ``cutoff_hz``, else the settings'
    ``analysis.marker_cutoff_hz``, else 6 Hz). A model marker absent from the file is an
    error naming it (MissingMarkerError), unless its weight is 0 (not tracked: OpenSim's
    IK tasks leave such markers out)."""
    from ..io.c3d import MarkerTrial
    from ..io.markers import MarkerTrajectories
    from ..io.trials import read_trial

    trial = trial_path if isinstance(trial_path, MarkerTrial) else read_trial(trial_path)
    if model.markers.size == 0:
        raise ValueError(f"model {model.name!r} has no markers; a trial cannot be tracked")
    untracked = [lab for lab, w in zip(model.markers.labels, model.markers.weight) if w == 0]
    from ..io.c3d import MissingMarkerError

    try:
        trial = trial.select(list(model.markers.labels), optional=untracked)
    except MissingMarkerError as exc:     # how to track a subset, as OpenSim's IK tasks do
        raise MissingMarkerError(f"{exc} (a model marker of weight 0 is not tracked and need not be in the "
                                 f"trial: give those weights, for an .osim with OpenSim's IK tasks, --ik-tasks "
                                 f"FILE)", exc.missing, exc.source, exc.available) from None
    if cutoff_hz is None:
        cutoff_hz = (settings or AnalysisSettings()).kinematics.get("marker_cutoff_hz", DEFAULT_CUTOFF_HZ)
    cutoff = None if (cutoff_hz is None or float(cutoff_hz) <= 0) else float(cutoff_hz)
    return trial, MarkerTrajectories(trial, cutoff_hz=cutoff)


def _trial_label(trial):
    """The trial's file (its ``source``) for summary.json."""
    return str(Path(trial.source)) if trial.source != "<memory>" else trial.source


def analysis_window(model, times, start=None, end=None, settings=None):
    """Sample times within [start, end] (defaults: the settings' ``analysis.start/end``,
    from the model file)."""
    window = (settings or AnalysisSettings()).kinematics
    start = window.get("start") if start is None else start
    end = window.get("end") if end is None else end
    _check_order(start, end)
    keep = np.ones(len(times), dtype=bool)
    if start is not None:
        keep &= times >= float(start) - 1e-9
    if end is not None:
        keep &= times <= float(end) + 1e-9
    if not keep.any():
        raise ValueError(f"no trial samples within the analysis window [{start}, {end}] s")
    return times[keep]


def _within_load_data(model, times, start=None, end=None, settings=None):
    """The trial's sample times (nf,) s, without those before or after the data of the
    model's measured loads (force-plate files usually start and end a sample off the
    markers'): the loads cannot be evaluated there, and the run would otherwise stop at
    its first such frame. Says so (one PlausibilityWarning) when it drops samples, and
    names the window's start or end (``start``, ``end`` s, or the settings') that lies
    outside the data."""
    from ..forces.data_loads import data_time_range
    from ..model.plausibility import warn_plausibility

    window = (settings or AnalysisSettings()).kinematics
    lo, hi = data_time_range(getattr(model, "external_loads", ()))
    keep = (times >= lo - 1e-9) & (times <= hi + 1e-9)
    if keep.all() or not keep.any():
        return times  # nothing to drop, or nothing left: analysis_window / the loads say why
    start = window.get("start") if start is None else start
    end = window.get("end") if end is None else end
    given = [f"the window's {name} ({float(t):g} s)" for name, t, out in
             (("start", start, start is not None and float(start) < lo - 1e-9),
              ("end", end, end is not None and float(end) > hi + 1e-9)) if out]
    where = f", where {' and '.join(given)} {'lies' if len(given) == 1 else 'lie'}," if given else ""
    warn_plausibility(f"analysis window {times[keep][0]:g}–{times[keep][-1]:g} s: the {np.count_nonzero(~keep)} "
                      f"trial sample(s) outside the measured loads' data ({lo:g}–{hi:g} s){where} are left out")
    return times[keep]


def _check_order(start, end):
    if start is not None and end is not None and float(start) > float(end):
        raise ValueError(f"analysis window: start ({float(start):g} s) is after end ({float(end):g} s); "
                         "give start <= end (--start/--end or the model file's analysis section)")


def determinate_times(model, start=None, end=None, settings=None):
    """Analysis times (nf,) s of a determinate run: [start, end] (defaults: the settings'
    ``analysis.start/end``, else 0 and 1 s) with ``analysis.frames`` frames (default 101),
    or every 1/``analysis.rate_hz`` s from the settings' start."""
    from ..kinematics.analysis import analysis_times

    a = (settings or AnalysisSettings()).kinematics
    t0 = float(a.get("start", 0.0) if start is None else start)
    t1 = float(a.get("end", 1.0) if end is None else end)
    _check_order(t0, t1)
    if "rate_hz" in a:  # frames on the grid start + k / rate_hz (a --motion file's samples)
        origin, rate = float(a.get("start", 0.0)), float(a["rate_hz"])
        k0, k1 = np.ceil((t0 - origin) * rate - 1e-6), np.floor((t1 - origin) * rate + 1e-6)
        if k1 < k0:
            raise ValueError(f"no frame of the {rate:g} Hz grid within [{t0:g}, {t1:g}] s")
        return origin + np.arange(int(k0), int(k1) + 1) / rate
    return analysis_times(t0, t1, int(a.get("frames", 101)))


def driver_time_range(model):
    """(first, last) s over which every sampled (spline, not extrapolated) driver of
    ``model`` has data (a motion file's coordinates), or (−inf, inf) when none is."""
    from ..model.timefunctions import sampled_time_range

    return sampled_time_range(getattr(c, "function", None) for c in model.constraints)


def _within_driver_and_load_data(model, times, loads=True):
    """The determinate frames ``times`` (nf,) s without those outside the data of the
    model's sampled drivers (a motion file's coordinates) and, with ``loads``, of its
    measured loads: they cannot be evaluated there, and the run would stop at the first
    such frame. Says so (one PlausibilityWarning) when it drops frames; ValueError when
    none is left."""
    from ..forces.data_loads import data_time_range
    from ..model.plausibility import warn_plausibility

    limits = [("drivers' samples (a motion file's coordinates: {:g}–{:g} s)", *driver_time_range(model))]
    if loads:
        limits.append(("measured loads' data ({:g}–{:g} s)", *data_time_range(getattr(model, "external_loads", ()))))
    keep = np.ones(len(times), dtype=bool)
    for _, lo, hi in limits:
        keep &= (times >= lo - 1e-9) & (times <= hi + 1e-9)
    if keep.all():
        return times
    what = " and the ".join(name.format(lo, hi) for name, lo, hi in limits
                            if np.any((times < lo - 1e-9) | (times > hi + 1e-9)))
    if not keep.any():
        raise ValueError(f"analysis window {times[0]:g}–{times[-1]:g} s: no frame within the {what}; give --start "
                         "and --end within it")
    warn_plausibility(f"analysis window {times[0]:g}–{times[-1]:g} s: the {np.count_nonzero(~keep)} frame(s) outside "
                      f"the {what} are left out")
    return times[keep]


def trial_window(model, trial_path, cutoff_hz=None, start=None, end=None, settings=None, loads=True):
    """The C3D trial, its filtered trajectories and the analysed times (nf,) s; warns
    (PlausibilityWarning) about markers never visible in the window or far from the
    model at its first frame. ``loads``: whether the run uses the model's measured loads
    (not ``openfdk kinematics``): its window is then kept within their data. Returns
    (trial, trajectories, times, info dict)."""
    from ..model.plausibility import check_trial_markers

    trial, traj = load_trajectories(model, trial_path, cutoff_hz, settings)
    all_times = np.asarray(trial.time, dtype=float)
    if loads:
        all_times = _within_load_data(model, all_times, start, end, settings)
    times = analysis_window(model, all_times, start, end, settings)
    check_trial_markers(model, trial, times)
    from .model_check import markers_move_nothing

    if markers_move_nothing(model):
        import warnings

        from ..model.plausibility import PlausibilityWarning

        warnings.warn(PlausibilityWarning(
            f"{trial.source}: the markers move nothing: the model's rows (its drivers, a motion file's) determine "
            "every coordinate; the run follows them, and the markers' residuals are only reported (run without the "
            "trial, or without the motion)"), stacklevel=2)
    return trial, traj, times, {"trial": _trial_label(trial), "rate_hz": trial.rate, "markers": list(trial.labels)}


def analysis_inputs(model, trial_path=None, cutoff_hz=None, start=None, end=None, settings=None, loads=True):
    """(trajectories or None, times (nf,) s, info): the trial's samples within the
    analysis window (:func:`trial_window`), or for determinate kinematics the model
    file's ``analysis`` start/end/frames (:func:`determinate_times`) within its drivers'
    data; settings : the model file's AnalysisSettings; loads : whether the run uses
    the model's measured loads (then the frames are kept within their data too). Once
    the inputs are read, a cold kernel cache is announced if the CLI asked for it
    (:func:`openfdk.analysis.kernel_cache.arm`)."""
    from .kernel_cache import announce_armed

    if trial_path is None:
        times = _within_driver_and_load_data(model, determinate_times(model, start, end, settings), loads)
        announce_armed()
        return None, times, {}
    _, traj, times, info = trial_window(model, trial_path, cutoff_hz, start, end, settings, loads)
    announce_armed()
    return traj, times, info


def _with_ground_reactions(model, settings, trial_path, traj, cutoff_hz, info):
    """The model with the trial's force plates as loads on its feet when the settings
    assign them (``ground_reactions``; :mod:`openfdk.io.ground_reactions`); the
    assignment of every stance goes to ``info["ground_reactions"]``, what the plates'
    reading assumed (sign convention, ORIGIN, units) to ``info["force_plate_notes"]``,
    and every measured load's body and the gravity (the ExternalLoads file's and the
    plates': :func:`~openfdk.forces.data_loads.load_record`) to ``info``: the one place
    every run (``run_job``, a study's case and its chunks) takes its loads from."""
    from ..forces.data_loads import load_record

    spec = getattr(settings, "ground_reactions", None)
    if not spec:
        info.update(load_record(model))
        return model
    if traj is None or not str(trial_path).lower().endswith(".c3d"):
        raise ValueError(f"ground_reactions: the force plates come from a C3D trial; {trial_path!r} is not one")
    from dataclasses import replace

    from ..io.ground_reactions import plate_loads

    if cutoff_hz is None:
        cutoff_hz = settings.kinematics.get("marker_cutoff_hz", DEFAULT_CUTOFF_HZ)
    loads, report, notes = plate_loads(model, trial_path, spec, traj.trial, cutoff_hz)
    info["ground_reactions"] = report
    if notes:
        info["force_plate_notes"] = notes
    model = replace(model, external_loads=tuple(model.external_loads) + loads)
    info.update(load_record(model))
    return model


def preflight(model, label, model_path):
    """The checks of a model before any frame, as ``openfdk check`` makes them (the
    serial and the chunked run alike): redundant equilibrium rows refused, contact
    meshes checked (warnings issued; a refused mesh is a ModelError naming ``label``).
    Returns their records for summary.json's ``input``: {opensim_import?, contact_meshes?}."""
    _refuse_redundant_rows(model, label)
    meshes = contact_mesh_checks(model, label)
    return {**import_record(model_path), **({"contact_meshes": meshes} if meshes else {})}


def import_record(model_path):
    """{"opensim_import": {dropped, merged_bodies, options?}} for a model read from an .osim
    (the elements left out with --ignore are listed in summary.json, and the options it
    was read with: :func:`openfdk.io.opensim.overlay.options_record`), for an overlay file
    the import of the .osim it names and its own ``--motion``, else {}."""
    from ..io.opensim import is_osim

    if not isinstance(model_path, (str, bytes)) and not hasattr(model_path, "__fspath__"):
        return {}
    from ..io.opensim.overlay import import_info, options_record, osim_of

    if not is_osim(model_path) and osim_of(model_path) is None:
        return {}
    options = options_record(model_path)  # an overlay's: --motion only (the rest are its own keys)
    return {"opensim_import": {**import_info(model_path), **({"options": options} if options else {})}}


def kinematics_job(model_path, trial_path=None, cutoff_hz=None, progress=True, start=None, end=None, alpha=None,
                   settings=None, loaded=None):
    """Kinematics of a model file (or Model) over a C3D trial (marker tracking), or over
    the model file's ``analysis`` interval (determinate) when ``trial_path`` is None;
    settings : AnalysisSettings (default: the file's, see :func:`model_and_settings`);
    loaded : that function's (Model, AnalysisSettings, label) of ``model_path`` when the
    caller has read it (``openfdk kinematics`` writes its measures with the same Model:
    the file and its measured loads are read, and warned about, once).
    Returns (KinematicsResult, info dict for the summary)."""
    from ..kinematics.analysis import run_determinate, run_tracking
    from ..model.plausibility import warn_held_fdk_loops, warn_outlier_markers

    model, settings, label = loaded if loaded is not None else model_and_settings(model_path, settings)
    _refuse_redundant_rows(model, label)
    if alpha is None:  # the FDK DOFs held at their initial values
        warn_held_fdk_loops(model, label)
    info = {"model": label, **import_record(model_path)}
    # (kinematics use no loads: a trial's window is not cut to another trial's load data)
    traj, times, more = analysis_inputs(model, trial_path, cutoff_hz, start, end, settings, loads=False)
    info.update(more)
    model = _with_ground_reactions(model, settings, trial_path, traj, cutoff_hz, info)
    if traj is None:
        return run_determinate(model, times, alpha=alpha, progress=progress), info
    kin = run_tracking(model, traj, times, alpha=alpha, progress=progress)
    warn_outlier_markers(kin)
    return kin, info


def run_job(model_path, trial_path=None, cutoff_hz=None, progress=True, start=None, end=None, checkpoints=None,
            resume=False, settings=None, loaded=None, rim_check=True):
    """Kinematics then inverse dynamics with muscle recruitment; when the model declares
    FDK DOFs, force-dependent kinematics (each frame's α found so that the FDK residual
    forces vanish). Returns (KinematicsResult, InverseDynamicsResult, info); for FDK,
    info["fdk"] holds the FDK summary. checkpoints, resume: see
    :func:`openfdk.analysis.run.run_trial` (Ctrl-C raises TrialInterrupted whose
    ``partial`` is (kin, dyn, info) of the finished frames). settings :
    AnalysisSettings (default: the model file's, see :func:`model_and_settings`);
    loaded : that function's (Model, AnalysisSettings, label) of ``model_path`` when the
    caller has already read it (``openfdk run`` writes its outputs with the same Model);
    rim_check : False leaves :func:`~openfdk.contact.rim.warn_contact_rims` to the caller
    (``openfdk run`` checks the rims while its figures are drawn)."""
    from .run import run_trial
    from ..contact.rim import warn_contact_rims
    from ..model.plausibility import warn_outlier_markers, warn_pulling_contacts
    from ..trial import TrialInterrupted

    model, settings, label = loaded if loaded is not None else model_and_settings(model_path, settings)
    checked = preflight(model, label, model_path)
    traj, times, info = analysis_inputs(model, trial_path, cutoff_hz, start, end, settings)
    info = {"model": label, **info, **checked}
    model = _with_ground_reactions(model, settings, trial_path, traj, cutoff_hz, info)

    def with_info(kin, dyn, fdk):
        out = dict(info)
        if fdk is not None:
            out["fdk"] = fdk.summary()
        return kin, dyn, out

    try:
        kin, dyn, fdk = run_trial(model, traj, times, settings=settings, progress=progress, checkpoints=checkpoints,
                                  resume=resume)
    except TrialInterrupted as exc:
        exc.partial = with_info(*exc.partial)
        raise
    warn_pulling_contacts(model, kin, dyn)
    if rim_check:
        warn_contact_rims(model, kin)
    warn_outlier_markers(kin)
    return with_info(kin, dyn, fdk)
