"""Dask clusters for studies and chunked runs.

Without a scheduler address, a :class:`distributed.LocalCluster` on this machine:
worker *processes* (``processes=True``) with one thread each — the analyses are
numpy/numba code holding the GIL, so threads would not run in parallel — listening on
127.0.0.1 only, no dashboard. With an address, any running Dask scheduler; its workers
must have openfdk installed and see the study's files and output folder at the same
paths (a shared file system).

Memory trimming: Dask's nanny sets ``MALLOC_TRIM_THRESHOLD_=65536`` in its workers by
default (``distributed.nanny.pre-spawn-environ``), which makes glibc return freed memory
to the system eagerly. docs/design.md §5 measured numpy-heavy tasks ≈40 % slower inside Dask
workers with it; openfdk's LocalCluster removes it unless ``malloc_trim=True``
(docs/studies.md has the measurement on the FDK parameter study).

Worker housekeeping: a Dask worker's event-loop thread samples the running task's stack
every 10 ms for the dashboard's profiler and runs several periodic callbacks; each needs
the GIL, which the analysis thread holds almost all the time. On the 2-core machine the
FDK cases ran ≈9 % faster with the profiler off and the housekeeping intervals
lengthened (:data:`WORKER_CONFIG`, applied to openfdk's LocalCluster workers only).

Worker start-up (once per worker, not per case): Dask spawns each worker as a fresh
interpreter by default, which then imports Dask and, at its first case, openfdk's
analysis layers (≈ 1.5 s of CPU each), while the driver idles. openfdk's LocalCluster
instead forks its workers from a *fork server* (``multiprocessing`` "forkserver"),
started before Dask is imported, which imports :data:`WORKER_MODULES` once — Dask's
worker and openfdk's analysis layers (:mod:`.worker_start`) — while the driver imports
Dask and starts the scheduler; the workers, and those a nanny restarts, begin with the
imports done, and each loads the compiled kernels its cases call from numba's cache.
The server lives as
long as this process and serves its later clusters. Its environment, fixed when it
starts, is :data:`FORK_SERVER_ENVIRONMENT` (one BLAS thread, as Dask's nanny sets); the
driver's other environment variables are passed to each worker as it starts. With
``malloc_trim=True`` (which must be in the environment when a process starts) the
workers are spawned as Dask does by default.

Core pinning: with as many workers as CPUs this process may use (the default), each
LocalCluster worker — every thread of it, the analysis thread and Dask's event loop —
is pinned to a CPU of its own (:class:`.pinning.CorePinning`, a Dask worker plugin, so
a worker the nanny restarts is pinned again). Unpinned, the analysis thread moved
between cores whenever the worker's event loop woke (heartbeats, monitors: ≈ 10 times
a second) and ran ≈ 6 % slower than in a plain process; pinned, the event loop takes
the analysis thread's core for its few milliseconds and the analysis keeps its caches
(one worker, 13 FDK cases: 6.34 → 5.98 s of CPU, a plain process 5.88 s;
docs/studies.md). ``OPENFDK_PIN_WORKERS=0`` turns it off.

In each worker, the case layer keeps the meshes and parsed model files of the cases it
ran (:mod:`openfdk.contact.mesh_cache`, :func:`openfdk.study.kinds.read_model_mapping`)
and the distance grids (:mod:`openfdk.contact.grid_cache`), so a worker loads a model's
files once, not once per case.
"""

from __future__ import annotations

import contextlib
import logging
import os

#: environment variables the nanny writes into this process's os.environ before
#: spawning a worker (restored when the cluster closes)
NANNY_ENVIRONMENT = ("MALLOC_TRIM_THRESHOLD_", "OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS",
                     "PYTHONHASHSEED")
#: Dask settings of openfdk's LocalCluster workers (module docstring)
WORKER_CONFIG = {
    "distributed.worker.profile.enabled": False,
    "distributed.admin.tick.interval": "1s",
    "distributed.admin.system-monitor.interval": "2s",
    "distributed.worker.memory.monitor-interval": "1s",
}
#: what a LocalCluster worker needs before its first case: the Dask worker, and openfdk's
#: case and analysis layers (:mod:`.worker_start`).
#: Imported once, by the fork server (module docstring), instead of once per worker.
WORKER_MODULES = ("distributed", "openfdk.study.worker_start")
#: environment of the fork server, hence of every worker forked from it (what Dask's nanny
#: sets before spawning a worker: one BLAS/OpenMP thread, a fixed hash seed)
FORK_SERVER_ENVIRONMENT = {"OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1",
                           "PYTHONHASHSEED": "6640"}
START_TIMEOUT_S = 60
#: environment variable that turns core pinning off when "0" (module docstring)
PIN_ENVIRONMENT = "OPENFDK_PIN_WORKERS"
CLOSE_TIMEOUT_S = 20


def start_fork_server():
    """Start (once per process) the fork server that openfdk's LocalCluster workers are
    forked from, importing :data:`WORKER_MODULES` with the environment
    :data:`FORK_SERVER_ENVIRONMENT` and without ``MALLOC_TRIM_THRESHOLD_``. Returns at
    once: the server imports while the caller starts the scheduler. Later clusters of
    this process reuse it."""
    import multiprocessing
    import multiprocessing.forkserver

    ctx = multiprocessing.get_context("forkserver")
    saved = {k: os.environ.get(k) for k in (*FORK_SERVER_ENVIRONMENT, "MALLOC_TRIM_THRESHOLD_")}
    try:
        os.environ.update(FORK_SERVER_ENVIRONMENT)
        os.environ.pop("MALLOC_TRIM_THRESHOLD_", None)
        ctx.set_forkserver_preload(list(WORKER_MODULES))
        multiprocessing.forkserver.ensure_running()
    finally:
        _restore(saved)


def pinnable_cpus(n_workers):
    """The CPUs (sorted ids) this process may run on, if there are exactly
    ``n_workers`` ≥ 2 of them (the cluster then uses every CPU, so pinning leaves none
    idle, also when another cluster runs beside it), pinning is available (Linux) and
    not turned off (:data:`PIN_ENVIRONMENT`); else None."""
    if os.environ.get(PIN_ENVIRONMENT, "1") == "0" or not hasattr(os, "sched_getaffinity"):
        return None
    cpus = sorted(os.sched_getaffinity(0))
    return cpus if 1 < n_workers == len(cpus) else None


def _forwarded_environment():
    """This process's environment variables as they are now, minus those the fork server
    fixes: a worker forked from the (earlier started) server sets them before it starts,
    so it sees e.g. an ``OPENFDK_CACHE_DIR`` set since, as a spawned worker would."""
    skip = {*FORK_SERVER_ENVIRONMENT, "MALLOC_TRIM_THRESHOLD_"}
    return {k: v for k, v in os.environ.items() if k not in skip}


def _restore(saved):
    for k, v in saved.items():
        if v is None:
            os.environ.pop(k, None)
        else:
            os.environ[k] = v


@contextlib.contextmanager
def dask_client(scheduler=None, workers=None, malloc_trim=False, timeout=START_TIMEOUT_S):
    """A connected :class:`distributed.Client`, closed (and its LocalCluster stopped)
    on exit.

    scheduler : address of a running scheduler ("tcp://host:8786"), or None for a
    LocalCluster of ``workers`` processes (default: the number of CPUs) on 127.0.0.1;
    malloc_trim : keep Dask's MALLOC_TRIM_THRESHOLD_ in the local workers; timeout : s
    allowed for the cluster to start / the scheduler to answer."""
    if scheduler is None and not malloc_trim:
        start_fork_server()  # first: it imports while this process imports Dask and starts the scheduler
    import dask
    from distributed import Client, LocalCluster

    if scheduler is not None:
        client = Client(scheduler, timeout=f"{timeout}s", set_as_default=False)
        try:
            yield client
        finally:
            with contextlib.suppress(Exception):
                client.close(timeout=CLOSE_TIMEOUT_S)
        return
    n = int(workers) if workers else (os.cpu_count() or 1)
    if n < 1:
        raise ValueError(f"a LocalCluster needs at least 1 worker, got {workers}")
    saved = {k: os.environ.get(k) for k in NANNY_ENVIRONMENT}
    config = dict(WORKER_CONFIG)
    if not malloc_trim:
        config["distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_"] = None
        config["distributed.worker.multiprocessing-method"] = "forkserver"
    cluster = client = None
    try:
        with dask.config.set(config):
            cluster = LocalCluster(
                n_workers=n, threads_per_worker=1, processes=True, host="127.0.0.1",
                # worker-side failures reach the driver through the futures (one line per
                # case); Dask's ERROR logs would print tracebacks, e.g. a heartbeat racing
                # the scheduler's close at the end of a study
                dashboard_address=None, worker_dashboard_address=None, silence_logs=logging.CRITICAL,
                # the scheduler always serves HTTP (health, metrics); without an address it
                # takes :8787 and warns when another cluster holds it: any free local port
                scheduler_kwargs={"dashboard": False, "dashboard_address": "127.0.0.1:0"},
                env=None if malloc_trim else _forwarded_environment(),
            )
            client = Client(cluster, timeout=f"{timeout}s", set_as_default=False)
            cpus = pinnable_cpus(n)
            if cpus is not None:
                from .pinning import CorePinning

                client.register_plugin(CorePinning(cpus), name=CorePinning.name)
        yield client
    finally:
        if client is not None:
            with contextlib.suppress(Exception):
                client.close(timeout=CLOSE_TIMEOUT_S)
        if cluster is not None:
            with contextlib.suppress(Exception):
                cluster.close(timeout=CLOSE_TIMEOUT_S)
        _restore(saved)
