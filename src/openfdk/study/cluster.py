"""Dask clusters for studies and chunked runs.

Without a scheduler address, a :class:`distributed.LocalCluster` on this machine:
worker *processes* (``processes=True``) with one thread each — the analyses are
numpy/numba code holding the GIL, so threads would not run in parallel — listening on
127.0.0.1 only, no dashboard. With an address, any running Dask scheduler; its workers
must have openfdk installed and see the study's files and output folder at the same
paths (a shared file system).

Memory trimming: Dask's nanny sets ``MALLOC_TRIM_THRESHOLD_=65536`` in its workers by
default (``distributed.nanny.pre-spawn-environ``), which makes glibc return freed memory
to the system eagerly. DESIGN.md §5 measured numpy-heavy tasks ≈40 % slower inside Dask
workers with it; openfdk's LocalCluster removes it unless ``malloc_trim=True``
(docs/studies.md has the measurement on the FDK parameter study).

Worker housekeeping: a Dask worker's event-loop thread samples the running task's stack
every 10 ms for the dashboard's profiler and runs several periodic callbacks; each needs
the GIL, which the analysis thread holds almost all the time. On the 2-core machine the
FDK cases ran ≈9 % faster with the profiler off and the housekeeping intervals
lengthened (:data:`WORKER_CONFIG`, applied to openfdk's LocalCluster workers only).
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
START_TIMEOUT_S = 60
CLOSE_TIMEOUT_S = 20


@contextlib.contextmanager
def dask_client(scheduler=None, workers=None, malloc_trim=False, timeout=START_TIMEOUT_S):
    """A connected :class:`distributed.Client`, closed (and its LocalCluster stopped)
    on exit.

    scheduler : address of a running scheduler ("tcp://host:8786"), or None for a
    LocalCluster of ``workers`` processes (default: the number of CPUs) on 127.0.0.1;
    malloc_trim : keep Dask's MALLOC_TRIM_THRESHOLD_ in the local workers; timeout : s
    allowed for the cluster to start / the scheduler to answer."""
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
    cluster = client = None
    try:
        with dask.config.set(config):
            cluster = LocalCluster(
                n_workers=n, threads_per_worker=1, processes=True, host="127.0.0.1",
                dashboard_address=None, worker_dashboard_address=None, silence_logs=logging.ERROR,
            )
            client = Client(cluster, timeout=f"{timeout}s", set_as_default=False)
        yield client
    finally:
        if client is not None:
            with contextlib.suppress(Exception):
                client.close(timeout=CLOSE_TIMEOUT_S)
        if cluster is not None:
            with contextlib.suppress(Exception):
                cluster.close(timeout=CLOSE_TIMEOUT_S)
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v
