"""openfdk — open-source Force-dependent Kinematics.

See the README and docs/ for the user guide and docs/design.md for the method and the
architecture; the code comments cite the paper's equation numbers (Andersen et al.,
J Biomech Eng 2017).
"""

__version__ = "0.1.0"

# Before any submodule decorates a kernel: numba's cache of every openfdk kernel is stamped
# with all numba-using openfdk sources, so that editing a callee recompiles its callers
# (openfdk/numerics/jit_cache.py; numba itself is imported only when a kernel module is).
from .numerics import jit_cache as _jit_cache  # noqa: E402

_jit_cache.install(__path__[0])

#: the notebook API (openfdk.api), imported on first use so that ``import openfdk`` stays light
_API = ("load_model", "load_settings", "load_trial", "run", "read_results")
#: the analysis settings, importable from the top level (``openfdk.RecruitmentSettings``)
_SETTINGS = {"AnalysisSettings": "openfdk.model.settings", "FDKSettings": "openfdk.fdk.settings",
             "RecruitmentSettings": "openfdk.forces.elements"}


def __getattr__(name):
    if name in _API:
        from . import api

        return getattr(api, name)
    if name in _SETTINGS:
        import importlib

        return getattr(importlib.import_module(_SETTINGS[name]), name)
    raise AttributeError(f"module 'openfdk' has no attribute {name!r}")


def __dir__():
    return sorted(list(globals()) + list(_API) + list(_SETTINGS))
