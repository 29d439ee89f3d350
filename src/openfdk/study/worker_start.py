"""What a study worker does once, before its first case: import openfdk's case and
analysis layers.

Imported by the fork server of openfdk's LocalCluster (:mod:`.cluster`), so the imports
(numpy, numba and openfdk's layers, ≈ 0.2 s of CPU) are done once per cluster —
while the driver starts the scheduler — and every worker forked from the server starts
with them done.

numba's compiled kernels are *not* loaded here: each worker loads, from numba's on-disk
cache, the kernels its cases call at their first call (about 20 of the ≈ 90 cached
overloads for the mandible's FDK cases, ≈ 0.15 s), and the two workers do so at the same
time. Loading all of them in the fork server cost ≈ 0.7 s on the cluster's start-up
path, and made the cold 2-worker study ≈ 0.9 s slower (4 alternated runs, 45 cases;
docs/studies.md "Start-up").
"""

from __future__ import annotations

import importlib

#: the modules a case needs (imported by :func:`openfdk.study.case.run_case` on the way)
CASE_MODULES = ("openfdk.study.case", "openfdk.study.summary", "openfdk.analysis.jobs", "openfdk.io.trials",
                "openfdk.io.markers", "openfdk.io.modelfile", "openfdk.analysis.run", "openfdk.fdk.analysis",
                "openfdk.forces.force_laws", "openfdk.contact.mesh")


def prepare_worker() -> None:
    """Import :data:`CASE_MODULES`."""
    for name in CASE_MODULES:
        importlib.import_module(name)


prepare_worker()
