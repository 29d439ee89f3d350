"""Is numba's on-disk cache of the frame kernels cold (fresh install, upgrade, new cache folder)?

The numerical kernels are ``numba.njit(cache=True)`` functions. numba keeps, per function,
an index file (``<module>.<function>-<line>.pyXY.nbi``) in the module's ``__pycache__`` (or
under ``NUMBA_CACHE_DIR``) that records the source stamp (for openfdk's kernels: the
function's file and all numba-using openfdk sources, :mod:`openfdk.numerics.jit_cache`) and
the compiled signatures. When that index is missing, or its stamp no longer matches the
sources (an upgrade rewrote one), the first call compiles — 1–2 min for all the kernels of a
run — and nothing would be shown while it does.

:func:`cache_is_cold` reads those index files (a few kB of pickles, milliseconds) through
each dispatcher's own cache object, so it sees the same folder and staleness rule numba
applies, and :func:`announce_cold_cache` prints one informational line before the first
kernel call of a CLI command (``check`` after reading the model; the analyses after reading
the model and the trial, through :func:`arm` and :func:`announce_armed`). While the inputs
are read, a model's own kernels may compile (DM's contacts and paths: about 2 min): a
compilation that lasts :data:`ANNOUNCE_AFTER_S` prints the line then (numba's
``numba:compile`` event, :class:`_CompileWatch`).
"""

from __future__ import annotations

import importlib
import sys

#: Modules whose kernels ``openfdk check`` calls for every model (the constraint program).
CHECK_KERNEL_MODULES = (
    "openfdk.model.compiled",
    "openfdk.model.kernels",
)
#: ... and those every kinematic frame calls (``openfdk kinematics``: the recruitment's
#: kernels are never compiled by it, so counting them would call a warm cache cold)
KINEMATICS_KERNEL_MODULES = CHECK_KERNEL_MODULES + ("openfdk.kinematics.frame_kernels",)
#: ... and those every kinematic, inverse-dynamics and FDK frame calls (kinematic frame
#: solve, equilibrium, the default polynomial recruitment).
FRAME_KERNEL_MODULES = CHECK_KERNEL_MODULES + (
    "openfdk.kinematics.frame_kernels",
    "openfdk.dynamics.equilibrium",
    "openfdk.recruitment.polynomial",
    "openfdk.recruitment.interior_point",
)

MESSAGE = ("openfdk: compiling numerical kernels (first run after install, about 1–3 min; "
           "cached afterwards)")


def cached_dispatchers(module):
    """The ``cache=True`` numba dispatchers defined in ``module`` (a module object)."""
    out = []
    for value in vars(module).values():
        cache = getattr(value, "_cache", None)
        py_func = getattr(value, "py_func", None)
        if py_func is None or getattr(py_func, "__module__", None) != module.__name__:
            continue
        if getattr(cache, "_cache_file", None) is not None:
            out.append(value)
    return out


def _index_is_fresh(dispatcher):
    """True when numba's index for ``dispatcher`` exists, is of this numba's format, matches
    the current source stamp and lists at least one compiled signature."""
    try:
        return bool(dispatcher._cache._cache_file._load_index())
    except Exception:  # unreadable / other numba layout: count as cold, numba will recompile
        return False


def _module_counts(modules):
    """[(cold kernels, cached kernels)] per module of ``modules`` (names or module objects)."""
    counts = []
    for module in modules:
        if isinstance(module, str):
            module = importlib.import_module(module)
        fresh = [_index_is_fresh(d) for d in cached_dispatchers(module)]
        counts.append((len(fresh) - sum(fresh), len(fresh)))
    return counts


def cold_fraction(modules=FRAME_KERNEL_MODULES):
    """(number of cached kernels without a fresh index, number of cached kernels) over
    ``modules`` (names or module objects)."""
    counts = _module_counts(modules)
    return sum(c for c, _ in counts), sum(n for _, n in counts)


def cache_is_cold(modules=FRAME_KERNEL_MODULES):
    """True when a module of ``modules`` has no compiled kernel at all (never used since
    the install or the last upgrade of its source), or when at least half of the kernels of
    ``modules`` have no fresh index.

    A model calls only some kernels of a module (no wrapping, one recruitment path…), so a
    warm cache still has never-compiled entries; but every module listed is used by every
    run, so a module with none compiled means its first call compiles."""
    counts = _module_counts(modules)
    n_cold, n_total = sum(c for c, _ in counts), sum(n for _, n in counts)
    if any(n and c == n for c, n in counts):
        return True
    return n_total > 0 and 2 * n_cold >= n_total


def announce_cold_cache(quiet=False, stream=None, modules=None, said=False):
    """Print :data:`MESSAGE` to ``stream`` (stderr) when the kernel cache of ``modules``
    (default :data:`FRAME_KERNEL_MODULES`) is cold and not ``quiet``; tell the progress
    displays to start their clocks after their first step (the one that compiles).
    ``said``: the line was printed already (the compile watch), only the clocks are set.
    Returns whether the cache was cold."""
    from ..trial.progress import set_warmup

    try:
        cold = cache_is_cold(FRAME_KERNEL_MODULES if modules is None else modules)
    except Exception:  # numba missing or its internals changed: say nothing, run as usual
        return False
    set_warmup(cold)
    if cold and not quiet and not said:
        _say(stream)
    return cold


_ARMED = None  # (quiet, modules) set by the CLI, used once the inputs are read


#: seconds a kernel compilation must have run, while the inputs are still being read,
#: before :data:`MESSAGE` is printed (a model's own kernels — DM's contacts, paths and
#: grids — compile while it is built: about 2 min of silence on a cold cache before the
#: announcement after the inputs; bad input fails in less, with its one line only)
ANNOUNCE_AFTER_S = 2.0
_ANNOUNCED = False  # MESSAGE printed by this command already
_WATCH = None  # the armed command's compile watch (:class:`_CompileWatch`), or None


class _CompileWatch:
    """A numba ``numba:compile`` event listener, registered from :func:`arm` until the
    inputs are read (:func:`announce_armed`): at the first compilation it starts a timer
    that prints :data:`MESSAGE` after :data:`ANNOUNCE_AFTER_S` unless the inputs are read
    first (numba fires the event only when it compiles, not when it loads a cached
    kernel)."""

    def __init__(self, quiet):
        self.quiet, self.timer = quiet, None

    def on_start(self, event):
        import threading

        if self.timer is None and not self.quiet:
            self.timer = threading.Timer(ANNOUNCE_AFTER_S, _say_once)
            self.timer.daemon = True
            self.timer.start()

    def on_end(self, event):
        pass

    def stop(self):
        if self.timer is not None:
            self.timer.cancel()


def _say(stream=None):
    """Print :data:`MESSAGE` (stderr)."""
    stream = sys.stderr if stream is None else stream
    print(MESSAGE, file=stream)
    stream.flush()


def _say_once():
    """:func:`_say` unless the armed command said it already (the compile watch's timer)."""
    global _ANNOUNCED
    if not _ANNOUNCED:
        _ANNOUNCED = True
        _say()


def _watch(quiet):
    """Register a :class:`_CompileWatch` (nothing when numba's event API is missing)."""
    global _WATCH
    try:
        from numba.core import event

        listener = type("CompileWatch", (_CompileWatch, event.Listener), {})(quiet)
        event.register("numba:compile", listener)
    except Exception:  # numba missing or its internals changed: the announcement after the inputs only
        return
    _WATCH = listener


def _unwatch():
    global _WATCH
    if _WATCH is None:
        return
    _WATCH.stop()
    try:
        from numba.core import event

        event.unregister("numba:compile", _WATCH)
    except Exception:  # noqa: BLE001 - already gone
        pass
    _WATCH = None


def arm(quiet=False, modules=None):
    """Ask for :func:`announce_cold_cache` at the next :func:`announce_armed` (the analysis
    calls it after reading the model and trial, so bad input still gives one line); and
    meanwhile, should a kernel compile for longer than :data:`ANNOUNCE_AFTER_S` while the
    inputs are read (the model's own kernels), print :data:`MESSAGE` then."""
    global _ARMED, _ANNOUNCED
    _ARMED, _ANNOUNCED = (bool(quiet), modules), False
    _unwatch()
    _watch(bool(quiet))


def disarm():
    """Forget :func:`arm` (the CLI, when a command ends)."""
    global _ARMED, _ANNOUNCED
    _ARMED, _ANNOUNCED = None, False
    _unwatch()


def announce_armed(stream=None):
    """:func:`announce_cold_cache` once if :func:`arm` was called; else nothing."""
    global _ARMED
    _unwatch()
    if _ARMED is None:
        return False
    quiet, modules = _ARMED
    _ARMED = None
    return announce_cold_cache(quiet=quiet, stream=stream, modules=modules, said=_ANNOUNCED)
