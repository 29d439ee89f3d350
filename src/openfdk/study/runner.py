"""Running a study: skip complete cases, run the others as independent tasks (on Dask or
in this process), retry failures, summarise.

Guarantees (docs/studies.md):

* each case publishes its own folder atomically (:mod:`.case`); a case is complete when
  its folder's ``case.json`` holds the case's fingerprint, and a rerun skips it;
* a case that raises is run again up to ``retries`` times, then recorded as failed with
  its error while the other cases go on; failed cases are tried again by the next run;
* a killed worker loses only its running task, which the scheduler gives to another
  worker (a LocalCluster's nanny also restarts the process); a task that kills three
  workers is reported as a failure (``KilledWorker``) like any other error;
* ``summary.csv`` / ``summary.json`` are written at the end, also after an error or an
  interruption (then with the cases finished so far).

One output folder belongs to one running study at a time (a lock file
``.study.lock`` holds the driver's host and pid; a stale lock is taken over).
"""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import socket
import time as _time
import traceback
import uuid
from dataclasses import dataclass
from pathlib import Path

from ..io.results import atomic_write_text
from ..io.trials import recorded_duration_s
from .case import CASES, case_dir, completed_record, finish_chunked_case, run_case, segment_task
from .spec import Study, StudyError, load_study
from .summary import case_metrics, write_summary

LOCK = ".study.lock"


@dataclass(frozen=True)
class StudyResult:
    """out_dir; records : one dict per case, study order (see summary.py); summary : the
    summary.json content; wall_time : s."""

    out_dir: Path
    records: list
    summary: dict
    wall_time: float

    @property
    def failed(self):
        return [r for r in self.records if r["status"] == "failed"]

    @property
    def ok(self):
        return not self.failed and len(self.records) == self.summary["counts"]["cases"]


def _pid_alive(pid):
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def _acquire_lock(out):
    path = out / LOCK
    me = {"host": socket.gethostname(), "pid": os.getpid(), "started": _time.strftime("%Y-%m-%dT%H:%M:%S")}
    for _ in range(2):
        try:
            fd = os.open(path, os.O_CREAT | os.O_EXCL | os.O_WRONLY)
        except FileExistsError:
            try:
                other = json.loads(path.read_text())
            except (OSError, ValueError):
                other = {}
            if not isinstance(other, dict):  # a lock that is not a JSON object (e.g. `[]`): its owner is unknown
                other = {}
            pid = other.get("pid")
            if not isinstance(pid, int) or isinstance(pid, bool) or not 0 < pid < 2 ** 31:  # not a process id
                other = {k: v for k, v in other.items() if k != "pid"}
            if other.get("host") == me["host"] and not _pid_alive(int(other.get("pid", -1))):
                path.unlink(missing_ok=True)  # stale: its process is gone
                continue
            raise StudyError(
                f"output folder {str(out)!r} is in use by a study running on {other.get('host')} (pid "
                f"{other.get('pid')}, since {other.get('started')}); if none is running, delete {str(path)!r}"
            ) from None
        with os.fdopen(fd, "w") as fh:
            json.dump(me, fh)
        return path
    raise StudyError(f"could not lock output folder {str(out)!r}")


def _clean_temporaries(out):
    """Remove half-written case folders left by killed attempts."""
    cases = out / CASES
    if cases.is_dir():
        for p in list(cases.glob(".*.tmp-*")) + list(cases.glob(".*.old-*")):
            shutil.rmtree(p, ignore_errors=True)


def _error_text(exc):
    msg = str(exc).strip().splitlines()
    return f"{type(exc).__name__}: {msg[0]}" if msg else type(exc).__name__


def _serial(pending, out, retries, force):
    """Cases one after the other in this process: yields (case, attempts, record, error)."""
    for case in pending:
        for attempt in range(1, retries + 2):
            try:
                yield case, attempt, run_case(case, out, force), None
                break
            except Exception as exc:  # noqa: BLE001 — recorded, the study goes on
                if attempt == retries + 1:
                    yield case, attempt, None, (exc, traceback.format_exc())


def analysed_duration_s(case, recorded=recorded_duration_s):
    """Length (s) of the part of its trial a case analyses: ``options.end`` (or the
    trial's end) − ``options.start`` (or 0), the end clipped to the recorded duration when
    the case names a trial file (``inputs["trials"]``, the ``model`` kind) whose header
    tells it; ``inf`` for a case with no end whose trial's length is unknown."""
    o = case.options
    start = float(o.start or 0.0)
    trial = case.inputs.get("trials") if isinstance(case.inputs, dict) else None
    duration = None if trial is None else recorded(trial)
    end = float("inf") if o.end is None else float(o.end)
    if duration is not None:
        end = min(end, duration)
    return max(end - start, 0.0)


def longest_first(cases):
    """``cases`` in the order they are given to the workers: longest analysed part of the
    trial (:func:`analysed_duration_s`) first, study order among equals. The last cases
    to finish are then the short ones, so the workers run out of work at nearly the same
    time (longest processing time first). Each trial file's header is read once."""
    durations = {}

    def recorded(path):
        if path not in durations:
            durations[path] = recorded_duration_s(path)
        return durations[path]

    return sorted(cases, key=lambda case: analysed_duration_s(case, recorded), reverse=True)


def _dask(client, pending, out, retries, force):
    """Cases as Dask tasks (a chunked case: K segment tasks + a stitching task); yields
    (case, attempts, record, error) as cases finish."""
    from distributed import as_completed

    token = uuid.uuid4().hex[:8]
    meta = {}

    def submit(case, attempt):
        key = f"openfdk-case-{case.case_id}-{token}-{attempt}"
        segments = []
        if case.options.chunks > 1:
            segments = [client.submit(segment_task, case, k, key=f"{key}-segment-{k}", pure=False)
                        for k in range(case.options.chunks)]
            fut = client.submit(finish_chunked_case, case, str(out), _time.time(), force, *segments, key=key,
                                pure=False)
        else:
            fut = client.submit(run_case, case, str(out), force, key=key, pure=False)
        meta[fut.key] = (case, attempt, segments)
        return fut

    queue = as_completed([submit(c, 1) for c in longest_first(pending)], loop=client.loop)
    for fut in queue:
        case, attempt, segments = meta.pop(fut.key)
        try:
            record = fut.result()
        except Exception as exc:  # noqa: BLE001 — recorded, the study goes on
            if attempt <= retries:
                queue.add(submit(case, attempt + 1))
            else:
                tb = "".join(traceback.format_exception(type(exc), exc, exc.__traceback__))
                yield case, attempt, None, (exc, tb)
            continue
        finally:
            fut.release()
            for s in segments:
                s.release()
        yield case, attempt, record, None


def _record(case, out, result, error, attempts, reused, metrics_columns):
    rec = {"case_id": case.case_id, "names": case.names, "parameters": case.parameters, "attempts": attempts,
           "reused": reused, "folder": str(case_dir(out, case.case_id))}
    if error is not None:
        exc, tb = error
        rec.update(status="failed", error=_error_text(exc), traceback=tb)
        return rec
    rec.update(status="completed", wall_time_s=result.get("wall_time_s"), worker=result.get("worker"))
    try:
        if "metrics" in result and result.get("metric_columns") == list(metrics_columns):
            metrics, warnings = result["metrics"], result["metric_warnings"]  # read by the worker
        else:
            metrics, warnings = case_metrics(case_dir(out, case.case_id), metrics_columns)
        rec["metrics"] = metrics
        if warnings:
            rec["warnings"] = warnings
    except (OSError, ValueError, KeyError) as exc:
        rec["warnings"] = [f"metrics could not be read: {_error_text(exc)}"]
    return rec


def run_study(study, out_dir, *, scheduler=None, workers=None, client=None, progress=True, force=False,
              retries=None, malloc_trim=False, on_case_done=None) -> StudyResult:
    """Run every case of ``study`` (a Study or a study file path) into ``out_dir``.

    Execution: ``client`` (a connected distributed.Client) if given; else the scheduler
    at address ``scheduler``; else ``workers`` = 0 runs the cases one after the other in
    this process (no Dask); else a LocalCluster of ``workers`` processes (default: the
    CPU count, at most the number of tasks) on 127.0.0.1, stopped at the end.
    force : run complete cases again; retries : override the study's ``run.retries``;
    malloc_trim : keep Dask's MALLOC_TRIM_THRESHOLD_ in local workers (cluster.py);
    on_case_done(record) : called in this process after each case finishes or fails.
    Returns a StudyResult; writes summary.csv and summary.json.
    """
    from .cluster import dask_client

    t0 = _time.perf_counter()
    if not isinstance(study, Study):
        study = load_study(study)
    if not str(out_dir).strip():
        raise StudyError("the output folder is empty (--out ''); give a folder name")
    out = Path(out_dir).resolve()
    out.mkdir(parents=True, exist_ok=True)
    lock = _acquire_lock(out)
    records = {}
    execution = {"mode": "serial"}
    try:
        _clean_temporaries(out)
        if study.source is not None:
            atomic_write_text(out / "study.yaml", Path(study.source).read_text())
        retries = study.options.retries if retries is None else int(retries)
        metric_columns = study.options.metrics
        pending = []
        for case in study.cases:
            done = None if force else completed_record(case_dir(out, case.case_id), case.fingerprint)
            if done is None:
                pending.append(case)
            else:
                records[case.case_id] = _record(case, out, done, None, 0, True, metric_columns)
        bar = None
        if progress:
            from ..trial.progress import progress as _display

            bar = _display(len(study.cases), f"study {study.name}", "case", initial=len(records))
        try:
            with contextlib.ExitStack() as stack:
                if not pending:
                    runs = iter(())
                elif client is not None:
                    runs = _dask(client, pending, out, retries, force)
                    execution = {"mode": "dask", "scheduler": client.scheduler.address}
                elif scheduler is None and workers == 0:
                    runs = _serial(pending, out, retries, force)
                else:
                    n = workers or min(os.cpu_count() or 1, sum(c.options.chunks for c in pending))
                    c = stack.enter_context(dask_client(scheduler, n, malloc_trim))
                    runs = _dask(c, pending, out, retries, force)
                    execution = {"mode": "dask", "scheduler": scheduler or "LocalCluster",
                                 "workers": len(c.scheduler_info().get("workers", {})), "malloc_trim": malloc_trim}
                for case, attempts, result, error in runs:
                    rec = _record(case, out, result, error, attempts, False, metric_columns)
                    records[case.case_id] = rec
                    if bar:
                        bar.update()
                        n_failed = sum(r["status"] == "failed" for r in records.values())
                        if n_failed:
                            bar.set_postfix(failed=n_failed)
                    if on_case_done is not None:
                        on_case_done(rec)
        finally:
            if bar:
                bar.close()
            ordered = [records[c.case_id] for c in study.cases if c.case_id in records]
            wall = _time.perf_counter() - t0
            summary = write_summary(out, study, ordered, execution, wall)
        _clean_temporaries(out)
    finally:
        lock.unlink(missing_ok=True)
    return StudyResult(out, ordered, summary, wall)
