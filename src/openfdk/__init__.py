"""openfdk — open-source Force-dependent Kinematics.

See the README and docs/ for the user guide; DESIGN notes are cited as paper equation
numbers (Andersen et al., J Biomech Eng 2017) in the code comments.
"""

__version__ = "0.1.0"

#: the notebook API (openfdk.api), imported on first use so that ``import openfdk`` stays light
_API = ("load_model", "load_settings", "load_trial", "run", "read_results")


def __getattr__(name):
    if name in _API:
        from . import api

        return getattr(api, name)
    raise AttributeError(f"module 'openfdk' has no attribute {name!r}")


def __dir__():
    return sorted(list(globals()) + list(_API))
