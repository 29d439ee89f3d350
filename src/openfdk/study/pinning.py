"""Pinning each worker of openfdk's LocalCluster to a CPU of its own (:mod:`.cluster`
explains why and when). A module of its own because it imports Dask's plugin base
class, which a study run without Dask must not import."""

from __future__ import annotations

import contextlib
import os

from distributed.diagnostics.plugin import WorkerPlugin


class CorePinning(WorkerPlugin):
    """Pins worker ``k`` of a LocalCluster (``worker.name`` = k) — every thread of its
    process — to ``cpus[k % len(cpus)]`` (Linux ``sched_setaffinity``); threads the
    worker starts later inherit it. Registered with the client, so Dask runs
    :meth:`setup` on each worker, also on one the nanny restarts."""

    name = "openfdk-core-pinning"

    def __init__(self, cpus):
        self.cpus = [int(c) for c in cpus]

    def setup(self, worker):
        cpu = self.cpus[int(worker.name) % len(self.cpus)]
        for tid in os.listdir("/proc/self/task"):
            with contextlib.suppress(OSError):  # a thread that has just ended
                os.sched_setaffinity(int(tid), {cpu})
