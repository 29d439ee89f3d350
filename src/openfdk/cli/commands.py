"""The ``openfdk`` command line.

    openfdk kinematics MODEL.yaml TRIAL.c3d --out DIR   marker-tracking kinematics
    openfdk kinematics MODEL.yaml --out DIR             determinate kinematics (drivers)
    openfdk run MODEL.yaml [TRIAL.c3d] --out DIR        kinematics + inverse dynamics (+ .sto, figures)
    openfdk plot RESULT_DIR                             figures of a run
    openfdk export-opensim RESULT_DIR --out DIR         OpenSim .osim + .mot of a run
    openfdk check MODEL.yaml                            validate a model file
    openfdk import-opensim MODEL.osim --out DIR         an OpenSim model as an openfdk model file
    openfdk cache info|clear                            the distance-grid cache on disk
    openfdk view RESULT_DIR [--out view.html]           3D viewer of a run (one HTML file)
    openfdk validate-kinematics RUN_DIR REF.sto --map MAP.yaml --cycle T0 T1   a run against measured kinematics
    openfdk cycles RUN_DIR --foot calcn_r               contact forces, FDK DOFs over the gait cycles
    openfdk demo [--out DIR] [--quick]                  the mandible study on the virtual subject
    openfdk subject create|record DIR [--realistic]     virtual subject and experiment
    openfdk subject study DIR [--out OUT] [--cycles N|all]   the mandible study on a subject folder
    openfdk bench [--quick] [--json]                    benchmarks

Exit codes: 0 success (every frame converged, or at most ``--max-failed`` of them
failed); 2 bad input (a one-line reason on stderr naming the file and the entry);
3 the run completed but more frames failed than ``--max-failed`` (a one-line summary
on stderr with the most common failure reason); 130 interrupted (Ctrl-C); 141 the reader of
the printed output left (a closed pipe).
Warnings are one line each (``openfdk: warning: ...``); numpy's floating-point and
empty-slice warnings never reach the console.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import sys
import time
import warnings
from pathlib import Path
from collections import Counter

from . import argtypes
from .argtypes import _display_arguments

#: exit codes (README "Exit codes")
EXIT_OK, EXIT_BAD_INPUT, EXIT_FAILED_FRAMES, EXIT_INTERRUPTED = 0, 2, 3, 130
#: the reader of stdout left (a pipe closed): 128 + SIGPIPE, as a shell reports a tool killed by it
EXIT_BROKEN_PIPE = 141
DEFAULT_MAX_FAILED = 0.01


class UserError(Exception):
    """Bad input from the user: reported as one line, exit code 2."""


def _cmd_check(args):
    from ..io.modelfile import load_model
    from ..analysis.model_check import check_model

    _announce_kernels(args, check=True)  # armed: a model whose own kernels compile while it is read says so
    model = load_model(args.model)
    from ..analysis.kernel_cache import announce_armed

    announce_armed()  # the check's kernels (CHECK_KERNEL_MODULES) cold: the line now, once
    report = check_model(model)
    _say(args, "\n".join(report.lines))
    if not report.ok:
        # the model cannot run: one line per problem, the first one as the exit message
        for extra in report.errors[1:]:
            print(f"openfdk: error: {args.model}: {extra}", file=sys.stderr)
        raise UserError(f"{args.model}: {report.errors[0]}")
    return 0


def _cmd_import_opensim(args):
    from ..io.opensim.overlay import imported_model_data, import_info
    from ..io.opensim.write_yaml import write_imported
    from ..io.outdir import check_output_dir

    args.out = str(check_output_dir(args.out, force=args.force))
    data = imported_model_data(args.model)
    if data is None:
        raise UserError(f"{args.model}: not an OpenSim model (.osim)")
    from pathlib import Path

    from ..io.modelfile import model_and_settings_from_dict
    from ..io.yamlfile import read_yaml
    from ..model.model import ModelError
    from ..model.plausibility import check_model

    model, settings = model_and_settings_from_dict(data, source=Path(args.model).name)
    check_model(model, Path(args.model).name, settings.units["length"])  # errors name the .osim; nothing written yet
    path = write_imported(data, args.out, args.model, import_info(args.model), force=args.force)
    model = model_and_settings_from_dict(read_yaml(path, ModelError, "model file"), source=path.name,
                                         base_dir=path.parent)[0]  # the written file must read back
    dropped = import_info(args.model).get("dropped", [])
    _say(args, f"import-opensim: {len(model.moving_bodies)} bodies, {len(model.coordinates)} coordinates, "
               f"{model.markers.size} markers -> {path}"
               + (f" ({len(dropped)} elements left out, counted at the top of the file)" if dropped else ""))
    return 0


def _cmd_cache(args):
    from ..contact.grid_cache import clear_grid_cache, grid_cache_info

    folder, n, size = grid_cache_info()
    if folder is None:
        print("distance-grid cache: off (OPENFDK_CACHE_DIR=off)")
        return 0
    if args.action == "clear":
        clear_grid_cache(disk=True)
        print(f"distance-grid cache {folder}: removed {n} grid files ({size / 2**20:.1f} MB)")
        return 0
    print(f"distance-grid cache {folder}: {n} grid files, {size / 2**20:.1f} MB")
    return 0


def _announce_kernels(args, check=False, modules=None):
    """One line on stderr when numba's kernel cache is cold (first run after install or
    upgrade), unless --quiet, once the inputs are read and before the first kernel call:
    when ``check`` has read the model, or when the analysis has read the model and trial
    (:func:`openfdk.analysis.jobs.analysis_inputs`); and 2 s into a compilation while the
    model is read (a model's own kernels, :func:`~openfdk.analysis.kernel_cache.arm`). The progress displays then start after each
    stage's first (compiling) frame. ``modules``: the kernel modules the command calls
    (default: a frame's kinematics, equilibrium and recruitment)."""
    from ..analysis.kernel_cache import CHECK_KERNEL_MODULES, arm

    arm(quiet=getattr(args, "quiet", False), modules=CHECK_KERNEL_MODULES if check else modules)


def _rate(frames_per_second):
    """"N frames/s", saying so when the figure includes compiling numba's kernels (this
    command found their cache cold, see openfdk.analysis.kernel_cache)."""
    from ..trial.progress import warming_up

    rate = frames_per_second or 0.0
    text = f"{rate:.0f} frames/s" if rate >= 10 else f"{rate:.2g} frames/s"  # 0.25, not "0"
    return text + (", including the kernels' first compilation" if warming_up() else "")


def _say(args, text):
    """An informational line on stdout, unless --quiet."""
    if not getattr(args, "quiet", False):
        print(text)


def _log(args):
    """The log of a long command (demo, subject study): ``print``, or with --quiet only
    its warnings and failures, on stderr."""
    if not getattr(args, "quiet", False):
        return print

    def log(text=""):
        line = str(text).strip()
        if line.startswith("warning:"):
            print(f"openfdk: {line}", file=sys.stderr)
        elif " failed" in line:
            print(f"openfdk: {line}", file=sys.stderr)

    return log


def _check_window(args):
    if args.start is not None and args.end is not None and args.start > args.end:
        raise UserError(f"--start ({args.start:g} s) is after --end ({args.end:g} s)")


def _prepare_out(args):
    """Output folder checked before any computation (writable; results only with --force)."""
    from ..io.outdir import check_output_dir, refuse_inputs_inside

    refuse_inputs_inside(args.out, _input_files(args))  # first: --force clears the folder's results
    args.out = str(check_output_dir(args.out, force=args.force, resume=getattr(args, "resume", False)))


#: the command line's options that name an input file (argparse dest, option)
_FILE_OPTIONS = (("overlay", "--with"), ("ik_tasks", "--ik-tasks"), ("external_loads", "--external-loads"),
                 ("motion", "--motion"), ("actuators", "--actuators"), ("joint_reaction", "--joint-reaction"))


def _input_files(args):
    """(label, path) of the files a run reads: the model, the trial, the files the command
    line's options name, those the model file names (an overlay's keys), and the data
    file of each ExternalLoads file among them (its ``<datafile>``, relative to it)."""
    from ..io.fingerprint import referenced_files

    files = [("model", args.model)] + ([("trial", args.trial)] if getattr(args, "trial", None) else [])
    files += [(flag, getattr(args, dest)) for dest, flag in _FILE_OPTIONS if getattr(args, dest, None)]
    try:
        files += [(f"{Path(args.model).name}: {name}", path) for name, path in referenced_files(args.model)]
    except Exception:  # noqa: BLE001 -- an unreadable model file: its own one-line error comes when it is read
        pass
    for label, path in list(files):
        if str(path).lower().endswith(".xml") and Path(path).is_file():
            try:
                text = Path(path).read_text(encoding="utf-8", errors="replace")[:1_000_000]
            except OSError:
                continue
            files += [(f"{Path(path).name}: datafile", Path(path).parent / m.strip())
                      for m in re.findall(r"<datafile>([^<]*)</datafile>", text) if m.strip()]
    return files


def _read_trial_first(args):
    """Read the trial (if any) before the model is loaded: a bad file's one-line error
    comes at once and not after the model's set-up (DM: 80 s), and the analysis takes the
    same trial from :func:`openfdk.io.trials.read_trial`'s cache."""
    if getattr(args, "trial", None) is not None:
        from ..io.trials import read_trial

        read_trial(args.trial)


def _reason(status, message):
    """A failure reason without frame numbers and times, for counting."""
    text = re.sub(r"^frame \d+ \(t = [^)]*\):\s*", "", str(message or ""))
    text = re.sub(r"kinematics failed:\s*frame \d+ \(t = [^)]*\):\s*", "kinematics failed: ", text)
    text = re.sub(r"[-+]?\d+(\.\d+)?(e[-+]?\d+)?", "#", text)
    text = text.split(";")[0].strip()
    return f"{status}: {text}" if status and text else (status or text or "unknown")


def failed_frames_exit(converged, statuses, messages, max_failed, what="frames"):
    """Exit code of a completed run: 0 when the failed fraction of frames is at most
    ``max_failed``, else 3 with a one-line summary on stderr naming the most common
    failure reason and its count."""
    import numpy as np

    converged = np.asarray(converged, dtype=bool)
    n, failed = len(converged), np.flatnonzero(~converged)
    if n == 0 or len(failed) <= max_failed * n:
        return EXIT_OK
    reasons = Counter(_reason(statuses[i] if statuses is not None else "", messages[i]) for i in failed)
    reason, count = reasons.most_common(1)[0]
    print(f"openfdk: {len(failed)} of {n} {what} failed ({100 * len(failed) / n:.1f} % > --max-failed "
          f"{100 * max_failed:g} %); most common reason ({count} frames): {reason}", file=sys.stderr)
    return EXIT_FAILED_FRAMES


def _cmd_kinematics(args):
    from ..io.results import write_kinematics
    from ..analysis.jobs import kinematics_job

    _check_window(args)
    _prepare_out(args)
    _read_trial_first(args)
    from ..analysis.jobs import model_and_settings
    from ..analysis.kernel_cache import KINEMATICS_KERNEL_MODULES

    _announce_kernels(args, modules=KINEMATICS_KERNEL_MODULES)
    import warnings

    from ..model.plausibility import RawGroundReactionWarning

    with warnings.catch_warnings():
        # the model's measured loads are not applied in a kinematics pass (a first pass
        # with an overlay that names another trial's loads warned about those)
        warnings.simplefilter("ignore", RawGroundReactionWarning)
        loaded = model_and_settings(args.model)  # read once, for the run and its measures
    result, info = kinematics_job(
        args.model, args.trial, cutoff_hz=args.cutoff, progress=_progress_on(args),
        start=args.start, end=args.end, loaded=loaded,
    )
    write_kinematics(args.out, result, {"input": info})
    _write_measures(args.out, args.model, result, loaded[0])
    s = result.summary()
    _say(args, f"kinematics: {s['converged_frames']}/{s['frames']} frames converged in {s['wall_time_s']:.2f} s "
               f"({_rate(s['frames_per_second'])}) -> {args.out}/kinematics.csv")
    from .outputs import after_run

    after_run(args, plots=False)
    _print_failed(args, result.failed_frames())
    return failed_frames_exit(result.converged, None, result.messages, args.max_failed)


def _print_failed(args, failed):
    if getattr(args, "quiet", False):
        return
    for i, t, msg in failed[:10]:
        print(f"  failed: {msg}", file=sys.stderr)
    if len(failed) > 10:
        print(f"  ... and {len(failed) - 10} more failed frames (see summary.json)", file=sys.stderr)


def _write_measures(out_dir, model_path, kinematics, model=None):
    """measures.csv: the model's named measures (joint measures included) per frame;
    coordinates.csv and coordinates.mot: its joint coordinates (OpenSim models), and in
    summary.json's ``kinematics`` the clamped coordinates that rest on a bound
    (``coordinates_at_bounds``). ``model``: the Model of ``model_path`` if already loaded."""
    from pathlib import Path

    from ..io.coordinate_outputs import coordinates_at_bounds, write_coordinates
    from ..io.measure_outputs import write_measures
    from ..io.modelfile import load_model
    from ..io.results import write_json

    model = model if model is not None else load_model(model_path)
    write_measures(out_dir, model, kinematics)
    write_coordinates(out_dir, model, kinematics)
    at_bounds = coordinates_at_bounds(model, kinematics) if model.coordinates else {}
    path = Path(out_dir) / "summary.json"
    if at_bounds and path.is_file():
        data = json.loads(path.read_text())
        data.setdefault("kinematics", {})["coordinates_at_bounds"] = at_bounds
        write_json(path, data)


def _write_grf(args, info, dyn, settings=None):
    """grf.csv/.sto and plots/grf.png when the trial's force plates were applied
    (``settings``: the model file's AnalysisSettings if already loaded)."""
    if "ground_reactions" not in info:
        return
    from pathlib import Path

    from ..io.ground_reactions import grf_figure, write_grf
    from ..io.modelfile import load_settings
    from ..analysis.jobs import DEFAULT_CUTOFF_HZ

    settings = settings if settings is not None else load_settings(args.model)
    cutoff = args.cutoff if args.cutoff is not None else settings.kinematics.get("marker_cutoff_hz", DEFAULT_CUTOFF_HZ)
    path = write_grf(args.out, args.trial, settings.ground_reactions, info["ground_reactions"], dyn.time, cutoff)
    if not getattr(args, "no_plots", False):
        (Path(args.out) / "plots").mkdir(exist_ok=True)
        grf_figure(path).savefig(Path(args.out) / "plots" / "grf.png", dpi=110)


def _write_generalized_forces(out_dir, model_path, dyn, model=None):
    """generalized_forces.csv/.sto of a run whose coordinates are driven (--motion), and
    the residuals in summary.json (``model``: the Model of ``model_path`` if already
    loaded)."""
    from ..io.generalized_forces import write_generalized_forces
    from ..io.modelfile import load_model

    _add_to_summary(out_dir, "residuals",
                    write_generalized_forces(out_dir, model if model is not None else load_model(model_path), dyn))


def _write_moment_arms(out_dir, kin, model):
    """moment_arms.csv/.sto (``--moment-arms``: OpenSim's MuscleAnalysis moment arms) and
    their count in summary.json's ``moment_arms``."""
    import warnings

    from ..io.moment_arm_outputs import write_moment_arms
    from ..model.plausibility import PlausibilityWarning

    written = write_moment_arms(out_dir, model, kin)
    if written is None:
        what = ("muscles" if not model.muscles else "joint coordinates" if not model.coordinates
                else "converged frame where a muscle spans a coordinate")
        warnings.warn(f"--moment-arms: the model has no {what}: no moment_arms.csv written", PlausibilityWarning,
                      stacklevel=2)
    _add_to_summary(out_dir, "moment_arms", written)


def _add_to_summary(out_dir, key, value):
    """summary.json in ``out_dir`` with ``key``: ``value`` added (nothing when value is None)."""
    from pathlib import Path

    from ..io.results import write_json

    if value is None:
        return
    path = Path(out_dir) / "summary.json"
    data = json.loads(path.read_text())
    data[key] = value
    write_json(path, data)


def _write_joint_loads(out_dir, kin, dyn, model, settings):
    """joint_loads.csv/.sto (the load each joint transmits to its child body, as OpenSim's
    JointReaction reports it, and the reports of the settings' ``joint_reaction``) and
    their peaks in summary.json's ``joint_loads``."""
    from ..io.joint_load_outputs import write_joint_loads

    _add_to_summary(out_dir, "joint_loads", write_joint_loads(out_dir, model, kin, dyn, settings.joint_reaction))


def _rim_check(model, kin):
    """The run's contact-rim check (:func:`~openfdk.contact.rim.contact_rim_frames`, its
    warnings by :func:`~openfdk.contact.rim.report_contact_rims`) as a
    :class:`~openfdk.plots.parallel.SideJob` drawn with the figures, holding only the
    poses and times of ``kin``; None without frames."""
    from ..contact import rim
    from ..plots.parallel import SideJob

    if kin is None or len(kin.time) == 0:
        return None
    q, time = kin.q, kin.time
    return SideJob(lambda: rim.contact_rim_frames(model, q), lambda hits: rim.report_contact_rims(hits, time),
                   rim.WEIGHT_PER_FRAME * len(time) * len(getattr(model, "contacts", ())))


def _cmd_run(args):
    if args.checkpoint_frames < 1 or not args.checkpoint_seconds > 0:
        raise UserError("--checkpoint-frames must be >= 1 and --checkpoint-seconds > 0")
    unused = [o for o, v in (("--scheduler", args.scheduler), ("--workers", args.workers)) if v is not None]
    if args.chunks == 1 and unused:  # a serial run starts no cluster: the option would be ignored
        raise UserError(f"{' and '.join(unused)} {'is' if len(unused) == 1 else 'are'} used only with --chunks K >= 2")
    _check_window(args)
    _prepare_out(args)
    _read_trial_first(args)
    _announce_kernels(args)
    from ..analysis.jobs import model_and_settings

    loaded = model_and_settings(args.model)  # (Model, AnalysisSettings, label): read once, for the run and its outputs
    if args.chunks > 1:
        from ..study.cli import run_chunked_job

        kin, dyn, info = run_chunked_job(
            args.model, args.trial, args.chunks, args.out, cutoff_hz=args.cutoff, start=args.start,
            end=args.end, overlap=args.overlap, scheduler=args.scheduler, workers=args.workers,
            progress=_progress_on(args), checkpoints=_run_checkpoints(args, chunked=True), resume=args.resume,
            loaded=loaded, rim_check=False)
    else:
        from ..analysis.jobs import run_job
        from ..study.case import write_run_outputs
        from ..trial import TrialInterrupted

        checkpoints = _run_checkpoints(args)
        try:
            kin, dyn, info = run_job(args.model, args.trial, cutoff_hz=args.cutoff, progress=_progress_on(args),
                                     start=args.start, end=args.end, checkpoints=checkpoints, resume=args.resume,
                                     loaded=loaded, rim_check=False)
        except TrialInterrupted as exc:
            kin, dyn, info = exc.partial
            write_run_outputs(args.out, kin, dyn, info, frames_planned=exc.frames_planned)
            print(f"openfdk: interrupted: {len(kin.time)} of {exc.frames_planned} frames finished, written to "
                  f"{args.out} (marked partial in summary.json; continue with --resume)", file=sys.stderr)
            return 130
        write_run_outputs(args.out, kin, dyn, info)
        checkpoints.clear()
    model, settings, _ = loaded
    _write_measures(args.out, args.model, kin, model)
    _write_generalized_forces(args.out, args.model, dyn, model)
    _write_joint_loads(args.out, kin, dyn, model, settings)
    if args.moment_arms:
        _write_moment_arms(args.out, kin, model)
    _write_grf(args, info, dyn, settings)
    fdk = info.get("fdk")
    _say(args,
         f"run: kinematics {int(kin.converged.sum())}/{len(kin.time)} frames, inverse dynamics "
         f"{int(dyn.converged.sum())}/{len(dyn.time)} frames converged -> {args.out}/forces.csv"
         )
    if fdk is not None:
        _say(args,
             f"  FDK: {fdk['converged_frames']}/{fdk['frames']} frames converged, "
             f"{fdk['mean_residual_evaluations_per_frame']:.2f} residual evaluations per frame, "
             f"{_rate(fdk['frames_per_second'])} ({fdk['jacobian']} Jacobian)"
             + (f", {fdk['restarted_frames']} frame(s) restarted from another starting α"
                if fdk.get("restarted_frames") else "")
             + (f", {fdk['backward_frames']} failed frame(s) solved again backward from the next converged frame"
                if fdk.get("backward_frames") else "")
             )
    if len(info.get("segments", ())) > 1:
        later = info["segments"][1:]
        kept = ", ".join(f"{seg['keep_from_s']:.3f}" for seg in later)
        cold = ", ".join(f"{seg['cold_start_s']:.3f}" for seg in later)
        why = " (a cut moves into the stance of the limb the FDK DOFs hold, docs/studies.md)" if fdk else ""
        _say(args, f"  chunks: {len(info['segments'])} segments; the later ones kept from {kept} s, started cold "
                   f"at {cold} s{why}")
    from .outputs import after_run

    failed = dyn.failed_frames(), dyn.converged, dyn.status, dyn.messages
    # the contact rims are checked with the figures, in their workers (serial and chunked runs)
    rim_check = _rim_check(model, kin)
    del kin, dyn, info  # written: the figures read them back, so the arrays need not stay
    after_run(args, model=model, side=rim_check)
    _print_failed(args, failed[0])
    return failed_frames_exit(*failed[1:], args.max_failed)


def _progress_on(args):
    return not (getattr(args, "no_progress", False) or getattr(args, "quiet", False))


def _run_checkpoints(args, chunked=False):
    """Checkpoints of ``openfdk run`` in OUT/.checkpoint, fingerprinted by the contents of
    the model file, the meshes it refers to and the trial file, and the analysis options;
    ``chunked``: the finished segments of ``--chunks K`` (SegmentCheckpoints)."""
    from pathlib import Path

    from ..io.fingerprint import run_fingerprint
    from ..trial.checkpoint import CHECKPOINT_DIR, Checkpoints, SegmentCheckpoints

    options = (args.cutoff, args.start, args.end, _version())
    if chunked:
        fingerprint = run_fingerprint(args.model, args.trial, (*options, "chunks", args.chunks, args.overlap))
        return SegmentCheckpoints(Path(args.out) / CHECKPOINT_DIR, fingerprint)
    fingerprint = run_fingerprint(args.model, args.trial, options)
    return Checkpoints(Path(args.out) / CHECKPOINT_DIR, fingerprint, args.checkpoint_frames,
                       args.checkpoint_seconds)


def _version():
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("openfdk")
    except PackageNotFoundError:  # pragma: no cover - running from a source tree
        return "unknown"


def _cmd_demo(args):
    from pathlib import Path

    from ..io.outdir import check_output_dir
    from ..mandible.demo import run_demo

    # before any computation: the demo folder (subject reused) and its study results
    args.out = str(check_output_dir(args.out))
    check_output_dir(Path(args.out) / "study", force=args.force)
    _announce_kernels(args)
    result = run_demo(args.out, quick=args.quick, progress=_progress_on(args), workers=args.workers, log=_log(args))
    return _failed_tasks_exit(result, f"{args.out}/study")


def _failed_tasks_exit(result, out):
    """Exit code of a mandible study (``openfdk demo``, ``openfdk subject study``): 0, or 3
    when some task failed while the others completed (each named on stderr)."""
    for task, message in result["failed"].items():
        print(f"openfdk: error: task {task!r} failed: {message}", file=sys.stderr)
    if not result["failed"]:
        return EXIT_OK
    print(f"openfdk: {len(result['failed'])} task(s) failed (listed in {out}/summary.json); the other "
          "tasks' tables and figures are written", file=sys.stderr)
    return EXIT_FAILED_FRAMES  # completed with failures (README "Exit codes")


def _cycles_argument(value):
    """--cycles: a whole number ≥ 1 or 'all'."""
    if value == "all":
        return value
    try:
        n = int(value)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number or 'all', got {value!r}") from None
    if n < 1:
        raise argparse.ArgumentTypeError(f"expected a whole number ≥ 1 or 'all', got {value!r}")
    return n


def _cmd_subject(args):
    from ..mandible.experiment import record_experiment
    from ..mandible.generator import create_subject

    if args.action == "study":
        from ..mandible.demo import report
        from ..mandible.study import run_study

        from ..io.outdir import check_output_dir

        out = args.out or f"{args.directory.rstrip('/')}-study"
        out = str(check_output_dir(out, force=args.force))  # before any computation
        _announce_kernels(args)
        cycles = 5 if args.cycles is None else (None if args.cycles == "all" else args.cycles)
        result = run_study(args.directory, out, n_cycles=cycles, quick=args.quick, progress=_progress_on(args),
                           workers=args.workers, scheduler=args.scheduler,
                           parameter_study=not args.no_parameter_study, log=_log(args))
        if result["table1"]:
            report(result, out, _log(args))
        return _failed_tasks_exit(result, out)
    elif args.action == "create":
        path = create_subject(args.directory, resolution=args.resolution, symmetric=not args.asymmetric, seed=args.seed)
        _say(args, f"virtual subject written to {path}/ (subject.yaml and STL files); next: openfdk subject record {path}")
    elif args.realistic:
        from ..mandible.realistic import record_realistic

        if args.cycles is not None:
            raise UserError("openfdk subject record --realistic: --cycles is fixed by the realistic protocol "
                            "(docs/virtual-experiment.md); drop it")
        files = record_realistic(args.directory, quick=args.quick, noise_mm=args.noise, seed=args.seed)
        _say(args, f"realistic virtual experiment written: {', '.join(sorted(str(k) for k in files))}")
    else:
        if args.cycles == "all":
            raise UserError("openfdk subject record: --cycles must be a whole number")
        files = record_experiment(args.directory, cycles=5 if args.cycles is None else args.cycles,
                                  noise_mm=args.noise, seed=args.seed)
        _say(args, f"virtual experiment written: {', '.join(sorted(str(k) for k in files))}")
    return 0


def _cmd_bench(args):
    import importlib

    from ..bench import BENCHMARK_MODULES

    failures = 0
    short = [name.rsplit(".", 1)[-1] for name in BENCHMARK_MODULES]

    def selected(module):
        # a --only that names a module exactly selects that one; otherwise it is a substring
        return any(o == module if o in short else o in module for o in args.only)

    for name, module in zip(BENCHMARK_MODULES, short):
        if args.only and not selected(module):
            continue
        try:
            mod = importlib.import_module(name)
            t0 = time.perf_counter()
            records = mod.run(quick=args.quick)
        except Exception as exc:  # report and go on: one broken benchmark must not hide others
            failures += 1
            rec = {"name": name.rsplit(".", 1)[-1] + "_error", "value": None, "unit": "", "error": f"{type(exc).__name__}: {exc}"}
            print(json.dumps(rec) if args.json else f"{rec['name']}: {rec['error']}", flush=True)
            continue
        for rec in records:
            if args.json:
                print(json.dumps(rec), flush=True)
            else:
                print(f"{rec['name']:50s} {rec['value']:12.4g} {rec['unit']}", flush=True)
        if not args.json:
            print(f"  ({name} took {time.perf_counter() - t0:.1f} s)", file=sys.stderr)
    return 1 if failures else 0


def _trial_arguments(p):
    """Arguments shared by the commands that analyse a model over a trial."""
    p.add_argument("model", help="model file (YAML or OpenSim .osim)")
    p.add_argument("trial", nargs="?",
                   help="C3D or TRC file with the model's markers (omit for determinate kinematics)")
    p.add_argument("--out", required=True, help="output folder (checked for writability before any computation)")
    p.add_argument("--force", action="store_true", help="overwrite the results already in the --out folder")
    p.add_argument("--cutoff-hz", "--cutoff", dest="cutoff", type=argtypes.nonnegative, default=None, metavar="HZ",
                   help="marker low-pass cutoff in Hz, as the API's cutoff_hz (default: model file, else 6 Hz; "
                        "0 = no filter; --cutoff is the same option)")
    p.add_argument("--start", type=argtypes.finite, default=None, help="first analysed time (s)")
    p.add_argument("--end", type=argtypes.finite, default=None, help="last analysed time (s)")
    p.add_argument("--max-failed", type=argtypes.fraction, default=DEFAULT_MAX_FAILED, metavar="FRACTION",
                   help=f"largest fraction of failed frames that still exits with 0 (default {DEFAULT_MAX_FAILED}); "
                        "more failed frames exit with 3")
    _display_arguments(p)
    _import_arguments(p)


def _import_arguments(p):
    """--with, --ignore and --geometry: the options of a model read from an OpenSim .osim."""
    g = p.add_argument_group("OpenSim models (.osim, or an overlay naming one: all but --with, replacing its keys)")
    g.add_argument("--with", dest="overlay", default=None, metavar="OVERLAY.yaml",
                   help="overlay file adding drivers, FDK DOFs and analysis settings to the .osim (SI units)")
    g.add_argument("--ignore", action="append", default=[], metavar="TYPE",
                   help="leave out every element of this OpenSim type (e.g. Thelen2003Muscle, Mesh; 'forces' for the "
                        "ForceSet and wrap objects); repeatable; the dropped elements are listed in summary.json")
    g.add_argument("--geometry", action="append", default=[], metavar="DIR",
                   help="another folder to look for the model's mesh files in (repeatable)")
    g.add_argument("--ik-tasks", default=None, metavar="FILE",
                   help="OpenSim IK setup (Setup_IK.xml) or tasks file: its marker weights and coordinate tasks")
    g.add_argument("--external-loads", default=None, metavar="LOADS.xml",
                   help="OpenSim ExternalLoads file (ground reactions) with its data file, applied as OpenSim does")
    g.add_argument("--external-loads-cutoff", type=argtypes.nonnegative, default=None, metavar="HZ",
                   help="low-pass filter the --external-loads samples (a ground reaction as a wrench, on its loaded "
                        "runs), as the markers are (e.g. their 6 Hz); default: as given, as OpenSim applies them")
    g.add_argument("--motion", default=None, metavar="FILE.mot",
                   help="drive every coordinate from this coordinate file (an IK .mot): inverse dynamics then gives "
                        "each coordinate's generalised force (generalized_forces.csv), as OpenSim's ID; with FDK DOFs "
                        "(also on an overlay file) FDK solves them on the file's other coordinates: two stages")
    g.add_argument("--motion-cutoff", type=argtypes.nonnegative, default=None, metavar="HZ",
                   help="low-pass filter the --motion coordinates (OpenSim's lowpass_cutoff_frequency_for_coordinates)")
    g.add_argument("--actuators", default=None, metavar="ACTUATORS.xml",
                   help="OpenSim actuator file (reserve and residual CoordinateActuators): recruited beside the "
                        "muscles, weighted by their optimal force, as in OpenSim's static optimisation")
    g.add_argument("--joint-reaction", default=None, metavar="SETUP.xml",
                   help="OpenSim JointReaction setup (setup_JointReaction.xml): joint_loads.sto reports its joints on "
                        "its bodies (apply_on_bodies) in its frames (express_in_frame), as OpenSim's JointReaction")


def _register_import(args):
    """Register the OpenSim import options of ``args.model`` before anything reads it."""
    model = getattr(args, "model", None)
    if model is None or not hasattr(args, "overlay"):
        return
    from ..io.opensim import is_osim

    if not is_osim(model):
        from ..io.opensim.overlay import osim_of

        overlay = osim_of(model) is not None
        if args.overlay or (not overlay and (args.ignore or args.geometry or args.ik_tasks or args.external_loads
                                             or args.actuators or args.external_loads_cutoff or args.joint_reaction
                                             or args.motion)):
            raise UserError(f"{model}: --with, --ignore, --geometry, --ik-tasks, --external-loads, --motion, "
                            "--actuators and --joint-reaction apply to OpenSim models (.osim); an overlay "
                            "(opensim: MODEL.osim) takes all but --with, and they replace its keys; a model file "
                            "takes joint_reaction: SETUP.xml")
        if not overlay:
            if args.motion_cutoff:
                raise UserError("--motion-cutoff: filters the coordinates of --motion, which is not given")
            return
    from pathlib import Path

    for option, value in (("--with", args.overlay), ("--ik-tasks", args.ik_tasks),
                          ("--external-loads", args.external_loads), ("--motion", args.motion),
                          ("--actuators", args.actuators), ("--joint-reaction", args.joint_reaction)):
        if value is not None and not Path(value).is_file():
            raise UserError(f"{option}: {value!r} does not exist or is not a regular file")
    from ..io.opensim.overlay import register

    if is_osim(model):  # an overlay's own keys may give what the cutoffs filter
        if args.external_loads_cutoff and args.external_loads is None:
            raise UserError("--external-loads-cutoff: filters the loads of --external-loads, which is not given")
        if args.motion_cutoff and not args.motion:
            raise UserError("--motion-cutoff: filters the coordinates of --motion, which is not given")
    register(model, args.ignore, args.geometry, args.overlay, args.ik_tasks, args.external_loads, args.motion,
             args.motion_cutoff or None, args.actuators, args.external_loads_cutoff or None, args.joint_reaction)



def _version():
    try:
        from importlib.metadata import version

        return version("openfdk")
    except Exception:  # not installed as a distribution: the package's own number
        from .. import __version__

        return __version__


def _subject_parser(sub):
    """``openfdk subject create|record|study``: one subcommand each, so that each
    ``--help`` lists only its own options."""
    s = sub.add_parser("subject", help="virtual mandible subject (create), its virtual experiment (record), and the "
                                       "mandible study on any subject folder (study)",
                       description="openfdk subject create|record|study DIR: see `openfdk subject ACTION --help`")
    actions = s.add_subparsers(dest="action", metavar="ACTION", required=True)
    folder = "subject folder (holding subject.yaml and its STL files)"
    c = actions.add_parser("create", help="write a virtual subject (subject.yaml, STL files)",
                           description="Write a virtual mandible subject folder (docs/subject-folder.md).")
    c.add_argument("directory", help=folder)
    c.add_argument("--resolution", default="default", choices=["coarse", "default", "fine"], help="mesh resolution")
    c.add_argument("--asymmetric", action="store_true", help="perturb left and right shapes differently")
    c.add_argument("--seed", type=int, default=0, help="random seed of the shapes")
    _display_arguments(c)
    r = actions.add_parser("record", help="record the virtual experiment of a virtual subject",
                           description="Record the virtual experiment (C3D files and truth) of a virtual subject "
                                       "folder (docs/virtual-experiment.md).")
    r.add_argument("directory", help=folder)
    r.add_argument("--cycles", type=_cycles_argument, default=None, help="cycles per task (default 5)")
    r.add_argument("--realistic", action="store_true",
                   help="realistic recordings (static trial 4.6° open, slow and wide tasks, 3 open-close cycles, "
                        "extra markers, gaps, trial names declared in trials:)")
    r.add_argument("--quick", action="store_true", help="with --realistic: fewer chewing and protrusion cycles")
    r.add_argument("--noise", type=argtypes.nonnegative, default=0.15, help="marker noise in mm")
    r.add_argument("--seed", type=int, default=0, help="random seed of the marker noise")
    _display_arguments(r)
    t = actions.add_parser("study", help="the mandible study (POP, FDK, tables, figures, parameter study)",
                           description="Run the mandible study on a subject folder, virtual or real "
                                       "(docs/mandible-study.md).")
    t.add_argument("directory", help=folder)
    t.add_argument("--out", default=None, help="output folder (default DIRECTORY-study; checked for writability "
                                               "before any computation)")
    t.add_argument("--force", action="store_true", help="overwrite the results already in the --out folder")
    t.add_argument("--cycles", type=_cycles_argument, default=None,
                   help="cycles analysed per task, a number or 'all' (default 5; a task's own count in trials: wins)")
    t.add_argument("--workers", type=argtypes.count(0), default=None,
                   help="parameter-study worker processes (default one per CPU, 0 = this process)")
    t.add_argument("--scheduler", type=argtypes.scheduler_address, default=None, help="address of a running Dask scheduler")
    t.add_argument("--quick", action="store_true",
                   help="a 2-model parameter study on open-close only (as openfdk demo --quick)")
    t.add_argument("--no-parameter-study", action="store_true", help="skip the ligament parameter study")
    _display_arguments(t)
    s.set_defaults(func=_cmd_subject)


class _Parser(argparse.ArgumentParser):
    """argparse's parser with a one-line usage error: ``openfdk run: error: MESSAGE (see
    openfdk run --help)``, exit 2, without the usage block argparse prints first (the
    subcommands' parsers are of this class too)."""

    def error(self, message):
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def build_parser():
    p = _Parser(prog="openfdk", description="Force-dependent kinematics and musculoskeletal analysis",
                                epilog="Exit codes: 0 success; 2 bad input; 3 more frames failed than --max-failed; "
                                       "130 interrupted; 141 the printed output's reader left.")
    p.add_argument("--version", action="version", version=f"openfdk {_version()}", help="print the version and exit")
    _display_arguments(p, top=True)
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND")

    c = sub.add_parser("check", help="validate a model file and print a summary",
                       description="Read a model file (YAML or OpenSim .osim), check it (units, references, meshes, "
                                   "the rank of the constraint rows at the reference pose) and print a summary. "
                                   "Errors exit with 2, plausibility warnings go to stderr (docs/input-checks.md).")
    c.add_argument("model", help="model file (YAML or OpenSim .osim) to validate: errors exit with 2, plausibility "
                                 "warnings go to stderr")
    _display_arguments(c)
    _import_arguments(c)
    c.set_defaults(func=_cmd_check)

    io = sub.add_parser("import-opensim", help="an OpenSim .osim as a readable openfdk model file plus its meshes",
                        description="Write an OpenSim model (.osim, 3.x or 4.x) as an openfdk YAML model file and "
                                    "its meshes; unsupported elements are left out and counted (docs/opensim-import.md).")
    io.add_argument("model", help="OpenSim model (.osim, OpenSim 3.x or 4.x)")
    io.add_argument("--out", required=True, help="output folder (the model file and a Geometry folder)")
    io.add_argument("--force", action="store_true", help="overwrite an earlier import in --out")
    _display_arguments(io)
    _import_arguments(io)
    io.set_defaults(func=_cmd_import_opensim)

    ca = sub.add_parser("cache", help="the on-disk distance-grid cache: size (info) or delete it (clear)",
                        description="The contact meshes' signed-distance grids are cached on disk (OPENFDK_CACHE_DIR; "
                                    "'off' disables it). info: folder, number of grids and size; clear: delete them "
                                    "(docs/contact.md).")
    ca.add_argument("action", choices=["info", "clear"], help="info: folder, number of grids and size; clear: delete them")
    _display_arguments(ca)
    ca.set_defaults(func=_cmd_cache)

    k = sub.add_parser("kinematics", help="kinematic analysis: marker tracking (with a C3D trial) or determinate",
                       description="Kinematic analysis of a model over a trial: marker tracking (least squares on the "
                                   "markers of a C3D or TRC trial, Eqs. 4-10) or, without a trial, determinate "
                                   "kinematics from the model's drivers (Eqs. 1-3). Writes kinematics.csv/.sto, "
                                   "measures.csv and summary.json to --out (docs/kinematics.md).")
    _trial_arguments(k)
    k.set_defaults(func=_cmd_kinematics)

    r = sub.add_parser("run", help="kinematics, then inverse dynamics with muscle recruitment",
                       description="Kinematics, then inverse dynamics with muscle recruitment (Eqs. 11-14) and, for a "
                                   "model with FDK DOFs, force-dependent kinematics (Eqs. 15-17). The model is checked "
                                   "first as by `openfdk check`. Writes kinematics.csv, forces.csv (+ .sto), "
                                   "measures.csv, summary.json and plots/ to --out (docs/inverse-dynamics.md, "
                                   "docs/fdk.md, docs/outputs.md).")
    _trial_arguments(r)
    r.set_defaults(func=_cmd_run)
    from ..study.cli import add_chunk_arguments, add_study_parser

    add_chunk_arguments(r)
    from ..trial.checkpoint import DEFAULT_EVERY_FRAMES, DEFAULT_EVERY_SECONDS

    r.add_argument("--resume", action="store_true",
                   help="continue an interrupted run from the checkpoint in --out (same model, trial and options)")
    r.add_argument("--checkpoint-frames", type=int, default=DEFAULT_EVERY_FRAMES, metavar="N",
                   help=f"write finished frames to --out at least every N frames (default {DEFAULT_EVERY_FRAMES})")
    r.add_argument("--checkpoint-seconds", type=float, default=DEFAULT_EVERY_SECONDS, metavar="S",
                   help=f"... and at least every S seconds (default {DEFAULT_EVERY_SECONDS:g})")
    r.add_argument("--moment-arms", action="store_true",
                   help="also write moment_arms.csv/.sto: each muscle's moment arm about each coordinate it spans "
                        "(OpenSim's MuscleAnalysis MomentArm), for a model with muscles and joint coordinates")
    add_study_parser(sub)
    from .outputs import add_output_parsers, add_run_output_arguments
    from ..viewer.cli import add_view_parser

    add_run_output_arguments(r)
    add_output_parsers(sub)
    add_view_parser(sub)
    from .validate import add_validate_parser

    add_validate_parser(sub)
    from .cycles import add_cycles_parser

    add_cycles_parser(sub)

    d = sub.add_parser("demo", help="the mandible study on the virtual subject, end to end",
                       description="The paper's application end to end: a virtual mandible subject and its recorded "
                                   "experiment (OUT/subject, reused when present), the POP and FDK TMJ models on every "
                                   "task, Tables 1-2, Figures 5-7 and the ligament parameter study (OUT/study; "
                                   "docs/mandible-study.md).")
    d.add_argument("--out", default="openfdk-demo", help="output directory (default ./openfdk-demo)")
    d.add_argument("--quick", action="store_true", help="a reduced run (coarse meshes, 2 cycles; for tests)")
    d.add_argument("--force", action="store_true",
                   help="overwrite the study results already in OUT/study (the subject in OUT/subject is reused)")
    _display_arguments(d)
    d.add_argument("--workers", type=argtypes.count(0), default=None,
                   help="parameter-study worker processes (default one per CPU; 0 = this process)")
    d.set_defaults(func=_cmd_demo)

    _subject_parser(sub)

    b = sub.add_parser("bench", help="run the benchmarks",
                       description="Run the benchmarks: medians over repeats on one core, one line per record "
                                   "(with --json one JSON object {name, value, unit} per line); --quick runs short "
                                   "versions. A benchmark that fails is reported and the others go on (exit 1).")
    b.add_argument("--quick", action="store_true", help="short runs (for tests)")
    b.add_argument("--json", action="store_true", help="one JSON object per line")
    b.add_argument("--only", nargs="*", help="benchmark modules to run: a module's name (full_body) or a substring of "
                                            "names (arm)")
    _display_arguments(b)
    b.set_defaults(func=_cmd_bench)
    return p


_NUMPY_NOISE = re.compile(r"invalid value encountered|divide by zero|overflow encountered|underflow encountered|"
                          r"All-NaN|Mean of empty slice|empty slice|Degrees of freedom|nan(arg)?(min|max)")


def _show_warning(message, category, filename, lineno, file=None, line=None):
    """Warnings as one line, ``openfdk: warning: ...``; numpy's floating-point and
    empty-slice warnings are dropped (failed frames are reported by the run itself)."""
    text = str(message)
    if issubclass(category, RuntimeWarning) and ("numpy" in filename or "scipy" in filename or _NUMPY_NOISE.search(text)):
        return
    text = " ".join(text.split())
    print(f"openfdk: warning: {text}", file=sys.stderr if file is None else file)


def _blas_threads():
    """BLAS limited for the command (:func:`openfdk.numerics.blas.blas_threads`); a bad
    ``OPENFDK_BLAS_THREADS`` is the command's one-line error."""
    from ..numerics.blas import blas_threads

    try:
        return blas_threads()
    except ValueError as e:
        raise UserError(str(e)) from None


def _silence_stdout():
    """Point stdout at the null device (its reader has gone: the interpreter's last flush
    would fail again)."""
    import os

    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError, AttributeError):  # a stdout without a file descriptor (tests)
        pass


def main(argv=None):
    import numpy as np

    args = build_parser().parse_args(argv)
    from ..trial.progress import set_quiet, set_warmup

    set_quiet(getattr(args, "quiet", False))
    old_show, old_err = warnings.showwarning, np.seterr(all="ignore")
    warnings.showwarning = _show_warning
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("default")
            warnings.showwarning = _show_warning
            _register_import(args)
            with _blas_threads():
                return args.func(args)
    except (KeyboardInterrupt, SystemError) as exc:
        from ..trial.driver import caused_by_interrupt

        if not caused_by_interrupt(exc):  # a SystemError of its own: a bug, with its traceback
            raise
        print("openfdk: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except BrokenPipeError:
        # the reader of the output left (``openfdk cycles RUN | head -3``): the printed
        # summary stops there, without a word, and the exit code is a Unix tool's killed by
        # SIGPIPE (the command's own code, e.g. 3 for failed frames, is not known here)
        _silence_stdout()
        return EXIT_BROKEN_PIPE
    except (UserError, ValueError, FileNotFoundError, OSError) as exc:
        # ModelError, SubjectError, StudyError, C3DError, MeshError, MissingMarkerError,
        # KinematicsError and OutputDirError are ValueErrors
        msg = " ".join(str(exc).split()) if str(exc).strip() else type(exc).__name__
        print(f"openfdk: error: {msg}", file=sys.stderr)
        return EXIT_BAD_INPUT
    finally:
        warnings.showwarning = old_show
        np.seterr(**old_err)
        set_quiet(False)
        set_warmup(False)
        from ..analysis.kernel_cache import disarm

        disarm()


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
