"""What a study worker does once, before its first case: import openfdk's case and
analysis layers and load numba's compiled kernels from its on-disk cache.

Imported by the fork server of openfdk's LocalCluster (:mod:`.cluster`), so this work is
done once per cluster — while the driver starts the scheduler — and every worker forked
from the server starts with it done. Without it, each worker did it during its first
case (≈ 2 s of CPU per worker: scipy/numba/trimesh imports, then about a dozen kernels
read from numba's cache on their first call).

:func:`load_cached_kernels` only *loads*: for each ``cache=True`` kernel of the imported
openfdk modules it takes the signatures that numba's cache index holds for this
machine and this source and loads those overloads, exactly as the kernel's first call
with such arguments would. It never compiles; a kernel whose cache is missing or stale is
compiled at its first call, as before. Any failure leaves the kernels as they were (the
warm-up is an optimisation only).
"""

from __future__ import annotations

import importlib
import sys

#: the modules a case needs (imported by :func:`openfdk.study.case.run_case` on the way)
CASE_MODULES = ("openfdk.study.case", "openfdk.study.summary", "openfdk.jobs", "openfdk.io.trials",
                "openfdk.io.markers", "openfdk.io.modelfile", "openfdk.analysis.run", "openfdk.fdk.analysis",
                "openfdk.forces.force_laws", "openfdk.contact.mesh", "trimesh")


def _openfdk_dispatchers():
    """The numba dispatchers with an on-disk cache among the attributes of the imported
    openfdk modules, each once."""
    from numba.core.caching import Cache
    from numba.core.dispatcher import Dispatcher

    seen, out = set(), []
    for name, module in list(sys.modules.items()):
        if not name.startswith("openfdk.") or module is None:
            continue
        for value in vars(module).values():
            if isinstance(value, Dispatcher) and id(value) not in seen and isinstance(value._cache, Cache):
                seen.add(id(value))
                out.append(value)
    return out


def load_cached_kernels() -> int:
    """Load every cached overload of the imported openfdk kernels (module docstring).
    Returns the number of overloads loaded."""
    loaded = 0
    for dispatcher in _openfdk_dispatchers():
        try:
            cache = dispatcher._cache
            codegen = dispatcher.targetctx.codegen()
            for key in list(cache._cache_file._load_index()):
                sig = key[0]  # the argument types
                args = tuple(sig) if isinstance(sig, tuple) else tuple(sig.args)
                # only an entry for this machine and this source: compile() then loads it
                if cache._index_key(sig, codegen) == key and args not in dispatcher.overloads:
                    dispatcher.compile(sig)
                    loaded += 1
        except Exception:  # noqa: BLE001 — an optimisation only: the first call loads or compiles
            continue
    return loaded


def prepare_worker() -> int:
    """Import :data:`CASE_MODULES` and load the cached kernels; returns the number of
    kernel overloads loaded."""
    for name in CASE_MODULES:
        importlib.import_module(name)
    return load_cached_kernels()


prepare_worker()
