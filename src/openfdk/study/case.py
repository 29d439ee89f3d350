"""One study case in a worker: build the model, run it, publish its folder atomically.

A case folder ``OUT/cases/<case_id>/`` holds what ``openfdk run`` writes
(``kinematics.csv``, ``forces.csv``, ``summary.json``) plus ``case.json`` (the case
definition, its fingerprint, the worker and the wall time). It is written under a
temporary name ``OUT/cases/.<case_id>.tmp-<random>`` and renamed when complete, so a
folder under the final name is always whole; ``case.json`` is written last. If the
final folder already holds the same fingerprint (another attempt of the same case
finished first) the new one is discarded; a stale folder (different fingerprint) is
replaced.

These functions are the Dask tasks: :func:`run_case` (a whole case),
:func:`segment_task` and :func:`finish_chunked_case` (a chunked case: K segment tasks,
then one task that stitches and publishes).
"""

from __future__ import annotations

import json
import os
import shutil
import socket
import time as _time
import uuid
from dataclasses import asdict
from pathlib import Path

from ..io.results import write_forces, write_json, write_kinematics
from .boundaries import cut_preference
from .chunks import analysis_inputs, chunk_info, plan_segments, solve_segment, stitch
from .defaults import CASES
from .kinds import import_callable
from .overrides import apply_overrides

CASE_JSON = "case.json"


def case_dir(out_root, case_id) -> Path:
    """The final folder of a case."""
    return Path(out_root) / CASES / case_id


def completed_record(folder, fingerprint):
    """The case.json record of a complete case folder with this fingerprint, else None."""
    try:
        rec = json.loads((Path(folder) / CASE_JSON).read_text())
    except (OSError, ValueError):
        return None
    if rec.get("status") == "completed" and rec.get("fingerprint") == fingerprint:
        return rec
    return None


def build_case_model(case):
    """(model, its AnalysisSettings, trial path or None, model label) of a case: the
    kind's prepare, then the overrides applied to the model mapping (settings sections
    included), then the model and its settings built."""
    from ..io.modelfile import built_from_data

    prepared = import_callable(case.prepare)(case)
    data = apply_overrides(prepared.model_data, case.overrides, source=prepared.source)
    # as the file is built on its own: a motion file's drivers that the model's rows
    # determine are left out (a chunked run's workers drove pf_ty_r against DM's tendon)
    model, settings = built_from_data(data, Path(prepared.base_dir or ".") / prepared.source,
                                      f"{prepared.source} [case {case.case_id}]", base_dir=prepared.base_dir,
                                      label=None)
    return model, settings, prepared.trial, str(Path(prepared.base_dir) / prepared.source)


def write_run_outputs(out, kin, dyn, info, frames_planned=None):
    """What ``openfdk run`` writes into ``out``: kinematics.csv, forces.csv and
    summary.json ({input, kinematics, inverse_dynamics, fdk?}). ``frames_planned``
    (int) marks an interrupted run: summary.json then says ``"partial": true`` with the
    frames finished and planned."""
    info = dict(info)
    fdk = info.pop("fdk", None)
    for key in ("model", "trial"):  # absolute paths, so that 'openfdk view' finds the inputs from anywhere
        if isinstance(info.get(key), str) and Path(info[key]).is_file():
            info[f"{key}_file"] = str(Path(info[key]).resolve())
    write_kinematics(out, kin, {"input": info})
    write_forces(out, dyn)
    summary = {"input": info, "kinematics": kin.summary(), "inverse_dynamics": dyn.summary()}
    if frames_planned is not None:
        summary = {"partial": True, "frames_finished": int(len(kin.time)), "frames_planned": int(frames_planned),
                   **summary}
    if fdk is not None:
        summary["fdk"] = fdk
    write_json(Path(out) / "summary.json", summary)


def _worker_tag():
    return f"{socket.gethostname()}:{os.getpid()}"


def case_definition(case):
    """JSON-able definition of a case (for case.json and the summary)."""
    return {
        "case_id": case.case_id, "kind": case.kind, "names": case.names, "inputs": case.inputs,
        "parameters": case.parameters,
        "overrides": [{"path": o.path, "value": o.value, "mode": o.mode} for o in case.overrides],
        "options": asdict(case.options), "fingerprint": case.fingerprint,
    }


def publish_case(out_root, case, kin, dyn, info, wall_time, force=False):
    """Write a case's results under a temporary name and rename it into place (an
    existing folder with the same fingerprint is kept unless ``force``). Returns the
    case.json record."""
    cases = Path(out_root) / CASES
    cases.mkdir(parents=True, exist_ok=True)
    final = cases / case.case_id
    tmp = cases / f".{case.case_id}.tmp-{uuid.uuid4().hex[:10]}"
    tmp.mkdir()
    try:
        write_run_outputs(tmp, kin, dyn, info)
        record = {**case_definition(case), "status": "completed", "wall_time_s": float(wall_time),
                  "worker": _worker_tag(), "finished": _time.strftime("%Y-%m-%dT%H:%M:%S")}
        write_json(tmp / CASE_JSON, record)
        try:
            os.rename(tmp, final)
        except OSError:
            # the final name exists: a finished twin (keep it) or a stale result (replace)
            twin = None if force else completed_record(final, case.fingerprint)
            if twin is not None:
                shutil.rmtree(tmp, ignore_errors=True)
                return twin
            old = cases / f".{case.case_id}.old-{uuid.uuid4().hex[:10]}"
            os.rename(final, old)
            os.rename(tmp, final)
            shutil.rmtree(old, ignore_errors=True)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return record


def with_metrics(record, out_root, case):
    """The case.json ``record`` of a complete case plus its summary metrics
    (:func:`.summary.case_metrics` of its folder, with the columns of
    ``case.options.metrics``): ``metrics``, ``metric_warnings`` and ``metric_columns``.
    Computed in the worker that ran the case, so that the driver, which shares the cores
    with the workers, only collects them. A folder whose metrics cannot be read returns
    ``record`` unchanged (the driver then reads them itself and reports the problem)."""
    from .summary import case_metrics

    try:
        metrics, warnings = case_metrics(case_dir(out_root, case.case_id), case.options.metrics)
    except (OSError, ValueError, KeyError):
        return record
    return {**record, "metrics": metrics, "metric_warnings": warnings, "metric_columns": list(case.options.metrics)}


def case_inputs(case):
    """(model, settings, label, trajectories, times (nf,) s, info) of a case: its model
    with the trial's force plates applied as loads when the settings assign them
    (``ground_reactions``, as ``openfdk run`` applies them), and its analysed frames."""
    from ..analysis.jobs import _with_ground_reactions

    model, settings, trial, label = build_case_model(case)
    opts = case.options
    traj, times, info = analysis_inputs(model, trial, opts.cutoff_hz, opts.start, opts.end, settings)
    model = _with_ground_reactions(model, settings, trial, traj, opts.cutoff_hz, info)
    return model, settings, label, traj, times, info


def run_case(case, out_root, force=False):
    """Dask task / serial step: run one case (its chunks one after the other when
    ``options.chunks`` > 1) and publish its folder; a complete folder is returned as it
    is unless ``force``. Returns the case.json record. Exceptions propagate (the driver
    retries, then records them)."""
    done = None if force else completed_record(case_dir(out_root, case.case_id), case.fingerprint)
    if done is not None:
        return with_metrics(done, out_root, case)
    t0 = _time.perf_counter()
    opts = case.options
    model, settings, label, traj, times, info = case_inputs(case)
    if opts.chunks > 1:
        preference = cut_preference(model, times)
        segments = plan_segments(len(times), opts.chunks, opts.overlap, preference)
        parts = [solve_segment(model, traj, times, s, cold_start_info(preference, s), settings) for s in segments]
        kin, dyn, fdk = stitch(parts, _time.perf_counter() - t0)
        info.update(chunk_info(parts, opts.overlap))
    else:
        from .chunks import analyse

        kin, dyn, fdk = analyse(model, traj, times, settings)
    info = {"model": label, **info}
    if fdk is not None:
        info["fdk"] = fdk.summary()
    return with_metrics(publish_case(out_root, case, kin, dyn, info, _time.perf_counter() - t0, force), out_root, case)


def segment_task(case, index, checks=True):
    """Dask task: solve segment ``index`` of a chunked case. Returns a SegmentResult.
    ``checks`` False: the plausibility warnings of the model and trial are silenced here
    (the caller checks them once for the whole trial, see
    :func:`openfdk.study.cli.run_chunked_job`)."""
    import contextlib
    import warnings

    from ..model.plausibility import PlausibilityWarning

    with warnings.catch_warnings() if not checks else contextlib.nullcontext():
        if not checks:
            warnings.simplefilter("ignore", PlausibilityWarning)
        opts = case.options
        model, settings, label, traj, times, info = case_inputs(case)
        preference = cut_preference(model, times)
        segment = plan_segments(len(times), opts.chunks, opts.overlap, preference)[index]
        return solve_segment(model, traj, times, segment, {"model": label, **info,
                                                           **cold_start_info(preference, segment)}, settings)


def cold_start_info(preference, segment):
    """{"cold_start_in_stance": bool} of a segment after the first when the trial has a
    stance preference (:func:`openfdk.study.boundaries.cut_preference`), else {}."""
    if preference is None or segment.index == 0:
        return {}
    return {"cold_start_in_stance": bool(preference[segment.solve_start] > 0)}


def finish_chunked_case(case, out_root, started, force, *segment_results):
    """Dask task: stitch the segments of a chunked case and publish it. ``started`` is
    the wall-clock time (time.time(), s) the case was submitted; ``force`` as in
    :func:`run_case`."""
    done = None if force else completed_record(case_dir(out_root, case.case_id), case.fingerprint)
    if done is not None:
        return with_metrics(done, out_root, case)
    wall = _time.time() - started
    kin, dyn, fdk = stitch(segment_results, wall)
    info = {**segment_results[0].info, **chunk_info(segment_results, case.options.overlap)}
    if fdk is not None:
        info["fdk"] = fdk.summary()
    return with_metrics(publish_case(out_root, case, kin, dyn, info, wall, force), out_root, case)
