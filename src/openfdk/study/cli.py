"""Command-line pieces of studies and chunked runs (wired into ``openfdk.cli``).

    openfdk study STUDY.yaml --out DIR [--scheduler ADDRESS] [--workers N] [--retries R]
                  [--force] [--list] [--no-progress]
    openfdk run MODEL.yaml TRIAL.c3d --out DIR --chunks K [--overlap F] [--scheduler ADDRESS] [--workers N]

``openfdk study`` exits with 0 when every case completed, 3 when some case failed (the
others are still run and summarised; as ``openfdk run`` with failed frames), 2 for a bad study file (raised as StudyError, a
ValueError, which ``openfdk.cli.main`` reports in one line).
"""

from __future__ import annotations

import argparse
import sys
from collections import Counter
import time as _time
from pathlib import Path

from ..cli import argtypes
from .defaults import DEFAULT_OVERLAP


def add_study_parser(subparsers):
    """Register the ``study`` subcommand on an argparse subparsers object; its handler
    (``args.func``) returns the exit code. Returns the parser."""
    p = subparsers.add_parser(
        "study", help="run a parameter / trial / subject study as independent tasks (Dask)",
        description="Run every case of a study file (docs/studies.md). Complete cases in DIR are skipped.",
    )
    p.add_argument("study", help="study file (YAML)")
    p.add_argument("--out", required=True, help="output directory (one folder per case, summary.csv)")
    p.add_argument("--scheduler", type=argtypes.scheduler_address, default=None,
                   help="address of a running Dask scheduler (default: a LocalCluster here)")
    p.add_argument("--workers", type=argtypes.count(0), default=None,
                   help="LocalCluster worker processes (default: CPU count); 0 = run the cases in this process")
    p.add_argument("--retries", type=argtypes.count(0), default=None,
                   help="runs of a failing case after the first (default: study file, else 2)")
    p.add_argument("--force", action="store_true", help="run complete cases again")
    p.add_argument("--list", action="store_true", help="list the cases and exit")
    p.add_argument("--no-progress", action="store_true", help="no progress display")
    p.add_argument("--quiet", "-q", action="store_true", default=argparse.SUPPRESS,
                   help="no progress display and no informational output (warnings and errors still go to stderr)")
    p.set_defaults(func=cmd_study)
    return p


def add_chunk_arguments(parser):
    """Add ``--chunks``, ``--overlap``, ``--scheduler`` and ``--workers`` to the ``run``
    subcommand's parser."""
    parser.add_argument("--chunks", type=argtypes.count(1), default=1,
                        help="split the trial into K frame segments solved in parallel, then stitched (default 1)")
    parser.add_argument("--overlap", type=argtypes.count(0), default=DEFAULT_OVERLAP,
                        help=f"warm-up frames solved before each chunk and dropped (default {DEFAULT_OVERLAP})")
    parser.add_argument("--scheduler", type=argtypes.scheduler_address, default=None,
                        help="address of a running Dask scheduler (default: a LocalCluster)")
    parser.add_argument("--workers", type=argtypes.count(0), default=None,
                        help="LocalCluster worker processes (default: min(chunks, CPUs)); 0 = in this process")
    return parser


def _print_cases(study):
    params = study.parameter_names
    print(f"study {study.name!r}: {len(study.cases)} cases (kind {study.kind})")
    for c in study.cases:
        names = " ".join(f"{k}={v}" for k, v in c.names.items())
        values = " ".join(f"{p}={c.parameters[p]}" for p in params if p in c.parameters)
        print(f"  {c.case_id}: {names} {values}".rstrip())


def cmd_study(args):
    """Handler of ``openfdk study``: returns the exit code."""
    from .runner import run_study
    from .spec import StudyError, load_study

    study = load_study(args.study)
    if args.list:
        _print_cases(study)
        return 0
    if args.workers is not None and args.workers < 0:
        raise StudyError(f"--workers must be >= 0, got {args.workers}")
    res = run_study(study, args.out, scheduler=args.scheduler, workers=args.workers, retries=args.retries,
                    force=args.force, progress=not args.no_progress)
    c = res.summary["counts"]
    if not getattr(args, "quiet", False):
        print(f"study {study.name!r}: {c['completed']}/{c['cases']} cases completed ({c['reused']} from an earlier run), "
              f"{c['failed']} failed, {res.wall_time:.1f} s -> {Path(res.out_dir) / 'summary.csv'}")
    for r in res.failed[:10]:
        print(f"  failed: {r['case_id']} after {r['attempts']} attempts: {r['error']}", file=sys.stderr)
    if len(res.failed) > 10:
        print(f"  ... and {len(res.failed) - 10} more failed cases (see summary.json)", file=sys.stderr)
    if res.failed:
        reasons = Counter(str(r["error"]).split(":")[0] for r in res.failed).most_common(1)[0]
        print(f"openfdk: {len(res.failed)} of {c['cases']} cases failed; most common reason ({reasons[1]} cases): "
              f"{reasons[0]}", file=sys.stderr)
        return 3
    return 0


def job_case(model_path, trial_path, chunks, overlap=DEFAULT_OVERLAP, cutoff_hz=None, start=None, end=None):
    """A model-kind Case (no overrides) for one model file and trial."""
    from .spec import Case, RunOptions

    model = Path(model_path)
    if not model.is_file():
        raise FileNotFoundError(f"model file {str(model)!r} does not exist")
    inputs = {"models": str(model.resolve())}
    names = {"models": model.stem}
    if trial_path is not None:
        trial = Path(trial_path)
        if not trial.is_file():
            raise FileNotFoundError(f"trial file {str(trial)!r} does not exist")
        inputs["trials"], names["trials"] = str(trial.resolve()), trial.stem
    options = RunOptions(chunks=int(chunks), overlap=int(overlap), cutoff_hz=cutoff_hz, start=start, end=end)
    from ..io.opensim.overlay import registered_options

    return Case("-".join(names.values()), "model", "openfdk.study.kinds:prepare_model_case", names, inputs, {}, (),
                options, import_options=registered_options(model))


def run_chunked_job(model_path, trial_path, chunks, out_dir=None, *, cutoff_hz=None, start=None, end=None,
                    overlap=DEFAULT_OVERLAP, scheduler=None, workers=None, client=None, progress=True,
                    malloc_trim=False, checkpoints=None, resume=False, loaded=None, rim_check=True):
    """``openfdk run --chunks K``: one trial split into ``chunks`` frame segments solved
    in parallel (each warmed up by ``overlap`` frames, docs/studies.md), stitched into
    one result equal to the serial run's to the solver tolerances.

    Execution: ``client`` if given; else the scheduler at ``scheduler``; else
    ``workers`` = 0 solves the segments one after the other in this process; else a
    LocalCluster of ``workers`` processes (default min(chunks, CPUs)) on 127.0.0.1.
    Returns (KinematicsResult, InverseDynamicsResult, info) like
    :func:`openfdk.analysis.jobs.run_job` (info["fdk"] for FDK models, info["chunks"],
    info["segments"]); with ``out_dir``, also writes kinematics.csv, forces.csv and
    summary.json there as ``openfdk run`` does.

    ``checkpoints``: a :class:`openfdk.trial.checkpoint.SegmentCheckpoints` keeping each
    finished segment (cleared once the results are written); with ``resume`` the
    segments kept there are reused and only the others solved, otherwise they are
    discarded first. ``loaded``: (Model, AnalysisSettings, …) of ``model_path`` when the
    caller has read it (``openfdk run`` writes its outputs with the same Model: the file
    and its measured loads are read, and warned about, once in this process).
    ``rim_check``: False leaves :func:`~openfdk.contact.rim.warn_contact_rims` to the
    caller (``openfdk run`` computes it with its figures, plots/parallel.py).
    """
    import contextlib
    import os

    from .case import segment_task, write_run_outputs
    from .chunks import chunk_info, stitch
    from .cluster import dask_client

    if int(chunks) < 1:
        raise ValueError(f"--chunks must be >= 1, got {chunks}")
    case = job_case(model_path, trial_path, chunks, overlap, cutoff_hz, start, end)
    # the plausibility checks of the whole trial, here once (the segments skip them):
    # model (on loading), trial markers in the window, and the pulling contacts below
    from ..io.modelfile import load_model_and_settings
    from ..analysis.jobs import analysis_inputs, preflight
    from ..contact.rim import warn_contact_rims
    from ..model.plausibility import warn_outlier_markers, warn_plausibility, warn_pulling_contacts

    model, settings = loaded[:2] if loaded is not None else load_model_and_settings(model_path)
    checked = preflight(model, str(model_path), model_path)
    analysis_inputs(model, trial_path, cutoff_hz, start, end, settings)
    done = {}
    if checkpoints is not None:
        if resume:
            done = checkpoints.load()
        else:
            checkpoints.clear()
    todo = [k for k in range(int(chunks)) if k not in done]

    def finished(result):
        results.append(result)
        if checkpoints is not None:
            checkpoints.save(result.segment.index, result)
        if bar:
            bar.update()

    t0 = _time.perf_counter()
    bar = None
    if progress:
        from ..trial.progress import progress as _display

        bar = _display(int(chunks), "chunks", "chunk", initial=len(done))
    results = [done[k] for k in sorted(done)]
    try:
        if client is None and scheduler is None and workers == 0:
            for k in todo:
                finished(segment_task(case, k, checks=False))
        else:
            from distributed import as_completed

            with contextlib.ExitStack() as stack:
                if client is None:
                    n = workers or min(int(chunks), os.cpu_count() or 1)
                    client = stack.enter_context(dask_client(scheduler, n, malloc_trim))
                futures = [client.submit(segment_task, case, k, checks=False, pure=False) for k in todo]
                for fut in as_completed(futures, loop=client.loop):
                    finished(fut.result())
    finally:
        if bar:
            bar.close()
    wall = _time.perf_counter() - t0
    kin, dyn, fdk = stitch(results, wall)
    warn_pulling_contacts(model, kin, dyn)
    if rim_check:
        warn_contact_rims(model, kin)
    warn_outlier_markers(kin)
    info = {**results[0].info, **checked, **chunk_info(results, overlap)}
    info["model"] = str(model_path)
    for k, seg in enumerate(info["segments"]):
        if seg.get("cold_start_in_stance") is False:
            warn_plausibility(f"segment {k + 1} of {len(results)} started cold at {seg['cold_start_s']:.3f} s, outside "
                              "the stance of the limb the FDK DOFs hold (no stance frame within half a chunk of the "
                              "equal cut): a cold start in swing can take a minute; another --chunks moves the cut "
                              "(docs/studies.md, 'Where the cuts fall')")
    if fdk is not None:
        info["fdk"] = fdk.summary()
    if out_dir is not None:
        write_run_outputs(out_dir, kin, dyn, info)
    if checkpoints is not None:
        checkpoints.clear()
    return kin, dyn, info
